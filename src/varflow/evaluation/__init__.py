"""Evaluation of flow estimates: error measures (AEE, AAE, RMS, outlier rates, photometric)."""

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
