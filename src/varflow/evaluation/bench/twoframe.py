"""A broader two-frame benchmark: photographic pairs, Middlebury and MPI-Sintel, with peers.

:func:`run_twoframe` runs registered two-frame methods (:data:`varflow.registry.
METHODS`, default ``tvl1``) and optional peers of other libraries
(:data:`varflow.evaluation.peers.PEERS`: OpenCV DeepFlow, DIS, DualTVL1 and
scikit-image TV-L1) on three sets:

``"photo"``
    The pairs of :func:`varflow.generators.photo_pairs.make_photo_pair` (real
    photographs under known motions of 3-15 px, exact flow and occlusion mask),
    per family, on the ``"tuning"`` seeds (0-2, for choosing defaults) and/or the
    disjoint ``"reporting"`` seeds (100-102, for the numbers one quotes).
``"middlebury"``
    The 8 Middlebury "other" sequences with public ground truth, frame10 ->
    frame11 (as :func:`varflow.evaluation.bench.middlebury.run_middlebury`); no occlusion masks.
``"sintel"``
    The MPI-Sintel training pairs of :data:`SINTEL_PAIRS` found under the data
    folder (the snippets of ``../shared/data``); each is marked ``small`` or
    ``large`` motion by its mean ground-truth motion (``large`` above
    :data:`LARGE_MOTION_PX` = 10 px).  The ``invalid`` mask is removed from the
    scored pixels when present.
``"large"``
    The large-motion pairs of :func:`varflow.generators.large_pairs.make_large_pair`
    (photographic objects moving 30-150 px over photographic backgrounds, 384 x
    512, exact flow and occlusion mask), on the same ``split`` seeds
    (tuning 0-3, reporting 100-103).
``"sintel-large"``
    The MPI-Sintel pairs with a mean motion above 10 px (:data:`SINTEL_LARGE_PAIRS`:
    market_5 final 2->3 and 9->10, cave_2 clean and final 2->3).

Without ``sets``, :data:`DEFAULT_SETS` (the first three) run.

Every (set, pair, method) is scored by the AEE over all pixels with ground truth
(``aee``; for the photo pairs also the occluded ones and those that leave the
frame), the AEE over the non-occluded ones where an occlusion mask exists
(``aee_noc``) and the wall time of the flow call (``seconds``; every method first
runs once, untimed, on a small synthetic pair so that Numba compilation is
excluded).  :func:`format_twoframe_table` prints one Markdown table per set (and
split): a line per pair, a group of columns per method, then the mean, the total
seconds and the ratios of every method to a baseline (DeepFlow when present, else
the first method).  :func:`write_twoframe_csv` writes the rows.
"""

from __future__ import annotations

import logging
import math
import os
import sys
import time
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ...generators.large_pairs import large_pair_cases, make_large_pair
from ...generators.photo_pairs import DEFAULT_SHAPE as PHOTO_SHAPE
from ...generators.photo_pairs import FAMILIES as PHOTO_FAMILIES
from ...generators.photo_pairs import SPLITS as PHOTO_SPLITS
from ...generators.photo_pairs import make_photo_pair, photo_pair_cases
from ...registry import get_method, make_params
from ..datasets import (
    DATA_HINT,
    MIDDLEBURY_SEQUENCES,
    data_root,
    load_middlebury_pair,
    load_sintel_pair,
)
from ..peers import PEERS, peer_status
from .common import _nanmean, _num, markdown_table, split_overrides, write_csv

__all__ = [
    "SETS",
    "DEFAULT_SETS",
    "SINTEL_LARGE_PAIRS",
    "large_set",
    "SPLIT_CHOICES",
    "SINTEL_PAIRS",
    "LARGE_MOTION_PX",
    "BASELINE_PEER",
    "TWOFRAME_CSV_FIELDS",
    "BenchPair",
    "check_twoframe_options",
    "resolve_peers",
    "photo_set",
    "middlebury_set",
    "sintel_set",
    "sintel_pairs_present",
    "check_twoframe_data",
    "run_twoframe",
    "format_twoframe_table",
    "write_twoframe_csv",
]

log = logging.getLogger(__name__)

#: The sets of :func:`run_twoframe`, in order.
SETS: tuple[str, ...] = ("photo", "middlebury", "sintel", "large", "sintel-large")

#: The sets run when none are named: the small-motion sets.
DEFAULT_SETS: tuple[str, ...] = ("photo", "middlebury", "sintel")

#: Values of ``split``: one split of the photo pairs or both.
SPLIT_CHOICES: tuple[str, ...] = ("tuning", "reporting", "both")

#: The MPI-Sintel training pairs with ground truth in the data folder: (clip, pass, N),
#: scored from frame N to N + 1.
SINTEL_PAIRS: tuple[tuple[str, str, int], ...] = (
    ("alley_1", "final", 1),
    ("alley_2", "clean", 2),
    ("bandage_1", "final", 35),
    ("cave_2", "clean", 2),
    ("cave_2", "final", 2),
    ("market_5", "clean", 2),
    ("market_5", "final", 9),
)

#: The large-motion MPI-Sintel pairs of the ``"sintel-large"`` set: (clip, pass, N).
SINTEL_LARGE_PAIRS: tuple[tuple[str, str, int], ...] = (
    ("market_5", "final", 2),
    ("market_5", "final", 9),
    ("cave_2", "clean", 2),
    ("cave_2", "final", 2),
)

#: A pair whose mean ground-truth motion exceeds this (px) is marked ``large``.
LARGE_MOTION_PX = 10.0

#: The ratios compare against this peer when it ran, else against the first method.
BASELINE_PEER = "deepflow"

#: Columns of :func:`write_twoframe_csv`, in order.
TWOFRAME_CSV_FIELDS: tuple[str, ...] = (
    "set", "split", "sequence", "family", "seed", "method", "kind", "aee", "aee_noc", "aae",
    "r1", "r3", "seconds", "mean_motion", "max_motion", "motion", "occluded",
)


@dataclass(frozen=True)
class BenchPair:
    """One pair of a set, with what it is scored on.

    Attributes
    ----------
    set : str
        One of :data:`SETS`.
    sequence : str
        Its label in the tables (``"affine/0"``, ``"Grove2"``, ``"cave_2 final 2->3"``).
    frame0, frame1 : ndarray, shape (H, W, 3)
        uint8 (Middlebury, Sintel) or float32 in [0, 1] (photo pairs).
    gt : ndarray, shape (H, W, 2), float32
        Ground-truth flow frame0 -> frame1 (NaN where unknown).
    mask : ndarray, shape (H, W), bool, or None
        Pixels scored (None: every pixel with a known ground truth).
    occlusion : ndarray, shape (H, W), bool, or None
        True where occluded (None: no mask; ``aee_noc`` is then None).
    split, family : str or None
        Of a photo pair.
    seed : int or None
        Of a photo pair.
    """

    set: str
    sequence: str
    frame0: np.ndarray
    frame1: np.ndarray
    gt: np.ndarray
    mask: np.ndarray | None = None
    occlusion: np.ndarray | None = None
    split: str | None = None
    family: str | None = None
    seed: int | None = None


# --------------------------------------------------------------------------- options


def _names(value: str | Sequence[str], what: str) -> list[str]:
    if isinstance(value, str):
        value = [v.strip() for v in value.split(",")]
    out = [str(v).strip() for v in value if str(v).strip()]
    if not out:
        raise ValueError(f"{what}: give at least one name")
    return out


def check_twoframe_options(
    sets: str | Sequence[str] = DEFAULT_SETS,
    split: str = "reporting",
    families: str | Sequence[str] = PHOTO_FAMILIES,
    photo_shape: tuple[int, int] = PHOTO_SHAPE,
) -> tuple[list[str], list[str], list[str], tuple[int, int]]:
    """Check the set, split, family and size options (before any work).

    Parameters
    ----------
    sets : str or sequence of str
        Some of :data:`SETS` (a comma-separated string is split).
    split : {"tuning", "reporting", "both"}
    families : str or sequence of str
        Some of :data:`varflow.generators.photo_pairs.FAMILIES`.
    photo_shape : (int, int)
        Size of the photo pairs, each side at least 32.

    Returns
    -------
    sets : list of str
        In :data:`SETS` order, without repetitions.
    splits : list of str
        ``["tuning"]``, ``["reporting"]`` or both.
    families : list of str
    photo_shape : (int, int)

    Raises
    ------
    ValueError
        Naming the bad option (``sets: ...``, ``split: ...``, ``families: ...``,
        ``photo_shape: ...``).
    """
    names = _names(sets, "sets")
    for s in names:
        if s not in SETS:
            raise ValueError(f"sets: unknown set {s!r}; expected some of {', '.join(SETS)}")
    if split not in SPLIT_CHOICES:
        raise ValueError(f"split: expected one of {', '.join(SPLIT_CHOICES)}, got {split!r}")
    splits = list(PHOTO_SPLITS) if split == "both" else [split]
    fams = _names(families, "families")
    for f in fams:
        if f not in PHOTO_FAMILIES:
            raise ValueError(
                f"families: unknown family {f!r}; expected some of {', '.join(PHOTO_FAMILIES)}"
            )
    try:
        h, w = (int(v) for v in photo_shape)
    except (TypeError, ValueError):
        raise ValueError(f"photo_shape: expected (H, W), got {photo_shape!r}") from None
    if min(h, w) < 32:
        raise ValueError(f"photo_shape: each side must be at least 32, got {h}x{w}")
    return [s for s in SETS if s in names], splits, list(dict.fromkeys(fams)), (h, w)


def resolve_peers(peers: str | Sequence[str] | None) -> tuple[list[str], dict[str, str]]:
    """Which of the requested peers can run.

    Parameters
    ----------
    peers : str, sequence of str or None
        Names from :data:`~varflow.evaluation.peers.PEERS`, ``"all"`` or ``"none"``
        (a comma-separated string is split); None or empty: no peer.

    Returns
    -------
    runnable : list of str
        The requested peers whose backend is installed, in :data:`PEERS` order.
    unavailable : dict
        Requested peer -> reason it cannot run (missing OpenCV contrib or
        scikit-image, with the install hint).

    Raises
    ------
    ValueError
        ``peers: ...`` for an unknown name.
    """
    if peers is None:
        return [], {}
    names = [p.strip() for p in peers.split(",")] if isinstance(peers, str) else list(peers)
    names = [p for p in names if p]
    if names in (["none"], []):
        return [], {}
    if names == ["all"]:
        names = list(PEERS)
    for p in names:
        if p not in PEERS:
            raise ValueError(
                f"peers: unknown peer {p!r}; expected some of {', '.join(PEERS)}, all or none"
            )
    status = peer_status()
    wanted = [p for p in PEERS if p in names]
    return ([p for p in wanted if status[p] is None],
            {p: str(status[p]) for p in wanted if status[p] is not None})


# --------------------------------------------------------------------------- sets


def photo_set(
    splits: Sequence[str] = ("reporting",),
    families: Sequence[str] = PHOTO_FAMILIES,
    shape: tuple[int, int] = PHOTO_SHAPE,
) -> Iterator[BenchPair]:
    """The photographic pairs, generated lazily (split, then family, then seed).

    Parameters
    ----------
    splits : sequence of {"tuning", "reporting"}
    families : sequence of str
    shape : (int, int)

    Returns
    -------
    iterator of BenchPair
        ``mask`` None (the flow is known everywhere), ``occlusion`` = not visible
        in frame 1 (occluded or leaving the frame).
    """
    cases = [(split, f, s) for split in splits for f, s in photo_pair_cases(split, families)]
    for split, family, seed in cases:
        pair = make_photo_pair(family, seed, shape=shape)
        yield BenchPair("photo", pair.name, pair.frame0, pair.frame1, pair.flow,
                        None, pair.occlusion, split, family, seed)


def large_set(splits: Sequence[str] = ("reporting",)) -> Iterator[BenchPair]:
    """The large-motion pairs of :mod:`varflow.generators.large_pairs`, generated lazily.

    Parameters
    ----------
    splits : sequence of {"tuning", "reporting"}

    Returns
    -------
    iterator of BenchPair
        ``occlusion`` = not visible in frame 1 (occluded or leaving the frame).
    """
    for split in splits:
        for family, seed in large_pair_cases(split):
            pair = make_large_pair(family, seed)
            yield BenchPair("large", pair.name, pair.frame0, pair.frame1, pair.flow,
                            None, pair.occlusion, split, family, seed)


def middlebury_set(root: str | os.PathLike[str] | None = None) -> Iterator[BenchPair]:
    """The 8 Middlebury pairs frame10 -> frame11 (uint8 RGB; unknown ground truth NaN)."""
    base = data_root(root)
    for seq in MIDDLEBURY_SEQUENCES:
        f0, f1, gt = load_middlebury_pair(seq, base)
        yield BenchPair("middlebury", seq, f0, f1, gt)


def _sintel_label(clip: str, pass_: str, frame: int) -> str:
    return f"{clip} {pass_} {frame}->{frame + 1}"


def sintel_pairs_present(
    root: str | os.PathLike[str] | None = None,
    pairs: Sequence[tuple[str, str, int]] = SINTEL_PAIRS,
) -> tuple[list[tuple[str, str, int]], list[tuple[str, str, int]]]:
    """Split ``pairs`` (default :data:`SINTEL_PAIRS`) into those on disk and the rest.

    A pair is on disk when both frames and the flow are.

    Returns
    -------
    present, missing : list of (clip, pass, N)
    """
    tr = data_root(root) / "sintel" / "training"
    present, missing = [], []
    for clip, pass_, n in pairs:
        files = [tr / pass_ / clip / f"frame_{n:04d}.png",
                 tr / pass_ / clip / f"frame_{n + 1:04d}.png",
                 tr / "flow" / clip / f"frame_{n:04d}.flo"]
        (present if all(f.is_file() for f in files) else missing).append((clip, pass_, n))
    return present, missing


def sintel_set(
    root: str | os.PathLike[str] | None = None,
    pairs: Sequence[tuple[str, str, int]] | None = None,
    set_name: str = "sintel",
) -> Iterator[BenchPair]:
    """MPI-Sintel pairs (default: those of :data:`SINTEL_PAIRS` on disk).

    The scored pixels exclude the ``invalid`` mask when there is one; the occlusion
    mask is used for ``aee_noc`` when there is one.
    """
    base = data_root(root)
    if pairs is None:
        pairs = sintel_pairs_present(base)[0]
    for clip, pass_, n in pairs:
        f0, f1, gt, occ, inv = load_sintel_pair(clip, n, pass_, base)
        yield BenchPair(set_name, _sintel_label(clip, pass_, n), f0, f1, gt,
                        None if inv is None else ~inv, occ)


def check_twoframe_data(
    sets: Sequence[str], root: str | os.PathLike[str] | None = None
) -> list[tuple[str, str, int]]:
    """Fail early when a requested data set is missing.

    Parameters
    ----------
    sets : sequence of str
        Some of :data:`SETS`.
    root : path-like, optional
        Data folder; see :func:`varflow.evaluation.datasets.data_root`.

    Returns
    -------
    list of (clip, pass, N)
        The pairs of :data:`SINTEL_PAIRS` not on disk when ``"sintel"`` is requested
        (they are skipped), else empty.

    Raises
    ------
    FileNotFoundError
        ``"middlebury"`` requested without ``<root>/middlebury``, or ``"sintel"``
        without any of :data:`SINTEL_PAIRS` (the message says how to point at the
        data).
    """
    base = data_root(root)
    if "middlebury" in sets and not (base / "middlebury").is_dir():
        raise FileNotFoundError(f"Middlebury data not found under {base}; {DATA_HINT}")
    missing_all: list[tuple[str, str, int]] = []
    for name, label, pairs in (("sintel", "Sintel", SINTEL_PAIRS),
                               ("sintel-large", "large-motion Sintel", SINTEL_LARGE_PAIRS)):
        if name not in sets:
            continue
        present, missing = sintel_pairs_present(base, pairs)
        if not present:
            raise FileNotFoundError(
                f"none of the {label} pairs found under {base / 'sintel' / 'training'}; "
                f"{DATA_HINT}"
            )
        missing_all += [m for m in missing if m not in missing_all]
    return missing_all


# --------------------------------------------------------------------------- running


def _warm_up_peer(name: str) -> None:
    """Run a peer once on a small synthetic pair (library start-up not timed)."""
    from ...generators.pairs import synthetic_pair

    f0, f1, _ = synthetic_pair("translation", shape=(48, 64), magnitude=1.0, seed=0)
    PEERS[name](f0, f1)


def _score(est: np.ndarray, pair: BenchPair) -> dict[str, Any]:
    from ..metrics import evaluate

    scores = evaluate(est, pair.gt, mask=pair.mask, occlusion=pair.occlusion)
    out: dict[str, Any] = {
        "aee": float(scores["aee"]),
        "aee_noc": None if pair.occlusion is None else float(scores["aee_noc"]),
        "aae": float(scores["aae"]),
        "r1": float(scores["r1"]),
        "r3": float(scores["r3"]),
    }
    return out


def _motion(pair: BenchPair) -> dict[str, Any]:
    mag = np.hypot(pair.gt[..., 0], pair.gt[..., 1])
    known = np.isfinite(mag)
    if pair.mask is not None:
        known &= pair.mask
    mean = float(mag[known].mean()) if known.any() else math.nan
    occluded = None
    if pair.occlusion is not None:
        occluded = float(pair.occlusion[known].mean()) if known.any() else math.nan
    return {
        "mean_motion": mean,
        "max_motion": float(mag[known].max()) if known.any() else math.nan,
        "motion": "large" if mean > LARGE_MOTION_PX else "small",
        "occluded": occluded,
    }


def run_twoframe(
    methods: Sequence[str] = ("tvl1",),
    peers: str | Sequence[str] | None = None,
    sets: str | Sequence[str] = DEFAULT_SETS,
    split: str = "reporting",
    families: str | Sequence[str] = PHOTO_FAMILIES,
    root: str | os.PathLike[str] | None = None,
    photo_shape: tuple[int, int] = PHOTO_SHAPE,
    overrides: Mapping[str, Any] | None = None,
    progress: bool = True,
    warm_up: bool = True,
) -> list[dict[str, Any]]:
    """Run varflow methods and peers on the photo pairs, Middlebury and Sintel.

    Parameters
    ----------
    methods : sequence of str
        Names from :data:`varflow.registry.METHODS` (may be empty when peers are given).
    peers : str or sequence of str, optional
        Names from :data:`~varflow.evaluation.peers.PEERS`, ``"all"`` or ``"none"``;
        peers whose backend is missing are skipped with a warning (see
        :func:`resolve_peers` for the reasons).
    sets : str or sequence of str
        Some of :data:`SETS`.
    split : {"tuning", "reporting", "both"}
        Seeds of the photo pairs.
    families : str or sequence of str
        Families of the photo pairs.
    root : path-like, optional
        Data folder for Middlebury and Sintel; see
        :func:`varflow.evaluation.datasets.data_root`.
    photo_shape : (int, int)
        Size of the photo pairs (default 256 x 320).
    overrides : mapping, optional
        Parameter overrides of the varflow methods; see
        :func:`varflow.evaluation.bench.common.split_overrides`.
    progress : bool
        A tqdm bar on stderr (only on a terminal).
    warm_up : bool
        First run every method and peer once, untimed, on a small synthetic pair.

    Returns
    -------
    list of dict
        One row per (set, pair, method), in set, pair, method order (the varflow
        methods first, then the peers): ``set``, ``split`` and ``family``, ``seed``
        (photo pairs; else None), ``sequence``, ``method``, ``kind`` (``"varflow"`` or
        ``"peer"``), ``aee``, ``aee_noc`` (None without an occlusion mask), ``aae``
        (degrees), ``r1``, ``r3`` (% of pixels with EPE above 1 and 3 px),
        ``seconds``, ``mean_motion``, ``max_motion`` (px, of the ground truth over
        the scored pixels), ``motion`` (``"large"`` when ``mean_motion`` >
        :data:`LARGE_MOTION_PX`, else ``"small"``) and ``occluded`` (share of the
        scored pixels occluded, None without a mask).

    Raises
    ------
    ValueError
        Unknown method, peer, set, split, family or parameter, or nothing to run.
    FileNotFoundError
        When a requested data set is missing (none of the Sintel pairs, or the
        Middlebury folder).
    """
    from tqdm import tqdm

    import varflow

    from .common import _warm_up

    methods = list(methods)
    for m in methods:
        get_method(m)
    sets_, splits, fams, photo_shape = check_twoframe_options(sets, split, families, photo_shape)
    runnable, unavailable = resolve_peers(peers)
    for p, reason in unavailable.items():
        log.warning("peer %s unavailable: %s", p, reason)
    if not methods and not runnable:
        raise ValueError("methods: need at least one method or available peer")
    if overrides and not methods:
        raise ValueError("overrides: parameters given but no varflow method to apply them to")
    per_method = split_overrides(methods, overrides) if methods else {}
    params = {m: make_params(m, **per_method[m]) for m in methods}  # validate before any work
    root_path = data_root(root)
    for clip, pass_, n in check_twoframe_data(sets_, root_path):
        log.warning("Sintel pair %s not found under %s; skipped",
                    _sintel_label(clip, pass_, n), root_path)
    if warm_up:
        for m in methods:
            _warm_up(m, params[m])
        for p in runnable:
            _warm_up_peer(p)

    runners: list[tuple[str, str, Any]] = [(m, "varflow", m) for m in methods]
    runners += [(p, "peer", PEERS[p]) for p in runnable]
    sources: list[tuple[str, Iterator[BenchPair], int]] = []
    for s in sets_:
        if s == "photo":
            n = sum(len(photo_pair_cases(sp, fams)) for sp in splits)
            sources.append((s, photo_set(splits, fams, photo_shape), n))
        elif s == "middlebury":
            sources.append((s, middlebury_set(root_path), len(MIDDLEBURY_SEQUENCES)))
        elif s == "large":
            n = sum(len(large_pair_cases(sp)) for sp in splits)
            sources.append((s, large_set(splits), n))
        else:
            pairs = SINTEL_PAIRS if s == "sintel" else SINTEL_LARGE_PAIRS
            present = sintel_pairs_present(root_path, pairs)[0]
            sources.append((s, sintel_set(root_path, present, s), len(present)))

    rows: list[dict[str, Any]] = []
    bar = tqdm(total=sum(n for *_, n in sources) * len(runners), desc="two-frame",
               unit="run", file=sys.stderr, disable=None if progress else True, leave=False)
    try:
        for set_name, pairs, _ in sources:
            for pair in pairs:
                motion = _motion(pair)
                for name, kind, fn in runners:
                    bar.set_postfix_str(f"{set_name} {pair.sequence} {name}")
                    t0 = time.perf_counter()
                    if kind == "varflow":
                        est = varflow.flow(pair.frame0, pair.frame1, fn, params=params[fn])
                    else:
                        est = fn(pair.frame0, pair.frame1)
                    seconds = time.perf_counter() - t0
                    row = {"set": set_name, "split": pair.split, "sequence": pair.sequence,
                           "family": pair.family, "seed": pair.seed, "method": name,
                           "kind": kind, **_score(est, pair), "seconds": seconds, **motion}
                    log.info("%s %s %s: AEE %.4f noc %s in %.2fs", set_name, pair.sequence,
                             name, row["aee"], row["aee_noc"], seconds)
                    rows.append(row)
                    bar.update(1)
    finally:
        bar.close()
    return rows


# --------------------------------------------------------------------------- tables


def _val(row: Mapping[str, Any] | None, key: str) -> float:
    v = None if row is None else row.get(key)
    if v is None or v == "":
        return math.nan
    return float(v)


def _group_title(set_name: str, split: str | None, n: int) -> str:
    if set_name == "photo":
        seeds = PHOTO_SPLITS.get(split or "", ())
        seed_text = f", seeds {', '.join(map(str, seeds))}" if seeds else ""
        return f"photo pairs, {split} split{seed_text} ({n} pairs)"
    if set_name == "middlebury":
        return f"Middlebury frame10 -> frame11 ({n} pairs)"
    if set_name == "sintel":
        return (f"MPI-Sintel ({n} pairs; motion large when the mean ground-truth motion "
                f"> {LARGE_MOTION_PX:g} px)")
    if set_name == "large":
        return f"large-motion photo pairs (objects 30-150 px), {split} split ({n} pairs)"
    if set_name == "sintel-large":
        return f"MPI-Sintel, large motion ({n} pairs)"
    return f"{set_name} ({n} pairs)"


def _one_table(rows: Sequence[Mapping[str, Any]], baseline: str | None) -> str:
    methods: list[str] = []
    seqs: list[str] = []
    cell: dict[tuple[str, str], Mapping[str, Any]] = {}
    info: dict[str, Mapping[str, Any]] = {}
    for r in rows:
        if r["method"] not in methods:
            methods.append(r["method"])
        if r["sequence"] not in seqs:
            seqs.append(r["sequence"])
            info[r["sequence"]] = r
        cell[(r["sequence"], r["method"])] = r
    set_name = rows[0]["set"]
    has_noc = any(math.isfinite(_val(r, "aee_noc")) for r in rows)
    show_class = set_name in ("sintel", "sintel-large")

    def get(s: str, m: str, key: str) -> float:
        return _val(cell.get((s, m)), key)

    header = ["sequence", "mean gt px"] + (["motion"] if show_class else [])
    for m in methods:
        header += [f"{m} AEE"] + ([f"{m} noc"] if has_noc else []) + [f"{m} s"]
    lead = len(header) - len(methods) * (3 if has_noc else 2)

    def method_cells(subset: Sequence[str]) -> list[str]:
        out: list[str] = []
        for m in methods:
            out.append(_num(_nanmean([get(s, m, "aee") for s in subset]), 3))
            if has_noc:
                out.append(_num(_nanmean([get(s, m, "aee_noc") for s in subset]), 3))
            out.append(_num(_nanmean([get(s, m, "seconds") for s in subset]), 3))
        return out

    body: list[list[str]] = []
    for s in seqs:
        line = [s, _num(_val(info[s], "mean_motion"), 2)]
        if show_class:
            line.append(str(info[s].get("motion") or ""))
        body.append(line + method_cells([s]))

    def summary(label: str, subset: Sequence[str]) -> list[str]:
        pad = [_num(_nanmean([_val(info[s], "mean_motion") for s in subset]), 2)]
        pad += [""] * (lead - 2)
        return [label] + pad + method_cells(subset)

    body.append(summary("mean", seqs))
    if show_class:
        for cls in ("small", "large"):
            subset = [s for s in seqs if info[s].get("motion") == cls]
            if subset and len(subset) < len(seqs):
                body.append(summary(f"mean {cls} motion ({len(subset)})", subset))
    families = list(dict.fromkeys(str(info[s].get("family")) for s in seqs
                                  if info[s].get("family")))
    if set_name == "photo" and len(families) > 1:
        for f in families:
            body.append(summary(f"mean {f}", [s for s in seqs if info[s].get("family") == f]))

    total = ["total s"] + [""] * (lead - 1)
    for m in methods:
        secs = [get(s, m, "seconds") for s in seqs]
        total += [""] + ([""] if has_noc else [])
        total.append(_num(float(np.nansum(secs)) if any(map(math.isfinite, secs))
                          else math.nan, 3))
    body.append(total)

    if baseline is None:
        baseline = BASELINE_PEER if BASELINE_PEER in methods else methods[0]
    if baseline in methods and len(methods) > 1:
        ratio = [f"ratio to {baseline}"] + [""] * (lead - 1)
        keys = ["aee"] + (["aee_noc"] if has_noc else []) + ["seconds"]
        for m in methods:
            for k in keys:
                both = [s for s in seqs if math.isfinite(get(s, m, k))
                        and math.isfinite(get(s, baseline, k))]
                base = _nanmean([get(s, baseline, k) for s in both])
                mine = _nanmean([get(s, m, k) for s in both])
                ratio.append(_num(mine / base if base > 0 else math.nan, 2))
        body.append(ratio)
    return markdown_table(header, body)


def format_twoframe_table(
    rows: Sequence[Mapping[str, Any]], baseline: str | None = None
) -> str:
    """Markdown tables of :func:`run_twoframe` rows, one per set (and split).

    Each table has a title line, then a line per pair: the sequence, its mean
    ground-truth motion ``mean gt px`` (over the scored pixels), for Sintel the motion
    class (``small`` / ``large``), and per method (in order of first appearance)
    ``AEE``, ``noc`` (AEE over the non-occluded pixels; the column is left out when
    no pair of the set has an occlusion mask) and ``s`` (seconds).  Under the pairs:

    * ``mean`` — the mean of every column over the pairs;
    * ``mean small motion (n)`` / ``mean large motion (n)`` — Sintel, when both
      classes occur;
    * ``mean <family>`` — photo pairs, per family, when there are several;
    * ``total s`` — the summed seconds of each method;
    * ``ratio to B`` — when there are several methods: for every method, its mean
      AEE, noc and seconds divided by those of the baseline ``B`` over the pairs
      both ran (< 1: lower error or faster than ``B``).

    Parameters
    ----------
    rows : sequence of mapping
        As returned by :func:`run_twoframe` (or read back from its CSV).
    baseline : str, optional
        The method of the ratio line: ``"deepflow"`` when it ran, else the first
        method.

    Returns
    -------
    str
        The titled tables separated by blank lines, without a trailing newline.
    """
    if not rows:
        return "(no results)"
    groups: dict[tuple[str, str | None], list[Mapping[str, Any]]] = {}
    for r in rows:
        split = r.get("split") or None
        groups.setdefault((str(r["set"]), split), []).append(r)
    order = {s: i for i, s in enumerate(SETS)}
    split_order = {s: i for i, s in enumerate(PHOTO_SPLITS)}

    def key(item: tuple[tuple[str, str | None], Any]) -> tuple[int, int, str]:
        set_name, split = item[0]
        return (order.get(set_name, len(SETS)), split_order.get(split or "", -1), split or "")

    parts = []
    for (set_name, split), group in sorted(groups.items(), key=key):
        n = len(dict.fromkeys(r["sequence"] for r in group))
        parts.append(_group_title(set_name, split, n) + "\n\n" + _one_table(group, baseline))
    return "\n\n".join(parts)


def write_twoframe_csv(rows: Sequence[Mapping[str, Any]], path: str | os.PathLike[str]) -> None:
    """Write :func:`run_twoframe` rows to a CSV file atomically.

    Columns are :data:`TWOFRAME_CSV_FIELDS` followed by any other keys of the rows;
    None is written as an empty cell.

    Parameters
    ----------
    rows : sequence of mapping
    path : path-like
        Target file; its directory must exist.
    """
    write_csv(rows, path, TWOFRAME_CSV_FIELDS)
