"""Campaign journal and run folder: state rules, resume, and exactly-once firing under kill -9.

The kill tests run a real subprocess that drives the journal with a fake rig: "firing" a
shot appends its id to fires.log (fsync'd), the ground truth of what was fired. The
subprocess writes real shot files (rig.shotfile) and is SIGKILLed at every window of a
shot's life and at random times; after each death the journal is reopened (resume), an
operator decides UNKNOWN shots from the ground truth, and the run goes on. At the end:
every planned shot is accounted for, none was fired twice, and no half file exists.
"""

from __future__ import annotations

import os
import random
import signal
import sqlite3
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from hopkinson.rig.errors import ConfigError
from hopkinson.rig.journal import Journal, JournalError, ShotState
from hopkinson.rig.plan import load_plan
from hopkinson.rig.run_folder import create_run_folder, open_run_folder
from hopkinson.rig.shotfile import read_shot
from hopkinson.rig.shotfile_writer import write_raw_shot
from tests.rig.journal_fakes import meta_for, raw_for

ROOT = Path(__file__).resolve().parents[2]

PLAN = """
name = "kill"
operator = "op"
[accelerometer]
model = "M"
serial = "S"
[defaults]
projectile = 3
[[shots]]
pressure_bar = 1.0
repeats = 3
[[shots]]
pressure_bar = 2.0
repeats = 3
[[shots]]
pressure_bar = 3.0
repeats = 2
"""


@pytest.fixture()
def plan_path(tmp_path: Path) -> Path:
    path = tmp_path / "kill.toml"
    path.write_text(PLAN)
    return path


# ---------------------------------------------------------------------------- the fake runner

CHILD = textwrap.dedent(
    """
    import os, random, signal, sys, uuid
    from pathlib import Path
    import hopkinson.rig.shotfile_writer as sf
    from hopkinson.rig.journal import Journal
    from tests.rig.journal_fakes import meta_for, raw_for

    folder, die_at, die_shot = Path(sys.argv[1]), sys.argv[2], sys.argv[3]
    rng = random.Random(int(sys.argv[4]))
    abort_p = float(sys.argv[5])

    def maybe_die(step, shot_id):
        if step == die_at and shot_id == die_shot:
            os.kill(os.getpid(), signal.SIGKILL)

    real_replace = os.replace
    def replace(src, dst):
        src = str(src)
        if Path(src).name.startswith(".") and ".h5." in src and src.endswith(".tmp"):  # a shot file's
            # temporary (hopkinson.fileio): an analysis replaces the file, a raw write creates it
            step = "before_analysis_rename" if Path(dst).exists() else "before_rename"
            maybe_die(step, Path(dst).stem)
        real_replace(src, dst)
    os.replace = replace

    def fire(shot_id):
        fd = os.open(folder / "fires.log", os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
        os.write(fd, (shot_id + "\\n").encode())
        os.fsync(fd)
        os.close(fd)

    def analyse(j, shot):
        sf.add_analysis(j.run.shot_path(shot.id), {"shot": shot.id, "pressure_bar": shot.pressure_bar})
        maybe_die("after_analysis_rename", shot.id)
        j.mark(shot.id, "ANALYSED")

    print("ready", flush=True)
    with Journal.open(folder) as j:
        for shot in j.pending_analysis():
            analyse(j, shot)
        while (shot := j.next_shot()) is not None:
            first_try = j.status(shot.id).aborts == 0
            if first_try and rng.random() < abort_p:  # interlock trips before FIRING
                j.mark(shot.id, "ABORTED", reason="door open")
                continue
            uid = str(uuid.uuid4())
            j.mark(shot.id, "FIRING", uuid=uid)
            maybe_die("after_firing_mark", shot.id)
            if first_try and rng.random() < abort_p:  # e-stop before the fire command
                j.mark(shot.id, "ABORTED", reason="e-stop")
                continue
            fire(shot.id)
            maybe_die("after_fire", shot.id)
            path = j.run.shot_path(shot.id)
            sf.write_raw_shot(path, raw_for(shot.index),
                              meta_for(shot.id, uid, j.run.campaign_id, shot.pressure_bar))
            maybe_die("after_rename", shot.id)
            j.mark(shot.id, "RECORDED", file=path.name)
            maybe_die("after_recorded", shot.id)
            analyse(j, shot)
    print("done", flush=True)
    """
)


def start_child(folder: Path, die_at: str = "none", die_shot: str = "", seed: int = 0,
                abort_p: float = 0.0) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-c", CHILD, str(folder), die_at, die_shot, str(seed), str(abort_p)],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )


def run_child(folder: Path, **kwargs: object) -> int:
    proc = start_child(folder, **kwargs)  # type: ignore[arg-type]
    out, err = proc.communicate(timeout=120)
    assert proc.returncode in (0, -signal.SIGKILL), err
    return proc.returncode


def fired(folder: Path) -> list[str]:
    log = folder / "fires.log"
    return log.read_text().split() if log.exists() else []


def operator_decides(folder: Path) -> list[str]:
    """Resume, then decide every UNKNOWN shot the way an operator checking the rig would."""
    truth = set(fired(folder))
    with Journal.open(folder) as j:
        undecided = [s.id for s in j.needs_decision()]
        for shot_id in undecided:
            j.decide(shot_id, "skip" if shot_id in truth else "retry", note="checked the rig")
    return undecided


def check_invariants(folder: Path) -> dict[str, int]:
    """No planned shot lost, none fired twice, no half file; returns counts by state."""
    fires = fired(folder)
    assert len(fires) == len(set(fires)), f"a shot was fired twice: {fires}"
    run = open_run_folder(folder)
    assert run.find_leftovers() == []
    with Journal.open(folder) as j:
        assert j.resume_report == []  # nothing left to settle
        statuses = j.statuses()
        assert j.is_complete
        states = {s.shot.id: s.state for s in statuses}
        # Every fired shot ends analysed (its data kept) or skipped by the operator.
        done = {sid for sid, st in states.items() if st == ShotState.ANALYSED}
        skipped = {sid for sid, st in states.items() if st == ShotState.SKIPPED}
        assert done | skipped == set(states)
        assert set(fires) == done | skipped
        for status in statuses:
            path = run.shot_path(status.shot.id)
            events = j.events(status.shot.id)  # an unbroken chain of states
            assert events[0]["from"] == "PLANNED" and events[-1]["to"] == status.state.value
            assert all(a["to"] == b["from"] for a, b in zip(events, events[1:], strict=False))
            if status.state == ShotState.SKIPPED:
                assert not path.exists()
                continue
            shot = read_shot(path)
            assert shot.state == "analysed" and shot.results == {
                "shot": status.shot.id, "pressure_bar": status.shot.pressure_bar}
            assert shot.meta.shot_id == status.shot.id and shot.meta.uuid == status.info["uuid"]
            assert np.array_equal(shot.raw.channels["doppler"].codes,
                                  raw_for(status.shot.index).channels["doppler"][0])
    # Every file under a final name is a whole shot file of a planned shot.
    for path in run.shots_dir.iterdir():
        assert path.stem in states and read_shot(path).meta.shot_id == path.stem
    return {state.value: sum(st == state for st in states.values()) for state in ShotState}


# ---------------------------------------------------------------------------- kill -9 tests

WINDOWS = [
    # (where the process dies during shot s001-r2, state after resume, was it fired?)
    ("after_firing_mark", ShotState.UNKNOWN, False),
    ("after_fire", ShotState.UNKNOWN, True),
    ("before_rename", ShotState.UNKNOWN, True),
    ("after_rename", ShotState.RECORDED, True),
    ("after_recorded", ShotState.RECORDED, True),
    ("before_analysis_rename", ShotState.RECORDED, True),
    ("after_analysis_rename", ShotState.RECORDED, True),
]


@pytest.mark.parametrize(("die_at", "after_resume", "was_fired"), WINDOWS, ids=[w[0] for w in WINDOWS])
def test_kill_at_every_window_of_a_shot(tmp_path: Path, plan_path: Path, die_at: str,
                                        after_resume: ShotState, was_fired: bool) -> None:
    folder = create_run_folder(plan_path, tmp_path / "runs").path
    assert run_child(folder, die_at=die_at, die_shot="s001-r2") == -signal.SIGKILL
    assert fired(folder) == (["s001-r1", "s001-r2"] if was_fired else ["s001-r1"])

    with Journal.open(folder) as j:
        status = j.status("s001-r2")
        assert status.state == after_resume
        assert j.status("s001-r1").state == ShotState.ANALYSED
        assert open_run_folder(folder).find_leftovers() == []  # cleaned under the lock
        if die_at in ("before_rename", "before_analysis_rename"):
            assert any(r.get("action") == "removed leftover" for r in j.resume_report)
        if after_resume == ShotState.UNKNOWN:
            assert [s.id for s in j.needs_decision()] == ["s001-r2"]
            assert j.next_shot().id == "s001-r3"  # never handed out again automatically
        else:
            assert [s.id for s in j.pending_analysis()] == ["s001-r2"]

    # Resume without any decision: everything else is fired, the UNKNOWN shot is not.
    assert run_child(folder) == 0
    assert fired(folder).count("s001-r2") == (1 if was_fired else 0)
    with Journal.open(folder) as j:
        summary = j.summary()
        assert summary["complete"] is (after_resume != ShotState.UNKNOWN)
        assert summary["needs_decision"] == (["s001-r2"] if after_resume == ShotState.UNKNOWN else [])
    if after_resume == ShotState.UNKNOWN:
        operator_decides(folder)
        assert run_child(folder) == 0
    counts = check_invariants(folder)
    assert counts["SKIPPED"] == (1 if after_resume == ShotState.UNKNOWN and was_fired else 0)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_random_kills_keep_every_shot_exactly_once(tmp_path: Path, plan_path: Path, seed: int) -> None:
    rng = random.Random(seed)
    plan_path.write_text(PLAN.replace("repeats = 3", "repeats = 7"))  # 16 shots
    folder = create_run_folder(plan_path, tmp_path / "runs").path
    kills = 0
    for attempt in range(40):
        proc = start_child(folder, seed=seed * 1000 + attempt, abort_p=0.25)
        assert proc.stdout is not None and proc.stdout.readline().strip() == "ready"
        if attempt < 6:  # kill the first runs at random points, after 0-2 more fires (by the fire log,
            # not by the clock: a fast machine would otherwise finish the campaign before the kills)
            target = len(fired(folder)) + rng.randint(0, 2)
            deadline = time.monotonic() + 60
            while proc.poll() is None and len(fired(folder)) < target and time.monotonic() < deadline:
                time.sleep(0.002)
            time.sleep(rng.uniform(0.0, 0.02))
            proc.send_signal(signal.SIGKILL)
        out, err = proc.communicate(timeout=120)
        assert proc.returncode in (0, -signal.SIGKILL), err
        kills += proc.returncode == -signal.SIGKILL
        operator_decides(folder)
        with Journal.open(folder) as j:
            if j.is_complete:
                break
    else:
        pytest.fail("campaign did not complete")
    assert kills >= 3  # the kills really landed while the campaign ran
    counts = check_invariants(folder)
    assert counts["ANALYSED"] + counts["SKIPPED"] == len(load_plan(plan_path).shots)


# ---------------------------------------------------------------------------- state rules


def test_state_rules(tmp_path: Path, plan_path: Path) -> None:
    run = create_run_folder(plan_path, tmp_path)
    with Journal.open(run) as j:
        first = j.next_shot()
        assert first is not None and first.id == "s001-r1"
        with pytest.raises(JournalError, match=r"s001-r1: PLANNED -> RECORDED is not allowed"):
            j.mark("s001-r1", "RECORDED")
        with pytest.raises(JournalError, match="'DONE' is not a shot state"):
            j.mark("s001-r1", "DONE")
        with pytest.raises(JournalError, match="'s9' is not in the plan"):
            j.mark("s9", "FIRING")
        j.mark("s001-r1", ShotState.FIRING, uuid="u1")
        with pytest.raises(JournalError, match="cannot fire while s001-r1 is still FIRING"):
            j.mark("s001-r2", "FIRING")
        with pytest.raises(JournalError, match="s001-r1 is still FIRING"):
            j.next_shot()
        j.mark("s001-r1", "UNKNOWN", reason="no trigger")  # fired, nothing captured
        with pytest.raises(JournalError, match=r"UNKNOWN -> FIRING is not allowed \(an operator decides"):
            j.mark("s001-r1", "FIRING")
        assert j.next_shot().id == "s001-r2"
        with pytest.raises(JournalError, match="cannot retry a PLANNED shot"):
            j.decide("s001-r2", "retry")
        with pytest.raises(JournalError, match="decision 'maybe'"):
            j.decide("s001-r1", "maybe")
        j.decide("s001-r1", "retry", note="valve did not open: not fired")
        assert j.next_shot().id == "s001-r1"
        status = j.mark("s001-r1", "FIRING", uuid="u2")
        assert status.fire_count == 2 and status.info["uuid"] == "u2" and "reason" not in status.info
        j.mark("s001-r1", "RECORDED", file="s001-r1.h5")
        j.mark("s001-r1", "ANALYSIS_FAILED", error="identify: too short")
        j.mark("s001-r1", "ANALYSED")  # re-analysis
        assert [e["to"] for e in j.events("s001-r1")] == [
            "FIRING", "UNKNOWN", "PLANNED", "FIRING", "RECORDED", "ANALYSIS_FAILED", "ANALYSED"]


def test_aborted_shots_are_retried_up_to_max_aborts(tmp_path: Path, plan_path: Path) -> None:
    run = create_run_folder(plan_path, tmp_path)
    with Journal.open(run, max_aborts=2) as j:
        j.mark("s001-r1", "ABORTED", reason="door open")
        assert j.next_shot().id == "s001-r1"
        j.mark("s001-r1", "FIRING", uuid="x")
        j.mark("s001-r1", "ABORTED", reason="e-stop before fire")
        assert j.status("s001-r1").aborts == 2
        assert j.next_shot().id == "s001-r2"
        assert j.summary()["aborted_out"] == ["s001-r1"]
        j.decide("s001-r1", "skip")
        for s in load_plan(plan_path).shots[1:]:
            j.decide(s.id, "skip")
        assert j.next_shot() is None and j.is_complete
        assert j.summary()["by_state"]["SKIPPED"] == 8


def test_resume_checks_the_raw_file(tmp_path: Path, plan_path: Path) -> None:
    run = create_run_folder(plan_path, tmp_path)
    campaign = run.campaign_id
    with Journal.open(run) as j:
        for sid, uuid in (("s001-r1", "11111111-1111-1111-1111-111111111111"),
                          ("s001-r2", "22222222-2222-2222-2222-222222222222")):
            j.mark(sid, "FIRING", uuid=uuid)
            write_raw_shot(run.shot_path(sid), raw_for(0), meta_for(sid, uuid, campaign, 1.0))
            if sid == "s001-r1":
                j.mark(sid, "RECORDED")
                j.mark(sid, "ANALYSED")
        # s001-r2 stays FIRING: its file is whole and carries the uuid noted at FIRING.
    run.shot_path("s001-r1").unlink()  # someone removed an analysed shot's file
    with Journal.open(run) as j:
        assert j.status("s001-r2").state == ShotState.RECORDED
        report = {r["shot_id"]: r for r in j.resume_report}
        assert report["s001-r2"]["to"] == "RECORDED"
        assert "s001-r1.h5 is missing" in report["s001-r1"]["reason"]
        j.mark("s001-r2", "ANALYSED")
        # A FIRING shot whose file belongs to another attempt is not taken as recorded.
        j.mark("s001-r3", "FIRING", uuid="33333333-3333-3333-3333-333333333333")
        other = "44444444-4444-4444-4444-444444444444"
        write_raw_shot(run.shot_path("s001-r3"), raw_for(2), meta_for("s001-r3", other, campaign, 1.0))
        # A PLANNED shot with a stray file is never fired over it.
        write_raw_shot(run.shot_path("s002-r1"), raw_for(3), meta_for("s002-r1", other, campaign, 2.0))
    with Journal.open(run) as j:
        assert j.status("s001-r3").state == ShotState.UNKNOWN
        assert "belongs to another shot" in j.status("s001-r3").info["resume"]
        assert j.status("s002-r1").state == ShotState.UNKNOWN
        assert "never fired by the journal" in j.status("s002-r1").info["resume"]
        assert j.next_shot().id == "s002-r2"


def test_run_lock_excludes_a_second_runner(tmp_path: Path, plan_path: Path) -> None:
    run = create_run_folder(plan_path, tmp_path)
    j = Journal.open(run)
    try:
        with pytest.raises(ConfigError, match=rf"{run.path}: the run folder is in use by another process \(pid {os.getpid()}\)"):
            Journal.open(run)
    finally:
        j.close()
    Journal.open(run).close()  # released on close


def test_plan_changed_since_start_is_refused(tmp_path: Path, plan_path: Path) -> None:
    run = create_run_folder(plan_path, tmp_path)
    Journal.open(run).close()
    plan_path.write_text(PLAN.replace("pressure_bar = 3.0", "pressure_bar = 3.5"))
    with pytest.raises(JournalError, match=r"journal\.sqlite: the plan .*kill\.toml differs from the one"):
        Journal.open(run, load_plan(plan_path))
    with Journal.open(run) as j:  # the run folder's own copy still matches
        assert len(j.statuses()) == 8
    run.plan_path.write_text(PLAN.replace("repeats = 2", "repeats = 1"))  # the copy edited
    with pytest.raises(JournalError, match=r"plan\.toml differs from the one this journal was started with"):
        Journal.open(run)


def test_unusable_journal_files(tmp_path: Path, plan_path: Path) -> None:
    run = create_run_folder(plan_path, tmp_path)
    run.journal_path.write_bytes(b"this is not a database" * 100)
    with pytest.raises(JournalError, match=r"journal\.sqlite: not a readable journal"):
        Journal.open(run)
    run.journal_path.unlink()
    with sqlite3.connect(run.journal_path) as db:
        db.execute("CREATE TABLE other (x)")
    with pytest.raises(JournalError, match="not a campaign journal"):
        Journal.open(run)


def test_run_folder_layout(tmp_path: Path, plan_path: Path) -> None:
    a = create_run_folder(plan_path, tmp_path / "runs")
    b = create_run_folder(plan_path, tmp_path / "runs")
    assert a.path != b.path and a.campaign_id.startswith("kill-")
    assert a.plan_path.read_bytes() == plan_path.read_bytes()
    assert a.shots_dir.is_dir() and a.report_dir.is_dir()
    assert a.shot_path("s001-r1") == a.path / "shots" / "s001-r1.h5"
    named = create_run_folder(plan_path, tmp_path / "runs", name="first")
    assert named.path.name == "first"
    with pytest.raises(ConfigError, match="a run folder of that name exists"):
        create_run_folder(plan_path, tmp_path / "runs", name="first")
    with pytest.raises(ConfigError, match="not a campaign run folder"):
        open_run_folder(tmp_path)
    with pytest.raises(ConfigError, match="no such run folder"):
        open_run_folder(tmp_path / "nowhere")
    bad = tmp_path / "bad.toml"
    bad.write_text(PLAN.replace("repeats = 2", "repeats = 0"))
    with pytest.raises(ConfigError, match=r"shots\[3\]\.repeats"):
        create_run_folder(bad, tmp_path / "runs2")
    assert not (tmp_path / "runs2").exists() or list((tmp_path / "runs2").iterdir()) == []
    # Leftovers are found anywhere in the folder but only cleaned under its own lock.
    (a.report_dir / "report.html.tmp").write_text("half")
    assert a.find_leftovers() == [a.report_dir / "report.html.tmp"]
    other_lock = b.lock()
    try:
        with pytest.raises(ConfigError, match="only under this folder's run lock"):
            a.clean_leftovers(other_lock)
    finally:
        other_lock.release()
    with Journal.open(a) as j:
        assert j.resume_report[0]["action"] == "removed leftover"
    assert a.find_leftovers() == []
