"""One shot as asked for and as it ended, and the shot pipeline after the capture:
raw data stored first (atomically), then analysed; an analysis failure is recorded in the
file and never loses the shot.

- ShotRequest: what to fire (pressure, projectile), who and what is calibrated, the analysis
  options asked over the configuration's (`analysis`, analysis.options.AnalysisOverrides), where the file goes, and how long ARM waits
  for the fire confirmation.
- ShotOutcome: how it ended (final state, file, results, error, exit code, the state it was
  aborted in, whether the fire command was sent). `raise_for_outcome()` raises ShotAborted
  with the one-line message for exit code 3.
- CapturedShot: what the digitizer recorded, by role (doppler, response, optional
  doppler_quadrature, response_2), codes in their native type.
- analyse_raw / shot_analyser: the channels by role to the shared shot analysis: the reference
  from the quadrature pair when there is a doppler_quadrature channel (else the PM beat), and a
  response_2 channel analysed like the first sensor with the rig's [analysis] amp_gain_2 and
  sensitivity_2_v_per_m_s2; its record's response is stored as /derived/response_2_<unit>.
- store_raw_shot / analyse_and_record: the STORE and ANALYSE steps, shared by the sequencer
  and a campaign analysing a recorded shot from its file.
- Clipping: a channel is clipped only when samples reach the digitizer's full scale (the
  format's full-scale codes, `Waveform.code_range`, stored with the shot as code_min/code_max),
  never judged from the record's own extremes. The analysis judges it (`RawShot.full_scale_v`
  passed as analysis.shot_analysis's `full_scale_v`), the same way for a shot just fired and
  for one re-analysed from its file: a clipped reference or response fails the analysis
  naming the channel (the shot is kept), a clipped further sensor is that sensor's error. An
  amplifier that reported an overload during the shot: not analysed, with the reason.

Analysis failures. When the analysis raises (bad data, a fit the data cannot support, a
bug), the shot file keeps its raw data and gets an /analysis group with status "failed" and
the error text; the shot still ends DONE (it was fired and recorded) with
`ShotOutcome.analysis_error` set and exit code 4 (EXIT_ANALYSIS_FAILED, docs/exit-codes.md):
a script never takes it for a calibration that worked.
"""

from __future__ import annotations

import dataclasses
import math
import uuid
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.options import AnalysisOptions, AnalysisOverrides
from hopkinson.analysis.records import Record
from hopkinson.drivers.digitizer import Waveform
from hopkinson.rig.config import RigConfig
from hopkinson.rig.errors import EXIT_ABORTED as EXIT_ABORTED  # re-exported: the shot's exit codes
from hopkinson.rig.errors import EXIT_ANALYSIS_FAILED as EXIT_ANALYSIS_FAILED
from hopkinson.rig.errors import EXIT_DONE, ConfigError, ShotAborted
from hopkinson.rig.shotfile import (
    PLAIN_NAME_RE,
    RawChannel,
    RawShot,
    ShotFileError,
    ShotMeta,
    sensor_response_name,
)
from hopkinson.rig.shotfile_writer import add_analysis, write_raw_shot

QUADRATURE_ROLE = "doppler_quadrature"
PROJECTILES = (1, 2, 3)  # the projectiles the rig's loader takes
MORE_SENSOR_ROLES = ("response_2",)  # sensors analysed like the first ("response"), in this order
# What a sensor's data sheet states that the budget carries (analysis.systematics): a plan's
# [accelerometer] or the panel gives them, the rig config's [uncertainty] where neither does; a
# shot file records them under their own keys in its settings (rig.reanalysis reads them back).
SENSOR_STATED = ("transverse_sensitivity_rel", "asymmetry_bound_rel")
# The second sensor's (response_2) are the rig config's [analysis] keys, beside its gain and
# sensitivity (the snapshot in its shot files keeps them): SENSOR_STATED's option -> its key.
SECOND_SENSOR_STATED = {"transverse_sensitivity_rel": "transverse_sensitivity_2_rel",
                        "asymmetry_bound_rel": "asymmetry_bound_2_rel"}
# The sensor's own options (its nominal sensitivity, its sine calibration, what it states) and
# the order of the options the first shot files' settings recorded.
SENSOR_OPTIONS = ("sensitivity_v_per_m_s2", "sine_calibration", *SENSOR_STATED)
RECORDED_FIRST = ("max_order", "order", "sample_rate_hz", "dcm_ratio", "dcm_damping", "uncertainty", "draws")


def sensor_stated(sensor: Any) -> dict[str, float | None]:
    """What `sensor` (a plan's [accelerometer]) states of SENSOR_STATED, as analysis options
    (None: not stated there)."""
    return {name: getattr(sensor, name) for name in SENSOR_STATED}


class ShotRequestError(ConfigError):
    """A shot request that cannot be fired as asked (exit code 2, nothing was done)."""


@dataclass(frozen=True)
class ShotRequest:
    """What to fire and how to analyse it (None = the rig configuration's value)."""

    pressure_bar: float
    projectile: int = 3
    operator: str = ""
    accelerometer_model: str = ""
    accelerometer_serial: str = ""
    # further sensors' identities, recorded with the shot: role (MORE_SENSOR_ROLES) -> {"model", "serial"}
    sensor_identities: dict[str, dict[str, str]] = field(default_factory=dict)
    # the analysis options asked over the rig configuration's (analysis.options; None: not given)
    analysis: AnalysisOverrides = field(default_factory=AnalysisOverrides)
    out_dir: Path = Path("shots")
    shot_name: str | None = None  # None -> "shot-<UTC time>-<8 hex>"
    campaign_id: str | None = None
    campaign_uuid: str | None = None  # the campaign's identity (rig.journal), recorded in the shot file
    shot_id: str | None = None
    shot_index: int | None = None
    confirm_timeout_s: float | None = None  # how long ARM waits for the fire confirmation; None -> timeouts.arm_s
    # automatic level control: the target and how the pressure was chosen (rig.level_control.
    # LevelChoice.to_dict), recorded in the shot file's settings ("level_control")
    level: dict[str, Any] | None = None
    # the sensor's own sensitivity unit (analysis.sensitivity_units; None: the analysis' SI value,
    # shown in µV/(m/s²)) and its tolerance on the nominal (per cent), recorded in the shot
    # file's settings ("sensitivity_unit", "sensitivity_tolerance_percent") for its verdict
    sensitivity_unit: str | None = None
    tolerance_percent: float | None = None

    def check(self, config: RigConfig) -> None:
        """Raise ShotRequestError (naming the field and the reason) unless the request is firable."""
        limits = config.limits
        p = self.pressure_bar
        if not (isinstance(p, int | float) and math.isfinite(p)):
            raise ShotRequestError(f"pressure_bar: must be a number, got {p!r}")
        if not limits.min_pressure_bar <= p <= limits.max_pressure_bar:
            raise ShotRequestError(f"pressure_bar: {p:g} bar is outside the rig's limits "
                                   f"{limits.min_pressure_bar:g} .. {limits.max_pressure_bar:g} bar "
                                   f"({config.path or 'configuration'} [limits])")
        if self.projectile not in PROJECTILES or isinstance(self.projectile, bool):
            raise ShotRequestError(f"projectile: must be 1, 2 or 3, got {self.projectile!r}")
        try:  # every analysis option, before anything moves (the amplifier gain is read back later)
            analysis_params(self, config, {})
        except AnalysisError as exc:
            raise ShotRequestError(str(exc)) from None
        if self.analysis.sine_calibration is not None:  # readable as a sine calibration, before anything moves
            from hopkinson.analysis.sine_comparison import read_sine_calibration

            try:
                read_sine_calibration(self.analysis.sine_calibration)
            except AnalysisError as exc:
                raise ShotRequestError(f"sine_calibration: {exc}") from None
        for role, identity in self.sensor_identities.items():
            if role not in MORE_SENSOR_ROLES:
                raise ShotRequestError(f"sensor_identities: {role!r} is not a further sensor's role "
                                       f"({', '.join(MORE_SENSOR_ROLES)})")
            if set(identity) != {"model", "serial"} or not all(isinstance(v, str) and v.strip()
                                                               for v in identity.values()):
                raise ShotRequestError(f"{role}: the accelerometer on it needs both its model and its serial number")
            if role not in config.digitizer.channels:
                raise ShotRequestError(f"{role}: an accelerometer is named for it, but the rig records no {role} "
                                       f"channel ({config.path or 'configuration'} [digitizer.channels])")
        self._check_sensor(config)
        if self.confirm_timeout_s is not None and not (
                isinstance(self.confirm_timeout_s, int | float) and 0 <= self.confirm_timeout_s <= 3600):
            raise ShotRequestError(f"confirm_timeout_s: must be 0..3600 s, got {self.confirm_timeout_s!r}")
        if self.shot_name is not None and not PLAIN_NAME_RE.match(self.shot_name):
            raise ShotRequestError(f"shot_name: {self.shot_name!r} is not a plain file name "
                                   "(letters, digits, '_', '.', '-')")
        if not Path(self.out_dir).is_dir():
            raise ShotRequestError(f"out_dir: {self.out_dir} is not an existing folder")

    def _check_sensor(self, config: RigConfig) -> None:
        """The sensitivity unit known and the nominal plausible in it; the tolerance 0..100 %."""
        if self.sensitivity_unit is not None:
            from hopkinson.analysis.sensitivity_units import check_plausible, sensitivity_unit

            try:
                unit = sensitivity_unit(self.sensitivity_unit)
                check_plausible(unit.from_si(self.sensitivity(config)), unit)
            except ValueError as exc:
                raise ShotRequestError(f"sensitivity: {exc}") from None
        t = self.tolerance_percent
        if t is not None and not (isinstance(t, int | float) and 0 < t < 100):
            raise ShotRequestError(f"tolerance_percent: must be between 0 and 100 %, got {t!r}")

    def shot_path(self) -> Path:
        """Where the shot file goes: out_dir / <shot_name or a generated name>.h5."""
        name = self.shot_name or generated_shot_name()
        return Path(self.out_dir) / f"{name}.h5"

    def sensitivity(self, config: RigConfig) -> float:
        """The nominal sensitivity, V/(m/s²): the request's, else the configuration's [analysis]."""
        given = self.analysis.sensitivity_v_per_m_s2
        return given if given is not None else config.analysis.sensitivity_v_per_m_s2

    def recorded_options(self) -> dict[str, Any]:
        """The analysis options given, as the shot file's settings record them ("analysis_options"):
        the sensor's own left out (the sensitivity is recorded under its own key), in `RECORDED_FIRST`'s
        order first."""
        given = {k: v for k, v in self.analysis.given().items() if k not in SENSOR_OPTIONS}
        return {k: given[k] for k in RECORDED_FIRST if k in given} | given


def second_accelerometer(model: str | None, serial: str | None) -> dict[str, dict[str, str]]:
    """A second accelerometer's model and serial as ShotRequest.sensor_identities: empty when
    neither is given; one given without the other is left for ShotRequest.check to refuse."""
    model, serial = (model or "").strip(), (serial or "").strip()
    return {"response_2": {"model": model, "serial": serial}} if model or serial else {}


def generated_shot_name(now: datetime | None = None) -> str:
    """"shot-20250101T120000Z-1a2b3c4d": UTC time of the request and 8 random hex digits."""
    now = now or datetime.now(UTC)
    return f"shot-{now.strftime('%Y%m%dT%H%M%SZ')}-{uuid.uuid4().hex[:8]}"


@dataclass(frozen=True)
class ShotOutcome:
    """How a shot ended.

    final_state: "DONE", "ABORTED" or "FAULT" (FAULT: the safe state could not be confirmed).
    error: the one-line message when the shot did not complete (None when DONE).
    analysis_error: set when the shot was recorded but its analysis failed (still DONE).
    exit_code: 0 done and analysed; 4 done but the analysis failed; 3 aborted or FAULT
    (rig/errors.py EXIT_CODES); the command's exit code and its JSON's `exit_code`.
    fire_confirmed_by: what confirmed the shot was fired (None: nothing did).
    fired: the fire command was sent (the projectile may have been launched).
    aborted_in: the state in which the abort began (None when DONE).
    hint: what the operator does about it.
    """

    final_state: str
    shot_path: Path | None = None
    results: dict[str, Any] | None = None
    error: str | None = None
    exit_code: int = EXIT_DONE
    aborted_in: str | None = None
    fired: bool = False
    fire_confirmed_by: str | None = None
    analysis_error: str | None = None
    analysis_to_redo: bool = False  # interrupted or not stored: a re-analysis of the file redoes it
    safe_confirmed: bool = True
    warnings: tuple[str, ...] = ()
    hint: str = ""  # what the operator does about `error` (from its cause, never from its words)
    log_path: Path | None = None  # the shot's JSON-lines log (rig/logbook.py)

    @property
    def done(self) -> bool:
        return self.final_state == "DONE"

    def raise_for_outcome(self) -> None:
        """Raise ShotAborted (exit code 3, the one-line message) unless the shot is DONE."""
        if not self.done:
            raise ShotAborted(self.error or f"shot ended in {self.final_state}")

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (the `--json` output of `hopkinson shot`)."""
        out = asdict(self)
        out["shot_path"] = str(self.shot_path) if self.shot_path is not None else None
        out["log_path"] = str(self.log_path) if self.log_path is not None else None
        out["warnings"] = list(self.warnings)
        return out


def digitizer_channels(config: RigConfig) -> dict[str, Any]:
    """role -> the digitizer's channel for each role the rig records (doppler and response first)."""
    roles = getattr(config.digitizer, "channels", None)
    if roles:
        return dict(roles)
    return {"doppler": 1, "response": 2}  # a configuration without [digitizer.channels]


@dataclass(frozen=True)
class CapturedShot:
    """What the digitizer recorded, by role, with the settings it was recorded under."""

    channels: dict[str, Waveform]  # "doppler", "response", optional "doppler_quadrature", "response_2"
    settings: dict[str, Any] = field(default_factory=dict)  # amplifier read-back, pressure at fire, ...
    truth: dict[str, Any] | None = None  # simulated truth (simulation only)

    def raw_shot(self) -> RawShot:
        """The channels as a RawShot: codes exactly as recorded (their native type, never
        converted), their scaling and the format's full-scale codes."""
        waves = list(self.channels.values())
        first = waves[0]
        for w in waves[1:]:
            if w.codes.size != first.codes.size or w.trigger_index != first.trigger_index or not math.isclose(
                    w.sample_interval_s, first.sample_interval_s, rel_tol=1e-9):
                raise ValueError("the channels differ in length, trigger index or sample interval")
        return RawShot(
            channels={role: RawChannel(np.asarray(w.codes), float(w.scale_v), float(w.offset_v),
                                       code_range=_code_range(w))
                      for role, w in self.channels.items()},
            sample_interval_s=first.sample_interval_s,
            trigger_index=first.trigger_index,
        )


def _code_range(w: Any) -> tuple[float, float] | None:
    code_range = getattr(w, "code_range", None)
    return (float(code_range[0]), float(code_range[1])) if code_range is not None else None


def shot_meta(request: ShotRequest, config: RigConfig, identities: dict[str, str],
              captured: CapturedShot) -> ShotMeta:
    """The shot file's meta: the request's who/what, a full configuration snapshot plus the
    settings this shot ran with (under "shot_settings"), instrument identities, truth."""
    snapshot = config.snapshot()
    snapshot["shot_settings"] = dict(captured.settings,
                                     sensitivity_v_per_m_s2=request.sensitivity(config),
                                     analysis_options=request.recorded_options())
    for name in SENSOR_STATED:  # the sensor's stated ones (a plan's, the panel's)
        if getattr(request.analysis, name) is not None:
            snapshot["shot_settings"][name] = float(getattr(request.analysis, name))
    if request.level is not None:
        snapshot["shot_settings"]["level_control"] = dict(request.level)
    if request.sensitivity_unit is not None:
        snapshot["shot_settings"]["sensitivity_unit"] = request.sensitivity_unit
    if request.tolerance_percent is not None:
        snapshot["shot_settings"]["sensitivity_tolerance_percent"] = float(request.tolerance_percent)
    return ShotMeta(
        operator=request.operator,
        accelerometer_model=request.accelerometer_model,
        accelerometer_serial=request.accelerometer_serial,
        sensor_identities={role: dict(identity) for role, identity in request.sensor_identities.items()},
        pressure_bar=float(request.pressure_bar),
        projectile=int(request.projectile),
        instruments=dict(identities),
        config=snapshot,
        shot_id=request.shot_id,
        shot_index=request.shot_index,
        campaign_id=request.campaign_id,
        campaign_uuid=request.campaign_uuid,
        simulated_truth=captured.truth,
    )


def store_raw_shot(path: Path, captured: CapturedShot, meta: ShotMeta) -> Path:
    """STORE: write the raw shot atomically (tmp, flush, fsync, rename) before any analysis."""
    return write_raw_shot(path, captured.raw_shot(), meta)


RESCUE_FOLDER = "rescued-shots"  # in the user's data folder: a raw shot its own folder could not take


def rescue_raw_shot(path: Path, captured: CapturedShot, meta: ShotMeta) -> Path | None:
    """Where the shot folder could not take the raw shot (a full disk, a quota, a read-only or
    vanished folder): the same file in the user's data folder (`rescued-shots/`), so that the
    shot is not lost with the folder's failure (named after the shot, with its uuid where an
    earlier rescue took that name: never over another record); None when that fails too."""
    from hopkinson.lab.database import data_folder

    folder = data_folder() / RESCUE_FOLDER
    target = folder / path.name
    if target.exists():
        target = folder / f"{path.stem}-{meta.uuid}{path.suffix}"
    try:
        folder.mkdir(parents=True, exist_ok=True)
        return write_raw_shot(target, captured.raw_shot(), meta)
    except (OSError, ShotFileError):
        return None


@dataclass(frozen=True)
class AnalysisResult:
    """What the analysis gives back to be stored: results dict and the reduced record."""

    results: dict[str, Any]
    record: Record | None = None
    derived: dict[str, np.ndarray] = field(default_factory=dict)  # e.g. a further sensor's record response


def analysis_params(request: ShotRequest, config: RigConfig, settings: dict[str, Any]) -> AnalysisOptions:
    """Everything the analysis needs besides the channels: the rig's constants (its [analysis]
    DCM limits and [uncertainty] reference chain too), the request's options and the amplifier
    gain read back at the shot (in `settings`), checked (AnalysisError naming the option)."""
    given = config.analysis.analysis_options() | config.uncertainty.analysis_options() | request.analysis.given()
    return AnalysisOptions.from_options(**given | {
        "amp_gain": float(settings.get("amplifier_gain", config.amplifier.gain)),
        "sensitivity_v_per_m_s2": request.sensitivity(config),
    })


def sensor_params(params: AnalysisOptions, config: RigConfig) -> dict[str, AnalysisOptions]:
    """role -> the analysis parameters of each further sensor: the first sensor's, with that
    sensor's conditioner gain and nominal sensitivity ([analysis] amp_gain_2,
    sensitivity_2_v_per_m_s2) and what its own data sheet states ([analysis]
    transverse_sensitivity_2_rel, asymmetry_bound_2_rel; unset: the rig config's [uncertainty]
    values, as for any sensor that states none), never the first sensor's sine calibration or
    stated values."""
    a, rig = config.analysis, config.uncertainty.analysis_options()
    stated = {name: own if (own := getattr(a, SECOND_SENSOR_STATED[name])) is not None else rig[name]
              for name in SENSOR_STATED}
    return {"response_2": dataclasses.replace(params, amp_gain=a.amp_gain_2, sine_calibration=None,
                                              sensitivity_v_per_m_s2=a.sensitivity_2_v_per_m_s2, **stated)}


def analyse_raw(raw: RawShot, params: AnalysisOptions,
                more_params: Mapping[str, AnalysisOptions] | None = None) -> AnalysisResult:
    """ANALYSE, the computation only (pure; runs in a worker thread): the shared shot
    analysis (analysis.shot_analysis) of the raw channels in volts, by role: the quadrature
    pair when recorded, and each further sensor with its parameters from `more_params` (one
    not given there: `params` with gain and sensitivity 1, i.e. its results in volts);
    clipping judged against each channel's digitizer full scale (module docstring)."""
    from hopkinson.analysis.shot_analysis import analyse_raw_shot  # heavy: loaded when needed

    given = dict(more_params or {})
    in_volts = dataclasses.replace(params, amp_gain=1.0, sensitivity_v_per_m_s2=1.0)
    more = {role: (raw.volts(role), given.get(role, in_volts)) for role in MORE_SENSOR_ROLES if role in raw.channels}
    quadrature = raw.volts(QUADRATURE_ROLE) if QUADRATURE_ROLE in raw.channels else None
    analysis = analyse_raw_shot(raw.volts("doppler"), raw.volts("response"), raw.sample_interval_s, params,
                                quadrature_v=quadrature, more_sensors=more, full_scale_v=raw.full_scale_v())
    derived = {}
    for role, sensor in analysis.sensors.items():
        if sensor.record is not None:
            unit = (sensor.reduction or {}).get("response_unit") or "V"
            derived[sensor_response_name(role, unit)] = np.asarray(sensor.record.response, dtype=float)
    return AnalysisResult(analysis.to_dict(), analysis.record, derived)


def shot_analyser(config: RigConfig) -> AnalyseFn:
    """The analysis of a shot on this rig: `analyse_raw` with the further sensors' parameters
    from its configuration (`sensor_params`)."""
    def analyse(raw: RawShot, params: AnalysisOptions) -> AnalysisResult:
        return analyse_raw(raw, params, sensor_params(params, config))

    return analyse


def analysis_error_text(exc: BaseException) -> str:
    """The one-line error of an analysis that raised: a ValueError (bad data, a fit the data
    cannot support) says why; anything else also names its type."""
    if isinstance(exc, ValueError):
        return f"analysis failed: {exc}"
    return f"analysis failed: {type(exc).__name__}: {exc}"


def record_analysis(path: Path, outcome: AnalysisResult | None, error: str | None) -> None:
    """Store the analysis (or its failure) in the shot file, atomically; raw data untouched."""
    if error is not None:
        add_analysis(path, outcome.results if outcome is not None else {}, error=error)
    else:
        assert outcome is not None
        add_analysis(path, outcome.results, record=outcome.record, derived=outcome.derived or None)


AnalyseFn = Callable[[RawShot, AnalysisOptions], AnalysisResult]


@dataclass(frozen=True)
class WorkResult:
    """How a piece of work ran: finished (with its value or exception), or why it did not."""

    finished: bool
    value: Any = None
    error: BaseException | None = None
    why_not: str = ""


Runner = Callable[[Callable[[], Any]], WorkResult]


def run_here(work: Callable[[], Any]) -> WorkResult:
    """Run `work` in this thread (a campaign re-analysing a stored shot)."""
    try:
        return WorkResult(True, work())
    except Exception as exc:
        return WorkResult(True, error=exc)


class RecordedAnalysis(NamedTuple):
    """What ANALYSE gives: the results (None without), why there are none or what went wrong,
    and whether the analysis (or why there is none) is stored in the shot file."""

    results: dict[str, Any] | None
    error: str | None
    stored: bool = True
    finished: bool = True  # False: interrupted, abandoned or timed out (a re-analysis redoes it)

    @property
    def to_redo(self) -> bool:
        """The analysis did not run to its end or was not stored: `--resume` / `analyse` redo it."""
        return not (self.finished and self.stored)


def analyse_and_record(path: Path, raw: RawShot, params: AnalysisOptions, analyse: AnalyseFn, *,
                       amplifier_overloaded: bool = False, run: Runner = run_here
                       ) -> RecordedAnalysis:
    """ANALYSE a stored shot and record the result (or why there is none) in its file. Never
    raises for the analysis' sake: an amplifier overload, a failing (a clipped channel among
    the reasons) or unfinished analysis become the error text; a file that cannot take the
    result (a full disk) too, with `stored` False: the record is then incomplete. `run` runs
    the computation (the sequencer: a worker thread with a timeout, abandoned on abort)."""
    result: AnalysisResult | None = None
    finished = True
    if amplifier_overloaded:  # the channels' clipping is the analysis' to judge (analyse_raw)
        error: str | None = ("not analysed: the amplifier overloaded during the shot: the response is clipped "
                             "(check the accelerometer cable and the amplifier range)")
    else:
        done = run(lambda: analyse(raw, params))
        if not done.finished:
            error, finished = done.why_not, False
        elif done.error is not None:
            error = analysis_error_text(done.error)
        elif not isinstance(done.value, AnalysisResult):
            error = f"analysis failed: the analysis returned {type(done.value).__name__}, not an AnalysisResult"
        else:
            result, error = done.value, None
    try:
        record_analysis(path, result, error)
    except Exception as store_exc:
        why = str(store_exc).removeprefix(f"{path}: ")
        error = f"{error + '; ' if error else ''}the analysis could not be stored in {path} ({why})"
        return RecordedAnalysis(None, error, stored=False, finished=finished)
    return RecordedAnalysis(result.results if result is not None else None, error, finished=finished)
