"""Scenario loading, validation, overrides and the TOML round trip (harness.config.load)."""

from __future__ import annotations

import dataclasses
import math
import tomllib
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from controllers.params import Gains, MasterParams, SlaveParams, SubtaskSpec
from harness.config import load as io_config
from harness.config import schema
from harness.config.errors import ConfigError
from harness.config.load import dump_scenario, load_scenario, parse_override, scenario_to_dict
from harness.config.scenario import Scenario

ROOT = Path(__file__).resolve().parents[1]
PAPER_TOML = ROOT / "scenarios" / "paper.toml"


# --------------------------------------------------------------------------------------------- defaults
@pytest.mark.parametrize("source", [None, {}, PAPER_TOML], ids=["none", "empty", "paper.toml"])
def test_defaults_reproduce_the_paper(source):
    scn = load_scenario(source)
    g = scn.gains
    assert (g.k1, g.k2, g.k3, g.k4, g.ky, g.ks, g.kn) == (3, 10, 10, 15, 1, 1, 100)  # eq. (39)
    assert scn.trajectory.center == (0.0, 1.0)  # eq. (40)
    assert scn.trajectory.amplitude == (0.01, 0.01)
    assert scn.trajectory.omega == 1.0
    assert scn.snr_db == 40.0
    assert scn.duration == 20.0
    assert scn.control_dt == 1e-3
    assert scn.master.lengths == (0.6, 0.6)
    assert scn.plant.master is None and scn.plant.slave is None
    assert scn == Scenario()


def test_paper_toml_spells_out_every_default():
    raw = tomllib.loads(PAPER_TOML.read_text())
    expected = scenario_to_dict(Scenario())
    assert raw == expected


def test_schema_matches_the_parameter_dataclasses():
    """The controller side's dataclasses (controllers.params, numpy only) declare names, types and
    defaults; harness.config.scenario adds ranges and descriptions.  Same names, same defaults, same
    types under the constraints, and the schema (the one range check) refuses just outside each bound."""
    import typing

    import msgspec

    from harness.config import scenario as sc

    for cls, spec in ((MasterParams, sc.MASTER), (SlaveParams, sc.SLAVE), (Gains, sc.GAINS),
                      (SubtaskSpec, sc.SUBTASK)):
        own = {f.name: f for f in dataclasses.fields(cls)}
        assert set(spec) == set(own), cls
        hints = typing.get_type_hints(cls)
        for name, tp in spec.items():
            def strip(t):
                t = schema.bare(t)
                for a in ("item_types",):
                    if hasattr(t, a):
                        return type(t)(tuple(strip(i) for i in getattr(t, a)))
                if hasattr(t, "item_type"):
                    return type(t)(strip(t.item_type))
                if isinstance(t, msgspec.inspect.LiteralType):
                    return msgspec.inspect.StrType()
                return type(t)()
            assert strip(schema.info(tp)) == strip(schema.info(hints[name])), (cls, name)
        derived = {f.name: f for f in dataclasses.fields(sc.checked(cls, spec))}
        assert {n: (f.default, f.default_factory) for n, f in derived.items()} == {
            n: (f.default, f.default_factory) for n, f in own.items()}
    # ranges: at every bound of the schema, a value just outside is refused; the bound itself, when
    # inclusive, is accepted
    def refused(fn):
        try:
            fn()
        except (ConfigError, ValueError):
            return True
        return False

    mismatches, checked = [], 0
    for cls, spec in ((MasterParams, sc.MASTER), (SlaveParams, sc.SLAVE), (Gains, sc.GAINS),
                      (SubtaskSpec, sc.SUBTASK)):
        typed = sc.checked(cls, spec)
        for name, tp in spec.items():
            t = schema.bare(schema.info(tp))
            item = schema.bare(t.item_types[0] if hasattr(t, "item_types") else getattr(t, "item_type", t))
            default = getattr(cls(), name)
            for bound, lower, inclusive in ((getattr(item, "gt", None), True, False),
                                            (getattr(item, "ge", None), True, True),
                                            (getattr(item, "lt", None), False, False),
                                            (getattr(item, "le", None), False, True)):
                if bound is None:
                    continue
                step = 1 if isinstance(bound, int) else max(abs(bound), 1.0) * 1e-9
                outside = bound if not inclusive else bound - step if lower else bound + step
                for v, ok in [(outside, False)] + ([(bound, True)] if inclusive else []):
                    value = (v, *default[1:]) if isinstance(default, tuple) else v
                    raw = list(value) if isinstance(value, tuple) else value
                    by_schema = refused(lambda: schema.decode({name: raw}, typed))  # noqa: B023
                    checked += 1
                    if by_schema != (not ok):
                        mismatches.append((cls.__name__, name, v, by_schema))
    assert checked > 30
    assert mismatches == []


# --------------------------------------------------------------------------------------------- bad inputs
BAD = [
    # (id, source dict, overrides, text the message must contain)
    ("unknown-top", {"durration": 5.0}, [], "durration"),
    ("unknown-section-key", {"gains": {"k5": 1.0}}, [], "gains.k5"),
    ("unknown-plant-key", {"plant": {"segmnts": 4}}, [], "plant.segmnts"),
    ("unknown-plant-slave-key", {}, ["plant.slave.mass=[1,1,1]"], "plant.slave.mass"),
    ("section-not-table", {"gains": 3}, [], "gains"),
    ("wrong-type-str", {"duration": "20"}, [], "duration"),
    ("bool-for-number", {"gains": {"k1": True}}, [], "gains.k1"),
    ("bool-for-int", {"seed": True}, [], "seed"),
    ("float-for-int", {"seed": 1.5}, [], "seed"),
    ("negative-gain", {"gains": {"kn": -100.0}}, [], "gains.kn"),
    ("zero-gain", {}, ["gains.k2=0"], "gains.k2"),
    ("nan-gain", {"gains": {"k3": math.nan}}, [], "gains.k3"),
    ("inf-duration", {"duration": math.inf}, [], "duration"),
    ("zero-mass", {"master": {"masses": [1.0, 0.0]}}, [], "master.masses"),
    ("zero-slave-mass", {}, ["slave.masses=[1.0, 0.0, 0.4]"], "slave.masses"),
    ("zero-plant-slave-mass", {}, ["plant.slave.masses=[0, 0.7, 0.4]"], "plant.slave.masses"),
    ("negative-length", {"master": {"lengths": [0.6, -0.6]}}, [], "master.lengths"),
    ("wrong-length-list", {"master": {"lengths": [0.6, 0.6, 0.6]}}, [], "master.lengths"),
    ("scalar-for-list", {"slave": {"rest_lengths": 0.3}}, [], "slave.rest_lengths"),
    ("negative-damping", {"slave": {"bending_damping": [0, -1, 0]}}, [], "slave.bending_damping"),
    ("zero-control-dt", {"control_dt": 0.0}, [], "control_dt"),
    ("negative-control-dt", {"control_dt": -1e-3}, [], "control_dt"),
    ("zero-physics-dt", {"plant": {"physics_dt": 0.0}}, [], "plant.physics_dt"),
    ("big-physics-dt", {"plant": {"physics_dt": 0.02}}, ["control_dt=0.02"], "plant.physics_dt"),
    ("control-dt-not-multiple", {"control_dt": 0.0015}, [], "control_dt"),
    ("control-dt-below-physics", {"control_dt": 0.0005}, [], "control_dt"),
    ("control-dt-above-duration", {"duration": 0.005, "transient": 0.0, "control_dt": 0.01,
                                   "plant": {"physics_dt": 0.01}}, [], "control_dt"),
    ("too-many-substeps", {"control_dt": 1.0, "plant": {"physics_dt": 1e-9}}, [], "plant.physics_dt"),
    ("too-many-steps", {"duration": 3600, "control_dt": 1e-5, "plant": {"physics_dt": 1e-5}}, [],
     "control_dt"),
    ("delay-ge-duration", {"duration": 1.0, "transient": 0.0, "plant": {"actuation_delay": 1.0}}, [],
     "plant.actuation_delay"),
    ("zero-duration", {"duration": 0}, [], "duration"),
    ("too-long-duration", {"duration": 3601}, [], "duration"),
    ("transient-ge-duration", {"duration": 2.0, "transient": 2.0}, [], "transient"),
    ("negative-transient", {"transient": -1.0}, [], "transient"),
    ("snr-too-high", {"snr_db": 201}, [], "snr_db"),
    ("snr-negative", {}, ["snr_db=-1"], "snr_db"),
    ("snr-true", {"snr_db": True}, [], "snr_db"),
    ("snr-word", {"snr_db": "off"}, [], "snr_db"),
    ("negative-seed", {"seed": -1}, [], "seed"),
    ("section-too-long", {"initial": {"slave_q2": [0.3, 0.3, 0.5, 0.0, 0.0, 0.0]}}, [], "initial.slave_q2"),
    ("section-too-short", {"initial": {"slave_q2": [0.29, 0.3, 0.3, 0.0, 0.0, 0.0]}}, [], "initial.slave_q2"),
    ("section-too-bent", {"initial": {"slave_q2": [0.3, 0.3, 0.3, 6.0, 0.0, 0.0]}}, [], "initial.slave_q2"),
    ("slave-q2-5-entries", {"initial": {"slave_q2": [0.3, 0.3, 0.3, 0.0, 0.0]}}, [], "initial.slave_q2"),
    ("elbow-zero", {"initial": {"master_elbow": 0}}, [], "initial.master_elbow"),
    ("elbow-bool", {"initial": {"master_elbow": True}}, [], "initial.master_elbow"),
    ("unreachable-far", {"trajectory": {"center": [0.0, 1.3]}}, [], "trajectory"),
    ("unreachable-margin", {"trajectory": {"center": [0.0, 1.1895]}}, [], "trajectory"),
    ("unreachable-amplitude", {"trajectory": {"amplitude": [0.25, 0.25]}}, [], "trajectory"),
    ("unreachable-inner", {"master": {"lengths": [0.9, 0.5]}, "trajectory": {"center": [0.0, 0.405]},
                           "initial": {"slave_q2": [0.3, 0.3, 0.3, 3.0, 0.0, 0.0]}}, [], "trajectory"),
    ("unreachable-plant-master", {}, ["plant.master.lengths=[0.5,0.5]"], "plant.master"),
    ("initial-offset-unreachable", {"initial": {"master_offset": [0.0, 0.5]}}, [], "initial.master_offset"),
    ("bad-plant-kind", {"plant": {"kind": "bullet"}}, [], "plant.kind"),
    ("bad-actuation", {}, ["plant.actuation=position"], "plant.actuation"),
    ("bad-integrator", {"plant": {"integrator": "RK4"}}, [], "plant.integrator"),
    ("segments-0", {"plant": {"segments": 0}}, [], "plant.segments"),
    ("segments-100", {"plant": {"segments": 100}}, [], "plant.segments"),
    ("segments-2.5", {"plant": {"segments": 2.5}}, [], "plant.segments"),
    ("segments-str", {}, ["plant.segments='8'"], "plant.segments"),
    ("servo-frequency-0", {"plant": {"servo_frequency": 0}}, [], "plant.servo_frequency"),
    ("servo-frequency-big", {"plant": {"servo_frequency": 1001}}, [], "plant.servo_frequency"),
    ("damping-ratio-0", {"plant": {"servo_damping_ratio": 0.0}}, [], "plant.servo_damping_ratio"),
    ("delay-negative", {"plant": {"actuation_delay": -0.001}}, [], "plant.actuation_delay"),
    ("delay-not-multiple", {"plant": {"actuation_delay": 0.0025}}, [], "plant.actuation_delay"),
    ("max-extension-1", {"slave": {"max_extension": 1.0}}, [], "slave.max_extension"),
    ("max-bend-big", {"slave": {"max_bend": 4.0}}, [], "slave.max_bend"),
    ("n-quad-1", {"slave": {"n_quad": 1}}, [], "slave.n_quad"),
    ("subtask-kind", {"subtask": {"kinds": ["manipulability", "joint_limits"]}}, [], "subtask.kinds"),
    ("subtask-weights-length", {"subtask": {"weights": [1.0]}}, [], "subtask.weights"),
    ("interaction-shape", {"interaction_forces": [[0.0, 0.0]]}, [], "interaction_forces"),
    ("bad-name", {"name": "../escape"}, [], "name"),
    ("plant-master-not-table", {"plant": {"master": 3}}, [], "plant.master"),
    ("continuous-on-mujoco", {"continuous_control": True}, [], "continuous_control"),
    ("slave-cannot-start", {"trajectory": {"center": [0.0, 0.8]}}, [], "trajectory.center"),
    ("curvature-too-big", {"initial": {"slave_curvature": 5.0}}, [], "initial.slave_curvature"),
    ("omega-nyquist", {"trajectory": {"omega": 4000.0}}, [], "trajectory.omega"),
]


@pytest.mark.parametrize(("source", "overrides", "needle"), [b[1:] for b in BAD], ids=[b[0] for b in BAD])
def test_bad_input_raises_config_error_naming_the_field(source, overrides, needle):
    with pytest.raises(ConfigError) as info:
        load_scenario(source, overrides)
    msg = str(info.value)
    assert needle in msg
    assert "\n" not in msg


def test_message_names_value_and_allowed_range():
    with pytest.raises(ConfigError, match=r"^plant\.segments = 100: must be an integer in \[1, 64\]"):
        load_scenario({"plant": {"segments": 100}})
    with pytest.raises(ConfigError, match=r"duration = 0: must be a number in \(0, 3600\]"):
        load_scenario({"duration": 0})
    with pytest.raises(ConfigError, match=r"gains\.k1 = True: .*\(got a boolean\)"):
        load_scenario({"gains": {"k1": True}})


def test_unknown_keys_get_suggestions():
    with pytest.raises(ConfigError, match="did you mean 'plant.segments'"):
        load_scenario({"plant": {"segmnts": 4}})
    with pytest.raises(ConfigError, match="did you mean 'plant.segments'"):
        load_scenario({"segments": 4})  # right key, wrong section
    with pytest.raises(ConfigError, match="did you mean 'duration'"):
        load_scenario({"durration": 5.0})


def test_reach_boundary_is_inclusive_of_the_margin():
    # |x_d| max = 1.189 + 0.01 = 1.199 = l1 + l2 - margin: allowed; 1e-4 further is not
    ok = load_scenario({"trajectory": {"center": [0.0, 1.189]}})
    assert ok.trajectory.center == (0.0, 1.189)
    with pytest.raises(ConfigError, match="annulus"):
        load_scenario({"trajectory": {"center": [0.0, 1.1891]}})


def test_reach_is_checked_only_over_the_simulated_arc():
    # x_d starts at (1.17, 0.03) and moves outwards along +X; within omega*duration = 0.5 rad it stays
    # inside the annulus, the full circle (|x_d| up to 1.2) does not.
    src = {"trajectory": {"center": [1.17, 0.0], "amplitude": [0.03, 0.03], "omega": 0.5},
           "duration": 1.0, "transient": 0.0, "initial": {"slave_q2": [0.3, 0.3, 0.3, 0.0, 0.0, 0.0]}}
    load_scenario(src)
    with pytest.raises(ConfigError, match="annulus"):
        load_scenario({**src, "duration": 10.0})
    rmin, rmax = io_config.trajectory_radius_range(load_scenario(src).trajectory, 100.0)
    assert rmin == pytest.approx(1.14, abs=1e-6) and rmax == pytest.approx(1.2, abs=1e-6)


def test_control_dt_multiple_tolerance():
    scn = load_scenario({"control_dt": 0.003, "plant": {"physics_dt": 0.001}})  # 2.9999999999999996
    assert scn.substeps == 3
    scn = load_scenario({"control_dt": 0.002, "plant": {"physics_dt": 0.0005, "actuation_delay": 0.006}})
    assert scn.substeps == 4
    with pytest.raises(ConfigError, match="control_dt"):
        load_scenario({"control_dt": 0.001 * (1 + 1e-6)})


def test_snr_none_and_false_mean_no_noise():
    assert load_scenario({"snr_db": "none"}).snr_db is None
    assert load_scenario({"snr_db": False}).snr_db is None
    assert load_scenario({}, ["snr_db=none"]).snr_db is None
    assert load_scenario({}, ["snr_db=30"]).snr_db == 30.0
    assert isinstance(load_scenario({"snr_db": 30}).snr_db, float)


def test_int_accepted_for_float_and_converted():
    scn = load_scenario({"duration": 10, "gains": {"k1": 2}, "trajectory": {"center": [0, 1]}})
    assert isinstance(scn.duration, float) and scn.duration == 10.0
    assert isinstance(scn.gains.k1, float)
    assert all(isinstance(v, float) for v in scn.trajectory.center)


# --------------------------------------------------------------------------------------------- overrides
def test_overrides_set_nested_values():
    scn = load_scenario(PAPER_TOML, ["plant.segments=16", "plant.slave.masses=[1.2,0.7,0.4]", "snr_db=30",
                                     "plant.kind=analytic", 'name="variant"'])
    assert scn.plant.segments == 16
    assert scn.plant.kind == "analytic"
    assert scn.snr_db == 30.0
    assert scn.name == "variant"
    # only the masses differ from the nominal slave
    assert scn.plant.slave == dataclasses.replace(scn.slave, masses=(1.2, 0.7, 0.4))
    assert scn.plant.master is None


def test_override_order_and_none():
    scn = load_scenario({}, ["plant.slave.masses=[1.2,0.7,0.4]", "plant.slave=none"])
    assert scn.plant.slave is None
    scn = load_scenario({}, ["seed=1", "seed=2"])
    assert scn.seed == 2


def test_override_errors_mention_the_override():
    with pytest.raises(ConfigError, match=r"from override 'plant\.segments=100'"):
        load_scenario({}, ["plant.segments=100"])
    with pytest.raises(ConfigError, match=r"from --segments 100"):
        load_scenario({}, ["plant.segments=100"], labels=["--segments 100"])
    with pytest.raises(ConfigError, match="key=value"):
        load_scenario({}, ["plant.segments"])
    with pytest.raises(ConfigError, match="invalid TOML value"):
        load_scenario({}, ["plant.slave.masses=[1,2"])
    with pytest.raises(ConfigError, match="not a dotted key"):
        load_scenario({}, ["plant..segments=3"])
    with pytest.raises(ConfigError, match="not a table"):
        load_scenario({"duration": 3.0, "transient": 0.0}, ["duration.x=1"])


def test_parse_override_values():
    assert parse_override("a.b=16") == (["a", "b"], 16)
    assert parse_override("a=[1.2, 0.7]") == (["a"], [1.2, 0.7])
    assert parse_override("a=analytic") == (["a"], "analytic")
    assert parse_override("a = none") == (["a"], "none")
    assert parse_override('a="x y"') == (["a"], "x y")
    assert parse_override("a=true") == (["a"], True)


def test_source_dict_is_not_modified():
    src = {"plant": {"segments": 4}}
    load_scenario(src, ["plant.segments=5", "plant.slave.masses=[1,1,1]"])
    assert src == {"plant": {"segments": 4}}


# --------------------------------------------------------------------------------------------- files
def test_file_errors(tmp_path):
    with pytest.raises(ConfigError, match="not found"):
        load_scenario(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("duration = [1,\n")
    with pytest.raises(ConfigError, match="invalid TOML") as info:
        load_scenario(bad)
    assert "bad.toml" in str(info.value)
    with pytest.raises(ConfigError):
        load_scenario(tmp_path)  # a directory
    wrong = tmp_path / "wrong.toml"
    wrong.write_text("[plant]\nsegments = 0\n")
    with pytest.raises(ConfigError, match=r"wrong\.toml: plant\.segments = 0"):
        load_scenario(wrong)


def test_name_defaults_to_file_stem(tmp_path):
    p = tmp_path / "short_run.toml"
    p.write_text("duration = 1.0\ntransient = 0.0\n")
    assert load_scenario(p).name == "short_run"
    p.write_text('name = "explicit"\n')
    assert load_scenario(p).name == "explicit"


def test_subtask_weights_default_per_kind():
    assert load_scenario({"subtask": {"kinds": ["limits"]}}).subtask.weights == (0.05,)
    assert load_scenario({"subtask": {"kinds": []}}).subtask.weights == ()


def test_parameter_error_is_wrapped_with_the_path():
    with pytest.raises(ConfigError, match=r"^plant\.master\.lengths"):
        load_scenario({"plant": {"master": {"lengths": [1.0]}}})
    with pytest.raises(ConfigError, match=r"^slave\.max_bend"):
        load_scenario({"slave": {"max_bend": 5.0}})


# --------------------------------------------------------------------------------------------- round trip
ROUND_TRIP = {
    "default": ({}, []),
    "mismatch": ({}, ["plant.master.masses=[1.5, 0.5]", "plant.slave.masses=[1.2,0.7,0.4]",
                      "plant.slave.bending_stiffness=[7.5, 3.1, 0.9]"]),
    "no-noise-analytic": ({"snr_db": "none", "continuous_control": True,
                           "plant": {"kind": "analytic", "physics_dt": 0.0005}}, []),
    "explicit-q2": ({"initial": {"slave_q2": [0.34, 0.33, 0.35, 0.5, -0.2, 0.1], "master_elbow": 1}}, []),
    "odd-floats": ({"duration": 7.3, "transient": 0.1, "seed": 12345,
                    "trajectory": {"center": [0.1, 0.95], "amplitude": [0.0125, 0.02], "omega": 2.5},
                    "interaction_forces": [[0.1, -0.2], [0.3, 0.0]],
                    "subtask": {"kinds": ["manipulability"], "weights": [0.7]}}, []),
}


@pytest.mark.parametrize(("source", "overrides"), list(ROUND_TRIP.values()), ids=list(ROUND_TRIP))
def test_dump_load_round_trip(tmp_path, source, overrides):
    scn = load_scenario(source, overrides)
    path = dump_scenario(scn, tmp_path / "config.toml")
    back = load_scenario(path)
    assert back == scn
    assert (back.plant.master is None) == (scn.plant.master is None)
    assert (back.plant.slave is None) == (scn.plant.slave is None)
    assert load_scenario(scenario_to_dict(scn)) == scn
    # the dump is complete: every schema key is present
    raw = tomllib.loads(path.read_text())
    for key in schema.paths(Scenario):
        node = raw
        parts = key.split(".")
        if parts[0] == "plant" and len(parts) == 3 and not isinstance(raw["plant"][parts[1]], dict):
            continue
        for p in parts:
            node = node[p]


def test_plant_model_set_equal_to_nominal_stays_set(tmp_path):
    scn = load_scenario({"plant": {"slave": {}}})
    assert scn.plant.slave == scn.slave
    assert load_scenario(dump_scenario(scn, tmp_path / "c.toml")).plant.slave is not None


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    gains=st.lists(st.floats(1e-3, 1e3, allow_nan=False), min_size=7, max_size=7),
    snr=st.none() | st.floats(0, 200),
    seed=st.integers(0, 2**63 - 1),
    segments=st.integers(1, 64),
    masses=st.none() | st.lists(st.floats(1e-3, 10), min_size=3, max_size=3),
    amp=st.floats(0, 0.05),
)
@pytest.mark.slow
def test_round_trip_property(tmp_path, gains, snr, seed, segments, masses, amp):
    src = {
        "gains": dict(zip(["k1", "k2", "k3", "k4", "ky", "ks", "kn"], gains, strict=True)),
        "snr_db": "none" if snr is None else snr, "seed": seed,
        "plant": {"segments": segments, **({"slave": {"masses": masses}} if masses else {})},
        "trajectory": {"amplitude": [amp, amp]},
    }
    scn = load_scenario(src)
    assert load_scenario(dump_scenario(scn, tmp_path / "rt.toml")) == scn


# --------------------------------------------------------------------------------------------- fuzzing
_KEYS = sorted({p for path in schema.paths(Scenario) for p in path.split(".")} | {"x", "", "none"})
_scalars = (
    st.none() | st.booleans() | st.integers() | st.integers(-(10**400), 10**400)
    | st.floats(allow_nan=True, allow_infinity=True) | st.text(max_size=8)
    | st.sampled_from(["none", "mujoco", "analytic", "servo", "torque", "rk4", "manipulability", "limits"])
)
_values = st.recursive(
    _scalars,
    lambda inner: st.lists(inner, max_size=7) | st.dictionaries(st.sampled_from(_KEYS) | st.text(max_size=5),
                                                                 inner, max_size=5),
    max_leaves=25,
)
_tables = st.dictionaries(st.sampled_from(_KEYS) | st.text(max_size=6) | st.integers(), _values, max_size=8)


def _check_loader(src) -> None:
    try:
        scn = load_scenario(src)
    except ConfigError:
        return
    assert isinstance(scn, Scenario)


@pytest.mark.slow
@settings(max_examples=200, deadline=None)
@given(_tables)
def test_fuzz_random_tables(src):
    _check_loader(src)


@pytest.mark.slow
@settings(max_examples=200, deadline=None)
@given(st.data())
def test_fuzz_mutated_valid_scenario(data):
    """Replace a few leaves (or whole tables) of a valid scenario with random values."""
    src = scenario_to_dict(Scenario())
    for _ in range(data.draw(st.integers(1, 3))):
        path = data.draw(st.sampled_from(schema.paths(Scenario))).split(".")
        node = src
        for p in path[:-1]:
            if not isinstance(node.get(p), dict):
                node[p] = {}
            node = node[p]
        node[path[-1]] = data.draw(_values)
    _check_loader(src)


@settings(max_examples=100, deadline=None)
@given(st.lists(st.text(max_size=30) | st.from_regex(r"[a-z_.]{1,20}=[\[\]0-9a-z.,\"' -]{0,20}",
                                                     fullmatch=True), max_size=4))
@pytest.mark.slow
def test_fuzz_overrides(overrides):
    try:
        scn = load_scenario(None, overrides)
    except ConfigError:
        return
    assert isinstance(scn, Scenario)


def test_short_run_gets_a_quarter_transient_unless_set():
    assert load_scenario({"duration": 2.0}).transient == 0.5
    assert load_scenario({"duration": 2.0, "transient": 0.1}).transient == 0.1
    assert load_scenario({"duration": 30.0}).transient == 5.0


def test_scene_xml_missing_malformed_or_incomplete(tmp_path):
    from harness import load_scenario as load_with_plant  # the plant checks its own scene

    with pytest.raises(ConfigError, match=r"plant\.scene_xml.*not found"):
        load_with_plant({"plant": {"scene_xml": str(tmp_path / "nope.xml")}})
    bad = tmp_path / "bad.xml"
    bad.write_text("<mujoco><worldbody><body name='x'><geom size='oops'/></body></worldbody></mujoco>")
    with pytest.raises(ConfigError, match=r"plant\.scene_xml.*unusable MJCF"):
        load_with_plant({"plant": {"scene_xml": str(bad)}})
    empty = tmp_path / "empty.xml"
    empty.write_text("<mujoco><worldbody/></mujoco>")
    with pytest.raises(ConfigError, match=r"plant\.scene_xml.*unusable MJCF"):
        load_with_plant({"plant": {"scene_xml": str(empty)}})
    with pytest.raises(ConfigError, match=r"plant\.scene_xml"):
        load_with_plant({"plant": {"scene_xml": 3}})


def test_scene_xml_custom_scene_is_accepted(tmp_path):
    """A user scene that includes the shipped robots (e.g. a different floor) loads and round-trips."""
    mjcf = Path(__file__).resolve().parents[1] / "mjcf"
    scene = tmp_path / "my_scene.xml"
    scene.write_text(f"""<mujoco model="my_scene">
  <include file="{mjcf / 'master.xml'}"/>
  <include file="{mjcf / 'octarm_base.xml'}"/>
  <option timestep="0.001" integrator="implicitfast"><flag contact="disable"/></option>
  <worldbody><light name="my_light" pos="0 0 3"/></worldbody>
</mujoco>""")
    scn = load_scenario({"plant": {"scene_xml": str(scene)}})
    assert scn.plant.scene_xml == str(scene)


def test_scene_xml_is_used_by_the_plant(tmp_path):
    from harness.plant.mujoco_model import build_model

    mjcf = Path(__file__).resolve().parents[1] / "mjcf"
    scene = tmp_path / "my_scene.xml"
    scene.write_text(f"""<mujoco model="my_scene">
  <include file="{mjcf / 'master.xml'}"/>
  <include file="{mjcf / 'octarm_base.xml'}"/>
  <option timestep="0.001" integrator="implicitfast"><flag contact="disable"/></option>
  <worldbody><light name="my_special_light" pos="0 0 3"/></worldbody>
</mujoco>""")
    scn = load_scenario({"plant": {"scene_xml": str(scene), "segments": 2}})
    m, _ = build_model(scn.plant_master, scn.plant_slave, scn.plant)
    assert m.light("my_special_light").id >= 0


# --- the schema's positivity rule on the model parameters (finite and > 0, or >= 0) --------------
@pytest.mark.parametrize("value", [1.0, 2.0, 0.0, -1.0, float("nan"), float("inf"), 1e-300, -0.0, 5])
@pytest.mark.parametrize("key, allow_zero", [("gains.k1", False), ("master.gravity", True)])
def test_positivity_of_model_parameters(value, key, allow_zero):
    bad = not math.isfinite(value) or (value < 0 if allow_zero else value <= 0)
    try:
        load_scenario({key.split(".")[0]: {key.split(".")[1]: value}})
        outcome = None
    except ConfigError as e:
        outcome = str(e)
    assert (outcome is not None) == bad
    if bad:
        assert outcome.startswith(f"{key} = ")


def test_toml_values_are_plain_python():
    from harness.config.load import to_toml

    out = to_toml((np.float64(1.5), np.int64(2), True, 3, "x", None, [np.float32(0.25)]))
    assert out == [1.5, 2, True, 3, "x", "none", [0.25]]
    assert [type(v) for v in out[:5]] == [float, int, bool, int, str]
    assert type(out[6][0]) is float


def test_continuous_control_refuses_an_actuation_delay():
    with pytest.raises(ConfigError, match=r"continuous_control = True: .*requires plant.actuation_delay = 0"):
        load_scenario(None, ["plant.kind=analytic", "continuous_control=true", "plant.actuation_delay=0.002"])
