"""The repositories of the lab's record: each takes the unit of work's session (lab.uow) and
neither commits nor audits (the unit of work does both). Rows are read by name, as mapped
objects or labelled columns, never by position.

A shot is recorded idempotently: its UUID and raw channels' SHA-256 are the key, the file's
SHA-256 names the analysis it holds. A certificate follows the record's rules (Certificates):
one valid per campaign and kind, a re-issue names the valid one it replaces, a specimen and a
real certificate never replace each other.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from typing import Any

import sqlalchemy as sa
from sqlalchemy.orm import Session

from hopkinson.analysis.key_figures import Figure
from hopkinson.lab import schema as t
from hopkinson.lab.errors import LabError, RecordRejected, TamperedShotError
from hopkinson.lab.records import ShotRecord, check_record, normal_serial

SENSOR_FIELDS = ("model", "owner", "nominal_sensitivity", "sensitivity_unit", "tolerance_percent", "interval_days")
FROM_SHOT = "recorded with a shot"  # SensorData written from a shot file (its model): audited with the shot


def _now() -> str:
    from hopkinson.lab.uow import utc_now

    return utc_now()


@dataclass(frozen=True)
class SensorInfo:
    serial: str
    model: str = ""
    owner: str = ""
    nominal_sensitivity: float | None = None
    sensitivity_unit: str = ""
    tolerance_percent: float | None = None
    interval_days: int | None = None


@dataclass(frozen=True)
class ShotResult:
    """One analysed shot (its newest analysis), as a history and a certificate read it."""

    utc_time: str
    shot_uuid: str
    shot_name: str
    campaign_uuid: str
    campaign: str
    rig: str
    operator: str
    peak_acceleration_m_s2: float | None
    pulse_width_s: float | None
    response_unit: str
    figures: dict[str, Figure | None]
    simulated_marks: tuple[str, ...] = ()
    static_gain: Figure | None = None  # analysis.static_gain (u shot-specific); None: not in the record
    static_gain_amplitude_m_s2: float | None = None
    context: dict[str, Any] = field(default_factory=dict)
    file_sha256: str = ""
    path: str = ""
    analysis_software: str = ""  # the version of hopkinson that analysed it

    @property
    def simulated(self) -> bool:
        return bool(self.simulated_marks)


class Sensors:
    def __init__(self, session: Session) -> None:
        self.session = session

    def row(self, serial: str) -> t.Sensor | None:
        return self.session.scalar(sa.select(t.Sensor).where(t.Sensor.serial == normal_serial(serial)))

    def ensure(self, serial: str) -> t.Sensor:
        key = normal_serial(serial)
        if not key:
            raise LabError("a sensor needs a serial number")
        sensor = self.row(key)
        if sensor is None:
            sensor = t.Sensor(serial=key, created_utc=_now())
            self.session.add(sensor)
            self.session.flush()
        return sensor

    def _data(self, sensor: t.Sensor) -> t.SensorData | None:
        return self.session.scalar(sa.select(t.SensorData).where(t.SensorData.sensor_id == sensor.id)
                                   .order_by(t.SensorData.id.desc()).limit(1))

    def info(self, serial: str) -> SensorInfo | None:
        sensor = self.row(serial)
        if sensor is None:
            return None
        data = self._data(sensor)
        return SensorInfo(sensor.serial, **{k: getattr(data, k) for k in SENSOR_FIELDS}) if data else \
            SensorInfo(sensor.serial)

    def revise(self, serial: str, *, create: bool = False, actor: str = "", **fields: Any) -> SensorInfo:
        """Record a sensor's data (SENSOR_FIELDS; None leaves one as it is) as a new row. An
        unknown serial is refused unless `create` (a typo never makes a sensor)."""
        unknown = set(fields) - set(SENSOR_FIELDS)
        if unknown:
            raise LabError(f"sensor {serial}: unknown field(s) {', '.join(sorted(unknown))}")
        if self.row(serial) is None and not create:
            raise LabError(f"sensor {normal_serial(serial) or repr(serial)}: not in the lab's record (a typo? "
                           f"--new records a sensor no shot has named yet)")
        sensor = self.ensure(serial)
        old = self.info(serial)
        assert old is not None
        merged = {k: (fields[k] if fields.get(k) is not None else getattr(old, k)) for k in SENSOR_FIELDS}
        if any(merged[k] != getattr(old, k) for k in SENSOR_FIELDS) or self._data(sensor) is None:
            self.session.add(t.SensorData(sensor_id=sensor.id, utc=_now(),
                                          actor=actor or self.session.info.get("actor", ""), **merged))
            self.session.flush()
        return SensorInfo(sensor.serial, **merged)

    def note_model(self, sensor: t.Sensor, model: str) -> None:
        """The model a shot file names, when the record knows none yet."""
        if model and self._data(sensor) is None:
            self.session.add(t.SensorData(sensor_id=sensor.id, utc=_now(), actor=FROM_SHOT, model=model, owner="",
                                          sensitivity_unit=""))


class Campaigns:
    def __init__(self, session: Session) -> None:
        self.session = session

    def ensure(self, record: ShotRecord, rig: t.Rig, sensor: t.Sensor | None) -> t.Campaign | None:
        """The campaign of a shot (None for a lone shot); RecordRejected when the campaign is
        known with another sensor (a certificate is of one sensor)."""
        if not record.campaign_uuid:
            return None
        campaign = self.session.scalar(sa.select(t.Campaign).where(t.Campaign.uuid == record.campaign_uuid))
        if campaign is None:
            campaign = t.Campaign(uuid=record.campaign_uuid, name=record.campaign or record.campaign_uuid,
                                  rig_id=rig.id, sensor_id=sensor.id if sensor else None, path=record.campaign_path,
                                  first_utc=record.utc_time)
            self.session.add(campaign)
            self.session.flush()
        elif campaign.sensor_id != (sensor.id if sensor else None):
            known = self.session.get(t.Sensor, campaign.sensor_id) if campaign.sensor_id else None
            raise RecordRejected(f"shot {record.uuid} ({record.path}): names sensor {record.serial or '(none)'} but "
                                 f"its campaign {campaign.name} ({campaign.uuid}) calibrates "
                                 f"{known.serial if known else '(none)'}; not recorded")
        return campaign

    def find(self, ref: str) -> t.Campaign:
        """A campaign by its UUID, else by its (run folder's) name when that is unambiguous."""
        by_uuid = self.session.scalar(sa.select(t.Campaign).where(t.Campaign.uuid == ref))
        if by_uuid is not None:
            return by_uuid
        named = self.session.scalars(sa.select(t.Campaign).where(t.Campaign.name == ref)
                                     .order_by(t.Campaign.id)).all()
        if not named:
            raise LabError(f"campaign {ref}: not in the lab's record (run `hopkinson lab import` on its folder)")
        if len(named) > 1:
            raise LabError(f"campaign {ref}: {len(named)} campaigns have this name "
                           f"({', '.join(c.uuid for c in named)}); name one by its UUID or its run folder")
        return named[0]

    def job(self, campaign: t.Campaign) -> t.Job | None:
        return self.session.scalar(sa.select(t.Job).where(t.Job.campaign_id == campaign.id)
                                   .order_by(t.Job.id.desc()).limit(1))

    def record_job(self, campaign: t.Campaign, **fields: str | None) -> t.Job:
        """A new job record for the campaign: the given fields over the newest record's."""
        old = self.job(campaign)
        names = ("received", "condition", "location", "customer", "customer_contact", "mounting", "environment")
        values = {k: (fields[k] if fields.get(k) is not None else (getattr(old, k) if old else "")) for k in names}
        job = t.Job(campaign_id=campaign.id, utc=_now(), actor=self.session.info.get("actor", ""), **values)
        self.session.add(job)
        self.session.flush()
        return job


class Shots:
    def __init__(self, session: Session, sensors: Sensors, campaigns: Campaigns) -> None:
        self.session = session
        self.sensors = sensors
        self.campaigns = campaigns

    def record(self, record: ShotRecord) -> str:
        """Record a shot and the analysis its file holds: "new", "analysis added" or "known".
        TamperedShotError when the UUID is known with other raw data; RecordRejected when the
        record breaks a rule (check_record, a campaign of another sensor)."""
        check_record(record)
        s = self.session
        shot = s.scalar(sa.select(t.Shot).where(t.Shot.uuid == record.uuid))
        outcome = "known"
        if shot is None:
            sensor = self.sensors.ensure(record.serial) if record.serial else None
            if sensor is not None:
                self.sensors.note_model(sensor, record.accelerometer_model)
            rig = self._rig(record.rig or "unnamed rig")
            self._reference_chain(rig, record)
            campaign = self.campaigns.ensure(record, rig, sensor)
            shot = t.Shot(uuid=record.uuid, raw_sha256=record.raw_sha256, sensor_id=sensor.id if sensor else None,
                          rig_id=rig.id, campaign_id=campaign.id if campaign else None, shot_name=record.shot_name,
                          operator=record.operator, utc_time=record.utc_time, pressure_bar=record.pressure_bar,
                          projectile=record.projectile, simulated=record.simulated,
                          simulated_marks="; ".join(record.simulated_marks), software_version=record.software_version,
                          path=record.path, context_json=json.dumps(record.context, sort_keys=True, default=str),
                          recorded_utc=_now())
            s.add(shot)
            s.flush()
            outcome = "new"
        elif shot.raw_sha256 != record.raw_sha256:
            raise TamperedShotError(
                f"{record.path}: raw channels' SHA-256 {record.raw_sha256[:12]}… differ from the recorded "
                f"{shot.raw_sha256[:12]}… of shot {record.uuid}: tampered or damaged; refused")
        if record.state != "raw" and s.scalar(sa.select(t.Analysis.id).where(
                t.Analysis.shot_id == shot.id, t.Analysis.file_sha256 == record.file_sha256)) is None:
            s.add(self._analysis(shot, record))
            s.flush()
            outcome = "new" if outcome == "new" else "analysis added"
        return outcome

    def _rig(self, name: str) -> t.Rig:
        rig = self.session.scalar(sa.select(t.Rig).where(t.Rig.name == name))
        if rig is None:
            rig = t.Rig(name=name)
            self.session.add(rig)
            self.session.flush()
        return rig

    def _reference_chain(self, rig: t.Rig, record: ShotRecord) -> None:
        for link in record.reference_chain:
            if self.session.scalar(sa.select(t.ReferenceItem.id).where(
                    t.ReferenceItem.rig_id == rig.id, t.ReferenceItem.item == link.item,
                    t.ReferenceItem.certificate == link.certificate)) is None:
                self.session.add(t.ReferenceItem(rig_id=rig.id, item=link.item, certificate=link.certificate,
                                                 issued_by=link.issued_by, u_rel=link.u_rel, due=link.due))

    @staticmethod
    def _analysis(shot: t.Shot, record: ShotRecord) -> t.Analysis:
        row = t.Analysis(shot_id=shot.id, file_sha256=record.file_sha256, state=record.state,
                         error=record.analysis_error, analysed_utc=record.analysed_utc,
                         software_version=record.analysis_software_version, response_unit=record.response_unit,
                         peak_acceleration_m_s2=record.peak_acceleration_m_s2, pulse_width_s=record.pulse_width_s,
                         recorded_utc=_now())
        for key in t.FIGURE_KEYS:
            figure = record.figures.get(key)
            if figure is None:
                continue
            setattr(row, key, figure.value)
            setattr(row, key + "_u", figure.u)
            if figure.interval is not None:
                setattr(row, key + "_lo", figure.interval[0])
                setattr(row, key + "_hi", figure.interval[1])
        if record.static_gain is not None and record.static_gain.value is not None:
            row.static_gain, row.static_gain_u = record.static_gain.value, record.static_gain.u
            row.static_gain_amplitude_m_s2 = record.static_gain_amplitude_m_s2
        return row

    def reference_chain(self, rig: str) -> list[dict[str, Any]]:
        """The reference items recorded for `rig` (each certificate once)."""
        rows = self.session.scalars(sa.select(t.ReferenceItem).join(t.Rig, t.Rig.id == t.ReferenceItem.rig_id)
                                    .where(t.Rig.name == rig).order_by(t.ReferenceItem.id)).all()
        return [{"item": r.item, "certificate": r.certificate, "issued_by": r.issued_by, "u_rel": r.u_rel,
                 "due": r.due} for r in rows]

    def raw_sha256(self, uuid: str) -> str | None:
        """The recorded raw SHA-256 of shot `uuid` (None: not recorded)."""
        return self.session.scalar(sa.select(t.Shot.raw_sha256).where(t.Shot.uuid == uuid))

    def results(self, serial: str | None = None, campaign: t.Campaign | None = None) -> list[ShotResult]:
        """Every analysed shot of a sensor (or of one campaign) with its newest analysis, oldest first."""
        newest = (sa.select(t.Analysis.shot_id, sa.func.max(t.Analysis.id).label("aid"))
                  .where(t.Analysis.state == "analysed").group_by(t.Analysis.shot_id).subquery())
        query = (sa.select(t.Shot, t.Analysis, t.Rig.name.label("rig"), t.Campaign.name.label("campaign"),
                           t.Campaign.uuid.label("campaign_uuid"))
                 .join(newest, newest.c.shot_id == t.Shot.id)
                 .join(t.Analysis, t.Analysis.id == newest.c.aid)
                 .join(t.Rig, t.Rig.id == t.Shot.rig_id)
                 .outerjoin(t.Campaign, t.Campaign.id == t.Shot.campaign_id)
                 .order_by(t.Shot.utc_time, t.Shot.id))
        if serial is not None:
            query = query.join(t.Sensor, t.Sensor.id == t.Shot.sensor_id).where(t.Sensor.serial == normal_serial(serial))
        if campaign is not None:
            query = query.where(t.Shot.campaign_id == campaign.id)
        return [_shot_result(row) for row in self.session.execute(query)]

    def every(self) -> list[tuple[t.Shot, list[t.Analysis]]]:
        """Every shot with its analyses (for `lab verify`)."""
        shots = self.session.scalars(sa.select(t.Shot).order_by(t.Shot.id)).all()
        analyses: dict[int, list[t.Analysis]] = {}
        for a in self.session.scalars(sa.select(t.Analysis).order_by(t.Analysis.id)):
            analyses.setdefault(a.shot_id, []).append(a)
        return [(shot, analyses.get(shot.id, [])) for shot in shots]


def analysis_figures(analysis: t.Analysis) -> dict[str, Figure | None]:
    """FIGURE_KEYS -> the Figure an analysis row holds (None where it has none)."""
    figures: dict[str, Figure | None] = {}
    for key in t.FIGURE_KEYS:
        value, u = getattr(analysis, key), getattr(analysis, key + "_u")
        lo, hi = getattr(analysis, key + "_lo"), getattr(analysis, key + "_hi")
        figures[key] = Figure(value, u, (lo, hi) if lo is not None and hi is not None else None) \
            if value is not None else None
    return figures


def _shot_result(row: Any) -> ShotResult:
    shot, analysis = row.Shot, row.Analysis
    return ShotResult(
        utc_time=shot.utc_time, shot_uuid=shot.uuid, shot_name=shot.shot_name, campaign_uuid=row.campaign_uuid or "",
        campaign=row.campaign or "", rig=row.rig, operator=shot.operator,
        peak_acceleration_m_s2=analysis.peak_acceleration_m_s2, pulse_width_s=analysis.pulse_width_s,
        response_unit=analysis.response_unit or "", figures=analysis_figures(analysis),
        static_gain=Figure(analysis.static_gain, analysis.static_gain_u) if analysis.static_gain is not None else None,
        static_gain_amplitude_m_s2=analysis.static_gain_amplitude_m_s2,
        simulated_marks=tuple(m for m in shot.simulated_marks.split("; ") if m) or (("flag",) if shot.simulated else ()),
        context=json.loads(shot.context_json or "{}"), file_sha256=analysis.file_sha256, path=shot.path,
        analysis_software=analysis.software_version or "")


@dataclass(frozen=True)
class IssuedCertificate:
    number: str
    replaces: str
    issued_utc: str
    content: dict[str, Any]
    withdrawn_by: str = ""  # the certificate that replaced this one ("" : still valid)


class Certificates:
    """Numbers and rules of certificates (module doc)."""

    def __init__(self, session: Session) -> None:
        self.session = session

    def row(self, number: str) -> t.Certificate | None:
        return self.session.scalar(sa.select(t.Certificate).where(t.Certificate.number == number))

    def valid(self, campaign: t.Campaign, specimen: bool) -> t.Certificate | None:
        """The campaign's certificate (or specimen) that nothing has replaced."""
        replaced = sa.select(t.Certificate.replaces).where(t.Certificate.replaces.is_not(None))
        return self.session.scalar(sa.select(t.Certificate).where(
            t.Certificate.campaign_id == campaign.id, t.Certificate.specimen == specimen,
            t.Certificate.number.not_in(replaced)).order_by(t.Certificate.revision.desc()).limit(1))

    def revision_for(self, campaign: t.Campaign, specimen: bool, replaces: str) -> int:
        """The revision a new certificate of `campaign` gets, or LabError naming the rule it breaks."""
        kind = "specimen" if specimen else "certificate"
        valid = self.valid(campaign, specimen)
        if not replaces:
            if valid is not None:
                raise LabError(f"campaign {campaign.name}: {kind} {valid.number} is valid; a re-issue names it "
                               f"(--replaces {valid.number}), which is then withdrawn")
            return 0
        old = self.row(replaces)
        if old is None:
            raise LabError(f"certificate {replaces}: not in the record; nothing to replace")
        if old.specimen != specimen:
            raise LabError(f"certificate {replaces}: a {'specimen' if old.specimen else 'certificate'} is replaced "
                           f"only by a {'specimen' if old.specimen else 'certificate'}, never by a {kind}")
        if old.campaign_id != campaign.id:
            raise LabError(f"certificate {replaces}: was issued for another campaign; not replaced")
        if valid is None or valid.number != old.number:
            by = self.session.scalar(sa.select(t.Certificate.number).where(t.Certificate.replaces == replaces))
            raise LabError(f"certificate {replaces}: " + (f"already withdrawn (replaced by {by})" if by else
                                                          "not the campaign's valid one (a later one replaced the same "
                                                          "certificate; schema 0001 allowed that)")
                           + f"; only the valid {kind} {valid.number if valid else '—'} can be replaced")
        return old.revision + 1

    def next_number(self, prefix: str, year: int) -> tuple[int, str]:
        last = self.session.scalar(sa.select(sa.func.max(t.Certificate.sequence))
                                   .where(t.Certificate.prefix == prefix, t.Certificate.year == year))
        sequence = (last or 0) + 1
        return sequence, f"{prefix}-{year}-{sequence:04d}"

    def add(self, *, number: str, prefix: str, year: int, sequence: int, campaign: t.Campaign, sensor: t.Sensor,
            specimen: bool, revision: int, replaces: str, authorised_by: str, issued_utc: str,
            content: dict[str, Any]) -> t.Certificate:
        text = json.dumps(content, sort_keys=True, allow_nan=False)
        row = t.Certificate(
            number=number, prefix=prefix, year=year, sequence=sequence, replaces=replaces or None,
            sensor_id=sensor.id, campaign_id=campaign.id, specimen=specimen, revision=revision, subject=campaign.name,
            customer=str(content.get("customer", ""))[:200], authorised_by=authorised_by, issued_utc=issued_utc,
            decision_rule=str(content.get("decision_rule", "")), conformity=str(content.get("conformity", ""))[:40],
            content_json=text, content_sha256=hashlib.sha256(text.encode()).hexdigest())
        self.session.add(row)
        self.session.flush()
        return row

    def issued(self, number: str) -> IssuedCertificate | None:
        row = self.row(number)
        if row is None:
            return None
        by = self.session.scalar(sa.select(t.Certificate.number).where(t.Certificate.replaces == number))
        return IssuedCertificate(row.number, row.replaces or "", row.issued_utc, json.loads(row.content_json), by or "")

    def of_sensor(self, serial: str) -> list[dict[str, Any]]:
        """The certificates issued for a sensor, oldest first, each with what withdrew it."""
        rows = self.session.scalars(sa.select(t.Certificate).join(t.Sensor, t.Sensor.id == t.Certificate.sensor_id)
                                    .where(t.Sensor.serial == normal_serial(serial)).order_by(t.Certificate.id)).all()
        by = {r.replaces: r.number for r in rows if r.replaces}
        return [{"number": r.number, "issued_utc": r.issued_utc, "replaces": r.replaces or "",
                 "conformity": r.conformity, "specimen": r.specimen, "campaign": r.subject,
                 "withdrawn_by": by.get(r.number, "")} for r in rows]

    def every(self) -> list[t.Certificate]:
        return list(self.session.scalars(sa.select(t.Certificate).order_by(t.Certificate.id)))


class AuditTrail:
    def __init__(self, session: Session) -> None:
        self.session = session

    def entries(self, subject: str | None = None, limit: int = 1000) -> list[dict[str, Any]]:
        """The newest audit entries (of one subject), newest first."""
        query = sa.select(t.AuditEntry).order_by(t.AuditEntry.id.desc()).limit(limit)
        if subject is not None:
            query = query.where(t.AuditEntry.subject == subject)
        return [{"utc": a.utc, "actor": a.actor, "action": a.action, "subject": a.subject,
                 "detail": json.loads(a.detail) if a.detail else {}} for a in self.session.scalars(query)]

    def counts(self) -> dict[str, int]:
        """Rows per table (for `hopkinson lab status` and tests)."""
        return {table.__tablename__: self.session.scalar(sa.select(sa.func.count()).select_from(table))
                for table in (t.Sensor, t.Rig, t.Campaign, t.Shot, t.Analysis, t.Certificate, t.AuditEntry)}
