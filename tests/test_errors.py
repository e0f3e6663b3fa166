"""varflow._errors.error_line: the one-line error texts of manifests and reports."""

from __future__ import annotations

from varflow._errors import error_line


def test_os_error_names_its_file() -> None:
    exc = FileNotFoundError(2, "No such file or directory", "/data/clip.mp4")
    assert error_line(exc) == "No such file or directory: /data/clip.mp4"
    assert error_line(exc, with_type=True) == (
        "FileNotFoundError: No such file or directory: /data/clip.mp4")


def test_other_errors_are_folded_onto_one_line() -> None:
    assert error_line(ValueError("frame1:\n  contains  NaN")) == "frame1: contains NaN"
    assert error_line(RuntimeError()) == "RuntimeError"
    assert error_line(OSError("disk full")) == "disk full"
    assert error_line(KeyError("x"), with_type=True) == "KeyError: 'x'"
