"""Validation before anything moves: a whole plan against the rig before its first shot, a sane
number of shots (with a confirmation above a count), every analysis option before FIRE, and the
instruments' settings read back in ARM immediately before FIRE. Clipping is judged against the
digitizer's full-scale codes, never the record's own extremes."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from hopkinson.analysis.options import AnalysisOptions, AnalysisOverrides
from hopkinson.rig.cli.main import main
from hopkinson.rig.errors import ConfigError
from hopkinson.rig.events import AwaitingConfirmation, RigEvent
from hopkinson.rig.instruments import make_instrument
from hopkinson.rig.plan import check_shot_count, load_plan
from hopkinson.rig.sequencer import FireAuthorisation
from hopkinson.rig.shot import analyse_and_record, analyse_raw
from hopkinson.rig.shotfile import RawChannel, RawShot, ShotMeta, read_shot
from hopkinson.rig.shotfile_writer import write_raw_shot
from hopkinson.rig.sim_session import sim_session
from tests.rig.conftest import fast_sim_config, rig_toml, short_timeouts_config

PLAN = """
name = "check"
operator = "tester"
authorise_firing = true
[accelerometer]
model = "SIM-ACC"
serial = "V1"
[defaults]
projectile = 3
{entries}
"""


def _plan(tmp_path: Path, entries: str) -> Path:
    path = tmp_path / "plan.toml"
    path.write_text(PLAN.format(entries=entries), encoding="utf-8")
    return path


def _one_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("hopkinson: error: ") and "Traceback" not in err[0], err
    return err[0]


def test_a_plan_whose_second_entry_is_too_high_fires_nothing(tmp_path: Path, capsys) -> None:
    plan = _plan(tmp_path, "[[shots]]\npressure_bar = 1.5\n[[shots]]\npressure_bar = 20.0\n")
    with sim_session(short_timeouts_config(), fast_sim_config()) as session:
        toml = rig_toml(session, tmp_path / "rig.toml")
        assert main(["campaign", "run", str(plan), "--config", str(toml), "--out", str(tmp_path / "run")]) == 2
        line = _one_line(capsys)
        assert "shots[2] (s002-r1)" in line and "20 bar is outside the rig's limits" in line
        assert session.world.shots_fired == 0 and session.world.coils()["fill"] is False
    assert not (tmp_path / "run").exists()  # not even the run folder


def test_a_billion_repeats_is_a_clear_error_not_a_memory_error(tmp_path: Path, capsys) -> None:
    plan = _plan(tmp_path, "[[shots]]\npressure_bar = 1.5\nrepeats = 1000000000\n")
    assert main(["campaign", "run", str(plan), "--sim"]) == 2
    assert "shots[1].repeats: must be 1..10000 (got 1000000000)" in _one_line(capsys)
    plan = _plan(tmp_path, "[[shots]]\npressure_bar = 1.5\nrepeats = 6000\n[[shots]]\npressure_bar = 2\nrepeats = 6000\n")
    with pytest.raises(ConfigError, match=r"shots\[2\].repeats: the plan would fire more than 10000 shots"):
        load_plan(plan)


def test_a_large_plan_needs_its_number_of_shots_confirmed(tmp_path: Path, capsys) -> None:
    plan_path = _plan(tmp_path, "[[shots]]\npressure_bar = 1.5\nrepeats = 3\n")
    assert main(["campaign", "run", str(plan_path), "--sim", "--confirm-above", "2",
                 "--out", str(tmp_path / "run")]) == 2
    line = _one_line(capsys)
    assert "fires 3 shots, more than 2: confirm the number with --shots 3" in line and "nothing was fired" in line
    assert not (tmp_path / "run").exists()
    plan = load_plan(plan_path)
    check_shot_count(plan, confirm_above=2, confirmed_shots=3)  # confirmed: goes on
    check_shot_count(plan)  # below the default count: nothing to confirm
    with pytest.raises(ConfigError, match="--shots 2 was given"):
        check_shot_count(plan, confirm_above=2, confirmed_shots=2)


@pytest.mark.parametrize("option, value, name", [
    ("--dcm-damping", "50", "dcm_damping"), ("--max-order", "0", "max_order"), ("--sample-rate", "-1", "sample_rate_hz"),
])
def test_every_analysis_option_is_checked_before_anything_moves(tmp_path: Path, capsys, option, value, name) -> None:
    with sim_session(short_timeouts_config(), fast_sim_config()) as session:
        toml = rig_toml(session, tmp_path / "rig.toml")
        assert main(["shot", "--config", str(toml), "--yes", "--out", str(tmp_path), option, value]) == 2
        assert f"analysis option {name}" in _one_line(capsys)
        assert session.world.shots_fired == 0 and session.world.watchdog_state() == "off"  # never connected
    assert not list(tmp_path.glob("*.log.jsonl"))


def test_a_second_client_changing_the_sample_rate_aborts_before_fire(rig) -> None:
    """Another program reconfigures the digitizer after CHECK set it (the simulated digitizer,
    like a real one, refuses changes while armed): ARM's read-back catches it before FIRE."""
    other = make_instrument(rig.config, "digitizer")  # another client of the same digitizer

    def meddle() -> None:
        other.connect()
        other.configure(sample_rate_hz=rig.config.digitizer.sample_rate_hz / 2)

    rig.on_state("CHARGE", meddle)
    try:
        outcome = rig.run(FireAuthorisation.pre_given())
    finally:
        other.close()  # after the shot: pyvisa's resource manager is shared by the process's sessions
    assert outcome.aborted_in == "ARM" and not outcome.fired and rig.world.shots_fired == 0
    assert "settings changed before FIRE" in outcome.error and "sample_rate_hz" in outcome.error
    assert outcome.hint.startswith("Another program may be using the instrument")
    rig.assert_safe()


def test_a_recorded_channel_turned_off_by_another_program_aborts_before_fire(rig) -> None:
    """A scope records only the channels that are on: ARM turns them on, and its read-back
    before FIRE catches one that another program turned off since (issue 21)."""
    import pyvisa

    channel = rig.config.digitizer.channels["response"]
    other = pyvisa.ResourceManager("@py").open_resource(rig.config.digitizer.resource, read_termination="\n",
                                                        write_termination="\n", timeout=2000)

    def meddle() -> None:
        other.write(f":CHANnel{channel[-1]}:DISPlay OFF")
        assert other.query(f":CHANnel{channel[-1]}:DISPlay?") == "0"

    rig.on_state("CHARGE", meddle)
    try:
        outcome = rig.run(FireAuthorisation.pre_given())
    finally:
        other.close()
    assert outcome.aborted_in == "ARM" and not outcome.fired and rig.world.shots_fired == 0
    assert f"{channel}: off on the instrument" in outcome.error, outcome.error
    rig.assert_safe()


def test_a_changed_pressure_set_point_aborts_before_fire(rig) -> None:
    authorisation = FireAuthorisation()

    def change_then_confirm(event: RigEvent) -> None:
        if isinstance(event, AwaitingConfirmation):
            rig.world.set_pressure_setpoint_bar(1.3)  # as a second Modbus client would
            authorisation.give()

    rig.bus.subscribe(change_then_confirm)
    outcome = rig.run(authorisation, pressure_bar=1.0, confirm_timeout_s=5.0)
    assert outcome.aborted_in == "ARM" and "pressure set-point: 1 bar wanted" in outcome.error
    assert rig.world.shots_fired == 0
    rig.assert_safe()


# -- clipping: the instrument's rails, never the record's own extremes --------------------------------
def _raw(codes: np.ndarray, code_range: tuple[float, float] | None, doppler_range=None) -> RawShot:
    doppler = RawChannel(np.full(codes.size, 1000, dtype=codes.dtype), 1e-4, 0.0,
                         doppler_range if doppler_range is not None else code_range)
    return RawShot({"doppler": doppler, "response": RawChannel(codes, 10.0 / 32768, 0.0, code_range)}, 1e-8, 100)


def test_the_full_scale_is_the_formats_full_scale_codes_in_volts() -> None:
    codes = np.zeros(16, dtype=np.int16)
    raw = _raw(codes, (-32768.0, 32767.0))
    assert raw.full_scale_v() == {"doppler": (-3.2768, 3.2767),
                                  "response": (-10.0, pytest.approx(10.0 * 32767 / 32768, abs=1e-12))}
    unsigned = RawShot({"doppler": RawChannel(codes.astype(np.uint16), -2e-4, 6.5536, (0.0, 65535.0)),
                        "response": RawChannel(codes.astype(np.uint16), 1e-3, -32.768, None)}, 1e-8, 0)
    # volts = codes * scale + offset: a negative scale turns the ends round; an unknown range is no range
    assert unsigned.full_scale_v() == {"doppler": (pytest.approx(6.5536 - 65535 * 2e-4), 6.5536)}


def _analysed(tmp_path: Path, raw: RawShot, overloaded: bool = False) -> str | None:
    """The rig's ANALYSE of a stored shot (as a campaign re-analyses one): its error text."""
    meta = ShotMeta(operator="t", accelerometer_model="M", accelerometer_serial="S", pressure_bar=1.0, projectile=3)
    path = write_raw_shot(tmp_path / f"shot-{len(list(tmp_path.glob('*.h5')))}.h5", raw, meta)
    results, error, *_ = analyse_and_record(path, read_shot(path).raw, AnalysisOptions(uncertainty=False),
                                        lambda stored, params: analyse_raw(stored, params),
                                        amplifier_overloaded=overloaded)
    assert results is None and read_shot(path, load_raw=False).analysis_error == error  # the file says why
    return error


def test_clipping_is_judged_against_the_digitizers_full_scale(tmp_path: Path) -> None:
    t = np.linspace(0.0, 1.0, 100_000)
    wide = np.round(3000 * np.sin(np.pi * t) ** 8).astype(np.int16)  # a wide pulse: its top stays on one code
    assert np.count_nonzero(wide == wide.max()) > 100  # the old own-extreme rule called this "clipped"
    # Not clipped: the response passes its checks and the analysis goes on to the reference's
    # beat, where it stops (the stand-in beat is flat).
    past_the_response = "analysis failed: raw shot: doppler channel: the signal is constant (0.1 V): no Doppler beat"
    assert _analysed(tmp_path, _raw(wide, (-32768.0, 32767.0))) == past_the_response
    unsigned = (wide.astype(np.int32) + 32768).astype(np.uint16)  # native uint16: never wrapped to int16
    assert _analysed(tmp_path, _raw(unsigned, (0.0, 65535.0))) == past_the_response
    assert _analysed(tmp_path, _raw(wide, None)) == past_the_response  # rails unknown (an old file): never guessed
    rails = wide.copy()
    rails[40_000:40_010] = 32767
    error = _analysed(tmp_path, _raw(rails, (-32768.0, 32767.0)))
    assert error.startswith("analysis failed: raw shot: response channel: clipped: 10 samples at the digitizer's "
                            "full scale (-10 .. 10 V)"), error
    low = wide.copy()
    low[50_000:50_003] = -32768
    assert "response channel: clipped: 3 samples" in _analysed(tmp_path, _raw(low, (-32768.0, 32767.0)))
    beat = _raw(wide, (-32768.0, 32767.0), doppler_range=(-1000.0, 1000.0))  # the doppler's 1000 is its top code
    assert "doppler channel: clipped: 100000 samples at the digitizer's full scale" in _analysed(tmp_path, beat)
    overload = _analysed(tmp_path, _raw(wide, (-32768.0, 32767.0)), overloaded=True)
    assert overload.startswith("not analysed: the amplifier overloaded")


def test_a_wide_pulse_is_analysed_not_rejected_as_clipped(make_rig) -> None:
    """Projectile No. 1 at 2 bar (the widest pulse): analysed, the raw channels in their native type."""
    rig = make_rig(config=dataclasses.replace(short_timeouts_config()))
    from hopkinson.rig.sequencer import Sequencer
    from hopkinson.rig.shotfile import read_shot

    rig.sequencer = Sequencer(rig.instruments, rig.config, rig.bus)  # the real analysis
    outcome = rig.run(pressure_bar=2.0, projectile=1, analysis=AnalysisOverrides(uncertainty=False))
    assert outcome.final_state == "DONE" and outcome.analysis_error is None, outcome.analysis_error
    raw = read_shot(outcome.shot_path).raw
    fmt = np.dtype(rig.config.digitizer.sample_format)
    for role, channel in raw.channels.items():
        assert channel.codes.dtype == fmt, role
        assert channel.code_range == (float(np.iinfo(fmt).min), float(np.iinfo(fmt).max)), role
