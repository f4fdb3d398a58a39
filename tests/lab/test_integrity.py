"""What an ISO/IEC 17025 assessor would try (issue 41's "Where it stands"), each on the code
that failed it: the right sensor on every certificate, simulated data never certified, nothing
lost between the shot and the database, one verification of shot files, the record's rules
on certificates, a number issued only with its document, and the smaller faults."""

from __future__ import annotations

import json
import sqlite3
import threading
from pathlib import Path

import h5py
import pytest
import sqlalchemy as sa

from hopkinson.lab import spool
from hopkinson.lab.errors import LabError
from hopkinson.lab.repository import open_repository
from hopkinson.rig.cli.main import main
from hopkinson.rig.lab_record import LabRecorder, shot_record
from hopkinson.rig.shotfile_integrity import RAW_MISMATCH, verify_shot
from tests.lab.records import made_up_record, write_made_up_shot
from tests.lab.test_lab_cli import LAB_SECTION, REPO, lab, record_job
from tests.lab.test_repository import issue_for


@pytest.fixture
def lab_config(tmp_path: Path) -> Path:
    path = tmp_path / "rig.toml"
    path.write_text((REPO / "config" / "rig-sim.toml").read_text() + LAB_SECTION)
    return path


@pytest.fixture
def url(tmp_path: Path) -> str:
    return f"sqlite:///{tmp_path / 'lab.sqlite'}"


def run_of(folder: Path, serial: str, n: int = 2, **kw) -> Path:
    (folder / "shots").mkdir(parents=True)
    for i in range(n):
        write_made_up_shot(folder / "shots" / f"s{i}.h5", serial=serial, campaign=folder.name,
                           utc=f"2026-03-0{1 + i}T10:00:00Z", **kw)
    return folder


def test_two_runs_with_one_folder_name_are_two_campaigns_and_each_certificate_names_its_sensor(
        tmp_path: Path, url: str, lab_config: Path, capsys: pytest.CaptureFixture[str]) -> None:
    a = run_of(tmp_path / "a" / "camp", "SN-A")
    b = run_of(tmp_path / "b" / "camp", "SN-B", n=3)
    for run in (a, b):
        record_job(capsys, url, run, lab_config)
    code, out, err = lab(capsys, url, "certificate", str(b), "-o", str(tmp_path / "b.html"), "--authorised-by", "Q",
                         "--json", "--config", str(lab_config))
    assert code == 0, err
    text = (tmp_path / "b.html").read_text()
    assert "SN-B" in text and "SN-A" not in text and "<td>shots</td><td>3</td>" in text
    with open_repository(url) as repo:
        assert repo.counts()["campaigns"] == 2
    code, _out, err = lab(capsys, url, "certificate", "camp", "-o", str(tmp_path / "x.html"), "--authorised-by", "Q",
                          "--config", str(lab_config))
    assert code == 2 and "2 campaigns have this name" in err  # a name alone never picks one


@pytest.mark.parametrize("mark", ["instrument identity", "truth"])
def test_a_simulated_shot_is_recognised_from_each_mark_and_never_gets_a_real_number(
        mark: str, tmp_path: Path, url: str, lab_config: Path, capsys: pytest.CaptureFixture[str]) -> None:
    run = run_of(tmp_path / "rehearsal", "SN-REAL", simulated=mark == "truth",
                 instruments={"digitizer": "Hopkinson-Sim,SIMDIG-4CH,SIM0001,1.0"} if mark != "truth" else None)
    with h5py.File(run / "shots" / "s0.h5", "r+") as f:
        f.attrs["simulated"] = False  # the flag removed: the other marks remain
    record_job(capsys, url, run, lab_config)
    code, _out, err = lab(capsys, url, "certificate", str(run), "-o", str(tmp_path / "c.html"), "--authorised-by", "Q",
                          "--config", str(lab_config))
    assert code == 2 and "made by the simulator" in err and not (tmp_path / "c.html").exists()
    code, out, _ = lab(capsys, url, "sensor", "SN-REAL", "--json", "--config", str(lab_config))
    history = json.loads(out)
    assert history["calibrations"][0]["simulated"] and "1 simulated calibration(s) not judged" in history["flags"]
    code, out, _ = lab(capsys, url, "sensor", "SN-REAL", "--config", str(lab_config))
    assert "SIMULATED" in out


def test_a_rejected_record_is_quarantined_with_its_reason_and_blocks_nothing(url: str, lab_config: Path,
                                                                             capsys: pytest.CaptureFixture[str]) -> None:
    with open_repository(url) as repo:
        where = repo.where
    bad = made_up_record("SN-Q", operator="x" * 300)
    good = made_up_record("SN-Q")
    spool.spool(bad, where, "was away")
    spool.spool(good, where, "was away")
    code, out, _ = lab(capsys, url, "import", "--json", "--config", str(lab_config))
    assert code == 0 and json.loads(out)["spool"].startswith("1 recorded, 1 quarantined, 0 waiting")
    assert spool.pending() == []
    (held,) = spool.quarantined()
    assert held.record.uuid == bad.uuid and "operator is 300 characters long, at most 200" in held.reason
    code, out, _ = lab(capsys, url, "status", "--json", "--config", str(lab_config))
    assert json.loads(out)["quarantined"][0]["reason"] == held.reason
    with open_repository(url) as repo:
        assert repo.shot_raw_sha256(good.uuid) is not None and repo.shot_raw_sha256(bad.uuid) is None


def test_a_locked_database_at_exit_spools_the_record_and_says_so(tmp_path: Path, url: str, lab_config: Path,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    shot = tmp_path / "one.h5"
    write_made_up_shot(shot, serial="SN-LOCK")
    open_repository(url).close()
    holder = sqlite3.connect(tmp_path / "lab.sqlite", isolation_level=None, check_same_thread=False)
    holder.execute("BEGIN EXCLUSIVE")  # another program holds the database
    recorder = LabRecorder(url)
    recorder._queue.put(shot)
    threading.Event().wait(0.3)
    recorder.close(wait_s=1.0)
    holder.execute("ROLLBACK")
    holder.close()
    assert recorder.spooled == 1 and not recorder.not_kept
    assert any("did not take it within" in m and "lab import" in m for m in recorder.messages)
    assert main(["lab", "import", "--database", url, "--config", str(lab_config)]) == 0
    with open_repository(url) as repo:
        assert repo.counts()["shots"] == 1 and repo.counts()["analyses"] == 1


def test_a_record_nowhere_is_said_and_never_exit_0(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from hopkinson.rig.cli.shot import not_recorded_exit

    shot = tmp_path / "one.h5"
    write_made_up_shot(shot, serial="SN-FULL")

    def full(*_a, **_k):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(spool, "_append", full)
    recorder = LabRecorder("postgresql://nobody@127.0.0.1:9/lab")  # away, and the spool cannot be written
    assert recorder.record_now(shot) == "not kept"
    recorder.close()
    assert recorder.not_kept == [str(shot)]
    assert "No space left on device" in recorder.messages[-1] and f"hopkinson lab import {shot.resolve()}" in \
        recorder.messages[-1]
    assert not_recorded_exit(recorder, 0) == 5


def test_a_number_exists_only_with_its_documents(run_folder_factory, url: str, lab_config: Path, tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str],
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    import hopkinson.fileio as fileio

    run = run_folder_factory()
    record_job(capsys, url, run, lab_config)
    real_write = fileio.atomic_write

    def full_for_xml(path, data, *a, **k):
        if str(path).endswith(".xml"):
            raise OSError(28, "No space left on device", str(path))
        return real_write(path, data, *a, **k)

    monkeypatch.setattr(fileio, "atomic_write", full_for_xml)
    pdf, xml = tmp_path / "c.pdf", tmp_path / "c.xml"
    code, _out, err = lab(capsys, url, "certificate", str(run), "-o", str(pdf), "-o", str(xml), "--authorised-by",
                          "Q", "--config", str(lab_config))
    assert code == 2 and "No space left on device" in err and "Traceback" not in err
    assert not pdf.exists() and not xml.exists()  # the PDF written first was removed again
    with open_repository(url) as repo:
        assert repo.counts()["certificates"] == 0
        assert not [a for a in repo.audit_trail() if a["action"].startswith("certificate")]
    monkeypatch.setattr(fileio, "atomic_write", real_write)
    code, out, err = lab(capsys, url, "certificate", str(run), "-o", str(xml), "--authorised-by", "Q", "--json",
                         "--config", str(lab_config))
    number = json.loads(out)["number"]
    assert code == 0 and number.endswith("-0001")  # the failed attempt used no number
    again = tmp_path / "again.xml"
    assert lab(capsys, url, "reprint", number, "-o", str(again), "--config", str(lab_config))[0] == 0
    import difflib

    assert again.read_bytes() == xml.read_bytes(), "\n".join(difflib.unified_diff(
        xml.read_text().splitlines(), again.read_text().splitlines(), lineterm=""))  # from the stored content


@pytest.fixture
def run_folder_factory(tmp_path: Path):
    def make(name: str = "run-r", serial: str = "SN-7") -> Path:
        return run_of(tmp_path / name, serial)
    return make


def test_reissue_rules(lab_url: str) -> None:
    with open_repository(lab_url) as repo:
        repo.record_shot(made_up_record(campaign="run-1"))
        first = issue_for(repo, "run-1")
        with pytest.raises(LabError, match=f"certificate {first.number} is valid; a re-issue names it"):
            issue_for(repo, "run-1")  # a second valid certificate for one campaign
        second = issue_for(repo, "run-1", replaces=first.number)
        with pytest.raises(LabError, match=f"already withdrawn \\(replaced by {second.number}\\)"):
            issue_for(repo, "run-1", replaces=first.number)  # two replacing the same one
        specimen = issue_for(repo, "run-1", specimen=True)
        assert "-SIM-" in specimen.number
        with pytest.raises(LabError, match="is replaced only by a certificate, never by a specimen"):
            issue_for(repo, "run-1", specimen=True, replaces=second.number)
        with pytest.raises(LabError, match="is replaced only by a specimen, never by a certificate"):
            issue_for(repo, "run-1", replaces=specimen.number)
        valid = [c["number"] for c in repo.certificates("SN-7") if not c["withdrawn_by"]]
        assert valid == [second.number, specimen.number]
        # the database itself refuses a second successor and a second first issue
        for statement in (f"INSERT INTO certificates (number, prefix, year, sequence, replaces, sensor_id, campaign_id, "
                          f"specimen, revision, subject, customer, authorised_by, issued_utc, decision_rule, "
                          f"conformity, content_json, content_sha256) SELECT 'X-1', prefix, year, 99, '{first.number}', "
                          f"sensor_id, campaign_id, specimen, 7, subject, '', 'Q', issued_utc, '', '', '{{}}', '' "
                          f"FROM certificates WHERE number = '{first.number}'",):
            with pytest.raises(sa.exc.IntegrityError), repo.engine.begin() as connection:
                connection.execute(sa.text(statement))


def test_every_table_refuses_update_and_delete(lab_url: str) -> None:
    with open_repository(lab_url) as repo:
        repo.record_shot(made_up_record(campaign="run-1"))
        repo.register_sensor("SN-7", "Q", owner="ACME")
        for table in ("shots", "analyses", "sensors", "sensor_data", "campaigns", "rigs", "reference_items"):
            for statement in (f"UPDATE {table} SET id = id", f"DELETE FROM {table}"):
                with pytest.raises(sa.exc.DBAPIError, match="append-only"), repo.engine.begin() as connection:
                    connection.execute(sa.text(statement))
        if repo.engine.dialect.name == "postgresql":
            with pytest.raises(sa.exc.DBAPIError, match="append-only"), repo.engine.begin() as connection:
                connection.execute(sa.text("TRUNCATE audit CASCADE"))
        assert repo.sensor("sn-7 ").owner == "ACME"  # the newest sensor_data row, by a normalised serial


def test_one_verification_serves_report_analyse_and_import(tmp_path: Path, url: str, lab_config: Path,
                                                           capsys: pytest.CaptureFixture[str]) -> None:
    edited = tmp_path / "edited.h5"
    write_made_up_shot(edited, serial="SN-V")
    with h5py.File(edited, "r+") as f:  # rewritten whole with h5py: HDF5's checksums are valid again
        codes = f["raw/response"][...]
        codes[7] += 3
        f["raw/response"][...] = codes
    assert verify_shot(edited) == [RAW_MISMATCH]
    from hopkinson.rig.shotfile import ShotFileError
    from hopkinson.rig.shotfile_integrity import require_sound

    with pytest.raises(ShotFileError, match="tampered"):
        require_sound(edited)  # what `report` and `analyse` call
    damaged = tmp_path / "damaged.h5"
    write_made_up_shot(damaged, serial="SN-V")
    with h5py.File(damaged, "r") as f:
        offset = f["entry/signals/response"].id.get_chunk_info(0).byte_offset
    data = bytearray(damaged.read_bytes())
    data[offset + 10] ^= 0xFF
    damaged.write_bytes(bytes(data))
    code, _out, err = lab(capsys, url, "import", str(edited), str(damaged), "--config", str(lab_config))
    assert code == 2 and err.count("hopkinson: error:") == 2
    assert "/entry/signals/response fails its checksum" in err and RAW_MISMATCH in err
    # the record keeps the raw SHA-256 of the first import: a file whose attribute was rewritten too is caught
    good = tmp_path / "good.h5"
    write_made_up_shot(good, serial="SN-V")
    with open_repository(url):
        kept = shot_record(good).raw_sha256
        assert verify_shot(good, kept) == [] and "kept by the lab's record" in verify_shot(good, "0" * 64)[0]


def test_lab_verify_finds_a_changed_analysis_and_certificate(tmp_path: Path, url: str, lab_config: Path,
                                                             capsys: pytest.CaptureFixture[str]) -> None:
    run = run_of(tmp_path / "run-v", "SN-7")
    record_job(capsys, url, run, lab_config)
    assert lab(capsys, url, "certificate", str(run), "-o", str(tmp_path / "c.html"), "--authorised-by", "Q",
               "--config", str(lab_config))[0] == 0
    code, out, err = lab(capsys, url, "verify", "--config", str(lab_config))
    assert code == 0 and "verified: no discrepancy" in out, err
    with sqlite3.connect(tmp_path / "lab.sqlite") as db:  # the owner, dropping the triggers
        for table in ("analyses", "certificates"):
            db.execute(f"DROP TRIGGER {table}_no_update")
        db.execute("UPDATE analyses SET sensitivity = 1.5 WHERE id = 1")
        db.execute("UPDATE certificates SET content_json = replace(content_json, 'SN-7', 'SN-8')")
    code, out, _ = lab(capsys, url, "verify", "--json", "--config", str(lab_config))
    problems = json.loads(out)["problems"]
    assert code == 1 and len(problems) == 2
    assert "holds figures no analysis in the shot file has" in problems[1] or \
        "holds figures no analysis in the shot file has" in problems[0]
    assert any("does not match its SHA-256" in p for p in problems)


def test_smaller_faults(tmp_path: Path, url: str, lab_config: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, _out, err = lab(capsys, url, "status", "--config", str(lab_config))
    assert code == 2 and "no lab record there yet" in err and not (tmp_path / "lab.sqlite").exists()
    long_text = "x" * 300  # no file can be named so: never "File name too long"
    code, _out, err = lab(capsys, url, "certificate", "nothing", "-o", str(tmp_path / "c.pdf"), "--authorised-by",
                          "Q", "--customer", long_text, "--conditions", long_text, "--config", str(lab_config))
    assert code == 2 and "File name too long" not in err and "not in the lab's record" in err
    for bad, why in (("sqlite:///relative.sqlite", "absolute path"),
                     ("sqlite:////nonexistent-dir/x/lab.sqlite", "does not exist")):
        code, _out, err = lab(capsys, bad, "status", "--config", str(lab_config))
        assert code == 2 and why in err
    assert not Path("relative.sqlite").exists() and not Path("/nonexistent-dir").exists()
    with open_repository(url) as repo:
        repo.record_shot(made_up_record("SN-TYPO"))
        repo.record_shot(made_up_record(" sn-typo "))
        repo.record_shot(made_up_record(""))
        counts = repo.counts()
        assert counts["sensors"] == 1 and counts["shots"] == 3  # one sensor; the shot without a serial is kept
    code, _out, err = lab(capsys, url, "sensor", "SN-TYPOO", "--owner", "X", "--config", str(lab_config))
    assert code == 2 and "not in the lab's record (a typo?" in err
    code, _out, err = lab(capsys, url, "sensor", "", "--config", str(lab_config))
    assert code == 2
    code, out, _ = lab(capsys, url, "sensor", "sn-typo", "--config", str(lab_config))
    assert "Z  " in out and "2 calibration(s)" in out  # times carry their zone; both shots, one sensor
    with open_repository(url) as repo:
        record = made_up_record("SN-S")
        spool.spool(record, repo.where)
        spool.spool(record, repo.where)  # spooled twice: one record waits
        assert spool.waiting_records(repo.where) == 1


def test_the_pdf_draws_every_character_or_refuses(tmp_path: Path, url: str, lab_config: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    from hopkinson.reports.certificate_pages import check_drawable

    run = run_of(tmp_path / "run-cjk", "SN-7")
    record_job(capsys, url, run, lab_config)
    customer = "株式会社 テスト 🚀"
    try:
        check_drawable(customer)
        drawable = True
    except ValueError:
        drawable = False
    code, _out, err = lab(capsys, url, "certificate", str(run), "-o", str(tmp_path / "c.pdf"), "-o",
                          str(tmp_path / "c.xml"), "--authorised-by", "Q", "--customer", customer,
                          "--config", str(lab_config))
    if drawable:
        assert code == 0, err
    else:  # no box is ever printed in place of a name: refused, naming the characters, no number issued
        assert code == 2 and "U+1F680" in err and "install" in err
        assert not (tmp_path / "c.pdf").exists() and not (tmp_path / "c.xml").exists()
        with open_repository(url) as repo:
            assert repo.counts()["certificates"] == 0


def test_report_and_analyse_check_the_raw_sha256_the_lab_record_kept(
        tmp_path: Path, url: str, lab_config: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """Channels and the SHA-256 written beside them, both rewritten with h5py, pass the file's own
    checks; `report` and `analyse` still refuse the file, against the SHA-256 the lab's record
    kept from its first import (the record in force: HOPKINSON_DATABASE_URL)."""
    from hopkinson.rig.shotfile import read_shot
    from hopkinson.rig.shotfile_integrity import raw_sha256

    shot = tmp_path / "shot.h5"
    write_made_up_shot(shot, serial="SN-K")
    code, _out, _err = lab(capsys, url, "import", str(shot), "--config", str(lab_config))
    assert code == 0
    with h5py.File(shot, "r+") as f:
        codes = f["raw/response"][...]
        codes[7] += 3
        f["raw/response"][...] = codes
    with h5py.File(shot, "r+") as f:
        f.attrs["raw_sha256"] = raw_sha256(read_shot(shot).raw)  # the file now agrees with itself
    assert verify_shot(shot) == []
    monkeypatch.setenv("HOPKINSON_DATABASE_URL", url)
    assert main(["report", str(shot), "-o", str(tmp_path / "r.pdf")]) == 2
    assert "kept by the lab's record" in capsys.readouterr().err
    assert not (tmp_path / "r.pdf").exists()
    assert main(["analyse", str(shot), "--jobs", "1", "--no-uncertainty"]) != 0
    told = capsys.readouterr()
    assert "kept by the lab's record" in told.out + told.err
    assert len(read_shot(shot, load_raw=False).analyses) <= 1  # no analysis added to a changed shot
