"""Composed parameters: flat names routed to their owner, presets, one registry."""

from __future__ import annotations

import dataclasses
import importlib

import pytest

import varflow
from varflow.parameters import UnknownParameter, flat_fields, owner_of, replace
from varflow.registry import FLOW, INTERPOLATE, TRACK, Registry
from varflow.twoframe.params import (
    PRESETS,
    MatchingTerm,
    SparseTerm,
    TensorTerm,
    TVL1Params,
    preset,
)


def test_flat_names_route_to_the_term_that_owns_them() -> None:
    p = PRESETS["sparse-2d"]
    q = p.replace(tensor_a=1.5, layout="1D", data_weight=20.0)
    assert q.tensor.tensor_a == 1.5 and q.sparse.layout == "1D" and q.data_weight == 20.0
    # nothing else moved, and the original is untouched (frozen)
    assert q.tensor.tensor_b == p.tensor.tensor_b and p.sparse.layout == "2D"
    assert owner_of(p, "tensor_a") is p.tensor and owner_of(p, "n_warps") is p
    assert owner_of(p, "nope") is None


def test_an_unknown_name_is_refused_naming_it() -> None:
    with pytest.raises(UnknownParameter, match="^tensor_a: not a parameter of TVL1Params"):
        PRESETS["tvl1"].replace(tensor_a=1.0)  # tvl1 has no tensor term
    with pytest.raises(ValueError, match="^tensor_a: not a parameter of method 'tvl1'"):
        varflow.make_params("tvl1", tensor_a=1.0)


def test_an_invalid_value_is_refused_naming_the_field() -> None:
    with pytest.raises(ValueError, match="^tensor_b: must be > 0"):
        PRESETS["tensor"].replace(tensor_b=0.0)
    with pytest.raises(ValueError, match="^match_scale: must be in"):
        varflow.make_params("tvl1-ld", match_scale=2.0)
    with pytest.raises(ValueError, match="^tensor: expected a TensorTerm"):
        TVL1Params(tensor=SparseTerm())


def test_a_new_flow_method_starts_from_its_own_defaults() -> None:
    p = varflow.make_track_params("twoframe", data_weight=3.0)
    assert p.flow_params.data_weight == 3.0
    q = p.replace(flow_method="tensor")  # the dependent flow_params is reset
    assert q.flow_params == FLOW["tensor"].defaults()
    r = p.replace(flow_method="tvl1-ld", match_scale=0.25, data_weight=4.0)
    assert r.flow_params.matching.match_scale == 0.25 and r.flow_params.data_weight == 4.0
    assert p.replace(flow_method="tvl1").flow_params.data_weight == 3.0  # same method: kept


def test_flat_fields_list_each_name_once_in_routing_order() -> None:
    p = varflow.make_track_params("rlr")
    names = [n for n, _, _ in flat_fields(p)]
    assert len(names) == len(set(names))
    assert "flow_params" not in names and "tensor" not in names
    assert names[0] == "flow_method" and "link_weight" in names and "data_weight" in names
    owners = {n: type(o) for n, _, o in flat_fields(p)}
    assert owners["data_weight"] is TVL1Params and owners["link_weight"] is type(p)
    # a name both have belongs to the outer object, as replace routes it
    sp = PRESETS["sparse-1d"]
    assert [n for n, _, _ in flat_fields(sp)][:3] == ["scale_factor", "max_levels", "min_size"]
    assert {"tensor_a", "layout", "combined_solver"} <= {n for n, _, _ in flat_fields(sp)}


def test_replace_is_one_function() -> None:
    """The method and the module function are the same routing."""
    p = PRESETS["tvl1-sparse-dct"]
    assert p.replace(patch_size=8, sparse_min_size=40) == replace(p, patch_size=8,
                                                                  sparse_min_size=40)


def test_presets_differ_from_tvl1_in_their_documented_fields_only() -> None:
    base = dataclasses.asdict(PRESETS["tvl1"])

    def changed(name: str) -> set[str]:
        d = dataclasses.asdict(PRESETS[name])
        return {k for k in d if d[k] != base[k]}

    assert changed("tvl1-fast") == {"scale_factor", "n_warps"}
    assert changed("multiframe") == {"max_iterations", "n_warps", "weighted_median_levels",
                                     "sharpness_match"}
    assert changed("tvl1-ld") == {"n_warps", "weighted_median_levels", "max_iterations",
                                  "matching"}
    assert changed("tvl1-tensor") == {"edge_weight", "tensor"}
    assert changed("plain") == {"data_weight", "max_iterations", "edge_weight",
                                "gradient_weight", "huber", "noise_reference", "texture_alpha",
                                "sharpness_match", "grey", "weighted_median_radius",
                                "weighted_median_levels", "n_warps"}
    assert PRESETS["tvl1-tensor"].tensor == TensorTerm(tensor_a=0.5)
    assert PRESETS["tensor"].tensor == TensorTerm() and PRESETS["tensor"].edge_weight == 0
    assert PRESETS["tvl1-ld"].matching == MatchingTerm()
    assert PRESETS["sparse-dct"].sparse == SparseTerm(dictionary="dct")
    assert PRESETS["tvl1-sparse-2x1d"].sparse == SparseTerm(layout="2x1D")
    assert preset("plain", n_warps=2).n_warps == 2
    with pytest.raises(ValueError, match="^preset: unknown preset 'nope'"):
        preset("nope")


def test_the_former_classes_still_build_their_presets() -> None:
    from varflow.twoframe.sparse import TVL1Sparse2DParams
    from varflow.twoframe.tensor import TensorParams
    from varflow.twoframe.tvl1 import PlainTVL1Params

    with pytest.warns(DeprecationWarning, match="PlainTVL1Params is deprecated"):
        assert PlainTVL1Params() == PRESETS["plain"]
    with pytest.warns(DeprecationWarning):
        assert TensorParams(tensor_a=5.0) == PRESETS["tensor"].replace(tensor_a=5.0)
    with pytest.warns(DeprecationWarning):
        assert TVL1Sparse2DParams() == PRESETS["tvl1-sparse-2d"]


def test_every_method_is_in_one_registry_with_everything_known_about_it() -> None:
    for registry in (FLOW, TRACK, INTERPOLATE):
        assert isinstance(registry, Registry) and len(registry) >= 3
        for name, entry in registry.items():
            assert entry.name == name and entry.description
            params = registry.make_params(name)
            entry.check_params(params)
            for kernel in entry.kernels:
                module, _, func = kernel.partition(":")
                assert hasattr(importlib.import_module(module), func), kernel
    for registry in (FLOW, TRACK):
        for name, entry in registry.items():
            assert entry.memory is not None, name
            assert entry.compile_seconds is not None, name
    assert varflow.METHODS is FLOW and varflow.TRACKERS is TRACK
    assert varflow.methods() == FLOW.names()


def test_a_method_refuses_parameters_with_other_terms() -> None:
    with pytest.raises(ValueError, match="^params: 'tvl1' takes the terms none, got"):
        varflow.make_params("tvl1", params=PRESETS["tensor"])
    with pytest.raises(ValueError, match="^flow_params: 'tvl1-ld' takes the terms"):
        varflow.make_track_params("twoframe", flow_method="tvl1-ld",
                                  flow_params=PRESETS["tvl1"])
    with pytest.raises(ValueError, match="^method: unknown method 'nope'; available: "):
        varflow.make_params("nope")
