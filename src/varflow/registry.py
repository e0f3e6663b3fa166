"""The registries: one kind of object for every kind of method.

Each kind of method has one :class:`Registry` that the API, the CLI, the benchmarks and
the documentation read:

========================  =====================  =========================================
registry                  entries                registered in
========================  =====================  =========================================
:data:`FLOW`              :class:`Method`        :mod:`varflow.twoframe.methods`
:data:`TRACK`             :class:`Tracker`       :mod:`varflow.multiframe.methods`
:data:`INTERPOLATE`       :class:`Interpolator`  :mod:`varflow.retime.methods`
:data:`RESTORE`           :class:`Restorer`      :mod:`varflow.restore.methods`
:data:`REPAIR`            :class:`Repairer`      :mod:`varflow.restore.methods`
========================  =====================  =========================================

An entry carries everything known about a method under its name: a one-line
description, the factory of its default parameters (a frozen dataclass, see
:mod:`varflow.parameters`), its peak-memory model (:class:`MemoryFactors`, read by
:mod:`varflow._memory`), the Numba kernels its first run compiles and a rough
compile time (read by :mod:`varflow._jit`), and the functions that run it.  Adding a
method is one :meth:`Registry.register` call in the module of its kind; a registry
imports that module on its first lookup.

:meth:`Registry.make_params` builds a method's parameters from its defaults, an
existing object and flat overrides, each routed to the parameter object that owns
it (a tracker's ``data_weight`` goes to its two-frame energy, a sparse method's
``tensor_a`` to its tensor term).  :meth:`Registry.fields` lists those flat names,
their defaults and the class that documents each: the CLI's flags and ``--params``
tables.

The former names stay: :data:`METHODS`, :data:`TRACKERS` and
``varflow.retime.methods.INTERPOLATORS`` are the registries themselves;
:func:`make_params`, :func:`make_track_params`, :func:`get_method`,
:func:`get_tracker` and :func:`parameter_fields` call them.
"""

from __future__ import annotations

import dataclasses
import importlib
from collections.abc import Callable, Iterator, MutableMapping
from dataclasses import dataclass
from typing import Any

from .parameters import UnknownParameter, flat_fields

__all__ = [
    "DEFAULT_METHOD",
    "Entry",
    "FLOW",
    "INTERPOLATE",
    "Interpolator",
    "METHODS",
    "MemoryFactors",
    "Method",
    "REGISTRIES",
    "REPAIR",
    "RESTORE",
    "Registry",
    "Repairer",
    "Restorer",
    "TRACK",
    "TRACKERS",
    "Tracker",
    "get_method",
    "get_tracker",
    "make_params",
    "make_track_params",
    "parameter_fields",
]

#: The method of :func:`varflow.flow` when none is named, and of the trackers and
#: interpolators built on two-frame flows unless they name another.
DEFAULT_METHOD = "tvl1"


@dataclass(frozen=True)
class MemoryFactors:
    """Peak-memory model of one method: ``fixed + pixels * per-pixel bytes``.

    See :mod:`varflow._memory` for how the factors are measured and used.

    Attributes
    ----------
    base : float
        Bytes per pixel independent of the number of frames (grey).
    per_frame : float
        Bytes per pixel and frame (trackers; 0 for two-frame methods, whose two
        frames are part of ``base``).
    per_channel : float
        Extra bytes per pixel for each colour channel beyond the first (per frame
        for trackers).
    fixed : float
        Bytes that do not grow with the image.
    """

    base: float
    per_frame: float = 0.0
    per_channel: float = 0.0
    fixed: float = 0.0


@dataclass(frozen=True)
class Entry:
    """A registered method, of any kind.

    Attributes
    ----------
    name : str
        The name users pass (``varflow.flow(..., "tvl1")``, ``--method tvl1``).
    description : str
        One line for listings (``varflow methods``, the documentation).
    defaults : callable
        ``defaults() -> params``: the method's default parameters, a frozen dataclass.
    memory : MemoryFactors or None
        Its measured peak-memory model; None: the largest of its kind.
    kernels : tuple of str
        ``"module:function"`` of the Numba kernels its first run compiles (beyond
        those every method compiles), to tell whether Numba's cache holds them.
    compile_seconds : int or None
        Rough seconds its first run spends compiling on a cold cache.
    use : str
        When to choose it, one line (``varflow methods``, ``--help``): the scenes or
        jobs it is for, against the other methods of its kind.
    knobs : tuple of (str, str)
        ``(field, when to change it)`` of the few parameters worth turning, in the
        order ``--help`` shows them; every other field keeps its default for most
        users.
    """

    name: str
    description: str
    defaults: Callable[[], Any]
    memory: MemoryFactors | None = None
    kernels: tuple[str, ...] = ()
    compile_seconds: int | None = None
    use: str = ""
    knobs: tuple[tuple[str, str], ...] = ()

    @property
    def params_type(self) -> type:
        """The class of the method's parameters."""
        return type(self.defaults())

    def check_params(self, params: Any) -> None:
        """Raise ``ValueError`` (naming ``params``) unless ``params`` suits the method."""
        if not isinstance(params, self.params_type):
            raise ValueError(f"params: expected {self.params_type.__name__} for "
                             f"{self.name!r}, got {type(params).__name__}")


@dataclass(frozen=True)
class Method(Entry):
    """A two-frame flow method (:data:`FLOW`).

    Its parameters are a :class:`~varflow.twoframe.params.TVL1Params` with exactly the
    optional terms of its defaults (``tensor``, ``sparse``, ``matching``).

    Attributes
    ----------
    solve_warp : callable
        The single-level, single-warp solver plugged into
        :func:`varflow.twoframe.coarse_to_fine.coarse_to_fine`.
    run : callable or None
        ``run(frame0, frame1, params, init_flow=None, callback=None, stats=None)``
        for a method whose pipeline has stages around the driver (which it calls
        with ``solve_warp``); None: the driver alone.
    """

    solve_warp: Callable[..., Any] | None = None
    run: Callable[..., Any] | None = None

    def check_params(self, params: Any) -> None:
        super().check_params(params)
        want, got = self.defaults().terms(), params.terms()
        if want != got:
            raise ValueError(
                f"params: {self.name!r} takes the terms {sorted(want) or 'none'}, "
                f"got {sorted(got) or 'none'}")


@dataclass(frozen=True)
class Tracker(Entry):
    """A multi-frame (trajectory) method (:data:`TRACK`).

    Attributes
    ----------
    track : callable
        ``track(frames, ref, params, callback, stats=None) -> (F, H, W, 2)`` with
        ``frames`` as returned by :func:`varflow.multiframe.track.check_frames`;
        ``stats`` (a dict) may gain ``visible``, the ``(F, H, W)`` bool visibility
        when the method estimates it.
    """

    track: Callable[..., Any] | None = None


@dataclass(frozen=True)
class Interpolator(Entry):
    """A frame-interpolation method (:data:`INTERPOLATE`).

    Attributes
    ----------
    prepare : callable
        ``prepare(frame0, frame1, params, previous=None, following=None,
        callback=None, stats=None, cache=None) -> PairMotion``; frames (H, W, C)
        float32 as :class:`~varflow.retime.motion.PairMotion` holds them;
        ``previous`` / ``following`` the frames before ``frame0`` and after
        ``frame1`` when the caller has them (methods with ``context`` 1 use them,
        the others ignore them); ``cache`` a
        :class:`~varflow.retime.motion.FlowCache` through which the flows are
        estimated.
    context : int
        Frames each side of the pair the method can use (0 or 1).
    """

    prepare: Callable[..., Any] | None = None
    context: int = 0


@dataclass(frozen=True)
class Restorer(Entry):
    """A restoration method (:data:`RESTORE`): a denoiser of clips.

    Attributes
    ----------
    run : callable
        ``run(clip, sigma, params, callback=None, stats=None) -> clip`` with
        ``clip`` ``(F, H, W, C)`` float32 in the input's units and ``sigma`` the
        noise's standard deviation in those units; ``callback(done, total)``
        reports progress; ``stats`` (a dict) gains timings.
    """

    run: Callable[..., Any] | None = None


@dataclass(frozen=True)
class Repairer(Entry):
    """A repair stage for archival defects (:data:`REPAIR`): gate weave, flicker, dirt.

    Attributes
    ----------
    run : callable
        ``run(clip, params, callback=None, stats=None, flows=None) -> (clip, mask)``
        with ``clip`` ``(F, H, W, C)`` float32 on the 0-255 scale and ``mask`` the
        ``(F, H, W)`` bool mask of the pixels the stage replaced (None for a stage
        that changes every pixel); ``callback(done, total)`` reports progress;
        ``stats`` (a dict) gains timings; ``flows`` the stage's own flows between
        consecutive frames (``pair_flows``' results stacked along a first axis), or
        for a stage without ``pair_flows`` an earlier stage's ``(fwd, bwd)`` (see
        ``pair_flows``), or None.
    pair_flows : callable or None
        ``pair_flows(frame0, frame1, params)`` -> an array or a tuple of arrays: the
        flows of one consecutive pair as the stage estimates them, so that a stream
        repaired in overlapping windows estimates each pair once; None: the stage
        takes no flows of its own from outside (its ``run`` may then be given, as
        ``flows``, the ``(fwd, bwd)`` an earlier stage that ``shares_flows`` left:
        flows to start from).
    shares_flows : bool
        The stage changes intensities, not positions, so the forward and backward
        flows of its ``pair_flows`` (the first two of its arrays) still hold for its
        output and a later stage without ``pair_flows`` of its own may start from
        them.  Default False.
    order : int
        Its place in the chain of :func:`varflow.restore.chain.iter_restore`, as
        restoration practice orders the stages: geometry first (the later stages
        compare aligned frames), then brightness (the dirt test compares
        intensities), then dirt; denoising comes after all of them.
    context : callable
        ``context(params) -> int``: the frames each side of a frame that its result
        depends on; a stream is repaired in windows overlapping by this many frames.
    """

    run: Callable[..., Any] | None = None
    order: int = 0
    context: Callable[[Any], int] | None = None
    pair_flows: Callable[..., Any] | None = None
    shares_flows: bool = False


class Registry(MutableMapping):
    """The methods of one kind, by name, in registration order.

    A mapping ``name -> entry`` (``registry["tvl1"]``, ``"tvl1" in registry``,
    ``sorted(registry)``) with the operations every kind shares.  Entries are added
    by :meth:`register`; item assignment and deletion (e.g. a test's temporary
    method) take an entry of the registry's type under its own name.

    Parameters
    ----------
    kind : str
        What its entries are called in messages (``"method"``, ``"trajectory
        method"``...).
    entry_type : type
        The :class:`Entry` subclass of its entries.
    source : str
        The module that registers the entries, imported on the first lookup.
    default : str
        The entry used when none is named (``--method`` omitted).
    """

    def __init__(self, kind: str, entry_type: type[Entry], source: str, default: str) -> None:
        self.kind = kind
        self.entry_type = entry_type
        self.source = source
        self.default = default
        self._entries: dict[str, Entry] = {}
        self._loaded = False

    def _load(self) -> dict[str, Entry]:
        if not self._loaded:
            self._loaded = True
            importlib.import_module(self.source)
        return self._entries

    def register(self, entry: Entry) -> Entry:
        """Add ``entry`` (of :attr:`entry_type`, with a new name) and return it."""
        if not isinstance(entry, self.entry_type):
            raise TypeError(f"expected a {self.entry_type.__name__}, got {type(entry).__name__}")
        if entry.name in self._entries:
            raise ValueError(f"{self.kind} {entry.name!r} is already registered")
        self._entries[entry.name] = entry
        return entry

    def __getitem__(self, name: str) -> Entry:
        return self._load()[name]

    def __setitem__(self, name: str, entry: Entry) -> None:
        if not isinstance(entry, self.entry_type) or entry.name != name:
            raise ValueError(f"{self.kind} {name!r}: expected a {self.entry_type.__name__} "
                             f"named {name!r}")
        self._load()[name] = entry

    def __delitem__(self, name: str) -> None:
        del self._load()[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._load())

    def __len__(self) -> int:
        return len(self._load())

    def __repr__(self) -> str:
        return f"Registry({self.kind!r}: {', '.join(self._load())})"

    def get(self, name: Any, default: Any = None) -> Any:  # type: ignore[override]
        """``self[name]``, or ``default`` for a name that is not registered."""
        try:
            return self._load()[name]
        except (KeyError, TypeError):
            return default

    def entry(self, method: str | Entry) -> Entry:
        """The entry named ``method`` (an entry is returned as is).

        Raises
        ------
        ValueError
            ``"method: unknown <kind> ...; available: ..."`` for an unknown name.
        """
        if isinstance(method, Entry):
            return method
        found = self.get(method)
        if found is None:
            raise ValueError(f"method: unknown {self.kind} {method!r}; available: "
                             f"{', '.join(self.names())}")
        return found

    def names(self) -> list[str]:
        """The registered names, sorted."""
        return sorted(self._load())

    def describe(self) -> list[tuple[str, str]]:
        """``(name, description)`` of every entry, sorted by name."""
        return [(name, self[name].description) for name in self.names()]

    def make_params(self, method: str | Entry, params: Any = None, **overrides: Any) -> Any:
        """A method's parameters: ``params`` (default: the method's defaults) with the
        flat ``overrides``, each routed to the parameter object that owns it
        (:func:`varflow.parameters.replace`), checked against the method.

        Raises
        ------
        ValueError
            An unknown method, parameters of the wrong kind, or an unknown or invalid
            field (named in the message).
        """
        m = self.entry(method)
        base = m.defaults() if params is None else params
        m.check_params(base)
        if not overrides:
            return base
        valid = sorted(name for name, _, _ in flat_fields(base))
        try:
            if not hasattr(base, "replace"):
                unknown = sorted(set(overrides) - set(valid))
                if unknown:
                    raise UnknownParameter(unknown[0], type(base).__name__)
                out = dataclasses.replace(base, **overrides)
            else:
                out = base.replace(**overrides)
        except UnknownParameter as exc:
            raise ValueError(f"{exc.name}: not a parameter of {self.kind} {m.name!r} "
                             f"(valid: {', '.join(valid)})") from None
        except TypeError as exc:  # dataclasses.replace of a class without routing
            raise ValueError(f"params: {exc}") from None
        m.check_params(out)
        return out

    def fields(self, method: str | Entry, flow_method: str | None = None
               ) -> list[tuple[str, Any, type]]:
        """``(name, default, class documenting it)`` of every flat parameter a method
        accepts, in the order :meth:`make_params` resolves them: the method's own
        fields, then those of the objects composed into it (for a method built on a
        two-frame method: the fields of ``flow_method``'s parameters, default the
        method's own choice).  The CLI builds its flags and help from it."""
        m = self.entry(method)
        defaults = m.defaults()
        if flow_method is not None and flow_method != getattr(defaults, "flow_method",
                                                              flow_method):
            defaults = self.make_params(m, flow_method=flow_method)
        return [(name, value, type(owner)) for name, value, owner in flat_fields(defaults)]


#: The two-frame flow methods (:func:`varflow.flow`).
FLOW = Registry("method", Method, "varflow.twoframe.methods", DEFAULT_METHOD)
#: The trajectory methods (:func:`varflow.track`).
TRACK = Registry("trajectory method", Tracker, "varflow.multiframe.methods", "rlr")
#: The frame-interpolation methods (:func:`varflow.interpolate`).
INTERPOLATE = Registry("interpolation method", Interpolator, "varflow.retime.methods",
                       "splat")

#: The restoration methods (:func:`varflow.denoise`).
RESTORE = Registry("restoration method", Restorer, "varflow.restore.methods", "nlbayes")

#: The repair stages of archival footage (:func:`varflow.restore_clip`).
REPAIR = Registry("repair stage", Repairer, "varflow.restore.methods", "dirt")

#: Every registry, in the order listings show them.
REGISTRIES = (FLOW, TRACK, INTERPOLATE, RESTORE, REPAIR)

METHODS = FLOW
TRACKERS = TRACK


def get_method(name: str) -> Method:
    """``FLOW.entry(name)``: a two-frame method by name (``ValueError`` if unknown)."""
    return FLOW.entry(name)


def get_tracker(name: str) -> Tracker:
    """``TRACK.entry(name)``: a trajectory method by name (``ValueError`` if unknown)."""
    return TRACK.entry(name)


def make_params(method: str | Method, params: Any = None, **overrides: Any) -> Any:
    """``FLOW.make_params``: a two-frame method's parameters (:meth:`Registry.make_params`)."""
    return FLOW.make_params(method, params, **overrides)


def make_track_params(method: str | Tracker, params: Any = None, **overrides: Any) -> Any:
    """``TRACK.make_params``: a trajectory method's parameters
    (:meth:`Registry.make_params`)."""
    return TRACK.make_params(method, params, **overrides)


def parameter_fields(entry: Entry, flow_method: str | None = None
                     ) -> list[tuple[str, Any, type]]:
    """The flat parameters of any registered entry (:meth:`Registry.fields`)."""
    for registry in REGISTRIES:
        if isinstance(entry, registry.entry_type):
            return registry.fields(entry, flow_method)
    raise ValueError(f"method: not a registered entry: {entry!r}")
