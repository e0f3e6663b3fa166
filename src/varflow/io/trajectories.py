"""Reading and writing dense multi-frame trajectories (compressed ``.npz``).

A trajectory file stores the displacement of every pixel of the reference frame in
every frame of a clip, plus the information needed to interpret it:

========================  ==========================================================
key                       content
========================  ==========================================================
``"trajectories"``        float32, shape ``(F, H, W, 2)``: ``[n, y, x]`` is the
                          displacement ``(u, v)`` of reference pixel ``(x, y)`` in
                          frame ``n`` (u horizontal, v vertical, NaN = unknown)
``"ref"``                 int64 scalar: index of the reference frame
``"visibility"``          bool, shape ``(F, H, W)``, optional: pixel visible in frame
                          ``n``
``"metadata"``            str scalar: a JSON object (method, parameters, frame
                          paths, ... whatever the writer was given)
========================  ==========================================================

The file is an ordinary NumPy archive (``np.load(path)`` opens it; no pickled
objects are stored) written atomically through :func:`varflow.io._atomic.atomic_write`.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import math
import numbers
import os
import zipfile
import zlib
from collections.abc import Mapping
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from ._atomic import atomic_write

__all__ = ["TrajectoryFile", "TrajectoryFormatError", "read_trajectories", "write_trajectories"]

logger = logging.getLogger(__name__)

_TRAJ_KEY = "trajectories"
_REF_KEY = "ref"
_VIS_KEY = "visibility"
_META_KEY = "metadata"
_KNOWN_KEYS = frozenset({_TRAJ_KEY, _REF_KEY, _VIS_KEY, _META_KEY})


class TrajectoryFile(NamedTuple):
    """Content of a trajectory file (unpacks as ``traj, ref, visibility, metadata``)."""

    #: float32, shape (F, H, W, 2); NaN where unknown.
    trajectories: np.ndarray
    #: Index of the reference frame, ``0 <= ref < F``.
    ref: int
    #: bool, shape (F, H, W), or None if the file has no visibility.
    visibility: np.ndarray | None
    #: The metadata dictionary given to :func:`write_trajectories` (``{}`` if none).
    metadata: dict[str, Any]


def _json_default(obj: Any) -> Any:
    """Make common non-JSON types serialisable (NumPy values, paths, dataclasses)."""
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return dataclasses.asdict(obj)
    if isinstance(obj, set | frozenset):
        return sorted(obj, key=repr)
    raise TypeError(f"object of type {type(obj).__name__} is not JSON serialisable")


def _check_trajectories(traj: np.ndarray, name: str = "traj") -> np.ndarray:
    arr = np.asarray(traj)
    if arr.ndim != 4 or arr.shape[3] != 2 or min(arr.shape[:3], default=0) < 1:
        raise ValueError(
            f"write_trajectories: {name} must have shape (F, H, W, 2) with F, H, W >= 1, "
            f"got {arr.shape}"
        )
    if arr.dtype == np.bool_ or not (
        np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)
    ):
        raise ValueError(
            f"write_trajectories: {name} must be a real-valued (float) array, got dtype {arr.dtype}"
        )
    with np.errstate(over="ignore"):  # float64 beyond float32 range -> inf
        return np.ascontiguousarray(arr, dtype=np.float32)


def _check_ref(ref: Any, n_frames: int) -> int:
    if isinstance(ref, bool) or not isinstance(ref, numbers.Integral):
        raise ValueError(f"write_trajectories: ref must be an integer, got {ref!r}")
    if not 0 <= int(ref) < n_frames:
        raise ValueError(f"write_trajectories: ref must be in 0..{n_frames - 1}, got {ref}")
    return int(ref)


def _check_visibility(visibility: Any, shape: tuple[int, ...]) -> np.ndarray:
    vis = np.asarray(visibility)
    if vis.shape != shape:
        raise ValueError(
            f"write_trajectories: visibility must have shape (F, H, W) = {shape}, got {vis.shape}"
        )
    if vis.dtype != np.bool_:
        if not np.issubdtype(vis.dtype, np.integer) or not np.isin(vis, (0, 1)).all():
            raise ValueError(
                "write_trajectories: visibility must be a boolean array (or integers 0/1), "
                f"got dtype {vis.dtype}"
            )
    return np.ascontiguousarray(vis, dtype=np.bool_)


def write_trajectories(
    path: str | os.PathLike[str],
    traj: np.ndarray,
    *,
    ref: int,
    visibility: np.ndarray | None = None,
    metadata: Mapping[str, Any] | None = None,
) -> None:
    """Write dense trajectories to a compressed ``.npz`` file, atomically.

    Parameters
    ----------
    path : str or path-like
        Target file; must end in ``.npz``.  Its directory must exist.
    traj : ndarray, shape (F, H, W, 2), real dtype
        Displacement of every reference-frame pixel in every frame, u = ``[..., 0]``
        (horizontal), v = ``[..., 1]`` (vertical); NaN where unknown.  Stored as
        float32 (float64 values beyond the float32 range become ±inf).
        ``traj[ref]`` is stored as given (it need not be zero).
    ref : int
        Index of the reference frame, ``0 <= ref < F``.
    visibility : ndarray, shape (F, H, W), bool, optional
        Visibility of each reference pixel in each frame (integer 0/1 accepted).
    metadata : mapping, optional
        Free-form information (method name, parameters, frame paths, ...), stored
        as a JSON string.  NumPy scalars and arrays, paths, sets and dataclass
        instances are converted; keys become strings (JSON objects only have
        string keys).

    Raises
    ------
    ValueError
        If ``path`` does not end in ``.npz``, or ``traj``, ``ref``, ``visibility``
        or ``metadata`` is invalid (the message names the argument).
    FileNotFoundError
        If the target directory does not exist.

    Notes
    -----
    The archive is written to a temporary file next to ``path`` and renamed onto
    it only when complete: on any error the target keeps its previous content.
    """
    path = Path(os.fspath(path))
    if path.suffix.lower() != ".npz":
        raise ValueError(f"write_trajectories: path must end in .npz, got {str(path)!r}")
    data = _check_trajectories(traj)
    n_frames, height, width = data.shape[:3]
    arrays: dict[str, np.ndarray] = {
        _TRAJ_KEY: data,
        _REF_KEY: np.array(_check_ref(ref, n_frames), dtype=np.int64),
    }
    if visibility is not None:
        arrays[_VIS_KEY] = _check_visibility(visibility, (n_frames, height, width))
    if metadata is None:
        metadata = {}
    if not isinstance(metadata, Mapping):
        raise ValueError(
            f"write_trajectories: metadata must be a dict, got {type(metadata).__name__}"
        )
    try:
        text = json.dumps(dict(metadata), default=_json_default, sort_keys=False)
    except (TypeError, ValueError) as exc:  # ValueError: circular reference
        raise ValueError(f"write_trajectories: metadata is not JSON serialisable ({exc})") from exc
    arrays[_META_KEY] = np.array(text, dtype=np.str_)

    with atomic_write(path, "wb") as f:
        np.savez_compressed(f, **arrays)
    logger.debug(
        "wrote %s: %d frames of %d x %d, ref %d%s",
        path,
        n_frames,
        width,
        height,
        ref,
        ", with visibility" if visibility is not None else "",
    )


class TrajectoryFormatError(ValueError):
    """A trajectory file is corrupted or not in the expected format."""


#: Largest expansion of a deflate stream (RFC 1951: 258 bytes per 2-bit code is the
#: bound in practice, about 1032:1); a member cannot hold more data than this.
_DEFLATE_MAX_RATIO = 1032


def _one_line(text: str) -> str:
    return " ".join(text.split())


def _bad(path: Path, reason: str) -> TrajectoryFormatError:
    return TrajectoryFormatError(
        f"{path}: not a valid varflow trajectory file ({_one_line(reason)})"
    )


def _member_limit(info: zipfile.ZipInfo, file_size: int) -> int:
    """Upper bound on the bytes a zip member can really decompress to."""
    stored = min(info.compress_size, file_size)
    if info.compress_type == zipfile.ZIP_STORED:
        return min(info.file_size, stored)
    return min(info.file_size, stored * _DEFLATE_MAX_RATIO + 1024)


def _read_member(zf: zipfile.ZipFile, info: zipfile.ZipInfo, key: str, path: Path,
                 file_size: int) -> np.ndarray:
    """Read one ``.npy`` member; refuse a header whose shape the data cannot hold.

    The shape in an ``.npy`` header is checked against what the member can contain
    *before* anything is allocated, so that a damaged or hostile header declaring
    ``10**9 x 10**9`` elements fails at once instead of asking for exabytes.
    """
    with zf.open(info) as fh:
        version = np.lib.format.read_magic(fh)
        if version == (1, 0):
            shape, _, dtype = np.lib.format.read_array_header_1_0(fh)
        elif version == (2, 0):
            shape, _, dtype = np.lib.format.read_array_header_2_0(fh)
        else:
            raise _bad(path, f"{key!r}: unsupported .npy format version {version}")
    if dtype.hasobject:
        raise _bad(path, f"{key!r} holds Python objects (pickled data is not read)")
    nbytes = math.prod(shape) * dtype.itemsize
    limit = _member_limit(info, file_size)
    if nbytes > limit:
        raise _bad(path, f"{key!r} declares shape {shape} of {dtype} ({nbytes} bytes), "
                         f"but its archive member can hold at most {limit} bytes")
    with zf.open(info) as fh:
        return np.lib.format.read_array(fh, allow_pickle=False)


def _read_archive(path: Path) -> dict[str, np.ndarray]:
    """The arrays of the trajectory keys in the ``.npz`` archive at ``path``."""
    with open(path, "rb") as f:
        magic = f.read(len(np.lib.format.MAGIC_PREFIX))
        file_size = os.fstat(f.fileno()).st_size
        if magic == np.lib.format.MAGIC_PREFIX:
            raise _bad(path, "a single .npy array, not an .npz archive")
        if not zipfile.is_zipfile(f):
            raise _bad(path, "not a NumPy .npz archive (no zip directory found)")
        with zipfile.ZipFile(f) as zf:
            members = {(i.filename[:-4] if i.filename.endswith(".npy") else i.filename): i
                       for i in zf.infolist()}
            keys = set(members)
            missing = sorted({_TRAJ_KEY, _REF_KEY} - keys)
            if missing:
                raise _bad(path, f"missing key(s) {missing}; found {sorted(keys)}")
            extra = sorted(keys - _KNOWN_KEYS)
            if extra:
                logger.debug("%s: ignoring unknown keys %s", path, extra)
            return {key: _read_member(zf, members[key], key, path, file_size)
                    for key in sorted(_KNOWN_KEYS & keys)}


def read_trajectories(path: str | os.PathLike[str]) -> TrajectoryFile:
    """Read a trajectory file written by :func:`write_trajectories`.

    Parameters
    ----------
    path : str or path-like

    Returns
    -------
    TrajectoryFile
        Named tuple ``(trajectories, ref, visibility, metadata)``:
        ``trajectories`` float32 ``(F, H, W, 2)`` (NaN where unknown), ``ref`` int,
        ``visibility`` bool ``(F, H, W)`` or None, ``metadata`` dict (``{}`` if
        none was stored).

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    TrajectoryFormatError
        A :class:`ValueError`: the file is not a readable NumPy archive (truncated,
        corrupted at any level, pickled content, a plain ``.npy``, an array header
        declaring more data than the archive holds) or its content is not a
        trajectory file (missing keys, wrong shapes or dtypes, ``ref`` out of range,
        metadata that is not a JSON object).  The one-line message names the file.
        Nothing larger than the archive can really hold is ever allocated.
    """
    path = Path(os.fspath(path))
    if not path.exists():
        raise FileNotFoundError(2, "trajectory file not found", str(path))
    try:
        arrays = _read_archive(path)
    except TrajectoryFormatError:
        raise
    except FileNotFoundError:
        raise
    except Exception as exc:  # noqa: BLE001 - any failure of zipfile/zlib/NumPy on bad bytes
        name = "zlib.error" if isinstance(exc, zlib.error) else type(exc).__name__
        raise _bad(path, f"{name}: {exc}") from exc
    traj = arrays[_TRAJ_KEY]
    ref_arr = arrays[_REF_KEY]
    vis = arrays.get(_VIS_KEY)
    meta_arr = arrays.get(_META_KEY)

    if traj.ndim != 4 or traj.shape[3] != 2 or min(traj.shape[:3]) < 1:
        raise _bad(path, f"'trajectories' has shape {traj.shape}, expected (F, H, W, 2)")
    if not np.issubdtype(traj.dtype, np.floating):
        raise _bad(path, f"'trajectories' has dtype {traj.dtype}, expected float32")
    traj = np.ascontiguousarray(traj, dtype=np.float32)
    n_frames = traj.shape[0]

    if ref_arr.shape != () or not np.issubdtype(ref_arr.dtype, np.integer):
        raise _bad(path, f"'ref' must be an integer scalar, got {ref_arr.dtype} {ref_arr.shape}")
    ref = int(ref_arr)
    if not 0 <= ref < n_frames:
        raise _bad(path, f"'ref' = {ref} out of range 0..{n_frames - 1}")

    if vis is not None:
        if vis.shape != traj.shape[:3] or vis.dtype != np.bool_:
            raise _bad(
                path,
                f"'visibility' is {vis.dtype} {vis.shape}, expected bool {traj.shape[:3]}",
            )

    metadata: dict[str, Any] = {}
    if meta_arr is not None:
        if meta_arr.shape != () or meta_arr.dtype.kind != "U":
            raise _bad(path, f"'metadata' must be a string scalar, got {meta_arr.dtype}")
        try:
            loaded = json.loads(str(meta_arr))
        except (json.JSONDecodeError, RecursionError) as exc:  # RecursionError: deep nesting
            raise _bad(path, f"'metadata' is not valid JSON ({exc})") from exc
        if not isinstance(loaded, dict):
            raise _bad(path, f"'metadata' is a JSON {type(loaded).__name__}, expected an object")
        metadata = loaded

    logger.debug("read %s: %d frames of %s, ref %d", path, n_frames, traj.shape[1:3], ref)
    return TrajectoryFile(traj, ref, vis, metadata)
