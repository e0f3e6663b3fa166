"""The large-motion pair generator (objects moving 30-150 px over photographs)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("skimage.data")

from varflow.evaluation.bench.twoframe import (  # noqa: E402
    DEFAULT_SETS,
    SETS,
    SINTEL_LARGE_PAIRS,
    check_twoframe_options,
)
from varflow.generators.large_pairs import (  # noqa: E402
    FAMILIES,
    REPORTING_SEEDS,
    TUNING_SEEDS,
    large_pair_cases,
    make_large_pair,
)
from varflow.ops.warp import warp_bicubic  # noqa: E402

SHAPE = (192, 256)


@pytest.mark.parametrize("family", FAMILIES)
def test_pair_has_exact_flow_and_large_object_motion(family):
    pair = make_large_pair(family, seed=1, shape=SHAPE)
    h, w = SHAPE
    assert pair.frame0.shape == pair.frame1.shape == (h, w, 3)
    assert pair.flow.shape == (h, w, 2) and pair.flow.dtype == np.float32
    assert pair.valid.shape == (h, w) and pair.valid.dtype == bool
    # frame 1 sampled where the flow points reproduces frame 0 on the visible pixels
    warped, inside = warp_bicubic(pair.frame1, pair.flow)
    interior = np.zeros((h, w), bool)
    interior[4:-4, 4:-4] = True
    ok = pair.valid & inside & interior
    residual = np.abs(warped - pair.frame0).mean(axis=-1)[ok]
    assert np.median(residual) < 0.01
    # the objects move far: farther than the background, and 30-150 px
    on_objects = pair.layer > 0
    disp = np.hypot(*pair.flow.transpose(2, 0, 1))
    assert on_objects.any()
    assert 25.0 <= disp[on_objects].mean() <= 160.0


def test_seeded_and_split():
    a = make_large_pair("objects", 2, shape=(96, 128))
    b = make_large_pair("objects", 2, shape=(96, 128))
    np.testing.assert_array_equal(a.frame0, b.frame0)
    np.testing.assert_array_equal(a.flow, b.flow)
    c = make_large_pair("objects", 3, shape=(96, 128))
    assert not np.array_equal(a.flow, c.flow)
    assert set(TUNING_SEEDS).isdisjoint(REPORTING_SEEDS)
    assert large_pair_cases("tuning") == [(f, s) for f in FAMILIES for s in TUNING_SEEDS]


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [({"family": "fast"}, "family"), ({"shape": (32, 64)}, "shape"),
     ({"channels": 2}, "channels"), ({"supersample": 0}, "supersample"),
     ({"seed": -1}, "seed")],
)
def test_invalid_arguments_name_the_argument(kwargs, field):
    args = {"family": "objects", **kwargs}
    with pytest.raises(ValueError, match=field):
        make_large_pair(**args)


def test_bench_sets():
    assert set(DEFAULT_SETS) < set(SETS) and {"large", "sintel-large"} <= set(SETS)
    sets, splits, _, _ = check_twoframe_options("sintel-large,large", "both")
    assert sets == ["large", "sintel-large"] and splits == ["tuning", "reporting"]
    assert ("market_5", "final", 9) in SINTEL_LARGE_PAIRS
