"""A real `hopkinson campaign run --sim` killed with SIGKILL at several points and resumed ends
with exactly the planned shots: every planned shot has one complete shot file, no *.tmp is left,
the journal says ANALYSED for each, and the simulated world fired each shot exactly once across
all the runs (its fire log, written by the world at each launch, is the witness) — except a shot
the process was killed between the launch and its raw file: the journal cannot know whether it
was fired, marks it UNKNOWN and fires it again only on an operator's decision, and then the
journal's fire count is the world's.
"""

from __future__ import annotations

import re
import signal
import subprocess
import sys
from collections import Counter
from pathlib import Path

from hopkinson.rig.cli.main import main
from hopkinson.rig.journal import Journal
from hopkinson.rig.logbook import read_log
from hopkinson.rig.run_folder import open_run_folder
from hopkinson.rig.shotfile import read_shot
from hopkinson.rig.sim_fire_log import read_fire_log

ROOT = Path(__file__).resolve().parents[2]
PLAN = """
name = "kill"
operator = "tester"
authorise_firing = true
[accelerometer]
model = "SIM-ACC"
serial = "K1"
[defaults]
projectile = 3
[defaults.analysis]
max_order = 6
uncertainty = false
[[shots]]
pressure_bar = 1.2
repeats = 2
[[shots]]
pressure_bar = 1.8
repeats = 2
"""
IDS = ["s001-r1", "s001-r2", "s002-r1", "s002-r2"]
TIME = re.compile(r"^\d\d:\d\d:\d\d\.\d\d\d ")  # progress lines start with their UTC time


def _untimed(line: str) -> str:
    return TIME.sub("", line, count=1)


class Campaign:
    def __init__(self, tmp_path: Path, plan: str = PLAN) -> None:
        self.plan = tmp_path / "plan.toml"
        self.plan.write_text(plan, encoding="utf-8")
        self.sim = tmp_path / "sim-fast.toml"
        self.sim.write_text("[world]\ntime_scale = 100.0\n", encoding="utf-8")
        self.run = tmp_path / "run"
        self.log = tmp_path / "fire.log"
        self.started = 0

    def start(self, kill_at: str | None, sig: int = signal.SIGKILL) -> tuple[int, list[str]]:
        """Run (or resume) the campaign; send `sig` when a stderr line starts with `kill_at`."""
        argv = [sys.executable, "-m", "hopkinson", "campaign", "run", str(self.plan), "--sim", "--sim-config",
                str(self.sim), "--out", str(self.run), "--no-report", "--sim-fire-log", str(self.log)]
        if self.started:
            argv.append("--resume")
        self.started += 1
        proc = subprocess.Popen(argv, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        lines: list[str] = []
        assert proc.stderr is not None
        for line in proc.stderr:
            line = _untimed(line.rstrip("\n"))
            lines.append(line)
            if kill_at is not None and line.startswith(kill_at):
                proc.send_signal(sig)
                if sig == signal.SIGKILL:
                    break
                kill_at = None
        lines += [_untimed(ln) for ln in proc.stderr.read().splitlines()]
        return proc.wait(timeout=60), lines

    def fired(self) -> Counter[str]:
        return Counter(e["shot_id"] for e in read_fire_log(self.log))

    def check_files_whole(self) -> None:
        """Whatever the moment of the kill, every file under a final name is a complete shot file."""
        for path in sorted((self.run / "shots").glob("*.h5")):
            shot = read_shot(path)  # raises on a truncated or half-written file
            assert shot.meta.shot_id == path.stem and shot.raw is not None


def test_killed_at_several_points_and_resumed_ends_with_exactly_the_planned_shots(tmp_path: Path) -> None:
    c = Campaign(tmp_path)
    # Before the second shot is fired (charging), after the third was fired (capture: no raw file
    # yet), while the fourth is analysed (its raw file stored), and while the resuming process
    # analyses that recorded shot from its file.
    kills = ["[2/4] s001-r2 CHARGE", "[3/4] s002-r1 CAPTURE", "[4/4] s002-r2 ANALYSE", "[4/4] s002-r2 analysing"]
    decided: list[str] = []
    outcomes = []
    for kill_at in kills:
        rc, lines = c.start(kill_at)
        outcomes.append((kill_at, rc, any(ln.startswith(kill_at) for ln in lines)))
        assert rc in (-signal.SIGKILL, 0, 3), lines[-5:]
        c.check_files_whole()
    assert [o[1] for o in outcomes] == [-signal.SIGKILL] * 4 and all(o[2] for o in outcomes), outcomes

    for _ in range(4):  # resume until done, deciding on shots that may have been fired without a record
        rc, lines = c.start(None)
        assert rc in (0, 3), lines[-5:]
        if rc == 0:
            break
        with Journal.open(c.run) as journal:
            doubtful = [s.id for s in journal.needs_decision()]
        assert doubtful, lines[-3:]
        for sid in doubtful:
            # The operator's evidence: the world fired it, and there is no raw file.
            assert c.fired()[sid] == 1 and not (c.run / "shots" / f"{sid}.h5").exists()
            assert main(["campaign", "decide", str(c.run), sid, "retry", "--note", "fired, no record"]) == 0
            decided.append(sid)
    assert rc == 0, lines[-5:]
    # Only the shot killed between its launch and its raw file can have needed a decision.
    assert set(decided) <= {"s002-r1"}

    run = open_run_folder(c.run)
    assert not run.find_leftovers()  # no *.tmp anywhere
    assert sorted(p.name for p in run.shots_dir.glob("*.h5")) == [f"{sid}.h5" for sid in IDS]
    # Every shot kept its log, and the campaign's log holds every run, resumes included.
    assert sorted(p.name for p in run.shots_dir.glob("*.log.jsonl")) == [f"{sid}.log.jsonl" for sid in IDS]
    opened = [e for e in read_log(run.path / "campaign.log.jsonl") if e["type"] == "LogOpened"]
    assert len(opened) == c.started
    fired = c.fired()
    launches = read_fire_log(c.log)
    with Journal.open(run) as journal:
        for status in journal.statuses():
            sid = status.shot.id
            assert status.state.value == "ANALYSED", (sid, status.state)
            expected = 2 if sid in decided else 1
            assert fired[sid] == expected and status.fire_count == expected, (sid, fired, decided)
            shot = read_shot(run.shot_path(sid))
            assert shot.state == "analysed" and shot.meta.shot_id == sid
            assert shot.meta.uuid == status.info["uuid"]
            # The file holds the data of this shot's last launch (the world's own numbers).
            last = [e for e in launches if e["shot_id"] == sid][-1]
            truth = shot.meta.simulated_truth
            assert (truth["shot_number"], truth["fired_at_sim_s"]) == (last["shot_number"], last["fired_at_sim_s"])
            assert truth["pressure_bar"] == last["pressure_bar"]
    assert sum(fired.values()) == len(IDS) + len(decided)
    assert set(fired) == set(IDS)
    # The journal's history holds every run's story (one event row per state change).
    with Journal.open(run) as journal:
        firing = Counter(e["shot_id"] for e in journal.events() if e["to"] == "FIRING")
    assert firing == fired


def test_ctrl_c_aborts_the_shot_to_the_safe_state_and_a_resume_fires_it_once(tmp_path: Path) -> None:
    c = Campaign(tmp_path, PLAN.split("[[shots]]")[0] + "[[shots]]\npressure_bar = 1.2\n")
    rc, lines = c.start("[1/1] s001-r1 CHARGE", sig=signal.SIGINT)
    assert rc == 3, lines[-5:]
    assert lines[-1].startswith("hopkinson: error: interrupted (SIGINT): the current shot was aborted and the rig "
                                "made safe; campaign stopped")
    assert any(ln.startswith("[1/1] s001-r1 SAFE") and "rig safe: fire and fill closed, vent open" in ln for ln in lines)
    assert not c.fired()  # interrupted before FIRE: nothing left the barrel
    with Journal.open(c.run) as journal:
        status = journal.status("s001-r1")
        assert (status.state.value, status.fire_count) == ("ABORTED", 0)
        assert "interrupted (SIGINT)" in status.info["reason"]
    rc, lines = c.start(None)
    assert rc == 0, lines[-5:]
    assert c.fired() == Counter({"s001-r1": 1})
