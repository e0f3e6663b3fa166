"""Offset-k patch grid with an apron (Gibson & Marques 2016, ch. 3; Jia, Wang & Tang 2011).

The sparse flow model codes every ``m × n`` patch whose top-left corner lies on a grid
of step ``k`` (the *offset*; ``k = 1`` gives fully overlapping patches).  When
``H − m`` (or ``W − n``) is not a multiple of ``k`` the last patches would stick out of
the image, so the field is padded with an **apron** of ``(−(H − m)) mod k`` rows at the
bottom and ``(−(W − n)) mod k`` columns at the right (the apron is always narrower than
``k``).  Apron pixels are filled by edge replication — a smooth continuation that keeps
unmasked codes sensible — but they are not data: :meth:`PatchGrid.patch_mask` marks which
entries of a patch matrix are real pixels, and the coding / learning routines of
:mod:`varflow.sparse` use it as 0/1 weights so that apron values never matter.

Vectorisation order
-------------------
A field of shape ``(H, W, c)`` becomes a patch matrix ``Y`` of shape ``(c·m·n, P)``.

* Row (entry of a patch vector): channel-major, then row-major inside the patch::

      row = ch · m·n + a · n + b        (a = row in patch, b = column in patch)

  so for a flow ``(H, W, 2)`` a column is ``[u-patch; v-patch]``, each ``m·n`` entries
  in C order — exactly the joint "2D" layout of :mod:`varflow.sparse.dictionaries`.
* Column (patch index): row-major over the patch grid,
  ``p = i · Pw + j`` for the patch with top-left pixel ``(i·k, j·k)``.

Operators
---------
``extract`` E is linear; ``extract_adjoint`` is its exact adjoint Eᵀ (sums the patch
entries back onto the padded image and folds the apron back onto the last real
row/column, the adjoint of edge replication).  ``average`` is the sparse
approximation of the field: the mean, over the patches covering a real pixel, of the
patch values at that pixel (apron entries ignored), so ``average(extract(x)) == x``.
For an energy term with masked residuals, ``extract_adjoint(M * R)`` equals the plain
"sum back and crop" because ``M`` zeroes the apron entries.

All routines are vectorised: one strided slice copy (or add) per patch offset
``(a, b)``, i.e. ``m·n`` NumPy operations on ``(Ph, Pw)`` arrays, independent of the
number of patches.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

__all__ = ["PatchGrid"]


def _fail(field: str, msg: str) -> None:
    raise ValueError(f"{field}: {msg}")


@dataclass(frozen=True)
class PatchGrid:
    """Grid of ``m × n`` patches with top-left corners every ``k`` pixels.

    Parameters
    ----------
    height, width : int
        Image size ``(H, W)``; must be at least the patch size (a smaller image raises
        ``ValueError`` — use smaller patches or skip the sparse term on such levels).
    patch_size : tuple of int
        ``(m, n)`` patch height and width.  Default ``(10, 10)`` (the book's setting).
    offset : int
        ``k``, step between patch corners, ``1 <= k <= min(m, n)`` (a larger step
        would leave pixels covered by no patch).  Default 1 (fully overlapping).

    Notes
    -----
    Derived properties:

    padded_shape : (Hp, Wp)
        ``Hp = m + k·ceil((H − m)/k)``; the apron is ``Hp − H < k`` rows at the bottom
        and ``Wp − W < k`` columns at the right.
    grid_shape : (Ph, Pw)
        Patches per column / row, ``Ph = (Hp − m)/k + 1``.
    n_patches : int
        ``P = Ph · Pw``.

    Examples
    --------
    >>> g = PatchGrid(480, 640, (10, 10), offset=4)
    >>> g.padded_shape, g.grid_shape
    ((482, 642), (119, 159))
    """

    height: int
    width: int
    patch_size: tuple[int, int] = (10, 10)
    offset: int = 1

    def __post_init__(self) -> None:
        m, n = (int(s) for s in self.patch_size)
        object.__setattr__(self, "patch_size", (m, n))
        if m < 1 or n < 1:
            _fail("patch_size", f"must be positive, got {self.patch_size}")
        if self.offset < 1:
            _fail("offset", f"must be >= 1, got {self.offset}")
        if self.offset > min(m, n):
            _fail("offset", f"must be <= min(patch_size) = {min(m, n)}, got {self.offset}")
        if self.height < m or self.width < n:
            _fail(
                "patch_size",
                f"{self.patch_size} is larger than the image ({self.height}, {self.width})",
            )

    # ------------------------------------------------------------------ geometry
    @property
    def patch_dim(self) -> int:
        """Entries per channel of a patch vector, ``m·n``."""
        return self.patch_size[0] * self.patch_size[1]

    @property
    def padded_shape(self) -> tuple[int, int]:
        """``(Hp, Wp)``: image size including the bottom/right apron."""
        m, n = self.patch_size
        k = self.offset
        return (
            m + k * (-(-(self.height - m) // k)),
            n + k * (-(-(self.width - n) // k)),
        )

    @property
    def grid_shape(self) -> tuple[int, int]:
        """``(Ph, Pw)``: number of patch rows and columns."""
        hp, wp = self.padded_shape
        m, n = self.patch_size
        return ((hp - m) // self.offset + 1, (wp - n) // self.offset + 1)

    @property
    def n_patches(self) -> int:
        """``P``, number of patches (columns of a patch matrix)."""
        ph, pw = self.grid_shape
        return ph * pw

    @property
    def has_apron(self) -> bool:
        """True when the padded image is larger than the image."""
        return self.padded_shape != (self.height, self.width)

    @cached_property
    def apron_mask(self) -> np.ndarray:
        """``(Hp, Wp)`` bool, True on apron (padding) pixels, False on real pixels."""
        mask = np.ones(self.padded_shape, dtype=bool)
        mask[: self.height, : self.width] = False
        mask.flags.writeable = False
        return mask

    @cached_property
    def count(self) -> np.ndarray:
        """``(H, W)`` float32: number of patches covering each real pixel.

        This is the weight map of :meth:`average`; with ``k = 1`` it ranges from 1 in
        the corners to ``m·n`` in the interior.
        """
        ph, pw = self.grid_shape
        k = self.offset
        acc = np.zeros(self.padded_shape, np.float32)
        for a in range(self.patch_size[0]):
            for b in range(self.patch_size[1]):
                acc[a : a + k * ph : k, b : b + k * pw : k] += 1.0
        out = acc[: self.height, : self.width].copy()
        out.flags.writeable = False
        return out

    def interior_patches(self) -> np.ndarray:
        """``(P,)`` bool: True for patches lying entirely inside the real image."""
        ph, pw = self.grid_shape
        m, n = self.patch_size
        k = self.offset
        rows = np.arange(ph) * k + m <= self.height
        cols = np.arange(pw) * k + n <= self.width
        return (rows[:, None] & cols[None, :]).ravel()

    def patch_mask(self, channels: int = 1) -> np.ndarray:
        """Mask matrix ``M``: True where an entry of a patch matrix is a real pixel.

        Parameters
        ----------
        channels : int
            ``c``, number of channels of the field (2 for a flow).

        Returns
        -------
        ndarray, shape (c·m·n, P), bool
            Same layout as :meth:`extract`; False exactly on apron entries.  All True
            when the grid has no apron.
        """
        if channels < 1:
            _fail("channels", f"must be >= 1, got {channels}")
        m, n = self.patch_size
        ph, pw = self.grid_shape
        k = self.offset
        out = np.empty((channels, m, n, ph, pw), dtype=bool)
        if not self.has_apron:
            out.fill(True)
            return out.reshape(channels * m * n, ph * pw)
        real = ~self.apron_mask
        for a in range(m):
            for b in range(n):
                out[:, a, b] = real[a : a + k * ph : k, b : b + k * pw : k]
        return out.reshape(channels * m * n, ph * pw)

    # ------------------------------------------------------------------ operators
    def _as_channels_first(self, field: np.ndarray, name: str) -> np.ndarray:
        arr = np.asarray(field)
        if arr.ndim == 2:
            arr = arr[:, :, None]
        if arr.ndim != 3 or arr.shape[:2] != (self.height, self.width):
            _fail(
                name,
                f"expected shape ({self.height}, {self.width}) or "
                f"({self.height}, {self.width}, c), got {np.shape(field)}",
            )
        return np.moveaxis(arr, 2, 0)

    def pad(self, field: np.ndarray) -> np.ndarray:
        """Pad a field with the apron by edge replication.

        Parameters
        ----------
        field : ndarray, shape (H, W) or (H, W, c)

        Returns
        -------
        ndarray, shape (c, Hp, Wp), float32, channel-first
        """
        src = self._as_channels_first(field, "field")
        hp, wp = self.padded_shape
        out = np.empty((src.shape[0], hp, wp), np.float32)
        h, w = self.height, self.width
        out[:, :h, :w] = src
        out[:, :h, w:] = out[:, :h, w - 1 : w]
        out[:, h:, :] = out[:, h - 1 : h, :]
        return out

    def extract(self, field: np.ndarray) -> np.ndarray:
        """Patch matrix of a field (apron filled by edge replication).

        Parameters
        ----------
        field : ndarray, shape (H, W) or (H, W, c)
            A flow ``(H, W, 2)``, an image, ...  Converted to float32.

        Returns
        -------
        ndarray, shape (c·m·n, P), float32, C-contiguous
            Column ``p`` is the vectorised patch ``p`` (order in the module docstring).
            Use :meth:`patch_mask` to tell real entries from apron entries.
        """
        padded = self.pad(field)
        c = padded.shape[0]
        m, n = self.patch_size
        ph, pw = self.grid_shape
        k = self.offset
        out = np.empty((c, m, n, ph, pw), np.float32)
        for a in range(m):
            for b in range(n):
                out[:, a, b] = padded[:, a : a + k * ph : k, b : b + k * pw : k]
        return out.reshape(c * m * n, ph * pw)

    def _sum_back(self, patches: np.ndarray, name: str) -> np.ndarray:
        """Sum patch entries onto the padded image; float64 ``(c, Hp, Wp)``."""
        y = np.asarray(patches)
        m, n = self.patch_size
        ph, pw = self.grid_shape
        if y.ndim != 2 or y.shape[1] != ph * pw or y.shape[0] % (m * n) or y.shape[0] == 0:
            _fail(name, f"expected shape (c·{m * n}, {ph * pw}), got {y.shape}")
        c = y.shape[0] // (m * n)
        y = y.reshape(c, m, n, ph, pw)
        k = self.offset
        acc = np.zeros((c,) + self.padded_shape, np.float64)
        for a in range(m):
            for b in range(n):
                acc[:, a : a + k * ph : k, b : b + k * pw : k] += y[:, a, b]
        return acc

    @staticmethod
    def _channels_last(acc: np.ndarray) -> np.ndarray:
        out = np.moveaxis(acc, 0, 2).astype(np.float32)
        return out[:, :, 0] if out.shape[2] == 1 else out

    def extract_adjoint(self, patches: np.ndarray) -> np.ndarray:
        """Exact adjoint of :meth:`extract`: ``<extract(x), Y> == <x, extract_adjoint(Y)>``.

        Sums every patch entry back onto the padded image, then folds the apron rows
        onto row ``H − 1`` and the apron columns onto column ``W − 1`` (adjoint of
        edge replication).  With apron entries zeroed (``Y * M``) this is the plain
        "sum back and crop".

        Parameters
        ----------
        patches : ndarray, shape (c·m·n, P)

        Returns
        -------
        ndarray, shape (H, W) if c = 1 else (H, W, c), float32
        """
        acc = self._sum_back(patches, "patches")
        h, w = self.height, self.width
        acc[:, h - 1, :] += acc[:, h:, :].sum(axis=1)
        acc[:, :h, w - 1] += acc[:, :h, w:].sum(axis=2)
        return self._channels_last(acc[:, :h, :w])

    def average(self, patches: np.ndarray) -> np.ndarray:
        """Field from (approximated) patches: per-pixel mean of the covering patches.

        This is the sparse approximation of the field, ``(Σ_p R_pᵀ D a_p) / count``
        restricted to real pixels; apron entries are ignored.  Accumulation is in
        float64, so ``average(extract(x)) == x`` exactly for float32 ``x``.

        Parameters
        ----------
        patches : ndarray, shape (c·m·n, P)

        Returns
        -------
        ndarray, shape (H, W) if c = 1 else (H, W, c), float32
        """
        acc = self._sum_back(patches, "patches")[:, : self.height, : self.width]
        acc /= self.count
        return self._channels_last(acc)
