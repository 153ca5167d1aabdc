"""Files written atomically, singly or as a set, and files identified by their bytes.

`atomic_write_set` writes every file of a set to `NAME.tmp` beside it (fsynced) and only then
renames them into place, so an error while writing (a full disk, an interruption) leaves every
previous file as it was and a reader never sees a half-written one. A full disk ends in a
`DiskFullError` naming the file; the temporary files are removed.
"""

from __future__ import annotations

import errno
import fnmatch
import hashlib
import os
from collections.abc import Callable, Mapping
from pathlib import Path

from pushtoknow.common.errors import DiskFullError

Content = bytes | str | Callable[[Path], object]  # the bytes, text, or a writer of a path
TMP_SUFFIX = ".tmp"  # NAME.tmp: what an interrupted write leaves (readers skip, resumes delete)


def tmp_path(path: Path) -> Path:
    """Where `path` is written before it is renamed into place."""
    path = Path(path)
    return path.with_name(path.name + TMP_SUFFIX)


def is_disk_full(e: BaseException) -> bool:
    """Whether `e` says the disk is full (errno ENOSPC, or HDF5's text naming errno 28)."""
    if isinstance(e, DiskFullError):
        return True
    if isinstance(e, OSError) and e.errno in (errno.ENOSPC, errno.EDQUOT):
        return True
    return isinstance(e, (OSError, RuntimeError)) and "errno = 28," in str(e)


def _fsync(path: Path) -> None:
    with open(path, "rb+") as f:
        os.fsync(f.fileno())


def atomic_write_set(files: Mapping[Path, Content]) -> list[Path]:
    """Write every file of `files` ({path: bytes, text or writer(tmp path)}) to its temporary
    name, then rename them all into place; returns the paths. Missing parent folders are made
    (a report asked for in a new folder is written, not lost after the work). On an error
    nothing is renamed and the temporary files are removed: a full disk raises `DiskFullError`
    naming the file, anything else is re-raised."""
    staged: list[tuple[Path, Path]] = []
    try:
        for path, content in files.items():
            path = Path(path)
            tmp = tmp_path(path)
            staged.append((tmp, path))
            path.parent.mkdir(parents=True, exist_ok=True)
            if isinstance(content, bytes):
                tmp.write_bytes(content)
            elif isinstance(content, str):
                tmp.write_text(content)
            else:
                content(tmp)
            _fsync(tmp)
    except BaseException as e:
        for tmp, _ in staged:
            tmp.unlink(missing_ok=True)
        if is_disk_full(e):
            raise DiskFullError(staged[-1][1]) from None
        raise
    for tmp, path in staged:
        os.replace(tmp, path)
    return [path for _, path in staged]


def atomic_write(path: Path, content: Content) -> Path:
    """Write one file atomically (`atomic_write_set`); returns its path."""
    return atomic_write_set({Path(path): content})[0]


def file_sha256(path: Path) -> str:
    """SHA-256 (hex) of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def find_files(root: Path, pattern: str) -> list[Path]:
    """Files under `root` whose names match the glob `pattern`, searched recursively through
    linked folders too (each real folder once), sorted."""
    found: list[Path] = []
    seen: set[str] = set()
    for folder, dirs, names in os.walk(root, followlinks=True):
        real = os.path.realpath(folder)
        if real in seen:
            dirs[:] = []
            continue
        seen.add(real)
        dirs.sort()
        found.extend(Path(folder) / n for n in names if fnmatch.fnmatch(n, pattern))
    return sorted(p for p in found if p.is_file())
