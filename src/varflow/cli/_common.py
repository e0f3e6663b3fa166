"""Pieces every ``varflow`` command shares.

The parser class (one-line usage errors), the method-parameter flags generated from
the parameter dataclasses (help with each method's defaults), the progress bar, the
checks of output paths and the one-line error messages.  Nothing here runs a method.
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import math
import re
import sys
import textwrap
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, NoReturn

import numpy as np

from ..registry import METHODS, TRACKERS, get_method, parameter_fields

__all__ = ["PROG", "method_card", "methods_epilog", "parameter_rows", "parameter_table"]

log = logging.getLogger("varflow.cli")

PROG = "varflow"
_PARAM_PREFIX = "param__"


class _CommandError(Exception):
    """An error the CLI reports as its message alone (no exception type)."""


class _UsageError(_CommandError):
    """Raised by the parser instead of printing usage and exiting."""


class MissingExtraError(_CommandError):
    """A command needs packages of an optional extra that are not installed."""


class _HelpFormatter(argparse.HelpFormatter):
    """argparse's formatter, except that text already laid out in lines (a list of
    methods, each line indented) keeps its lines, each wrapped with a hanging indent."""

    def _fill_text(self, text: str, width: int, indent: str) -> str:
        if "\n  " not in text:
            return super()._fill_text(text, width, indent)
        out = []
        for line in text.splitlines():
            body = line.lstrip(" ")
            hang = len(line) - len(body)
            m = re.match(r"(\S+\s{2,})", body) if hang else None
            sub = " " * (hang + (len(m.group(1)) if m else 2)) if hang else ""
            out.append(textwrap.fill(body, width, initial_indent=indent + " " * hang,
                                     subsequent_indent=indent + sub) if body else "")
        return "\n".join(out)


class _Parser(argparse.ArgumentParser):
    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("formatter_class", _HelpFormatter)
        super().__init__(*args, **kwargs)

    def error(self, message: str) -> NoReturn:  # one line instead of usage + message
        raise _UsageError(f"{message} (see '{self.prog} --help')")


# --------------------------------------------------------------------------- parameters


@dataclasses.dataclass(frozen=True)
class _FieldDoc:
    name: str
    symbol: str
    meaning: str


_SYMBOL = re.compile(
    r"^(?P<sym>(?:[^\W\d_]{1,2}|[^\x00-\x7f]{1,2})(?:_[A-Za-z]{1,4})?)"
    r"(?:,\s+|\s+(?=of\b))(?P<rest>.*)$",
    re.S,
)


def _is_header(lines: list[str], i: int) -> bool:
    """True if ``lines[i]`` is a numpydoc section title (the next line is dashes)."""
    return i + 1 < len(lines) and set(lines[i + 1].strip()) == {"-"}


def _field_docs(cls: type) -> dict[str, _FieldDoc]:
    """Parse the numpydoc ``Attributes`` sections of a dataclass and its bases.

    Returns ``{field: _FieldDoc(name, symbol, meaning)}``; ``symbol`` is the paper
    symbol when the description starts with one (``"λ, weight of ..."`` or
    ``"c of the ..."``), and ``meaning`` drops "Default ..." sentences (the default
    is taken from the dataclass itself, the reasons belong to the docs) and those
    pointing to the benchmarks' history.
    """
    out: dict[str, _FieldDoc] = {}
    for klass in reversed(cls.__mro__):
        doc = klass.__dict__.get("__doc__") or ""
        lines = doc.expandtabs().splitlines()
        in_attrs = False
        current: str | None = None
        buf: dict[str, list[str]] = {}
        for i, line in enumerate(lines):
            stripped = line.strip()
            if stripped == "Attributes" and _is_header(lines, i):
                in_attrs = True
                continue
            if not in_attrs or set(stripped) == {"-"}:
                continue
            indent = len(line) - len(line.lstrip())
            m = re.match(r"^(\w+)\s*:", stripped)
            if m and indent <= 4 and stripped:
                current = m.group(1)
                buf[current] = []
            elif stripped and indent <= 4 and _is_header(lines, i):
                in_attrs = False  # next section
                current = None
            elif current is not None and stripped:
                buf[current].append(stripped)
        for name, parts in buf.items():
            sentences = re.split(r"(?<=\.)\s+", " ".join(parts))
            text = " ".join(t for t in sentences if t and not t.startswith("Default")
                            and "benchmarks/" not in t).strip()  # no history in help
            sym = ""
            m = _SYMBOL.match(text)
            if m:
                sym = m.group("sym")
                if text[len(sym)] == ",":  # "λ, weight of ..." -> "Weight of ..."
                    text = m.group("rest").strip()
                    text = text[:1].upper() + text[1:]
            out[name] = _FieldDoc(name, sym, text)
    return out


_ROLE = re.compile(r":(?:\w+:)?\w+:`(~?)([^`<]*?)(?:\s*<[^`]*>)?`")
_LITERAL = re.compile(r"``([^`]+)``")


def plain_text(text: str, markdown: bool = False) -> str:
    """A docstring fragment without its reStructuredText markup, for the terminal.

    A cross-reference becomes the last component of its target
    (``:func:`~varflow.ops.fusion.repair``` and ``:func:`varflow.ops.fusion.repair```
    both ``repair``: help names no module paths); literals lose their double
    backticks.  With ``markdown`` both become Markdown code spans.
    """
    def role(m: re.Match) -> str:
        name = m.group(2).strip()
        if "<" not in m.group(0):  # no explicit title: the target's last component
            name = name.rsplit(".", 1)[-1]
        return f"`{name}`" if markdown else name

    text = _ROLE.sub(role, text)
    return _LITERAL.sub(r"`\1`" if markdown else r"\1", text)


@dataclasses.dataclass
class _Param:
    name: str
    type: type
    default: Any  # of the first method that has the field
    owners: list[str]
    doc: _FieldDoc | None
    defaults: dict[str, Any] = dataclasses.field(default_factory=dict)  # per owner

    @property
    def flag(self) -> str:
        return "--" + self.name.replace("_", "-")


def _collect_params(registry: Mapping[str, Any] = METHODS) -> dict[str, _Param]:
    """All scalar fields of all registered methods' parameter classes, in registry order.

    A tracker that composes a two-frame method (``twoframe``, ``chain``) offers that
    method's fields too (:func:`varflow.registry.parameter_fields`).  Every field
    records the methods that have it (``owners``) and each one's default
    (``defaults``).
    """
    params: dict[str, _Param] = {}
    for mname, method in registry.items():
        docs: dict[type, dict[str, _FieldDoc]] = {}
        for name, default, owner in parameter_fields(method):
            if name in params:
                params[name].owners.append(mname)
                params[name].defaults[mname] = default
                continue
            kind = type(default)
            if kind not in (bool, int, float, str):
                log.debug("no CLI flag for %s.%s (type %s)", mname, name, kind.__name__)
                continue
            if owner not in docs:
                docs[owner] = _field_docs(owner)
            params[name] = _Param(name, kind, default, [mname], docs[owner].get(name),
                                  {mname: default})
    return params


def chosen_methods(argv: Sequence[str] | None, registry: Mapping[str, Any]) -> list[str] | None:
    """The methods of ``registry`` named by ``--method`` / ``--methods`` in ``argv``.

    Used to show those methods' defaults in ``--help``.  None when ``argv`` names
    no method of ``registry`` (then the help gives every method's default).
    """
    names: list[str] = []
    tokens = list(argv or ())
    for k, tok in enumerate(tokens):
        if tok == "--":
            break
        for opt in ("--method", "--methods"):
            if tok == opt and k + 1 < len(tokens):
                names += _split_list(tokens[k + 1])
            elif tok.startswith(opt + "="):
                names += _split_list(tok[len(opt) + 1:])
    chosen = [n for n in dict.fromkeys(names) if n in registry]
    return chosen or None


def _method_names(names: Sequence[str], registry: Mapping[str, Any]) -> str:
    """``names`` joined by commas, a whole family written ``sparse-*``.

    A family is every registered name that starts with the same ``prefix-`` (at
    least two of them; ``tvl1-`` or ``tvl1-sparse-`` for ``tvl1-sparse-1d``); it is
    abbreviated only when all its members are in ``names``, by the shortest such
    prefix.
    """
    out: list[str] = []
    done: set[str] = set()
    for n in names:
        if n in done:
            continue
        parts = n.split("-")
        for k in range(1, len(parts)):
            prefix = "-".join(parts[:k]) + "-"
            family = [m for m in registry if m.startswith(prefix)]
            if len(family) >= 2 and set(family) <= set(names):
                out.append(prefix + "*")
                done.update(family)
                break
        else:
            out.append(n)
            done.add(n)
    return ", ".join(out)


def _defaults_text(p: _Param, methods: Sequence[str], registry: Mapping[str, Any]) -> str:
    """``"default 4; tvl1-*: 3; tensor, sparse-*: 5"`` over ``methods`` that have ``p``.

    The first group is the default of the first of ``methods`` having the field;
    the others follow in registry order.  ``"; methods: ..."`` is added when only
    some of ``methods`` have the field.
    """
    owners = [m for m in methods if m in p.defaults]
    groups: dict[str, tuple[Any, list[str]]] = {}
    for m in owners:
        value = p.defaults[m]
        groups.setdefault(repr(value), (value, []))[1].append(m)
    (first, _), *others = groups.values()
    text = f"default {first}"
    for value, names in others:
        text += f"; {_method_names(names, registry)}: {value}"
    if len(owners) != len(methods):
        text += f"; methods: {_method_names(owners, registry)}"
    return text


def _knobs(methods: Sequence[str], registry: Mapping[str, Any]) -> dict[str, str]:
    """``{field: when to change it}`` of the knobs of ``methods``, first mention wins."""
    out: dict[str, str] = {}
    for m in methods:
        for name, hint in registry[m].knobs:
            out.setdefault(name, hint)
    return out


def _add_param_flags(
    parser: argparse.ArgumentParser,
    params: dict[str, _Param],
    registry: Mapping[str, Any] = METHODS,
    chosen: Sequence[str] | None = None,
) -> None:
    """Add one flag per parameter field; ``--help`` shows the knobs that matter.

    Every field of every method of ``registry`` is accepted as ``--field-name``;
    the help lists only the knobs (:attr:`~varflow.registry.Entry.knobs`) of the
    ``chosen`` methods (of the registry's default method when none is chosen),
    each with when to change it and its default, and points to ``varflow methods
    NAME`` for the full table.

    Parameters
    ----------
    parser : ArgumentParser
    params : dict
        From :func:`_collect_params` of ``registry``.
    registry : Registry
        :data:`~varflow.registry.METHODS`, :data:`~varflow.registry.TRACKERS`,
        :data:`~varflow.registry.INTERPOLATORS` or :data:`~varflow.registry.RESTORE`.
    chosen : sequence of str, optional
        Methods named on the command line (:func:`chosen_methods`).
    """
    methods = list(chosen) if chosen else [getattr(registry, "default", next(iter(registry)))]
    knobs = _knobs(methods, registry)
    which = _method_names(methods, registry)
    first = methods[0]
    description = (f"The parameters worth changing for {which}; every other parameter is a "
                   f"flag too (--field-name VALUE), listed by 'varflow methods {first}'. "
                   "Only the flags you give are changed.")
    group = parser.add_argument_group(f"knobs of {which}", description)
    order = [params[k] for k in knobs if k in params]
    for p in order + [q for q in params.values() if q.name not in knobs]:
        text: str = argparse.SUPPRESS
        if p.name in knobs and any(m in p.defaults for m in methods):
            sym = f"{p.doc.symbol}: " if p.doc and p.doc.symbol and not \
                knobs[p.name].startswith(p.doc.symbol) else ""
            text = f"{sym}{knobs[p.name]} ({_defaults_text(p, methods, registry)})"
            text = text.replace("%", "%%")
        kwargs: dict[str, Any] = {"dest": _PARAM_PREFIX + p.name, "default": argparse.SUPPRESS,
                                  "help": text}
        if p.type is bool:
            group.add_argument(p.flag, action=argparse.BooleanOptionalAction, **kwargs)
        else:
            group.add_argument(p.flag, type=p.type, metavar=p.type.__name__.upper(), **kwargs)


def methods_epilog(registry: Mapping[str, Any], option: str = "--method") -> str:
    """The ``--help`` epilog: every method of ``registry`` with when to use it."""
    width = max(len(n) for n in registry)
    lines = [f"methods ({option} NAME; 'varflow methods NAME' lists its parameters):"]
    for name, entry in registry.items():
        lines.append(f"  {name:<{width}}  {entry.use or entry.description}")
    return "\n".join(lines)


def _given_params(args: argparse.Namespace) -> dict[str, Any]:
    return {k[len(_PARAM_PREFIX):]: v for k, v in vars(args).items() if k.startswith(_PARAM_PREFIX)}


def _params_note(overrides: Mapping[str, Any]) -> str:
    """``"; parameters changed: a=1, b=2"`` for a benchmark header ("" when none)."""
    if not overrides:
        return ""
    return "; parameters changed: " + ", ".join(f"{k}={v}" for k, v in sorted(overrides.items()))


def _own_params(args: argparse.Namespace, entry: Any, kind: str) -> dict[str, Any]:
    """The parameter flags given on the command line; each must be a field of ``entry``
    (for a tracker composing a two-frame method, or of its ``--flow-method``'s
    parameters)."""
    given = _given_params(args)
    own = {name for name, _, _ in parameter_fields(entry, given.get("flow_method"))}
    for name in given:
        if name not in own:
            flag = "--" + name.replace("_", "-")
            raise ValueError(f"{flag} is not a parameter of {kind} {entry.name!r}")
    return given


def _entry(method: str) -> Any:
    """The registered entry named ``method``, of any kind (two-frame flow first)."""
    from ..registry import INTERPOLATE, REPAIR, RESTORE

    if method in TRACKERS:
        return TRACKERS[method]
    if method in INTERPOLATE:
        return INTERPOLATE[method]
    if method in RESTORE:
        return RESTORE[method]
    if method in REPAIR:
        return REPAIR[method]
    return get_method(method)


_RANGE = re.compile(r"(?:must be|expected)\s+(?:a finite number |an integer |one of )?(.*?),"
                    r" got ")


def _field_range(entry: Any, name: str, default: Any) -> str:
    """The values a field accepts, as its check states them (``"(0, 1)"``, ``">= 1"``).

    Found by giving the method's parameter check a value no field accepts (NaN, or
    an unknown word) and reading the range from its message, so the table and the
    check cannot disagree; "" when the check takes any value.
    """
    from ..registry import REGISTRIES

    if isinstance(default, bool):
        return "on/off"
    registry = next(r for r in REGISTRIES if r.get(entry.name) is entry)
    probe: Any = "\x00?" if isinstance(default, str) else float("nan")
    try:
        registry.make_params(entry, **{name: probe})
    except ValueError as exc:
        text = str(exc)
        if "unknown two-frame method" in text:
            return "flow method"
        m = _RANGE.search(text)
        if m:
            rng = m.group(1).replace("'", "").replace(" or an odd integer", ", odd")
            return rng[3:] if rng.startswith("in ") else rng
    return ""


_UNITS = (  # (pattern in a field's description, unit shown), first match wins
    (r"pixels per pixel", "px/px"),
    (r"1/intensity units", "1/intensity"),
    (r"1/pixel²", "1/px²"),
    (r"\bpixels²", "px²"),
    (r"intensity units", "intensity"),
    (r"(?:,|\bin) pixels\b|\(pixels\)|\bpixels\.$", "px"),
)


def _field_units(meaning: str) -> str:
    """The unit a field's description states in one of the usual phrasings ("" if none)."""
    first = re.split(r"(?<=\.)\s", meaning, maxsplit=1)[0]
    for pattern, unit in _UNITS:
        if re.search(pattern, first):
            return unit
    return ""


def flag_of(method: str, field: str) -> str:
    """The command-line spelling of a parameter: ``--field-name``, or for a repair
    stage of ``varflow restore`` ``--set STAGE.field=``."""
    from ..registry import REPAIR

    if method in REPAIR:
        return f"--set {method}.{field}="
    return "--" + field.replace("_", "-")


def parameter_rows(method: str) -> list[tuple[str, str, str, str]]:
    """The rows of a method's parameter table: ``(name, symbol, repr(default), meaning)``.

    Parameters
    ----------
    method : str
        A registered two-frame, trajectory, interpolation or restoration method name.

    Returns
    -------
    list of (str, str, str, str)
        Every field :func:`varflow.registry.parameter_fields` gives, in its order;
        ``symbol`` the paper symbol of the field's docstring ("" when it has none).
    """
    m = _entry(method)
    docs: dict[type, dict[str, _FieldDoc]] = {}
    rows = []
    for name, default, owner in parameter_fields(m):
        if owner not in docs:
            docs[owner] = _field_docs(owner)
        d = docs[owner].get(name)
        rows.append((name, d.symbol if d and d.symbol else "", repr(default),
                     d.meaning if d else ""))
    return rows


def parameter_table(method: str, markdown: bool = False) -> str:
    """Table of a method's parameters: name, CLI flag, paper symbol, default, meaning.

    Parameters
    ----------
    method : str
        A registered two-frame, trajectory, interpolation or restoration method name.
    markdown : bool
        A Markdown table instead of aligned text.

    Returns
    -------
    str
    """
    rows = parameter_rows(method)
    if markdown:
        lines = ["| parameter (`--flag`) | symbol | default | meaning |", "|---|---|---|---|"]
        for name, sym, default, meaning in rows:
            flag = flag_of(method, name)
            meaning = plain_text(meaning, markdown=True).replace("|", "\\|")
            lines.append(f"| `{name}` (`{flag}`) | {sym or '—'} | `{default}` | {meaning} |")
        return "\n".join(lines)
    wn = max(len(r[0]) for r in rows)
    ws = max(len(r[1]) for r in rows)
    wd = max(len(r[2]) for r in rows)
    return "\n".join(
        f"  {n:<{wn}}  {s or '-':<{ws}}  {d:>{wd}}  {plain_text(t)}" for n, s, d, t in rows
    )


def method_card(method: str, width: int | None = None) -> str:
    """One method for the terminal: what it is for, then every parameter on one line.

    The rows give the flag, the paper symbol, the default, the accepted range, the
    unit and the first sentence of the description, cut to ``width`` columns (the
    terminal's by default); the knobs (:attr:`~varflow.registry.Entry.knobs`)
    come first, marked ``*``.

    Parameters
    ----------
    method : str
        A registered two-frame, trajectory, interpolation or restoration method name.
    width : int, optional
        Line width; the terminal's (``COLUMNS``), at least 80, by default.

    Returns
    -------
    str
    """
    import shutil

    from ..registry import REPAIR

    m = _entry(method)
    if width is None:
        width = max(80, shutil.get_terminal_size((100, 24)).columns)
    knobs = [k for k, _ in m.knobs]
    rows = parameter_rows(method)
    fields = parameter_fields(m)
    defaults = {name: default for name, default, _ in fields}
    flow_method = defaults.get("flow_method") if m.name not in METHODS else None
    inherited: set[str] = set()
    if isinstance(flow_method, str) and flow_method in METHODS:  # composes a flow method
        inherited = {name for name, _, _ in parameter_fields(METHODS[flow_method])}
        inherited -= set(knobs) | {name for name, _, owner in fields
                                   if owner is type(m.defaults())}
        rows = [r for r in rows if r[0] not in inherited]
    rows.sort(key=lambda r: knobs.index(r[0]) if r[0] in knobs else len(knobs))
    table = []
    for name, sym, default, meaning in rows:
        text = plain_text(meaning)
        first = re.split(r"(?<=\.)\s", text, maxsplit=1)[0].rstrip(".")
        first = re.sub(r"\s*\([^()]*\)", "", first)  # the gist, without the asides
        table.append(("*" if name in knobs else " ", flag_of(m.name, name),
                      sym or "-", default, _field_range(m, name, defaults[name]) or "any",
                      _field_units(text) or "-", first))
    head = ("", "flag", "symbol", "default", "range", "unit", "meaning")
    cols = [max(len(r[k]) for r in [head, *table]) for k in range(6)]
    lines = [f"{m.name}: {m.use}" if m.use else m.name,
             textwrap.fill(f"How: {plain_text(m.description)}.", width),
             f"* = the knobs worth changing; every flag goes after 'varflow COMMAND --method "
             f"{m.name}'." if m.name not in REPAIR else
             f"* = the knobs worth changing; set with 'varflow restore --{m.name} --set "
             f"{m.name}.FIELD=VALUE'.", ""]
    for r in [head, *table]:
        line = (f"{r[0]} {r[1]:<{cols[1]}}  {r[2]:<{cols[2]}}  {r[3]:>{cols[3]}}  "
                f"{r[4]:<{cols[4]}}  {r[5]:<{cols[5]}}  ")
        rest = max(width - len(line), 30)  # a narrow terminal wraps rather than lose it
        tail = r[6] if len(r[6]) <= rest else r[6][:rest - 1] + "…"
        lines.append((line + tail).rstrip())
    if inherited:
        lines.append(f"  and the {len(inherited)} parameters of its flow method "
                     f"(--flow-method, default {flow_method}): 'varflow methods {flow_method}'")
    return "\n".join(lines)


# --------------------------------------------------------------------------- helpers


class _Progress:
    """A tqdm bar on stderr fed by ``callback(done, total)``; off with --quiet or no TTY."""

    def __init__(self, desc: str, quiet: bool, unit: str = "warp") -> None:
        from tqdm import tqdm

        enabled = not quiet and sys.stderr.isatty()
        self.bar = tqdm(total=None, desc=desc, unit=unit, file=sys.stderr, disable=not enabled,
                        leave=False)

    def __call__(self, done: int, total: int) -> None:
        if self.bar.total != total:
            self.bar.total = total
        self.bar.update(done - self.bar.n)

    def __enter__(self) -> _Progress:
        return self

    def __exit__(self, *exc: object) -> None:
        self.bar.close()


def _compile_notice(method: str, quiet: bool, entry: Any = None) -> None:
    """Say on stderr that this run compiles the kernels, when Numba's cache is cold.

    Only when :func:`varflow._jit.kernels_cached` is sure they are not cached (the
    first run of ``method`` on this machine); nothing with ``--quiet``.  ``entry``: a
    registered entry whose kernels come on top of those of ``method``, its flow
    method (a restoration method).
    """
    if quiet:
        return
    from .._jit import compile_seconds, kernels_cached

    cold = kernels_cached(method) is False
    seconds = (compile_seconds(method) or 0) if cold else 0
    if entry is not None and kernels_cached(kernels=entry.kernels) is False:
        cold = True
        seconds += entry.compile_seconds or 0
    if cold:
        about = f", about {seconds} s" if seconds else ""
        print(f"{PROG}: compiling kernels, once per machine{about}", file=sys.stderr,
              flush=True)


#: The files one command line reads and writes, ``{resolved path: option}``: two
#: outputs (or an output and an input) on one file are refused before any work
#: instead of the later write silently replacing the earlier.  Reset by ``main``.
_CLAIMED: dict[Path, str] = {}


def _reset_claims() -> None:
    _CLAIMED.clear()


def _claim(path: Path, what: str) -> None:
    """Record ``path`` as the output of option ``what``; refuse a file already named."""
    key = path.resolve()
    other = _CLAIMED.get(key)
    if other is not None:
        raise ValueError(f"{what}: {path} is also {other}; give each output a file of its own")
    _CLAIMED[key] = f"the {what} output"


def _claim_inputs(*items: tuple[str | None, str]) -> None:
    """Record inputs (``(path, label)``, files or folders) so that no output replaces them."""
    for path, label in items:
        if path is not None and Path(path).exists():
            _CLAIMED.setdefault(Path(path).resolve(), f"the input {label}")


def _check_output(path: str, suffixes: Sequence[str] | None, what: str) -> Path:
    """Fail before any work when an output cannot be written.

    Also refuses an output path that another output or an input of the same
    command line already names (:func:`_claim`).
    """
    p = Path(path)
    if suffixes is not None and p.suffix.lower() not in suffixes:
        allowed = " or ".join(suffixes) if len(suffixes) < 3 else \
            ", ".join(suffixes[:-1]) + f" or {suffixes[-1]}"
        raise ValueError(f"{what}: {p} must end in {allowed}")
    if suffixes is None:
        from PIL import Image

        if p.suffix.lower() not in Image.registered_extensions():
            raise ValueError(f"{what}: {p} has no known image extension (use .png)")
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.is_dir():
        raise FileNotFoundError(2, f"{what}: directory does not exist", str(parent))
    if p.is_dir():
        raise IsADirectoryError(21, f"{what}: is a directory", str(p))
    _claim(p, what)
    return p


def _max_radius(value: float | None) -> float | None:
    if value is not None and not (math.isfinite(value) and value > 0):
        raise ValueError(f"--max-radius: must be positive, got {value}")
    return value


def _magnitude(flow: np.ndarray) -> np.ndarray:
    mag = np.hypot(flow[..., 0], flow[..., 1])
    return mag[np.isfinite(mag)]


def _to_uint8(image: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(np.asarray(image, np.float64) * 255.0), 0, 255).astype(np.uint8)


def rate_arg(text: str) -> Any:
    """argparse ``type`` of a frame rate: a positive number or ratio, as a Fraction."""
    from ..retime.schedule import parse_rate

    try:
        return parse_rate(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected a positive rate such as 60, 29.97 or 24000/1001, got {text!r}"
        ) from None


def int_at_least(minimum: int) -> Callable[[str], int]:
    """argparse ``type`` of an integer of at least ``minimum``."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"expected an integer >= {minimum}, got {text!r}") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"must be an integer >= {minimum}, got {value}")
        return value

    return parse


def _split_list(text: str) -> list[str]:
    return [t.strip() for t in text.split(",") if t.strip()]



def flag_names(message: str, args: argparse.Namespace | None) -> str:
    """``message`` with a leading parameter field (``"data_weight: ..."``) written as
    the flag the user gave (``"--data-weight: ..."``)."""
    if args is None:
        return message
    m = re.match(r"^([a-z][a-z0-9_]*): ", message)
    if m and m.group(1) in _given_params(args):
        return "--" + m.group(1).replace("_", "-") + message[len(m.group(1)):]
    return message


def _one_line(exc: BaseException) -> str:
    if isinstance(exc, OSError) and exc.strerror and exc.filename is not None:
        msg = f"{exc.strerror}: {exc.filename}"
        if exc.filename2 is not None:
            msg += f" -> {exc.filename2}"
    else:
        msg = str(exc) or type(exc).__name__
    if not isinstance(exc, ValueError | OSError | _CommandError):
        msg = f"{type(exc).__name__}: {msg}"
    return " ".join(msg.split())


def _fail(message: str) -> int:
    print(f"{PROG}: error: {message}", file=sys.stderr)
    return 2
