"""Motion compensation with a flow: warping by it, and checking it against its inverse.

The two helpers an OpenCV or scikit-image user reaches for first, on the library's
conventions (flows ``(H, W, 2)`` float32, u = ``[..., 0]``, v = ``[..., 1]``, NaN
where unknown): :func:`warp`, the ``cv2.remap`` of a flow, and :func:`consistency`,
the forward-backward check that marks occlusions and unreliable vectors.  Both
sample with the bilinear kernel of :func:`varflow.ops.warp.warp_bilinear`.  Exported
as ``varflow.warp`` and ``varflow.consistency``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .ops.warp import warp_bilinear

__all__ = ["consistency", "warp"]


def _real_array(arr: Any, name: str, kinds: str = "buif") -> np.ndarray:
    """``arr`` as an ndarray whose dtype kind is one of ``kinds``, else a ValueError
    naming ``name``."""
    out = np.asarray(arr)
    if out.dtype.kind not in kinds:
        raise ValueError(f"{name}: expected a real-valued array (integer or float), "
                         f"got dtype {out.dtype}")
    return out


def _flow_like(arr: Any, name: str, shape: tuple[int, ...] | None = None) -> np.ndarray:
    """``arr`` checked as an ``(H, W, 2)`` flow (of the given ``(H, W)``), float32."""
    out = _real_array(arr, name, "iuf")
    if out.ndim != 3 or out.shape[2] != 2 or (shape is not None and out.shape[:2] != shape):
        want = "(H, W, 2)" if shape is None else f"{shape + (2,)}"
        raise ValueError(f"{name}: expected a flow of shape {want}, got {out.shape}")
    return out.astype(np.float32, copy=False)


def warp(image: np.ndarray, flow: np.ndarray) -> np.ndarray:
    """Backward-warp an image by a flow: ``out[y, x] = image(x + u, y + v)``, bilinear.

    The image is sampled with bilinear interpolation at the points the flow sends
    every pixel to, so warping ``frame1`` by the flow from ``frame0`` to ``frame1``
    gives an image aligned with ``frame0``.  Where a point falls outside the image
    (outside ``[0, W-1] x [0, H-1]``, i.e. one of its 4 bilinear taps is missing)
    or the flow is NaN, the result is NaN; so is it where one of the 4 image pixels
    around the point is NaN.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, C)
        Any real dtype (uint8, uint16, float, ...).  The values are not rescaled:
        the result is in the image's own units (0-255 for uint8).  The channels are
        warped independently, so their order (RGB or BGR) does not matter.
    flow : ndarray, shape (H, W, 2)
        In pixels, with the image's H and W; ``[..., 0]`` = u (x, columns),
        ``[..., 1]`` = v (y, rows).  Integer or float; NaN where unknown.

    Returns
    -------
    ndarray, shape of ``image``, float32
        ``out[y, x] = image(x + u(y, x), y + v(y, x))``.  Always float32, whatever
        the image's dtype: the samples are interpolated (not rounded back to
        integers) and the pixels without a value are NaN, which only a float
        can hold.  Use ``np.isnan(out)`` for the mask of missing pixels.

    Raises
    ------
    ValueError
        If ``image`` is not ``(H, W)`` or ``(H, W, C)`` or not real-valued, or if
        ``flow`` is not ``(H, W, 2)`` with the image's H and W, or not real-valued.
        The message is one line and names the argument.

    See Also
    --------
    consistency : Which pixels of a flow its backward flow confirms.

    Notes
    -----
    The same with OpenCV (``xx, yy`` the pixel grid, ``np.mgrid`` ordering)::

        yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
        out = cv2.remap(image.astype(np.float32), xx + flow[..., 0], yy + flow[..., 1],
                        cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                        borderValue=(np.nan,) * 4)

    that is ``map_x = x + u`` and ``map_y = y + v``.  The two agree to float32
    rounding inside the image; OpenCV also gives NaN on the last row and column
    when it samples them exactly (its zero-weight tap beyond the border is NaN),
    and OpenCV 4 rounds the sampling positions to 1/32 pixel.  ``borderValue``
    needs the NaN in all four entries for colour images.  Frames from
    :func:`read_image` are RGB and ``cv2.imread`` gives BGR: convert with
    ``cv2.cvtColor(img, cv2.COLOR_RGB2BGR)`` before mixing them (the warp itself
    does not care).

    Examples
    --------
    >>> import numpy as np
    >>> import varflow
    >>> image = np.arange(12, dtype=np.uint8).reshape(3, 4)
    >>> flow = np.zeros((3, 4, 2), np.float32)
    >>> flow[..., 0] = 1.0                     # sample one pixel to the right
    >>> varflow.warp(image, flow)
    array([[ 1.,  2.,  3., nan],
           [ 5.,  6.,  7., nan],
           [ 9., 10., 11., nan]], dtype=float32)
    >>> flow[..., 0] = 0.5                     # half-way: the mean of the neighbours
    >>> varflow.warp(image, flow)[0]
    array([0.5, 1.5, 2.5, nan], dtype=float32)
    """
    img = _real_array(image, "image")
    if img.ndim not in (2, 3) or 0 in img.shape:
        raise ValueError(f"image: expected a non-empty array of shape (H, W) or (H, W, C), "
                         f"got {img.shape}")
    f = _flow_like(flow, "flow", img.shape[:2])
    planes = img[..., None] if img.ndim == 2 else img
    out, inside = warp_bilinear(planes, f)
    out[~inside] = np.nan
    return out[..., 0] if img.ndim == 2 else out


def _weight(value: Any, name: str) -> np.float32:
    """A finite, non-negative float parameter, else a ValueError naming ``name``."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected a number, got {value!r}") from None
    if isinstance(value, bool) or not (np.isfinite(v) and v >= 0):
        raise ValueError(f"{name}: expected a finite number >= 0, got {value!r}")
    return np.float32(v)


def consistency(flow_fw: np.ndarray, flow_bw: np.ndarray, *, alpha1: float = 0.01,
                alpha2: float = 0.5) -> np.ndarray:
    """Forward-backward consistency of a flow: True where the backward flow confirms it.

    A pixel ``x`` of the first frame is consistent when following the forward
    flow ``w_f`` and then the backward flow ``w_b`` brings it back near ``x``
    (Sundaram, Brox & Keutzer 2010)::

        |w_f + w_b(x + w_f)|^2  <  alpha1 (|w_f|^2 + |w_b(x + w_f)|^2) + alpha2

    with ``w_b`` sampled bilinearly at ``x + w_f(x)``.  The tolerance grows with
    the motion (``alpha1``) on top of a constant (``alpha2``, px²).

    Parameters
    ----------
    flow_fw : ndarray, shape (H, W, 2)
        Flow from the first frame to the second (``varflow.flow(frame0, frame1)``),
        in pixels; NaN where unknown.
    flow_bw : ndarray, shape (H, W, 2)
        Flow from the second frame to the first (``varflow.flow(frame1, frame0)``).
    alpha1 : float
        Relative tolerance (dimensionless), finite and >= 0.
    alpha2 : float
        Absolute tolerance in px², finite and >= 0.

    Returns
    -------
    ndarray, shape (H, W), bool
        True where the forward flow is consistent: the pixel is visible in both
        frames and its flow is confirmed.  False where the check fails (the pixel
        is occluded in the second frame, or one of the flows is wrong there),
        where ``x + w_f(x)`` falls outside ``[0, W-1] x [0, H-1]``, where
        ``w_f(x)`` is NaN, and where ``w_b`` is NaN at one of the 4 pixels around
        ``x + w_f(x)``.  ``~mask`` is the occlusion mask (True = occluded or
        unreliable).

    Raises
    ------
    ValueError
        If a flow is not ``(H, W, 2)`` and real-valued, the two differ in shape, or
        ``alpha1`` / ``alpha2`` is not a finite number >= 0; the message names the
        argument.

    See Also
    --------
    warp : The same bilinear sampling applied to an image.

    Notes
    -----
    The backward flow is sampled by the bilinear kernel of :func:`warp`.  The
    frame interpolation of :mod:`varflow.retime` uses a linear variant of the same
    test, ``|w_f + w_b(x + w_f)| <= tau + kappa |w_f|``
    (``varflow.ops.occlusion.hidden_mask``).

    References
    ----------
    N. Sundaram, T. Brox, K. Keutzer, "Dense point trajectories by GPU-accelerated
    large displacement optical flow", ECCV 2010.

    Examples
    --------
    >>> import numpy as np
    >>> import varflow
    >>> fw = np.zeros((3, 4, 2), np.float32)
    >>> fw[..., 0] = 1.0                       # everything moves one pixel right
    >>> bw = -fw                               # and back
    >>> varflow.consistency(fw, bw)            # the last column leaves the frame
    array([[ True,  True,  True, False],
           [ True,  True,  True, False],
           [ True,  True,  True, False]])
    >>> occluded = ~varflow.consistency(fw, np.zeros_like(fw))
    >>> bool(occluded.all())
    True
    """
    fw = _flow_like(flow_fw, "flow_fw")
    bw = _flow_like(flow_bw, "flow_bw")
    if bw.shape != fw.shape:
        raise ValueError(f"flow_bw: expected the shape of flow_fw {fw.shape}, got {bw.shape}")
    a1 = _weight(alpha1, "alpha1")
    a2 = _weight(alpha2, "alpha2")
    back, inside = warp_bilinear(bw, fw)
    with np.errstate(invalid="ignore", over="ignore"):
        # the two components added explicitly: a reduction over a length-2 axis is
        # several times slower than the adds, with the same result
        loop = fw + back
        err = np.square(loop[..., 0]) + np.square(loop[..., 1])
        limit = a1 * (np.square(fw[..., 0]) + np.square(fw[..., 1])
                      + (np.square(back[..., 0]) + np.square(back[..., 1]))) + a2
        return inside & (err < limit)  # NaN compares False
