"""`hopkinson lab upgrade`: a record's schema migrated to this software's, with a backup first.

A migration cannot be undone (the record is append-only; migration 0002's downgrade says to
restore a backup), so a backup is taken, or vouched for, before anything changes:

- SQLite: the database is copied beside its file, `<name>.schema-<rev>.<UTC time>.sqlite`,
  through SQLite's online backup (whole and consistent, the WAL included), before migrating;
  when the copy cannot be written nothing is migrated;
- PostgreSQL: the owner runs `pg_dump` (the command is printed, with the database's URL and
  no password) and says so with `--yes-i-have-a-backup`; without it nothing is migrated.

The migration runs in one transaction (lab.database.upgrade_database). When it fails the
database is read again: still at the old revision means nothing changed (said so, with the
backup's place); another revision means it is half-migrated, and the message says how to
restore the backup. Migrations may append one "schema upgraded" audit entry saying what they
did; `UpgradeOutcome.notes` summarises those.
"""

from __future__ import annotations

import json
import os
import shlex
import sqlite3
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

import sqlalchemy as sa
from sqlalchemy.engine import make_url

from hopkinson.lab.database import (
    Failure,
    current_revision,
    failure_of,
    first_line,
    head_revision,
    known_revision,
    make_engine,
    redacted,
    upgrade_database,
)
from hopkinson.lab.errors import LabError

BACKUP_FLAG = "--yes-i-have-a-backup"


@dataclass(frozen=True)
class UpgradeOutcome:
    before: str | None
    after: str
    dialect: str  # "sqlite" or "postgresql"
    backup: Path | None = None  # the SQLite copy taken first
    notes: list[str] = field(default_factory=list)


def _stamp() -> str:
    return datetime.now(UTC).strftime("%Y%m%dT%H%M%SZ")


def sqlite_backup_path(database: Path, revision: str, stamp: str) -> Path:
    """Where the copy of a SQLite record at `revision` goes: beside it, named by both and the
    time (-2, -3, … when that name is taken)."""
    name = f"{database.stem}.schema-{revision}.{stamp}"
    suffix = database.suffix or ".sqlite"
    target, n = database.with_name(name + suffix), 1
    while target.exists():
        n += 1
        target = database.with_name(f"{name}-{n}{suffix}")
    return target


def back_up_sqlite(database: Path, revision: str) -> Path:
    """Copy the SQLite record (SQLite's online backup: consistent, its WAL included) beside it;
    the copy's path. LabError, nothing changed, when it cannot be written."""
    target = sqlite_backup_path(database, revision, _stamp())
    partial = target.with_name(target.name + ".partial")
    try:
        source = sqlite3.connect(database, timeout=30.0)
        try:
            copy = sqlite3.connect(partial)
            try:
                source.backup(copy)
                copy.execute("PRAGMA journal_mode=DELETE")  # one self-contained file
                if copy.execute("PRAGMA quick_check").fetchone()[0] != "ok":
                    raise sqlite3.DatabaseError("the copy does not pass SQLite's quick_check")
            finally:
                copy.close()
        finally:
            source.close()
        os.replace(partial, target)
    except (OSError, sqlite3.Error) as exc:
        partial.unlink(missing_ok=True)
        raise LabError(f"database {database}: cannot take the backup {target} before upgrading "
                       f"({getattr(exc, 'strerror', None) or exc}); nothing changed") from None
    return target


def pg_dump_command(url: str, revision: str) -> str:
    """The pg_dump command that backs the PostgreSQL record up (its URL without a password:
    pg_dump finds that in ~/.pgpass or PGPASSWORD)."""
    uri = make_url(url).set(drivername="postgresql", password=None).render_as_string(hide_password=False)
    return f"pg_dump --format=custom --file={shlex.quote(f'lab.schema-{revision}.{_stamp()}.dump')} {shlex.quote(uri)}"


def upgrade_record(url: str, have_backup: bool = False) -> UpgradeOutcome:
    """Back the record at `url` up (module doc), then migrate it to this software's schema."""
    engine = make_engine(url)
    try:
        before = current_revision(engine)
        if before == head_revision():
            return UpgradeOutcome(before, before, engine.dialect.name)
        if before is not None and not known_revision(before):
            raise LabError(f"database {redacted(url)}: schema version {before} is newer than this software's "
                           f"({head_revision()}); use a newer hopkinson; nothing changed")
        backup = _backup_first(engine, url, before, have_backup) if before is not None else None
        last_audit = _last_audit_id(engine) if before is not None else 0
        try:
            upgrade_database(engine)
        except Exception as exc:
            raise LabError(_failed(engine, url, before, backup, exc)) from None
        return UpgradeOutcome(before, head_revision(), engine.dialect.name, backup, _notes(engine, last_audit))
    finally:
        engine.dispose()


def _backup_first(engine: sa.Engine, url: str, before: str, have_backup: bool) -> Path | None:
    if engine.dialect.name == "sqlite":
        return back_up_sqlite(Path(engine.url.database), before)
    if not have_backup:
        raise LabError(f"database {redacted(url)} is at schema {before}; the upgrade to {head_revision()} cannot be "
                       f"undone: back it up first as its owner role ({pg_dump_command(url, before)}), then run "
                       f"`hopkinson lab upgrade {BACKUP_FLAG}`; nothing changed")
    return None


def _failed(engine: sa.Engine, url: str, before: str | None, backup: Path | None, exc: BaseException) -> str:
    """What a failed upgrade left, for people (module doc)."""
    where, reason = redacted(url), first_line(exc)
    if isinstance(exc, LabError):
        reason = str(exc)
    role = " (run `lab upgrade` as the role that owns the tables: docs/lab-record.md)" \
        if failure_of(exc) is Failure.SETUP and not isinstance(exc, LabError) else ""
    try:
        now = current_revision(engine)
    except sa.exc.SQLAlchemyError:
        now = "unknown"
    kept = f"; the backup taken before is {backup}" if backup is not None else ""
    if now == before:
        return (f"database {where}: the upgrade to {head_revision()} failed and was undone: the database is as it was, "
                f"at schema {before or '(empty)'} ({reason}){role}{kept}")
    restore = (f"stop every rig and copy {backup} over {engine.url.database}" if backup is not None
               else "restore the pg_dump taken before (pg_restore --clean --dbname=…)")
    return (f"database {where}: the upgrade to {head_revision()} failed part-way and left schema {now} ({reason}): "
            f"{restore}")


def _last_audit_id(engine: sa.Engine) -> int:
    with engine.connect() as connection:
        return connection.execute(sa.text("SELECT max(id) FROM audit")).scalar() or 0


def _notes(engine: sa.Engine, after_id: int) -> list[str]:
    """One line per "schema upgraded" audit entry the upgrade appended (module doc)."""
    with engine.connect() as connection:
        rows = connection.execute(sa.text("SELECT subject, detail FROM audit WHERE id > :id AND action = "
                                          "'schema upgraded' ORDER BY id"), {"id": after_id}).all()
    notes = []
    for subject, detail in rows:
        told = json.loads(detail or "{}")
        origins = [v.get("from", "") for v in (told.get("campaign_uuids") or {}).values()]
        new = sum(o.startswith("new") for o in origins)
        if origins:
            notes.append(f"campaigns: {len(origins) - new} took the UUID their run folder's journal gives, {new} a new "
                         f"one (run folder not found from here)" + (f"; `hopkinson lab audit --subject {subject} "
                                                                    f"--json` lists them" if new else ""))
        for old, normal in sorted((told.get("serials_normalised") or {}).items()):
            notes.append(f"sensor {old!r} is now {normal} (serials are normalised)")
        for old, normal in sorted((told.get("serials_left_apart") or {}).items()):
            notes.append(f"sensor {old!r} kept apart from sensor {normal}, which the record already had: "
                         f"`lab sensor {normal}` shows {normal}'s shots only")
        for number, replaced in sorted((told.get("second_successors") or {}).items()):
            notes.append(f"certificate {number} replaced {replaced}, which another certificate had replaced before "
                         f"(0001 allowed it): both kept as issued")
    return notes
