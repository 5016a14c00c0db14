"""The compiled-kernel cache on disk (`teleop cache`): its folders numba-<digest> (`fast`) and
aot-<digest>-<recipe> (`aot`), one per kernel-source version; nothing else in the root is touched."""

from __future__ import annotations

import os
import re
import shutil
from dataclasses import dataclass
from pathlib import Path

from harness.loop import aot, fast

_NAME = re.compile(r"^(numba)-([0-9a-f]{16})$|^(aot)-([0-9a-f]{16})-([0-9a-f]{8})$")


@dataclass(frozen=True)
class CacheFolder:
    """One cache folder: path, kind ("numba" / "aot"), size (bytes), whether this installation uses it."""

    path: Path
    kind: str
    size: int
    current: bool


def _size(path: Path) -> int:
    total = 0
    for root, _, files in os.walk(path):
        for f in files:
            try:
                total += os.lstat(os.path.join(root, f)).st_size
            except OSError:  # removed meanwhile (another process pruning, a build's temporary file)
                pass
    return total


def folders(root: Path | None = None) -> list[CacheFolder]:
    """The cache folders under `root` (default `fast.cache_root()`) by name; NotADirectoryError if `root`
    is not a folder."""
    root = fast.cache_root() if root is None else Path(root)
    if not root.exists():
        return []
    if not root.is_dir():
        raise NotADirectoryError(f"the kernel cache {root} is not a folder "
                                 "(TELEOP_CACHE_DIR / XDG_CACHE_HOME)")
    current = {f"numba-{fast.source_digest()}", aot.aot_dir().name}
    out = []
    for p in sorted(root.iterdir()):
        m = _NAME.match(p.name)
        if m is None or not p.is_dir() or p.is_symlink():
            continue
        out.append(CacheFolder(p, m.group(1) or m.group(3), _size(p), p.name in current))
    return out


def remove(items: list[CacheFolder]) -> tuple[int, list[str]]:
    """Delete the folders; (bytes freed, one message per folder that could not be removed)."""
    freed, errors = 0, []
    for item in items:
        try:
            shutil.rmtree(item.path)
            freed += item.size
        except FileNotFoundError:  # removed meanwhile
            pass
        except OSError as e:
            errors.append(f"{item.path}: {e.strerror or e}")
    return freed, errors


def mib(n: int) -> str:
    return f"{n / 2**20:.1f} MiB"


__all__ = ["CacheFolder", "folders", "mib", "remove"]
