"""Process-level settings of the `teleop` command and the sweep's workers: `RuntimeOptions` (TELEOP_*
environment variables), GC thresholds, the fast end of a process, provenance and progress bars."""

from __future__ import annotations

import atexit
import contextlib
import dataclasses
import functools
import gc
import os
import re
import signal
import sys
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import NoReturn


@dataclasses.dataclass(frozen=True)
class RuntimeOptions:
    """cache_dir: compiled-kernel cache ($TELEOP_CACHE_DIR, else $XDG_CACHE_HOME or ~/.cache
    /octarm-teleop); jit: numba kernels (TELEOP_NO_JIT=1: interpreted, same maths); aot: ahead-of-time
    loop modules (TELEOP_NO_AOT=1: numba's JIT); debug: tracebacks of output failures (TELEOP_DEBUG=1)."""

    cache_dir: Path
    jit: bool = True
    aot: bool = True
    debug: bool = False

    @classmethod
    def from_env(cls, env: Mapping[str, str] = os.environ) -> RuntimeOptions:
        root = env.get("TELEOP_CACHE_DIR") or os.path.join(
            env.get("XDG_CACHE_HOME") or os.path.join(Path.home(), ".cache"), "octarm-teleop")
        return cls(cache_dir=Path(root), jit=env.get("TELEOP_NO_JIT", "0") != "1",
                   aot=env.get("TELEOP_NO_AOT", "0") != "1", debug=bool(env.get("TELEOP_DEBUG")))


_OPTIONS: list[RuntimeOptions] = []


def options() -> RuntimeOptions:
    """The options `using_options` set, else those of the environment now."""
    return _OPTIONS[-1] if _OPTIONS else RuntimeOptions.from_env()


@contextlib.contextmanager
def using_options(opts: RuntimeOptions) -> Iterator[RuntimeOptions]:
    """Run the block with `opts` as `options()`."""
    _OPTIONS.append(opts)
    try:
        yield opts
    finally:
        _OPTIONS.remove(opts)


# fewer collections of the many long-lived objects numba, MuJoCo, Rerun and matplotlib import
GC_THRESHOLDS = (10_000, 50, 50)


def set_gc_thresholds() -> None:
    """Apply GC_THRESHOLDS to this process."""
    gc.set_threshold(*GC_THRESHOLDS)


def end_process(rc: int) -> NoReturn:
    """Flush stdout/stderr and `os._exit(rc)`, skipping the interpreter's teardown (every file written
    must be closed first)."""
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    os._exit(rc)


def fast_exit(rc: int) -> NoReturn:
    """Run the atexit handlers (Rerun's shutdown, multiprocessing, logging), then `end_process(rc)`."""
    try:
        atexit._run_exitfuncs()
    finally:
        end_process(rc)


def _is_terminal(stream) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError, OSError):  # closed or not a file
        return False


@functools.cache
def parent_death_signal():
    """libc's `prctl` on Linux, else None (look it up in the parent before a `preexec_fn` uses it)."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        import ctypes

        return ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):
        return None


def die_with_parent(sig: int = signal.SIGTERM) -> None:
    """Have the kernel send `sig` to this process when its parent ends (Linux `PR_SET_PDEATHSIG`; a no-op
    elsewhere); call it first thing in the child."""
    prctl = parent_death_signal()
    if prctl is None:
        return
    parent = os.getppid()
    prctl(1, int(sig), 0, 0, 0)  # PR_SET_PDEATHSIG = 1
    if os.getppid() != parent:  # the parent ended before the request took effect
        os.kill(os.getpid(), sig)


DIST_NAME = "octarm-teleop"


@functools.cache
def provenance() -> dict[str, str]:
    """{"version": ..., "git_revision": ...} of the running code (each absent when unknown; never raises)."""
    out: dict[str, str] = {}
    root = Path(__file__).resolve().parents[2]  # the checkout, or site-packages
    try:
        from importlib.metadata import version

        out["version"] = _checkout_version(root) or version(DIST_NAME)
    except Exception:  # noqa: BLE001 - not installed and not a checkout: no version
        pass
    try:
        rev = _git_revision(root)
    except (OSError, ValueError, UnicodeDecodeError):
        rev = None
    if rev:
        out["git_revision"] = rev
    return out


def _checkout_version(root: Path) -> str | None:
    """[project] version of root/pyproject.toml if it is this package's."""
    path = root / "pyproject.toml"
    if not path.is_file():
        return None
    import tomllib

    project = tomllib.loads(path.read_text(encoding="utf-8")).get("project", {})
    return str(project["version"]) if project.get("name") == DIST_NAME and "version" in project else None


def _git_revision(root: Path) -> str | None:
    """The commit of HEAD of the checkout at `root` (a .git folder, or a .git file of a worktree)."""
    gitdir = root / ".git"
    if gitdir.is_file():  # worktree or submodule: "gitdir: <path>"
        text = gitdir.read_text(encoding="utf-8").strip()
        if not text.startswith("gitdir:"):
            return None
        gitdir = (root / text[len("gitdir:"):].strip()).resolve()
    elif not gitdir.is_dir():
        return None
    head = (gitdir / "HEAD").read_text(encoding="utf-8").strip()
    ref, common = head.removeprefix("ref:").strip(), gitdir
    if (gitdir / "commondir").is_file():  # a worktree keeps its refs in the main repository
        common = (gitdir / (gitdir / "commondir").read_text(encoding="utf-8").strip()).resolve()
    found = [head] if ref == head else [f.read_text(encoding="utf-8").strip()
                                        for f in (gitdir / ref, common / ref) if f.is_file()]
    if not found and (common / "packed-refs").is_file():
        lines = (common / "packed-refs").read_text(encoding="utf-8").splitlines()
        found = [parts[0] for parts in map(str.split, lines) if parts[1:] == [ref]]
    return found[0] if found and re.fullmatch(r"[0-9a-f]{40,64}", found[0]) else None


@functools.cache
def progress_bar_class() -> type:
    """tqdm's bar without its monitor thread (a process with threads must not fork its workers), drawn
    only on a terminal.  ImportError without tqdm."""
    from tqdm import tqdm

    class Bar(tqdm):
        monitor_interval = 0

        def __init__(self, *args, **kwargs):
            if not _is_terminal(kwargs.get("file") or sys.stderr):
                kwargs["disable"] = True
            super().__init__(*args, **kwargs)

    return Bar


__all__ = ["DIST_NAME", "GC_THRESHOLDS", "RuntimeOptions", "die_with_parent", "end_process", "fast_exit",
           "options", "parent_death_signal", "progress_bar_class", "provenance", "set_gc_thresholds",
           "using_options"]
