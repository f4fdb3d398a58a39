"""A shot's headline numbers, computed once: the one typed object the report, the campaign,
the panel and the commands read (never the results dict itself).

`KeyFigures.from_results(results)` builds it from a results dict (`ShotAnalysis.to_dict()`,
a shot file's /analysis, old files included); `from_analysis(ShotAnalysis)` from the object.
Each uncertain figure is an `Estimate(value, u, interval)` (analysis.estimate; also named `Figure`):
the value reported everywhere, its standard uncertainty and its 95 % coverage interval (GUM
Supplement 1), u and interval None when the shot was analysed without uncertainty. Light: no NumPy at import.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import TYPE_CHECKING, Any

from hopkinson.analysis.estimate import Estimate, finite_number

if TYPE_CHECKING:
    from hopkinson.analysis.shot_analysis import ShotAnalysis

Z95 = 1.959963984540054  # the normal distribution's 95 % coverage factor
LEVELS = ("5", "10")  # FBSD band levels in per cent (keys of fbsd_hz)
# Budget rows every shot of one sensor on one rig shares (KeyFigures.shot_specific_u)
COMMON_SOURCES = ("grating pitch", "interferometer", "amplifier gain", "digitizer gain",
                  "transverse sensitivity × transverse motion")
# The name the key figures, the reports, the lab and the panel use for an Estimate
Figure = Estimate
# How the order was chosen, in words (results' order_selection: "knee" is the order test's
# stored name, kept for the files' sake)
ORDER_SELECTION_TEXT = {"order_test": "chosen by the order test", "asked": "as asked",
                        "knee": "chosen by the order test"}  # "knee": the name results stored before


@dataclass(frozen=True)
class FbsdBound:
    """An FBSD edge beyond what the shot supports: only 'above lower_bound_hz' is known."""

    lower_bound_hz: float
    reason: str


@dataclass(frozen=True)
class KeyFigures:
    """The shot's headline numbers (see the module docstring)."""

    sensitivity: Estimate  # DC gain, response units per m/s²
    response_unit: str
    shock_sensitivity: Estimate | None  # ISO 16063-13 peak ratio, response units per m/s²
    natural_frequency_hz: Estimate | None  # main mode: lowest supported complex pole pair
    damping_ratio: Estimate | None
    fbsd_hz: dict[str, Estimate]  # "5", "10": the model's edge
    fbsd_bounds: dict[str, FbsdBound]  # edges beyond the supported band (report "> bound")
    supported_band_hz: tuple[float, float] | None
    order: int | None
    order_selection: str | None
    fit_percent: float | None
    delay_s: float | None
    pulse_width_s: Estimate | None
    peak_acceleration_m_s2: Estimate | None
    peak_velocity_m_s: Estimate | None
    compensated_fbsd_hz: dict[str, float]
    dcm_recommended: bool | None
    dcm_not_recommended_reason: str | None
    compensation_check: dict[str, Any] | None
    compensated_peak: Estimate | None
    uncertainty_method: str | None
    draws: int | None
    coverage_probability: float | None
    budget: tuple[dict[str, Any], ...]
    warnings: tuple[str, ...] = field(default_factory=tuple)
    # The DCM's design figures (analysis.dcm_design): the ±5 % band widening aimed for
    # and reached (and why not), its white-noise gain and limit, its band limit, its latency.
    dcm_target_widening: float | None = None
    dcm_reached_widening: float | None = None
    dcm_widening_note: str | None = None
    dcm_noise_gain: float | None = None
    dcm_noise_gain_limit: float | None = None
    dcm_band_limit_hz: float | None = None
    dcm_latency_s: float | None = None
    # figure -> why the shot does not determine it (analysis.determination; those figures read None
    # or Estimate.undetermined), and whether the shot is a result at all (its DC gain determined)
    not_determined: dict[str, str] = field(default_factory=dict)
    is_result: bool = True
    not_a_result_reason: str = ""
    # the tension/compression asymmetry ε and the other input terms' estimates (analysis.input_terms)
    input_terms: dict[str, Any] = field(default_factory=dict)
    gain_amplitude_m_s2: float | None = None  # the amplitude the DC gain is measured at (excitation.gain_amplitude)
    # the quasi-static gain in the main pulse's direction and the amplitude it is measured at
    # (analysis.static_gain: what the amplitude linearity is fitted to; u shot-specific); None: not
    # determined (static_gain_not_determined says why) or results written before it
    static_gain: Estimate | None = None
    static_gain_amplitude_m_s2: float | None = None
    static_gain_not_determined: str | None = None

    @property
    def order_how(self) -> str:
        """How the order was chosen, in words."""
        selection = self.order_selection or "order_test"
        return ORDER_SELECTION_TEXT.get(selection, selection)

    @property
    def has_uncertainty(self) -> bool:
        return self.sensitivity.u is not None

    def shot_specific_u(self, figure: str = "dc_gain") -> float | None:
        """The standard uncertainty of `figure` (budget key: "dc_gain", …) less the Type B rows
        every shot of one sensor on one rig shares (the reference chain, the transverse row): what
        differs from shot to shot, for comparing shots (a linearity's slope, a repeatability)."""
        if figure == "static_gain":  # analysis.static_gain: shot-specific already
            return self.static_gain.u if self.static_gain is not None else None
        own = {"dc_gain": self.sensitivity, "shock_sensitivity": self.shock_sensitivity}.get(figure)
        if own is None or own.u is None or not own.value:
            return None
        common = sum((row.get("u_rel_by_figure") or {}).get(figure, 0.0) ** 2 for row in self.budget
                     if row.get("source") in COMMON_SOURCES)
        return math.sqrt(max(own.u ** 2 - common * own.value ** 2, (0.1 * own.u) ** 2))

    def fbsd_text(self, level: str, scale: float = 1e3, unit: str = "kHz") -> str:
        """'> 18 kHz (unsupported by the excitation)' for a bound, else value ± U."""
        bound = self.fbsd_bounds.get(level)
        if bound is not None:
            return f"> {bound.lower_bound_hz / scale:.3g} {unit} ({bound.reason})"
        figure = self.fbsd_hz.get(level)
        return figure.format(scale, unit=unit) if figure is not None else "—"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (Figures as {"value", "u", "interval"})."""
        out = asdict(self)
        for key in list(out):
            attr = getattr(self, key)
            if isinstance(attr, Estimate):
                out[key] = attr.to_dict()
            elif key == "fbsd_hz":
                out[key] = {k: f.to_dict() for k, f in attr.items()}
        out["supported_band_hz"] = list(self.supported_band_hz) if self.supported_band_hz else None
        out["budget"] = [dict(b) for b in self.budget]
        out["warnings"] = list(self.warnings)
        out["not_determined"] = dict(self.not_determined)
        return out

    @classmethod
    def from_analysis(cls, analysis: ShotAnalysis) -> KeyFigures:
        """From a ShotAnalysis object (the same path as a stored results dict)."""
        return cls.from_results(analysis.to_dict())

    @classmethod
    def from_results(cls, results: dict[str, Any]) -> KeyFigures:
        """From a results dict (ShotAnalysis.to_dict(), a shot file's /analysis; old files too)."""
        results = results or {}
        ident = results.get("identification") or {}
        model = results.get("model") or {}
        reduction = results.get("reduction") or {}
        excitation = results.get("excitation") or {}
        dcm = results.get("dcm") or {}
        unc = results.get("uncertainty") or {}
        unc_main = unc.get("main_mode") or {}
        unc_fbsd = unc.get("fbsd_hz") or {}

        dc_gain = finite_number(model.get("dc_gain", ident.get("dc_gain")))
        sensitivity = _figure(dc_gain, unc.get("dc_gain"))
        shock_value = finite_number(reduction.get("shock_sensitivity"))
        shock = _figure(shock_value, unc.get("shock_sensitivity")) if shock_value is not None else None

        main = main_mode_of(ident)
        f_n = _figure(finite_number(main.get("natural_frequency_hz")), unc_main.get("natural_frequency_hz")) if main else None
        zeta = _figure(finite_number(main.get("damping_ratio")), unc_main.get("damping_ratio")) if main else None

        fbsd_values = results.get("fbsd_hz") or {}
        fbsd = {k: _figure(finite_number(fbsd_values.get(k)), unc_fbsd.get(k)) for k in LEVELS if k in fbsd_values}
        bounds = {}
        for k, b in (results.get("fbsd_bounds") or {}).items():
            if isinstance(b, dict) and finite_number(b.get("lower_bound_hz")) is not None:
                bounds[str(k)] = FbsdBound(float(b["lower_bound_hz"]), str(b.get("reason", "")))
        band = ident.get("supported_band_hz")
        band_pair = (float(band[0]), float(band[1])) if isinstance(band, (list, tuple)) and len(band) == 2 else None

        dt = finite_number(model.get("sample_interval_s"))
        delay = finite_number(model.get("delay_samples", ident.get("delay_samples")))
        ref_unc = unc.get("reference") or {}
        pulse_width = finite_number(reduction.get("pulse_width_s", excitation.get("pulse_width_s")))
        peak_acc = finite_number(reduction.get("peak_acceleration_m_s2", excitation.get("peak_m_s2")))
        peak_vel = finite_number(reduction.get("peak_velocity_m_s"))
        comp = dcm.get("compensated_fbsd_hz") or {}
        undetermined = {str(k): str(v) for k, v in (results.get("not_determined") or {}).items()}
        if "dc_gain" in undetermined:
            sensitivity = Estimate.undetermined(undetermined["dc_gain"])
        if "shock_sensitivity" in undetermined:
            shock = None
        for key in ("natural_frequency_hz", "damping_ratio"):
            if key in undetermined and (f_n if key == "natural_frequency_hz" else zeta) is not None:
                if key == "natural_frequency_hz":
                    f_n = Estimate.undetermined(undetermined[key])
                else:
                    zeta = Estimate.undetermined(undetermined[key])
        for level in list(fbsd):
            if f"fbsd_{level}_hz" in undetermined and level not in bounds:
                fbsd[level] = Estimate.undetermined(undetermined[f"fbsd_{level}_hz"])
        static = results.get("static_gain") or {}
        static_value, static_u = finite_number(static.get("value")), finite_number(static.get("u"))
        static_gain = None
        if static_value is not None:
            static_gain = Estimate(static_value, static_u, None if static_u is None else
                                 (static_value - Z95 * static_u, static_value + Z95 * static_u))
        verdict = results.get("result") or {}
        warnings = list(results.get("warnings") or [])
        for w in unc.get("warnings") or []:
            if w not in warnings:
                warnings.append(w)
        return cls(
            sensitivity=sensitivity,
            response_unit=str(reduction.get("response_unit") or "response units"),
            shock_sensitivity=shock,
            natural_frequency_hz=f_n,
            damping_ratio=zeta,
            fbsd_hz=fbsd,
            fbsd_bounds=bounds,
            supported_band_hz=band_pair,
            order=_int(model.get("order", ident.get("order"))),
            order_selection=ident.get("order_selection"),
            fit_percent=finite_number(ident.get("fit_percent")),
            delay_s=delay * dt if delay is not None and dt is not None else None,
            pulse_width_s=_figure(pulse_width, ref_unc.get("pulse_width_s")) if pulse_width is not None else None,
            peak_acceleration_m_s2=_figure(peak_acc, ref_unc.get("peak_acceleration_m_s2")) if peak_acc is not None else None,
            peak_velocity_m_s=_figure(peak_vel, ref_unc.get("peak_velocity_m_s")) if peak_vel is not None else None,
            compensated_fbsd_hz={k: float(v) for k, v in comp.items() if finite_number(v) is not None},
            dcm_recommended=dcm.get("recommended"),
            dcm_not_recommended_reason=dcm.get("not_recommended_reason"),
            compensation_check=dcm.get("check"),
            compensated_peak=Estimate.of(dcm.get("compensated_peak")),
            dcm_target_widening=finite_number(dcm.get("target_widening")),
            dcm_reached_widening=finite_number(dcm.get("reached_widening")),
            dcm_widening_note=dcm.get("widening_note"),
            dcm_noise_gain=finite_number(dcm.get("noise_gain")),
            dcm_noise_gain_limit=finite_number(dcm.get("noise_gain_limit")),
            dcm_band_limit_hz=finite_number(dcm.get("band_limit_hz")),
            dcm_latency_s=finite_number(dcm.get("latency_s")),
            uncertainty_method=unc.get("method"),
            draws=_int(unc.get("draws")),
            coverage_probability=finite_number(unc.get("coverage_probability")),
            budget=tuple(dict(b) for b in unc.get("budget") or [] if isinstance(b, dict)),
            warnings=tuple(warnings),
            not_determined=undetermined,
            is_result=bool(verdict.get("valid", True)),
            not_a_result_reason=str(verdict.get("reason") or ""),
            input_terms=dict(ident.get("input_terms") or {}),
            gain_amplitude_m_s2=finite_number(excitation.get("gain_amplitude_m_s2")),
            static_gain=static_gain,
            static_gain_amplitude_m_s2=finite_number(static.get("amplitude_m_s2")) if static_gain is not None else None,
            static_gain_not_determined=str(static["not_determined"]) if static.get("not_determined") else None,
        )


def main_mode_of(identification: dict[str, Any]) -> dict[str, Any] | None:
    """The main mode of an identification dict: its `main_mode`, else (older results) the
    lowest complex pole pair not flagged unsupported. None when there is none."""
    if "main_mode" in identification:
        main = identification.get("main_mode")
        return dict(main) if isinstance(main, dict) else None
    pairs = [
        m for m in identification.get("modes") or []
        if m.get("kind") in ("complex", "pair") and m.get("supported", True) and finite_number(m.get("natural_frequency_hz"))
        and (finite_number(m.get("damping_ratio")) or 0.0) <= 0.3  # a pair damped more is no resonance (analysis.modes)
    ]
    return dict(min(pairs, key=lambda m: m["natural_frequency_hz"])) if pairs else None


def _figure(value: float | None, uncertainty: Any) -> Estimate:
    """The reported value with the uncertainty stored beside it (if any)."""
    found = Estimate.of(uncertainty) if isinstance(uncertainty, dict) else None
    return found.with_value(value) if found is not None else Estimate(value)


def _int(value: Any) -> int | None:
    return int(value) if isinstance(value, int) and not isinstance(value, bool) else None


