"""Frame interpolation and retiming: what motion is for.

:func:`varflow.interpolate` synthesises the frame at time ``t`` between two frames from
the motion between them.  The methods live in the plain registry
:data:`varflow.retime.methods.INTERPOLATORS` (read by the API, the CLI and the
benchmark); each has a frozen parameter dataclass and a ``prepare`` function that
estimates the motion of a pair once and returns a :class:`~varflow.retime.methods.PairMotion`
whose ``render(t)`` gives any in-between frame, so a retimed video estimates each
pair's flows once for all its in-between frames.
"""

from __future__ import annotations

from .methods import (
    DEFAULT_INTERPOLATOR,
    INTERPOLATORS,
    Interpolator,
    PairMotion,
    get_interpolator,
    interpolate,
    make_interp_params,
)

__all__ = [
    "DEFAULT_INTERPOLATOR",
    "INTERPOLATORS",
    "Interpolator",
    "PairMotion",
    "get_interpolator",
    "interpolate",
    "make_interp_params",
]
