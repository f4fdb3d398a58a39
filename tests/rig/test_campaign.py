"""The campaign runner on the in-process simulated rig: every planned shot fired once and
journaled, an aborted shot stops the campaign and a resume finishes it, a shot fired without a
record waits for an operator, a recorded shot is analysed on resume without being fired again,
and `hopkinson campaign run` (authorisation, progress lines, bad input).

The simulated world logs every launch (rig.sim_fire_log.attach_fire_log): that log, not the
journal, is the witness of how often each shot was fired.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import re
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from hopkinson.rig.campaign import CampaignRunner
from hopkinson.rig.campaign_setup import shot_request
from hopkinson.rig.cli.campaign import ProgressPrinter
from hopkinson.rig.cli.main import main
from hopkinson.rig.events import (
    CampaignShotStarted,
    EventBus,
    Reading,
    RigError,
    RigEvent,
    StateEntered,
    StepProgress,
)
from hopkinson.rig.instruments import open_instruments
from hopkinson.rig.journal import Journal, ShotState
from hopkinson.rig.plan import load_plan
from hopkinson.rig.run_folder import create_run_folder
from hopkinson.rig.sequencer import FireAuthorisation, Sequencer
from hopkinson.rig.shotfile import read_shot
from hopkinson.rig.sim_fire_log import FireLog, attach_fire_log, read_fire_log
from hopkinson.rig.sim_session import SimSession, sim_session
from tests.rig.conftest import fast_sim_config, short_timeouts_config

S = ShotState
TIME = r"\d\d:\d\d:\d\d\.\d\d\d "  # every progress line starts with its UTC time

PLAN = """
name = "camp"
operator = "tester"
authorise_firing = {authorise}
[accelerometer]
model = "SIM-ACC"
serial = "T1"
[defaults]
projectile = 3
[defaults.analysis]
max_order = 6
uncertainty = false  # not what these tests are about (analysis.uncertainty has its own)
{entries}
"""
TWO_LEVELS = "[[shots]]\npressure_bar = 1.2\nrepeats = 2\n[[shots]]\npressure_bar = 2.0\n[shots.analysis]\norder = 2\n"


def write_plan(folder: Path, entries: str = TWO_LEVELS, authorise: bool = True, name: str = "plan.toml") -> Path:
    path = folder / name
    path.write_text(PLAN.format(authorise=str(authorise).lower(), entries=entries), encoding="utf-8")
    return path


class Rig:
    """A running simulated rig with its instruments and a fire log."""

    def __init__(self, session: SimSession, instruments, fire_log: FireLog) -> None:
        self.session = session
        self.instruments = instruments
        self.config = session.config
        self.fire_log = fire_log

    def fired(self) -> list[str]:
        return [e["shot_id"] for e in read_fire_log(self.fire_log.path)]

    def runner(self, run, plan, bus: EventBus | None = None, on_shot_start=None) -> CampaignRunner:
        def started(shot) -> None:
            self.fire_log.set_shot(shot)
            if on_shot_start is not None:
                on_shot_start(shot)

        return CampaignRunner(run, plan, self.instruments, self.config, bus or EventBus(), on_shot_start=started)


@pytest.fixture
def rig(tmp_path: Path) -> Iterator[Rig]:
    with contextlib.ExitStack() as stack:
        session = stack.enter_context(sim_session(short_timeouts_config(), fast_sim_config()))
        instruments = stack.enter_context(open_instruments(session.config, session.simulated_truth))
        log = FireLog(tmp_path / "fire.log")
        attach_fire_log(session.world, log)
        yield Rig(session, instruments, log)


def new_run(tmp_path: Path, **plan_kw):
    plan_path = write_plan(tmp_path, **plan_kw)
    run = create_run_folder(plan_path, tmp_path / "runs", "run-1")
    return run, load_plan(plan_path)


def states(run) -> dict[str, tuple[str, int]]:
    with Journal.open(run) as journal:
        return {s.shot.id: (s.state.value, s.fire_count) for s in journal.statuses()}


def test_every_planned_shot_is_fired_once_journaled_and_analysed(tmp_path: Path, rig: Rig) -> None:
    run, plan = new_run(tmp_path)
    bus = EventBus()
    events: list[RigEvent] = []
    bus.subscribe(events.append)
    outcome = rig.runner(run, plan, bus).run()

    assert outcome.exit_code == 0 and outcome.complete, outcome.message
    assert outcome.fired_this_run == ["s001-r1", "s001-r2", "s002-r1"]
    assert rig.fired() == ["s001-r1", "s001-r2", "s002-r1"] and rig.session.world.shots_fired == 3
    assert states(run) == {sid: ("ANALYSED", 1) for sid in ("s001-r1", "s001-r2", "s002-r1")}
    with Journal.open(run) as journal:
        for sid in ("s001-r1", "s001-r2", "s002-r1"):
            hist = journal.events(sid)
            assert [(e["from"], e["to"]) for e in hist] == [("PLANNED", "FIRING"), ("FIRING", "RECORDED"),
                                                           ("RECORDED", "ANALYSED")]
            # Rule 1: FIRING was on disk before the projectile left (same clock, the world's log).
            launch = next(e for e in read_fire_log(rig.fire_log.path) if e["shot_id"] == sid)
            assert hist[0]["utc"] < launch["utc"]
            shot = read_shot(run.shot_path(sid), load_raw=False)
            assert (shot.meta.shot_id, shot.meta.campaign_id, shot.state) == (sid, "run-1", "analysed")
            assert hist[1]["info"]["uuid"] == shot.meta.uuid
    # The plan's fixed order reached the analysis of s002-r1; the others chose theirs.
    fixed = read_shot(run.shot_path("s002-r1"), load_raw=False).results["identification"]
    assert (fixed["order"], fixed["order_selection"]) == (2, "asked")
    knee = read_shot(run.shot_path("s001-r1"), load_raw=False).results["identification"]
    assert knee["order_selection"] == "order_test"  # "knee" before issue 18: the order test chose it
    # The identified main resonance is the simulated truth's (the shot file holds both).
    shot = read_shot(run.shot_path("s001-r1"), load_raw=False)
    truth = shot.meta.simulated_truth["accelerometer"]["modes"][0]
    pairs = [m for m in shot.results["identification"]["modes"] if m["kind"] in ("complex", "pair")]
    fn = min(pairs, key=lambda m: m["natural_frequency_hz"])["natural_frequency_hz"]
    assert fn == pytest.approx(truth["natural_frequency_hz"], rel=0.01)
    starts = [e for e in events if isinstance(e, CampaignShotStarted)]
    assert [(e.index, e.total, e.shot_id) for e in starts] == [
        (1, 3, "s001-r1"), (2, 3, "s001-r2"), (3, 3, "s002-r1")]


def test_an_aborted_shot_stops_the_campaign_and_a_resume_finishes_it(tmp_path: Path, rig: Rig) -> None:
    run, plan = new_run(tmp_path)
    faults = rig.session.rig.faults

    def door_opens_before_the_second_shot(shot) -> None:
        if shot is not None and shot.id == "s001-r2":
            faults.inject("door-open")

    outcome = rig.runner(run, plan, on_shot_start=door_opens_before_the_second_shot).run()
    assert outcome.exit_code == 3 and not outcome.complete
    assert "s001-r2" in outcome.message and f"--resume --out {run.path}" in outcome.message
    assert outcome.last_shot is not None and not outcome.last_shot.fired
    assert rig.fired() == ["s001-r1"]  # s002-r1 was not fired after the abort
    st = states(run)
    assert st["s001-r2"] == ("ABORTED", 0) and st["s002-r1"] == ("PLANNED", 0)

    faults.clear()
    outcome = rig.runner(run, plan).run()
    assert outcome.exit_code == 0 and outcome.complete
    assert rig.fired() == ["s001-r1", "s001-r2", "s002-r1"]
    assert {sid: s for sid, (s, _) in states(run).items()} == dict.fromkeys(("s001-r1", "s001-r2", "s002-r1"),
                                                                            "ANALYSED")


def test_a_shot_fired_without_a_record_waits_for_an_operator(tmp_path: Path, rig: Rig) -> None:
    run, plan = new_run(tmp_path, entries="[[shots]]\npressure_bar = 1.2\nrepeats = 2\n")
    faults = rig.session.rig.faults
    faults.inject("no-trigger")  # the projectile flies, the digitizer never triggers
    # CAPTURE waits for a trigger that never comes until its timeout: 0.5 s, not the fixture's 3 s,
    # for this run only (the shots that follow capture records under the fixture's timeouts)
    configured = rig.config
    rig.config = dataclasses.replace(configured, timeouts=dataclasses.replace(configured.timeouts, capture_s=0.5))
    outcome = rig.runner(run, plan).run()
    rig.config = configured
    assert outcome.exit_code == 3 and outcome.last_shot.fired and outcome.last_shot.shot_path is None
    assert "timed out after 0.5 s" in outcome.message  # (the shortened timeout is the one that ended it)
    assert "hopkinson campaign decide" in outcome.message and "s001-r1" in outcome.message
    assert rig.fired() == ["s001-r1"] and states(run)["s001-r1"] == ("UNKNOWN", 1)

    faults.clear()
    outcome = rig.runner(run, plan).run()  # goes on with the rest, never re-fires the doubtful shot
    assert outcome.exit_code == 3 and outcome.summary["needs_decision"] == ["s001-r1"]
    assert rig.fired() == ["s001-r1", "s001-r2"]

    assert main(["campaign", "decide", str(run.path), "s001-r1", "retry", "--note", "no data: fire again"]) == 0
    outcome = rig.runner(run, plan).run()
    assert outcome.exit_code == 0 and outcome.complete
    # Fired twice in all, by the operator's decision; the journal counts what the world saw.
    assert rig.fired().count("s001-r1") == 2 and states(run)["s001-r1"] == ("ANALYSED", 2)


def test_a_recorded_shot_is_analysed_on_resume_not_fired_again(tmp_path: Path, rig: Rig) -> None:
    run, plan = new_run(tmp_path, entries="[[shots]]\npressure_bar = 1.2\nrepeats = 2\n")
    shot = plan.shots[0]
    # A previous process marked FIRING, fired and stored the raw file, then died before RECORDED.
    with Journal.open(run, plan) as journal:
        journal.mark(shot.id, S.FIRING)

    def no_analysis(raw, params):
        raise RuntimeError("died here")

    rig.fire_log.set_shot(shot)
    sequencer = Sequencer(rig.instruments, rig.config, EventBus(), analyse=no_analysis)
    first = sequencer.run_shot(shot_request(plan, shot, run), FireAuthorisation.pre_given())
    assert first.shot_path == run.shot_path(shot.id) and first.analysis_error
    assert rig.fired() == ["s001-r1"]

    outcome = rig.runner(run, plan).run()
    assert outcome.exit_code == 0 and outcome.complete
    assert any(r.get("shot_id") == "s001-r1" and r.get("to") == "RECORDED" for r in outcome.resume_report)
    assert rig.fired() == ["s001-r1", "s001-r2"]  # s001-r1 analysed from its file, not fired again
    assert outcome.fired_this_run == ["s001-r2"]
    stored = read_shot(run.shot_path("s001-r1"), load_raw=False)
    assert stored.state == "analysed" and stored.record is not None
    assert states(run)["s001-r1"] == ("ANALYSED", 1)


def test_a_shot_is_not_fired_when_firing_cannot_be_journaled(tmp_path: Path, rig: Rig, monkeypatch) -> None:
    run, plan = new_run(tmp_path, entries="[[shots]]\npressure_bar = 1.2\n")
    original = Journal.mark

    def disk_full_at_firing(self, shot_id, state, **info):
        if state == S.FIRING:
            raise OSError("disk full")
        return original(self, shot_id, state, **info)

    monkeypatch.setattr(Journal, "mark", disk_full_at_firing)
    outcome = rig.runner(run, plan).run()
    monkeypatch.undo()
    assert outcome.exit_code == 3 and not outcome.last_shot.fired
    assert "FIRING of s001-r1 could not be recorded (disk full)" in outcome.message
    assert rig.fired() == [] and rig.session.world.shots_fired == 0  # the valve never opened
    assert states(run)["s001-r1"] == ("ABORTED", 0)


# ------------------------------------------------------------------ the command line


@pytest.fixture
def sim_files(tmp_path: Path) -> dict[str, Path]:
    fast = tmp_path / "sim-fast.toml"
    fast.write_text("[world]\ntime_scale = 100.0\n", encoding="utf-8")
    return {"sim": fast, "log": tmp_path / "fire.log"}


def cli_args(plan: Path, out: Path, sim_files: dict[str, Path], *extra: str) -> list[str]:
    return ["campaign", "run", str(plan), "--sim", "--sim-config", str(sim_files["sim"]), "--out", str(out),
            "--sim-fire-log", str(sim_files["log"]), *extra]


def one_error_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("hopkinson: error: ") and "Traceback" not in err[0]
    return err[0]


def test_cli_refuses_to_fire_without_authorisation(tmp_path: Path, sim_files, capsys) -> None:
    plan = write_plan(tmp_path, authorise=False)
    out = tmp_path / "run"
    assert main(cli_args(plan, out, sim_files)) == 2
    line = one_error_line(capsys)
    assert "not authorised" in line and "--yes" in line and "authorise_firing" in line
    assert not out.exists() and not sim_files["log"].exists()  # nothing created, nothing fired


def test_cli_runs_a_campaign_with_progress_lines(tmp_path: Path, sim_files, capsys) -> None:
    plan = write_plan(tmp_path, authorise=False, entries="[[shots]]\npressure_bar = 1.5\nrepeats = 2\n")
    out = tmp_path / "run"
    assert main(cli_args(plan, out, sim_files, "--yes", "--no-report")) == 0
    captured = capsys.readouterr()
    lines = captured.err.splitlines()
    for pattern in (r"\[1/2\] s001-r1 START 1.5 bar, projectile No. 3", r"\[1/2\] s001-r1 CHARGE \d+\.\d\d bar",
                    r"\[1/2\] s001-r1 FIRE", r"\[2/2\] s001-r2 ANALYSED order \d", r"campaign: campaign complete"):
        assert any(re.match(TIME + pattern, ln) for ln in lines), pattern
    assert f"run folder: {out}" in captured.out
    assert [e["shot_id"] for e in read_fire_log(sim_files["log"])] == ["s001-r1", "s001-r2"]

    # Running it again into the same folder needs --resume; resuming a finished campaign fires nothing.
    assert main(cli_args(plan, out, sim_files, "--yes", "--no-report")) == 2
    assert "--resume" in one_error_line(capsys)
    assert main(cli_args(plan, out, sim_files, "--yes", "--no-report", "--resume")) == 0
    assert len(read_fire_log(sim_files["log"])) == 2
    assert "campaign: campaign complete: 2 of 2 shots done" in capsys.readouterr().err
    # A different plan cannot resume this run.
    other = write_plan(tmp_path, entries="[[shots]]\npressure_bar = 1.7\n", name="other.toml")
    assert main(cli_args(other, out, sim_files, "--yes", "--no-report", "--resume")) == 2
    assert "differs" in one_error_line(capsys)
    assert main(["campaign", "decide", str(out), "s001-r1", "skip"]) == 2
    assert "cannot skip a ANALYSED shot" in one_error_line(capsys)
    assert main(["campaign", "status", str(out)]) == 0
    assert "ANALYSED 2" in capsys.readouterr().out


@pytest.mark.parametrize("argv, message", [
    (["campaign", "run", "missing.toml", "--yes"], "missing.toml: no such plan file"),
    (["campaign", "run", "config/campaigns/demo.toml", "--sim-fault", "door-open"], "need --sim"),
    (["campaign", "run", "config/campaigns/demo.toml", "--report", "docx"], "--report: 'docx'"),
    (["campaign", "status", "no-such-run"], "no-such-run: no such run folder"),
])
def test_cli_bad_input_is_one_line_exit_2(argv, message, capsys) -> None:
    assert main(argv) == 2
    assert message in one_error_line(capsys)


def test_progress_lines_are_plain_text() -> None:
    import io

    class Current:
        prefix = "[3/8] s002-r1"

    class Runner:
        current = Current()

    stream = io.StringIO()
    printer = ProgressPrinter(stream)
    printer.runner = Runner()
    utc = "2025-01-01T12:00:01.250000Z"
    printer(StateEntered(state="CHARGE", message="charging the reservoir", utc=utc))
    printer(StepProgress(state="CHARGE", message="charging: 4.100 of 4.1 bar", reservoir_pressure_bar=4.1, utc=utc))
    printer(RigError(state="CHARGE", message="aborting: door open", utc=utc))
    printer(Reading(state="CHARGE", message="readings", reservoir_pressure_bar=4.0, fixture_vacuum_mbar=50.0, utc=utc))
    assert stream.getvalue().splitlines() == ["12:00:01.250 [3/8] s002-r1 CHARGE", "12:00:01.250 [3/8] s002-r1 CHARGE 4.10 bar",
                                              "12:00:01.250 [3/8] s002-r1 CHARGE ! aborting: door open"]
    assert "\r" not in stream.getvalue() and "\x1b" not in stream.getvalue()


def test_an_analysis_interrupted_by_an_abort_is_redone_on_resume(tmp_path: Path, rig: Rig) -> None:
    # issue 18: an abort (as SIGTERM/SIGINT/SIGHUP) during ANALYSE left the shot ANALYSIS_FAILED
    # and --resume skipped it. Now the journal marks it to redo, and the resume analyses it.
    run, plan = new_run(tmp_path, entries="[[shots]]\npressure_bar = 1.2\n")
    holder: list[CampaignRunner] = []

    def aborted_analysis(raw, params):
        holder[0].abort("operator: interrupted during the analysis")
        time.sleep(10.0)  # abandoned long before this ends
        raise AssertionError("the abandoned analysis was waited for")

    first = CampaignRunner(run, plan, rig.instruments, rig.config, EventBus(), analyse=aborted_analysis)
    holder.append(first)
    outcome = first.run()
    assert outcome.exit_code != 0 and not outcome.complete
    with Journal.open(run) as journal:
        status = journal.status("s001-r1")
        assert status.state == S.ANALYSIS_FAILED and status.info["redo"] is True
        pending = journal.pending_analysis()
        assert [p.id for p in pending] == ["s001-r1"], pending
    assert "--resume" in outcome.message

    resumed = rig.runner(run, plan).run()  # the real analysis
    assert resumed.exit_code == 0 and resumed.complete, resumed.message
    assert len(rig.fired()) == 1  # analysed from its file, never fired again
    assert states(run)["s001-r1"] == ("ANALYSED", 1)
    shot = read_shot(run.shot_path("s001-r1"), load_raw=False)
    assert shot.state == "analysed" and [a["status"] for a in shot.analyses] == ["failed", "ok"]


def test_a_rescued_raw_shot_is_journaled_with_where_it_is_and_a_resume_records_it(tmp_path: Path, rig: Rig) -> None:
    # The shot folder vanishes between FIRE and STORE: the raw shot is rescued into the user's
    # data folder; the journal used to say only UNKNOWN ("no raw file"), not where the record was.
    import os
    import shutil

    run, plan = new_run(tmp_path, entries="[[shots]]\npressure_bar = 1.2\n")
    bus = EventBus()
    bus.subscribe(lambda e: shutil.rmtree(run.shots_dir) if isinstance(e, StateEntered) and e.state == "SAFE"
                  and run.shots_dir.exists() else None)
    outcome = rig.runner(run, plan, bus).run()
    assert outcome.exit_code == 3 and rig.fired() == ["s001-r1"]
    rescued = Path(os.environ["XDG_DATA_HOME"]) / "hopkinson" / "rescued-shots" / "s001-r1.h5"
    assert read_shot(rescued).raw is not None
    with Journal.open(run) as journal:
        status = journal.status("s001-r1")
        assert status.state == S.UNKNOWN and status.info["rescued"] == str(rescued)
        assert f"move that file to {run.shot_path('s001-r1')} and resume" in status.info["reason"]

    # another campaign's shot of the same id rescued later never replaces this record
    other = create_run_folder(write_plan(tmp_path, entries="[[shots]]\npressure_bar = 1.2\n", name="p2.toml"),
                              tmp_path / "runs", "run-2")
    bus = EventBus()
    bus.subscribe(lambda e: shutil.rmtree(other.shots_dir) if isinstance(e, StateEntered) and e.state == "SAFE"
                  and other.shots_dir.exists() else None)
    assert rig.runner(other, plan, bus).run().exit_code == 3
    with Journal.open(other) as journal:
        second = Path(journal.status("s001-r1").info["rescued"])
    assert second != rescued and read_shot(second).meta.uuid != read_shot(rescued).meta.uuid

    run.shots_dir.mkdir()
    shutil.move(rescued, run.shot_path("s001-r1"))
    outcome = rig.runner(run, plan).run()
    assert outcome.exit_code == 0 and outcome.complete
    assert states(run)["s001-r1"] == ("ANALYSED", 1)  # recorded, never fired again
    assert rig.fired() == ["s001-r1", "s001-r1"]  # once per campaign


# -- exit codes a script can trust (issue 44; docs/exit-codes.md) -------------------------------------------
def test_a_campaign_with_failed_analyses_exits_4_and_says_how_many(tmp_path: Path, sim_files, capsys) -> None:
    """Every shot is fired and recorded; one entry's analysis rate (20 kS/s: 40 samples) cannot be
    analysed. A script must not take the campaign for a calibration that worked."""
    entries = ("[[shots]]\npressure_bar = 1.5\n"
               "[[shots]]\npressure_bar = 1.5\nrepeats = 2\n[shots.analysis]\nsample_rate_hz = 20000.0\n")
    plan = write_plan(tmp_path, entries=entries)
    out = tmp_path / "run"
    rc = main(cli_args(plan, out, sim_files, "--no-report", "--json"))
    captured = capsys.readouterr()
    result = json.loads(captured.out)
    assert rc == 4 and result["exit_code"] == rc and result["complete"] is True
    assert result["analyses_failed"] == ["s002-r1", "s002-r2"]
    assert result["message"].startswith("campaign complete: 3 of 3 shots done (2 with a failed analysis: "
                                        "s002-r1, s002-r2; the raw shots are kept, `hopkinson analyse` them)")
    assert captured.err.strip().splitlines()[-1] == f"hopkinson: error: {result['message']}"
    assert states(out_run(out)) == {"s001-r1": ("ANALYSED", 1), "s002-r1": ("ANALYSIS_FAILED", 1),
                                    "s002-r2": ("ANALYSIS_FAILED", 1)}


def test_the_campaign_json_exit_code_is_the_process_exit_code_after_a_signal(tmp_path: Path, sim_files, capsys,
                                                                             monkeypatch) -> None:
    """A signal that lands as the last shot ends: the campaign is complete (its outcome says 0),
    the command exits 3, and so does its JSON."""
    import signal as signals

    import hopkinson.rig.cli.campaign as cli

    class LateSignal:
        received = signals.SIGHUP
        reason = "interrupted (SIGHUP)"

        def __enter__(self):
            return self

        def __exit__(self, *exc: object) -> None:
            return None

        def on_signal(self, action) -> None:
            pass

    monkeypatch.setattr("hopkinson.rig.signals.SignalLatch", LateSignal)
    plan = write_plan(tmp_path, entries="[[shots]]\npressure_bar = 1.5\n")
    rc = cli.run_campaign_command(cli_namespace(plan, tmp_path / "run", sim_files))
    result = json.loads(capsys.readouterr().out)
    assert rc == 3 and result["exit_code"] == 3 and result["complete"] is True
    assert result["interrupted"] == "interrupted (SIGHUP)"


def out_run(folder: Path):
    from hopkinson.rig.run_folder import open_run_folder

    return open_run_folder(folder)


def cli_namespace(plan: Path, out: Path, sim_files: dict[str, Path]):
    from hopkinson.rig.cli.main import build_parser

    return build_parser().parse_args(cli_args(plan, out, sim_files, "--no-report", "--json"))
