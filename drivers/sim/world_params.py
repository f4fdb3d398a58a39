"""[world] of config/sim.toml: the simulated rig's physics, one frozen dataclass per table.

Every key is declared once, here, with its default, bounds and meaning
(drivers/sim/config_fields.py); rig/config.py validates a sim.toml against these classes, and
`hopkinson config schema` writes their JSON Schema. The realism tables are in
drivers/sim/real_records.py, the servers' in drivers/sim/simulated_rig.py.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Annotated, Literal

from pydantic import AfterValidator, Field

from hopkinson.drivers.sim.accelerometer import AccelerometerTruth, Mode
from hopkinson.drivers.sim.config_fields import SECTION, Flag, Hint, Int, Number, Orders, one_of
from hopkinson.drivers.sim.doppler_beat import DEFAULT_GRATING_PITCH_M, QuadratureOutput
from hopkinson.drivers.sim.real_records import IdealPulseSource, PulseSource, RealismParams

PROJECTILES = (1, 2, 3)
# The digitizer's channel of each signal (World.capture's keys): the PM beat, the amplifier
# output, and when configured the quadrature photodetector and the second sensor.
CHANNELS = {"doppler": 1, "response": 2, "doppler_quadrature": 3, "response_2": 4}
# What the simulated amplifier accepts (its data sheet; drivers/sim/serial_amplifier.py). The
# simulator keeps its own copy of the steps, written apart from the driver's declaration
# (drivers/amplifier.py), so loopback tests check the driver against the protocol.
AMP_GAINS = (1, 2, 5, 10, 20, 50, 100, 200, 500, 1000)
AMP_LOWPASS_HZ = (1e3, 2e3, 5e3, 10e3, 20e3, 50e3, 100e3, 200e3)  # plus 0 = off
AMP_EXCITATION_RANGE_V = (0.5, 10.0)

Positive = Annotated[Number, Field(gt=0)]
Bar = Annotated[Number, Field(ge=0, le=100)]
Mbar = Annotated[Number, Field(ge=0, le=2000)]
FilterOrder = Annotated[Int, Field(ge=1, le=8, description="Butterworth order")]
Width = Annotated[Number, Field(gt=0, le=0.01)]

SnrDb = Annotated[Number, Field(ge=0, le=200, description="signal-to-noise ratio, dB; 0 = no noise"),
                  Hint("0 (no noise) .. 200 dB")]


def _some_modes(modes: tuple[Mode, ...]) -> tuple[Mode, ...]:
    if not modes:
        raise ValueError("at least one mode is needed")
    return modes


Modes = Annotated[tuple[Mode, ...], AfterValidator(_some_modes),
                  Field(description="the sensor's resonances", json_schema_extra={"minItems": 1})]


@dataclass(frozen=True)
class PneumaticsParams:
    """[world.pneumatics]: reservoir, valves, vacuum fixture and interlock inputs (gauge bar,
    absolute mbar)."""

    __pydantic_config__ = SECTION
    supply_pressure_bar: Annotated[Bar, Field(description="the gas supply behind the fill valve")] = 10.0
    fill_rate_bar_s: Annotated[Positive, Field(description="the reservoir's rise while filling")] = 0.5
    vent_time_constant_s: Annotated[Positive, Field(description="exponential decay through the vent valve")] = 1.0
    fire_exhaust_time_constant_s: Annotated[Positive, Field(description="through the open fire valve")] = 0.05
    min_fire_pressure_bar: Annotated[Bar, Field(description="below this an open fire valve launches "
                                                            "nothing")] = 0.05
    atmosphere_mbar: Annotated[Number, Field(gt=0, le=2000, description="what the fixture leaks back to")] = 1013.25
    pump_time_constant_s: Annotated[Positive, Field(description="exponential pump-down of the fixture")] = 2.0
    pump_floor_mbar: Annotated[Mbar, Field(description="the best vacuum the pump reaches")] = 2.0
    leak_rate_mbar_s: Annotated[Positive, Field(description="the fixture's leak with the pump off")] = 1.0
    fault_leak_floor_mbar: Annotated[Mbar, Field(description="best vacuum under the vacuum-leak fault")] = 500.0
    door_closed: Flag = True
    fixture_clamped: Flag = True
    estop_healthy: Flag = True
    watchdog_s: Annotated[Number, Field(ge=0.2, le=60, description="the controller's own link watchdog "
                                                                   "until a host writes another")] = 3.0


@dataclass(frozen=True)
class LauncherParams:
    """[world.launcher]: pressure → speed → velocity change and pulse width of the object."""

    __pydantic_config__ = SECTION
    projectile: Annotated[Literal[1, 2, 3], Field(description="the projectile loaded at start")] = 3
    speed_m_s_per_sqrt_bar: Positive = 10.0
    velocity_transfer: Positive = 0.85
    pulse_width_s: Annotated[tuple[Width, Width, Width], Field(description="projectiles No. 1, 2, 3")] = (
        120e-6, 75e-6, 38.6e-6)


@dataclass(frozen=True)
class AccelerometerParams:
    """[world.accelerometer]: the true sensor, recorded with every shot as simulation truth."""

    __pydantic_config__ = SECTION
    modes: Modes = (Mode(27_000.0, 0.05),)
    zero_shift_m_s2: Number = 0.0
    sensitivity_v_per_m_s2: Annotated[Positive, Field(description="bridge output at the nominal excitation")] = 2.0e-7
    nominal_excitation_v: Positive = 5.0
    shunt_equivalent_m_s2: Annotated[Positive, Field(description="the shunt calibration's acceleration")] = 490_332.5
    bridge_offset_v: Annotated[Number, Field(ge=-1, le=1, description="bridge unbalance until auto-zero")] = 0.002
    nonlinearity_per_m_s2: Annotated[Number, Field(ge=-1e-5, le=1e-5, description=(
        "sensitivity change per m/s2 of |a|; 0 = linear")), Hint("per m/s2 of |a|; 0 = linear")] = 0.0


@dataclass(frozen=True)
class AmplifierParams:
    """[world.amplifier]: the bridge amplifier's identity, power-on settings and limits."""

    __pydantic_config__ = SECTION
    identity: str = "Hopkinson-Sim,SIMAMP-1,SIM0002,1.0"
    gain: Annotated[Number, *one_of(AMP_GAINS)] = 10.0
    excitation_v: Annotated[Number, Field(ge=AMP_EXCITATION_RANGE_V[0], le=AMP_EXCITATION_RANGE_V[1])] = 5.0
    lowpass_hz: Annotated[Number, *one_of((0.0, *AMP_LOWPASS_HZ)), Field(description="0 = filter off")] = 200_000.0
    lowpass_order: FilterOrder = 2
    output_limit_v: Positive = 10.0
    auto_zero_residual_v: Annotated[Number, Field(ge=-1, le=1)] = 0.0


@dataclass(frozen=True)
class SignalParams:
    """[world.signals]: the Doppler channel and the noise of the response channel."""

    __pydantic_config__ = SECTION
    grating_pitch_m: Positive = DEFAULT_GRATING_PITCH_M
    orders: Annotated[Orders, Field(description="diffraction orders (phi, xi); they differ")] = (1, -1)
    pm_amplitude_v: Positive = 0.4
    pm_dc_offset_v: Annotated[Number, Field(ge=-10, le=10)] = 0.15
    pm_fluctuation: Annotated[Number, Field(ge=0, le=1)] = 0.1
    pm_snr_db: SnrDb = 30.0
    response_white_snr_db: SnrDb = 60.0
    response_coloured_snr_db: SnrDb = 50.0
    response_coloured_pole: Annotated[Number, Field(ge=0, le=0.999)] = 0.9
    response_rate_hz: Annotated[Positive, Field(description="internal rate of the response model")] = 10e6
    # Hard parts of real records: a bipolar pulse (a negative half-sine of this ratio of the peak
    # follows at once; 0 = a half-sine), the response channel's skew against the Doppler channel
    # (s; negative: it leads) and a drift of the amplifier output (V/s).
    pulse_bipolar_ratio: Annotated[Number, Field(ge=0, le=0.95)] = 0.0
    channel_skew_s: Annotated[Number, Field(ge=-1e-6, le=1e-6)] = 0.0
    response_drift_v_per_s: Annotated[Number, Field(ge=-1e3, le=1e3)] = 0.0
    # A quadrature interferometer (ISO 16063-11 method 3): a second photodetector 90° from the
    # PM beat on channel 3 (role doppler_quadrature), with its own offset (V), amplitude ÷ the
    # first's and departure from 90° (degrees): the ellipse the analysis' Heydemann fit undoes.
    quadrature: Flag = False
    quadrature_offset_v: Annotated[Number, Field(ge=-10, le=10)] = 0.12
    quadrature_gain_ratio: Annotated[Number, Field(gt=0, le=10)] = 0.85
    quadrature_error_deg: Annotated[Number, Field(ge=-45, le=45)] = 4.0

    def quadrature_output(self) -> QuadratureOutput:
        return QuadratureOutput(self.quadrature_offset_v, self.quadrature_gain_ratio,
                                math.radians(self.quadrature_error_deg))


@dataclass(frozen=True)
class SecondSensorParams:
    """[world.accelerometer_2]: an optional second accelerometer beside the first, on channel 4
    (role response_2), with its own conditioner set by hand (fixed gain and low-pass): its own
    true model, recorded with every shot as simulation truth. Its noise follows [world.signals]
    like the first's."""

    __pydantic_config__ = SECTION
    enabled: Flag = False
    modes: Modes = (Mode(33_000.0, 0.03),)
    zero_shift_m_s2: Number = 0.0
    sensitivity_v_per_m_s2: Annotated[Positive, Field(description="at its conditioner's input")] = 1.0e-7
    conditioner_gain: Positive = 20.0
    lowpass_hz: Annotated[Number, Field(ge=0, le=1e8, description="the conditioner's low-pass corner"),
                          Hint("0 (off) or the filter corner")] = 200_000.0
    lowpass_order: FilterOrder = 2

    def truth(self) -> AccelerometerTruth:
        return AccelerometerTruth(modes=tuple(self.modes), lowpass_hz=self.lowpass_hz,
                                  lowpass_order=self.lowpass_order, sensitivity=1.0, zero_shift=self.zero_shift_m_s2)


@dataclass(frozen=True)
class WorldParams:
    """[world]: everything config/sim.toml sets about the physics."""

    __pydantic_config__ = SECTION
    time_scale: Annotated[Number, Field(gt=0, le=10_000, description="simulated seconds per wall-clock second")] = 1.0
    seed: Annotated[Int, Field(ge=0, le=2**63, description="shot n's noise is drawn from (seed, n)")] = 0
    pneumatics: PneumaticsParams = field(default_factory=PneumaticsParams)
    launcher: LauncherParams = field(default_factory=LauncherParams)
    accelerometer: AccelerometerParams = field(default_factory=AccelerometerParams)
    amplifier: AmplifierParams = field(default_factory=AmplifierParams)
    signals: SignalParams = field(default_factory=SignalParams)
    accelerometer_2: SecondSensorParams = field(default_factory=SecondSensorParams)
    realism: RealismParams = field(default_factory=RealismParams)  # off: the idealised world

    def pulse_source(self) -> PulseSource:
        """What makes each shot's pulse: the closed form, or the bar model ([world.realism])."""
        if self.realism.enabled and self.realism.pulse_source == "bar":
            from hopkinson.drivers.sim.bar_source import BarPulseSource

            return BarPulseSource.mounted(self.realism.bar_mount)
        return IdealPulseSource(self.launcher.speed_m_s_per_sqrt_bar, self.launcher.velocity_transfer,
                                tuple(self.launcher.pulse_width_s), self.signals.pulse_bipolar_ratio)

    def channels(self) -> dict[str, int]:
        """role -> the simulated digitizer's channel, for the signals this world makes."""
        roles = ["doppler", "response"]
        if self.signals.quadrature:
            roles.append("doppler_quadrature")
        if self.accelerometer_2.enabled:
            roles.append("response_2")
        return {role: CHANNELS[role] for role in roles}
