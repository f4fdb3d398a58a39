"""Shot records the database could not take yet: one JSON line each in the data folder's
`lab-spool.jsonl`, retried at the next shot and by `hopkinson lab import`. The shot file is
always on disk first; the spool only ever delays its record, never loses it."""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import threading
from collections.abc import Callable, Iterator
from pathlib import Path

from hopkinson.lab.database import data_folder
from hopkinson.lab.errors import TamperedShotError
from hopkinson.lab.records import ShotRecord

from hopkinson.fileio import atomic_write

SPOOL_NAME = "lab-spool.jsonl"
_lock = threading.Lock()  # one process's threads take turns


def spool_path() -> Path:
    return data_folder() / SPOOL_NAME


@contextlib.contextmanager
def _held(path: Path) -> Iterator[None]:
    """The spool to ourselves: this process's threads and every other process (a POSIX lock on
    `<spool>.lock`), so a line appended while another drains is never lost in its rewrite."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with _lock, open(path.with_name(path.name + ".lock"), "a") as lock_file:
        fcntl.flock(lock_file.fileno(), fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(lock_file.fileno(), fcntl.LOCK_UN)


def spool(record: ShotRecord, path: Path | None = None) -> Path:
    """Append `record` to the spool (fsynced)."""
    path = path or spool_path()
    line = json.dumps(record.to_dict(), allow_nan=True) + "\n"
    with _held(path), open(path, "a", encoding="utf-8") as f:
        f.write(line)
        f.flush()
        os.fsync(f.fileno())
    return path


def pending(path: Path | None = None) -> list[ShotRecord]:
    """The spooled records (a damaged line is skipped: its shot file is still on disk for import)."""
    path = path or spool_path()
    if not path.exists():
        return []
    out = []
    for line in path.read_text(encoding="utf-8").splitlines():
        try:
            out.append(ShotRecord.from_dict(json.loads(line)))
        except (ValueError, TypeError):
            continue
    return out


def drain(record: Callable[[ShotRecord], object], path: Path | None = None) -> int:
    """Hand every spooled record to `record` (which raises when the database is still away);
    keeps the ones that failed. Returns how many went in."""
    path = path or spool_path()
    if not path.exists():
        return 0
    with _held(path):
        waiting = pending(path)
        if not waiting:
            return 0
        left: list[ShotRecord] = []
        done = 0
        for item in waiting:
            if left:
                left.append(item)
                continue
            try:
                record(item)
                done += 1
            except TamperedShotError:  # never goes in; its file is still there for people to judge
                continue
            except Exception:  # still unreachable (or refused): keep it and the rest, in order
                left.append(item)
        if left:
            atomic_write(path, "".join(json.dumps(r.to_dict(), allow_nan=True) + "\n" for r in left))
        else:
            path.unlink(missing_ok=True)
        return done
