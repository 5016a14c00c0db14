"""Bounds files and checks (harness.config.bounds)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from harness.config.bounds import Bounds, Violation, check_bounds, load_bounds
from harness.config.errors import ConfigError

ROOT = Path(__file__).resolve().parents[1]
PAPER_BOUNDS = ROOT / "bounds" / "paper_mujoco.toml"

GOOD = {
    "e1_rms": 1e-4, "e1_max": 2e-4, "e2_rms": 1e-3, "e2_max": 2e-3, "e2_plant_rms": 1.5e-3,
    "e2_plant_max": 3e-3, "beta_min": 0.02, "mujoco_warnings": 0, "status": "ok",
}
ALL = Bounds(e1_rms_max=1e-3, e1_max_max=2e-3, e2_rms_max=1e-2, e2_max_max=2e-2, e2_plant_rms_max=1e-2,
             e2_plant_max_max=2e-2, beta_min_min=1e-3, no_mujoco_warnings=True, status_ok=True)


def test_shipped_paper_bounds_load():
    b = load_bounds(PAPER_BOUNDS)
    assert b.status_ok and b.no_mujoco_warnings
    for v in (b.e1_rms_max, b.e1_max_max, b.e2_rms_max, b.e2_max_max, b.beta_min_min):
        assert v is not None and v > 0
    assert "TODO" not in PAPER_BOUNDS.read_text()  # limits are measured, not placeholders


def test_all_within_bounds():
    assert check_bounds(GOOD, ALL) == []


def test_violation_lists_measured_and_limit():
    m = dict(GOOD, e2_rms=0.0123)
    (v,) = check_bounds(m, Bounds(e2_rms_max=0.01))
    assert (v.name, v.measured, v.limit, v.bound) == ("e2_rms", 0.0123, 0.01, "e2_rms_max")
    assert str(v) == "e2_rms = 0.0123 m exceeds limit 0.0100 m"


def test_every_violation_is_reported_in_order():
    bad = {"e1_rms": 2e-3, "e1_max": 1.0, "e2_rms": 0.5, "e2_max": 1.0, "e2_plant_rms": 0.5,
           "e2_plant_max": 1.0, "beta_min": 1e-5, "mujoco_warnings": 7, "status": "diverged"}
    names = [v.name for v in check_bounds(bad, ALL)]
    assert names == ["e1_rms", "e1_max", "e2_rms", "e2_max", "e2_plant_rms", "e2_plant_max", "beta_min",
                     "mujoco_warnings", "status"]


def test_min_bound():
    (v,) = check_bounds(dict(GOOD, beta_min=5e-4), Bounds(beta_min_min=1e-3))
    assert v.name == "beta_min" and v.measured == 5e-4 and v.limit == 1e-3
    assert "is below limit" in str(v)
    assert check_bounds(dict(GOOD, beta_min=1e-3), Bounds(beta_min_min=1e-3)) == []  # inclusive


def test_limit_is_inclusive():
    assert check_bounds(dict(GOOD, e2_rms=0.01), Bounds(e2_rms_max=0.01)) == []


@pytest.mark.parametrize("missing", ["absent", "none", "nan"])
def test_missing_metric_is_a_violation(missing):
    m = dict(GOOD)
    if missing == "absent":
        del m["e2_plant_rms"]
    else:
        # NaN: harness.loop.metrics' "not measured"
        m["e2_plant_rms"] = None if missing == "none" else math.nan
    (v,) = check_bounds(m, Bounds(e2_plant_rms_max=0.01))
    assert v.name == "e2_plant_rms" and v.measured is None
    assert "not measured" in str(v)


def test_missing_flag_metrics_are_violations():
    m = {k: v for k, v in GOOD.items() if k not in ("mujoco_warnings", "status")}
    names = {v.name for v in check_bounds(m, Bounds(no_mujoco_warnings=True, status_ok=True))}
    assert names == {"mujoco_warnings", "status"}


@pytest.mark.parametrize("value", [math.inf, -math.inf, "0.001", True, [0.0]])
def test_non_finite_or_non_number_is_a_violation(value):
    (v,) = check_bounds(dict(GOOD, e1_rms=value), Bounds(e1_rms_max=1.0))
    assert v.name == "e1_rms"
    assert str(v)


def test_flags():
    lax = Bounds(no_mujoco_warnings=False, status_ok=False)
    assert check_bounds(dict(GOOD, mujoco_warnings=3, status="diverged"), lax) == []
    (v,) = check_bounds(dict(GOOD, mujoco_warnings=3), Bounds(no_mujoco_warnings=True))
    assert v.measured == 3 and v.limit == 0 and "exceeds limit 0" in str(v)
    (v,) = check_bounds(dict(GOOD, status="interrupted"), Bounds())  # status_ok defaults to true
    assert v.name == "status" and v.measured == "interrupted" and "'ok'" in str(v)


def test_numpy_metrics():
    m = dict(GOOD, e2_rms=np.float64(0.5), mujoco_warnings=np.int64(0))
    (v,) = check_bounds(m, ALL)
    assert v.name == "e2_rms" and v.measured == 0.5


def test_violation_formatting_small_numbers():
    v = Violation("e1_rms", 1.5e-5, 1e-5, "e1_rms_max", "max", "m")
    assert str(v) == "e1_rms = 1.500e-05 m exceeds limit 1.000e-05 m"


# --------------------------------------------------------------------------------------------- bad files
BAD_FILES = [
    ("unknown-key", "[bounds]\ne2_rms_maxx = 0.1\n", "bounds.e2_rms_maxx"),
    ("unknown-top", "[bound]\ne2_rms_max = 0.1\n", "bound"),
    ("missing-table", 'description = "x"\n', "bounds"),
    ("not-table", "bounds = 3\n", "bounds"),
    ("negative", "[bounds]\ne2_rms_max = -0.1\n", "bounds.e2_rms_max"),
    ("zero", "[bounds]\ne1_rms_max = 0\n", "bounds.e1_rms_max"),
    ("nan", "[bounds]\ne1_rms_max = nan\n", "bounds.e1_rms_max"),
    ("bool-number", "[bounds]\nbeta_min_min = true\n", "bounds.beta_min_min"),
    ("string-number", '[bounds]\ne2_max_max = "0.1"\n', "bounds.e2_max_max"),
    ("number-flag", "[bounds]\nstatus_ok = 1\n", "bounds.status_ok"),
    ("bad-description", "description = 3\n[bounds]\n", "description"),
    ("invalid-toml", "[bounds\n", "invalid TOML"),
]


@pytest.mark.parametrize(("text", "needle"), [b[1:] for b in BAD_FILES], ids=[b[0] for b in BAD_FILES])
def test_bad_bounds_file(tmp_path, text, needle):
    p = tmp_path / "b.toml"
    p.write_text(text)
    with pytest.raises(ConfigError) as info:
        load_bounds(p)
    assert needle in str(info.value)
    assert "\n" not in str(info.value)


def test_unknown_key_suggestion_and_missing_file(tmp_path):
    p = tmp_path / "b.toml"
    p.write_text("[bounds]\ne2_rms_maxx = 0.1\n")
    with pytest.raises(ConfigError, match="did you mean 'bounds.e2_rms_max'"):
        load_bounds(p)
    with pytest.raises(ConfigError, match="not found"):
        load_bounds(tmp_path / "nope.toml")


def test_load_from_dict():
    b = load_bounds({"bounds": {"e2_rms_max": 1, "status_ok": False}})
    assert b.e2_rms_max == 1.0 and isinstance(b.e2_rms_max, float) and not b.status_ok


# --------------------------------------------------------------------------------------------- fuzzing
_BOUND_KEYS = sorted(Bounds.__dataclass_fields__) + ["description", "bounds", "x", ""]


def _fuzz_values():
    from hypothesis import strategies as st

    scalars = (st.none() | st.booleans() | st.integers() | st.floats(allow_nan=True, allow_infinity=True)
               | st.text(max_size=8))
    keys = st.sampled_from(_BOUND_KEYS) | st.text(max_size=4)
    return st.recursive(scalars, lambda inner: st.lists(inner, max_size=4)
                        | st.dictionaries(keys, inner, max_size=4), max_leaves=12)


@pytest.mark.slow
def test_fuzz_bounds_loader():
    """Random tables: load_bounds either returns Bounds or raises a one-line ConfigError."""
    from hypothesis import given, settings
    from hypothesis import strategies as st

    @settings(max_examples=300, deadline=None)
    @given(st.dictionaries(st.sampled_from(_BOUND_KEYS) | st.text(max_size=5), _fuzz_values(), max_size=6))
    def check(src):
        try:
            b = load_bounds(src)
        except ConfigError as e:
            assert "\n" not in str(e) and str(e)
            return
        assert isinstance(b, Bounds)
        check_bounds(GOOD, b)  # a valid Bounds can always be checked

    check()


def test_every_bounded_metric_is_the_field_s_own_with_its_unit_from_the_table():
    """Each numeric bound `<metric>_max`/`_min` names its metric, which has a unit in the one table
    (harness.config.metrics); its description and violation reports carry that unit."""
    from harness.config.bounds import FLAGS, limit_of
    from harness.config.metrics import METRIC_UNITS
    from harness.config.schema import description, info

    numeric = [f for f in info(Bounds).fields if f.name.endswith(("_max", "_min"))]
    assert len(numeric) > 10
    flagged = [m for m in FLAGS.values() if m != "status"]  # status is a row field, not a metric
    assert [m for m in flagged + [limit_of(f.name)[0] for f in numeric] if m not in METRIC_UNITS] == []
    for f in numeric:
        metric, rel, unit = limit_of(f.name)
        assert f.name == f"{metric}_{rel}"
        assert unit in (METRIC_UNITS[metric], "")
        desc = description(f.type)
        if unit:
            assert desc.startswith(f"{unit}, ")
            limit = {f.name: 1.0 if rel == "max" else 10.0}
            (v,) = check_bounds({metric: 9.0}, Bounds(status_ok=False, **limit))
            assert str(v).endswith(f" {unit}") and f"9.0000 {unit}" in str(v)
        else:
            assert desc.split(",")[0] not in METRIC_UNITS.values()
    # the units a value is printed with: the symbol, none for a dimensionless number, a count or a mixed unit
    assert {limit_of(f.name)[0]: limit_of(f.name)[2] for f in numeric if limit_of(f.name)[2] == ""} == {
        "beta_min": "", "deN_rms": "", "range_violation": ""}
