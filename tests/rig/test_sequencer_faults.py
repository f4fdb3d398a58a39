"""Every named simulator fault, injected in every state where it can occur.

A fault is injected when the sequencer enters the state (a subscriber to the state events,
called in the sequencer's thread before the state's first action), so a fault that bites only
in a later state is injected at that point. The rig must end safe (judged from the World's own
coils), the outcome must name the state, the instrument and the reason, and any data recorded
must be kept.

Where a fault cannot occur:
- visa-garbled-block bites only on a waveform fetch (CAPTURE); no-trigger at the launch (FIRE)
  or at the capture (CAPTURE); stuck-fill-valve only while the fill valve is open (CHARGE).
- vacuum-leak is not injected at FIRE: the leak needs time to spoil the vacuum; one that
  starts at the moment of firing does not affect the shot (its test would only measure a race).
- The Modbus faults are a link that comes back: they are cleared when SAFE begins (else no
  command can reach the valves; see test_permanent_modbus_loss_is_a_fault).

In ARM the fire confirmation is given (as by a person) only after a few readings, so a fault
injected on entering ARM has time to bite before FIRE.
"""

from __future__ import annotations

import threading
import time

import pytest

from hopkinson.drivers.sim.faults import FAULTS
from hopkinson.rig.events import Reading, RigEvent
from hopkinson.rig.logbook import read_log
from hopkinson.rig.sequencer import FireAuthorisation
from hopkinson.rig.shotfile import read_shot
from tests.rig.conftest import SLOW_DELAY_S, Rig, short_timeouts_config

STATES = ("CHECK", "EVACUATE", "CHARGE", "ARM", "FIRE")
MODBUS = ("modbus-disconnect", "modbus-slow")

# fault -> states where it can occur
WHERE: dict[str, tuple[str, ...]] = {
    "modbus-disconnect": STATES,
    "modbus-slow": STATES,
    "door-open": STATES,
    "estop": STATES,
    "amp-overload": STATES,
    "serial-noise": STATES,
    "vacuum-leak": ("EVACUATE", "CHARGE", "ARM"),
    "stuck-fill-valve": ("CHARGE",),
    "no-trigger": ("FIRE", "CAPTURE"),
    "visa-garbled-block": ("CAPTURE",),
    "visa-endless-reply": ("ARM", "CAPTURE"),  # it bites once the digitizer is armed
}
CASES = [(fault, state) for fault, states in WHERE.items() for state in states]


def _instrument(rig: Rig, fault: str) -> str:
    if fault in ("amp-overload", "serial-noise"):
        return rig.instruments.amplifier.name
    if fault in ("no-trigger", "visa-garbled-block", "visa-endless-reply"):
        return rig.instruments.digitizer.instrument
    return rig.instruments.valves.name


# What the one-line message must say about the reason.
REASON = {
    "modbus-disconnect": "connection lost",
    "modbus-slow": "no reply within",
    "door-open": "interlock lost: door/guard open",
    "estop": "interlock lost: e-stop tripped",
    "amp-overload": "interlock lost: amplifier overloaded",
    "serial-noise": "checksum",
    "vacuum-leak": "fixture vacuum",
    "stuck-fill-valve": "above the set-point",
    "no-trigger": "waiting for the trigger",
    "visa-garbled-block": "garbled binary block",
    "visa-endless-reply": "reply longer than",
}


def test_every_named_fault_is_covered() -> None:
    assert set(WHERE) == set(FAULTS)


def _human_confirmation(rig: Rig, authorisation: FireAuthorisation, after_readings: int = 3) -> None:
    count = [0]

    def on_event(event: RigEvent) -> None:
        if isinstance(event, Reading) and event.state == "ARM":
            count[0] += 1
            if count[0] == after_readings:
                authorisation.give()

    rig.bus.subscribe(on_event)


@pytest.mark.parametrize("fault, state", CASES, ids=[f"{f}@{s}" for f, s in CASES])
def test_fault_in_state_ends_safe(make_rig, fault: str, state: str) -> None:
    # no-trigger waits out the capture timeout: keep it short there.
    rig = make_rig(config=short_timeouts_config(capture_s=0.5) if fault == "no-trigger" else None)
    authorisation = FireAuthorisation()
    _human_confirmation(rig, authorisation)
    rig.on_state(state, lambda: rig.faults.inject(fault))
    if fault in MODBUS:
        rig.on_state("SAFE", lambda: rig.faults.clear(fault))
    outcome = rig.run(authorisation, pressure_bar=1.0, confirm_timeout_s=5.0)

    if fault == "stuck-fill-valve":  # the valve stays open: the pressure rises past the set-point
        assert outcome.aborted_in in ("CHARGE", "ARM"), outcome.error
    else:  # no-trigger injected at FIRE bites when the capture is awaited
        assert outcome.aborted_in == ("CAPTURE" if fault == "no-trigger" else state), outcome.error
    assert outcome.exit_code == 3
    assert outcome.error.startswith(f"shot aborted in {outcome.aborted_in}: {_instrument(rig, fault)}: "), outcome.error
    assert REASON[fault] in outcome.error
    assert "\n" not in outcome.error

    if fault == "modbus-slow":
        time.sleep(SLOW_DELAY_S + 0.1)  # a request that timed out may be carried out late: still safe?
    if fault == "stuck-fill-valve":
        # The valve is stuck open: the vent cannot bring the reservoir down, and SAFE says so.
        assert outcome.final_state == "FAULT" and not outcome.safe_confirmed
        assert "SAFE NOT CONFIRMED" in outcome.error and "fill valve stuck open?" in outcome.error
        rig.assert_safe(vented=False, stuck=("fill",))
    elif fault == "visa-endless-reply":  # a hung digitizer: SAFE cannot disarm it, and says so
        assert outcome.final_state == "ABORTED" and outcome.safe_confirmed
        warnings = [e["message"] for e in read_log(outcome.log_path) if e["type"] == "RigWarning"]
        assert any(w.startswith("SAFE could not disarm the digitizer") for w in warnings), warnings
        rig.assert_safe(digitizer=False)
    else:
        assert outcome.final_state == "ABORTED" and outcome.safe_confirmed
        assert "rig safe" in outcome.error
        rig.assert_safe()

    fired = fault == "no-trigger" or state == "CAPTURE"  # the only faults that bite after the fire command
    assert outcome.fired is fired
    assert rig.world.shots_fired == (1 if fired else 0)
    assert outcome.shot_path is None and not list(rig.out_dir.glob("*.h5"))  # nothing was recorded
    log = read_log(outcome.log_path)  # but the shot's log tells the story, the fault included
    errors = [e for e in log if e["type"] == "RigError"]
    assert errors and REASON[fault] in errors[0]["message"] and log[-1]["type"] == "ShotFinished"
    if fired:
        assert "the shot was fired but nothing was recorded" in outcome.error


def test_permanent_modbus_loss_is_a_fault(make_rig) -> None:
    """No command reaches the valves: SAFE cannot confirm anything and says so (exit 3)."""
    rig = make_rig()
    rig.on_state("CHARGE", lambda: rig.faults.inject("modbus-disconnect"))
    outcome = rig.run(pressure_bar=1.0)
    assert outcome.final_state == "FAULT" and not outcome.safe_confirmed and outcome.exit_code == 3
    assert outcome.error.startswith(f"shot aborted in CHARGE: {rig.instruments.valves.name}: ")
    assert "SAFE NOT CONFIRMED" in outcome.error and "check the rig by hand" in outcome.error
    # Without a link the simulated controller still regulates: never above the set-point.
    assert rig.world.reservoir_pressure_bar() <= 1.0 + rig.config.limits.pressure_tolerance_bar
    assert rig.world.shots_fired == 0


def test_permanently_slow_controller_is_made_safe_by_late_commands(make_rig) -> None:
    """Every request times out; SAFE keeps sending the safe commands, which the controller
    carries out late: the rig ends safe, but SAFE could not confirm it (FAULT)."""
    rig = make_rig()
    rig.on_state("CHARGE", lambda: rig.faults.inject("modbus-slow"))
    outcome = rig.run(pressure_bar=1.0)
    assert outcome.final_state == "FAULT" and "SAFE NOT CONFIRMED" in outcome.error
    time.sleep(SLOW_DELAY_S + 0.1)
    rig.assert_safe(read_back=False)  # every request still times out


# -- faults after the capture: the data is kept -------------------------------------------------------
def test_link_lost_in_safe_after_capture_keeps_the_data_and_recovers(make_rig) -> None:
    rig = make_rig()

    def lose_link_briefly() -> None:
        rig.faults.inject("modbus-disconnect")
        threading.Timer(0.3, rig.faults.clear, args=("modbus-disconnect",)).start()

    rig.on_state("SAFE", lose_link_briefly)
    outcome = rig.run(pressure_bar=1.0)
    assert outcome.final_state == "DONE" and outcome.safe_confirmed and outcome.exit_code == 0
    rig.assert_safe()
    assert read_shot(outcome.shot_path).raw.channels["doppler"].codes.size == rig.config.digitizer.record_length


def test_link_lost_for_good_in_safe_after_capture_still_stores_the_shot(make_rig) -> None:
    rig = make_rig()
    rig.on_state("SAFE", lambda: rig.faults.inject("modbus-disconnect"))
    outcome = rig.run(pressure_bar=1.0)
    assert outcome.final_state == "FAULT" and outcome.aborted_in == "SAFE" and outcome.exit_code == 3
    assert outcome.fired and outcome.shot_path is not None
    assert f"the recorded data is kept in {outcome.shot_path}" in outcome.error
    assert "SAFE NOT CONFIRMED" in outcome.error
    shot = read_shot(outcome.shot_path)
    assert shot.state == "raw"  # stored, not analysed (the rig is not known to be safe)
    assert shot.raw.channels["response"].codes.size == rig.config.digitizer.record_length
    assert shot.meta.simulated_truth["shot_number"] == 1
    # FIRE and CHARGE had closed both valves before the link went; the shot emptied the reservoir.
    coils = rig.world.coils()
    assert coils["fire"] is False and coils["fill"] is False
    assert rig.world.reservoir_pressure_bar() <= rig.config.limits.vent_done_bar


def test_amplifier_overload_during_the_shot_is_a_warning_not_a_loss(make_rig) -> None:
    rig = make_rig()
    rig.on_state("CAPTURE", lambda: rig.faults.inject("amp-overload"))
    outcome = rig.run(pressure_bar=1.0)
    assert outcome.final_state == "DONE" and outcome.shot_path is not None
    assert any("overloaded during the shot" in w for w in outcome.warnings)
    shot = read_shot(outcome.shot_path)
    assert shot.meta.config["shot_settings"]["amplifier_overloaded"] is True
    # The response is clipped: kept, but not analysed, and the file says why.
    assert outcome.analysis_error.startswith("not analysed: the amplifier overloaded")
    assert shot.state == "analysis_failed" and "amplifier overloaded" in shot.analysis_error
    rig.assert_safe()


def test_a_gauge_reading_nan_stops_the_charge_at_once_and_safe_does_not_claim_vented(rig) -> None:
    """A float32 gauge register (or a lab's driver) may read NaN, which passes every comparison:
    the pressure interlock must fail on it (not charge with the fill open until CHARGE times out),
    and SAFE must not call an unknown pressure vented."""
    valves = rig.instruments.valves
    rig.on_state("CHARGE", lambda: setattr(valves, "reservoir_pressure_bar", lambda: float("nan")))
    outcome = rig.run(pressure_bar=2.0)
    assert outcome.aborted_in == "CHARGE" and not outcome.fired and rig.world.shots_fired == 0
    assert "interlock lost: reservoir gauge reads nan (not a number" in outcome.error
    assert outcome.final_state == "FAULT" and not outcome.safe_confirmed  # the pressure is unknown
    assert "SAFE NOT CONFIRMED" in outcome.error and "reservoir still at nan bar" in outcome.error
    rig.assert_safe(read_back=False)  # the gauge's reading is what is broken


def test_check_refuses_a_gauge_reading_nan_before_anything_moves(rig) -> None:
    valves = rig.instruments.valves
    rig.on_state("CHECK", lambda: setattr(valves, "reservoir_pressure_bar", lambda: float("nan")))
    outcome = rig.run(pressure_bar=2.0)
    assert outcome.aborted_in == "CHECK" and "the reservoir gauge reads nan" in outcome.error
    rig.assert_safe(read_back=False)


def test_safe_holds_after_a_modbus_timeout_until_a_late_command_has_landed(make_rig) -> None:
    """A request the controller did not answer in time may still be carried out: here a "fill
    open" lands SLOW_DELAY_S after it was sent, once SAFE has closed the fill. Told that the
    controller timed out, SAFE keeps re-checking for safe_hold_s, sees the fill open again and
    closes it; without the hold it would confirm, and the fill would open behind its back."""
    from hopkinson.drivers.errors import InstrumentTimeout
    from hopkinson.rig.sequencer.context import Publisher
    from hopkinson.rig.sequencer.safe import make_rig_safe, safe_hold_s

    rig = make_rig()
    valves = rig.instruments.valves
    rig.faults.inject("modbus-slow")
    with pytest.raises(InstrumentTimeout):
        valves.set_fill_valve(True)  # the controller carries it out SLOW_DELAY_S after it was sent
    rig.faults.clear("modbus-slow")
    assert rig.world.coils()["fill"] is False  # not yet
    assert safe_hold_s(rig.config) > SLOW_DELAY_S - rig.config.valve_controller.timeout_s  # the hold covers it
    result = make_rig_safe(valves, rig.config, Publisher(rig.bus), controller_timed_out=True)
    assert result.confirmed and result.controller_timed_out
    assert result.elapsed_s >= safe_hold_s(rig.config)  # the hold itself (a lower bound: no timing margin needed)
    time.sleep(SLOW_DELAY_S)  # long after the late command
    rig.assert_safe()
