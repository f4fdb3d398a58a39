"""The repository layer on SQLite and on a real PostgreSQL server: idempotent shot records,
tamper refusal, the append-only audit trail and certificates, unique certificate numbers,
the schema's version, and many writers at once."""

from __future__ import annotations

import json
import threading

import pytest
import sqlalchemy as sa

from hopkinson.lab.database import head_revision, make_engine
from hopkinson.lab.errors import LabError, TamperedShotError
from hopkinson.lab.issuing import issue
from hopkinson.lab.repository import LabRepository, open_repository
from tests.lab.records import made_up_record


def issue_for(repo: LabRepository, campaign: str, content: dict | None = None, *, replaces: str = "",
              specimen: bool = False, authorised_by: str = "Q", prefix: str = "HB"):
    """A certificate of `campaign` with fixed content (the record's rules, not the document)."""
    return issue(repo, campaign=campaign, prefix=prefix, authorised_by=authorised_by, specimen=specimen,
                 replaces=replaces, content=lambda _uow, _campaign: dict(content or {}))


@pytest.fixture
def repo(lab_url: str):
    with open_repository(lab_url) as repository:
        yield repository


def test_first_use_creates_the_schema_and_a_shot_is_recorded_once(repo: LabRepository) -> None:
    record = made_up_record(sensitivity=1.004, u=0.003)
    assert repo.record_shot(record) == "new"
    assert repo.record_shot(record) == "known"  # idempotent: the UUID and the raw SHA-256 are the key
    reanalysed = made_up_record(uid=record.uuid, sensitivity=1.001, u=0.003, analysis="b")
    assert repo.record_shot(reanalysed) == "analysis added"  # the file's SHA-256 names the analysis
    assert repo.counts()["shots"] == 1 and repo.counts()["analyses"] == 2
    (calibration,) = repo.shot_results("SN-7")  # the newest analysis of the one shot
    assert calibration.figures["sensitivity"].value == pytest.approx(1.001)
    assert calibration.figures["sensitivity"].expanded == pytest.approx(0.006)
    assert calibration.figures["fbsd_10_hz"] is None
    assert calibration.rig == "HB-1" and calibration.operator == "tech A"
    assert repo.reference_chain("HB-1") == [{"item": "interferometer", "certificate": "PTB-1234",
                                             "issued_by": "PTB", "u_rel": 5e-4, "due": "2027-06-30"}]
    actions = [a["action"] for a in repo.audit_trail(record.uuid)]
    assert actions == ["result recorded", "result recorded", "shot fired"]


def test_a_known_uuid_with_other_raw_data_is_refused(repo: LabRepository) -> None:
    record = made_up_record(raw=b"the codes as fired")
    repo.record_shot(record)
    with pytest.raises(TamperedShotError, match=f"{record.uuid}: tampered or damaged; refused"):
        repo.record_shot(made_up_record(uid=record.uuid, raw=b"the codes changed", analysis="b"))
    assert repo.counts()["analyses"] == 1


def test_audit_trail_and_certificates_cannot_be_changed_in_the_database(repo: LabRepository) -> None:
    repo.record_shot(made_up_record(campaign="run-1"))
    issue_for(repo, "run-1", {"customer": "ACME"}, authorised_by="Q. Manager")
    for statement in ("UPDATE audit SET actor = 'someone else'", "DELETE FROM audit",
                      "UPDATE certificates SET customer = 'other'", "DELETE FROM certificates"):
        with pytest.raises(sa.exc.DBAPIError, match="append-only"), repo.engine.begin() as connection:
            connection.execute(sa.text(statement))
    assert repo.audit_trail()[0]["actor"] == "Q. Manager"
    assert not any(name.startswith(("update", "delete")) for name in dir(repo))  # no such path in the layer


def test_certificate_numbers_are_sequential_and_a_reissue_names_the_one_it_replaces(repo: LabRepository) -> None:
    repo.record_shot(made_up_record(campaign="run-1"))
    first = issue_for(repo, "run-1", {"x": 1})
    second = issue_for(repo, "run-1", {"x": 2}, replaces=first.number)
    year = first.issued_utc[:4]
    assert (first.number, second.number) == (f"HB-{year}-0001", f"HB-{year}-0002")
    assert repo.certificate(first.number).content == {"x": 1, "number": first.number, "issued_utc": first.issued_utc,
                                                      "replaces": ""}  # unchanged
    assert repo.certificate(first.number).withdrawn_by == second.number
    assert repo.certificate(second.number).replaces == first.number
    assert [a["action"] for a in repo.audit_trail()[:2]] == ["certificate replaced", "certificate issued"]
    with pytest.raises(LabError, match="HB-1999-0001: not in the record"):
        issue_for(repo, "run-1", replaces="HB-1999-0001")
    with pytest.raises(LabError, match="authorises"):
        issue_for(repo, "run-1", authorised_by=" ")


def test_a_newer_schema_is_refused_naming_both_versions(lab_url: str) -> None:
    open_repository(lab_url).close()
    engine = make_engine(lab_url)
    with engine.begin() as connection:
        connection.execute(sa.text("UPDATE alembic_version SET version_num = '9999'"))
    engine.dispose()
    with pytest.raises(LabError, match=f"schema version 9999 is newer than this software's \\({head_revision()}\\)"):
        open_repository(lab_url)


def test_a_foreign_database_is_not_touched(lab_url: str) -> None:
    engine = make_engine(lab_url)
    with engine.begin() as connection:
        connection.execute(sa.text("CREATE TABLE someone_elses (x INTEGER)"))
    engine.dispose()
    with pytest.raises(LabError, match="holds tables but no hopkinson schema version; not touched"):
        open_repository(lab_url)


def test_many_writers_at_once_lose_nothing(lab_url: str) -> None:
    """Three rigs store shots of the same new sensors while two desks issue certificates, each
    with its own connection: every shot is recorded once, every certificate number is unique."""
    open_repository(lab_url).close()
    shots_per_rig, certificates_per_desk = 12, 6
    errors: list[BaseException] = []
    numbers: list[str] = []
    barrier = threading.Barrier(5)

    def rig(n: int) -> None:
        with LabRepository(lab_url) as repo:
            barrier.wait()
            for i in range(shots_per_rig):
                repo.record_shot(made_up_record(serial=f"SN-{i % 3}", rig=f"rig-{n}", campaign=f"run-{i % 3}"))

    def desk() -> None:
        with LabRepository(lab_url) as repo:
            repo.record_shot(made_up_record(serial="SN-0", campaign="run-0"))
            barrier.wait()
            for _ in range(certificates_per_desk):  # each re-issues the valid one (one valid per campaign)
                while True:
                    valid = [c for c in repo.certificates("SN-0") if not c["withdrawn_by"]]
                    try:
                        numbers.append(issue_for(repo, "run-0", replaces=valid[0]["number"] if valid else "").number)
                        break
                    except LabError as exc:  # the other desk re-issued it first: replace the new one
                        assert "is valid" in str(exc) or "already withdrawn" in str(exc), exc

    def guarded(target, *args) -> None:
        try:
            target(*args)
        except BaseException as exc:  # noqa: BLE001 (reported below)
            errors.append(exc)

    threads = [threading.Thread(target=guarded, args=(rig, n)) for n in range(3)]
    threads += [threading.Thread(target=guarded, args=(desk,)) for _ in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(120)
    assert not errors, errors
    with open_repository(lab_url) as repo:
        counts = repo.counts()
        assert counts["shots"] == 3 * shots_per_rig + 2
        assert counts["sensors"] == 3 and counts["rigs"] == 4 and counts["campaigns"] == 3
        assert counts["certificates"] == 2 * certificates_per_desk == len(set(numbers))
        sequences = sorted(int(n.rsplit("-", 1)[1]) for n in numbers)
        assert sequences == list(range(1, 2 * certificates_per_desk + 1))
        assert counts["audit"] == 2 * counts["shots"] + counts["certificates"]  # shot fired + result, each
        assert all(json.loads(json.dumps(a)) for a in repo.audit_trail(limit=5))
