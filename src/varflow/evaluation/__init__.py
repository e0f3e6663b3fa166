"""Evaluation of flow estimates: error measures (AEE, AAE, RMS, outlier rates, photometric).

What users import: :mod:`~varflow.evaluation.metrics` (re-exported here),
:mod:`~varflow.evaluation.trajectory_metrics`, :mod:`~varflow.evaluation.datasets`
(Middlebury and MPI-Sintel loaders) and :mod:`~varflow.evaluation.peers` (other
libraries' methods).  The runners behind ``varflow bench`` are in
:mod:`varflow.evaluation.bench`.
"""

from .metrics import (
    angular_error,
    angular_error_map,
    endpoint_error,
    endpoint_error_map,
    evaluate,
    outlier_rate,
    photometric_residual,
    photometric_residual_map,
    rms_endpoint_error,
    valid_mask,
)

__all__ = [
    "angular_error",
    "angular_error_map",
    "endpoint_error",
    "endpoint_error_map",
    "evaluate",
    "outlier_rate",
    "photometric_residual",
    "photometric_residual_map",
    "rms_endpoint_error",
    "valid_mask",
]
