"""Every warning of the lab's record reaches the user exactly once per event (issue 41: "each
warning prints twice"): the real commands run (`shot --sim`, `campaign run --sim`, `lab …`)
with the record away, refusing the rig, refusing a record, or nowhere to keep it, and every
warning and error line they print, on stdout and stderr together, is counted."""

from __future__ import annotations

import contextlib
import json
import re
import uuid
from collections import Counter
from pathlib import Path

import pytest

from hopkinson.lab import spool
from hopkinson.rig.cli.main import main
from tests.lab.pg_cluster import new_postgres_database
from tests.lab.records import write_made_up_shot
from tests.lab.test_lab_cli import LAB_SECTION, REPO

AWAY = "postgresql://nobody@127.0.0.1:9/lab"  # port 9 (discard): nothing listens on loopback
TOLD = re.compile(r"\b(warning|error): (.*)$")


def told(text: str) -> Counter[str]:
    """Each warning or error a command printed, by what it says (an event line's time, state and
    shot are left out, so the same message as an event line and as a closing line counts twice)."""
    return Counter(f"{m.group(1)}: {m.group(2)}" for m in map(TOLD.search, text.splitlines()) if m)


def assert_each_once(text: str) -> Counter[str]:
    counts = told(text)
    assert counts and all(n == 1 for n in counts.values()), "\n".join(f"{n}× {k}" for k, n in counts.items() if n > 1)
    return counts


@pytest.fixture
def fast_sim(tmp_path: Path) -> Path:
    path = tmp_path / "sim-fast.toml"
    path.write_text("[world]\ntime_scale = 100.0\n")
    return path


def shot(capsys: pytest.CaptureFixture[str], tmp_path: Path, fast_sim: Path, *extra: str) -> tuple[int, str, str]:
    code = main(["shot", "--sim", "--sim-config", str(fast_sim), "--yes", "--no-uncertainty", "--pressure-bar", "1.0",
                 "--accelerometer-serial", "SN-W", "--out", str(tmp_path / "shots"), *extra])
    out, err = capsys.readouterr()
    return code, out, err


def lab_warnings(counts: Counter[str]) -> list[str]:
    return [k for k in counts if k.startswith("warning: lab record")]


@pytest.mark.parametrize("json_out", [False, True], ids=["event lines", "--json"])
def test_a_shot_with_the_database_away_warns_once(json_out: bool, tmp_path: Path, fast_sim: Path,
                                                  monkeypatch: pytest.MonkeyPatch,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setenv("HOPKINSON_DATABASE_URL", AWAY)
    code, out, err = shot(capsys, tmp_path, fast_sim, *(("--json",) if json_out else ()))
    assert code == 0, err
    counts = assert_each_once(out + err)
    (warning,) = lab_warnings(counts)  # raw and analysed records both spooled: one event for the operator
    assert "not recorded now" in warning and str(spool.spool_path()) in warning
    if json_out:  # stdout is one JSON object; the warning is on stderr (it was told nowhere before)
        assert json.loads(out)["exit_code"] == 0 and f"hopkinson: {warning}" in err.splitlines()
    assert spool.waiting_records() == 2  # the raw record and its analysis, each kept


def test_a_shot_against_a_database_that_refuses_the_rig_warns_once(
        tmp_path: Path, fast_sim: Path, postgres_server: str, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """PostgreSQL with a role that may read but not write (a grant forgotten): not an outage."""
    import psycopg

    url = new_postgres_database(postgres_server)
    assert main(["lab", "upgrade", "--database", url, "--config", str(REPO / "config" / "rig-sim.toml")]) == 0
    role = f"reader_{uuid.uuid4().hex[:8]}"
    with contextlib.closing(psycopg.connect(url, autocommit=True)) as db:
        db.execute(f"CREATE ROLE {role} LOGIN")
        db.execute(f"GRANT SELECT ON ALL TABLES IN SCHEMA public TO {role}")
    capsys.readouterr()
    monkeypatch.setenv("HOPKINSON_DATABASE_URL", url.replace("hopkinson@", f"{role}@"))
    code, out, err = shot(capsys, tmp_path, fast_sim)
    assert code == 0, err
    (warning,) = lab_warnings(assert_each_once(out + err))
    assert "refused this rig" in warning and "permission denied" in warning and "not an outage" in warning


def test_a_refused_record_warns_once(tmp_path: Path, fast_sim: Path, monkeypatch: pytest.MonkeyPatch,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setenv("HOPKINSON_DATABASE_URL", f"sqlite:///{tmp_path / 'lab.sqlite'}")
    code, out, err = shot(capsys, tmp_path, fast_sim, "--operator", "x" * 300)
    assert code == 0, err
    (warning,) = lab_warnings(assert_each_once(out + err))
    assert "operator is 300 characters long" in warning and "set aside" in warning
    assert len(spool.quarantined()) == 2  # both records set aside, each with its reason


def test_a_record_kept_nowhere_is_told_once_and_exits_5(tmp_path: Path, fast_sim: Path,
                                                        monkeypatch: pytest.MonkeyPatch,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    blocked = tmp_path / "not-a-folder"
    blocked.write_text("")  # the data folder's place holds a file: neither spool nor quarantine can be written
    monkeypatch.setenv("XDG_DATA_HOME", str(blocked))
    monkeypatch.setenv("HOPKINSON_DATABASE_URL", AWAY)
    code, out, err = shot(capsys, tmp_path, fast_sim)
    assert code == 5
    counts = assert_each_once(out + err)
    (warning,) = lab_warnings(counts)
    assert "not queued either" in warning
    (error,) = [k for k in counts if "neither the database nor the spool" in k]
    assert error.startswith("error: the lab record of ") and "hopkinson lab import" in error


@pytest.mark.parametrize("json_out", [False, True], ids=["progress lines", "--json"])
def test_a_campaign_with_the_database_away_warns_once_per_shot(json_out: bool, tmp_path: Path, fast_sim: Path,
                                                               monkeypatch: pytest.MonkeyPatch,
                                                               capsys: pytest.CaptureFixture[str]) -> None:
    """Each shot's records (raw, analysed, and the campaign's catch-up at its end) are one warning."""
    plan = tmp_path / "plan.toml"
    plan.write_text('name = "w"\noperator = "demo"\nauthorise_firing = true\n[accelerometer]\nmodel = "M"\n'
                    'serial = "SN-W"\n[defaults]\nprojectile = 3\n[defaults.analysis]\nmax_order = 6\n'
                    'uncertainty = false\n[[shots]]\npressure_bar = 1.5\nrepeats = 2\n')
    monkeypatch.setenv("HOPKINSON_DATABASE_URL", AWAY)
    code = main(["campaign", "run", str(plan), "--sim", "--sim-config", str(fast_sim), "--out", str(tmp_path / "run"),
                 "--no-report", *(("--json",) if json_out else ())])
    out, err = capsys.readouterr()
    assert code == 0, err
    warnings = lab_warnings(assert_each_once(out + err))
    assert sorted(w.split(": ")[2] for w in warnings) == ["s001-r1.h5", "s001-r2.h5"]


def test_the_lab_commands_say_each_thing_once(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`lab import` (a spool to drain, a tampered file), `lab sensor` (drift, tolerance),
    `lab verify` (a changed certificate), `lab certificate` (refused): each line once."""
    import sqlite3

    import h5py

    config = tmp_path / "rig.toml"
    config.write_text((REPO / "config" / "rig-sim.toml").read_text() + LAB_SECTION)
    url = f"sqlite:///{tmp_path / 'lab.sqlite'}"

    def lab(*args: str) -> str:
        main(["lab", args[0], "--database", url, "--config", str(config), *args[1:]])
        out, err = capsys.readouterr()
        return out + err

    runs = []
    for name, sensitivity in (("run-a", 1.000), ("run-b", 1.050)):
        run = tmp_path / name
        (run / "shots").mkdir(parents=True)
        for i in range(2):
            write_made_up_shot(run / "shots" / f"s{i}.h5", serial="SN-D", campaign=name, sensitivity=sensitivity,
                               u=0.002, utc=f"2026-0{3 + len(runs)}-0{1 + i}T10:00:00Z")
        runs.append(run)
    with h5py.File(runs[1] / "shots" / "s1.h5", "r+") as f:  # tampered: refused on import
        codes = f["raw/response"][...]
        codes[3] += 1
        f["raw/response"][...] = codes
    text = lab("import", str(runs[0]), str(runs[1]))
    counts = assert_each_once(text)
    assert [k for k in counts if k.startswith("error:") and "tampered" in k]
    text = lab("sensor", "SN-D", "--tolerance-percent", "1")
    assert "DRIFTED" in text and "out of tolerance" in text
    lines = [line for line in text.splitlines() if line.strip()]
    assert len(lines) == len(set(lines)), text
    lab("job", str(runs[0]), "--received", "2026-02-20", "--condition", "as new", "--location", "lab")
    assert "certificate" in lab("certificate", str(runs[0]), "-o", str(tmp_path / "c.html"), "--authorised-by", "Q")
    assert_each_once(lab("certificate", str(runs[0]), "-o", str(tmp_path / "d.html"), "--authorised-by", "Q"))
    with sqlite3.connect(tmp_path / "lab.sqlite") as db:  # the owner, dropping a trigger, changes a certificate
        db.execute("DROP TRIGGER certificates_no_update")
        db.execute("UPDATE certificates SET content_json = replace(content_json, 'SN-D', 'SN-E')")
    text = lab("verify")
    problems = [line for line in text.splitlines() if line.startswith("PROBLEM: ")]
    assert len(problems) == len(set(problems)) == 1, text


@pytest.mark.parametrize("json_out", [False, True], ids=["event lines", "--json"])
def test_a_shot_s_own_warning_is_told_once(json_out: bool, tmp_path: Path, fast_sim: Path,
                                           monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """The sequencer's warnings follow the same rule as the record's: an event line, or (no event
    lines) one closing line on stderr; never both. Here the reservoir reads 1 bar at CHECK."""
    import hopkinson.rig.sequencer.steps as steps

    gauge = steps._gauge_bar
    reads = []

    def charged_at_first(valves):  # noqa: ANN001, ANN202
        reads.append(1)
        return 1.0 if len(reads) == 1 else gauge(valves)

    monkeypatch.setattr(steps, "_gauge_bar", charged_at_first)
    monkeypatch.setenv("HOPKINSON_DATABASE_URL", f"sqlite:///{tmp_path / 'lab.sqlite'}")
    code, out, err = shot(capsys, tmp_path, fast_sim, *(("--json",) if json_out else ()))
    assert code == 0, err
    counts = assert_each_once(out + err)
    (warning,) = [k for k in counts if "venting it first" in k]
    assert (f"hopkinson: {warning}" in err.splitlines()) is json_out
