"""Expanding the inputs of ``varflow batch`` and probing them.

An input argument is one of

* a **video file** (an extension in :data:`varflow.io.video.VIDEO_EXTENSIONS`);
  its name is the file name without the extension (``clips/a.mp4`` -> ``a``);
* a **frame folder** (a directory of still images, read in natural order by
  :func:`varflow.io.video.list_frame_files`); its name is the folder name;
* a **folder of videos** (a directory without still images but with video files):
  each video in it (natural order, not recursive) is an input;
* a **glob pattern** (``clips/*.mp4``, ``shots/*/``, ``**`` allowed) that is not an
  existing path: every match that is a video or a directory becomes an input
  (other matches are skipped); a pattern without any usable match is an error;
* an **input list**: a text file ending in ``.txt``, ``.lst``, ``.list`` or
  ``.jsonl`` with one entry per line -- a path or glob, or a JSON object
  ``{"path": "...", "name": "..."}`` (``name`` optional).  Relative paths are taken
  relative to the list's folder; blank lines and lines starting with ``#`` are
  skipped.  Lists do not nest.

The same file given twice (e.g. by a glob and by name) counts once.  Two
different inputs with the same name are an error: the outputs ``OUT/<name>/``
would collide.  Rename one of them, or give explicit names in an input list.
A missing path or a single image file is an error too.  All these errors are
raised before any work starts; an input that exists but cannot be decoded is
reported later by :func:`probe_input` and recorded as failed by the runner.
"""

from __future__ import annotations

import glob
import hashlib
import json
import logging
import os
from dataclasses import dataclass
from pathlib import Path

from ..io.codecs import VIDEO_EXTENSIONS
from ..io.probe import video_info
from ..io.sequences import (
    IMAGE_EXTENSIONS,
    list_frame_files,
    missing_input_error,
    natural_key,
    no_frames_message,
    not_a_sequence_message,
    single_image_message,
    too_few_frames_message,
)

__all__ = ["BatchInput", "InputProbe", "LIST_EXTENSIONS", "expand_inputs", "probe_input"]

log = logging.getLogger(__name__)

#: Extensions of input-list files (lower case, with the dot).
LIST_EXTENSIONS: frozenset[str] = frozenset({".txt", ".lst", ".list", ".jsonl"})

_RESERVED = ("manifest.sqlite", "manifest.lock")


@dataclass(frozen=True)
class BatchInput:
    """One input of a batch run.

    Attributes
    ----------
    path : Path
        Absolute path of the video file or frame folder.
    name : str
        Output name: results go to ``OUT/<name>/``.
    kind : str
        ``"video"`` or ``"folder"``.
    """

    path: Path
    name: str
    kind: str


@dataclass(frozen=True)
class InputProbe:
    """What the driver needs to know about an input before planning its tasks.

    Attributes
    ----------
    n_frames : int
        Number of frames.
    files : tuple of str, optional
        The frame files of a folder, in order (None for a video).
    fingerprint : str
        Changes when the input's files change (size and modification time).
    """

    n_frames: int
    files: tuple[str, ...] | None
    fingerprint: str


def _has_magic(text: str) -> bool:
    return any(c in text for c in "*?[")


def _check_name(name: str, origin: str) -> str:
    bad = (
        not name
        or name in (".", "..")
        or name.startswith(".")
        or "/" in name
        or "\\" in name
        or "\x00" in name
        or name.endswith(".zarr")
        or name in _RESERVED
    )
    if bad:
        raise ValueError(
            f"{origin}: {name!r} cannot be an output name (no path separators, no leading "
            "dot, no .zarr ending)"
        )
    return name


def _videos_in(directory: Path) -> list[Path]:
    """The video files directly inside a folder that holds no still images."""
    if list_frame_files(directory):
        return []
    exts = VIDEO_EXTENSIONS
    videos = [p for p in directory.iterdir()
              if not p.name.startswith(".") and p.suffix.lower() in exts and p.is_file()]
    return [Path(p) for p in _natural([str(v) for v in videos])]


def _classify(path: Path, origin: str, name: str | None, strict: bool) -> list[BatchInput]:
    """The inputs a path stands for ([] for a skipped glob match when ``strict=False``)."""
    if path.is_dir():
        videos = _videos_in(path)
        if videos:  # a folder of videos, not of frames
            if name is not None:
                raise ValueError(f"{origin}: a name is given but {path} holds "
                                 f"{len(videos)} videos")
            return [BatchInput(v.absolute(), _check_name(v.stem, origin), "video")
                    for v in videos]
        return [BatchInput(path.absolute(), _check_name(name or path.absolute().name, origin),
                           "folder")]
    suffix = path.suffix.lower()
    if path.is_file() and suffix in VIDEO_EXTENSIONS:
        return [BatchInput(path.absolute(), _check_name(name or path.stem, origin), "video")]
    if not strict:
        log.info("%s: skipping %s (neither a video nor a folder)", origin, path)
        return []
    if suffix in IMAGE_EXTENSIONS:
        raise ValueError(_at(origin, path, single_image_message(path)))
    lists = sorted(LIST_EXTENSIONS)
    raise ValueError(_at(origin, path, f"{not_a_sequence_message(path)}; input lists end in "
                         f"{', '.join(lists[:-1])} or {lists[-1]}"))


def _at(origin: str, path: Path, message: str) -> str:
    """``message`` (which names ``path``), after ``origin`` when that is not the path
    itself (an entry of an input list: ``list.txt:3``)."""
    return message if Path(os.path.expanduser(origin)) == path else f"{origin}: {message}"


def _natural(paths: list[str]) -> list[str]:
    return sorted(paths, key=natural_key)


def _expand_one(
    text: str, base: Path | None, name: str | None, origin: str, allow_list: bool
) -> list[BatchInput]:
    raw = os.path.expanduser(text)
    path = Path(raw) if base is None or os.path.isabs(raw) else base / raw
    if not path.exists() and _has_magic(raw):
        matches = _natural(glob.glob(str(path), recursive=True))
        found = [inp for m in matches for inp in _classify(Path(m), origin, None, False)]
        if not found:
            raise FileNotFoundError(2, f"{origin}: no video or folder matches", str(path))
        if name is not None and len(found) > 1:
            raise ValueError(f"{origin}: a name is given but {text!r} matches {len(found)} inputs")
        if name is not None:
            found = [BatchInput(found[0].path, _check_name(name, origin), found[0].kind)]
        return found
    if not path.exists():
        raise missing_input_error(path, None if base is None else origin)
    if allow_list and path.is_file() and path.suffix.lower() in LIST_EXTENSIONS:
        if name is not None:
            raise ValueError(f"{origin}: an input list cannot be given a name")
        return _read_list(path)
    return _classify(path, origin, name, True)


def _read_list(path: Path) -> list[BatchInput]:
    out: list[BatchInput] = []
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except UnicodeDecodeError as exc:
        raise ValueError(f"{path}: an input list must be UTF-8 text ({exc.reason})") from exc
    for k, line in enumerate(lines, 1):
        text = line.strip()
        if not text or text.startswith("#"):
            continue
        origin = f"{path}:{k}"
        name = None
        if text.startswith("{"):
            try:
                entry = json.loads(text)
            except json.JSONDecodeError as exc:
                raise ValueError(f"{origin}: invalid JSON ({exc.msg})") from exc
            if not isinstance(entry.get("path"), str) or not entry["path"]:
                raise ValueError(f"{origin}: a JSON entry needs a \"path\" string")
            unknown = set(entry) - {"path", "name"}
            if unknown:
                raise ValueError(f"{origin}: unknown key(s) {', '.join(sorted(unknown))}")
            name = entry.get("name")
            if name is not None and not isinstance(name, str):
                raise ValueError(f"{origin}: \"name\" must be a string")
            text = entry["path"]
        out.extend(_expand_one(text, path.parent, name, origin, allow_list=False))
    if not out:
        raise ValueError(f"{path}: the input list is empty")
    return out


def expand_inputs(args: list[str]) -> list[BatchInput]:
    """Expand the command-line inputs into videos and frame folders.

    Parameters
    ----------
    args : list of str
        Video files, frame folders, glob patterns or input lists (see the module
        documentation).

    Returns
    -------
    list of BatchInput
        In the order given (glob matches in natural order), each file once.

    Raises
    ------
    FileNotFoundError
        A path that does not exist, or a glob without a usable match.
    ValueError
        A single image, an unknown file type, a bad input list, an invalid name, or
        two inputs with the same name.
    """
    if not args:
        raise ValueError("give at least one input")
    seen: dict[Path, BatchInput] = {}
    for arg in args:
        for inp in _expand_one(arg, None, None, arg, allow_list=True):
            key = Path(os.path.realpath(inp.path))
            if key not in seen:
                seen[key] = inp
    by_name: dict[str, BatchInput] = {}
    for inp in seen.values():
        other = by_name.get(inp.name)
        if other is not None:
            raise ValueError(
                f"two inputs are named {inp.name!r}: {other.path} and {inp.path}; rename "
                "one, or name them in an input list (one JSON object per line: "
                '{"path": ..., "name": ...})'
            )
        by_name[inp.name] = inp
    return list(by_name.values())


def _stat_key(path: Path) -> str:
    st = path.stat()
    return f"{path.name}\t{st.st_size}\t{st.st_mtime_ns}"


def probe_input(inp: BatchInput) -> InputProbe:
    """Count an input's frames and fingerprint its files.

    Parameters
    ----------
    inp : BatchInput

    Returns
    -------
    InputProbe

    Raises
    ------
    ValueError, OSError
        When the video cannot be opened, or the input has fewer than 2 frames (the
        messages of :func:`varflow.io.sequences.no_frames_message` and
        :func:`varflow.io.sequences.too_few_frames_message`).
    """
    if inp.kind == "folder":
        files = list_frame_files(inp.path)
        if not files:
            raise ValueError(no_frames_message(inp.path))
        if len(files) < 2:
            raise ValueError(too_few_frames_message(inp.path, len(files)))
        digest = hashlib.sha256("\n".join(_stat_key(f) for f in files).encode()).hexdigest()
        return InputProbe(len(files), tuple(str(f) for f in files), digest)
    n_frames = int(video_info(inp.path).n_frames)
    if n_frames < 2:
        raise ValueError(too_few_frames_message(inp.path, n_frames))
    return InputProbe(n_frames, None, hashlib.sha256(_stat_key(inp.path).encode()).hexdigest())
