"""Restoration of footage with motion.

* :mod:`varflow.restore.noise` -- the noise level of a clip, per channel and as a
  curve over intensity, from its least textured blocks.
* :mod:`varflow.restore.denoise` -- :func:`varflow.denoise` and the streaming
  :func:`~varflow.restore.denoise.iter_denoise`; the kernels of motion-compensated
  NL-Bayes are in :mod:`varflow.restore._nlbayes`.
* :mod:`varflow.restore.methods` -- the restoration methods and their parameters
  (:data:`varflow.registry.RESTORE`).
* :mod:`varflow.restore.flicker` -- :func:`varflow.deflicker`: a smooth gain and
  offset per frame against the motion-compensated neighbours, corrected toward a
  temporally smoothed path (fades and lights that stay are kept).
* :mod:`varflow.restore.dirt` -- :func:`varflow.remove_dirt`: blotches as temporal
  outliers along the motion, filled from the neighbours, with the mask of what changed.
* :mod:`varflow.restore.stabilise` -- :func:`varflow.stabilise`: gate weave removed
  from a robust global fit to the flows and a smoothed camera path.
* :mod:`varflow.restore.chain` -- :func:`varflow.restore_clip` and the streaming
  :func:`~varflow.restore.chain.iter_restore`: the stages chained in the order of
  practice (stabilise, deflicker, dirt, denoise).
* :mod:`varflow.restore.video` -- a video or a frame folder denoised into a video
  or a frame folder (``varflow denoise`` and ``varflow batch denoise``).
"""

from .noise import NoiseEstimate, estimate_noise

__all__ = ["NoiseEstimate", "estimate_noise"]
