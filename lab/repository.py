"""The one layer that reads and writes the lab's record (module doc of hopkinson.lab).

Every write is one transaction that also appends its audit entry: it happens whole or not at
all. Writers that collide on a unique key (two rigs meeting a new serial, two desks allocating
a certificate number) retry their transaction. There is no update or delete path for the
audit trail or for certificates; the database refuses them too (migration 0001's triggers).
"""

from __future__ import annotations

import hashlib
import json
import time
from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Any, TypeVar

import sqlalchemy as sa
from hopkinson.analysis.key_figures import Figure
from hopkinson.lab import schema as t
from hopkinson.lab.database import (
    WRITER,
    check_schema,
    database_url,
    first_line,
    make_engine,
    redacted,
)
from hopkinson.lab.errors import LabError, TamperedShotError
from hopkinson.lab.records import ShotRecord
from sqlalchemy.orm import Session

T = TypeVar("T")
RETRIES = 8  # a transaction that lost a race on a unique key is run again


def utc_now() -> str:
    return datetime.now(UTC).isoformat(timespec="microseconds").replace("+00:00", "Z")


@dataclass(frozen=True)
class SensorInfo:
    serial: str
    model: str
    owner: str
    nominal_sensitivity: float | None
    sensitivity_unit: str
    tolerance_percent: float | None
    interval_days: int | None


@dataclass(frozen=True)
class Calibration:
    """One analysed shot of a sensor, as its history shows it."""

    utc_time: str
    shot_uuid: str
    shot_name: str
    campaign: str
    rig: str
    operator: str
    peak_acceleration_m_s2: float | None
    response_unit: str
    figures: dict[str, Figure | None]
    simulated: bool = False  # the shot was made by the simulator (`hopkinson sim`), not by a rig


@dataclass(frozen=True)
class IssuedCertificate:
    number: str
    replaces: str
    issued_utc: str
    content: dict[str, Any]


class LabRepository:
    """The lab's record behind one small API (see the module doc)."""

    def __init__(self, url: str = "", explicit: str = "") -> None:
        self.url = database_url(url, explicit)
        self.engine = make_engine(self.url)
        self._writer = self.engine.execution_options(**{WRITER: True})
        try:
            check_schema(self.engine, self.url)
        except Exception:
            self.engine.dispose()
            raise

    @property
    def where(self) -> str:
        return redacted(self.url)

    def close(self) -> None:
        self.engine.dispose()

    def __enter__(self) -> LabRepository:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def ping(self) -> None:
        """One round trip to the database (SELECT 1): the benchmarks' baseline."""
        with self.engine.connect() as connection:
            connection.execute(sa.text("SELECT 1")).scalar_one()

    # -- transactions ---------------------------------------------------------------------------
    def _write(self, work: Callable[[Session], T]) -> T:
        """Run `work` in one transaction, again when it lost a race on a unique key."""
        for attempt in range(RETRIES):
            try:
                with Session(self._writer) as session, session.begin():
                    return work(session)
            except sa.exc.IntegrityError:
                if attempt == RETRIES - 1:
                    raise
                time.sleep(0.005 * (attempt + 1))
            except sa.exc.OperationalError as exc:
                if "locked" in str(exc) and attempt < RETRIES - 1:  # SQLite's busy writer
                    time.sleep(0.05 * (attempt + 1))
                    continue
                raise LabError(f"database {self.where}: {first_line(exc)}") from None
            except sa.exc.SQLAlchemyError as exc:  # anything else the database refused: one line
                raise LabError(f"database {self.where}: {first_line(exc)}") from None
        raise AssertionError("unreachable")

    @staticmethod
    def _audit(session: Session, actor: str, action: str, subject: str, **detail: Any) -> None:
        session.add(t.AuditEntry(utc=utc_now(), actor=actor or _os_user(), action=action, subject=subject,
                                 detail=json.dumps(detail, sort_keys=True) if detail else ""))

    # -- sensors, rigs ------------------------------------------------------------------------------
    @staticmethod
    def _sensor(session: Session, serial: str, model: str = "") -> t.Sensor:
        sensor = session.scalar(sa.select(t.Sensor).where(t.Sensor.serial == serial))
        if sensor is None:
            sensor = t.Sensor(serial=serial, model=model, owner="", sensitivity_unit="", created_utc=utc_now())
            session.add(sensor)
            session.flush()
        elif model and not sensor.model:
            sensor.model = model
        return sensor

    @staticmethod
    def _rig(session: Session, name: str) -> t.Rig:
        rig = session.scalar(sa.select(t.Rig).where(t.Rig.name == name))
        if rig is None:
            rig = t.Rig(name=name)
            session.add(rig)
            session.flush()
        return rig

    def register_sensor(self, serial: str, actor: str, **fields: Any) -> SensorInfo:
        """Create or update a sensor's data (model, owner, nominal_sensitivity, sensitivity_unit,
        tolerance_percent, interval_days); the change is audited."""
        if not serial.strip():
            raise LabError("a sensor needs a serial number")
        known = {f for f in SensorInfo.__dataclass_fields__ if f != "serial"}
        unknown = set(fields) - known
        if unknown:
            raise LabError(f"sensor {serial}: unknown field(s) {', '.join(sorted(unknown))}")

        def work(session: Session) -> SensorInfo:
            sensor = self._sensor(session, serial)
            changed = {k: v for k, v in fields.items() if v is not None and getattr(sensor, k) != v}
            for key, value in changed.items():
                setattr(sensor, key, value)
            if changed:
                self._audit(session, actor, "sensor updated", serial, **changed)
            return _sensor_info(sensor)

        return self._write(work)

    def sensor(self, serial: str) -> SensorInfo | None:
        with Session(self.engine) as session:
            sensor = session.scalar(sa.select(t.Sensor).where(t.Sensor.serial == serial))
            return _sensor_info(sensor) if sensor is not None else None

    # -- shots ----------------------------------------------------------------------------------
    def record_shot(self, record: ShotRecord, actor: str = "", action: str = "shot fired") -> str:
        """Record a shot and the analysis its file holds; idempotent (the UUID and the raw
        channels' SHA-256 are the key, the file's SHA-256 names the analysis). Returns what
        happened: "new", "analysis added" or "known". TamperedShotError when the UUID is known
        with other raw data."""

        def work(session: Session) -> str:
            shot = session.scalar(sa.select(t.Shot).where(t.Shot.uuid == record.uuid))
            outcome = "known"
            if shot is None:
                sensor = self._sensor(session, record.accelerometer_serial, record.accelerometer_model)
                rig = self._rig(session, record.rig or "unnamed rig")
                self._reference_chain(session, rig, record)
                campaign = self._campaign(session, record, rig, sensor)
                shot = t.Shot(uuid=record.uuid, raw_sha256=record.raw_sha256, sensor_id=sensor.id, rig_id=rig.id,
                              campaign_id=campaign.id if campaign is not None else None, shot_name=record.shot_name,
                              operator=record.operator, utc_time=record.utc_time, pressure_bar=record.pressure_bar,
                              projectile=record.projectile, simulated=record.simulated,
                              software_version=record.software_version, path=record.path, recorded_utc=utc_now())
                session.add(shot)
                session.flush()
                self._audit(session, actor or record.operator, action, record.uuid, serial=record.accelerometer_serial,
                            path=record.path, raw_sha256=record.raw_sha256, campaign=record.campaign)
                outcome = "new"
            elif shot.raw_sha256 != record.raw_sha256:
                raise TamperedShotError(
                    f"{record.path}: raw channels' SHA-256 {record.raw_sha256[:12]}… differ from the recorded "
                    f"{shot.raw_sha256[:12]}… of shot {record.uuid}: tampered or damaged; refused")
            if record.state != "raw" and session.scalar(sa.select(t.Analysis.id).where(
                    t.Analysis.shot_id == shot.id, t.Analysis.file_sha256 == record.file_sha256)) is None:
                session.add(self._analysis(shot, record))
                self._audit(session, actor or record.operator, "result recorded", record.uuid,
                            file_sha256=record.file_sha256, state=record.state)
                outcome = "new" if outcome == "new" else "analysis added"
            return outcome

        return self._write(work)

    @staticmethod
    def _analysis(shot: t.Shot, record: ShotRecord) -> t.Analysis:
        row = t.Analysis(shot_id=shot.id, file_sha256=record.file_sha256, state=record.state,
                         error=record.analysis_error, analysed_utc=record.analysed_utc,
                         software_version=record.analysis_software_version, response_unit=record.response_unit,
                         peak_acceleration_m_s2=record.peak_acceleration_m_s2, recorded_utc=utc_now())
        for key in t.FIGURE_KEYS:
            figure = record.figures.get(key)
            if figure is None:
                continue
            setattr(row, key, figure.value)
            setattr(row, key + "_u", figure.u)
            if figure.interval is not None:
                setattr(row, key + "_lo", figure.interval[0])
                setattr(row, key + "_hi", figure.interval[1])
        return row

    @staticmethod
    def _reference_chain(session: Session, rig: t.Rig, record: ShotRecord) -> None:
        for link in record.reference_chain:
            if session.scalar(sa.select(t.ReferenceItem.id).where(
                    t.ReferenceItem.rig_id == rig.id, t.ReferenceItem.item == link.item,
                    t.ReferenceItem.certificate == link.certificate)) is None:
                session.add(t.ReferenceItem(rig_id=rig.id, item=link.item, certificate=link.certificate,
                                            issued_by=link.issued_by, u_rel=link.u_rel, due=link.due))

    @staticmethod
    def _campaign(session: Session, record: ShotRecord, rig: t.Rig, sensor: t.Sensor) -> t.Campaign | None:
        if not record.campaign:
            return None
        campaign = session.scalar(sa.select(t.Campaign).where(t.Campaign.name == record.campaign))
        if campaign is None:
            campaign = t.Campaign(name=record.campaign, rig_id=rig.id, sensor_id=sensor.id,
                                  path=record.campaign_path, first_utc=record.utc_time)
            session.add(campaign)
            session.flush()
        return campaign

    def shot_raw_sha256(self, uuid: str) -> str | None:
        """The recorded raw SHA-256 of shot `uuid` (None: not recorded)."""
        with Session(self.engine) as session:
            return session.scalar(sa.select(t.Shot.raw_sha256).where(t.Shot.uuid == uuid))

    # -- reading --------------------------------------------------------------------------------
    def calibrations(self, serial: str, campaign: str | None = None) -> list[Calibration]:
        """Every shot of `serial` (or of one campaign) with its newest analysis, oldest first."""
        newest = (sa.select(t.Analysis.shot_id, sa.func.max(t.Analysis.id).label("aid"))
                  .where(t.Analysis.state == "analysed").group_by(t.Analysis.shot_id).subquery())
        columns = [getattr(t.Analysis, key + part) for key in t.FIGURE_KEYS for part in t.FIGURE_PARTS]
        query = (sa.select(t.Shot.utc_time, t.Shot.uuid, t.Shot.shot_name, t.Campaign.name, t.Rig.name,
                           t.Shot.operator, t.Analysis.peak_acceleration_m_s2, t.Analysis.response_unit,
                           t.Shot.simulated, *columns)
                 .join(newest, newest.c.shot_id == t.Shot.id)
                 .join(t.Analysis, t.Analysis.id == newest.c.aid)
                 .join(t.Sensor, t.Sensor.id == t.Shot.sensor_id)
                 .join(t.Rig, t.Rig.id == t.Shot.rig_id)
                 .outerjoin(t.Campaign, t.Campaign.id == t.Shot.campaign_id)
                 .where(t.Sensor.serial == serial).order_by(t.Shot.utc_time, t.Shot.id))
        if campaign is not None:
            query = query.where(t.Campaign.name == campaign)
        out = []
        with self.engine.connect() as connection:
            for row in connection.execute(query):
                values = row[9:]
                figures = {}
                for i, key in enumerate(t.FIGURE_KEYS):
                    value, u, lo, hi = values[4 * i: 4 * i + 4]
                    figures[key] = (Figure(value, u, (lo, hi) if lo is not None and hi is not None else None)
                                    if value is not None else None)
                out.append(Calibration(row[0], row[1], row[2], row[3] or "", row[4], row[5], row[6], row[7] or "",
                                       figures, bool(row[8])))
        return out

    def campaign_sensor(self, campaign: str) -> str | None:
        """The serial a campaign calibrated (None: no such campaign recorded)."""
        with Session(self.engine) as session:
            return session.scalar(sa.select(t.Sensor.serial).join(t.Campaign, t.Campaign.sensor_id == t.Sensor.id)
                                  .where(t.Campaign.name == campaign))

    def reference_chain(self, rig: str) -> list[dict[str, Any]]:
        """The reference items recorded for `rig` (each certificate once)."""
        with Session(self.engine) as session:
            rows = session.scalars(sa.select(t.ReferenceItem).join(t.Rig, t.Rig.id == t.ReferenceItem.rig_id)
                                   .where(t.Rig.name == rig).order_by(t.ReferenceItem.id)).all()
            return [{"item": r.item, "certificate": r.certificate, "issued_by": r.issued_by, "u_rel": r.u_rel,
                     "due": r.due} for r in rows]

    def audit_trail(self, subject: str | None = None, limit: int = 1000) -> list[dict[str, Any]]:
        """The newest audit entries (of one subject), newest first."""
        query = sa.select(t.AuditEntry).order_by(t.AuditEntry.id.desc()).limit(limit)
        if subject is not None:
            query = query.where(t.AuditEntry.subject == subject)
        with Session(self.engine) as session:
            return [{"utc": a.utc, "actor": a.actor, "action": a.action, "subject": a.subject,
                     "detail": json.loads(a.detail) if a.detail else {}} for a in session.scalars(query)]

    # -- certificates ---------------------------------------------------------------------------
    def issue_certificate(self, prefix: str, content: dict[str, Any], *, serial: str, subject: str,
                          authorised_by: str, replaces: str = "",
                          number_into: Callable[[dict[str, Any], str, str], dict[str, Any]] | None = None,
                          ) -> IssuedCertificate:
        """Allocate the next number `<prefix>-<year>-<NNNN>` and store the certificate with it,
        in one transaction (two desks never get the same number: the number is unique and the
        loser of a race retries). `number_into(content, number, issued_utc)` puts the number
        into the content before it is stored (the stored content is what was issued)."""
        if not authorised_by.strip():
            raise LabError("a certificate needs the name of the person who authorises it")

        def work(session: Session) -> IssuedCertificate:
            sensor = self._sensor(session, serial)
            if replaces:
                old = session.scalar(sa.select(t.Certificate).where(t.Certificate.number == replaces))
                if old is None:
                    raise LabError(f"certificate {replaces}: not in the record; nothing to replace")
                if old.sensor_id != sensor.id:
                    raise LabError(f"certificate {replaces}: was issued for another sensor; not replaced")
            issued = utc_now()
            year = int(issued[:4])
            last = session.scalar(sa.select(sa.func.max(t.Certificate.sequence))
                                  .where(t.Certificate.prefix == prefix, t.Certificate.year == year))
            sequence = (last or 0) + 1
            number = f"{prefix}-{year}-{sequence:04d}"
            final = number_into(content, number, issued) if number_into else dict(content, number=number)
            text = json.dumps(final, sort_keys=True, allow_nan=False)
            session.add(t.Certificate(
                number=number, prefix=prefix, year=year, sequence=sequence, replaces=replaces, sensor_id=sensor.id,
                subject=subject, customer=str(final.get("customer", "")), authorised_by=authorised_by,
                issued_utc=issued, decision_rule=str(final.get("decision_rule", "")),
                conformity=str(final.get("conformity", "")), content_json=text,
                content_sha256=hashlib.sha256(text.encode()).hexdigest()))
            session.flush()
            self._audit(session, authorised_by, "certificate replaced" if replaces else "certificate issued",
                        number, serial=serial, campaign=subject, replaces=replaces)
            return IssuedCertificate(number, replaces, issued, final)

        return self._write(work)

    def certificate(self, number: str) -> IssuedCertificate | None:
        with Session(self.engine) as session:
            row = session.scalar(sa.select(t.Certificate).where(t.Certificate.number == number))
            if row is None:
                return None
            return IssuedCertificate(row.number, row.replaces, row.issued_utc, json.loads(row.content_json))

    def certificates(self, serial: str) -> list[dict[str, str]]:
        """The certificates issued for a sensor, oldest first."""
        with Session(self.engine) as session:
            rows = session.execute(sa.select(t.Certificate.number, t.Certificate.issued_utc, t.Certificate.replaces,
                                             t.Certificate.conformity)
                                   .join(t.Sensor, t.Sensor.id == t.Certificate.sensor_id)
                                   .where(t.Sensor.serial == serial).order_by(t.Certificate.id)).all()
            return [{"number": r[0], "issued_utc": r[1], "replaces": r[2], "conformity": r[3]} for r in rows]

    def counts(self) -> dict[str, int]:
        """Rows per table (for `hopkinson lab status` and tests)."""
        with self.engine.connect() as connection:
            return {table.__tablename__: connection.execute(sa.select(sa.func.count()).select_from(table)).scalar_one()
                    for table in (t.Sensor, t.Rig, t.Campaign, t.Shot, t.Analysis, t.Certificate, t.AuditEntry)}


def _sensor_info(sensor: t.Sensor) -> SensorInfo:
    return SensorInfo(sensor.serial, sensor.model, sensor.owner, sensor.nominal_sensitivity,
                      sensor.sensitivity_unit, sensor.tolerance_percent, sensor.interval_days)


def open_repository(url: str = "", explicit: str = "") -> LabRepository:
    """The lab's record: `explicit`, else HOPKINSON_DATABASE_URL, else `url` (the configured
    one), else the default (hopkinson.lab.database); LabError when it cannot be reached or
    its schema is not this software's."""
    try:
        return LabRepository(url, explicit)
    except sa.exc.SQLAlchemyError as exc:
        raise LabError(f"database {redacted(database_url(url, explicit))}: {first_line(exc)}") from None



def _os_user() -> str:
    """Who runs this process, for an audit entry nobody named."""
    import getpass

    try:
        return getpass.getuser()
    except (KeyError, OSError):
        return "unknown"
