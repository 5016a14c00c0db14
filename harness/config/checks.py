"""Primitive checkers of the scenario schema: (dotted path, raw TOML value) -> converted value, or a
one-line `ConfigError` naming the field, its value and the allowed range.  `harness.config.schema`
builds the per-field schema from them.
"""



from __future__ import annotations

import difflib
import math
import re
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any

from harness.config.errors import ConfigError, short_repr

NONE_WORDS = ("none",)
NAME_RE = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.+=,@-]{0,99}$")
KEY_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_-]*$")
BARE_WORD_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_.+-]*$")

Checker = Callable[[str, Any], Any]


# ---------------------------------------------------------------------------------------------
# primitive checkers: (dotted path, raw value) -> converted value, or ConfigError
# ---------------------------------------------------------------------------------------------
def type_name(v: Any) -> str:
    if v is None:
        return "nothing"
    if isinstance(v, bool):
        return "a boolean"
    if isinstance(v, int):
        return "an integer"
    if isinstance(v, float):
        return "a float"
    if isinstance(v, str):
        return "a string"
    if isinstance(v, (list, tuple)):
        return "an array"
    if isinstance(v, Mapping):
        return "a table"
    return f"a {type(v).__name__}"


def is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def fmt_number(x: float) -> str:
    if x == math.pi:
        return "pi"
    return f"{x:g}"


class Range:
    """A real interval; `None` ends are unbounded."""

    def __init__(self, lo: float | None = None, hi: float | None = None,
                 lo_open: bool = False, hi_open: bool = False) -> None:
        self.lo, self.hi, self.lo_open, self.hi_open = lo, hi, lo_open, hi_open

    def __contains__(self, x: float) -> bool:
        if self.lo is not None and (x <= self.lo if self.lo_open else x < self.lo):
            return False
        if self.hi is not None and (x >= self.hi if self.hi_open else x > self.hi):
            return False
        return True

    def describe(self) -> str:
        if self.lo is None and self.hi is None:
            return "finite"
        if self.hi is None:
            return f"{'>' if self.lo_open else '>='} {fmt_number(self.lo)}"
        if self.lo is None:
            return f"{'<' if self.hi_open else '<='} {fmt_number(self.hi)}"
        left, right = "(" if self.lo_open else "[", ")" if self.hi_open else "]"
        return f"in {left}{fmt_number(self.lo)}, {fmt_number(self.hi)}{right}"


POSITIVE = Range(0.0, None, lo_open=True)
NONNEG = Range(0.0, None)
FINITE = Range()


def as_float(v: Any) -> float | None:
    """float(v) for a finite real number (not bool), else None."""
    if not is_number(v):
        return None
    try:
        f = float(v)
    except OverflowError:
        return None
    return f if math.isfinite(f) else None


def num(rng: Range = FINITE) -> Checker:
    desc = "a finite number" if rng.describe() == "finite" else f"a number {rng.describe()}"

    def check(path: str, v: Any) -> float:
        f = as_float(v)
        if f is None:
            got = "" if is_number(v) else f" (got {type_name(v)})"
            raise ConfigError.field(path, v, f"must be {desc}{got}")
        if f not in rng:
            raise ConfigError.field(path, v, f"must be {desc}")
        return f

    check.desc = desc  # type: ignore[attr-defined]
    return check


def integer(lo: int, hi: int, allowed: tuple[int, ...] | None = None) -> Checker:
    desc = (f"one of the integers {', '.join(map(str, allowed))}" if allowed
            else f"an integer in [{lo}, {hi}]")

    def check(path: str, v: Any) -> int:
        if not isinstance(v, int) or isinstance(v, bool):
            raise ConfigError.field(path, v, f"must be {desc} (got {type_name(v)})")
        if not lo <= v <= hi or (allowed and v not in allowed):
            raise ConfigError.field(path, v, f"must be {desc}")
        return int(v)

    return check


def boolean(path: str, v: Any) -> bool:
    if not isinstance(v, bool):
        raise ConfigError.field(path, v, f"must be true or false (got {type_name(v)})")
    return v


def choice(options: Iterable[str]) -> Checker:
    options = tuple(options)
    desc = "one of " + ", ".join(repr(o) for o in options)

    def check(path: str, v: Any) -> str:
        if not isinstance(v, str):
            raise ConfigError.field(path, v, f"must be {desc} (got {type_name(v)})")
        if v not in options:
            close = difflib.get_close_matches(v, options, n=1)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            raise ConfigError.field(path, v, f"must be {desc}{hint}")
        return v

    return check


def name_check(path: str, v: Any) -> str:
    if not isinstance(v, str) or not NAME_RE.match(v):
        raise ConfigError.field(
            path, v, "must be a string of 1-100 letters, digits or _ . + = , @ - (usable as a folder "
            "name; no spaces or slashes, not starting with '.' or '-')")
    return v


def mjcf_path(path: str, v: Any) -> str:
    """An existing MJCF file (its content is checked by the plant: `harness.plant.validate_plant`)."""
    if not isinstance(v, str) or not v.strip():
        raise ConfigError.field(path, v, "must be the path of an MJCF scene file (string)")
    if not Path(v).is_file():
        raise ConfigError.field(path, v, "must be an existing MJCF file (relative paths: from the "
                                "current directory); file not found")
    return v


mjcf_path.desc = "the path of an MJCF scene file"  # type: ignore[attr-defined]
mjcf_path.keep_message = True  # type: ignore[attr-defined]


def vec(n: int, rng: Range = FINITE, unit: str = "numbers") -> Checker:
    each = "" if rng.describe() == "finite" else f", each {rng.describe()}"
    desc = f"an array of {n} finite {unit}{each}"

    def check(path: str, v: Any) -> tuple[float, ...]:
        if not isinstance(v, (list, tuple)):
            raise ConfigError.field(path, v, f"must be {desc} (got {type_name(v)})")
        if len(v) != n:
            raise ConfigError.field(path, v, f"must be {desc} (got {len(v)} entries)")
        out = []
        for i, x in enumerate(v):
            f = as_float(x)
            if f is None or f not in rng:
                raise ConfigError.field(path, v, f"must be {desc} (entry {i} is {short_repr(x, 30)})")
            out.append(f)
        return tuple(out)

    check.desc = desc  # type: ignore[attr-defined]
    return check


def matrix(rows: int, cols: int) -> Checker:
    row = vec(cols)
    desc = f"an array of {rows} arrays of {cols} finite numbers"

    def check(path: str, v: Any) -> tuple[tuple[float, ...], ...]:
        if not isinstance(v, (list, tuple)) or len(v) != rows:
            raise ConfigError.field(path, v, f"must be {desc}")
        try:
            return tuple(row(path, r) for r in v)
        except ConfigError:
            raise ConfigError.field(path, v, f"must be {desc}") from None

    return check


def str_list(options: Iterable[str]) -> Checker:
    options = tuple(options)
    desc = "an array of distinct strings from " + ", ".join(repr(o) for o in options)

    def check(path: str, v: Any) -> tuple[str, ...]:
        if not isinstance(v, (list, tuple)) or not all(isinstance(x, str) for x in v):
            raise ConfigError.field(path, v, f"must be {desc}")
        bad = [x for x in v if x not in options]
        if bad or len(set(v)) != len(v):
            raise ConfigError.field(path, v, f"must be {desc}")
        return tuple(v)

    return check


def num_list(rng: Range) -> Checker:
    desc = f"an array of finite numbers, each {rng.describe()}"

    def check(path: str, v: Any) -> tuple[float, ...]:
        if not isinstance(v, (list, tuple)):
            raise ConfigError.field(path, v, f"must be {desc} (got {type_name(v)})")
        return vec(len(v), rng)(path, v)

    return check


def is_none_word(v: Any) -> bool:
    return isinstance(v, str) and v.strip().lower() in NONE_WORDS


def optional(inner: Checker, allow_false: bool = False) -> Checker:
    def check(path: str, v: Any) -> Any:
        if is_none_word(v) or (allow_false and v is False):
            return None
        try:
            return inner(path, v)
        except ConfigError:
            if getattr(inner, "keep_message", False):
                raise
            alt = ', "none" or false' if allow_false else ' or "none"'
            raise ConfigError.field(path, v, f"must be {inner.desc}{alt} (got {type_name(v)})") from None

    return check
