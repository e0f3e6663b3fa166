"""The runners behind ``varflow bench`` (accuracy and timing benchmarks).

What users import to score their own results lives one level up, in
:mod:`varflow.evaluation` (metrics, datasets, peers); these modules run the
registered methods over whole benchmark sets and lay out the tables.

Modules
-------
common
    Parameter overrides per method, Markdown tables, CSV rows, JIT warm-up.
middlebury
    The 8 Middlebury pairs with public ground truth (``varflow bench middlebury``).
twoframe
    Two-frame methods and peers on photographic pairs, Middlebury and MPI-Sintel
    (``varflow bench twoframe``).
trajectories
    Trajectory methods on the procedural and photographic synthetic clips
    (``varflow bench trajectories``).
multiframe
    Trajectory methods scored on Middlebury RubberWhale and MPI-Sintel
    (``varflow bench middlebury-multiframe`` and ``sintel-trajectories``): the
    public home of the names of multiframe_data (loaders), multiframe_run (the runs),
    multiframe_tables (the tables) and sintel_protocol (the book's Table 4.1 protocol).
"""
