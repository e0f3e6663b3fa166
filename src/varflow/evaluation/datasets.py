"""Where the benchmark data lives, and loaders for Middlebury and MPI-Sintel pairs.

The data are read in place from a folder laid out as::

    <root>/middlebury/other-data/<Seq>/frame10.png, frame11.png
    <root>/middlebury/other-gt-flow/<Seq>/flow10.flo
    <root>/sintel/training/{clean,final}/<clip>/frame_NNNN.png
    <root>/sintel/training/flow/<clip>/frame_NNNN.flo            (frame N -> N+1)
    <root>/sintel/training/{occlusions,invalid}/<clip>/frame_NNNN.png   (white = yes)

:func:`data_root` decides where ``<root>`` is: an explicit argument (the CLI's
``--data``), else the environment variable ``VARFLOW_DATA``, else ``../shared/data``
seen from the working directory or from the repository root.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

__all__ = [
    "ENV_VAR",
    "MIDDLEBURY_SEQUENCES",
    "BOOK_TV_AEE",
    "BOOK_TENSOR_AEE",
    "BOOK_REFERENCE_AEE",
    "SINTEL_PASSES",
    "data_root",
    "middlebury_sequence",
    "load_middlebury_pair",
    "load_sintel_pair",
    "sintel_pairs",
]

#: Environment variable naming the data folder.
ENV_VAR = "VARFLOW_DATA"

#: The eight Middlebury "other" sequences with public ground truth.
MIDDLEBURY_SEQUENCES: tuple[str, ...] = (
    "Dimetrodon",
    "Grove2",
    "Grove3",
    "Hydrangea",
    "RubberWhale",
    "Urban2",
    "Urban3",
    "Venus",
)

#: Average endpoint error of plain TV-L1 ("TV-only"), frame10 -> frame11, from
#: Gibson & Marques 2016, Table 3.3.  Mean 0.3286.
BOOK_TV_AEE: dict[str, float] = {
    "Dimetrodon": 0.1562,
    "Grove2": 0.1921,
    "Grove3": 0.6869,
    "Hydrangea": 0.1597,
    "RubberWhale": 0.1118,
    "Urban2": 0.3801,
    "Urban3": 0.6441,
    "Venus": 0.2977,
}

#: Average endpoint error of tensor-directed TV-L1 from Gibson & Marques 2016, Table 3.4.
BOOK_TENSOR_AEE: dict[str, float] = {
    "Dimetrodon": 0.1576,
    "Grove2": 0.2000,
    "Grove3": 0.6630,
    "Hydrangea": 0.1633,
    "RubberWhale": 0.1169,
    "Urban2": 0.3761,
    "Urban3": 0.6051,
    "Venus": 0.3035,
}

#: The book's figure for a registered method name, per sequence.  Add an entry
#: when a method with a published counterpart is registered.
BOOK_REFERENCE_AEE: dict[str, dict[str, float]] = {
    "tvl1": BOOK_TV_AEE,
    "tensor": BOOK_TENSOR_AEE,
}

SINTEL_PASSES: tuple[str, ...] = ("clean", "final")

#: How to point at the data, appended to the messages of a missing file.
DATA_HINT = f"pass --data DIR or set {ENV_VAR} to the folder holding middlebury/ and sintel/"


def _repo_root() -> Path:
    # src/varflow/evaluation/datasets.py -> the repository root of an editable install
    return Path(__file__).resolve().parents[3]


def data_root(explicit: str | os.PathLike[str] | None = None) -> Path:
    """The benchmark data folder.

    Parameters
    ----------
    explicit : path-like, optional
        Used as is when given (e.g. the CLI's ``--data``).

    Returns
    -------
    Path
        ``explicit``; else ``$VARFLOW_DATA`` when set and non-empty; else the first
        existing of ``./../shared/data`` (relative to the working directory) and
        ``<repository root>/../shared/data``.  When none exists the first candidate
        is returned; the path is not guaranteed to exist, callers check (the loaders
        raise ``FileNotFoundError`` with a hint).
    """
    if explicit is not None:
        return Path(explicit).expanduser()
    env = os.environ.get(ENV_VAR, "").strip()
    if env:
        return Path(env).expanduser()
    candidates = [Path.cwd() / ".." / "shared" / "data", _repo_root() / ".." / "shared" / "data"]
    for c in candidates:
        if c.is_dir():
            return c.resolve()
    return candidates[0].resolve()


def require_file(path: Path, what: str, root: Path) -> Path:
    """``path``, checked to be a file.

    Parameters
    ----------
    path : Path
    what : str
        What the file is, for the message (``"Middlebury Grove2 frame10"``).
    root : Path
        The data root, for the message.

    Raises
    ------
    FileNotFoundError
        When ``path`` is not a file; the message names it, the data root and
        :data:`DATA_HINT`.
    """
    if not path.is_file():
        raise FileNotFoundError(f"{what} not found: {path} (data root {root}); {DATA_HINT}")
    return path


def middlebury_sequence(name: str) -> str:
    """Canonical spelling of a Middlebury sequence name (case-insensitive).

    Raises
    ------
    ValueError
        For a name not in :data:`MIDDLEBURY_SEQUENCES`.
    """
    for s in MIDDLEBURY_SEQUENCES:
        if s.lower() == str(name).strip().lower():
            return s
    raise ValueError(
        f"sequence: unknown Middlebury sequence {name!r}; "
        f"available: {', '.join(MIDDLEBURY_SEQUENCES)}"
    )


def nan_unknown(flow: np.ndarray) -> np.ndarray:
    """A float32 copy of a ground-truth flow with unknown vectors NaN in both components.

    Non-finite components and components larger than 1e9 in magnitude (the
    Middlebury/Sintel "unknown" code) make the whole vector NaN.
    """
    flow = np.array(flow, dtype=np.float32, copy=True)
    flow[~np.isfinite(flow) | (np.abs(flow) > 1e9)] = np.nan
    bad = np.isnan(flow).any(axis=2)
    flow[bad] = np.nan
    return flow


def load_middlebury_pair(
    seq: str, root: str | os.PathLike[str] | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Frames 10 and 11 of a Middlebury sequence and the ground-truth flow between them.

    Parameters
    ----------
    seq : str
        One of :data:`MIDDLEBURY_SEQUENCES` (case-insensitive).
    root : path-like, optional
        Data folder; see :func:`data_root`.

    Returns
    -------
    frame0, frame1 : ndarray, shape (H, W, 3), uint8
        RGB frames ``frame10.png`` and ``frame11.png``.
    flow : ndarray, shape (H, W, 2), float32
        Ground truth from frame10 to frame11; unknown pixels are NaN.

    Raises
    ------
    ValueError
        Unknown sequence name.
    FileNotFoundError
        A file is missing (the message says how to point at the data).
    """
    from ..io.flo import read_flo
    from ..io.images import read_image

    seq = middlebury_sequence(seq)
    base = data_root(root)
    mb = base / "middlebury"
    p0 = require_file(mb / "other-data" / seq / "frame10.png", f"Middlebury {seq} frame10", base)
    p1 = require_file(mb / "other-data" / seq / "frame11.png", f"Middlebury {seq} frame11", base)
    pf = require_file(mb / "other-gt-flow" / seq / "flow10.flo", f"Middlebury {seq} ground truth",
                      base)
    f0 = to_rgb(read_image(p0))
    f1 = to_rgb(read_image(p1))
    gt = nan_unknown(read_flo(pf))
    if f0.shape != f1.shape or gt.shape[:2] != f0.shape[:2]:
        raise ValueError(
            f"Middlebury {seq}: inconsistent sizes {f0.shape}, {f1.shape}, flow {gt.shape}"
        )
    return f0, f1, gt


def to_rgb(img: np.ndarray) -> np.ndarray:
    """An ``(H, W, 3)`` image: grey replicated to three channels, alpha dropped."""
    if img.ndim == 2:
        return np.repeat(img[:, :, None], 3, axis=2)
    return np.ascontiguousarray(img[:, :, :3])


def read_mask(path: Path) -> np.ndarray | None:
    """A white-is-true mask image as a bool array ``(H, W)``; None when the file is missing.

    Used for the Sintel ``occlusions`` and ``invalid`` masks; a pixel is True above
    half the dtype's range (any channel).
    """
    from ..io.images import read_image

    if not path.is_file():
        return None
    m = read_image(path)
    if m.ndim == 3:
        m = m.max(axis=2)
    return m > (np.iinfo(m.dtype).max // 2 if np.issubdtype(m.dtype, np.integer) else 0.5)


def load_sintel_pair(
    clip: str,
    frame: int,
    pass_: str = "clean",
    root: str | os.PathLike[str] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None]:
    """Frames ``frame`` and ``frame + 1`` of an MPI-Sintel training clip, with ground truth.

    Parameters
    ----------
    clip : str
        Clip name, e.g. ``"alley_1"``.
    frame : int
        Frame number N (1-based, as in the file names ``frame_NNNN.png``).
    pass_ : {"clean", "final"}
        Rendering pass.
    root : path-like, optional
        Data folder; see :func:`data_root`.

    Returns
    -------
    frame0, frame1 : ndarray, shape (H, W, 3), uint8
    flow : ndarray, shape (H, W, 2), float32
        Ground truth from frame N to N + 1 (NaN where unknown).
    occlusion : ndarray of bool, shape (H, W), or None
        True where occluded; None when the clip has no occlusion mask for N.
    invalid : ndarray of bool, shape (H, W), or None
        True where the ground truth is invalid; None when there is no mask.

    Raises
    ------
    ValueError
        Unknown pass or negative frame number.
    FileNotFoundError
        A frame or the flow file is missing.
    """
    from ..io.flo import read_flo
    from ..io.images import read_image

    if pass_ not in SINTEL_PASSES:
        raise ValueError(f"pass_: expected one of {SINTEL_PASSES}, got {pass_!r}")
    frame = int(frame)
    if frame < 0:
        raise ValueError(f"frame: must be >= 0, got {frame}")
    base = data_root(root)
    tr = base / "sintel" / "training"
    n0, n1 = f"frame_{frame:04d}", f"frame_{frame + 1:04d}"
    what = f"Sintel {pass_}/{clip}"
    f0 = to_rgb(read_image(require_file(tr / pass_ / clip / f"{n0}.png", f"{what} {n0}", base)))
    f1 = to_rgb(read_image(require_file(tr / pass_ / clip / f"{n1}.png", f"{what} {n1}", base)))
    gt = nan_unknown(read_flo(require_file(tr / "flow" / clip / f"{n0}.flo", f"{what} flow", base)))
    occ = read_mask(tr / "occlusions" / clip / f"{n0}.png")
    inv = read_mask(tr / "invalid" / clip / f"{n0}.png")
    return f0, f1, gt, occ, inv


def sintel_pairs(
    root: str | os.PathLike[str] | None = None, pass_: str | None = None
) -> list[tuple[str, int, str]]:
    """The Sintel pairs present under the data folder.

    Parameters
    ----------
    root : path-like, optional
    pass_ : {"clean", "final"}, optional
        Restrict to one pass.

    Returns
    -------
    list of (clip, frame, pass)
        Pairs for which both frames and the ground-truth flow exist, sorted.
    """
    tr = data_root(root) / "sintel" / "training"
    out = []
    for p in SINTEL_PASSES if pass_ is None else (pass_,):
        for flo in sorted((tr / "flow").glob("*/frame_*.flo")):
            clip, n = flo.parent.name, int(flo.stem.split("_")[1])
            d = tr / p / clip
            if (d / f"frame_{n:04d}.png").is_file() and (d / f"frame_{n + 1:04d}.png").is_file():
                out.append((clip, n, p))
    return sorted(out)
