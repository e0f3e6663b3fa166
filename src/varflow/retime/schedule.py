"""The retiming schedule: which source frames (and at what time between them) every
output frame is made of, in exact rational arithmetic.

Times are :class:`fractions.Fraction`, so rates such as ``24000/1001`` are exact and
a pass-through is decided by an exact integer test, not a float comparison.

New frame rate (``--fps F``)
    ``N`` source frames at rate ``R`` last ``N / R`` seconds; the output has
    ``M = round(N F / R)`` frames, rounding half up (``floor(N F / R + 1/2)``, so
    ``2.5 -> 3``), and at least one.  Output frame ``k`` (``k = 0 .. M - 1``) sits at
    time ``k / F``, i.e. at the source position ``s = k R / F``.
Slow motion (``--slowmo K``, an integer >= 2)
    ``K - 1`` new frames between every two source frames, played at the source
    rate: ``M = (N - 1) K + 1`` frames at ``s = k / K``.

Each output frame at position ``s``:

* ``s`` an integer ``<= N - 1``: source frame ``s`` passed through unchanged
  (bit-exact);
* ``s > N - 1`` (the end of the last frame's display interval): the last source
  frame, passed through;
* otherwise the pair ``(floor(s), floor(s) + 1)`` at ``t = s - floor(s)`` in
  ``(0, 1)``.

:meth:`Schedule.steps` groups consecutive output frames by what they need (one
source frame, or one pair with all its times), so that the motion of every pair is
estimated once for all its in-between frames.
"""

from __future__ import annotations

import itertools
import math
import numbers
from collections.abc import Iterator
from dataclasses import dataclass
from fractions import Fraction

__all__ = [
    "OutputFrame",
    "Schedule",
    "Step",
    "fps_schedule",
    "parse_rate",
    "retime_count",
    "round_half_up",
    "slowmo_schedule",
]

#: Largest denominator accepted for a rate given as a float.
_MAX_DENOMINATOR = 1_000_000


def round_half_up(x: Fraction) -> int:
    """``floor(x + 1/2)``: the nearest integer, halves rounded up (``2.5 -> 3``)."""
    return math.floor(x + Fraction(1, 2))


def parse_rate(value: str | float | Fraction | numbers.Rational, name: str = "fps") -> Fraction:
    """A positive frame rate as an exact fraction.

    Parameters
    ----------
    value : str, int, float or Fraction
        ``"24000/1001"``, ``"29.97"`` (taken as the decimal it spells, 2997/100),
        ``30``, ``Fraction(30000, 1001)``; a float is converted with a denominator of
        at most 10**6.
    name : str
        Used in the error message.

    Returns
    -------
    Fraction

    Raises
    ------
    ValueError
        When ``value`` is not a positive finite number.
    """
    try:
        if isinstance(value, str):
            rate = Fraction(value.strip())
        elif isinstance(value, numbers.Rational):
            rate = Fraction(value)
        else:
            f = float(value)
            if not math.isfinite(f):
                raise ValueError
            rate = Fraction(f).limit_denominator(_MAX_DENOMINATOR)
    except (TypeError, ValueError, ZeroDivisionError, OverflowError):
        raise ValueError(f"{name}: expected a positive number or a ratio such as 24000/1001, "
                         f"got {value!r}") from None
    if rate <= 0:
        raise ValueError(f"{name}: must be positive, got {value!r}")
    return rate


def retime_count(n_source: int, rate_in: Fraction, rate_out: Fraction) -> int:
    """Output frames of ``n_source`` frames retimed from ``rate_in`` to ``rate_out``.

    ``max(1, round_half_up(n_source * rate_out / rate_in))`` (the module notes).
    """
    return max(1, round_half_up(Fraction(n_source) * rate_out / rate_in))


@dataclass(frozen=True)
class OutputFrame:
    """One output frame of a schedule.

    Attributes
    ----------
    index : int
        Position in the output, 0-based.
    position : Fraction
        Source position ``s`` (in source frames).
    pair : int or None
        ``i`` of the pair ``(i, i + 1)`` it is interpolated in; None for a
        pass-through.
    t : Fraction
        Time in the pair, in ``(0, 1)``; 0 for a pass-through.
    source : int
        The source frame passed through; for an interpolated frame the nearer
        frame of its pair (``i`` for ``t < 1/2``, else ``i + 1``), used at a scene
        cut.
    """

    index: int
    position: Fraction
    pair: int | None
    t: Fraction
    source: int

    @property
    def passthrough(self) -> bool:
        """True when the frame is a source frame unchanged."""
        return self.pair is None


@dataclass(frozen=True)
class Step:
    """Consecutive output frames made of the same source material.

    Attributes
    ----------
    pair : int or None
        ``i`` of the pair ``(i, i + 1)``, or None for pass-through frames.
    source : int
        The source frame of pass-through frames; ``pair`` otherwise.
    frames : tuple of OutputFrame
        In output order; one pass-through frame may be repeated (a lower rate at the
        end of the clip), the frames of a pair have increasing ``t``.
    """

    pair: int | None
    source: int
    frames: tuple[OutputFrame, ...]

    @property
    def times(self) -> list[float]:
        """The ``t`` of the frames as floats (for :func:`varflow.interpolate`)."""
        return [float(f.t) for f in self.frames]


def _frame(k: int, s: Fraction, n_source: int) -> OutputFrame:
    last = n_source - 1
    if s >= last:
        return OutputFrame(k, s, None, Fraction(0), last)
    i = math.floor(s)
    t = s - i
    if t == 0:
        return OutputFrame(k, s, None, Fraction(0), i)
    return OutputFrame(k, s, i, t, i if t < Fraction(1, 2) else i + 1)


@dataclass(frozen=True)
class Schedule:
    """What every output frame of a retimed clip is made of.

    Attributes
    ----------
    n_source : int
        Source frames.
    rate_in, rate_out : Fraction
        Source and output frame rates (equal for slow motion).
    step : Fraction
        Source frames per output frame (``rate_in / rate_out``, or ``1 / K``).
    n_output : int
        Output frames.
    """

    n_source: int
    rate_in: Fraction
    rate_out: Fraction
    step: Fraction
    n_output: int

    def frame(self, k: int) -> OutputFrame:
        """Output frame ``k`` (0-based)."""
        if not 0 <= k < self.n_output:
            raise IndexError(f"output frame {k} out of range 0..{self.n_output - 1}")
        return _frame(k, k * self.step, self.n_source)

    def __iter__(self) -> Iterator[OutputFrame]:
        return (self.frame(k) for k in range(self.n_output))

    def __len__(self) -> int:
        return self.n_output

    def steps(self) -> Iterator[Step]:
        """The output frames grouped by pair (or pass-through source frame), in order.

        Yields
        ------
        Step
            Each pair appears at most once, with all its output frames.
        """
        def key(f: OutputFrame) -> tuple[bool, int]:
            return (f.pair is None, f.source if f.pair is None else f.pair)

        for (through, index), group in itertools.groupby(self, key=key):
            yield Step(None if through else index, index, tuple(group))

    @property
    def n_passthrough(self) -> int:
        """Output frames that are source frames unchanged."""
        return sum(f.passthrough for f in self)

    @property
    def pairs(self) -> list[int]:
        """The pairs ``i`` that have in-between frames, ascending."""
        return [s.pair for s in self.steps() if s.pair is not None]


def _check_n(n_source: int) -> int:
    if isinstance(n_source, bool) or not isinstance(n_source, numbers.Integral) or n_source < 1:
        raise ValueError(f"n_source: expected an integer >= 1, got {n_source!r}")
    return int(n_source)


def fps_schedule(n_source: int, rate_in: str | float | Fraction,
                 rate_out: str | float | Fraction) -> Schedule:
    """The schedule of a change of frame rate (``--fps``).

    Parameters
    ----------
    n_source : int
        Source frames (>= 1).
    rate_in, rate_out : str, float or Fraction
        Source and output rates (:func:`parse_rate`).

    Returns
    -------
    Schedule

    Examples
    --------
    >>> s = fps_schedule(24, 24, 60)
    >>> s.n_output, [str(f.position) for f in list(s)[:3]]
    (60, ['0', '2/5', '4/5'])
    """
    n = _check_n(n_source)
    r_in, r_out = parse_rate(rate_in, "input fps"), parse_rate(rate_out, "fps")
    return Schedule(n, r_in, r_out, r_in / r_out, retime_count(n, r_in, r_out))


def slowmo_schedule(n_source: int, factor: int, rate: str | float | Fraction = 25) -> Schedule:
    """The schedule of slow motion by an integer ``factor`` (``--slowmo``).

    Parameters
    ----------
    n_source : int
        Source frames (>= 1).
    factor : int
        ``K >= 2``: ``K - 1`` new frames between every two.
    rate : str, float or Fraction
        The source rate, which is also the output rate.

    Returns
    -------
    Schedule
        ``(N - 1) K + 1`` frames.
    """
    n = _check_n(n_source)
    if isinstance(factor, bool) or not isinstance(factor, numbers.Integral) or factor < 2:
        raise ValueError(f"slowmo: expected an integer >= 2, got {factor!r}")
    r = parse_rate(rate, "input fps")
    return Schedule(n, r, r, Fraction(1, int(factor)), (n - 1) * int(factor) + 1)
