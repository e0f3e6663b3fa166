"""The restoration methods, registered in :data:`varflow.registry.RESTORE` (denoisers)
and :data:`varflow.registry.REPAIR` (the repair stages of archival defects).

Each :class:`~varflow.registry.Restorer` names its parameter defaults (a frozen
dataclass) and its ``run`` function; :func:`varflow.restore.denoise.denoise` (re-exported
as :func:`varflow.denoise`) runs one.  Each :class:`~varflow.registry.Repairer`
(``stabilise``, ``deflicker``, ``dirt``) wraps the stage function of its module with
its parameter class, its place in the chain and the temporal context it needs;
:func:`varflow.restore.chain.iter_restore` runs them in order.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from .._validate import check_field
from ..registry import REPAIR, RESTORE, MemoryFactors, Repairer, Restorer
from ..twoframe.methods import FlowComposed
from ..twoframe.params import TVL1Params

__all__ = ["DEFAULT_RESTORER", "NLBayesParams", "fast_defaults", "get_restorer",
           "make_restore_params"]


@dataclass(frozen=True)
class NLBayesParams(FlowComposed):
    """Parameters of ``nlbayes``: motion-compensated NL-Bayes (Arias & Morel 2018).

    For every reference patch, the most similar patches are searched in the frame
    and along the flows in the ``radius`` frames each side (the chain stops where
    the forward-backward check fails: hidden neighbours are never used); each
    group is estimated by an empirical Wiener filter in the eigenbasis of its
    covariance (:mod:`varflow.restore._nlbayes`), first from the noisy group, then
    ("final" pass) with the statistics of the first estimate.  Colour frames are
    processed in an orthonormal opponent space (the noise stays white with the
    same σ).

    Attributes
    ----------
    radius : int
        Frames searched each side of the reference frame, along the flows (the
        temporal radius); 0 denoises each frame alone.  Default 5.
    patch : int
        Side of the square patches of the first pass, pixels (d = patch² values
        per channel).  Default 5.
    patch_final : int
        Side of the patches of the final pass, pixels.  Default 7.
    n_similar : int
        Patches per group in the first pass (N₁; at least 2, and above patch² for
        a well-posed covariance).  Default 90.
    n_similar_final : int
        Patches per group in the final pass (N₂).  Default 90.
    search : int
        Half-side of the search window in the reference frame, pixels
        (a (2·search + 1)² window).  Default 7.
    search_t : int
        Half-side of the search window in the other frames, around where the
        flows carry the reference patch, pixels.  Default 4.
    tau : float
        Of the ``n_similar`` nearest patches, the first pass keeps those within
        ``tau σ²`` per value of the reference (two noisy copies of one patch are
        ``2 σ²`` apart on average): a texture unlike its surroundings is averaged
        with its own copies along the motion only, not with look-alikes; 0 keeps
        all ``n_similar``.  Groups of fewer patches than values are estimated in
        their Gram matrix.  Default 8.
    tau_final : float
        The same in the final pass, on the first estimate (whose copies of one
        patch are much closer than ``2 σ²``); it binds at low noise only, where
        a tight threshold leaves groups too small.  Default 8.
    stride : int
        Step between reference patches, pixels (at most the patch side, so
        every pixel is covered); positions already covered by an estimated
        patch are skipped.  Default 3.
    beta : float
        β, the multiple of σ² taken off the group's eigenvalues in the first
        pass.  Default 1.
    flat : float
        γ of the homogeneous-area rule: a group whose variance is below γ σ² is
        replaced by its mean; 0 turns the rule off.  Default 1.05.
    passes : int
        1 (the first estimate only) or 2 (with the final pass).  Default 2.
    luma_final : bool
        The final pass compares patches on the first estimate's luminance only
        (as the first pass does on the noisy clip) instead of on all its channels:
        a third of the distance computations, for a little accuracy.  Default False.
    flow_method : str
        The two-frame method of the flows between consecutive frames.
        Default ``"tvl1-fast"``.
    flow_params : TVL1Params or None
        Its parameters (None: its defaults).
    flow_blur : float
        σ of the Gaussian (pixels) that smooths the noisy frames before their
        flows are estimated (both passes use these flows).  Default 1.
    flow_max_pixels : int
        Frames of more pixels than this get their flows on a reduced copy (the
        search window absorbs the coarser flow); 0: never.  Default 0.
    fb_tolerance : float
        α₂ of the forward-backward check (px², :func:`varflow.consistency`).
        Default 0.5.
    grain : float
        The fraction of the removed noise put back (0: the full estimate, 1: the
        input): film grain instead of a waxy look.  Default 0.
    """

    radius: int = 5
    patch: int = 5
    patch_final: int = 7
    n_similar: int = 90
    n_similar_final: int = 90
    search: int = 7
    search_t: int = 4
    tau: float = 8.0
    tau_final: float = 8.0
    stride: int = 3
    beta: float = 1.0
    flat: float = 1.05
    passes: int = 2
    luma_final: bool = False
    flow_method: str = "tvl1-fast"
    flow_params: TVL1Params | None = None
    flow_blur: float = 1.0
    flow_max_pixels: int = 0
    fb_tolerance: float = 0.5
    grain: float = 0.0

    def __post_init__(self) -> None:
        super().__post_init__()

        def integer(name: str, low: int, high: int | None = None) -> int:
            v = getattr(self, name)
            ok = isinstance(v, int) and not isinstance(v, bool) and v >= low and (
                high is None or v <= high)
            rng = f">= {low}" if high is None else f"in [{low}, {high}]"
            check_field(ok, name, f"must be an integer {rng}, got {v!r}")
            return v

        def number(name: str, low: float, high: float | None = None) -> None:
            v = getattr(self, name)
            ok = isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(
                v) and v >= low and (high is None or v <= high)
            rng = f">= {low:g}" if high is None else f"in [{low:g}, {high:g}]"
            check_field(ok, name, f"must be a finite number {rng}, got {v!r}")

        integer("radius", 0, 16)
        patch = integer("patch", 2, 16)
        integer("patch_final", 2, 16)
        integer("n_similar", 2)
        integer("n_similar_final", 2)
        integer("search", 1, 64)
        integer("search_t", 0, 64)
        stride = integer("stride", 1)
        check_field(stride <= min(patch, self.patch_final), "stride",
                    f"must be at most the patch sides ({min(patch, self.patch_final)}), "
                    f"got {stride}")
        integer("passes", 1, 2)
        check_field(isinstance(self.luma_final, bool), "luma_final",
                    f"must be True or False, got {self.luma_final!r}")
        integer("flow_max_pixels", 0)
        number("beta", 0.0)
        number("flat", 0.0)
        number("tau", 0.0)
        number("tau_final", 0.0)
        number("flow_blur", 0.0)
        number("fb_tolerance", 0.0)
        number("grain", 0.0, 1.0)


def fast_defaults() -> NLBayesParams:
    """The ``nlbayes-fast`` preset: both passes on radius 3, 5 × 5 patches in both, a
    sparser grid of reference patches (stride 4), smaller search windows, 60 patches
    per first-pass group, and flows on frames reduced to at most 150 000 pixels.  The
    final pass keeps 90 patches per group: its estimate is what the output is made
    of, and fewer patches there cost more than anywhere else."""
    return NLBayesParams(radius=3, patch_final=5, n_similar=60, n_similar_final=90,
                         search=5, search_t=3, stride=4, flow_max_pixels=150_000)


def _run(*args: Any, **kwargs: Any) -> Any:
    from .denoise import run_nlbayes

    return run_nlbayes(*args, **kwargs)


_KERNELS = ("varflow.restore._nlbayes:_phase", "varflow.restore._nlbayes:estimate_group")
_KNOBS = (
    ("radius", "frames each side used: more is cleaner on steady footage, slower"),
    ("grain", "fraction of the noise put back (film grain): 0.1-0.3 keeps texture"),
    ("flow_method", "the flows' method: tvl1 for more accurate motion, slower"),
)

RESTORE.register(Restorer(
    name="nlbayes",
    description="motion-compensated NL-Bayes: space-time patch groups along the flows, "
    "two Wiener passes (Arias & Morel 2018)",
    defaults=NLBayesParams,
    memory=MemoryFactors(base=0, per_frame=120),
    kernels=_KERNELS,
    compile_seconds=30,
    use="the best quality: noisy video, low light, film grain",
    knobs=_KNOBS,
    run=_run,
))
RESTORE.register(Restorer(
    name="nlbayes-fast",
    description="nlbayes with radius 3, smaller patches and searches, a sparser grid "
    "and reduced flows",
    defaults=fast_defaults,
    memory=MemoryFactors(base=0, per_frame=100),
    kernels=_KERNELS,
    compile_seconds=30,
    use="previews and long clips: several times faster than nlbayes, a little noisier",
    knobs=_KNOBS,
    run=_run,
))

#: The method of :func:`varflow.denoise` when none is named.
DEFAULT_RESTORER = RESTORE.default


def get_restorer(name: str) -> Restorer:
    """``RESTORE.entry(name)``: a restoration method by name (``ValueError`` if unknown)."""
    return RESTORE.entry(name)


def make_restore_params(method: str | Restorer, params: Any = None, **overrides: Any) -> Any:
    """``RESTORE.make_params``: a restoration method's parameters."""
    return RESTORE.make_params(method, params, **overrides)


# --------------------------------------------------------------------------- repair stages


def _stabilise_defaults() -> Any:
    from .stabilise import StabiliseParams

    return StabiliseParams()


def _deflicker_defaults() -> Any:
    from .flicker import DeflickerParams

    return DeflickerParams()


def _dirt_defaults() -> Any:
    from .dirt import DirtParams

    return DirtParams()


def _run_stabilise(clip: Any, params: Any, callback: Any = None, stats: Any = None,
                   flows: Any = None) -> Any:
    from .stabilise import stabilise

    return stabilise(clip, params, flows=flows, callback=callback, stats=stats), None


def _run_deflicker(clip: Any, params: Any, callback: Any = None, stats: Any = None,
                   flows: Any = None) -> Any:
    from .flicker import deflicker

    return deflicker(clip, params, flows=flows, callback=callback, stats=stats), None


def _run_dirt(clip: Any, params: Any, callback: Any = None, stats: Any = None,
              flows: Any = None) -> Any:
    from .dirt import remove_dirt

    # flows an earlier stage estimated (deflicker's) replace only the first estimate:
    # the final ones are estimated again after a rough fill of the dirt (refine); with
    # no refinement the stage's own flow settings are kept
    initial = flows if flows is not None and params.refine > 0 else None
    return remove_dirt(clip, params, return_mask=True, initial_flows=initial,
                       callback=callback, stats=stats)


def _stabilise_pair_flows(frame0: Any, frame1: Any, params: Any) -> Any:
    from .stabilise import pair_flows

    return pair_flows(frame0, frame1, params)


def _deflicker_pair_flows(frame0: Any, frame1: Any, params: Any) -> Any:
    from .flicker import pair_flows

    return pair_flows(frame0, frame1, params)


def _stabilise_context(p: Any) -> int:
    # the path smoother's Gaussian is cut at 4 σ; the border fill looks fill_radius
    # frames further; an infinite σ (one fit to the whole clip) needs the whole scene
    if math.isinf(p.smooth):
        return 1 << 30
    return int(math.ceil(4 * p.smooth)) + p.fill_radius + 1


def _deflicker_context(p: Any) -> int:
    # neighbours matched, the brightness path's local fit (whose own reach is a
    # window further through the robust weights) and its step test
    return p.radius + 2 * p.window + p.persist


REPAIR.register(Repairer(
    name="stabilise",
    description="gate weave removed: a robust similarity (or affine) fit to the flows, "
    "a smoothed camera path, uncovered borders filled from the neighbours",
    defaults=_stabilise_defaults,
    use="jitter of the picture in the gate or a shaky camera; pans and zooms are kept",
    knobs=(("smooth", "σ of the path smoother in frames: larger removes slower shake"),
           ("model", "similarity (shift, rotation, scale) or affine")),
    run=_run_stabilise,
    order=0,
    context=_stabilise_context,
    pair_flows=_stabilise_pair_flows,
))
REPAIR.register(Repairer(
    name="deflicker",
    description="flicker removed: smooth gain and offset fields against the "
    "motion-compensated neighbours, corrected toward a smoothed brightness path",
    defaults=_deflicker_defaults,
    use="brightness pumping from frame to frame; fades and lights that stay are kept",
    knobs=(("window", "half-width of the brightness smoothing in frames"),
           ("degree", "polynomial degree of the gain field: 0 is a global gain")),
    run=_run_deflicker,
    order=1,
    context=_deflicker_context,
    pair_flows=_deflicker_pair_flows,
    shares_flows=True,
))
REPAIR.register(Repairer(
    name="dirt",
    description="dust, dirt and hairs removed: spikes in time along the flows, filled "
    "from the neighbours (Kokaram 1998); the mask of what changed",
    defaults=_dirt_defaults,
    use="blotches on one frame only; sensitivity trades recall for precision",
    knobs=(("sensitivity", "above 1 finds fainter dirt and touches more picture"),),
    run=_run_dirt,
    order=2,
    context=lambda p: 3,
))
