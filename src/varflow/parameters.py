"""Parameter objects: frozen dataclasses composed of smaller ones, and one way to change them.

Every method's parameters are a frozen dataclass.  Parts that several methods share
are *composed* as fields, not inherited: a tracker holds its two-frame energy in
``flow_params``, and a two-frame energy holds its optional terms (the tensor
regulariser, the sparse term, the matching stage) in typed fields.  A user still
names a parameter flatly — ``data_weight``, ``tensor_a``, ``link_weight`` — and
:func:`replace` finds the object that owns it:

1. a field of the object itself;
2. else a field of its first composed field (in field order) that has it, looked up
   the same way (so a name is routed as deep as it needs to go);
3. else :class:`ValueError` naming the field.

A class lists its composed fields in ``_COMPOSED`` (they may hold None); they are
not flat names themselves.  An object may declare
``_DEPENDENT = {"flow_method": "flow_params"}``: changing the key without the
dependent field resets the dependent field to ``None``, which the object's
``__post_init__`` fills with the new key's defaults (a new two-frame method
starts from its own parameters, not from those of the previous one).

:class:`Routed` gives a dataclass this ``replace`` as a method, and reads flat names
the same way (``energy.tensor_a`` is ``energy.tensor.tensor_a``); :func:`flat_fields`
lists the names a user may pass, in the order :func:`replace` resolves them.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator
from typing import Any

__all__ = ["Routed", "UnknownParameter", "replace", "flat_fields", "owner_of",
           "composed_fields"]


class UnknownParameter(ValueError):
    """A name that no parameter object of a composition owns (``.name`` holds it)."""

    def __init__(self, name: str, owner: str) -> None:
        super().__init__(f"{name}: not a parameter of {owner}")
        self.name = name


def _is_params(value: Any) -> bool:
    return dataclasses.is_dataclass(value) and not isinstance(value, type)


def _own(obj: Any) -> dict[str, dataclasses.Field]:
    return {f.name: f for f in dataclasses.fields(obj) if f.init}


def _composed_names(obj: Any) -> frozenset[str]:
    """The fields of ``obj`` that hold (or may hold) parameter objects: its class's
    ``_COMPOSED``, and any field that holds one."""
    declared = frozenset(getattr(type(obj), "_COMPOSED", ()))
    return declared | {name for name in _own(obj) if _is_params(getattr(obj, name))}


def composed_fields(obj: Any) -> list[tuple[str, Any]]:
    """The fields of ``obj`` that hold parameter objects, ``(name, value)`` in field order."""
    return [(name, getattr(obj, name)) for name in _own(obj)
            if _is_params(getattr(obj, name))]


def owner_of(obj: Any, name: str) -> Any | None:
    """The parameter object, ``obj`` or one composed into it, that a flat ``name``
    resolves to (the module's rules 1–2); None when nothing has it."""
    if name in _own(obj):
        return obj
    for _, value in composed_fields(obj):
        found = owner_of(value, name)
        if found is not None:
            return found
    return None


def flat_fields(obj: Any) -> Iterator[tuple[str, Any, Any]]:
    """Every name a user may pass to :func:`replace` on ``obj``, once each.

    Yields ``(name, value, owner)`` with ``owner`` the parameter object that holds
    it: the object's own fields first, then, field after field, those of each
    composed object that are not already named (the names :func:`replace` would
    route elsewhere are left out).  The fields that hold parameter objects (or
    None in their place, listed in a class's ``_COMPOSED``) are not flat names.
    """
    seen: set[str] = set()

    def walk(o: Any) -> Iterator[tuple[str, Any, Any]]:
        skip = _composed_names(o)
        for name in _own(o):
            if name not in seen and name not in skip:
                seen.add(name)
                yield name, getattr(o, name), o
        for _, value in composed_fields(o):
            yield from walk(value)

    yield from walk(obj)


def replace(obj: Any, **changes: Any) -> Any:
    """A copy of the frozen dataclass ``obj`` with ``changes``, each routed to the
    object that owns its name (module notes); validated again by every
    ``__post_init__`` on the way.

    Raises
    ------
    UnknownParameter
        A :class:`ValueError`, ``"<name>: not a parameter of <Class>"``, for a name
        nothing owns.
    """
    own = _own(obj)
    mine = {k: v for k, v in changes.items() if k in own}
    rest = {k: v for k, v in changes.items() if k not in own}
    for key, dependent in getattr(type(obj), "_DEPENDENT", {}).items():
        if key in mine and dependent not in mine and mine[key] != getattr(obj, key):
            mine[dependent] = None
    out = dataclasses.replace(obj, **mine) if mine else obj
    if not rest:
        return out
    groups: dict[str, dict[str, Any]] = {}
    parts = composed_fields(out)
    for name, value in rest.items():
        target = next((field for field, part in parts if owner_of(part, name) is not None),
                      None)
        if target is None:
            raise UnknownParameter(name, type(obj).__name__)
        groups.setdefault(target, {})[name] = value
    return dataclasses.replace(
        out, **{field: replace(getattr(out, field), **kv) for field, kv in groups.items()})


class Routed:
    """Mixin of a parameter dataclass: flat names are routed both ways (module notes).

    :meth:`replace` changes a name where it is owned; reading an attribute that is not
    a field of the object returns the field of the composed object that owns it
    (``energy.tensor_a`` is ``energy.tensor.tensor_a``; a tracker's ``data_weight``
    is its ``flow_params.data_weight``).
    """

    __slots__ = ()

    def __getattr__(self, name: str) -> Any:
        # only called when the ordinary lookup fails: never for the object's own fields
        if not name.startswith("_"):
            for f in dataclasses.fields(self):
                value = self.__dict__.get(f.name)
                if _is_params(value):
                    owner = owner_of(value, name)
                    if owner is not None:
                        return getattr(owner, name)
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    def replace(self, **changes: Any) -> Any:
        """A copy with ``changes``, each routed to the parameter object that owns its
        name (:func:`varflow.parameters.replace`)."""
        return replace(self, **changes)
