"""Restoration of footage with motion: noise estimation (and, to come, denoising and
archival defects).

* :mod:`varflow.restore.noise` -- the noise level of a clip, per channel and as a
  curve over intensity, from its least textured blocks.
"""

from .noise import NoiseEstimate, estimate_noise

__all__ = ["NoiseEstimate", "estimate_noise"]
