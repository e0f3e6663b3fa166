"""Seeded scene generators with exact ground truth, apart from loaders and runners.

* :mod:`varflow.generators.pairs` — two-frame pairs of an analytic texture under a
  known motion (:func:`~varflow.generators.pairs.synthetic_pair`).
* :mod:`varflow.generators.sequences` — multi-frame clips of analytic textures with
  exact trajectories and visibility (the procedural trajectory suite,
  :func:`~varflow.generators.sequences.make_sequence`).
* :mod:`varflow.generators.photo` — multi-frame clips of real photographs (bundled
  with scikit-image), area-sampled under camera motion, waves or moving objects,
  with illumination change or camera noise, with exact trajectories and
  visibility; seeded tuning and reporting splits (the generalisation suite,
  :func:`~varflow.generators.photo.make_photo_clip`).
* :mod:`varflow.generators.photo_pairs` — two-frame pairs of the same photographs
  and renderer (camera affine or perspective motion, waves, occluding objects,
  illumination change, noise, blur; 3-15 px), with exact flow and occlusion mask,
  on the same tuning and reporting seeds
  (:func:`~varflow.generators.photo_pairs.make_photo_pair`).
"""
