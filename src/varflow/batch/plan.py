"""Planning a batch run: pairs, windows, output names and the task list of an input.

Flow (``varflow batch flow``)
    With ``--stride S`` (default 1) an input of ``N`` frames gives the pairs
    ``(n, n + S)`` for ``n = 0 .. N - 1 - S``; the flow from frame ``n`` to frame
    ``n + S`` is written to ``OUT/<name>/nnnnnn.flo`` (``n`` zero-based, six
    digits; ``.png`` with ``--format png``).  With ``--pairs FILE`` the pairs are
    read from a text file (one ``I J`` per line, whitespace or comma separated,
    zero-based; ``#`` comments) and applied to every input; since two listed pairs
    may start at the same frame, their outputs are named ``iiiiii_jjjjjj.flo``.  A
    listed pair outside an input's frames is a failed task of that input.

Trajectories (``varflow batch track``)
    Windows of ``F`` frames overlapping by ``K`` frames start at ``0, F - K,
    2 (F - K), ...`` as long as they fit; when frames remain after the last one, a
    final window ``[N - F, N)`` is added (it overlaps its neighbour by more than
    ``K``), so that every frame is covered.  An input shorter than ``F`` frames gives
    one window of all its frames.  Each window's trajectories (reference = the
    window's centre frame, :func:`varflow.multiframe.track.default_ref`) go to
    ``OUT/<name>/window_ssssss.npz`` with ``s`` the window's first frame.

Retiming (``varflow batch retime``)
    One task per input: the whole video (or frame folder) retimed with
    :func:`varflow.retime.stream.retime_video` (``--fps F`` or ``--slowmo K``) to
    ``OUT/<name>.<format>`` (``mkv`` by default: lossless FFV1).

Denoising (``varflow batch denoise``)
    One task per input: the whole video (or frame folder) denoised with
    :func:`varflow.restore.video.denoise_video` (σ given on the 0-255 scale, or
    estimated per input) to ``OUT/<name>.<format>`` (``mkv`` by default: lossless
    FFV1; lossless in the other containers where they allow it), audio copied.

Restoration (``varflow batch restore``)
    The same, through :func:`varflow.restore.video.restore_video`: the stages of a
    :class:`varflow.restore.chain.ChainParams` (its ``params``; ``method`` names the
    stages, e.g. ``"deflicker+dirt"``).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

__all__ = [
    "BatchConfig",
    "Task",
    "flow_pairs",
    "plan_tasks",
    "read_pairs_file",
    "track_windows",
]

#: Output formats of ``varflow batch flow``.
FLOW_FORMATS = ("flo", "png")
#: Output formats (video containers) of ``varflow batch retime``.
RETIME_FORMATS = ("mkv", "mp4", "mov", "avi", "webm", "m4v")
#: Output formats (video containers) of ``varflow batch denoise`` and ``restore``.
DENOISE_FORMATS = RETIME_FORMATS
#: The kinds whose task is one whole video per input.
VIDEO_KINDS = ("retime", "denoise", "restore")


@dataclass(frozen=True)
class BatchConfig:
    """The settings of a batch run that determine its outputs.

    Attributes
    ----------
    kind : str
        ``"flow"``, ``"track"``, ``"retime"``, ``"denoise"`` or ``"restore"``.
    method : str
        Registered two-frame method (flow), trajectory method (track),
        interpolation method (retime), restoration method (denoise), or the stages
        joined by ``+`` (restore).
    params : dataclass instance
        The method's parameters (restore: a
        :class:`~varflow.restore.chain.ChainParams`).
    fmt : str
        ``"flo"`` or ``"png"`` for flow; ``"npz"`` for track; a video extension of
        :data:`RETIME_FORMATS` for retime, of :data:`DENOISE_FORMATS` for denoise.
    stride : int
        Frame gap of the pairs (flow without ``pairs``).
    pairs : tuple of (int, int), optional
        Explicit pairs (flow).
    window, overlap : int, optional
        Window length and overlap in frames (track).
    fps : str, optional
        Output frame rate (retime), e.g. ``"60"`` or ``"24000/1001"``.
    slowmo : int, optional
        Slow-motion factor (retime; exactly one of ``fps`` and ``slowmo``).
    input_fps : str, optional
        Source rate of frame folders / override of the videos' rates (retime,
        denoise, restore).
    codec : str, optional
        Video encoder (retime: default after ``fmt``; denoise, restore: default
        lossless).
    sigma : float, optional
        Noise standard deviation on the 0-255 scale (denoise, restore; None:
        estimated per input).
    scene_cuts : bool
        Look across no scene cut (denoise, restore).
    """

    kind: str
    method: str
    params: Any
    fmt: str = "flo"
    stride: int = 1
    pairs: tuple[tuple[int, int], ...] | None = None
    window: int | None = None
    overlap: int | None = None
    fps: str | None = None
    slowmo: int | None = None
    input_fps: str | None = None
    codec: str | None = None
    sigma: float | None = None
    scene_cuts: bool = True

    def __post_init__(self) -> None:
        if self.kind == "flow":
            if self.fmt not in FLOW_FORMATS:
                raise ValueError(f"--format: expected one of {', '.join(FLOW_FORMATS)}")
            if self.pairs is None and (isinstance(self.stride, bool) or self.stride < 1):
                raise ValueError(f"--stride: must be >= 1, got {self.stride}")
        elif self.kind == "track":
            if self.window is None or self.window < 2:
                raise ValueError(f"--window: must be >= 2 frames, got {self.window}")
            if self.overlap is None or not 0 <= self.overlap < self.window:
                raise ValueError(
                    f"--overlap: must be in 0..{self.window - 1} (less than --window), got "
                    f"{self.overlap}"
                )
            if self.fmt != "npz":
                raise ValueError("track outputs are .npz files")
        elif self.kind == "retime":
            if self.fmt not in RETIME_FORMATS:
                raise ValueError(f"--format: expected one of {', '.join(RETIME_FORMATS)}")
            if (self.fps is None) == (self.slowmo is None):
                raise ValueError("give exactly one of --fps and --slowmo")
            if self.slowmo is not None and (isinstance(self.slowmo, bool) or self.slowmo < 2):
                raise ValueError(f"--slowmo: must be an integer >= 2, got {self.slowmo}")
        elif self.kind in ("denoise", "restore"):
            if self.fmt not in DENOISE_FORMATS:
                raise ValueError(f"--format: expected one of {', '.join(DENOISE_FORMATS)}")
            s = self.sigma
            if s is not None and (isinstance(s, bool) or not isinstance(s, int | float)
                                  or not math.isfinite(s) or s < 0):
                raise ValueError(f"--sigma: must be a finite number >= 0, got {s!r}")
        else:
            raise ValueError(f"unknown batch kind {self.kind!r}")

    @property
    def params_json(self) -> str:
        """The parameters as canonical JSON (sorted keys)."""
        return json.dumps(dataclasses.asdict(self.params), sort_keys=True, default=str)

    def identity(self, version: str) -> dict[str, Any]:
        """Everything that must be equal for two runs to share an output folder."""
        ident: dict[str, Any] = {
            "kind": self.kind,
            "method": self.method,
            "params": json.loads(self.params_json),
            "version": version,
            "format": self.fmt,
        }
        if self.kind == "flow":
            if self.pairs is not None:
                ident["pairs"] = [list(p) for p in self.pairs]
            else:
                ident["stride"] = self.stride
        elif self.kind == "retime":
            ident.update({"fps": self.fps, "slowmo": self.slowmo, "input_fps": self.input_fps,
                          "codec": self.codec})
        elif self.kind in ("denoise", "restore"):
            ident.update({"sigma": self.sigma, "input_fps": self.input_fps,
                          "codec": self.codec, "scene_cuts": self.scene_cuts})
        else:
            ident["window"] = self.window
            ident["overlap"] = self.overlap
        return ident

    def fingerprint(self, version: str) -> str:
        """SHA-256 of what decides the numbers: method, resolved parameters, version.

        The canonical JSON (sorted keys) of ``{"method", "params", "version"}`` with
        ``params`` every field of the resolved parameter dataclass
        (:func:`dataclasses.asdict`).  Recorded in the manifest's ``meta`` table as
        ``fingerprint``; a resume with another fingerprint is refused.
        """
        text = json.dumps({"method": self.method, "params": json.loads(self.params_json),
                           "version": version}, sort_keys=True)
        return hashlib.sha256(text.encode()).hexdigest()

    def identity_hash(self, version: str) -> str:
        """SHA-256 of :meth:`identity` (the "params hash" of the manifest's meta table)."""
        text = json.dumps(self.identity(version), sort_keys=True)
        return hashlib.sha256(text.encode()).hexdigest()


@dataclass(frozen=True)
class Task:
    """One unit of work: a pair or a window of one input.

    Attributes
    ----------
    task_id : str
        ``"<name>/<output file name>"``.
    name : str
        The input's output name.
    frames : tuple of int
        ``(i, j)`` for a pair (flow from frame i to frame j), the window's frame
        indices for track, the first and last frame for retime, denoise and restore.
    output : str
        Output path relative to the output folder (``/``-separated).
    index : int
        Position among the input's tasks (row of its Zarr array).
    problem : str, optional
        Why the task cannot run (a listed pair outside the input's frames).
    """

    task_id: str
    name: str
    frames: tuple[int, ...]
    output: str
    index: int
    problem: str | None = None


def flow_pairs(n_frames: int, stride: int = 1) -> list[tuple[int, int]]:
    """The pairs ``(n, n + stride)`` of a sequence of ``n_frames`` frames.

    Parameters
    ----------
    n_frames : int
    stride : int
        ``>= 1``.

    Returns
    -------
    list of (int, int)
        Empty when ``n_frames <= stride``.
    """
    if stride < 1:
        raise ValueError(f"stride must be >= 1, got {stride}")
    return [(n, n + stride) for n in range(max(0, n_frames - stride))]


def track_windows(n_frames: int, window: int, overlap: int) -> list[tuple[int, int]]:
    """Windows ``(start, stop)`` covering ``n_frames`` frames (see the module notes).

    Parameters
    ----------
    n_frames : int
    window : int
        Frames per window, ``>= 2``.
    overlap : int
        Frames shared by consecutive windows, ``0 <= overlap < window``.

    Returns
    -------
    list of (int, int)
        Half-open frame ranges in increasing order; empty when ``n_frames < 2``.

    Examples
    --------
    >>> track_windows(10, 4, 1)
    [(0, 4), (3, 7), (6, 10)]
    >>> track_windows(11, 4, 1)
    [(0, 4), (3, 7), (6, 10), (7, 11)]
    >>> track_windows(3, 5, 2)
    [(0, 3)]
    """
    if window < 2:
        raise ValueError(f"window must be >= 2, got {window}")
    if not 0 <= overlap < window:
        raise ValueError(f"overlap must be in 0..{window - 1}, got {overlap}")
    if n_frames < 2:
        return []
    if n_frames <= window:
        return [(0, n_frames)]
    step = window - overlap
    out = [(s, s + window) for s in range(0, n_frames - window + 1, step)]
    if out[-1][1] < n_frames:
        out.append((n_frames - window, n_frames))
    return out


def read_pairs_file(path: str | os.PathLike[str]) -> tuple[tuple[int, int], ...]:
    """Read a ``--pairs`` file: one ``I J`` per line (zero-based frame indices).

    Parameters
    ----------
    path : str or path-like
        Text file; items separated by whitespace or a comma; blank lines and lines
        starting with ``#`` are ignored.

    Returns
    -------
    tuple of (int, int)
        In file order.

    Raises
    ------
    FileNotFoundError
        If the file does not exist.
    ValueError
        On a malformed line, a negative index, ``I == J``, a repeated pair or an
        empty file (the message names the line).
    """
    p = Path(os.fspath(path))
    if not p.is_file():
        raise FileNotFoundError(2, "--pairs: file not found", str(p))
    pairs: list[tuple[int, int]] = []
    seen: set[tuple[int, int]] = set()
    for k, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1):
        text = line.split("#", 1)[0].replace(",", " ").split()
        if not text:
            continue
        where = f"--pairs {p}:{k}"
        if len(text) != 2:
            raise ValueError(f"{where}: expected two frame indices 'I J', got {line.strip()!r}")
        try:
            i, j = int(text[0]), int(text[1])
        except ValueError:
            raise ValueError(
                f"{where}: frame indices must be integers, got {line.strip()!r}"
            ) from None
        if i < 0 or j < 0 or i == j:
            raise ValueError(f"{where}: need two different indices >= 0, got {i} {j}")
        if (i, j) in seen:
            raise ValueError(f"{where}: the pair {i} {j} is listed twice")
        seen.add((i, j))
        pairs.append((i, j))
    if not pairs:
        raise ValueError(f"--pairs {p}: no pairs in the file")
    return tuple(pairs)


def plan_tasks(name: str, n_frames: int, config: BatchConfig) -> list[Task]:
    """The tasks of one input.

    Parameters
    ----------
    name : str
        The input's output name.
    n_frames : int
        Its number of frames.
    config : BatchConfig

    Returns
    -------
    list of Task

    Raises
    ------
    ValueError
        When the input is too short to give any task.
    """
    tasks: list[Task] = []
    if config.kind in VIDEO_KINDS:
        if config.kind == "retime" and n_frames < 2:
            raise ValueError(f"only {n_frames} frame(s): retiming needs at least 2")
        if n_frames < 1:
            raise ValueError("no frames")
        file = f"{name}.{config.fmt}"
        return [Task(f"{name}/{file}", name, (0, n_frames - 1), file, 0)]
    if config.kind == "flow":
        if config.pairs is not None:
            for k, (i, j) in enumerate(config.pairs):
                file = f"{i:06d}_{j:06d}.{config.fmt}"
                problem = None
                if max(i, j) >= n_frames:
                    problem = (f"pair {i} {j} is outside the input's {n_frames} frames "
                               f"(0..{n_frames - 1})")
                tasks.append(Task(f"{name}/{file}", name, (i, j), f"{name}/{file}", k, problem))
            return tasks
        for k, (i, j) in enumerate(flow_pairs(n_frames, config.stride)):
            file = f"{i:06d}.{config.fmt}"
            tasks.append(Task(f"{name}/{file}", name, (i, j), f"{name}/{file}", k))
        if not tasks:
            raise ValueError(
                f"only {n_frames} frame(s): stride {config.stride} needs at least "
                f"{config.stride + 1}"
            )
        return tasks
    assert config.window is not None and config.overlap is not None
    for k, (s, e) in enumerate(track_windows(n_frames, config.window, config.overlap)):
        file = f"window_{s:06d}.npz"
        tasks.append(Task(f"{name}/{file}", name, tuple(range(s, e)), f"{name}/{file}", k))
    if not tasks:
        raise ValueError(f"only {n_frames} frame(s): a window needs at least 2")
    return tasks
