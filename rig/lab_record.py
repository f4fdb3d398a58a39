"""The rig's side of the lab's record (hopkinson.lab): a shot file read into a ShotRecord, the
recorder that records every shot as it is stored, and `lab import`.

The recorder subscribes to the event bus where the command line, the panel and a campaign
build their sequencer (`attach_recorder`): on `Stored` (the raw shot file has its final name)
and `Analysed` (its analysis is in the file) it hands the shot file to a worker thread, which
reads it and records it in one transaction; on `CampaignFinished` every shot file of the run
folder (what a campaign analysed from file, e.g. on resume, goes in too; the rest is known). The sequencer never waits for the database; a
database that cannot be reached costs nothing but time: the record goes to the spool
(hopkinson.lab.spool) and in at the next shot or `hopkinson lab import`.
"""

from __future__ import annotations

import contextlib
import getpass
import hashlib
import logging
import queue
import threading
from collections.abc import Iterable, Iterator
from pathlib import Path

import h5py
from hopkinson.analysis.key_figures import KeyFigures
from hopkinson.lab import spool
from hopkinson.lab.database import first_line
from hopkinson.lab.errors import LabError, TamperedShotError
from hopkinson.lab.records import ReferenceLink, ShotRecord, figures_of
from hopkinson.lab.repository import LabRepository, open_repository
from hopkinson.rig.config import RigConfig
from hopkinson.rig.events import Analysed, CampaignFinished, EventBus, RigEvent, RigWarning, Stored
from hopkinson.rig.run_folder import SHOTS_DIR
from hopkinson.rig.shotfile import ShotFileError, raw_sha256, read_shot

_log = logging.getLogger(__name__)
CLOSE_WAIT_S = 15.0  # at exit, how long the recorder finishes its queue before spooling the rest


def file_sha256(path: Path) -> str:
    with open(path, "rb") as f:
        return hashlib.file_digest(f, "sha256").hexdigest()


def shot_record(path: str | Path) -> ShotRecord:
    """A shot file as the lab's record holds it. TamperedShotError when its raw channels no
    longer match the SHA-256 written with them; ShotFileError when it cannot be read."""
    path = Path(path).resolve()
    shot = read_shot(path, load_raw=True)
    assert shot.raw is not None
    digest = raw_sha256(shot.raw)
    with h5py.File(path, "r") as f:
        written = f.attrs.get("raw_sha256")
        analysis = dict(f["analysis"].attrs) if "analysis" in f else {}
    if written is not None and str(written) != digest:
        raise TamperedShotError(f"{path}: raw channels do not match their SHA-256 written with the shot "
                                f"(tampered or damaged); refused")
    meta = shot.meta
    lab = meta.config.get("lab") or {}
    rig = str(lab.get("rig") or Path(str(meta.config.get("path") or "unnamed rig")).stem)
    chain = tuple(ReferenceLink(str(r.get("item", "")), str(r.get("certificate", "")), str(r.get("issued_by", "")),
                                float(r["u_rel"]) if r.get("u_rel") else None, str(r.get("due", "")))
                  for r in lab.get("reference_chain") or () if isinstance(r, dict))
    in_run = path.parent.name == SHOTS_DIR and meta.campaign_id is not None
    key_figures = KeyFigures.from_results(shot.results) if shot.state == "analysed" and shot.results else None
    return ShotRecord(
        uuid=meta.uuid, raw_sha256=digest, file_sha256=file_sha256(path), path=str(path), state=shot.state,
        operator=meta.operator, utc_time=meta.utc_time, accelerometer_model=meta.accelerometer_model,
        accelerometer_serial=meta.accelerometer_serial, pressure_bar=meta.pressure_bar, projectile=meta.projectile,
        simulated=meta.simulated_truth is not None, software_version=meta.software_version, rig=rig,
        campaign=meta.campaign_id or "", campaign_path=str(path.parent.parent) if in_run else "",
        shot_name=meta.shot_id or path.stem, reference_chain=chain,
        analysis_error=shot.analysis_error or "", analysed_utc=str(analysis.get("utc_time", "")),
        analysis_software_version=str(analysis.get("software_version", "")),
        response_unit=key_figures.response_unit if key_figures else "",
        peak_acceleration_m_s2=(key_figures.peak_acceleration_m_s2.value
                                if key_figures and key_figures.peak_acceleration_m_s2 else None),
        figures=figures_of(key_figures) if key_figures else {},
    )


def shot_files(paths: Iterable[str | Path]) -> list[Path]:
    """The shot files named: each SHOT.h5 itself, a run folder's shots/*.h5, a folder's *.h5."""
    out: list[Path] = []
    for given in paths:
        path = Path(given)
        if path.is_dir():
            folder = path / SHOTS_DIR if (path / SHOTS_DIR).is_dir() else path
            found = sorted(p for p in folder.glob("*.h5") if not p.name.startswith("."))
            if not found:
                raise LabError(f"{path}: no shot files (*.h5) in this folder")
            out.extend(found)
        elif path.exists():
            out.append(path)
        else:
            raise LabError(f"{path}: no such file or folder")
    return out


def import_shots(repo: LabRepository, paths: Iterable[str | Path], actor: str = ""
                 ) -> Iterator[tuple[Path, str]]:
    """Record each shot file (idempotent): yields (path, "new" | "analysis added" | "known" |
    "refused: <why>"). The spool is drained first."""
    spool.drain(lambda r: repo.record_shot(r, r.operator))
    for path in shot_files(paths):
        try:
            record = shot_record(path)
            yield path, repo.record_shot(record, actor or getpass.getuser(), action="shot imported")
        except (TamperedShotError, ShotFileError) as exc:
            yield path, f"refused: {exc}"


class LabRecorder:
    """Records each stored or analysed shot (module doc) on its own thread."""

    def __init__(self, url: str = "", bus: EventBus | None = None) -> None:
        self.url = url
        self.bus = bus
        self._queue: queue.Queue[Path | None] = queue.Queue()
        self._repo: LabRepository | None = None
        self._thread = threading.Thread(target=self._run, name="lab-recorder", daemon=True)
        self._thread.start()
        self.recorded = 0
        self.spooled = 0

    def on_event(self, event: RigEvent) -> None:
        if isinstance(event, Stored | Analysed):
            self._queue.put(Path(event.shot_path))
        elif isinstance(event, CampaignFinished):
            for path in sorted((Path(event.run_folder) / SHOTS_DIR).glob("*.h5")):
                self._queue.put(path)

    def record_now(self, path: Path) -> str:
        """Record one shot file in this thread (the worker's step; spools when the database is away)."""
        try:
            record = shot_record(path)
        except (ShotFileError, TamperedShotError) as exc:
            self._warn(f"lab record: {exc}")
            return "refused"
        try:
            repo = self._repository()
            spool.drain(lambda r: repo.record_shot(r, r.operator))
            outcome = repo.record_shot(record)
            self.recorded += 1
            return outcome
        except TamperedShotError as exc:
            self._warn(f"lab record: {exc}")
            return "refused"
        except Exception as exc:  # the database away or failing: the record waits in the spool
            self._drop_repository()
            where = spool.spool(record)
            self.spooled += 1
            self._warn(f"lab record: not recorded now ({first_line(exc)}); queued in {where} "
                       f"(retried at the next shot or `hopkinson lab import`)")
            return "spooled"

    def close(self, wait_s: float = CLOSE_WAIT_S) -> None:
        """Finish the queue (up to `wait_s`), then spool what is left and close the database."""
        self._queue.put(None)
        self._thread.join(wait_s)
        if self._thread.is_alive():
            while True:
                try:
                    path = self._queue.get_nowait()
                except queue.Empty:
                    break
                if path is not None:
                    with contextlib.suppress(Exception):
                        spool.spool(shot_record(path))
        self._drop_repository()

    def _run(self) -> None:
        while True:
            path = self._queue.get()
            if path is None:
                return
            try:
                self.record_now(path)
            except Exception:  # never let the recorder die with shots still to come
                _log.exception("lab recorder failed on %s", path)

    def _repository(self) -> LabRepository:
        if self._repo is None:
            self._repo = open_repository(self.url)
        return self._repo

    def _drop_repository(self) -> None:
        if self._repo is not None:
            self._repo.close()
            self._repo = None

    def _warn(self, message: str) -> None:
        _log.warning("%s", message)
        if self.bus is not None:
            self.bus.publish(RigWarning(state="STORE", message=message))


def attach_recorder(bus: EventBus, config: RigConfig, stack: contextlib.ExitStack | None = None) -> LabRecorder:
    """Record every shot stored on `bus` in the lab's record (config's [database], or the
    default); with `stack`, the recorder is closed when it unwinds (else call close())."""
    recorder = LabRecorder(config.database.url, bus)
    unsubscribe = bus.subscribe(recorder.on_event)
    if stack is not None:
        stack.callback(recorder.close)
        stack.callback(unsubscribe)
    return recorder
