"""Memory estimate and the check that runs before flow() and track()."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import varflow
import varflow.registry
from varflow import _memory
from varflow._memory import (
    ENV_VAR,
    InsufficientMemoryError,
    available_bytes,
    check_memory,
    estimate_bytes,
    parse_size,
)
from varflow.cli import main


def test_estimate_grows_with_size_frames_and_channels() -> None:
    small = estimate_bytes("tvl1", (100, 100))
    assert estimate_bytes("tvl1", (200, 200)) == pytest.approx(4 * small, rel=1e-6)
    assert estimate_bytes("tvl1", (100, 100, 3)) > small
    assert estimate_bytes("rlr", (100, 100), 9) > estimate_bytes("rlr", (100, 100), 5)
    # 8000 x 8000 with TV-L1: tens of GiB, as the example says
    assert 8 * 2**30 < estimate_bytes("tvl1", (8000, 8000)) < 64 * 2**30
    # every registered method has measured factors; a kind gets the largest
    for registry in (varflow.registry.FLOW, varflow.registry.TRACK):
        for entry in registry.values():
            assert entry.memory is not None, entry.name
    for kind, names in (("flow", varflow.methods()), ("track", varflow.track_methods())):
        for name in names:
            assert 0 < estimate_bytes(name, (100, 100), 5) <= estimate_bytes(kind, (100, 100), 5)
    assert estimate_bytes("not-registered", (10, 10)) == estimate_bytes("flow", (10, 10))


def test_parse_size() -> None:
    assert parse_size("1000") == 1000
    assert parse_size("512M") == 512 * 2**20
    assert parse_size("1.5GiB") == 3 * 2**29
    assert parse_size("2 gb") == 2 * 10**9
    with pytest.raises(ValueError, match=ENV_VAR):
        parse_size("lots")


def test_available_bytes_env_and_system(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(ENV_VAR, "3G")
    assert available_bytes() == 3 * 2**30
    monkeypatch.setenv(ENV_VAR, "off")
    assert available_bytes() is None
    monkeypatch.delenv(ENV_VAR)
    have = available_bytes()
    if Path("/proc/meminfo").exists():
        assert have is not None and have > 0


def test_cgroup_v2_and_v1(tmp_path: Path) -> None:
    v2 = tmp_path / "v2"
    v2.mkdir()
    (v2 / "memory.max").write_text("1000000\n")
    (v2 / "memory.current").write_text("600000\n")
    (v2 / "memory.stat").write_text("anon 1\ninactive_file 100000\n")
    assert _memory._cgroup_available(v2) == 500000
    (v2 / "memory.max").write_text("max\n")
    assert _memory._cgroup_available(v2) is None  # no v2 limit and no v1 files
    v1 = tmp_path / "v1"
    (v1 / "memory").mkdir(parents=True)
    (v1 / "memory" / "memory.limit_in_bytes").write_text("9223372036854771712\n")
    assert _memory._cgroup_available(v1) is None  # "unlimited"
    (v1 / "memory" / "memory.limit_in_bytes").write_text("2000000\n")
    (v1 / "memory" / "memory.usage_in_bytes").write_text("1500000\n")
    (v1 / "memory" / "memory.stat").write_text("total_inactive_file 250000\n")
    assert _memory._cgroup_available(v1) == 750000


def test_check_memory_message(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(ENV_VAR, "4G")
    with pytest.raises(InsufficientMemoryError) as info:
        check_memory("tvl1", (8000, 8000))
    msg = str(info.value)
    assert msg.startswith("needs about ")
    assert "GiB for 8000x8000 with tvl1, 4.0 GiB available" in msg
    assert msg.endswith("; downscale or crop") and "\n" not in msg
    assert isinstance(info.value, ValueError) and isinstance(info.value, MemoryError)
    assert check_memory("tvl1", (100, 100)) == estimate_bytes("tvl1", (100, 100))
    monkeypatch.setenv(ENV_VAR, "1M")
    with pytest.raises(ValueError, match=r"for 64x48 x 5 frames with rlr, 1 MiB available"):
        check_memory("rlr", (48, 64), 5)


def test_flow_and_track_refuse_before_running(monkeypatch: pytest.MonkeyPatch) -> None:
    calls = []
    frames = np.zeros((4, 60, 80), np.uint8)
    monkeypatch.setenv(ENV_VAR, "100K")
    with pytest.raises(InsufficientMemoryError, match="with tvl1"):
        varflow.flow(frames[0], frames[1], callback=lambda d, t: calls.append(d))
    with pytest.raises(InsufficientMemoryError, match="80x60 x 4 frames with chain"):
        varflow.track(frames, method="chain", callback=lambda d, t: calls.append(d))
    with pytest.raises(InsufficientMemoryError, match="with twoframe"):
        varflow.track(list(frames), method="twoframe")
    assert calls == []  # nothing ran
    monkeypatch.setenv(ENV_VAR, "64M")
    assert not varflow.flow(frames[0], frames[1]).any()


def test_cli_reports_memory_in_one_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    from varflow.io import write_image

    img = np.zeros((40, 50), np.uint8)
    write_image(tmp_path / "a.png", img)
    monkeypatch.setenv(ENV_VAR, "10K")
    out = tmp_path / "f.flo"
    assert main(["flow", str(tmp_path / "a.png"), str(tmp_path / "a.png"), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("varflow: error: needs about ") and err.count("\n") == 1
    assert "10 KiB available; downscale or crop" in err
    assert not out.exists()
