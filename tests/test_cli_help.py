"""``--help`` states the defaults of the method that will run (issue 26).

Without ``--method`` the help gives every method's default where they differ
(``(default 4; tvl1-fast, tvl1-ld: 3; tensor, sparse-*: 5)``); with ``--method NAME`` on the
command line, only NAME's, and it hides the flags NAME does not have.
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
    text = text[text.index("method parameters:"):]  # not the usage line
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


def test_flow_help_gives_every_method_default_where_they_differ(
    capsys: pytest.CaptureFixture[str],
) -> None:
    text = help_text(capsys, "flow")
    assert "(default 4; tvl1-fast, tvl1-ld: 3; tensor, sparse-*: 5)" in flag_help(text, "--n-warps")
    assert "(default 15.0; tensor, sparse-*: 40.0)" in flag_help(text, "--data-weight")
    assert "(default True; tensor, sparse-*: False)" in flag_help(text, "--grey")
    assert "(default 0.8; tvl1-fast: 0.5)" in flag_help(text, "--scale-factor")
    assert "(default 40)" in flag_help(text, "--max-levels")  # one value for all
    dictionary = flag_help(text, "--dictionary")
    assert ("(default dct; sparse-1d, sparse-2x1d, sparse-2d, tvl1-sparse-1d, tvl1-sparse-2x1d, "
            "tvl1-sparse-2d: mod; methods: sparse-*, tvl1-sparse-*)") in dictionary


@pytest.mark.parametrize(("method", "n_warps", "data_weight", "grey"), [
    ("tvl1", 4, 15.0, True),
    ("tvl1-ld", 3, 15.0, True),
    ("tensor", 5, 40.0, False),
    ("sparse-1d", 5, 40.0, False),
])
def test_flow_help_with_method_gives_its_defaults(
    capsys: pytest.CaptureFixture[str], method: str, n_warps: int, data_weight: float,
    grey: bool,
) -> None:
    for argv in (("flow", "--method", method), ("flow", f"--method={method}")):
        text = help_text(capsys, *argv)
        assert flag_help(text, "--n-warps").endswith(f"(default {n_warps})")
        assert flag_help(text, "--data-weight").endswith(f"(default {data_weight})")
        assert flag_help(text, "--grey").endswith(f"(default {grey})")
        assert f"parameter dataclass of {method}," in text
    if not method.startswith("sparse"):
        assert "--dictionary" not in text  # not one of its flags: hidden


def test_help_after_the_flag_and_unknown_method(capsys: pytest.CaptureFixture[str]) -> None:
    rc = cli.main(["flow", "--help", "--method", "tensor"])
    text = " ".join(capsys.readouterr().out.split())
    assert rc == 0 and flag_help(text, "--n-warps").endswith("(default 5)")
    # an unknown name: every method's defaults (the run itself reports the name)
    text = help_text(capsys, "flow", "--method", "nope")
    assert "(default 4; tvl1-fast, tvl1-ld: 3; tensor, sparse-*: 5)" in flag_help(text, "--n-warps")


@pytest.mark.parametrize("method", list(METHODS))
def test_every_flow_flag_states_the_method_default(method: str) -> None:
    """Against the registry: each shown flag's default is the method's dataclass default."""
    # the energy's fields and those of its terms (a sparse method's ``tensor_a``...)
    own = {name: d for name, d, _ in parameter_fields(METHODS[method])}
    for argv in (["flow", "--method", method], ["batch", "flow", "--method", method]):
        helps = param_helps(subparser(cli.build_parser(argv), *argv[:-2]))
        for name, text in helps.items():
            if name not in own:
                assert text is None, name
                continue
            assert text is not None and text.endswith(f"(default {own[name]})"), (name, text)


@pytest.mark.parametrize("method", list(TRACKERS))
def test_every_track_flag_states_the_tracker_default(method: str) -> None:
    # a tracker composing a two-frame method has that method's fields too
    own = {name: d for name, d, _ in parameter_fields(TRACKERS[method])}
    for argv in (["track", "--method", method], ["batch", "track", "--method", method]):
        helps = param_helps(subparser(cli.build_parser(argv), *argv[:-2]))
        for name, text in helps.items():
            if name in own:
                assert text is not None
                assert text.endswith(f"(default {own[name]})"), (name, text)
            else:
                assert text is None, name


def test_track_and_batch_help_without_method(capsys: pytest.CaptureFixture[str]) -> None:
    # twoframe and chain take the default two-frame method's (tvl1's) defaults, rlr and
    # mfsf their TVL1_ENERGY (5 warps, the weighted median on every level)
    text = help_text(capsys, "track")
    assert "(default 0; twoframe, chain: 3)" in flag_help(text, "--weighted-median-levels")
    assert "(default 5; twoframe, chain: 4)" in flag_help(text, "--n-warps")
    text = help_text(capsys, "batch", "track")
    assert "(default 0; twoframe, chain: 3)" in flag_help(text, "--weighted-median-levels")
    text = help_text(capsys, "batch", "flow")
    assert "(default 4; tvl1-fast, tvl1-ld: 3; tensor, sparse-*: 5)" in flag_help(text, "--n-warps")
    text = help_text(capsys, "batch", "flow", "--method", "tvl1-ld")
    assert flag_help(text, "--n-warps").endswith("(default 3)")


def test_bench_help_with_methods(capsys: pytest.CaptureFixture[str]) -> None:
    text = help_text(capsys, "bench", "middlebury", "--methods", "tvl1,tensor")
    assert "(default 4; tensor: 5)" in flag_help(text, "--n-warps")
    text = help_text(capsys, "bench", "middlebury", "--methods", "tensor")
    assert flag_help(text, "--n-warps").endswith("(default 5)")
    text = help_text(capsys, "bench", "trajectories", "--methods", "mfsf")
    assert "--link-weight" not in text  # rlr's, hidden for mfsf
    assert flag_help(text, "--subspace-weight").endswith("(default 10.0)")
    assert flag_help(text, "--n-warps").endswith("(default 5)")


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
    assert plain_text(text) == ("see repair and varflow.multiframe.propagate, "
                                "FINAL_REPAIR_DISTANCES, x.y; ref ± 1 only")
    assert plain_text(text, markdown=True) == (
        "see `repair` and `varflow.multiframe.propagate`, `FINAL_REPAIR_DISTANCES`, `x.y`; "
        "`ref ± 1` only")


@pytest.mark.parametrize("argv", [("flow",), ("track",), ("bench", "trajectories")])
def test_help_has_no_sphinx_markup(capsys: pytest.CaptureFixture[str], argv: tuple) -> None:
    """The flags' help is read in a terminal: no ``:func:`...``` roles or double backticks."""
    text = help_text(capsys, *argv)
    assert not re.search(r":\w+:`|``", text), re.search(r".{40}(:\w+:`|``).{40}", text)
    if argv[0] == "track":  # a role became its name: (:func:`varflow.ops.fusion.repair`)
        assert "(varflow.ops.fusion.repair)" in flag_help(text, "--final-repair")


def test_methods_params_text_and_markdown_without_roles(
        capsys: pytest.CaptureFixture[str]) -> None:
    for argv in (["methods", "--params"], ["methods", "--params", "--markdown"]):
        assert cli.main(argv) == 0
        out = capsys.readouterr().out
        assert not re.search(r":\w+:`", out), argv
