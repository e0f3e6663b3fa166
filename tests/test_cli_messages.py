"""One wording for each input error, whichever command meets it.

``varflow track``, ``varflow retime`` and the inputs of ``varflow batch`` read the same
kinds of input (a folder of frames, a video); a missing path, an empty folder, a folder
with one frame, a single image and a file of an unknown type get the same message from
all of them, and the command-line messages name no option the command does not have.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from varflow import cli
from varflow.batch.inputs import expand_inputs, probe_input
from varflow.cli._common import _one_line
from varflow.io.images import write_image
from varflow.io.sequences import (
    missing_input_error,
    no_frames_message,
    not_a_sequence_message,
    read_frames,
    single_image_message,
    too_few_frames_message,
)

H, W = 48, 64


def _error(capsys: pytest.CaptureFixture[str], *args: object) -> str:
    """The one error line of a command that must fail with exit status 2."""
    rc = cli.main([str(a) for a in args])
    out, err = capsys.readouterr()
    assert rc == 2 and not out, (rc, out, err)
    assert err.startswith("varflow: error: ") and err.count("\n") == 1, err
    return err[len("varflow: error: "):-1]


def _track(capsys: pytest.CaptureFixture[str], source: Path, tmp: Path) -> str:
    return _error(capsys, "track", source, "-o", tmp / "t.npz", "-q")


def _retime(capsys: pytest.CaptureFixture[str], source: Path, tmp: Path) -> str:
    return _error(capsys, "retime", source, "-o", tmp / "out.mkv", "--fps", "50", "-q")


def _batch(source: Path) -> str:
    """The message of the batch input reader (the expansion, then the probe)."""
    with pytest.raises((ValueError, OSError)) as info:
        for inp in expand_inputs([str(source)]):
            probe_input(inp)
    return _one_line(info.value)


def _frame(path: Path, value: int = 0) -> Path:
    write_image(path, np.full((H, W, 3), value, np.uint8))
    return path


@pytest.fixture
def work(tmp_path: Path) -> Path:
    """An output folder next to the inputs; the commands must leave it empty."""
    out = tmp_path / "out"
    out.mkdir()
    return out


def test_an_empty_folder_reads_the_same_everywhere(tmp_path: Path, work: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    empty = tmp_path / "empty"
    empty.mkdir()
    (empty / "notes.txt").write_text("no frames here")
    expected = no_frames_message(empty)
    assert expected.startswith(f"{empty}: no image files in the folder (looked for .png, ")
    assert _track(capsys, empty, work) == expected
    assert _retime(capsys, empty, work) == expected
    assert _batch(empty) == expected
    with pytest.raises(ValueError) as info:
        read_frames(empty)
    assert str(info.value) == expected
    assert not any(work.iterdir())


def test_one_frame_names_no_option_the_cli_lacks(tmp_path: Path, work: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    one = tmp_path / "one"
    one.mkdir()
    _frame(one / "f0.png")
    expected = too_few_frames_message(one, 1)
    assert expected == f"{one}: need at least 2 frames, found 1"
    got = _track(capsys, one, work)
    assert got == expected
    for word in ("max_frames", "stop=", "start=", "step=", "read_frames"):
        assert word not in got
    assert _retime(capsys, one, work) == expected
    assert _batch(one) == expected
    # the Python API names its keyword arguments, but only those that were changed
    with pytest.raises(ValueError, match=r"1 of 1 selected with step=2, max_frames=1$"):
        read_frames(one, step=2, max_frames=1)
    two = tmp_path / "two"
    two.mkdir()
    _frame(two / "a.png")
    _frame(two / "b.png")
    with pytest.raises(ValueError, match=r"need at least 2 frames, 1 of 2 selected with "
                                         r"start=1$"):
        read_frames(two, start=1)
    assert not any(work.iterdir())


def test_missing_single_image_and_unknown_file(tmp_path: Path, work: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    missing = tmp_path / "missing"
    expected = _one_line(missing_input_error(missing))
    assert expected == f"input not found: {missing}"
    assert _track(capsys, missing, work) == expected
    assert _retime(capsys, missing, work) == expected
    assert _batch(missing) == expected

    image = _frame(tmp_path / "single.png")
    expected = single_image_message(image)
    assert _track(capsys, image, work) == expected
    assert _retime(capsys, image, work) == expected
    assert _batch(image) == expected

    other = tmp_path / "data.xyz"
    other.write_bytes(b"not a video at all " * 20)
    expected = not_a_sequence_message(other)
    assert "unknown extension '.xyz'" in expected and ".mp4" in expected
    assert _track(capsys, other, work) == expected
    assert _retime(capsys, other, work) == expected
    # batch also takes input lists, and says so
    got = _batch(other)
    assert got.startswith(expected + "; input lists end in ") and ".txt" in got
    # an entry of an input list is named by its line
    listing = tmp_path / "inputs.txt"
    listing.write_text("missing\n")
    assert _batch(listing) == f"{listing}:1: input not found: {missing}"
    assert not any(work.iterdir())


def test_batch_command_says_it_too(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The errors found before any work are the same through ``varflow batch``."""
    pytest.importorskip("distributed")
    image = _frame(tmp_path / "single.png")
    out = tmp_path / "batch"
    for source, expected in ((tmp_path / "missing", f"input not found: {tmp_path / 'missing'}"),
                             (image, single_image_message(image))):
        got = _error(capsys, "batch", "retime", source, "-o", out, "--fps", "50", "-q")
        assert got == expected
    assert not out.exists()


def test_a_video_file_that_is_not_one(tmp_path: Path, work: Path,
                                      capsys: pytest.CaptureFixture[str]) -> None:
    """A damaged file with a video extension is reported as a video that cannot be read,
    not as an unknown kind of file."""
    bad = tmp_path / "bad.mp4"
    bad.write_bytes(b"not a video at all " * 20)
    for got in (_track(capsys, bad, work), _retime(capsys, bad, work)):
        assert got.startswith(f"{bad}: ") and "neither" not in got
