"""One shot from raw channels to results: reduce → excitation → identify → FBSD → DCM.

The single entry point the rig, the campaign runner, the report and the panel share, so the
analysis of a shot is the same wherever it runs. `ShotAnalysis.to_dict()` is what shot files
store under /analysis; `ShotAnalysis.from_dict` rebuilds the model and the DCM from it.

DCM (analysis.compensation.compensate_shot): designed from the modes the shot supports, with
the automatic ratio (`dcm_ratio=None`: sized to the shot's pulse, analysis.dcm_ratio; or the r
that widens the ±5 % band `dcm_widening` times), the noise-gain bound and the band limit;
checked on the shot itself, and marked not recommended where it does not improve it or may
leave the compensated peak beyond ±5 % of the reference's.

Interferometer and sensors. `analyse_raw_shot` reduces the reference from the PM beat, or from
a quadrature interferometer's pair when its second photodetector is given (analysis.reduce);
the reduction's quantities name the method and the fitted ellipse. Further sensors recorded
with the same reference (e.g. role response_2) are each analysed like the first, against the
same reference acceleration, with their own gain and sensitivity: `ShotAnalysis.sensors`
(role -> ShotAnalysis), stored as the results' "sensors" object, while the top-level keys
stay the first sensor's, so every reader of one sensor keeps working. A further sensor whose
channel or analysis fails does not fail the first: its entry is {"error": why} and the first
sensor's warnings say so.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from hopkinson.analysis.determination import is_result, not_determined
from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.excitation import ExcitationSummary, excitation_summary
from hopkinson.analysis.findings import texts
from hopkinson.analysis.identify import Identification, identify, identify_with_sine
from hopkinson.analysis.key_figures import main_mode_of
from hopkinson.analysis.model import DiscreteModel
from hopkinson.analysis.options import AnalysisOptions
from hopkinson.analysis.records import Record
from hopkinson.analysis.resample import resample_to_rate
from hopkinson.analysis.response import fbsd_bounds, fbsd_hz, model_output, pole_analysis
from hopkinson.analysis.sine_comparison import SineCalibration, read_sine_calibration
from hopkinson.analysis.sine_joint import with_draws
from hopkinson.analysis.uncertainty import shot_uncertainty

if TYPE_CHECKING:  # the DCM's modules import scipy.signal: loaded where a DCM is made or read, so
    # `hopkinson identify` (which makes none) starts without them
    from hopkinson.analysis.dcm import DCM

# Keys of the results' "dcm" object that come from analysis.compensation.
COMPENSATION_KEYS = ("target_widening", "reached_widening", "widening_note", "sized_to", "predicted_peak_error_pct",
                     "noise_gain", "noise_gain_limit", "band_limit_hz", "band_limit_reason", "latency_s", "recommended",
                     "not_recommended_reason", "check", "compensated_peak")


@dataclass
class ShotAnalysis:
    """Everything the analysis found for one shot."""

    params: AnalysisOptions
    record: Record | None  # the two-channel record at the analysis rate (None when rebuilt from a dict)
    reduction: dict[str, Any] | None  # shock quantities of the interferometer reduction
    excitation: ExcitationSummary | dict[str, Any]
    identification: Identification | dict[str, Any]
    model: DiscreteModel
    fbsd_hz: dict[str, float]
    pole_analysis: list[dict[str, Any]]
    dcm: DCM
    compensated_fbsd_hz: dict[str, float]
    rise_time_ratio: float
    settling_time_ratio: float | None = None  # ±5 % settling, uncompensated ÷ compensated
    peak_overshoot: float | None = None  # model's peak response ÷ (DC gain × peak reference)
    warnings: list[str] = field(default_factory=list)
    # the DCM's design figures, its check on the shot and the verdict (ShotCompensation.to_dict)
    compensation: dict[str, Any] = field(default_factory=dict)
    # analysis.uncertainty's JSON (None: switched off or failed, with a warning)
    uncertainty: dict[str, Any] | None = None
    fbsd_bounds: dict[str, dict[str, Any]] = field(default_factory=dict)  # edges beyond the supported band
    # further sensors against the same reference (role -> their analysis), and why one has none
    sensors: dict[str, ShotAnalysis] = field(default_factory=dict)
    sensor_errors: dict[str, str] = field(default_factory=dict)
    # the quasi-static gain at the amplitude it is measured at (analysis.static_gain; what the linearity
    # is fitted to), or {"not_determined": why}; None for results written before it
    static_gain: dict[str, Any] | None = None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready results (stored in shot files, printed by --json); a "sensors" object
        (role -> results, or {"error": why}) only when further sensors were analysed. Beside the
        figures: "not_determined" (figure -> why the shot does not determine it) and "result"
        (whether the shot is a result at all: analysis.determination)."""
        out = self._own_dict()
        out["not_determined"] = not_determined(out)
        valid, why = is_result(out["not_determined"])
        out["result"] = {"valid": valid, "reason": why}
        if self.sensors or self.sensor_errors:
            out["sensors"] = {**{role: a.to_dict() for role, a in self.sensors.items()},
                              **{role: {"error": why} for role, why in self.sensor_errors.items()}}
        return out

    def _own_dict(self) -> dict[str, Any]:
        ident = self.identification
        exc = self.excitation
        main = main_mode_of(ident) if isinstance(ident, dict) else ident.main_mode
        f_n = main["natural_frequency_hz"] if main else None
        return {
            "params": self.params.to_dict(),
            "reduction": self.reduction,
            "excitation": exc if isinstance(exc, dict) else exc.to_dict(f_n),
            "identification": ident if isinstance(ident, dict) else ident.to_dict(),
            "model": self.model.to_dict(),
            "fbsd_hz": dict(self.fbsd_hz),
            "fbsd_bounds": {k: dict(v) for k, v in self.fbsd_bounds.items()},
            "uncertainty": self.uncertainty,
            "pole_analysis": self.pole_analysis,
            "dcm": {
                **self.dcm.to_dict(),
                **self.compensation,
                "compensated_fbsd_hz": dict(self.compensated_fbsd_hz),
                "rise_time_ratio": self.rise_time_ratio,
                "settling_time_ratio": self.settling_time_ratio,
            },
            "peak_overshoot": self.peak_overshoot,
            "static_gain": self.static_gain,
            "warnings": list(self.warnings),
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any], record: Record | None = None,
                  sensor_records: Mapping[str, Record] | None = None) -> ShotAnalysis:
        """Rebuild from `to_dict()` output (e.g. a shot file): model and DCM become objects again;
        further sensors too (their records from `sensor_records`, by role, when given)."""
        sensors: dict[str, ShotAnalysis] = {}
        sensor_errors: dict[str, str] = {}
        for role, results in (data.get("sensors") or {}).items():
            if isinstance(results, dict) and "error" in results and "model" not in results:
                sensor_errors[role] = str(results["error"])
            else:
                sensors[role] = cls.from_dict(results, (sensor_records or {}).get(role))
        try:
            params = AnalysisOptions.from_dict(data["params"], ignore_unknown=True)
            model = DiscreteModel.from_dict(data["model"], source="shot analysis")
            from hopkinson.analysis.dcm import DCM

            dcm = DCM.from_dict(data["dcm"], source="shot analysis DCM")
            return cls(
                params=params, record=record, reduction=data.get("reduction"),
                excitation=data["excitation"], identification=data["identification"], model=model,
                fbsd_hz=dict(data["fbsd_hz"]), pole_analysis=list(data["pole_analysis"]), dcm=dcm,
                compensated_fbsd_hz=dict(data["dcm"]["compensated_fbsd_hz"]),
                rise_time_ratio=float(data["dcm"]["rise_time_ratio"]),
                settling_time_ratio=data["dcm"].get("settling_time_ratio"),
                peak_overshoot=data.get("peak_overshoot"), warnings=list(data.get("warnings", [])),
                compensation={k: data["dcm"][k] for k in COMPENSATION_KEYS if k in data["dcm"]},
                uncertainty=data.get("uncertainty"), fbsd_bounds=dict(data.get("fbsd_bounds") or {}),
                sensors=sensors, sensor_errors=sensor_errors, static_gain=data.get("static_gain"),
            )
        except (KeyError, TypeError) as exc:
            raise AnalysisError(f"shot analysis results are incomplete: missing {exc}") from None

    @property
    def shock_sensitivity(self) -> float | None:
        """Peak response ÷ peak reference (ISO 16063-13), when reduced from raw channels."""
        return None if self.reduction is None else self.reduction.get("shock_sensitivity")


@dataclass(frozen=True)
class ModelWithUncertainty:
    """The identified model and its Monte Carlo uncertainty: what `hopkinson identify` reports
    and what a shot's analysis goes on from."""

    identification: Identification
    uncertainty: dict[str, Any] | None  # analysis.uncertainty's JSON (None: switched off or failed)
    model_draws: list[DiscreteModel]  # the Monte Carlo's models (empty without the uncertainty)
    warnings: list[str]  # the identification's and the uncertainty's, in that order

    def to_dict(self) -> dict[str, Any]:
        """The model file's JSON (`hopkinson identify`'s, docs/files-and-formats.md): the
        identification, its FBSD (edges beyond the supported band as bounds), the pole analysis,
        the uncertainty and the warnings."""
        ident = self.identification
        edges = fbsd_hz(ident.model)
        return {**ident.to_dict(), "fbsd_hz": edges, "fbsd_bounds": fbsd_bounds(edges, ident.supported_band_hz),
                "pole_analysis": pole_analysis(ident.poles), "uncertainty": self.uncertainty,
                "warnings": list(self.warnings)}


def identify_with_uncertainty(record: Record, params: AnalysisOptions, reduction: dict[str, Any] | None = None,
                              sine: SineCalibration | None = None) -> ModelWithUncertainty:
    """Identify the model of `record` (with `sine`: fitted with that sinusoidal calibration) and
    evaluate its uncertainty (`reduction`: the interferometer's shock quantities, whose
    uncertainty it also gives). The one sequence of the shot analysis, `hopkinson identify` and
    the panel."""
    ident = identify(record, params) if sine is None else identify_with_sine(record, sine, params)
    return with_uncertainty(ident, params, reduction)


def with_uncertainty(ident: Identification, params: AnalysisOptions, reduction: dict[str, Any] | None = None
                     ) -> ModelWithUncertainty:
    """`ident` with its Monte Carlo uncertainty (`identify_with_uncertainty`'s second half: for
    an identification already at hand)."""
    warnings = list(ident.warnings)
    uncertainty, model_draws, found = shot_uncertainty(ident, params, reduction)
    warnings += [text for text in texts(found) if text not in warnings]
    order = (uncertainty or {}).get("order") or {}
    if order.get("draws"):  # the order choice's stability, measured by the draws
        ident = ident.with_order_stability(order["draws"], order["fraction_by_order"])
    ident = with_draws(ident, model_draws)  # the sine's consistency with the model's uncertainty (when fitted with one)
    return ModelWithUncertainty(ident, uncertainty, model_draws, warnings)


def analyse_record(record: Record, params: AnalysisOptions | None = None,
                   reduction: dict[str, Any] | None = None) -> ShotAnalysis:
    """Analyse a two-channel record (reference m/s², response in any unit)."""
    params = AnalysisOptions() if params is None else params
    params.check()
    sine = read_sine_calibration(params.sine_calibration) if params.sine_calibration else None
    fitted = identify_with_uncertainty(record, params, reduction, sine)
    ident, uncertainty, model_draws, warnings = fitted.identification, fitted.uncertainty, fitted.model_draws, \
        list(fitted.warnings)
    model = ident.model
    exc = excitation_summary(record.reference, record.sample_interval_s, record.start_time_s)
    # imported here: `hopkinson identify` never needs the static gain
    from hopkinson.analysis.static_gain import static_gain

    static, why_not = static_gain(ident, model_draws)
    # DCM section (H4): design, check on the shot, verdict; the design's figures join "dcm".
    from hopkinson.analysis.compensation import compensate_shot
    from hopkinson.analysis.dcm_figures import compare_steps

    # the seed the Monte Carlo used (drawn fresh and stored where none was asked), so that a
    # re-analysis with the stored seed gives the compensated peak's interval again
    seed = params.seed if params.seed is not None else (uncertainty or {}).get("seed")
    compensation = compensate_shot(ident, record, params, draws=model_draws, seed=seed)
    warnings += compensation.warnings
    dcm, comp = compensation.design.dcm, compensation.design.compensated_fbsd_hz
    steps = compare_steps(model, dcm)  # one simulation for both ratios
    rtr = steps.rise_time_ratio()
    settling = steps.settling_time_ratio()
    if settling <= 1:
        warnings.append(f"the DCM does not shorten the ±5 % settling time (ratio {settling:.2f}): choose a larger "
                        "ratio r or a band widening")
    # The model runs at its own (analysis) rate: the reference is brought to it first.
    overshoot = peak_overshoot(model, resample_to_rate(record, 1.0 / model.sample_interval_s).reference)
    if overshoot > 1.02:
        warnings.append(
            f"the pulse excites the sensor's resonance: its peak response is {overshoot:.3f}× the DC gain times "
            "the peak reference, so a peak-ratio shock sensitivity (ISO 16063-13) reads that much high; the "
            "model's DC gain is the sensitivity without the overshoot (or use a longer pulse)"
        )
    report = fitted.to_dict()
    return ShotAnalysis(
        params=params, record=record, reduction=reduction, excitation=exc, identification=ident, model=model,
        fbsd_hz=report["fbsd_hz"], pole_analysis=report["pole_analysis"], dcm=dcm, compensated_fbsd_hz=comp,
        rise_time_ratio=float(rtr), settling_time_ratio=float(settling), peak_overshoot=overshoot,
        warnings=warnings, compensation=compensation.to_dict(), uncertainty=uncertainty,
        fbsd_bounds=report["fbsd_bounds"],
        static_gain=static.to_dict() if static is not None else {"not_determined": why_not},
    )


def peak_overshoot(model: DiscreteModel, reference_m_s2: np.ndarray) -> float:
    """How much the model's response to this reference peaks above DC gain × peak reference.

    1.0 for a pulse too slow to excite the sensor's dynamics; a lightly damped sensor hit by a
    short pulse rings above it, and a peak-ratio shock sensitivity inherits the excess.
    """
    predicted = model_output(model, reference_m_s2)
    peak_in = float(np.max(np.abs(reference_m_s2)))
    if peak_in == 0 or model.dc_gain == 0:
        return float("nan")
    return float(np.max(np.abs(predicted)) / (abs(model.dc_gain) * peak_in))


def analyse_raw_shot(doppler_v: np.ndarray, response_v: np.ndarray, sample_interval_s: float,
                     params: AnalysisOptions | None = None, *, quadrature_v: np.ndarray | None = None,
                     more_sensors: Mapping[str, tuple[np.ndarray, AnalysisOptions]] | None = None,
                     full_scale_v: Mapping[str, tuple[float, float]] | None = None) -> ShotAnalysis:
    """Reduce the raw channels (PM beat, or the quadrature pair with `quadrature_v`; amplifier
    volts) to a record, then analyse it. `more_sensors`: role -> (volts, that sensor's
    AnalysisOptions: its amp_gain and sensitivity; the reference's constants are `params`'),
    each analysed like the first against the same reference (module docstring).
    `full_scale_v`: role -> the digitizer's full scale in volts (analysis.full_scale.
    full_scale_volts from the shot file's code_min/code_max): a channel with samples there is
    refused as clipped; without it clipping is not judged here (the rig judged the shot)."""
    # the demodulation imports scipy.signal: loaded for raw shots only (`hopkinson identify` reads a record)
    from hopkinson.analysis.reduce import (
        SensorChannel,
        check_carries_pulse,
        check_sensor_channel,
        reduce_sensors,
    )

    params = AnalysisOptions() if params is None else params
    source = "raw shot"
    channels = {"response": SensorChannel(response_v, params.amp_gain, params.sensitivity_v_per_m_s2)}
    errors: dict[str, str] = {}
    own_params: dict[str, AnalysisOptions] = {}
    for role, (volts, own) in (more_sensors or {}).items():
        channel = SensorChannel(volts, own.amp_gain, own.sensitivity_v_per_m_s2)
        try:
            own.check()
            check_sensor_channel(role, channel, np.asarray(doppler_v).size, source, (full_scale_v or {}).get(role))
            check_carries_pulse(role, np.asarray(volts, dtype=float).ravel(), doppler_v, source)
        except AnalysisError as exc:
            errors[role] = str(exc)
        else:  # the reference's constants are the first sensor's
            channels[role] = channel
            own_params[role] = dataclasses.replace(own, grating_pitch_m=params.grating_pitch_m, orders=params.orders,
                                                   sample_rate_hz=params.sample_rate_hz,
                                                   sine_calibration=None)  # the first sensor's sine is not its
    reduced = reduce_sensors(doppler_v, channels, sample_interval_s, quadrature_v=quadrature_v,
                             grating_pitch_m=params.grating_pitch_m, orders=params.orders,
                             sample_rate_hz=params.sample_rate_hz, source=source, full_scale_v=full_scale_v)
    first = reduced.pop("response")
    first.check_direction_known(source)
    analysis = analyse_record(first.record, params, reduction=first.quantities())
    for role, reduction in reduced.items():
        try:
            analysis.sensors[role] = analyse_record(reduction.record, own_params[role],
                                                    reduction=reduction.quantities())
        except (ArithmeticError, ValueError, np.linalg.LinAlgError) as exc:
            errors[role] = f"analysis failed: {exc}"
    analysis.sensor_errors.update(errors)
    analysis.warnings.extend(f"sensor {role} not analysed: {why}" for role, why in errors.items())
    return analysis
