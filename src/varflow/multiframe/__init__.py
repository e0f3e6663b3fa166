"""Multi-frame trajectory estimation (Gibson & Marques 2016, ch. 4).

Modules: :mod:`varflow.multiframe.lowrank` — the low-rank step (L-step) of the
Robust Low-Rank (RLR) method: principal component pursuit, exact and in linear
time by random column sub-sampling and l1 filtering.
"""
