"""The lab record's unit of work: one transaction, the repositories that work in it, and the
audit trail written as the transaction flushes.

    db = open_lab(url)                       # engine and sessionmaker, made once
    with db.unit_of_work("Q. Manager") as uow:
        uow.sensors.revise("SN-7", tolerance_percent=2.0)
        uow.certificates.issue(...)           # both commit together, or neither
    db.transact(actor, work)                 # the same, run again when it lost a race

The audit entry of every new row is made by a `before_flush` hook on the session
(`_audit_new_rows`), as SQLAlchemy's versioning examples do: a repository never writes one
by hand, so no write path can forget it. Rows are never changed or deleted (lab.schema): the
hook refuses a flush that would, before the database's triggers do.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from datetime import UTC, datetime
from typing import Any, TypeVar

import sqlalchemy as sa
from sqlalchemy import event
from sqlalchemy.orm import Session, sessionmaker

from hopkinson.lab import schema as t
from hopkinson.lab.database import (
    WRITER,
    check_schema,
    database_url,
    first_line,
    make_engine,
    redacted,
    sqlite_missing,
)
from hopkinson.lab.errors import DatabaseAway, LabError

T = TypeVar("T")
RETRIES = 8  # a transaction that lost a race on a unique key is run again


def utc_now() -> str:
    return datetime.now(UTC).isoformat(timespec="microseconds").replace("+00:00", "Z")


class LabSession(Session):
    """The record's session class: carries the audit hook (module doc)."""


class UnitOfWork:
    """One transaction and the repositories bound to it (module doc)."""

    def __init__(self, session: Session) -> None:
        from hopkinson.lab.repositories import AuditTrail, Campaigns, Certificates, Sensors, Shots

        self.session = session
        self.sensors = Sensors(session)
        self.campaigns = Campaigns(session)
        self.shots = Shots(session, self.sensors, self.campaigns)
        self.certificates = Certificates(session)
        self.audit = AuditTrail(session)
        self._on_rollback: list[Callable[[], None]] = []

    def on_rollback(self, undo: Callable[[], None]) -> None:
        """Run `undo` if this unit of work does not commit (e.g. remove a document written)."""
        self._on_rollback.append(undo)

    def rolled_back(self) -> None:
        for undo in reversed(self._on_rollback):
            undo()


class LabDatabase:
    """The lab's record: its engine and sessionmaker, made once per process (module doc)."""

    def __init__(self, url: str = "", explicit: str = "", create: bool = True) -> None:
        self.url = database_url(url, explicit)
        missing = sqlite_missing(self.url)
        if missing is not None and not create:
            raise LabError(f"database {self.where}: no lab record there yet (nothing recorded; {missing} "
                           f"does not exist)")
        self.engine = make_engine(self.url)
        self._writer = sessionmaker(self.engine.execution_options(**{WRITER: True}), class_=LabSession,
                                    expire_on_commit=False)
        self._reader = sessionmaker(self.engine, class_=LabSession, expire_on_commit=False)
        try:
            check_schema(self.engine, self.url)
        except Exception:
            self.engine.dispose()
            raise

    @property
    def where(self) -> str:
        """The URL without its password (for messages, logs and the spool's key)."""
        return redacted(self.url)

    def close(self) -> None:
        self.engine.dispose()

    def __enter__(self) -> LabDatabase:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @contextmanager
    def unit_of_work(self, actor: str, **info: Any) -> Iterator[UnitOfWork]:
        """One write transaction: commits when the block ends, rolls back on any error. `info`
        reaches the audit hook (e.g. shot_action="shot imported")."""
        session = self._writer()
        session.info.update(info, actor=actor or _os_user())
        uow = UnitOfWork(session)
        try:
            with session.begin():
                yield uow
        except BaseException:
            uow.rolled_back()
            raise
        finally:
            session.close()

    @contextmanager
    def reading(self) -> Iterator[UnitOfWork]:
        """A read-only unit of work (never waits for a writer)."""
        session = self._reader()
        try:
            yield UnitOfWork(session)
        finally:
            session.close()  # its rows stay readable, detached (a rollback would expire them)

    def transact(self, actor: str, work: Callable[[UnitOfWork], T], **info: Any) -> T:
        """Run `work` in one unit of work, again when it lost a race on a unique key or met
        SQLite's busy writer; any other database error becomes one LabError line."""
        for attempt in range(RETRIES):
            try:
                with self.unit_of_work(actor, **info) as uow:
                    return work(uow)
            except sa.exc.IntegrityError:
                if attempt == RETRIES - 1:
                    raise
                time.sleep(0.005 * (attempt + 1))
            except sa.exc.OperationalError as exc:
                if "locked" in str(exc) and attempt < RETRIES - 1:
                    time.sleep(0.05 * (attempt + 1))
                    continue
                raise DatabaseAway(f"database {self.where}: {first_line(exc)}") from exc
        raise AssertionError("unreachable")

    def ping(self) -> None:
        """One round trip to the database (SELECT 1): the benchmarks' baseline."""
        with self.engine.connect() as connection:
            connection.execute(sa.text("SELECT 1")).scalar_one()


def open_lab(url: str = "", explicit: str = "", create: bool = True, cls: type[LabDatabase] | None = None) -> Any:
    """The lab's record: `explicit`, else HOPKINSON_DATABASE_URL, else `url` (the configured
    one), else the default (lab.database). LabError when it cannot be reached or its schema is
    not this software's; with create=False also when a SQLite file does not exist yet."""
    try:
        return (cls or LabDatabase)(url, explicit, create)
    except sa.exc.SQLAlchemyError as exc:
        raise LabError(f"database {redacted(database_url(url, explicit))}: {first_line(exc)}") from None


# -- the audit hook ---------------------------------------------------------------------------
@event.listens_for(LabSession, "before_flush")
def _audit_new_rows(session: Session, _flush_context: Any, _instances: Any) -> None:
    changed = [obj for obj in (*session.dirty, *session.deleted) if isinstance(obj, t.Base)
               and (obj in session.deleted or session.is_modified(obj))]
    if changed:
        raise LabError(f"{type(changed[0]).__tablename__} {t.APPEND_ONLY_MESSAGE}")
    actor = session.info.get("actor") or _os_user()
    for obj in list(session.new):
        described = _describe(session, obj)
        if described is not None:
            action, subject, detail = described
            session.add(t.AuditEntry(utc=utc_now(), actor=actor, action=action, subject=subject,
                                     detail=json.dumps(detail, sort_keys=True) if detail else ""))


def _describe(session: Session, obj: Any) -> tuple[str, str, dict[str, Any]] | None:
    """(action, subject, detail) of a new row worth an audit entry (None: implied by another)."""
    with session.no_autoflush:
        if isinstance(obj, t.Shot):
            campaign = session.get(t.Campaign, obj.campaign_id) if obj.campaign_id else None
            sensor = session.get(t.Sensor, obj.sensor_id) if obj.sensor_id else None
            return (session.info.get("shot_action", "shot fired"), obj.uuid,
                    {"serial": sensor.serial if sensor else "", "path": obj.path, "raw_sha256": obj.raw_sha256,
                     "campaign": campaign.name if campaign else "", "campaign_uuid": campaign.uuid if campaign else "",
                     "simulated": obj.simulated_marks})
        if isinstance(obj, t.Analysis):
            shot = session.get(t.Shot, obj.shot_id)
            return "result recorded", shot.uuid if shot else "", {"file_sha256": obj.file_sha256, "state": obj.state}
        if isinstance(obj, t.SensorData):
            from hopkinson.lab.repositories import FROM_SHOT

            if obj.actor == FROM_SHOT:  # the shot's own entry covers it
                return None
            sensor = session.get(t.Sensor, obj.sensor_id)
            fields = {k: getattr(obj, k) for k in ("model", "owner", "nominal_sensitivity", "sensitivity_unit",
                                                    "tolerance_percent", "interval_days")}
            return "sensor updated", sensor.serial if sensor else "", fields
        if isinstance(obj, t.Job):
            campaign = session.get(t.Campaign, obj.campaign_id)
            return "job recorded", campaign.uuid if campaign else "", {
                k: getattr(obj, k) for k in ("received", "condition", "location", "customer", "customer_contact",
                                             "mounting", "environment")}
        if isinstance(obj, t.Certificate):
            sensor = session.get(t.Sensor, obj.sensor_id)
            campaign = session.get(t.Campaign, obj.campaign_id) if obj.campaign_id else None
            return ("certificate replaced" if obj.replaces else "certificate issued", obj.number,
                    {"serial": sensor.serial if sensor else "", "campaign": obj.subject,
                     "campaign_uuid": campaign.uuid if campaign else "", "replaces": obj.replaces or "",
                     "specimen": obj.specimen, "content_sha256": obj.content_sha256})
    return None


def _os_user() -> str:
    """Who runs this process, for an audit entry nobody named."""
    import getpass

    try:
        return getpass.getuser()
    except (KeyError, OSError):
        return "unknown"
