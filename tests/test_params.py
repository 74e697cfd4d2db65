"""Parameter files: typed loading, merging and validation with clear errors."""

from __future__ import annotations

import json

import pytest

from ehm_drake.params import (
    ParameterError,
    apply_variant,
    load_params,
    params_from_dict,
    save_params,
)


def test_defaults_load_and_are_physical(params):
    assert params.simulation.time_step_s == 0.001  # paper: 1 ms
    assert params.pid.integrator
    assert params.contact.model == "point"
    assert all(k > 0 for k in params.passive.lumbar.stiffness)


def test_partial_file_merges_over_defaults(tmp_path, params):
    f = tmp_path / "p.yaml"
    f.write_text("pid:\n  spine:\n    kp: [1, 2, 3]\n")
    p = load_params(f)
    assert p.pid.spine.kp == (1.0, 2.0, 3.0)
    assert p.pid.spine.kd == params.pid.spine.kd
    assert p.passive == params.passive


def test_json_round_trip(tmp_path, params):
    f = tmp_path / "p.json"
    save_params(params, f)
    assert load_params(f) == params
    g = tmp_path / "p.yaml"
    save_params(params, g)
    assert load_params(g) == params


@pytest.mark.parametrize("data,match", [
    ({"pid": {"spine": {"kpp": [1, 2, 3]}}}, r"pid\.spine\.kpp"),
    ({"passive": {"hips": {"stiffness": [-1, 2, 3]}}}, r"passive\.hips\.stiffness\[0\].*negative"),
    ({"contact": {"pelvis_pan": {"stiffness": float("nan")}}},
     r"contact\.pelvis_pan\.stiffness.*finite"),
    ({"contact": {"pelvis_pan": {"damping": "soft"}}}, r"contact\.pelvis_pan\.damping.*number"),
    ({"contact": {"model": "magic"}}, r"contact\.model"),
    ({"simulation": {"time_step_s": 1.0}}, r"time_step_s.*milliseconds"),
    ({"pid": {"spine": {"kp": [1, 2]}}}, r"pid\.spine\.kp.*3 numbers"),
    ({"pid": {"integrator": "yes"}}, r"pid\.integrator"),
    ({"bogus": 1}, r"bogus"),
])
def test_bad_parameters_name_the_key(data, match):
    with pytest.raises(ParameterError, match=match):
        params_from_dict(data)


def test_bad_files(tmp_path):
    with pytest.raises(ParameterError, match="not found"):
        load_params(tmp_path / "missing.yaml")
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(ParameterError, match="not valid JSON"):
        load_params(bad)
    lst = tmp_path / "list.yaml"
    lst.write_text("- 1\n- 2\n")
    with pytest.raises(ParameterError, match="mapping"):
        load_params(lst)


def test_fit_result_file_is_accepted(tmp_path, params):
    f = tmp_path / "fitted.json"
    f.write_text(json.dumps({"ehm_drake_fit": 1, "params": {"his": {"kp": [1, 1, 1]}}}))
    assert load_params(f).his.kp == (1.0, 1.0, 1.0)


def test_variants(params):
    no_i = apply_variant(params, "no-integrator")
    assert not no_i.pid.integrator and params.pid.integrator  # input untouched
    hs = apply_variant(params, "high-stiffness")
    f = params.variants.high_stiffness_factor
    assert hs.passive.neck.stiffness[1] == pytest.approx(f * params.passive.neck.stiffness[1])
    assert not hs.pid.integrator
    with pytest.raises(ParameterError, match="unknown variant"):
        apply_variant(params, "stiff")
