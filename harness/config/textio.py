"""TOML in (within `MAX_DOCUMENT_BYTES` and `MAX_DEPTH`, regular files only), TOML/JSON values out, and
the one way every output is written: `atomic_path` (renamed into place only when complete)."""

from __future__ import annotations

import contextlib
import errno
import math
import os
import stat
import tomllib
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w

from .errors import ConfigError

MAX_DOCUMENT_BYTES = 1 << 20  # a scenario, bounds or study file
MAX_DEPTH = 32  # nesting of tables and arrays
TMP_MARK = ".tmp-"  # temporary names: .<final name>.tmp-<pid>-<n>


def loads_toml(text: str, what: str) -> dict:
    """`tomllib.loads` within the size and depth limits (TOMLDecodeError is left to the caller)."""
    if len(text) > MAX_DOCUMENT_BYTES:
        raise ConfigError(f"{what}: {len(text)} characters, more than the limit of {MAX_DOCUMENT_BYTES}")
    deep = ConfigError(f"{what}: nested deeper than {MAX_DEPTH} levels of tables/arrays")
    try:
        doc = tomllib.loads(text)
    except RecursionError:
        raise deep from None
    stack = [(doc, 1)]
    while stack:  # iterative: no recursion limit
        node, depth = stack.pop()
        if isinstance(node, (dict, list)):
            if depth > MAX_DEPTH:
                raise deep
            stack += [(c, depth + 1) for c in (node.values() if isinstance(node, dict) else node)]
    return doc


def _open_regular(path: Path, what: str):
    """`path` opened for reading if it is a regular file (checked on the descriptor), else ConfigError."""
    irregular = ConfigError(f"{what} {path}: not a regular file (a named pipe, device or socket is not "
                            "read)", path=str(path))
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except OSError as e:
        if e.errno == errno.ENXIO:  # a socket (or a device without its driver): no file to read
            raise irregular from None
        raise
    try:
        st = os.fstat(fd)
        if stat.S_ISDIR(st.st_mode):
            raise IsADirectoryError(errno.EISDIR, "Is a directory", str(path))
        if not stat.S_ISREG(st.st_mode):
            raise irregular
        if hasattr(os, "set_blocking"):
            os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def read_toml(path: str | Path, what: str) -> dict:
    """A parsed TOML file; every failure is a one-line ConfigError naming `what` ("scenario file"...)."""
    path = Path(path)
    try:
        with _open_regular(path, what) as fh:
            data = fh.read(MAX_DOCUMENT_BYTES + 1)
        if len(data) > MAX_DOCUMENT_BYTES:
            raise ConfigError(f"{what} {path}: larger than the limit of {MAX_DOCUMENT_BYTES} bytes",
                              path=str(path))
        return loads_toml(data.decode("utf-8"), f"{what} {path}")
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
    """One TOML value on one line (arrays and tables inline)."""
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(toml_literal(x) for x in v) + "]"
    if isinstance(v, dict):
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


class OutputError(ConfigError):
    """An output file could not be written (one line naming the file and the cause)."""


def describe_os_error(e: BaseException) -> str:
    if isinstance(e, OSError):
        return e.strerror or str(e) or type(e).__name__
    return f"{type(e).__name__}: {e}"


_counter = iter(range(1 << 62))


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """A temporary path next to `path`, fsynced and renamed to `path` when the block succeeds, removed
    otherwise; an OSError is an `OutputError`."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}{TMP_MARK}{os.getpid()}-{next(_counter)}")
    try:
        yield tmp
        if not tmp.exists():
            raise OutputError(f"cannot write {path}: the writer produced no file", path=str(path))
        with open(tmp, "rb") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except OSError as e:
        raise OutputError(f"cannot write {path}: {describe_os_error(e)}", path=str(path)) from None
    finally:
        with contextlib.suppress(OSError):
            tmp.unlink()


def write_atomic(path: str | Path, data: bytes | str | Callable[[Path], Any]) -> Path:
    """Write bytes, text (UTF-8) or whatever `data(tmp_path)` writes to `path` via `atomic_path`."""
    path = Path(path)
    with atomic_path(path) as tmp:
        if callable(data):
            data(tmp)
        else:
            tmp.write_bytes(data.encode("utf-8") if isinstance(data, str) else data)
    return path


def remove_outputs(folder: Path, names: list[str]) -> None:
    """Remove the previous run's outputs (`names`) and temporary files from `folder`."""
    victims = {folder / n for n in names}
    victims.update(p for p in folder.glob(f".*{TMP_MARK}*") if p.is_file())
    for p in victims:
        try:
            if p.is_file() or p.is_symlink():
                p.unlink()
        except OSError as e:
            raise OutputError(f"cannot remove the previous output {p}: {describe_os_error(e)}",
                              path=str(p)) from None
