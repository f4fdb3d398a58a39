"""Every shot is recorded when it is stored: the recorder on the event bus of a real sequencer
(simulated rig). A database that cannot be reached costs no shot: the record is spooled and
`hopkinson lab import` catches up."""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable
from pathlib import Path

import h5py
import pytest

from hopkinson.lab import spool
from hopkinson.lab.database import redacted
from hopkinson.lab.repository import open_repository
from hopkinson.rig.cli.main import main
from hopkinson.rig.config import DatabaseConfig
from hopkinson.rig.events import RigWarning
from hopkinson.rig.lab_record import LabRecorder, attach_recorder
from tests.rig.conftest import Rig, short_timeouts_config

UNREACHABLE = "postgresql://nobody@127.0.0.1:9/lab"  # port 9 (discard): nothing listens on loopback
CONFIG = str(Path(__file__).resolve().parents[2] / "config" / "rig-sim.toml")


def test_a_stored_shot_is_recorded_from_the_bus(make_rig: Callable[..., Rig], tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'lab.sqlite'}"
    config = short_timeouts_config()
    rig = make_rig(config=dataclasses.replace(config, database=DatabaseConfig(url)))
    recorder = attach_recorder(rig.bus, rig.config)
    outcome = rig.run(pressure_bar=1.0, accelerometer_serial="SN-REC", operator="tech B")
    recorder.close()
    assert outcome.final_state == "DONE" and recorder.spooled == 0
    with h5py.File(outcome.shot_path) as f:
        uuid, raw_sha = str(f.attrs["uuid"]), str(f.attrs["raw_sha256"])
    with open_repository(url) as repo:
        assert repo.shot_raw_sha256(uuid) == raw_sha
        trail = repo.audit_trail(uuid)
        assert [a["action"] for a in trail][-1] == "shot fired" and trail[-1]["actor"] == "tech B"
        assert trail[-1]["detail"]["path"] == str(Path(outcome.shot_path).resolve())
        assert repo.counts()["analyses"] == 1  # its analysis, named by the analysed file's SHA-256


def test_an_unreachable_database_costs_no_shot(make_rig: Callable[..., Rig], tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    config = short_timeouts_config()
    rig = make_rig(config=dataclasses.replace(config, database=DatabaseConfig(UNREACHABLE)))
    recorder = attach_recorder(rig.bus, rig.config)
    outcome = rig.run(pressure_bar=1.0, accelerometer_serial="SN-SPOOL")
    recorder.close()
    assert outcome.final_state == "DONE" and Path(outcome.shot_path).exists()
    warnings = [e.message for e in rig.recorder.of(RigWarning) if "lab record" in e.message]
    assert warnings and "cannot be reached" in warnings[0] and str(spool.spool_path()) in warnings[0]
    assert len(spool.pending()) == recorder.spooled >= 1

    # another database never takes them (they were meant for the PostgreSQL one): not the next
    # shot's recorder, not a plain `lab import` into it
    url = f"sqlite:///{tmp_path / 'lab.sqlite'}"
    later = LabRecorder(url)
    assert later.record_now(Path(outcome.shot_path)) == "new"
    later.close()
    assert len(spool.pending()) == recorder.spooled and spool.pending()[0].database == redacted(UNREACHABLE)
    assert main(["lab", "import", "--database", url, "--json", "--config", CONFIG]) == 0
    assert json.loads(capsys.readouterr().out)["spool"] == ""
    assert len(spool.pending()) == recorder.spooled
    with open_repository(url) as repo:
        assert repo.counts()["shots"] == 1 and repo.counts()["analyses"] == 1


def test_a_spooled_record_goes_into_its_own_database_when_it_is_back(make_rig: Callable[..., Rig], tmp_path: Path,
                                                                     capsys: pytest.CaptureFixture[str]) -> None:
    away = tmp_path / "not-mounted-yet"
    url = f"sqlite:///{away / 'lab.sqlite'}"  # its folder missing: the database cannot be opened
    config = short_timeouts_config()
    rig = make_rig(config=dataclasses.replace(config, database=DatabaseConfig(url)))
    recorder = attach_recorder(rig.bus, rig.config)
    outcome = rig.run(pressure_bar=1.0, accelerometer_serial="SN-BACK")
    recorder.close()
    assert outcome.final_state == "DONE" and recorder.spooled >= 1 and not recorder.not_kept
    away.mkdir()  # the database is back
    assert main(["lab", "import", "--database", url, "--json", "--config", CONFIG]) == 0  # no path: the spool
    assert json.loads(capsys.readouterr().out)["spool"].startswith(f"{recorder.spooled} recorded")
    assert spool.pending() == []
    with open_repository(url) as repo:
        assert repo.counts()["shots"] == 1 and repo.counts()["analyses"] == 1
