"""The shot sequencer against the in-process simulated rig (real Modbus, VISA socket, pty).

Safety is judged from the simulator's World itself (its coils, its launch counter), never
from what the sequencer says about itself.
"""

from __future__ import annotations

import json
import threading
import time
from pathlib import Path

import pytest

from hopkinson.analysis.options import MIN_DRAWS, AnalysisOptions, AnalysisOverrides
from hopkinson.rig.config import LimitsConfig
from hopkinson.rig.errors import ShotAborted
from hopkinson.rig.events import (
    AwaitingConfirmation,
    EventBus,
    EventQueue,
    Note,
    Reading,
    RigError,
    RigEvent,
    ShotFinished,
    StateEntered,
    StepProgress,
)
from hopkinson.rig.interlocks import INTERLOCKS, REQUIRED, RigReadings, evaluate
from hopkinson.rig.sequencer import FINAL_STATES, TRANSITIONS, FireAuthorisation, Sequencer, State
from hopkinson.rig.shot import AnalysisResult, ShotRequestError
from hopkinson.rig.shotfile import RawShot, read_shot
from tests.rig.conftest import short_timeouts_config

ACTIVE = (State.CHECK, State.EVACUATE, State.CHARGE, State.ARM, State.FIRE, State.CAPTURE)
HAPPY_PATH = ["CHECK", "EVACUATE", "CHARGE", "ARM", "FIRE", "CAPTURE", "SAFE", "STORE", "ANALYSE", "DONE"]


# -- the transition table ------------------------------------------------------------------------
def test_transition_table_every_active_state_can_only_go_on_or_to_safe() -> None:
    assert set(TRANSITIONS) == set(State)
    for state in ACTIVE:
        assert State.SAFE in TRANSITIONS[state]
        assert len(TRANSITIONS[state] - {State.SAFE}) <= 1  # the next state or SAFE, nothing else
    # The final states are reached only through SAFE (and STORE/ANALYSE after it).
    for state, targets in TRANSITIONS.items():
        if targets & FINAL_STATES:
            assert state in (State.SAFE, State.STORE, State.ANALYSE), state
    # The happy path is a path of the table.
    for a, b in zip(HAPPY_PATH, HAPPY_PATH[1:], strict=False):
        assert State(b) in TRANSITIONS[State(a)]


# -- a whole shot ----------------------------------------------------------------------------------
def _peak_analysis(seen: dict):
    """An analysis that records what it was given and whether the raw file existed already."""
    def analyse(raw: RawShot, params: AnalysisOptions) -> AnalysisResult:
        path = seen["path"]
        seen["file_state_during_analysis"] = read_shot(path, load_raw=False).state if path.exists() else None
        seen["params"] = params
        response = raw.volts("response")
        return AnalysisResult({"peak_response_v": float(response.max()), "samples": int(response.size)})
    return analyse


def test_complete_shot_stores_raw_before_analysis_and_ends_safe(rig) -> None:
    seen: dict = {"path": rig.out_dir / "one.h5"}
    rig.sequencer = Sequencer(rig.instruments, rig.config, rig.bus, analyse=_peak_analysis(seen))
    outcome = rig.run(pressure_bar=1.0, shot_name="one", accelerometer_serial="SN1")

    assert outcome.final_state == "DONE" and outcome.exit_code == 0 and outcome.error is None
    assert outcome.fired and outcome.safe_confirmed and outcome.analysis_error is None
    assert rig.recorder.states() == HAPPY_PATH
    assert rig.world.shots_fired == 1
    rig.assert_safe()

    # Raw data was on disk (state "raw") when the analysis ran, and the analysis stored after.
    assert seen["file_state_during_analysis"] == "raw"
    shot = read_shot(outcome.shot_path)
    assert shot.state == "analysed"
    assert shot.results == outcome.results
    assert shot.results["peak_response_v"] == pytest.approx(float(shot.volts("response").max()))
    d = rig.config.digitizer
    assert shot.raw.channels["doppler"].codes.size == d.record_length
    assert shot.raw.trigger_index == d.pre_trigger_samples
    assert shot.raw.sample_interval_s == pytest.approx(1 / d.sample_rate_hz)
    # Meta: who/what, the config snapshot with this shot's settings, identities, simulated truth.
    assert shot.meta.accelerometer_serial == "SN1" and shot.meta.operator == "test"
    assert shot.meta.simulated_truth["pressure_bar"] == pytest.approx(1.0, abs=0.06)
    assert shot.meta.simulated_truth == rig.world.last_shot_truth
    assert shot.meta.config["shot_settings"]["amplifier_gain"] == rig.config.amplifier.gain
    assert shot.meta.config["limits"]["max_pressure_bar"] == rig.config.limits.max_pressure_bar
    assert "SIMDIG" in shot.meta.instruments["digitizer"]
    assert seen["params"].amp_gain == rig.config.amplifier.gain
    assert seen["params"].sensitivity_v_per_m_s2 == rig.config.analysis.sensitivity_v_per_m_s2

    # Events: readings in every watched state, one ShotFinished with the file; every event JSON-ready.
    readings = rig.recorder.of(Reading)
    assert {"EVACUATE", "CHARGE", "ARM", "FIRE"} <= {e.state for e in readings}
    assert all(e.interlocks and e.reservoir_pressure_bar is not None for e in readings)
    (result,) = rig.recorder.of(ShotFinished)
    assert result.shot_path == str(outcome.shot_path) and result.error is None and result.final_state == "DONE"
    for event in rig.recorder.events:
        d = event.to_dict()
        assert d["type"] == type(event).__name__ and d["utc"].endswith("Z") and json.dumps(d)


def test_real_analysis_identifies_the_simulated_accelerometer(rig) -> None:
    """The default analysis (analysis.shot_analysis) through the whole pipeline, judged against
    the simulator's truth recorded with the shot."""
    rig.sequencer = Sequencer(rig.instruments, rig.config, rig.bus)  # the default analysis
    outcome = rig.run(pressure_bar=2.0, analysis=AnalysisOverrides(draws=MIN_DRAWS))  # (its intervals: tests/analysis)
    assert outcome.final_state == "DONE" and outcome.analysis_error is None, outcome.analysis_error
    shot = read_shot(outcome.shot_path)
    assert shot.state == "analysed" and shot.results == outcome.results
    truth = shot.meta.simulated_truth
    (true_mode,) = truth["accelerometer"]["modes"]
    modes = [m for m in outcome.results["identification"]["modes"] if m["kind"] in ("complex", "pair")]
    found = min(modes, key=lambda m: abs(m["natural_frequency_hz"] - true_mode["natural_frequency_hz"]))
    assert found["natural_frequency_hz"] == pytest.approx(true_mode["natural_frequency_hz"], rel=0.01)
    assert found["damping_ratio"] == pytest.approx(true_mode["damping_ratio"], rel=0.1)
    reduction = outcome.results["reduction"]
    assert reduction["peak_acceleration_m_s2"] == pytest.approx(truth["peak_acceleration_m_s2"], rel=0.02)
    assert reduction["peak_velocity_m_s"] == pytest.approx(truth["delta_velocity_m_s"], rel=0.02)
    assert shot.record is not None and shot.record.sample_rate_hz == pytest.approx(rig.config.analysis.sample_rate_hz)


def test_analysis_failure_is_recorded_and_the_shot_kept(rig) -> None:
    def broken(raw: RawShot, params: AnalysisOptions) -> AnalysisResult:
        raise ValueError("no beat found in the Doppler channel")

    rig.sequencer = Sequencer(rig.instruments, rig.config, rig.bus, analyse=broken)
    outcome = rig.run()
    assert outcome.final_state == "DONE" and outcome.exit_code == 4  # its own code: never taken for a calibration
    assert outcome.results is None
    assert "no beat found" in outcome.analysis_error
    shot = read_shot(outcome.shot_path)
    assert shot.state == "analysis_failed" and "no beat found" in shot.analysis_error
    assert shot.raw.channels["response"].codes.size == rig.config.digitizer.record_length
    rig.assert_safe()


def test_two_shots_in_a_row_on_the_same_instruments(rig) -> None:
    first = rig.run(pressure_bar=1.0)
    second = rig.run(pressure_bar=1.5)
    assert first.final_state == second.final_state == "DONE"
    assert first.shot_path != second.shot_path
    assert rig.world.shots_fired == 2
    assert rig.world.last_shot_truth["pressure_bar"] == pytest.approx(1.5, abs=0.06)


# -- confirmation ------------------------------------------------------------------------------------
def test_no_confirmation_never_fires(rig) -> None:
    outcome = rig.run(FireAuthorisation(), confirm_timeout_s=0.3)
    assert outcome.final_state == "ABORTED" and outcome.aborted_in == "ARM" and outcome.exit_code == 3
    assert "not confirmed" in outcome.error
    assert not outcome.fired and outcome.shot_path is None
    assert rig.world.shots_fired == 0 and rig.world.fire_refusals == []
    assert rig.recorder.states()[-3:] == ["ARM", "SAFE", "ABORTED"]
    rig.assert_safe()
    with pytest.raises(ShotAborted, match="shot aborted in ARM: operator: shot not confirmed") as info:
        outcome.raise_for_outcome()
    assert info.value.exit_code == 3


def test_confirmation_given_from_another_thread_fires(rig) -> None:
    authorisation = FireAuthorisation()

    def on_event(event: RigEvent) -> None:  # the panel: the operator clicks FIRE a little later
        if isinstance(event, AwaitingConfirmation):
            threading.Timer(0.2, authorisation.give).start()

    rig.bus.subscribe(on_event)
    outcome = rig.run(authorisation, confirm_timeout_s=10.0)
    assert outcome.final_state == "DONE" and outcome.fired
    assert rig.world.shots_fired == 1
    progress = [e.message for e in rig.recorder.of(StepProgress, AwaitingConfirmation) if e.state == "ARM"]
    assert progress == ["armed: waiting for the fire confirmation", "fire confirmed"]


def test_withdrawn_confirmation_does_not_fire(rig) -> None:
    authorisation = FireAuthorisation.pre_given()
    rig.on_state("CHARGE", authorisation.withdraw)
    outcome = rig.run(authorisation, confirm_timeout_s=0.2)
    assert outcome.aborted_in == "ARM" and rig.world.shots_fired == 0
    rig.assert_safe()


# -- abort, timeout, interrupt, lost interlock --------------------------------------------------------
@pytest.mark.parametrize("state", ["CHARGE", "ARM"])
def test_abort_from_another_thread_reaches_safe(make_rig, state: str) -> None:
    # At 10x, charging 4 bar takes ~0.8 s: the abort comes while charging (timeouts with margin).
    rig = make_rig(config=short_timeouts_config(evacuate_s=5.0, charge_s=5.0), time_scale=10.0)
    started = threading.Event()

    def on_event(event: RigEvent) -> None:
        if event.state == state and isinstance(event, StepProgress | Reading):
            started.set()

    rig.bus.subscribe(on_event)
    aborter = threading.Thread(target=lambda: started.wait(10) and rig.sequencer.abort("operator pressed ABORT"))
    aborter.start()
    outcome = rig.run(FireAuthorisation(), pressure_bar=4.0, confirm_timeout_s=10.0)
    aborter.join()
    assert outcome.final_state == "ABORTED" and outcome.aborted_in == state and outcome.exit_code == 3
    assert outcome.error.startswith(f"shot aborted in {state}: operator: aborted: operator pressed ABORT")
    assert not outcome.fired and rig.world.shots_fired == 0
    assert rig.recorder.states()[-2:] == ["SAFE", "ABORTED"]
    rig.assert_safe()
    rig.sequencer.abort("again")  # idempotent and harmless once the shot is over
    assert rig.sequencer.state == State.ABORTED


def test_abort_right_after_the_fire_command_keeps_the_record(rig) -> None:
    def abort_from_another_thread() -> None:
        aborter = threading.Thread(target=rig.sequencer.abort, args=("too late",))
        aborter.start()
        aborter.join()

    rig.on_state("CAPTURE", abort_from_another_thread)
    outcome = rig.run()
    assert outcome.fired and outcome.shot_path is not None
    assert read_shot(outcome.shot_path).raw.channels["doppler"].codes.size == rig.config.digitizer.record_length
    assert outcome.final_state == "ABORTED" and outcome.exit_code == 3  # one meaning per exit code (issue 18)
    assert outcome.analysis_error.startswith("analysis abandoned: too late") and outcome.analysis_to_redo
    assert outcome.error.startswith("shot aborted after FIRE (too late): the recorded data is kept in ")
    rig.assert_safe()


def test_state_timeout_reaches_safe(make_rig) -> None:
    rig = make_rig(config=short_timeouts_config(evacuate_s=5.0, charge_s=0.2), time_scale=10.0)  # 6 bar: ~1.2 s
    outcome = rig.run(pressure_bar=6.0)
    assert outcome.aborted_in == "CHARGE" and outcome.final_state == "ABORTED"
    assert "timed out after 0.2 s charging the reservoir" in outcome.error
    assert rig.config.valve_controller.host in outcome.error  # names the instrument
    rig.assert_safe()
    assert rig.world.shots_fired == 0


def test_keyboard_interrupt_in_charge_is_deferred_until_safe(rig) -> None:
    def interrupt() -> None:
        raise KeyboardInterrupt

    rig.on_state("CHARGE", interrupt)
    with pytest.raises(KeyboardInterrupt):
        rig.run(pressure_bar=2.0)
    # By the time the interrupt reaches the caller, SAFE has run and the rig is safe.
    rig.assert_safe()
    assert rig.recorder.states()[-3:] == ["CHARGE", "SAFE", "ABORTED"]
    (result,) = rig.recorder.of(ShotFinished)
    assert result.aborted_in == "CHARGE" and "interrupted (KeyboardInterrupt)" in result.error
    assert any(e.message.startswith("rig safe") for e in rig.recorder.of(Note))
    assert rig.world.shots_fired == 0


def test_door_opened_mid_arm_aborts(rig) -> None:
    armed_readings = []

    def on_event(event: RigEvent) -> None:
        if isinstance(event, Reading) and event.state == "ARM":
            armed_readings.append(event)
            if len(armed_readings) == 2:  # the rig is armed and waiting: now someone opens the door
                rig.faults.inject("door-open")

    rig.bus.subscribe(on_event)
    outcome = rig.run(FireAuthorisation(), confirm_timeout_s=10.0)
    assert outcome.aborted_in == "ARM" and outcome.final_state == "ABORTED"
    assert "interlock lost: door/guard open" in outcome.error
    assert rig.recorder.of(AwaitingConfirmation)
    assert armed_readings[0].interlocks["door"] is True
    (error,) = rig.recorder.of(RigError)  # the operator's hint comes from the interlock's code
    assert error.codes == ("door",) and error.hint == "Close the door/guard, then ARM again."
    assert outcome.hint == error.hint
    assert rig.world.shots_fired == 0
    rig.assert_safe()
    assert rig.sequencer.interlocks_ok is False


# -- make_safe: SAFE's work with no shot running -----------------------------------------------------
def _leave_the_rig_charged(rig, stuck_fill_valve: bool = False) -> None:
    """A rig left as after a FAULT: fill open, vent shut, pump on, reservoir charged to 1 bar or more."""
    if stuck_fill_valve:
        rig.faults.inject("stuck-fill-valve")
    world = rig.world
    world.set_vent_valve(False)
    world.set_pump(True)
    world.set_pressure_setpoint_bar(2.0)
    world.set_fill_valve(True)
    deadline = time.monotonic() + 5.0
    while world.reservoir_pressure_bar() < 1.0 and time.monotonic() < deadline:
        time.sleep(0.01)
    assert world.reservoir_pressure_bar() >= 1.0


def test_make_safe_when_idle_vents_the_rig_and_leaves_the_state_alone(rig) -> None:
    _leave_the_rig_charged(rig)
    assert rig.sequencer.make_safe() == (True, None)
    rig.assert_safe()
    assert rig.world.coils()["pump"] is False
    assert rig.sequencer.state == State.IDLE and rig.recorder.states() == []
    assert any(e.message.startswith("rig safe") for e in rig.recorder.of(Note))


def test_make_safe_reports_what_it_could_not_confirm(make_rig) -> None:
    rig = make_rig(config=short_timeouts_config(safe_s=1.0))
    _leave_the_rig_charged(rig, stuck_fill_valve=True)
    confirmed, problem = rig.sequencer.make_safe()
    assert confirmed is False and "fill valve stuck open?" in problem
    assert [e.hint for e in rig.recorder.of(RigError)] == ["Check the rig by hand: valves and reservoir pressure."]
    rig.assert_safe(vented=False, stuck=("fill",))


def test_make_safe_refuses_while_a_shot_runs(rig) -> None:
    assert rig.sequencer.make_safe() == (True, None)  # idle: done, and the sequencer is free again
    refused: list[str] = []

    def attempt() -> None:
        try:
            rig.sequencer.make_safe()
        except RuntimeError as exc:
            refused.append(str(exc))

    rig.on_state("EVACUATE", attempt)
    outcome = rig.run()
    assert refused and "a shot is running" in refused[0]
    assert outcome.final_state == "DONE" and rig.world.shots_fired == 1


# -- input, events --------------------------------------------------------------------------------
def test_bad_request_moves_nothing(rig) -> None:
    with pytest.raises(ShotRequestError, match="pressure_bar: 50 bar is outside the rig's limits"):
        rig.run(pressure_bar=50.0)
    with pytest.raises(ShotRequestError, match="projectile"):
        rig.run(projectile=7)
    assert rig.recorder.events == []
    assert rig.world.coils() == {"fire": False, "fill": False, "vent": False, "pump": False}


def test_a_failing_subscriber_does_not_break_the_shot(rig) -> None:
    def broken(event: RigEvent) -> None:
        raise RuntimeError("display crashed")

    rig.bus.subscribe(broken)
    outcome = rig.run()
    assert outcome.final_state == "DONE" and rig.world.shots_fired == 1


def test_event_bus_subscribe_unsubscribe_and_threads() -> None:
    bus = EventBus()
    queue = EventQueue(bus, types=(Note,))
    got: list[RigEvent] = []
    unsubscribe = bus.subscribe(got.append)

    def publish_many() -> None:
        for i in range(200):
            bus.publish(Note(state="IDLE", message=f"n{i}"))

    threads = [threading.Thread(target=publish_many) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(got) == 800 and len(queue.drain()) == 800
    unsubscribe()
    bus.publish(StateEntered(state="CHECK", message="after"))
    assert len(got) == 800
    assert [e.message for e in queue.drain()] == []  # a StateEntered is not a type the queue keeps


# -- interlock rules (pure) ------------------------------------------------------------------------------
def _readings(**kw: object) -> RigReadings:
    base = dict(reservoir_pressure_bar=2.0, fixture_vacuum_mbar=50.0, door_closed=True, fixture_clamped=True,
                estop_healthy=True, amplifier_overloaded=False, digitizer_state="ARMED")
    base.update(kw)
    return RigReadings(**base)  # type: ignore[arg-type]


LIMITS = LimitsConfig(max_pressure_bar=8.0, min_pressure_bar=0.2, pressure_tolerance_bar=0.05,
                      fixture_vacuum_max_mbar=100.0)


@pytest.mark.parametrize("pressure, charging, ok", [
    (2.0, False, True), (2.049, False, True), (2.051, False, False), (1.949, False, False),
    (1.0, True, True), (2.049, True, True), (2.051, True, False), (8.01, True, False),
    (float("nan"), True, False), (float("nan"), False, False), (float("inf"), True, False),
])
def test_pressure_interlock_bounds(pressure: float, charging: bool, ok: bool) -> None:
    report = evaluate(_readings(reservoir_pressure_bar=pressure), LIMITS, ("pressure",), setpoint_bar=2.0,
                      charging=charging)
    assert report.all_ok is ok


@pytest.mark.parametrize("field, value, name", [
    ("door_closed", False, "door"), ("fixture_clamped", False, "clamp"), ("estop_healthy", False, "estop"),
    ("fixture_vacuum_mbar", 100.1, "vacuum"), ("fixture_vacuum_mbar", float("nan"), "vacuum"),
    ("reservoir_pressure_bar", float("nan"), "pressure"), ("amplifier_overloaded", True, "amplifier"),
    ("amplifier_overloaded", None, "amplifier"), ("digitizer_state", "IDLE", "digitizer"),
])
def test_each_interlock_fails_alone(field: str, value: object, name: str) -> None:
    report = evaluate(_readings(**{field: value}), LIMITS, INTERLOCKS, setpoint_bar=2.0)
    assert report.failing() == [name]
    assert evaluate(_readings(), LIMITS, INTERLOCKS, setpoint_bar=2.0).all_ok
    assert set(REQUIRED["FIRE"]) == set(INTERLOCKS)


def test_out_dir_must_exist(rig, tmp_path: Path) -> None:
    with pytest.raises(ShotRequestError, match="out_dir"):
        rig.run(out_dir=tmp_path / "missing")
