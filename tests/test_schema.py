"""The schema as the one source: the reference pages list every field, the docs page is current, and a
controller's Params are parsed through the same decoder and one-line errors."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pytest

from harness.config import reference
from harness.config.bounds import BoundsFile
from harness.config.controller import parse_params
from harness.config.errors import ConfigError
from harness.config.scenario import Scenario
from harness.config.schema import fields_of
from harness.config.study import StudyFile

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize(("kind", "cls"),
                         [("scenario", Scenario), ("bounds", BoundsFile), ("study", StudyFile)])
def test_reference_lists_every_schema_field(kind, cls):
    page = reference.markdown(kind)
    paths = [p for p, _, _ in fields_of(cls, arrays=True)]
    assert len(paths) > 10
    missing = [p for p in paths if f"| `{p}" not in page]
    assert missing == []
    rows = [line for line in page.splitlines() if line.startswith("| `")]
    assert len(rows) == len(paths)
    assert all(line.count(" | ") >= 4 for line in rows)  # field, type, default, allowed, description


def test_every_scenario_field_has_a_description():
    from harness.config.schema import description

    bare = [p for p, t, _ in fields_of(Scenario, arrays=True) if not description(t)]
    assert bare == []


@dataclass(frozen=True)
class _Params:
    gain: float = 10.0
    steps: int = 3
    mode: str = "a"
    offset: tuple[float, float] = (0.0, 0.0)
    on: bool = True

    def check(self):
        from controllers.interface import check_range

        check_range("gain", self.gain, 0.0, lo_open=True)


class _Ctrl:
    name = "demo"
    Params = _Params


class _NoParams:
    name = "bare"
    Params = None


def test_parse_params_defaults_and_conversion():
    p = parse_params(_Ctrl, {"gain": 2, "offset": [1, 2]})
    assert p == _Params(gain=2.0, offset=(1.0, 2.0)) and isinstance(p.gain, float)
    assert parse_params(_Ctrl, None) == _Params()
    assert parse_params(_NoParams, {}) is None


@pytest.mark.parametrize(("raw", "text"), [
    ({"gian": 3}, "controller.params.gian = 3: unknown key; did you mean 'controller.params.gain'?"),
    ({"gain": "x"}, "controller.params.gain = 'x': must be a finite number (got a string)"),
    ({"gain": float("nan")}, "controller.params.gain = nan: must be finite"),
    ({"steps": 1.5}, "controller.params.steps = 1.5: must be an integer (got a float)"),
    ({"on": 1}, "controller.params.on = 1: must be true or false"),
    ({"offset": [1]}, "controller.params.offset = [1]: must be an array of 2 finite numbers (got 1 entries)"),
])
def test_parse_params_errors_are_one_line(raw, text):
    with pytest.raises(ConfigError) as info:
        parse_params(_Ctrl, raw)
    assert str(info.value).startswith(text) and "\n" not in str(info.value)


def test_parse_params_keeps_the_class_check_and_no_params():
    with pytest.raises(ConfigError, match=r"controller\.params\.gain = -1\.0: must be > 0"):
        parse_params(_Ctrl, {"gain": -1})
    with pytest.raises(ConfigError, match="controller.params.k = 1: unknown key; controller 'bare' takes no"):
        parse_params(_NoParams, {"k": 1})


def test_shipped_params_parse_and_refuse_in_one_line():
    """The shipped controllers' Params (built-in and example) take their defaults and valid values, and
    refuse a wrong type, an out-of-range value and an unknown key in one line naming the key."""
    from harness.config.controller import BUILTINS, load_class

    example = load_class(f"{ROOT / 'examples' / 'controllers' / 'jacobian_transpose.py'}:JacobianTransposePD")
    classes = [c for c in [*BUILTINS.values(), example] if getattr(c, "Params", None) is not None]
    assert len(classes) == 2
    for cls in classes:
        key, default = next(iter(vars(cls.Params()).items()))
        assert parse_params(cls, {}) == cls.Params()
        assert parse_params(cls, {key: 2 * default + 1}) == cls.Params(**{key: 2 * default + 1})
        for raw in ({key: "x"}, {key: -1.0}, {"nope": 1}):
            with pytest.raises(ConfigError) as b:
                parse_params(cls, raw)
            text = str(b.value)
            assert text.startswith(f"controller.params.{next(iter(raw))} = ") and "\n" not in text


def test_set_refuses_an_unknown_object_name():
    from harness.config.load import load_scenario

    src = {"environment": {"objects": {"wall": {"kind": "plane"}}}}
    with pytest.raises(ConfigError, match="did you mean 'environment.objects.wall'"):
        load_scenario(src, ["environment.objects.wal.stiffness=1e5"])
    scn = load_scenario(src, ["environment.objects.wall.stiffness=1e5"])
    assert [(o.name, o.stiffness) for o in scn.environment.objects] == [("wall", 1e5)]
    scn = load_scenario(src, ['environment.objects.box2={kind="box", position=[0.3, 1.2]}'])
    assert [o.name for o in scn.environment.objects] == ["wall", "box2"]
