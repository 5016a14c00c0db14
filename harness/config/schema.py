"""The one validator of every input file: frozen dataclasses whose fields carry their constraints and
descriptions as `msgspec.Meta` annotations, decoded by `decode` into one-line errors
``<dotted field> = <value>: must be <range>`` (plus unknown keys with "did you mean", non-finite numbers)."""

from __future__ import annotations

import dataclasses
import difflib
import functools
import math
import re
import typing
from collections.abc import Iterable, Iterator, Mapping
from typing import Annotated, Any

import msgspec
from msgspec import Meta
from msgspec import inspect as mi

from harness.config.errors import ConfigError, short_repr


def num(desc: str, **rng: float) -> Any:
    """A finite real number (TOML integers accepted) with optional bounds gt/ge/lt/le."""
    return doc(float, desc, **rng)


def integer(desc: str, **rng: int) -> Any:
    """An integer with optional bounds gt/ge/lt/le."""
    return doc(int, desc, **rng)


def vec(n: int, desc: str, **rng: float) -> Any:
    """An array of `n` finite numbers, each within the bounds."""
    item = Annotated[float, Meta(**rng)] if rng else float
    return Annotated[tuple[(item,) * n], Meta(description=desc or None)]


_META = ("gt", "ge", "lt", "le", "multiple_of", "pattern", "min_length", "max_length")


def doc(tp: Any, desc: str, **meta: Any) -> Any:
    """`tp` with a description, msgspec constraints and extra keys (`expect`: the error's 'must be ...')."""
    extra = {k: v for k, v in meta.items() if k not in _META}
    rules = {k: v for k, v in meta.items() if k in _META}
    return Annotated[tp, Meta(description=desc or None, extra=extra or None, **rules)]


def checked(cls: type, spec: Mapping[str, Any]) -> type:
    """A frozen subclass of the parameter dataclass `cls` (names, defaults: its own) with the constrained
    types of `spec` (one entry per field); `decode` builds `cls` itself from it."""
    extra = [(f.name, spec[f.name], dataclasses.field(default=f.default, default_factory=f.default_factory))
             for f in dataclasses.fields(cls)]
    return dataclasses.make_dataclass(cls.__name__, extra, bases=(cls,), frozen=True, eq=False,
                                      namespace={"schema_of": cls})


@functools.cache
def info(tp: Any) -> Any:
    return mi.type_info(tp)


def bare(t: Any) -> Any:
    """The type under `Annotated` metadata."""
    while isinstance(t, mi.Metadata):
        t = t.type
    return t


def description(t: Any) -> str:
    return (t.extra_json_schema or {}).get("description", "") if isinstance(t, mi.Metadata) else ""


def _fmt(x: float) -> str:
    return "pi" if x == math.pi else str(x) if isinstance(x, int) else f"{x:g}"


def describe_range(t: Any) -> str:
    """'in (0, 3600]', '> 0', '' for a numeric type's bounds."""
    lo = ("(", ">", t.gt) if t.gt is not None else ("[", ">=", t.ge)
    hi = (")", "<", t.lt) if t.lt is not None else ("]", "<=", t.le)
    if lo[2] is not None and hi[2] is not None:
        return f"in {lo[0]}{_fmt(lo[2])}, {_fmt(hi[2])}{hi[0]}"
    return " ".join(f"{op} {_fmt(v)}" for _, op, v in (lo, hi) if v is not None)


def describe(t: Any) -> str:
    """What a value of (msgspec type info) `t` must be, as the end of 'must be ...'."""
    if isinstance(t, mi.Metadata) and "expect" in (t.extra or {}):
        return t.extra["expect"]
    t = bare(t)
    if isinstance(t, mi.IntType):
        return f"an integer {describe_range(t)}".rstrip()
    if isinstance(t, mi.FloatType):
        rng = describe_range(t)
        return f"a number {rng}" if rng else "a finite number"
    if isinstance(t, mi.BoolType):
        return "true or false"
    if isinstance(t, mi.StrType):
        return "a string" + (f" matching {t.pattern}" if t.pattern else "")
    if isinstance(t, mi.LiteralType):
        if all(isinstance(v, int) for v in t.values):
            return "one of the integers " + ", ".join(map(str, t.values))
        return "one of " + ", ".join(repr(v) for v in t.values)
    if isinstance(t, mi.TupleType):
        items = [bare(i) for i in t.item_types]
        if items and all(isinstance(i, mi.FloatType) for i in items):
            rng = describe_range(items[0])
            return f"an array of {len(items)} finite numbers" + (f", each {rng}" if rng else "")
        if items and all(i == items[0] for i in items):
            return f"an array of {len(items)} arrays of " + describe(items[0]).removeprefix("an array of ")
        return f"an array of {len(items)} entries"
    if isinstance(t, (mi.VarTupleType, mi.ListType)):
        item = bare(t.item_type)
        if isinstance(item, mi.FloatType):
            rng = describe_range(item)
            return "an array of finite numbers" + (f", each {rng}" if rng else "")
        if isinstance(item, mi.LiteralType):
            return "an array of distinct strings from " + ", ".join(repr(v) for v in item.values)
        return "an array of " + describe(item).removeprefix("an ").removeprefix("a ") + "s"
    if isinstance(t, mi.UnionType):
        kinds = [u for u in t.types if not isinstance(bare(u), mi.NoneType)]
        text = " or ".join(describe(k) for k in kinds)
        return text + ' or "none"' if len(kinds) < len(t.types) else text
    if isinstance(t, (mi.DataclassType, mi.DictType)):
        return "a table"
    return "a valid value"


def type_name(v: Any) -> str:
    for kind, text in ((type(None), "nothing"), (bool, "a boolean"), (int, "an integer"), (float, "a float"),
                       (str, "a string"), ((list, tuple), "an array"), (Mapping, "a table")):
        if isinstance(v, kind):
            return text
    return f"a {type(v).__name__}"


def suggest(word: Any, choices: Iterable[str], n: int = 3) -> list[str]:
    """The close spellings of `word` among `choices` (the one "did you mean" of the harness)."""
    return difflib.get_close_matches(str(word), list(choices), n=n, cutoff=0.6)


def did_you_mean(hints: Iterable[str], key: str = "") -> str:
    hints = list(hints)
    alts = " or ".join(repr(h) for h in hints[:4])
    return f"did you mean {alts}{f' for {key!r}' if key else ''}? " if hints else ""


def unknown_keys(prefix: str, bad: Mapping, allowed: Iterable[str],
                 elsewhere: Iterable[str] = ()) -> ConfigError:
    """One line for the unknown keys `bad` (key -> value) of the table at `prefix` ("plant." or ""):
    the close spellings among `allowed`, and the dotted paths of the file (`elsewhere`) where the key
    belongs, e.g. `plant.segments` for a top-level `segments`."""
    allowed, elsewhere = list(allowed), list(elsewhere)
    hints = []
    for k in bad:
        close = [prefix + c for c in suggest(k, allowed)]
        other = [e for e in elsewhere if e.rsplit(".", 1)[-1] == k and e != prefix + k and e not in close]
        text = did_you_mean(close + other, k if len(bad) > 1 else "")
        where = other[0].rpartition(".")[0] if other else ""
        hints.append(text + (f"({k!r} belongs {f'under [{where}]' if where else 'at the top level'}) "
                             if other else ""))
    if len(bad) == 1:
        (k, v), = bad.items()
        head, path = f"{prefix}{k} = {short_repr(v, 40)}: unknown key", prefix + str(k)
    else:
        path = prefix.rstrip(".")
        head = f"{path or 'file'}: unknown keys {', '.join(map(repr, bad))}"
    return ConfigError(f"{head}; {''.join(hints)}allowed keys here: {', '.join(allowed) or 'none'}",
                       path=path)


def _dataclass_of(t: Any) -> Any:
    """The dataclass type info inside `t` (through Annotated and Optional), else None."""
    t = bare(t)
    kinds = [bare(u) for u in t.types] if isinstance(t, mi.UnionType) else [t]
    return next((k for k in kinds if isinstance(k, mi.DataclassType)), None)


def fields_of(cls: type, prefix: str = "", arrays: bool = False) -> Iterator[tuple[str, Any, Any]]:
    """(dotted name, msgspec type info, default) of every field of `cls` and of its sub-tables; with
    `arrays`, also of the tables in arrays of tables (`factor[].param`, or as the array's `item` extra
    says: `environment.objects.<name>.kind`)."""
    for f in info(cls).fields:
        path = prefix + f.name
        default = f.default if f.default is not msgspec.NODEFAULT else \
            f.default_factory() if f.default_factory is not msgspec.NODEFAULT else msgspec.NODEFAULT
        yield path, f.type, default
        sub = _dataclass_of(f.type)
        if sub is None and arrays and isinstance(bare(f.type), mi.VarTupleType):
            extra = f.type.extra if isinstance(f.type, mi.Metadata) and f.type.extra else {}
            item = extra.get("item", "[]")
            sub, path = _dataclass_of(bare(f.type).item_type), path + (item if item == "[]" else "." + item)
        if sub is not None:
            yield from fields_of(sub.cls, path + ".", arrays)


@functools.cache
def paths(cls: type, prefix: str = "") -> tuple[str, ...]:
    """Every dotted key of a `cls` table (for "did you mean" of keys put in the wrong table)."""
    return tuple(prefix + p for p, _, _ in fields_of(cls))


def _non_finite(raw: Any) -> bool:
    """Whether `raw` is or holds a non-finite float."""
    if isinstance(raw, float):
        return not math.isfinite(raw)
    items = raw.values() if isinstance(raw, Mapping) else raw if isinstance(raw, (list, tuple)) else ()
    return any(_non_finite(v) for v in items)


def _value_error(path: str, value: Any, t: Any, why: str, entry: int | None) -> ConfigError:
    """The one line for `value` (type info `t`) at `path`: msgspec's `why` or "finite"; `entry`: the index
    of the first bad entry inside the value."""
    path, b = path or "file", bare(t)
    expected = f"a table [{path}]" if isinstance(b, (mi.DataclassType, mi.DictType)) else describe(t)
    got = ""
    if entry is not None and isinstance(b, (mi.TupleType, mi.VarTupleType, mi.ListType)):
        got = f" (entry {entry} is {short_repr(value[entry], 30)})"
    elif "length" in why and isinstance(value, (list, tuple)):
        got = f" (got {len(value)} entries)"
    elif isinstance(b, mi.LiteralType) and isinstance(value, str):
        hint = suggest(value, [str(v) for v in b.values], n=1)
        got = f"; did you mean {hint[0]!r}?" if hint else ""
    elif why.startswith("Expected `") and ", got `" in why:
        got = f" (got {type_name(value)})"
    return ConfigError.field(path, value, f"must be {f'finite ({expected})' if why == 'finite' else expected}"
                             f"{got}")


def _table(raw: Mapping, dc: Any, path: str, elsewhere: tuple[str, ...]) -> Any:
    """The table `raw` as an instance of the dataclass (type info) `dc`; unknown keys raise."""
    prefix = f"{path}." if path else ""
    fields = {f.name: f for f in dc.fields}
    bad = {k: v for k, v in raw.items() if k not in fields}
    if bad:
        raise unknown_keys(prefix, bad, fields, elsewhere)
    hints = _hints(dc.cls)
    values = {k: _convert(v, hints[k], prefix + k, elsewhere) for k, v in raw.items()}
    missing = [f for f in dc.fields if f.required and f.name not in raw]
    if missing:
        key, kind = prefix + missing[0].name, missing[0].type
        what = f"[{key}] table" if _dataclass_of(kind) else f"key {key} ({describe(kind)})"
        raise ConfigError(f"missing {what}", path=key)
    try:
        return getattr(dc.cls, "schema_of", dc.cls)(**values)
    except (TypeError, ValueError) as e:  # the class' own check (__post_init__) names its field first
        why = " ".join(str(e).split())
        head = re.match(r"[\w.]*", why)[0]
        name = head.rpartition(".")[2]
        if name in fields:
            raise ConfigError(prefix + name + why[len(head):], path=prefix + name) from None
        raise ConfigError(f"{path or 'file'}: {why}", path=path) from None


def _convert(raw: Any, hint: Any, path: str, elsewhere: tuple[str, ...]) -> Any:
    """`raw` as a value of the annotation `hint` at the dotted `path` (`elsewhere`: the file's dotted keys,
    for "did you mean")."""
    t = info(hint)
    b, dc = bare(t), _dataclass_of(t)
    if isinstance(b, mi.UnionType) and any(isinstance(u, mi.NoneType) for u in b.types) and (
            raw is False or (isinstance(raw, str) and raw.strip().lower() == "none")):
        return None  # TOML has no null: "none" (or false) unsets an optional field
    if dc is not None and isinstance(raw, Mapping):
        return _table(raw, dc, path, elsewhere)
    item = _dataclass_of(b.item_type) if isinstance(b, (mi.VarTupleType, mi.ListType)) else None
    if item is not None and isinstance(t, mi.Metadata) and (t.extra or {}).get("item") == "<name>":
        if not isinstance(raw, Mapping):  # [<path>.<name>] tables, each named by its key
            raise ConfigError.field(path, raw, f"must be a table of [{path}.<name>] tables "
                                    f"(got {type_name(raw)})")
        for k, v in raw.items():
            if isinstance(v, Mapping) and "name" in v:
                raise ConfigError.field(f"{path}.{k}.name", v["name"], "unknown key: the name of an entry "
                                        f"is its table's key ({path}.{k})")
        return tuple(_convert({**v, "name": k} if isinstance(v, Mapping) else v, item.cls, f"{path}.{k}",
                              elsewhere) for k, v in raw.items())
    if item is not None and isinstance(raw, (list, tuple)):  # an array of tables
        return (tuple if isinstance(b, mi.VarTupleType) else list)(
            _convert(v, item.cls, f"{path}[{i}]", elsewhere) for i, v in enumerate(raw))
    if isinstance(b, mi.DictType) and isinstance(raw, Mapping):
        key, value = typing.get_args(_unannotated(hint))
        try:
            for k in raw:
                msgspec.convert(k, key)
        except msgspec.ValidationError:
            raise ConfigError.field(path or "file", raw, "keys must be names (letters, digits, _ and -)") \
                from None
        return {k: _convert(v, value, f"{path}.{k}", elsewhere) for k, v in raw.items()}
    if _non_finite(raw):
        entries = enumerate(raw) if isinstance(raw, (list, tuple)) else ()
        raise _value_error(path, raw, t, "finite", next((i for i, v in entries if _non_finite(v)), None))
    try:
        return msgspec.convert(raw, hint)
    except msgspec.ValidationError as e:
        why, _, where = str(e).rpartition(" - at ")
        entry = re.match(r"`\$\[(\d+)\]", where)
        raise _value_error(path, raw, t, why or str(e), int(entry[1]) if entry else None) from None


@functools.cache
def _hints(cls: type) -> dict[str, Any]:
    return typing.get_type_hints(cls, include_extras=True)


def _unannotated(hint: Any) -> Any:
    while typing.get_origin(hint) is Annotated:
        hint = typing.get_args(hint)[0]
    return hint


def decode(raw: Any, cls: type, *, prefix: str = "") -> Any:
    """`raw` (a parsed TOML table) as a `cls` instance, or a one-line ConfigError ("none" or false unset
    an optional field).  `prefix`: before every field path."""
    return _convert(raw, cls, prefix.rstrip("."), paths(cls, prefix))


__all__ = ["ConfigError", "Meta", "checked", "decode", "describe", "did_you_mean", "doc",
           "fields_of", "info", "integer", "num", "paths", "suggest", "type_name",
           "unknown_keys", "vec"]

