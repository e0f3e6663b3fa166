"""``--help`` in layers (issues 26 and 47).

``varflow flow --help`` shows the common options, the knobs that matter of the method
that will run (``--method NAME`` on the command line, the default method otherwise)
with their defaults, and every method with when to use it; every other parameter is
still a flag, listed by ``varflow methods NAME`` with symbol, default, range and unit.
"""

from __future__ import annotations

import argparse
import re

import pytest

from varflow import cli
from varflow.registry import METHODS, TRACKERS, parameter_fields


def help_text(capsys: pytest.CaptureFixture[str], *argv: str) -> str:
    """The printed ``--help`` of ``argv``, whitespace collapsed (wrapping removed)."""
    rc = cli.main([*argv, "--help"])
    out, err = capsys.readouterr()
    assert rc == 0, err
    return " ".join(out.split())


def flag_help(text: str, flag: str) -> str:
    """The help of one flag in a collapsed help text: from the flag to the next flag."""
    text = text[text.index("knobs of "):]  # not the usage line
    text = text.split(" methods (--method")[0]  # nor the list of methods
    no = "--no-" + flag[2:]
    head = rf" {re.escape(flag)}(?:, {re.escape(no)}| [A-Z]+) "
    m = re.search(head + r"(.*?)(?= --[a-z][a-z-]*[ ,]|$)", text)
    assert m, f"{flag} not in the help"
    return m.group(1)


def subparser(parser: argparse.ArgumentParser, *names: str) -> argparse.ArgumentParser:
    for name in names:
        action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
        parser = action.choices[name]
    return parser


def param_helps(parser: argparse.ArgumentParser) -> dict[str, str | None]:
    """``{field: help}`` of the parameter flags (None when hidden)."""
    out = {}
    for a in parser._actions:
        if a.dest.startswith("param__"):
            out[a.dest[len("param__"):]] = None if a.help == argparse.SUPPRESS else a.help
    return out


def knob_names(method: str, registry=METHODS) -> list[str]:
    return [name for name, _ in registry[method].knobs]


def test_flow_help_is_layered(capsys: pytest.CaptureFixture[str]) -> None:
    """Issue 47: the common options, the default method's knobs with when to change them,
    every method with when to use it; under 80 lines."""
    rc = cli.main(["flow", "--help"])
    raw = capsys.readouterr().out
    assert rc == 0 and len(raw.splitlines()) <= 80, len(raw.splitlines())
    text = " ".join(raw.split())
    assert "knobs of tvl1:" in text and "'varflow methods tvl1'" in text
    for name in METHODS:  # every method, with its "when to use it" line
        assert f" {name} {' '.join(METHODS[name].use.split())}" in text, name
    assert flag_help(text, "--n-warps").endswith("(default 4)")
    assert flag_help(text, "--data-weight").startswith("λ: higher follows the images")
    assert flag_help(text, "--data-weight").endswith("(default 15.0)")
    assert "--median-size" not in text and "--weighted-median-radius" not in text  # not knobs
    helps = param_helps(subparser(cli.build_parser(["flow"]), "flow"))
    shown = {k for k, v in helps.items() if v is not None}
    assert shown == set(knob_names("tvl1"))
    every = {name for m in METHODS for name, d, _ in parameter_fields(METHODS[m])
             if type(d) in (bool, int, float, str)}
    assert set(helps) == every and len(every) > 70  # every field is still a flag


def test_hidden_flags_still_work(tmp_path, capsys: pytest.CaptureFixture[str]) -> None:
    import numpy as np

    from varflow.io import read_flow, write_image

    rng = np.random.default_rng(0)
    img = (rng.random((24, 32)) * 255).astype(np.uint8)
    write_image(tmp_path / "a.png", img)
    write_image(tmp_path / "b.png", img)
    rc = cli.main(["flow", str(tmp_path / "a.png"), str(tmp_path / "b.png"), "-o",
                   str(tmp_path / "f.flo"), "--method", "tvl1-fast", "--median-size", "3", "-q"])
    assert rc == 0, capsys.readouterr().err
    assert read_flow(tmp_path / "f.flo").shape == (24, 32, 2)
    rc = cli.main(["flow", str(tmp_path / "a.png"), str(tmp_path / "b.png"), "-o",
                   str(tmp_path / "g.flo"), "--dictionary", "mod", "-q"])
    assert rc == 2 and "--dictionary is not a parameter of method 'tvl1'" in \
        capsys.readouterr().err


@pytest.mark.parametrize(("method", "n_warps", "data_weight"), [
    ("tvl1", 4, 15.0),
    ("tvl1-ld", 3, 15.0),
    ("tensor", 5, 40.0),
    ("sparse-1d", 5, 40.0),
])
def test_flow_help_with_method_gives_its_knobs_and_defaults(
    capsys: pytest.CaptureFixture[str], method: str, n_warps: int, data_weight: float,
) -> None:
    for argv in (("flow", "--method", method), ("flow", f"--method={method}")):
        text = help_text(capsys, *argv)
        assert f"knobs of {method}:" in text and f"'varflow methods {method}'" in text
        assert flag_help(text, "--data-weight").endswith(f"(default {data_weight})")
        if "n_warps" in knob_names(method):
            assert flag_help(text, "--n-warps").endswith(f"(default {n_warps})")
        for name in knob_names(method):
            assert f"--{name.replace('_', '-')}" in text, name


def test_help_after_the_flag_and_unknown_method(capsys: pytest.CaptureFixture[str]) -> None:
    rc = cli.main(["flow", "--help", "--method", "tvl1-ld"])
    text = " ".join(capsys.readouterr().out.split())
    assert rc == 0 and flag_help(text, "--n-warps").endswith("(default 3)")
    assert "--match-max-displacement" in text
    # an unknown name: the default method's knobs (the run itself reports the name)
    text = help_text(capsys, "flow", "--method", "nope")
    assert "knobs of tvl1:" in text and flag_help(text, "--n-warps").endswith("(default 4)")


@pytest.mark.parametrize("method", list(METHODS))
def test_every_flow_knob_states_the_method_default(method: str) -> None:
    """Against the registry: each shown flag is a knob and states the method's default."""
    own = {name: d for name, d, _ in parameter_fields(METHODS[method])}
    knobs = knob_names(method)
    assert knobs and set(knobs) <= set(own), method  # knobs are fields of the method
    for argv in (["flow", "--method", method], ["batch", "flow", "--method", method]):
        helps = param_helps(subparser(cli.build_parser(argv), *argv[:-2]))
        for name, text in helps.items():
            if name not in knobs:
                assert text is None, name
                continue
            assert text is not None and text.endswith(f"(default {own[name]})"), (name, text)


@pytest.mark.parametrize("method", list(TRACKERS))
def test_every_track_knob_states_the_tracker_default(method: str) -> None:
    own = {name: d for name, d, _ in parameter_fields(TRACKERS[method])}
    knobs = knob_names(method, TRACKERS)
    assert knobs and set(knobs) <= set(own), method
    for argv in (["track", "--method", method], ["batch", "track", "--method", method]):
        helps = param_helps(subparser(cli.build_parser(argv), *argv[:-2]))
        for name, text in helps.items():
            if name in knobs:
                assert text is not None and text.endswith(f"(default {own[name]})"), (name, text)
            else:
                assert text is None, name


def test_interpolators_have_knobs_that_are_fields() -> None:
    from varflow.retime.methods import INTERPOLATORS

    for name, entry in INTERPOLATORS.items():
        own = {f for f, _, _ in parameter_fields(entry)}
        assert entry.use and entry.knobs and {k for k, _ in entry.knobs} <= own, name


def test_bench_help_with_several_methods(capsys: pytest.CaptureFixture[str]) -> None:
    text = help_text(capsys, "bench", "middlebury", "--methods", "tvl1,tensor")
    assert "knobs of tvl1, tensor:" in text
    assert "(default 15.0; tensor: 40.0)" in flag_help(text, "--data-weight")
    assert "(default 4; tensor: 5)" in flag_help(text, "--n-warps")  # a knob of tvl1
    text = help_text(capsys, "bench", "trajectories", "--methods", "mfsf")
    assert "--link-weight" not in text  # rlr's, hidden for mfsf
    assert flag_help(text, "--subspace-weight").endswith("(default 10.0)")


def test_methods_name_fits_a_screen(capsys: pytest.CaptureFixture[str]) -> None:
    """``varflow methods tvl1``: one method, every parameter on a line, in under 60 lines,
    the knobs first, with symbol, default, range and unit."""
    assert cli.main(["methods", "tvl1"]) == 0
    out = capsys.readouterr().out
    lines = out.splitlines()
    assert len(lines) <= 60, len(lines)
    assert lines[0] == f"tvl1: {METHODS['tvl1'].use}"
    rows = [ln for ln in lines if re.match(r"^[* ] --", ln)]
    assert len(rows) == len(parameter_fields(METHODS["tvl1"]))
    assert [r.split()[1] for r in rows[:3]] == ["--data-weight", "--n-warps", "--grey"]
    data = next(r for r in rows if "--data-weight " in r).split()
    assert data[:7] == ["*", "--data-weight", "λ", "15.0", ">", "0", "1/intensity"]
    scale = next(r for r in rows if "--scale-factor " in r)
    assert re.search(r"η\s+0\.8\s+\(0, 1\)\s", scale)  # the range the check enforces
    median = next(r for r in rows if "--median-size " in r)
    assert "0, 1, odd" in median
    # a tracker: its own fields, the flow method's knobs, a pointer for the rest
    assert cli.main(["methods", "rlr"]) == 0
    out = capsys.readouterr().out
    assert "--link-weight" in out and "--median-size" not in out
    assert "parameters of its flow method (--flow-method, default tvl1): 'varflow methods tvl1'" \
        in out
    assert cli.main(["methods", "nope"]) == 2
    assert "unknown method 'nope'; available: tvl1," in capsys.readouterr().err


def test_field_range_agrees_with_the_check() -> None:
    """Every range shown is the one the parameter check enforces: a value just outside
    it is refused and the default inside it is accepted."""
    from varflow.cli._common import _field_range
    from varflow.registry import make_params

    m = METHODS["tvl1"]
    assert _field_range(m, "scale_factor", 0.8) == "(0, 1)"
    assert _field_range(m, "tv_step", 0.25) == "(0, 0.25]"
    assert _field_range(m, "grey", True) == "on/off"
    with pytest.raises(ValueError, match="scale_factor"):
        make_params("tvl1", scale_factor=1.0)
    assert _field_range(TRACKERS["rlr"], "init", "propagate") == "propagate, twoframe or zero"


HISTORY = re.compile(r"benchmarks/|HISTORY|\bmeasured\b|\btuned\b|\bon MPI-Sintel\b|"
                     r"varflow\.[a-z_]+\.[a-z_]")


@pytest.mark.parametrize("argv", [
    ("flow", "--help"), ("track", "--help"), ("retime", "--help"), ("interpolate", "--help"),
    ("video", "--help"), ("batch", "flow", "--help"), ("eval", "--help"),
    ("methods",), ("methods", "tvl1"), ("methods", "tvl1-ld"), ("methods", "rlr"),
    ("methods", "splat"), ("methods", "--params"),
])
def test_help_names_no_module_path_or_history(capsys, argv) -> None:
    rc = cli.main(list(argv))
    out = capsys.readouterr().out
    assert rc == 0
    found = HISTORY.search(out)
    assert found is None, out[max(found.start() - 80, 0):found.end() + 80]


def test_methods_params_table_unchanged(capsys: pytest.CaptureFixture[str]) -> None:
    """``varflow methods --params`` stays the full table of every method."""
    assert cli.main(["methods", "--params"]) == 0
    out = capsys.readouterr().out
    for name in (*METHODS, *TRACKERS):
        assert re.search(rf"^{re.escape(name)}\s", out, re.M), name
    assert re.search(r"^\s+n_warps\s+.*\s5\s", out, re.M)  # tensor's row


def test_plain_text_drops_the_sphinx_markup() -> None:
    from varflow.cli._common import plain_text

    text = ("see :func:`~varflow.ops.fusion.repair` and :mod:`varflow.multiframe.propagate`, "
            ":data:`FINAL_REPAIR_DISTANCES`, :py:attr:`x.y <varflow.x.y>`; ``ref ± 1`` only")
    assert plain_text(text) == ("see repair and propagate, "
                                "FINAL_REPAIR_DISTANCES, x.y; ref ± 1 only")
    assert plain_text(text, markdown=True) == (
        "see `repair` and `propagate`, `FINAL_REPAIR_DISTANCES`, `x.y`; "
        "`ref ± 1` only")


@pytest.mark.parametrize("argv", [("flow",), ("track",), ("bench", "trajectories")])
def test_help_has_no_sphinx_markup(capsys: pytest.CaptureFixture[str], argv: tuple) -> None:
    """The flags' help is read in a terminal: no ``:func:`...``` roles or double backticks."""
    text = help_text(capsys, *argv)
    assert not re.search(r":\w+:`|``", text), re.search(r".{40}(:\w+:`|``).{40}", text)


def test_methods_params_text_and_markdown_without_roles(
        capsys: pytest.CaptureFixture[str]) -> None:
    for argv in (["methods", "--params"], ["methods", "--params", "--markdown"]):
        assert cli.main(argv) == 0
        out = capsys.readouterr().out
        assert not re.search(r":\w+:`", out), argv
