"""Shared fixtures: the location of the benchmark data."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from varflow.evaluation import datasets


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line(
        "markers", "data: needs the benchmark data (VARFLOW_DATA); runs in CI (.ci/run)"
    )


@pytest.fixture(scope="session")
def data_root() -> Path:
    """The benchmark data folder (see :func:`varflow.evaluation.datasets.data_root`).

    Skips the test when the folder does not exist, or fails it when the environment
    variable ``VARFLOW_REQUIRE_DATA=1`` (as in CI).
    """
    root = datasets.data_root()
    if not root.is_dir():
        msg = f"benchmark data not found at {root}; set {datasets.ENV_VAR}"
        if os.environ.get("VARFLOW_REQUIRE_DATA", "").strip() == "1":
            pytest.fail(msg)
        pytest.skip(msg)
    return root
