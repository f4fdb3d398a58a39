"""Shot records on their way into the database: the spool and the quarantine, and `deliver`,
the one place that drains the spool and then records (the recorder and `lab import` both
call it).

The spool (`lab-spool.jsonl` in the data folder) holds records a database could not take yet,
one JSON line each naming the database it is for (its URL without password): a record is only
ever drained into the database it was meant for. Lines from before databases were named are
drained only by an explicit `hopkinson lab import` (no path), into the database that command
names.

The quarantine (`lab-quarantine.jsonl`) holds records a database refused as they are (a field
too long, a tampered shot, a rule broken: lab.errors.RecordRejected, or the database's own
refusal of the data) with the reason; they never block the others and are never retried
blindly. `hopkinson lab status` lists both.

The shot file is always on disk first; these files only ever delay its record. When neither
can be written (a full disk), `deliver` says so: the caller tells the operator and exits
non-zero (rig.lab_record).
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import threading
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hopkinson.fileio import atomic_write
from hopkinson.lab.database import Failure, data_folder, failure_of, first_line
from hopkinson.lab.records import ShotRecord

SPOOL_NAME = "lab-spool.jsonl"
QUARANTINE_NAME = "lab-quarantine.jsonl"
LEGACY = ""  # the database of a line written before lines named theirs
_lock = threading.RLock()  # one process's threads take turns (re-entered: a drain quarantines)


def spool_path() -> Path:
    return data_folder() / SPOOL_NAME


def quarantine_path() -> Path:
    return data_folder() / QUARANTINE_NAME


@dataclass(frozen=True)
class Spooled:
    """One line of the spool or the quarantine."""

    database: str
    record: ShotRecord
    utc: str = ""
    reason: str = ""

    def line(self) -> str:
        return json.dumps({"database": self.database, "utc": self.utc, "reason": self.reason,
                           "record": self.record.to_dict()}, allow_nan=True) + "\n"

    @classmethod
    def read(cls, line: str) -> Spooled:
        data = json.loads(line)
        if "record" not in data:  # a line from before lines named their database: the record itself
            return cls(LEGACY, ShotRecord.from_dict(data))
        return cls(str(data.get("database", LEGACY)), ShotRecord.from_dict(data["record"]), str(data.get("utc", "")),
                   str(data.get("reason", "")))


@contextlib.contextmanager
def _held(path: Path) -> Iterator[None]:
    """The file to ourselves: this process's threads and every other process (a POSIX lock on
    `<file>.lock`), so a line appended while another drains is never lost in its rewrite."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with _lock, open(path.with_name(path.name + ".lock"), "a") as lock_file:
        fcntl.flock(lock_file.fileno(), fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(lock_file.fileno(), fcntl.LOCK_UN)


def _append(path: Path, entry: Spooled) -> Path:
    with _held(path), open(path, "a", encoding="utf-8") as f:
        f.write(entry.line())
        f.flush()
        os.fsync(f.fileno())
    return path


def _read(path: Path) -> list[Spooled]:
    if not path.exists():
        return []
    out = []
    for line in path.read_text(encoding="utf-8").splitlines():
        try:
            out.append(Spooled.read(line))
        except (ValueError, TypeError, KeyError):
            continue  # a damaged line: its shot file is still on disk for `lab import`
    return out


def spool(record: ShotRecord, database: str, reason: str = "", path: Path | None = None) -> Path:
    """Append `record`, meant for `database`, to the spool (fsynced); OSError when it cannot."""
    from hopkinson.lab.uow import utc_now

    return _append(path or spool_path(), Spooled(database, record, utc_now(), reason))


def quarantine(record: ShotRecord, database: str, reason: str, path: Path | None = None) -> Path:
    """Set `record` aside with the reason the database refused it (fsynced); OSError when it cannot."""
    from hopkinson.lab.uow import utc_now

    return _append(path or quarantine_path(), Spooled(database, record, utc_now(), reason))


def pending(database: str | None = None, path: Path | None = None) -> list[Spooled]:
    """The spooled lines (of one database; LEGACY: lines that name none)."""
    return [s for s in _read(path or spool_path()) if database is None or s.database == database]


def waiting_records(database: str | None = None, path: Path | None = None) -> int:
    """How many distinct records wait (a record spooled twice counts once)."""
    return len({(s.database, s.record.uuid, s.record.file_sha256) for s in pending(database, path)})


def quarantined(path: Path | None = None) -> list[Spooled]:
    return _read(path or quarantine_path())


@dataclass
class Drained:
    recorded: int = 0
    quarantined: int = 0
    left: int = 0
    away: str = ""  # why the rest waits (the database's message), "" when it all went


def drain(database: str, record: Callable[[ShotRecord], object], legacy: bool = False,
          path: Path | None = None) -> Drained:
    """Hand each spooled record meant for `database` (and, with `legacy`, each that names none)
    to `record`: the ones it refuses go to the quarantine with the reason; when the database is
    away the rest wait, in order. Other databases' lines are kept as they are."""
    path = path or spool_path()
    report = Drained()
    if not path.exists():
        return report
    with _held(path):
        lines = _read(path)
        keep: list[Spooled] = []
        for entry in lines:
            mine = entry.database == database or (legacy and entry.database == LEGACY)
            if not mine or report.away:
                keep.append(entry)
                report.left += mine
                continue
            try:
                record(entry.record)
                report.recorded += 1
            except Exception as exc:  # sorted below: refused for good, or to try again later
                if failure_of(exc) is Failure.REJECTED:
                    _append(quarantine_path() if path == spool_path() else path.with_name(QUARANTINE_NAME),
                            Spooled(database, entry.record, entry.utc, first_line(exc)))
                    report.quarantined += 1
                else:
                    report.away = first_line(exc)
                    keep.append(entry)
                    report.left += 1
        if len(keep) != len(lines):
            if keep:
                atomic_write(path, "".join(e.line() for e in keep))
            else:
                path.unlink(missing_ok=True)
    return report


@dataclass(frozen=True)
class Delivery:
    """Where a record went: "new", "analysis added", "known" (in the database), "spooled",
    "quarantined", or "not kept" (neither file could be written); `message` says it for people."""

    outcome: str
    message: str = ""
    failure: Failure | None = None

    @property
    def kept(self) -> bool:
        return self.outcome != "not kept"


def deliver(database: str, open_db: Callable[[], Any], record: ShotRecord, actor: str = "",
            action: str = "shot fired") -> Delivery:
    """Drain `database`'s spool, then record `record` (module doc). `open_db` gives the
    lab.repository.LabRepository (raising when it cannot be reached)."""
    try:
        db = open_db()
        drain(database, lambda r: db.record_shot(r, r.operator, action))
        return Delivery(db.record_shot(record, actor or record.operator, action))
    except Exception as exc:  # sorted: the record is set aside, or waits for the database
        failure = failure_of(exc)
        reason = first_line(exc)
        try:
            if failure is Failure.REJECTED:
                where = quarantine(record, database, reason)
                return Delivery("quarantined", f"refused by the lab record ({reason}); set aside in {where} with "
                                               f"its reason (`hopkinson lab status` lists it)", failure)
            where = spool(record, database, reason)
        except OSError as os_exc:
            return Delivery("not kept", f"not recorded ({reason}) and not queued either ({os_exc.strerror or os_exc}): "
                                        f"the shot file {record.path} is kept; run `hopkinson lab import "
                                        f"{record.path}` once that is fixed", failure)
        if failure is Failure.SETUP:
            return Delivery("spooled", f"the database refused this rig ({reason}): not an outage; fix the "
                                       f"configuration ([database] url, the role's password or grants), then run "
                                       f"`hopkinson lab import`; the record waits in {where}", failure)
        return Delivery("spooled", f"not recorded now ({reason}); queued for {database} in {where} (taken in at "
                                   f"the next shot or by `hopkinson lab import`)", failure)
