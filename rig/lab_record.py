"""The rig's side of the lab's record (hopkinson.lab): a shot file read into a ShotRecord, the
recorder that records every shot as it is stored, and `lab import`.

The recorder subscribes to the event bus where the command line, the panel and a campaign
build their sequencer (`attach_recorder`): on `Stored` (the raw shot file has its final name)
and `Analysed` (its analysis is in the file) it hands the shot file to a worker thread, which
reads it and delivers it (lab.spool.deliver: the spool drained, then the record, in one
transaction); on `CampaignFinished` every shot file of the run folder. The sequencer never
waits for the database. A record the database cannot take now waits in the spool, one it
refuses is quarantined with the reason; at close whatever is still queued or in flight is
spooled, and the operator is told where each record is. `not_kept` lists the shot files
whose record is in neither the database nor the spool (a full data folder): the command
exits EXIT_NOT_RECORDED then.

A shot file is verified before it is read into a record (rig.shotfile_integrity.verify_shot: the HDF5
checksums and the raw channels' SHA-256), and it is simulated when any of its marks says so:
the simulator's truth, the file's flag, an instrument identifying itself as the simulator.
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
from typing import Any

import h5py

from hopkinson.analysis.key_figures import Figure, KeyFigures
from hopkinson.lab import spool
from hopkinson.lab.database import database_url, redacted
from hopkinson.lab.errors import LabError, RecordRejected, TamperedShotError
from hopkinson.lab.records import SIMULATOR_IDENTITY, ReferenceLink, ShotRecord, figures_of
from hopkinson.lab.repository import LabRepository, open_repository
from hopkinson.rig.config import RigConfig
from hopkinson.rig.events import Analysed, CampaignFinished, EventBus, RigEvent, RigWarning, Stored
from hopkinson.rig.journal import read_campaign_uuid
from hopkinson.rig.run_folder import JOURNAL_NAME, SHOTS_DIR
from hopkinson.rig.shotfile import ShotFileError, ShotMeta, read_shot
from hopkinson.rig.shotfile_integrity import raw_sha256, verify_shot

_log = logging.getLogger(__name__)
CLOSE_WAIT_S = 15.0  # at exit, how long the recorder finishes its queue before spooling the rest
EXIT_NOT_RECORDED = 5  # a shot whose lab record is in neither the database nor the spool


def file_sha256(path: Path) -> str:
    with open(path, "rb") as f:
        return hashlib.file_digest(f, "sha256").hexdigest()


def simulated_marks(meta: ShotMeta, flag: bool) -> tuple[str, ...]:
    """Every mark of simulated data a shot carries (module doc)."""
    marks = []
    if meta.simulated_truth is not None:
        marks.append("simulator's truth")
    if flag:
        marks.append("simulated flag")
    for name, identity in sorted(meta.instruments.items()):
        if SIMULATOR_IDENTITY.search(str(identity)):
            marks.append(f"{name} identifies as the simulator ({identity})")
    return tuple(marks)


def shot_context(meta: ShotMeta) -> dict[str, Any]:
    """What a certificate states of a shot besides its figures: the conditioner's settings and
    identity, the sensitivity its response was scaled by, the instruments, the uncertainty
    budget's reference inputs (from the configuration snapshot in the file)."""
    config = meta.config or {}
    settings = config.get("shot_settings") or {}
    amplifier = config.get("amplifier") or {}
    return {
        "sensitivity_v_per_m_s2": settings.get("sensitivity_v_per_m_s2"),
        "amplifier_gain": settings.get("amplifier_gain", amplifier.get("gain")),
        "amplifier": {k: settings.get(f"amplifier_{k}", amplifier.get(k)) for k in ("excitation_v", "lowpass_hz")}
        | {"driver": amplifier.get("driver"), "identity": meta.instruments.get("amplifier", amplifier.get("identity"))},
        "instruments": dict(meta.instruments),
        "uncertainty": dict(config.get("uncertainty") or {}),
        "mounting": str((config.get("lab") or {}).get("mounting", "")),
        "reference_chain": [dict(r) for r in (config.get("lab") or {}).get("reference_chain") or ()
                            if isinstance(r, dict)],
    }


def shot_record(path: str | Path, recorded_raw_sha256: str | None = None) -> ShotRecord:
    """A shot file as the lab's record holds it, after the one verification
    (rig.shotfile_integrity.verify_shot). TamperedShotError when it fails; ShotFileError when it
    cannot be read."""
    path = Path(path).resolve()
    problems = verify_shot(path, recorded_raw_sha256)
    if problems:
        raise TamperedShotError(f"{path}: {'; '.join(problems)}; refused")
    with h5py.File(path, "r") as f:
        analysis = dict(f["analysis"].attrs) if "analysis" in f else {}
        flag = bool(f.attrs.get("simulated", False))
        written = f.attrs.get("raw_sha256")  # verified against the channels above
    shot = read_shot(path, load_raw=written is None)
    digest = str(written) if written is not None else raw_sha256(shot.raw)
    meta = shot.meta
    lab = meta.config.get("lab") or {}
    rig = str(lab.get("rig") or Path(str(meta.config.get("path") or "unnamed rig")).stem)
    chain = tuple(ReferenceLink(str(r.get("item", "")), str(r.get("certificate", "")), str(r.get("issued_by", "")),
                                float(r["u_rel"]) if r.get("u_rel") else None, str(r.get("due", "")))
                  for r in lab.get("reference_chain") or () if isinstance(r, dict))
    in_run = path.parent.name == SHOTS_DIR and (path.parent.parent / JOURNAL_NAME).is_file()
    campaign_uuid = meta.campaign_uuid or (read_campaign_uuid(path.parent.parent / JOURNAL_NAME) if in_run else None)
    key_figures = KeyFigures.from_results(shot.results) if shot.state == "analysed" and shot.results else None
    return ShotRecord(
        uuid=meta.uuid, raw_sha256=digest, file_sha256=file_sha256(path), path=str(path),
        state=shot.state, operator=meta.operator, utc_time=meta.utc_time, accelerometer_model=meta.accelerometer_model,
        accelerometer_serial=meta.accelerometer_serial, pressure_bar=meta.pressure_bar, projectile=meta.projectile,
        simulated_marks=simulated_marks(meta, flag), software_version=meta.software_version, rig=rig,
        campaign_uuid=campaign_uuid or "", campaign=(meta.campaign_id or "") if campaign_uuid else "",
        campaign_path=str(path.parent.parent) if in_run else "", shot_name=meta.shot_id or path.stem,
        reference_chain=chain, analysis_error=shot.analysis_error or "",
        analysed_utc=str(analysis.get("utc_time", "")),
        analysis_software_version=str(analysis.get("software_version", "")),
        response_unit=key_figures.response_unit if key_figures else "",
        peak_acceleration_m_s2=(key_figures.peak_acceleration_m_s2.value
                                if key_figures and key_figures.peak_acceleration_m_s2 else None),
        pulse_width_s=(key_figures.pulse_width_s.value if key_figures and key_figures.pulse_width_s else None),
        figures=figures_of(key_figures) if key_figures else {},
        static_gain=key_figures.static_gain if key_figures else None,
        static_gain_amplitude_m_s2=key_figures.static_gain_amplitude_m_s2 if key_figures else None,
        context=shot_context(meta),
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


def import_shots(repo: LabRepository, paths: Iterable[str | Path], actor: str = "", legacy_spool: bool = False
                 ) -> Iterator[tuple[Path | str, str]]:
    """Record each shot file (idempotent), the spool of this database drained first: yields
    (path, "new" | "analysis added" | "known" | "refused: <why>"), and ("spool", "<n> recorded,
    …") when the spool held any. A file is verified against the raw SHA-256 the record kept
    from its first import too."""
    drained = spool.drain(repo.where, lambda r: repo.record_shot(r, r.operator), legacy=legacy_spool)
    if drained.recorded or drained.quarantined or drained.left:
        yield "spool", (f"{drained.recorded} recorded, {drained.quarantined} quarantined, {drained.left} waiting"
                        + (f" ({drained.away})" if drained.away else ""))
    for path in shot_files(paths):
        try:
            record = shot_record(path, _kept_raw_sha256(repo, path))
            yield path, repo.record_shot(record, actor or getpass.getuser(), action="shot imported")
        except (RecordRejected, ShotFileError) as exc:
            yield path, f"refused: {exc}"


def _kept_raw_sha256(repo: LabRepository, path: Path) -> str | None:
    """The raw SHA-256 the record kept for this file's shot since its first import (None: new)."""
    try:
        return repo.shot_raw_sha256(read_shot(path, load_raw=False).meta.uuid)
    except ShotFileError:
        return None


_lookup_lock = threading.Lock()
_lookups: dict[str, LabRepository | None] = {}  # by the URL in force; None: it cannot be reached


def kept_raw_sha256(path: str | Path) -> str | None:
    """The raw channels' SHA-256 the lab's record kept from the shot's first import, for `report`
    and `analyse` to verify against (None: no lab record on this machine, or the shot is not in
    it). The record in force (HOPKINSON_DATABASE_URL, else the default SQLite file) is opened once
    per process and never created; one that cannot be reached is not asked again."""
    url = database_url()
    with _lookup_lock:
        if url not in _lookups:
            try:
                _lookups[url] = open_repository(url, create=False)
            except (LabError, OSError):
                _lookups[url] = None
        repo = _lookups[url]
    if repo is None:
        return None
    from sqlalchemy.exc import SQLAlchemyError

    try:
        return _kept_raw_sha256(repo, Path(path))
    except (LabError, OSError, SQLAlchemyError) as exc:
        _log.warning("the lab's record could not be asked for %s's recorded SHA-256: %s", path, exc)
        return None


class LabRecorder:
    """Records each stored or analysed shot (module doc) on its own thread."""

    def __init__(self, url: str = "", bus: EventBus | None = None) -> None:
        self.url = url
        self.database = redacted(database_url(url))
        self.bus = bus
        self._queue: queue.Queue[Path | None] = queue.Queue()
        self._repo: LabRepository | None = None
        self._current: Path | None = None
        self.recorded = 0
        self.spooled = 0
        self.quarantined = 0
        self.not_kept: list[str] = []
        self.messages: list[str] = []
        self._thread = threading.Thread(target=self._run, name="lab-recorder", daemon=True)
        self._thread.start()

    def on_event(self, event: RigEvent) -> None:
        if isinstance(event, Stored | Analysed):
            self._queue.put(Path(event.shot_path))
        elif isinstance(event, CampaignFinished):
            for path in sorted((Path(event.run_folder) / SHOTS_DIR).glob("*.h5")):
                self._queue.put(path)

    def record_now(self, path: Path) -> str:
        """Record one shot file in this thread (the worker's step): its outcome."""
        try:
            record = shot_record(path)
        except (ShotFileError, RecordRejected) as exc:
            self._warn(f"lab record: {exc}")
            return "refused"
        delivery = spool.deliver(self.database, self._repository, record)
        if delivery.outcome in ("new", "analysis added", "known"):
            self.recorded += 1
        else:
            self._drop_repository()
            self.spooled += delivery.outcome == "spooled"
            self.quarantined += delivery.outcome == "quarantined"
            if not delivery.kept:
                self._not_kept(path)
            self._warn(f"lab record: {path.name}: {delivery.message}")
        return delivery.outcome

    def close(self, wait_s: float = CLOSE_WAIT_S) -> None:
        """Finish the queue (up to `wait_s`), then spool what is still queued or in flight
        and close the database."""
        self._queue.put(None)
        self._thread.join(wait_s)
        if self._thread.is_alive():
            left = [self._current] if self._current is not None else []
            while True:
                try:
                    path = self._queue.get_nowait()
                except queue.Empty:
                    break
                if path is not None:
                    left.append(path)
            for path in dict.fromkeys(left):  # each once, in order
                self._spool_unfinished(path)
        else:
            self._drop_repository()

    def _spool_unfinished(self, path: Path) -> None:
        """A shot the database did not take in time: its record waits in the spool."""
        try:
            record = shot_record(path)
            where = spool.spool(record, self.database, "the database did not answer in time")
            self.spooled += 1
            self._warn(f"lab record: {path.name}: the database {self.database} did not take it within "
                       f"{CLOSE_WAIT_S:g} s; queued in {where} (taken in by `hopkinson lab import`)")
        except (OSError, ShotFileError, RecordRejected) as exc:
            self._not_kept(path)
            self._warn(f"lab record: {path.name}: not recorded and not queued ({exc}); the shot file is kept: run "
                       f"`hopkinson lab import {path}`")

    def _run(self) -> None:
        while True:
            path = self._queue.get()
            if path is None:
                return
            self._current = path
            try:
                self.record_now(path)
            except Exception as exc:  # never let the recorder die with shots still to come
                self._not_kept(path)
                self._warn(f"lab record: {path.name}: not recorded ({exc}); run `hopkinson lab import {path}`")
            finally:
                self._current = None

    def _repository(self) -> LabRepository:
        if self._repo is None:
            self._repo = open_repository(self.url)
        return self._repo

    def _drop_repository(self) -> None:
        if self._repo is not None:
            with contextlib.suppress(Exception):
                self._repo.close()
            self._repo = None

    def _not_kept(self, path: Path) -> None:
        if str(path) not in self.not_kept:  # a shot's raw and analysed records are one shot file to import
            self.not_kept.append(str(path))

    def _warn(self, message: str) -> None:
        """Once per event: on the bus when there is one (its printers show it), else in the log.
        A shot's records (raw, analysed, the campaign's catch-up) meeting the same refusal are
        one event for the operator: the same message is told once."""
        if message in self.messages:
            return
        self.messages.append(message)
        if self.bus is not None:
            self.bus.publish(RigWarning(state="STORE", message=message))
        else:
            _log.warning("%s", message)


def attach_recorder(bus: EventBus, config: RigConfig, stack: contextlib.ExitStack | None = None) -> LabRecorder:
    """Record every shot stored on `bus` in the lab's record (config's [database], or the
    default); with `stack`, the recorder is closed when it unwinds (else call close())."""
    recorder = LabRecorder(config.database.url, bus)
    unsubscribe = bus.subscribe(recorder.on_event)
    if stack is not None:
        stack.callback(unsubscribe)
        stack.callback(recorder.close)
    return recorder


def verify_record(repo: LabRepository) -> dict[str, Any]:
    """`lab verify`: every certificate's content against its stored SHA-256, every shot file
    against the verification and the raw SHA-256 kept since its first import, every analysis
    row against an analysis the shot file holds. Problems are listed; files not found are
    listed apart (moved or archived: they cannot be checked here)."""
    import json as json_module

    from hopkinson.lab.repositories import analysis_figures
    from hopkinson.rig.shotfile import analysis_results

    problems: list[str] = []
    missing: list[str] = []
    with repo.reading() as uow:
        certificates = uow.certificates.every()
        shots = uow.shots.every()
        for c in certificates:
            if hashlib.sha256(c.content_json.encode()).hexdigest() != c.content_sha256:
                problems.append(f"certificate {c.number}: its stored content does not match its SHA-256 (changed)")
            elif json_module.loads(c.content_json).get("number") not in (c.number, None):
                problems.append(f"certificate {c.number}: its content names another number")
    for shot, analyses in shots:
        path = Path(shot.path)
        if not path.is_file():
            missing.append(str(path))
            continue
        found = verify_shot(path, shot.raw_sha256)
        if found:
            problems.append(f"shot {shot.uuid} ({path}): {'; '.join(found)}")
            continue
        held = []
        for version in read_shot(path, load_raw=False).analyses:
            results = analysis_results(path, int(version["version"]))
            if results:
                kf = KeyFigures.from_results(results)
                held.append({**figures_of(kf), "static_gain": kf.static_gain,
                             "static_gain_amplitude_m_s2": Figure(kf.static_gain_amplitude_m_s2)})
        for a in analyses:
            if a.state != "analysed":
                continue
            stored = analysis_figures(a)
            if a.static_gain is not None:  # recorded since schema 0003 (before: not in the row, nothing to check)
                stored.update(static_gain=Figure(a.static_gain, a.static_gain_u),
                              static_gain_amplitude_m_s2=Figure(a.static_gain_amplitude_m_s2))
            if not any(_same_figures(stored, h) for h in held):
                problems.append(f"shot {shot.uuid} ({path}): analysis {a.id} (file {a.file_sha256[:12]}…) holds "
                                f"figures no analysis in the shot file has (changed in the database)")
    return {"certificates": len(certificates), "shots": len(shots), "problems": problems, "missing_files": missing}


def _same_figures(a: dict[str, Any], b: dict[str, Any]) -> bool:
    """Whether the figures `a` stores are `b`'s; a figure without a value (not determined: the row
    holds no number) is the same as none."""
    def known(f: Any) -> Any:
        return f if f is not None and f.value is not None else None

    for key in a:
        x, y = known(a.get(key)), known(b.get(key))
        if (x is None) != (y is None):
            return False
        if x is None:
            continue
        for p, q in ((x.value, y.value), (x.u, y.u)):
            if (p is None) != (q is None) or (p is not None and abs(p - q) > 1e-12 * max(1.0, abs(q))):
                return False
    return True


def campaign_ref(repo: LabRepository, source: str | Path, actor: str) -> str:
    """The campaign a run folder (its shots imported first) or a UUID/name names: its reference
    for the lab's record (`hopkinson lab certificate RUN_FOLDER`, the panel's Certificate…)."""
    folder = Path(source)
    if not folder.is_dir():
        return str(source)
    refused = [o for _p, o in import_shots(repo, [folder], actor) if o.startswith("refused")]
    if refused:
        raise LabError(refused[0].removeprefix("refused: "))
    uuid = read_campaign_uuid(folder / JOURNAL_NAME)
    if uuid is None:
        uuids = {shot_record(p).campaign_uuid for p in shot_files([folder])}
        if len(uuids) != 1 or not next(iter(uuids)):
            raise LabError(f"{folder}: not the run folder of one campaign (its shots name {len(uuids)} campaigns)")
        uuid = uuids.pop()
    return uuid


def lab_identity(config: RigConfig) -> Any:
    """The lab as its certificates name it (lab.certificate.LabIdentity) from the rig's [lab]."""
    from hopkinson.lab.certificate import LabIdentity

    lab = config.lab
    return LabIdentity(lab.name, lab.address, lab.accreditation, lab.certificate_prefix, lab.decision_rule,
                       {s.name: s.role for s in lab.signatories}, lab.country)
