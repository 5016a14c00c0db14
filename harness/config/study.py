"""The study file's schema (`harness.studies.study.load_study` reads it): [study], [[factor]],
[sampling] and an optional inline [scenario], each field declared once with its range and description."""

import re
from dataclasses import dataclass, field
from typing import Any, Literal

from harness.config.metrics import METRIC_NAMES
from harness.config.schema import doc, integer, num

# the keys of each {random = kind, ...} table with their ranges (low < high, integers: low <= high)
DISTRIBUTIONS = {
    "uniform": {"low": num(""), "high": num("")},
    "loguniform": {"low": num("", gt=0.0), "high": num("")},
    "normal": {"mean": num(""), "std": num("", gt=0.0)},
    "integers": {"low": integer(""), "high": integer("")},
}
DEFAULT_MAX_CASES = 10000  # [sampling] max_cases / --max-cases
PARAM_RE = re.compile(r"^([A-Za-z_]\w*(?:\.[A-Za-z_]\w*)*)(?:\[(\d+)\])?$")


_Number = int | float


@dataclass(frozen=True)
class Record:
    worst: integer("number of worst cases recorded as .rrd", ge=1) = 1
    by: doc(Literal[METRIC_NAMES], "metric that ranks the cases (one of study.metrics)") = "e2_rms"
    order: doc(Literal["max", "min"] | None, 'which end of the metric is worst; default "min" for beta_min, '
               'else "max"') = None


@dataclass(frozen=True)
class StudyTable:
    name: doc(doc(str, "", pattern=r"^[\w.-]+$") | None, "output folder name (letters, digits, '_', '-', "
              "'.'); default: the file's stem") = None
    description: doc(str, "free text") = ""
    scenario: doc(str | None, "base scenario file, relative to the study file; default: the inline "
                  "[scenario] table or the built-in paper scenario") = None
    set: doc(tuple[str, ...], "scenario overrides 'key=value' applied to every case") = ()
    metrics: doc(tuple[Literal[METRIC_NAMES], ...], "metrics kept per case (default: all)",
                 min_length=1) = METRIC_NAMES
    record: doc(Record | None, "recordings of the worst cases: {worst, by, order}") = None


@dataclass(frozen=True)
class Factor:
    """One varied field; `name` defaults to `param`; `mode`: "scale" or "values" (the one given), `dist`:
    its {random = ...} table or `levels`: its list; `path`, `index`: ("plant", "slave", "masses"), 0 of
    param "plant.slave.masses[0]"."""

    param: doc(str, "dotted Scenario path, optionally indexed (plant.slave.masses[0]); "
               "'controller' compares controllers", pattern=PARAM_RE.pattern,
               expect="a dotted Scenario path like 'plant.slave.masses[0]'")
    name: doc(doc(str, "", min_length=1) | None, "label in tables and plots; default: param") = None
    scale: doc(list[_Number] | dict[str, Any] | None, "multiplicative factors of the nominal value, "
               "or a {random = ...} table", expect="an array of numbers or a {random = ...} table") = None
    values: doc(list[Any] | dict[str, Any] | None, "absolute values, or a {random = ...} table",
                expect="an array of values or a {random = ...} table") = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "name", self.param if self.name is None else self.name)

    @property
    def mode(self) -> str:
        return "scale" if self.scale is not None else "values"

    @property
    def dist(self) -> dict | None:
        spec = getattr(self, self.mode)
        return spec if isinstance(spec, dict) else None

    @property
    def is_random(self) -> bool:
        return self.dist is not None

    @property
    def levels(self) -> tuple | None:
        return None if self.is_random else tuple(getattr(self, self.mode) or ())

    @property
    def path(self) -> tuple[str, ...]:
        return tuple(PARAM_RE.match(self.param).group(1).split("."))

    @property
    def index(self) -> int | None:
        i = PARAM_RE.match(self.param).group(2)
        return None if i is None else int(i)


@dataclass(frozen=True)
class SamplingTable:
    mode: doc(Literal["grid", "random"], '"grid": cartesian product; "random": n random cases') = "grid"
    n: doc(integer("", ge=1) | None, "number of random draws (mode = 'random' or random factors)") = None
    seed: integer("seed of the random draws", ge=0) = 0
    max_cases: integer("refuse larger studies before expanding them (--max-cases)", ge=1) = DEFAULT_MAX_CASES


@dataclass(frozen=True)
class StudyFile:
    """A study file: [study], one [[factor]] per varied field, [sampling], an optional inline
    [scenario] (same keys as a scenario file)."""

    factor: doc(tuple[Factor, ...], "one table per varied field (at least one)") = ()
    study: doc(StudyTable, "the study") = field(default_factory=StudyTable)
    sampling: doc(SamplingTable, "how cases are drawn") = field(default_factory=SamplingTable)
    scenario: doc(dict[str, Any] | None, "inline base scenario (instead of study.scenario)") = None
