"""The lab record's tables (SQLAlchemy 2 declarative). Changing a table means a new Alembic
revision in migrations/versions: the database is never silently rewritten.

Every table is append-only: a row, once written, is never updated or deleted (the database's
triggers refuse it, migration 0002; the rig's role holds INSERT and SELECT only,
docs/lab-record.md). What changes over time is a new row: a sensor's data (`SensorData`, the
newest row wins), a campaign's job record (`Job`), a re-issued certificate (a new row naming
the one it replaces, which is thereby withdrawn).

Times are ISO 8601 UTC text ending in Z (as in shot files: sortable, the same on SQLite and
PostgreSQL). Key figures are stored as value, standard uncertainty u and the 95 % interval
(lo, hi) per figure: `FIGURE_KEYS`, one column each, so a sensor's history is one query.
"""

from __future__ import annotations

from sqlalchemy import Boolean, Float, ForeignKey, Index, Integer, String, Text, UniqueConstraint
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column

# The key figures kept per analysis (reports.statistics.COMBINED's keys)
FIGURE_KEYS = ("sensitivity", "shock_sensitivity", "natural_frequency_hz", "damping_ratio", "fbsd_5_hz",
               "fbsd_10_hz")
FIGURE_PARTS = ("", "_u", "_lo", "_hi")
APPEND_ONLY_MESSAGE = "is append-only: rows are never updated or deleted"


class Base(DeclarativeBase):
    pass


class Sensor(Base):
    """An accelerometer by its serial (normalised: lab.records.normal_serial)."""

    __tablename__ = "sensors"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    serial: Mapped[str] = mapped_column(String(120), unique=True)
    created_utc: Mapped[str] = mapped_column(String(40))


class SensorData(Base):
    """What the lab knows of a sensor beyond its shots, as of `utc`: the newest row is in force."""

    __tablename__ = "sensor_data"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    sensor_id: Mapped[int] = mapped_column(ForeignKey("sensors.id"), index=True)
    utc: Mapped[str] = mapped_column(String(40))
    actor: Mapped[str] = mapped_column(String(200))
    model: Mapped[str] = mapped_column(String(200), default="")
    owner: Mapped[str] = mapped_column(String(200), default="")
    nominal_sensitivity: Mapped[float | None] = mapped_column(Float, nullable=True)
    sensitivity_unit: Mapped[str] = mapped_column(String(40), default="")
    tolerance_percent: Mapped[float | None] = mapped_column(Float, nullable=True)
    interval_days: Mapped[int | None] = mapped_column(Integer, nullable=True)


class Rig(Base):
    __tablename__ = "rigs"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    name: Mapped[str] = mapped_column(String(120), unique=True)


class ReferenceItem(Base):
    """One link of a rig's reference chain as it stood when a shot was recorded (its certificate)."""

    __tablename__ = "reference_items"
    __table_args__ = (UniqueConstraint("rig_id", "item", "certificate"),)
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    rig_id: Mapped[int] = mapped_column(ForeignKey("rigs.id"))
    item: Mapped[str] = mapped_column(String(200))
    certificate: Mapped[str] = mapped_column(String(200))
    issued_by: Mapped[str] = mapped_column(String(200), default="")
    u_rel: Mapped[float | None] = mapped_column(Float, nullable=True)  # k = 1
    due: Mapped[str] = mapped_column(String(20), default="")  # YYYY-MM-DD


class Campaign(Base):
    """A calibration: one run of a plan, known by the UUID in its run folder's journal and shot
    files (never by its folder's name, which is only shown)."""

    __tablename__ = "campaigns"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    uuid: Mapped[str] = mapped_column(String(36), unique=True)
    name: Mapped[str] = mapped_column(String(200))  # the run folder's name, for people
    rig_id: Mapped[int | None] = mapped_column(ForeignKey("rigs.id"), nullable=True)
    sensor_id: Mapped[int | None] = mapped_column(ForeignKey("sensors.id"), nullable=True)
    path: Mapped[str] = mapped_column(Text, default="")
    first_utc: Mapped[str] = mapped_column(String(40))


class Job(Base):
    """A campaign's job record (ISO/IEC 17025 §7.8.2.1: receipt, condition, location); the
    newest row of a campaign is in force."""

    __tablename__ = "jobs"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    campaign_id: Mapped[int] = mapped_column(ForeignKey("campaigns.id"), index=True)
    utc: Mapped[str] = mapped_column(String(40))
    actor: Mapped[str] = mapped_column(String(200))
    received: Mapped[str] = mapped_column(String(20), default="")  # YYYY-MM-DD
    condition: Mapped[str] = mapped_column(Text, default="")  # condition of the item as received
    location: Mapped[str] = mapped_column(Text, default="")  # where the calibration was done
    customer: Mapped[str] = mapped_column(String(200), default="")
    customer_contact: Mapped[str] = mapped_column(Text, default="")
    mounting: Mapped[str] = mapped_column(Text, default="")
    environment: Mapped[str] = mapped_column(Text, default="")


class Shot(Base):
    """A shot fired: keyed by its UUID; its raw channels' SHA-256 never changes."""

    __tablename__ = "shots"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    uuid: Mapped[str] = mapped_column(String(36), unique=True)
    raw_sha256: Mapped[str] = mapped_column(String(64))
    sensor_id: Mapped[int | None] = mapped_column(ForeignKey("sensors.id"), index=True, nullable=True)
    rig_id: Mapped[int] = mapped_column(ForeignKey("rigs.id"))
    campaign_id: Mapped[int | None] = mapped_column(ForeignKey("campaigns.id"), nullable=True, index=True)
    shot_name: Mapped[str] = mapped_column(String(200), default="")
    operator: Mapped[str] = mapped_column(String(200), default="")
    utc_time: Mapped[str] = mapped_column(String(40))
    pressure_bar: Mapped[float] = mapped_column(Float)
    projectile: Mapped[int] = mapped_column(Integer)
    simulated: Mapped[bool] = mapped_column(Boolean, default=False)
    simulated_marks: Mapped[str] = mapped_column(Text, default="")  # what marked it simulated ("; ")
    software_version: Mapped[str] = mapped_column(String(60), default="")
    path: Mapped[str] = mapped_column(Text)
    context_json: Mapped[str] = mapped_column(Text, default="{}")  # amplifier, instruments, budget inputs
    recorded_utc: Mapped[str] = mapped_column(String(40))


class Analysis(Base):
    """One analysis of a shot, as the shot file held it (the file's SHA-256 names the version)."""

    __tablename__ = "analyses"
    __table_args__ = (UniqueConstraint("shot_id", "file_sha256"),)
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    shot_id: Mapped[int] = mapped_column(ForeignKey("shots.id"), index=True)
    file_sha256: Mapped[str] = mapped_column(String(64))
    state: Mapped[str] = mapped_column(String(20))  # "raw", "analysed" or "analysis_failed"
    error: Mapped[str] = mapped_column(Text, default="")
    analysed_utc: Mapped[str] = mapped_column(String(40), default="")
    software_version: Mapped[str] = mapped_column(String(60), default="")
    response_unit: Mapped[str] = mapped_column(String(40), default="")
    peak_acceleration_m_s2: Mapped[float | None] = mapped_column(Float, nullable=True)
    pulse_width_s: Mapped[float | None] = mapped_column(Float, nullable=True)
    recorded_utc: Mapped[str] = mapped_column(String(40))
    # one column per key figure and part: sensitivity, sensitivity_u, sensitivity_lo, ...
    locals().update({key + part: mapped_column(Float, nullable=True)
                     for key in FIGURE_KEYS for part in FIGURE_PARTS})
    # the quasi-static gain in the main pulse's direction (analysis.static_gain: what the amplitude
    # linearity is fitted to), its shot-specific u and the amplitude it is measured at (migration 0003)
    static_gain: Mapped[float | None] = mapped_column(Float, nullable=True)
    static_gain_u: Mapped[float | None] = mapped_column(Float, nullable=True)
    static_gain_amplitude_m_s2: Mapped[float | None] = mapped_column(Float, nullable=True)


class Certificate(Base):
    """A certificate as issued: immutable. A re-issue is a new row naming this one in
    `replaces` (unique: one successor; migration 0002 leaves out only a second successor 0001
    had let be issued), with the next `revision` of the same campaign and kind
    (unique: one first issue, one line of re-issues); the one not replaced is valid."""

    __tablename__ = "certificates"
    __table_args__ = (UniqueConstraint("prefix", "year", "sequence"),
                      UniqueConstraint("campaign_id", "specimen", "revision", name="uq_certificates_lineage"),
                      Index("uq_certificates_replaces", "replaces", unique=True))
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    number: Mapped[str] = mapped_column(String(40), unique=True)
    prefix: Mapped[str] = mapped_column(String(16))
    year: Mapped[int] = mapped_column(Integer)
    sequence: Mapped[int] = mapped_column(Integer)
    replaces: Mapped[str | None] = mapped_column(String(40), nullable=True)
    sensor_id: Mapped[int] = mapped_column(ForeignKey("sensors.id"), index=True)
    campaign_id: Mapped[int | None] = mapped_column(ForeignKey("campaigns.id"), nullable=True, index=True)
    specimen: Mapped[bool] = mapped_column(Boolean, default=False)
    revision: Mapped[int] = mapped_column(Integer, default=0)
    subject: Mapped[str] = mapped_column(Text)  # the campaign certified (its name, for people)
    customer: Mapped[str] = mapped_column(String(200), default="")
    authorised_by: Mapped[str] = mapped_column(String(200))
    issued_utc: Mapped[str] = mapped_column(String(40))
    decision_rule: Mapped[str] = mapped_column(String(20))
    conformity: Mapped[str] = mapped_column(String(40))
    content_json: Mapped[str] = mapped_column(Text)  # everything the certificate says
    content_sha256: Mapped[str] = mapped_column(String(64))


class AuditEntry(Base):
    """Who did what and when: written by the unit of work's before_flush hook (lab.uow)."""

    __tablename__ = "audit"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    utc: Mapped[str] = mapped_column(String(40), index=True)
    actor: Mapped[str] = mapped_column(String(200))
    action: Mapped[str] = mapped_column(String(40))
    subject: Mapped[str] = mapped_column(Text)
    detail: Mapped[str] = mapped_column(Text, default="")


APPEND_ONLY_TABLES = tuple(table.__tablename__ for table in (
    Sensor, SensorData, Rig, ReferenceItem, Campaign, Job, Shot, Analysis, Certificate, AuditEntry))
