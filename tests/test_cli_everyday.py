"""The path a user walks every day (issue 47): outputs, mixed inputs, formats.

Each test reproduces a friction point a new user met: an output silently overwritten,
a grey and a colour frame refused, a KITTI PNG that looks broken in a viewer, a
picture passed where a flow file belongs, no ``.npy`` output.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from varflow import cli
from varflow.generators.pairs import synthetic_pair
from varflow.io import read_flow, read_image, write_flow, write_image


def _frames(tmp_path: Path, grey0: bool = False) -> tuple[Path, Path, np.ndarray]:
    f0, f1, gt = synthetic_pair("smooth", shape=(48, 64), magnitude=1.5, seed=2)
    to8 = lambda a: np.clip(np.rint(a * 255), 0, 255).astype(np.uint8)  # noqa: E731
    rgb0 = np.repeat(to8(f0)[..., None], 3, axis=2) if f0.ndim == 2 else to8(f0)
    rgb1 = np.repeat(to8(f1)[..., None], 3, axis=2) if f1.ndim == 2 else to8(f1)
    a, b = tmp_path / "a.png", tmp_path / "b.png"
    write_image(a, rgb0.mean(axis=2).round().astype(np.uint8) if grey0 else rgb0)
    write_image(b, rgb1)
    return a, b, gt


def _run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    rc = cli.main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


def test_two_outputs_on_one_file_are_refused(tmp_path, capsys) -> None:
    a, b, _ = _frames(tmp_path)
    same = tmp_path / "same.png"
    rc, _, err = _run(capsys, "flow", a, b, "-o", same, "--png", same, "-q")
    assert rc == 2
    assert err.strip() == (f"varflow: error: --png: {same} is also the -o/--output output; "
                           "give each output a file of its own")
    assert not same.exists()  # refused before any work
    # the same file by another spelling
    rc, _, err = _run(capsys, "flow", a, b, "-o", same, "--png", tmp_path / "." / "same.png")
    assert rc == 2 and "is also the -o/--output output" in err


def test_an_output_may_not_replace_an_input(tmp_path, capsys) -> None:
    a, b, _ = _frames(tmp_path)
    before = a.read_bytes()
    rc, _, err = _run(capsys, "flow", a, b, "-o", tmp_path / "f.flo", "--png", a, "-q")
    assert rc == 2 and err.strip() == (f"varflow: error: --png: {a} is also the input FRAME0; "
                                       "give each output a file of its own")
    assert a.read_bytes() == before
    kitti = tmp_path / "f.png"
    write_flow(kitti, np.zeros((4, 4, 2), np.float32))
    before = kitti.read_bytes()
    rc, _, err = _run(capsys, "show", kitti, "-o", kitti)
    assert rc == 2 and "is also the input FLOW" in err
    assert kitti.read_bytes() == before


def test_a_grey_and_a_colour_frame_are_accepted(tmp_path, capsys) -> None:
    a, b, gt = _frames(tmp_path, grey0=True)
    assert read_image(a).ndim == 2 and read_image(b).ndim == 3
    out = tmp_path / "f.flo"
    rc, stdout, err = _run(capsys, "flow", a, b, "-o", out, "--method", "tvl1-fast", "-q")
    assert rc == 0, err
    flow = read_flow(out)
    aee = float(np.mean(np.hypot(*(flow - gt).transpose(2, 0, 1))))
    assert aee < 0.3, aee
    # exactly the flow of the grey frame given as colour (its value in every channel)
    import varflow

    grey_as_rgb = np.repeat(read_image(a)[..., None], 3, axis=2)
    ref = varflow.flow(grey_as_rgb, read_image(b), "tvl1-fast")
    np.testing.assert_array_equal(flow, ref)


def test_mixed_frames_in_the_api_and_clear_shape_errors() -> None:
    import varflow

    rng = np.random.default_rng(1)
    rgb = (rng.random((32, 40, 3)) * 255).astype(np.uint8)
    grey = rgb.mean(axis=2).astype(np.uint8)
    assert varflow.flow(grey, rgb, "tvl1-fast").shape == (32, 40, 2)
    with pytest.raises(ValueError, match=r"^frame0 and frame1 differ in shape: "
                                         r"\(32, 40\) vs \(30, 40, 3\)$"):
        varflow.flow(grey, rgb[:30])
    rgba = np.concatenate([rgb, rgb[..., :1]], axis=2)
    with pytest.raises(ValueError, match=r"\(32, 40, 4\) vs \(32, 40, 3\)"):
        varflow.flow(rgba, rgb)


def test_kitti_png_output_says_it_is_not_a_picture(tmp_path, capsys) -> None:
    a, b, _ = _frames(tmp_path)
    out = tmp_path / "flow.png"
    rc, stdout, err = _run(capsys, "flow", a, b, "-o", out, "--method", "tvl1-fast", "-q")
    assert rc == 0 and out.exists()
    assert "16-bit KITTI flow PNG" in err and "--png COLOUR.png" in err
    assert "KITTI" not in stdout  # results on stdout, the note on stderr
    rc, _, err = _run(capsys, "flow", a, b, "-o", out, "--png", tmp_path / "c.png", "-q")
    assert rc == 0 and "KITTI" not in err  # a picture was asked for: no note


def test_npy_output_and_eval(tmp_path, capsys) -> None:
    a, b, gt = _frames(tmp_path)
    out = tmp_path / "flow.npy"
    rc, stdout, err = _run(capsys, "flow", a, b, "-o", out, "--method", "tvl1-fast", "-q")
    assert rc == 0, err
    flow = np.load(out)
    assert flow.dtype == np.float32 and flow.shape == (48, 64, 2)
    write_flow(tmp_path / "gt.npy", gt)
    rc, stdout, err = _run(capsys, "eval", out, tmp_path / "gt.npy", "--json")
    assert rc == 0, err
    assert '"aee"' in stdout
    rc, stdout, err = _run(capsys, "show", out, "-o", tmp_path / "colour.png")
    assert rc == 0 and read_image(tmp_path / "colour.png").shape == (48, 64, 3)


def test_eval_of_a_picture_says_it_is_not_a_flow(tmp_path, capsys) -> None:
    a, _, gt = _frames(tmp_path)
    write_flow(tmp_path / "gt.flo", gt)
    rc, _, err = _run(capsys, "eval", tmp_path / "gt.flo", a)
    assert rc == 2
    assert err.strip() == (f"varflow: error: {a}: not a KITTI flow PNG (8-bit RGB, a picture?); "
                           "a KITTI flow PNG is 16-bit RGB with R = u, G = v, B = valid")
    rc, _, err = _run(capsys, "eval", tmp_path / "gt.flo", tmp_path / "x.jpg")
    assert rc == 2 and "unknown flow file extension '.jpg' (use .flo, .png or .npy)" in err


def test_max_pixels_downscales_large_frames(tmp_path, capsys) -> None:
    f0, f1, gt = synthetic_pair("smooth", shape=(96, 128), magnitude=2.0, seed=5)
    to8 = lambda x: np.clip(np.rint(x * 255), 0, 255).astype(np.uint8)  # noqa: E731
    write_image(tmp_path / "a.png", to8(f0))
    write_image(tmp_path / "b.png", to8(f1))
    out = tmp_path / "f.flo"
    rc, stdout, err = _run(capsys, "flow", tmp_path / "a.png", tmp_path / "b.png", "-o", out,
                           "--max-pixels", 3072, "--method", "tvl1-fast", "-q")
    assert rc == 0, err
    flow = read_flow(out)
    assert flow.shape == (96, 128, 2)  # full size, vectors in full-size pixels
    aee = float(np.mean(np.hypot(*(flow - gt).transpose(2, 0, 1))))
    assert aee < 0.35, aee
    rc, _, err = _run(capsys, "flow", tmp_path / "a.png", tmp_path / "b.png", "-o", out,
                      "--max-pixels", "-5")
    assert rc == 2 and "--max-pixels" in err


def test_flow_max_pixels_in_the_api() -> None:
    """``varflow.flow(..., max_pixels=N)``: the flow of reduced copies, at full size."""
    import varflow

    f0, f1, gt = synthetic_pair("smooth", shape=(96, 128), magnitude=2.0, seed=5)
    full = varflow.flow(f0, f1, "tvl1-fast")
    small = varflow.flow(f0, f1, "tvl1-fast", max_pixels=3072)  # a quarter of the pixels
    same = varflow.flow(f0, f1, "tvl1-fast", max_pixels=96 * 128)  # within: untouched
    np.testing.assert_array_equal(same, full)
    assert small.shape == full.shape and small.dtype == np.float32
    aee = lambda f: float(np.mean(np.hypot(*(f - gt).transpose(2, 0, 1))))  # noqa: E731
    assert aee(small) < 0.35 and aee(full) < 0.2, (aee(small), aee(full))
    assert not np.array_equal(small, full)
    for bad in (-1, 2.5, True):
        with pytest.raises(ValueError, match="^max_pixels: must be an integer >= 0"):
            varflow.flow(f0, f1, "tvl1-fast", max_pixels=bad)
    with pytest.raises(ValueError, match=r"^init_flow: expected shape \(96, 128, 2\)"):
        varflow.flow(f0, f1, "tvl1-fast", max_pixels=3072,
                     init_flow=np.zeros((10, 10, 2), np.float32))


def test_track_interpolate_and_retime_keep_their_inputs(tmp_path, capsys) -> None:
    """No command writes over what it reads, nor two outputs over one another."""
    a, b, _ = _frames(tmp_path)
    before = a.read_bytes()
    rc, _, err = _run(capsys, "interpolate", a, b, "-o", b)
    assert rc == 2 and f"-o/--output: {b} is also the input B" in err
    rc, _, err = _run(capsys, "track", a, b, "-o", tmp_path / "t.npz", "--plot", a)
    assert rc == 2 and f"--plot: {a} is also the input FRAME" in err
    rc, _, err = _run(capsys, "track", tmp_path, "-o", tmp_path / "t.npz",
                      "--warped", tmp_path)
    assert rc == 2 and "--warped" in err and "is also the input FRAME" in err
    rc, _, err = _run(capsys, "track", a, b, "-o", tmp_path / "t.npz",
                      "--warped", tmp_path / "w", "--png", tmp_path / "w")
    assert rc == 2 and "is also the --warped output" in err
    rc, _, err = _run(capsys, "retime", tmp_path, "-o", tmp_path, "--fps", "50")
    assert rc == 2 and "is also the input IN" in err
    assert a.read_bytes() == before and not (tmp_path / "t.npz").exists()


def test_parameter_errors_name_the_flag(tmp_path, capsys) -> None:
    a, b, _ = _frames(tmp_path)
    rc, _, err = _run(capsys, "flow", a, b, "-o", tmp_path / "f.flo", "--data-weight", "-3")
    assert rc == 2 and err.strip() == "varflow: error: --data-weight: must be > 0, got -3.0"
    rc, _, err = _run(capsys, "flow", a, b, "-o", tmp_path / "f.txt")
    assert rc == 2 and err.strip().endswith("f.txt must end in .flo, .png or .npy")
