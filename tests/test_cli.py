"""End-to-end tests of the ``varflow`` command line (in-process and as a real script)."""

from __future__ import annotations

import dataclasses
import io
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import varflow
from varflow import cli, registry
from varflow.evaluation.metrics import evaluate
from varflow.generators.pairs import synthetic_pair
from varflow.io import read_flo, read_flow, read_image, write_flo, write_image
from varflow.twoframe.coarse_to_fine import CoarseToFineParams
from varflow.viz import flow_to_color, flow_to_color_with_legend

SHAPE = (96, 128)
# Measured AEE of default tvl1 on this pair (uint8 frames): 0.064 px.
AEE_BOUND = 0.15


def run(capsys: pytest.CaptureFixture[str], *args: object) -> tuple[int, str, str]:
    """Call ``cli.main`` in-process; return (exit code, stdout, stderr)."""
    rc = cli.main([str(a) for a in args])
    out, err = capsys.readouterr()
    return rc, out, err


def assert_one_line_error(rc: int, err: str, *needles: str) -> None:
    assert rc == 2
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("varflow: error: "), err
    assert "Traceback" not in err
    for n in needles:
        assert n in lines[0], (n, err)


def to_uint8(image: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(np.asarray(image, np.float64) * 255.0), 0, 255).astype(np.uint8)


@pytest.fixture(scope="module")
def pair(tmp_path_factory: pytest.TempPathFactory) -> dict:
    """A smooth synthetic motion (magnitude 2) saved as PNGs, with the exact flow."""
    d = tmp_path_factory.mktemp("pair")
    f0, f1, gt = synthetic_pair("smooth", shape=SHAPE, magnitude=2.0, seed=1)
    f0, f1 = to_uint8(f0), to_uint8(f1)
    write_image(d / "frame0.png", f0)
    write_image(d / "frame1.png", f1)
    write_flo(d / "gt.flo", gt)
    return {"dir": d, "f0": d / "frame0.png", "f1": d / "frame1.png", "gt": gt,
            "gt_path": d / "gt.flo", "frames": (f0, f1)}


@pytest.fixture(scope="module")
def estimated(pair: dict) -> dict:
    """One default ``varflow flow`` run with a colour PNG, shared by several tests."""
    out, png = pair["dir"] / "est.flo", pair["dir"] / "est_colour.png"
    buf_out, buf_err = io.StringIO(), io.StringIO()
    saved = sys.stdout, sys.stderr
    sys.stdout, sys.stderr = buf_out, buf_err
    try:
        rc = cli.main(["flow", str(pair["f0"]), str(pair["f1"]), "-o", str(out), "--png", str(png)])
    finally:
        sys.stdout, sys.stderr = saved
    return {"rc": rc, "stdout": buf_out.getvalue(), "stderr": buf_err.getvalue(), "flo": out,
            "png": png}


# ----------------------------------------------------------------------------- flow


def test_flow_writes_accurate_flo(pair: dict, estimated: dict) -> None:
    assert estimated["rc"] == 0, estimated["stderr"]
    assert estimated["stderr"] == ""  # no progress bar when stderr is not a terminal
    flow = read_flo(estimated["flo"])
    assert flow.shape == SHAPE + (2,) and flow.dtype == np.float32
    scores = evaluate(flow, pair["gt"])
    assert scores["aee"] < AEE_BOUND
    # The one-line summary reports the size and the magnitudes of the written flow.
    line = estimated["stdout"].strip()
    assert "\n" not in line and "128x96" in line and str(estimated["flo"]) in line
    mean, peak = (float(x) for x in re.findall(r"\|w\| ([0-9.]+) px", line))
    mag = np.hypot(flow[..., 0], flow[..., 1])
    assert mean == pytest.approx(mag.mean(), abs=1e-3)
    assert peak == pytest.approx(mag.max(), abs=1e-3)
    # The colour PNG is the Middlebury coding of that flow.
    np.testing.assert_array_equal(read_image(estimated["png"]), flow_to_color(flow))


def test_flow_kitti_png_output_matches_flo(
    capsys: pytest.CaptureFixture[str], pair: dict, estimated: dict, tmp_path: Path
) -> None:
    out = tmp_path / "est.png"
    rc, _, err = run(capsys, "flow", pair["f0"], pair["f1"], "-o", out, "--quiet")
    assert rc == 0, err
    kitti = read_flow(out)
    ref = read_flo(estimated["flo"])
    assert kitti.shape == ref.shape
    assert np.max(np.abs(kitti - ref)) <= 0.5 / 64 + 1e-6  # KITTI stores 1/64 px steps


def test_flow_parameter_flags_reach_the_solver(
    capsys: pytest.CaptureFixture[str], pair: dict, estimated: dict, tmp_path: Path
) -> None:
    out = tmp_path / "fast.flo"
    rc, _, err = run(capsys, "flow", pair["f0"], pair["f1"], "-o", out, "--n-warps", 1,
                     "--max-iterations", 5, "--no-structure-texture", "--data-weight", 20)
    assert rc == 0, err
    got = read_flo(out)
    f0, f1 = pair["frames"]
    want = varflow.flow(f0, f1, n_warps=1, max_iterations=5, structure_texture=False,
                        data_weight=20.0)
    np.testing.assert_allclose(got, want, atol=1e-5)
    assert np.max(np.abs(got - read_flo(estimated["flo"]))) > 1e-2  # flags changed the result


def test_flow_progress_bar_on_a_terminal(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], pair: dict,
    tmp_path: Path
) -> None:
    class FakeTTY(io.StringIO):
        def isatty(self) -> bool:
            return True

    args = ["flow", str(pair["f0"]), str(pair["f1"]), "-o", str(tmp_path / "a.flo"),
            "--n-warps", "1", "--max-iterations", "2"]
    tty = FakeTTY()
    monkeypatch.setattr(sys, "stderr", tty)
    assert cli.main(args) == 0
    assert "warp" in tty.getvalue()  # tqdm bar drawn from the callback
    quiet = FakeTTY()
    monkeypatch.setattr(sys, "stderr", quiet)
    assert cli.main(args + ["--quiet"]) == 0
    assert quiet.getvalue() == ""


# ----------------------------------------------------------------------------- show / eval


def test_show_writes_colour_coding(
    capsys: pytest.CaptureFixture[str], estimated: dict, tmp_path: Path
) -> None:
    flow = read_flo(estimated["flo"])
    rc, out, err = run(capsys, "show", estimated["flo"], "-o", tmp_path / "c.png")
    assert rc == 0, err
    np.testing.assert_array_equal(read_image(tmp_path / "c.png"), flow_to_color(flow))
    assert str(tmp_path / "c.png") in out
    rc, _, err = run(capsys, "show", estimated["flo"], "-o", tmp_path / "l.png", "--legend",
                     "--max-radius", 5)
    assert rc == 0, err
    np.testing.assert_array_equal(read_image(tmp_path / "l.png"),
                                  flow_to_color_with_legend(flow, max_radius=5.0))


def test_eval_prints_the_numbers_of_evaluate(
    capsys: pytest.CaptureFixture[str], pair: dict, estimated: dict
) -> None:
    rc, out, err = run(capsys, "eval", estimated["flo"], pair["gt_path"])
    assert rc == 0, err
    printed = {}
    for line in out.splitlines():
        m = re.match(r"^(AEE|AAE|RMS|R1|R3|R5)\s+(-?[0-9.]+)", line)
        if m:
            printed[m.group(1).lower()] = float(m.group(2))
    want = evaluate(read_flo(estimated["flo"]), read_flo(pair["gt_path"]))
    assert set(printed) == {"aee", "aae", "rms", "r1", "r3", "r5"}
    for k, v in printed.items():
        assert v == pytest.approx(want[k], abs=1e-6), k
    assert printed["aee"] < AEE_BOUND


def test_eval_json_with_occlusion_mask(
    capsys: pytest.CaptureFixture[str], pair: dict, estimated: dict, tmp_path: Path
) -> None:
    occ = np.zeros(SHAPE, np.uint8)
    occ[:, : SHAPE[1] // 3] = 255  # white = occluded
    write_image(tmp_path / "occ.png", occ)
    rc, out, err = run(capsys, "eval", estimated["flo"], pair["gt_path"], "--occlusions",
                       tmp_path / "occ.png", "--json")
    assert rc == 0, err
    got = json.loads(out)
    want = evaluate(read_flo(estimated["flo"]), read_flo(pair["gt_path"]), occlusion=occ > 0)
    assert set(got) == set(want) >= {"aee_noc", "aee_occ"}
    for k in want:
        assert got[k] == pytest.approx(want[k], rel=1e-12, abs=1e-12), k
    assert got["aee_noc"] != got["aee_occ"]


# ----------------------------------------------------------------------------- demo / methods


def test_demo_writes_files_and_reports_small_error(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    d = tmp_path / "demo"
    rc, out, err = run(capsys, "demo", "-o", d, "--quiet")
    assert rc == 0, err
    names = ["frame0.png", "frame1.png", "flow.flo", "flow.png", "gt.flo", "gt.png"]
    for name in names:
        assert (d / name).is_file(), name
        assert str(d / name) in out
    h, w = cli.DEMO_SHAPE
    assert read_image(d / "frame0.png").shape == (h, w, 3)
    assert read_image(d / "flow.png").shape == (h, w, 3)
    printed = float(re.search(r"AEE ([0-9.]+) px", out).group(1))
    f0, f1, gt = synthetic_pair("smooth", shape=cli.DEMO_SHAPE, magnitude=cli.DEMO_MAGNITUDE,
                                seed=cli.DEMO_SEED)
    assert printed == pytest.approx(evaluate(read_flo(d / "flow.flo"), gt)["aee"], abs=1e-4)
    np.testing.assert_array_equal(read_flo(d / "gt.flo"), gt)
    assert printed < 0.1  # measured 0.05 px
    # The frames on disk are the 8-bit rendering of the synthetic pair.
    np.testing.assert_array_equal(read_image(d / "frame0.png"), to_uint8(f0))
    np.testing.assert_array_equal(read_image(d / "frame1.png"), to_uint8(f1))


def test_methods_lists_registry(capsys: pytest.CaptureFixture[str]) -> None:
    rc, out, _ = run(capsys, "methods")
    assert rc == 0
    lines = [ln for ln in out.splitlines() if not ln.startswith("# ")]
    from varflow.retime.methods import INTERPOLATORS

    entries = [*registry.METHODS.items(), *registry.TRACKERS.items(), *INTERPOLATORS.items(),
               *registry.RESTORE.items(), *registry.REPAIR.items()]
    assert len(lines) == len(entries)
    for line, (name, m) in zip(lines, entries, strict=True):
        assert line.split()[0] == name and m.use and m.use in line  # when to use it
    rc, out, _ = run(capsys, "methods", "--params", "--markdown")
    assert rc == 0
    default = registry.FLOW["tvl1"].defaults().data_weight
    assert re.search(rf"`data_weight` \(`--data-weight`\) \| λ \| `{default!r}` \|", out)
    assert re.search(r"`splat_sharpness` \(`--splat-sharpness`\) \| α \| `50.0` \|", out)


def test_help_lists_generated_parameter_flags(capsys: pytest.CaptureFixture[str]) -> None:
    """Every field is a flag: the knobs in ``--help``, all of them in ``methods NAME``."""
    rc, out, _ = run(capsys, "flow", "--help")
    assert rc == 0
    for name, _ in registry.FLOW["tvl1"].knobs:
        assert "--" + name.replace("_", "-") in out
    assert "--no-grey" in out
    rc, out, _ = run(capsys, "methods", "tvl1")
    assert rc == 0
    for name, _, _ in registry.parameter_fields(registry.FLOW["tvl1"]):
        assert "--" + name.replace("_", "-") + " " in out


# ----------------------------------------------------------------------------- errors


def test_missing_input_is_one_line_exit_2(
    capsys: pytest.CaptureFixture[str], pair: dict, tmp_path: Path
) -> None:
    missing = tmp_path / "nope.png"
    rc, out, err = run(capsys, "flow", missing, pair["f1"], "-o", tmp_path / "o.flo")
    assert_one_line_error(rc, err, str(missing))
    assert out == ""
    assert not (tmp_path / "o.flo").exists()


@pytest.mark.parametrize("damage", ["truncate", "magic"])
def test_corrupted_flo_is_one_line_exit_2(
    capsys: pytest.CaptureFixture[str], pair: dict, tmp_path: Path, damage: str
) -> None:
    data = Path(pair["gt_path"]).read_bytes()
    bad = tmp_path / "bad.flo"
    bad.write_bytes(data[: len(data) // 2] if damage == "truncate" else b"XXXX" + data[4:])
    rc, _, err = run(capsys, "eval", bad, pair["gt_path"])
    assert_one_line_error(rc, err, str(bad))


def test_unknown_parameter_flag_exit_2(
    capsys: pytest.CaptureFixture[str], pair: dict, tmp_path: Path
) -> None:
    rc, _, err = run(capsys, "flow", pair["f0"], pair["f1"], "-o", tmp_path / "o.flo",
                     "--no-such-param", 3)
    assert_one_line_error(rc, err, "--no-such-param")


def test_parameter_of_another_method_exit_2(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], pair: dict,
    tmp_path: Path
) -> None:
    @dataclasses.dataclass(frozen=True)
    class DummyParams(CoarseToFineParams):
        """Dummy.

        Attributes
        ----------
        dummy_strength : float
            σ, strength of nothing.
        """

        dummy_strength: float = 1.0

    method = registry.Method(name="dummy", description="test", defaults=DummyParams,
                             solve_warp=registry.FLOW["tvl1"].solve_warp)
    monkeypatch.setitem(registry.METHODS, "dummy", method)
    rc, _, err = run(capsys, "flow", pair["f0"], pair["f1"], "-o", tmp_path / "o.flo",
                     "--dummy-strength", 2)
    assert_one_line_error(rc, err, "--dummy-strength", "'tvl1'")
    assert not (tmp_path / "o.flo").exists()


def test_negative_data_weight_names_the_field(
    capsys: pytest.CaptureFixture[str], pair: dict, tmp_path: Path
) -> None:
    rc, _, err = run(capsys, "flow", pair["f0"], pair["f1"], "-o", tmp_path / "o.flo",
                     "--data-weight", -1)
    assert_one_line_error(rc, err, "--data-weight: must be > 0")


@pytest.mark.parametrize(
    "args, needle",
    [
        (["flow"], "required"),
        (["flow", "a.png", "b.png", "-o", "x.flo", "--n-warps", "2.5"], "--n-warps"),
        (["flow", "a.png", "b.png", "-o", "x.txt"], ".flo, .png or .npy"),
        (["flow", "a.png", "b.png", "-o", "x.flo", "--method", "nope"], "nope"),
        (["show", "a.flo", "-o", "c.png", "--max-radius", "-2"], "--max-radius"),
        (["bench", "middlebury", "--methods", "tvl1,nope"], "nope"),
        (["bench", "middlebury", "--sequences", "Atlantis"], "Atlantis"),
        (["frobnicate"], "frobnicate"),
        ([], "COMMAND"),
    ],
)
def test_bad_arguments_exit_2(
    capsys: pytest.CaptureFixture[str], args: list[str], needle: str
) -> None:
    rc, out, err = run(capsys, *args)
    assert_one_line_error(rc, err, needle)
    assert out == ""


def test_mismatched_frames_exit_2_without_output(
    capsys: pytest.CaptureFixture[str], pair: dict, tmp_path: Path
) -> None:
    small = tmp_path / "small.png"
    write_image(small, np.zeros((40, 50, 3), np.uint8))
    out = tmp_path / "o.flo"
    rc, _, err = run(capsys, "flow", pair["f0"], small, "-o", out)
    assert_one_line_error(rc, err, "shape")
    assert not out.exists()


# ----------------------------------------------------------------------------- atomic output


def test_failing_write_leaves_no_partial_file(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], pair: dict,
    tmp_path: Path
) -> None:
    def refuse(src: object, dst: object) -> None:
        raise OSError(28, "No space left on device", str(dst))

    monkeypatch.setattr(os, "replace", refuse)
    out = tmp_path / "o.flo"
    rc, _, err = run(capsys, "flow", pair["f0"], pair["f1"], "-o", out, "--n-warps", 1,
                     "--max-iterations", 2)
    assert_one_line_error(rc, err, "No space left on device")
    assert list(tmp_path.iterdir()) == []  # neither the target nor a temporary file


def test_failed_run_keeps_existing_output(
    capsys: pytest.CaptureFixture[str], pair: dict, tmp_path: Path
) -> None:
    out = tmp_path / "o.flo"
    out.write_bytes(b"previous result")
    rc, _, err = run(capsys, "flow", pair["f0"], pair["f1"], "-o", out, "--coupling", 0)
    assert_one_line_error(rc, err, "coupling")
    assert out.read_bytes() == b"previous result"


def test_keyboard_interrupt_exit_130(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], pair: dict,
    tmp_path: Path
) -> None:
    def interrupted(*args: object, **kwargs: object) -> np.ndarray:
        raise KeyboardInterrupt

    monkeypatch.setattr(varflow, "flow", interrupted)
    out = tmp_path / "o.flo"
    rc, _, err = run(capsys, "flow", pair["f0"], pair["f1"], "-o", out)
    assert rc == 130
    assert "Traceback" not in err and len(err.splitlines()) == 1
    assert not out.exists()


# ----------------------------------------------------------------------------- real script


def _script() -> list[str]:
    exe = shutil.which("varflow") or str(Path(sys.executable).with_name("varflow"))
    if not Path(exe).is_file():
        pytest.fail("the 'varflow' console script is not installed (pip install -e .)")
    return [exe]


def test_console_script_end_to_end(pair: dict, tmp_path: Path) -> None:
    out = tmp_path / "o.flo"
    env = {**os.environ, "COLUMNS": "100"}
    proc = subprocess.run(
        _script() + ["flow", str(pair["f0"]), str(pair["f1"]), "-o", str(out)],
        capture_output=True, text=True, timeout=600, env=env,
    )
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == ""  # stderr is a pipe: no progress bar
    assert evaluate(read_flo(out), pair["gt"])["aee"] < AEE_BOUND

    bad = subprocess.run(
        _script() + ["eval", str(tmp_path / "missing.flo"), str(out)],
        capture_output=True, text=True, timeout=600, env=env,
    )
    assert_one_line_error(bad.returncode, bad.stderr, "missing.flo")
    assert bad.stdout == ""


def test_flags_of_another_method_are_rejected(tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    from varflow.io import write_image

    img = np.zeros((20, 24), np.uint8)
    write_image(tmp_path / "a.png", img)
    rc, _, err = run(capsys, "flow", str(tmp_path / "a.png"), str(tmp_path / "a.png"),
                     "-o", str(tmp_path / "f.flo"), "--tensor-a", "3")
    assert rc == 2 and "--tensor-a is not a parameter of method 'tvl1'" in err
    rc, _, err = run(capsys, "track", str(tmp_path / "a.png"), str(tmp_path / "a.png"),
                     "-o", str(tmp_path / "t.npz"), "--n-atoms", "400")
    # trajectory methods only get the flags of trajectory parameter classes
    assert rc == 2 and "unrecognized arguments: --n-atoms" in err and len(err.splitlines()) == 1
