"""A dataset folder held by the one process writing its shards (`simulate`, `collect`,
`import-mit`): a lock file naming the writer's PID and host, so a second run into the same folder
is refused up front instead of meeting the first one's shards half-written."""

from __future__ import annotations

import json
import os
import socket
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from pushtoknow.common.errors import DatasetError, DiskFullError
from pushtoknow.common.files import is_disk_full

LOCK_FILE = ".pushtoknow.lock"  # a dataset folder being written: {"pid", "host"} of the writer
_FRESH_LOCK_S = 10.0  # an unreadable lock this young is being written, not stale


def _lock_holder(lock: Path) -> dict | None:
    """The writer a lock file names, or None when it is stale (its process is gone, or it is
    unreadable and old)."""
    try:
        holder = json.loads(lock.read_text())
        pid, host = int(holder["pid"]), str(holder["host"])
    except FileNotFoundError:
        return None
    except (OSError, ValueError, KeyError, TypeError):
        try:
            young = time.time() - lock.stat().st_mtime < _FRESH_LOCK_S
        except OSError:
            return None
        return {"pid": "?", "host": "?"} if young else None
    if host != socket.gethostname():
        return holder  # cannot tell from here: assume it runs
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return None
    except PermissionError:
        pass  # another user's live process
    return holder


@contextmanager
def dataset_lock(out: Path) -> Iterator[None]:
    """Hold `out` (created if need be) for this process while it writes shards: a lock file
    with the PID and host; a second writer gets a DatasetError naming the first, and a stale
    lock (its process gone) is taken over."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    lock = out / LOCK_FILE
    me = {"pid": os.getpid(), "host": socket.gethostname()}
    for _ in range(3):
        try:
            fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
        except FileExistsError:
            holder = _lock_holder(lock)
            if holder is not None:
                raise DatasetError(
                    out,
                    f"in use by another run (PID {holder['pid']} on {holder['host']}, see "
                    f"{LOCK_FILE}); wait for it to end or use another --out directory (if no "
                    "such run is going, delete the lock file)",
                ) from None
            lock.unlink(missing_ok=True)  # stale: taken over
            continue
        try:
            with os.fdopen(fd, "w") as f:
                json.dump(me, f)
        except OSError as e:
            lock.unlink(missing_ok=True)
            if is_disk_full(e):
                raise DiskFullError(lock) from None
            raise
        break
    else:
        raise DatasetError(lock, "could not take the lock (removed and re-created meanwhile)")
    try:
        yield
    finally:
        try:
            if json.loads(lock.read_text()) == me:
                lock.unlink()
        except (OSError, ValueError):
            pass
