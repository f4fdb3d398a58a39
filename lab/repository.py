"""Convenience calls on the lab's record, each one unit of work (lab.uow): for scripts,
benchmarks and callers that do one thing at a time. Work that must happen together opens
`LabDatabase.unit_of_work` itself."""

from __future__ import annotations

from typing import Any

from hopkinson.lab.history import Calibration, calibrations_of
from hopkinson.lab.records import ShotRecord
from hopkinson.lab.repositories import IssuedCertificate, SensorInfo, ShotResult
from hopkinson.lab.uow import LabDatabase, open_lab

__all__ = ["IssuedCertificate", "LabRepository", "SensorInfo", "ShotResult", "open_repository"]


class LabRepository(LabDatabase):
    """The lab's record with one call per unit of work (module doc)."""

    def record_shot(self, record: ShotRecord, actor: str = "", action: str = "shot fired") -> str:
        """Record a shot (lab.repositories.Shots.record): "new", "analysis added" or "known"."""
        return self.transact(actor or record.operator, lambda uow: uow.shots.record(record), shot_action=action)

    def register_sensor(self, serial: str, actor: str, create: bool = True, **fields: Any) -> SensorInfo:
        return self.transact(actor, lambda uow: uow.sensors.revise(serial, create=create, **fields))

    def sensor(self, serial: str) -> SensorInfo | None:
        with self.reading() as uow:
            return uow.sensors.info(serial)

    def shot_results(self, serial: str) -> list[ShotResult]:
        with self.reading() as uow:
            return uow.shots.results(serial)

    def calibrations(self, serial: str) -> list[Calibration]:
        with self.reading() as uow:
            return calibrations_of(uow.shots.results(serial), uow.sensors.info(serial))

    def shot_raw_sha256(self, uuid: str) -> str | None:
        with self.reading() as uow:
            return uow.shots.raw_sha256(uuid)

    def reference_chain(self, rig: str) -> list[dict[str, Any]]:
        with self.reading() as uow:
            return uow.shots.reference_chain(rig)

    def certificates(self, serial: str) -> list[dict[str, Any]]:
        with self.reading() as uow:
            return uow.certificates.of_sensor(serial)

    def certificate(self, number: str) -> IssuedCertificate | None:
        with self.reading() as uow:
            return uow.certificates.issued(number)

    def audit_trail(self, subject: str | None = None, limit: int = 1000) -> list[dict[str, Any]]:
        with self.reading() as uow:
            return uow.audit.entries(subject, limit)

    def counts(self) -> dict[str, int]:
        with self.reading() as uow:
            return uow.audit.counts()


def open_repository(url: str = "", explicit: str = "", create: bool = True) -> LabRepository:
    """The lab's record (lab.uow.open_lab) with the convenience calls above."""
    return open_lab(url, explicit, create, cls=LabRepository)
