"""Small shared readers/writers for the harness' text files (TOML in, TOML/JSON out)."""

from __future__ import annotations

import math
import os
import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w

from .errors import ConfigError


def read_toml(path: str | Path, what: str) -> dict:
    """Parse a TOML file; every failure is a one-line ConfigError naming `what` ("scenario file"...)."""
    path = Path(path)
    try:
        with path.open("rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise ConfigError(f"{what} not found: {path}", path=str(path)) from None
    except IsADirectoryError:
        raise ConfigError(f"{what} {path} is a directory", path=str(path)) from None
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"{path}: invalid TOML: {e}", path=str(path)) from None
    except UnicodeDecodeError as e:
        raise ConfigError(f"{path}: not UTF-8 text ({e.reason})", path=str(path)) from None
    except OSError as e:
        raise ConfigError(f"cannot read {what} {path}: {e.strerror or e}", path=str(path)) from None


def jsonable(v: Any) -> Any:
    """JSON-ready copy: numpy -> Python, tuples -> lists, non-finite floats -> None, other -> str."""
    if isinstance(v, dict):
        return {str(k): jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [jsonable(x) for x in v]
    if isinstance(v, (np.ndarray, np.generic)):
        return jsonable(v.tolist())
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if v is None or isinstance(v, (bool, int, float, str)):
        return v
    return str(v)


def toml_literal(v: Any) -> str:
    """One TOML value on one line (arrays inline), e.g. for `--set key=value` overrides."""
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(toml_literal(x) for x in v) + "]"
    if isinstance(v, dict):  # inline table (e.g. controller={name = "dls_ik"})
        return "{" + ", ".join(f"{k} = {toml_literal(x)}" for k, x in v.items()) + "}"
    try:
        return tomli_w.dumps({"v": v})[len("v = "):].rstrip("\n")
    except TypeError:
        raise ConfigError(f"cannot write {v!r} as a TOML value") from None


def prepare_out_dir(path: Path, option: str = "--out") -> Path:
    """Create `path` (and parents) and check that files can be written in it, else ConfigError."""
    path = Path(path)
    try:
        path.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise ConfigError(f"{option} = '{path}': exists and is not a directory", path=option) from None
    except OSError as e:
        raise ConfigError(f"{option} = '{path}': cannot create the output folder ({e.strerror or e})",
                          path=option) from None
    probe = path / f".teleop-write-test-{os.getpid()}"
    try:
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as e:
        raise ConfigError(f"{option} = '{path}': output folder is not writable ({e.strerror or e})",
                          path=option) from None
    return path
