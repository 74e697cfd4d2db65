"""Parameter files: typed loading, merging and validation with clear errors."""

from __future__ import annotations

import json

import pytest

from ehm_drake.params import (
    COMMAND_DESIGN,
    ParameterError,
    apply_variant,
    command_design,
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


# ---------------------------------------------------------------------------
# Bad files: one line naming the file, the key and (for a value) the allowed range
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("name,text,expected", [
    ("unknown.yaml", "pid:\n  spine:\n    kpp: [1, 2, 3]\n",
     "unknown.yaml: unknown parameter key: pid.spine.kpp "
     "(known here: kp, kd, integral_time_s, integral_torque_limit)"),
    ("type.yaml", "contact:\n  pelvis_pan:\n    damping: soft\n",
     "type.yaml: contact.pelvis_pan.damping: expected a number, got 'soft'"),
    ("item.yaml", "pid:\n  spine:\n    kp: [1, 2, true]\n",
     "item.yaml: pid.spine.kp[2]: expected a number, got True"),
    ("bool.yaml", "pid:\n  integrator: 1\n",
     "bool.yaml: pid.integrator: expected true/false, got 1"),
    ("nan.yaml", "contact:\n  pelvis_pan:\n    stiffness: .nan\n",
     "nan.yaml: contact.pelvis_pan.stiffness: must be finite, got nan (allowed > 0 N/m)"),
    ("nan.json", '{"his": {"kd": [1, NaN, 1]}}',
     "nan.json: his.kd[1]: must be finite, got nan (allowed >= 0 N m s/rad)"),
    ("negative.yaml", "passive:\n  neck:\n    stiffness: [-1, 1, 1]\n",
     "negative.yaml: passive.neck.stiffness[0] = -1.0: must not be negative "
     "(allowed >= 0 N m/rad)"),
    ("step.yaml", "simulation:\n  time_step_s: 10\n",
     "step.yaml: simulation.time_step_s = 10.0: allowed 1e-05..0.01 s "
     "(1 ms as in the paper; give seconds, not milliseconds)"),
    ("rate.yaml", "simulation:\n  time_step_s: 0.002\n  output_rate_hz: 1000\n",
     "rate.yaml: simulation.output_rate_hz = 1000.0: allowed 100..500 Hz "
     "(at least 100 Hz, at most the simulation rate 1/simulation.time_step_s)"),
    ("period.yaml", "simulation:\n  design: implicit\n  time_step_s: 0.002\n",
     "period.yaml: simulation.output_rate_hz = 200: the output period must be a whole number "
     "of time steps (0.002 s); it is 2.5 steps"),
    ("pair.yaml", "contact:\n  thighs_pan: {stiffness: 0}\n",
     "pair.yaml: contact.thighs_pan.stiffness = 0.0: allowed > 0 N/m "
     "(a contact pair without stiffness does not carry the body)"),
    ("limit.yaml", "restraints:\n  feet_floor: {force_limit: 0}\n",
     "limit.yaml: restraints.feet_floor.force_limit must be positive when "
     "restraints.feet_floor.stiffness > 0, got 0.0 (allowed > 0 N: beyond this force the "
     "restraint slips)"),
    ("model.yaml", "contact:\n  model: magic\n",
     "model.yaml: contact.model = 'magic': allowed 'point' or 'hydroelastic'"),
    ("group.yaml", "his: 3\n", "group.yaml: his: expected a mapping, got 3"),
    ("short.yaml", "his:\n  kp: [1, 2]\n",
     "short.yaml: his.kp: expected a list of 3 numbers, got [1, 2]"),
    ("syntax.yaml", "his: [1\n",
     "syntax.yaml: not valid YAML: line 2, column 1: while parsing a flow sequence, "
     "expected ',' or ']', but got '<stream end>'"),
])
def test_bad_file_errors_are_one_line_naming_file_key_and_range(tmp_path, name, text,
                                                                expected):
    f = tmp_path / name
    f.write_text(text)
    with pytest.raises(ParameterError) as e:
        load_params(f)
    assert str(e.value) == f"{tmp_path}/{expected}"
    assert "\n" not in str(e.value) and str(e.value).count(name) == 1


def test_conditional_ranges_only_apply_when_their_condition_holds():
    p = params_from_dict({"pid": {"integrator": False, "spine": {"integral_time_s": 0}}})
    assert p.pid.spine.integral_time_s == 0
    assert params_from_dict({"restraints": {"pelvis_pan": {"stiffness": 0,
                                                           "force_limit": 0}}})
    with pytest.raises(ParameterError, match=r"pid\.neck\.integral_time_s must be positive when "
                                             r"pid\.integrator is true, got 0\.0"):
        params_from_dict({"pid": {"neck": {"integral_time_s": 0}}})


def test_drake_loader_conventions(tmp_path, params):
    """What yaml_load_typed adds over plain YAML: numbers written as YAML 1.2
    or quoted are read as numbers (PyYAML leaves "8.0e4" a string), "true"
    reads as a bool; one number stands for all three components of a vector."""
    f = tmp_path / "p.yaml"
    f.write_text("passive:\n  spine_axial_stiffness: 8.0e4\nhis:\n  enabled: 'true'\n"
                 "  kd: 0.7\n  kp: ['1.5', 2, 3]\n")
    p = load_params(f)
    assert p.passive.spine_axial_stiffness == 80000.0 and p.his.enabled is True
    assert p.his.kd == (0.7, 0.7, 0.7) and p.his.kp == (1.5, 2.0, 3.0)
    assert all(type(x) is float for x in p.his.kd + p.his.kp)


def test_complete_dicts_load_exactly(params):
    """Sweep and fit pass complete parameter sets: the same values come back,
    bit for bit, and the caller's dict is not changed."""
    d = params.to_dict()
    d["pid"]["spine"]["kp"] = [1, 2.5, 3]
    d["passive"]["knees"]["stiffness"][0] = -0.0
    before = json.dumps(d)
    p = params_from_dict(d)
    assert json.dumps(d) == before
    assert json.dumps(p.to_dict()) == before.replace("[1, 2.5, 3]", "[1.0, 2.5, 3.0]")
    assert load_params() == params and load_params() is not load_params()


def test_every_number_has_a_range_row_with_a_unit(params):
    """The RANGES table covers every numeric key (none falls to the catch-all)."""
    from ehm_drake.params import RANGES, _walk_values, range_of

    bases = {base for _, base, v in _walk_values(params) if isinstance(v, float)}
    for base in bases:
        r = range_of(base)
        assert r is not RANGES[-1], base
        assert r.unit or base == "variants.high_stiffness_factor", base


def test_fit_bounds_lie_within_the_admissible_ranges(params):
    """The fit's physiological bounds (data/fit_parameters.yaml) are a
    narrower, sourced prior; each must be admissible and in the same unit."""
    from ehm_drake.identification.parameters import load_registry
    from ehm_drake.params import range_of

    registry, _ = load_registry()
    for fp in registry.values():
        lo, hi = fp.bounds
        for path in fp.paths:
            r = range_of(path)
            assert r.unit == fp.unit, (fp.name, path)
            top = r.hi(params) if callable(r.hi) else r.hi
            assert r.lo <= lo < hi <= top and (lo > 0 or not r.lo_open), (fp.name, path)


def test_commands_run_the_implicit_design_unless_the_file_states_the_stepping(tmp_path,
                                                                                params):
    """The commands' design: --design when given; else a parameter file's
    that states its design or its step (a step chosen for one design stays
    on it); else the implicit design, also for the packaged configurations.
    `load_params()` itself keeps the paper's reference design."""
    assert params.simulation.design == "reference" and COMMAND_DESIGN == "implicit"
    assert command_design(None, None) == "implicit"
    assert command_design(None, "reference") == "reference"
    assert command_design("rigid_seat", None) == "implicit"
    cases = {"design.yaml": "simulation: {design: reference}\n",
             "step.yaml": "simulation: {time_step_s: 0.0005}\n",
             "other.yaml": "simulation: {settle_time_s: 2.0}\n"}
    for name, text in cases.items():
        (tmp_path / name).write_text(text)
    assert command_design(tmp_path / "design.yaml", None) is None
    assert command_design(tmp_path / "step.yaml", None) is None
    assert command_design(tmp_path / "step.yaml", "implicit") == "implicit"
    assert command_design(tmp_path / "other.yaml", None) == "implicit"
    # A complete parameter set (save_params, a fit's output) states both.
    save_params(params, tmp_path / "all.yaml")
    assert command_design(tmp_path / "all.yaml", None) is None
