"""The lab record's tables (SQLAlchemy 2 declarative). Changing a table means a new Alembic
revision in migrations/versions: the database is never silently rewritten.

Times are ISO 8601 UTC text ending in Z (as in shot files: sortable, the same on SQLite and
PostgreSQL). Key figures are stored as value, standard uncertainty u and the 95 % interval
(lo, hi) per figure: `FIGURE_KEYS`, one column each, so a sensor's history is one query.
"""

from __future__ import annotations

from sqlalchemy import Boolean, Float, ForeignKey, Integer, String, Text, UniqueConstraint
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column

# The key figures kept per analysis (reports.statistics.COMBINED's keys)
FIGURE_KEYS = ("sensitivity", "shock_sensitivity", "natural_frequency_hz", "damping_ratio", "fbsd_5_hz",
               "fbsd_10_hz")
FIGURE_PARTS = ("", "_u", "_lo", "_hi")


class Base(DeclarativeBase):
    pass


class Sensor(Base):
    """An accelerometer by serial: what the lab knows of it beyond its shots."""

    __tablename__ = "sensors"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    serial: Mapped[str] = mapped_column(String(120), unique=True)
    model: Mapped[str] = mapped_column(String(200), default="")
    owner: Mapped[str] = mapped_column(String(200), default="")
    nominal_sensitivity: Mapped[float | None] = mapped_column(Float, nullable=True)
    sensitivity_unit: Mapped[str] = mapped_column(String(40), default="")
    tolerance_percent: Mapped[float | None] = mapped_column(Float, nullable=True)
    interval_days: Mapped[int | None] = mapped_column(Integer, nullable=True)
    created_utc: Mapped[str] = mapped_column(String(40))


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
    __tablename__ = "campaigns"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    name: Mapped[str] = mapped_column(String(200), unique=True)  # the run folder's name
    rig_id: Mapped[int | None] = mapped_column(ForeignKey("rigs.id"), nullable=True)
    sensor_id: Mapped[int | None] = mapped_column(ForeignKey("sensors.id"), nullable=True)
    path: Mapped[str] = mapped_column(Text, default="")
    first_utc: Mapped[str] = mapped_column(String(40))


class Shot(Base):
    """A shot fired: keyed by its UUID; its raw channels' SHA-256 never changes."""

    __tablename__ = "shots"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    uuid: Mapped[str] = mapped_column(String(36), unique=True)
    raw_sha256: Mapped[str] = mapped_column(String(64))
    sensor_id: Mapped[int] = mapped_column(ForeignKey("sensors.id"), index=True)
    rig_id: Mapped[int] = mapped_column(ForeignKey("rigs.id"))
    campaign_id: Mapped[int | None] = mapped_column(ForeignKey("campaigns.id"), nullable=True, index=True)
    shot_name: Mapped[str] = mapped_column(String(200), default="")
    operator: Mapped[str] = mapped_column(String(200), default="")
    utc_time: Mapped[str] = mapped_column(String(40))
    pressure_bar: Mapped[float] = mapped_column(Float)
    projectile: Mapped[int] = mapped_column(Integer)
    simulated: Mapped[bool] = mapped_column(Boolean, default=False)
    software_version: Mapped[str] = mapped_column(String(60), default="")
    path: Mapped[str] = mapped_column(Text)
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
    recorded_utc: Mapped[str] = mapped_column(String(40))
    # one column per key figure and part: sensitivity, sensitivity_u, sensitivity_lo, ...
    locals().update({key + part: mapped_column(Float, nullable=True)
                     for key in FIGURE_KEYS for part in FIGURE_PARTS})


class Certificate(Base):
    """A certificate as issued: immutable (a re-issue is a new row naming this one)."""

    __tablename__ = "certificates"
    __table_args__ = (UniqueConstraint("prefix", "year", "sequence"),)
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    number: Mapped[str] = mapped_column(String(40), unique=True)
    prefix: Mapped[str] = mapped_column(String(16))
    year: Mapped[int] = mapped_column(Integer)
    sequence: Mapped[int] = mapped_column(Integer)
    replaces: Mapped[str] = mapped_column(String(40), default="")
    sensor_id: Mapped[int] = mapped_column(ForeignKey("sensors.id"), index=True)
    subject: Mapped[str] = mapped_column(Text)  # the campaign (run folder) certified
    customer: Mapped[str] = mapped_column(String(200), default="")
    authorised_by: Mapped[str] = mapped_column(String(200))
    issued_utc: Mapped[str] = mapped_column(String(40))
    decision_rule: Mapped[str] = mapped_column(String(20))
    conformity: Mapped[str] = mapped_column(String(40))
    content_json: Mapped[str] = mapped_column(Text)  # everything the certificate says
    content_sha256: Mapped[str] = mapped_column(String(64))


class AuditEntry(Base):
    """Who did what and when: append-only (no update or delete path; triggers refuse them)."""

    __tablename__ = "audit"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    utc: Mapped[str] = mapped_column(String(40), index=True)
    actor: Mapped[str] = mapped_column(String(200))
    action: Mapped[str] = mapped_column(String(40))
    subject: Mapped[str] = mapped_column(Text)
    detail: Mapped[str] = mapped_column(Text, default="")
