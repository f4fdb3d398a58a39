"""The options of one shot's analysis: rig constants, identification, uncertainty, DCM.

`AnalysisParams` travels end to end (sequencer, campaign, shot file /analysis/params, the
panel): `check()` validates every field and names the option that is wrong (the sequencer
calls it before FIRE, so a bad option never costs a shot); `to_dict()` / `from_dict()` are
its JSON form. Light on purpose: no NumPy or SciPy at import (the rig imports it early).

Reference-chain uncertainties (GUM: relative standard uncertainties, k = 1) are the lab's
own, from its calibration certificates; the defaults are typical values, documented in
config/rig.toml [uncertainty] and the README, and are meant to be replaced:
- grating pitch d: a holographic grating's period is certified to about 1e-4;
- interferometer: beat-frequency demodulation and beam alignment (cosine error), 5e-4;
- amplifier gain: a calibrated bridge amplifier, 2e-3;
- digitizer gain: the response channel's vertical gain after calibration, 2e-3;
- channel skew: timing skew between the two channels, 1 ns.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from typing import Any

from hopkinson.analysis.errors import AnalysisError

DEFAULT_ANALYSIS_RATE_HZ = 1e6
# The order test's level: a higher order must beat a lower one beyond chance at this level
# (analysis.order_choice; docs/decisions/0011).
SIGNIFICANCE = 0.01
DEFAULT_GRATING_PITCH_M = 2.0e-6  # the simulated rig's grating (drivers/sim/doppler_beat.py)
# The DCM's defaults and the rules its options obey live here, once: analysis.dcm_design's
# DcmOptions and AnalysisParams.check() both apply `dcm_option_problem`, so the rig's check
# before FIRE refuses exactly what the design would refuse after it.
# DCM: None sizes the compensated band to the shot's pulse (analysis.dcm_ratio); a number W aims for
# W × the model's ±5 % band instead.
DEFAULT_DCM_WIDENING: float | None = None
DEFAULT_DCM_NOISE_GAIN_LIMIT = 4.0  # DCM white-noise RMS gain allowed (12 dB; analysis.dcm_design)
DEFAULT_DCM_DAMPING = 0.707  # ζ_e of the DCM's new poles
# Two poles closer than this (relative) are one conjugate pair (analysis.dcm.check_conjugate_pairs).
CONJUGATE_TOLERANCE = 1e-9
# Monte Carlo draws per shot (GUM-S1 §7.9: enough for the 95 % interval's ends to be stable
# to about one significant digit of the standard uncertainty; see analysis.uncertainty).
DEFAULT_DRAWS = 400
MAX_ORDER_LIMIT = 60
MAX_DRAWS = 1_000_000
MIN_DRAWS = 50  # fewer cannot locate the ends of a 95 % interval


@dataclass(frozen=True)
class IdentifyOptions:
    """What the identification may try.

    max_order: the largest order tried; order: fit exactly this order (None: the order test).
    sample_rate_hz: the analysis rate, Hz (None: the record's).
    significance: the order test's level. max_delay_samples: the largest input delay searched.
    remove_delay: False holds the delay at 0. patience: stop this many orders past the choice
    without gain (None: try every order). max_evaluations: each order's search budget.
    stability_draws: noise draws that re-run the order choice (0: none; the uncertainty does).
    """

    max_order: int = 12
    order: int | None = None
    sample_rate_hz: float | None = DEFAULT_ANALYSIS_RATE_HZ
    significance: float = SIGNIFICANCE
    max_delay_samples: int = 32
    remove_delay: bool = True
    patience: int | None = 3
    max_evaluations: int = 60
    stability_draws: int = 0

    @property
    def n_max(self) -> int:
        """The largest order the search may reach (an asked order above max_order included)."""
        return max(self.max_order, self.order or 0)


@dataclass(frozen=True)
class AnalysisParams:
    """Rig constants and analysis options for one shot."""

    grating_pitch_m: float = DEFAULT_GRATING_PITCH_M
    orders: tuple[int, int] = (1, -1)
    amp_gain: float = 1.0  # bridge amplifier gain (V/V)
    sensitivity_v_per_m_s2: float = 1.0  # accelerometer nominal sensitivity at the amplifier input
    sample_rate_hz: float = DEFAULT_ANALYSIS_RATE_HZ
    max_order: int = 12
    order: int | None = None  # None: chosen by analysis.identify's order test
    dcm_ratio: float | None = None  # None: automatic (analysis.dcm_ratio)
    dcm_damping: float = DEFAULT_DCM_DAMPING
    dcm_widening: float | None = DEFAULT_DCM_WIDENING  # None: sized to the pulse
    extra_poles: tuple[complex, ...] = ()
    # DCM noise gain (white-noise RMS gain at the analysis rate) allowed in the automatic design
    dcm_noise_gain_limit: float = DEFAULT_DCM_NOISE_GAIN_LIMIT
    dcm_band_limit_hz: float | None = None  # DCM low-pass cut-off; None: from the shot, 0: none
    # Uncertainty (analysis.uncertainty, GUM Supplement 1)
    uncertainty: bool = True
    draws: int = DEFAULT_DRAWS
    seed: int | None = None  # None: fresh draws; the seed used is stored with the result
    u_grating_pitch_rel: float = 1e-4
    u_interferometer_rel: float = 5e-4
    u_amp_gain_rel: float = 2e-3
    u_digitizer_gain_rel: float = 2e-3
    u_channel_skew_s: float = 1e-9
    # Transverse sensitivity (analysis.systematics): the sensor's stated transverse sensitivity
    # (its datasheet's limit; 5 %: the usual "< 5 %" of shock accelerometers) and the bar's
    # transverse motion share at the sensor (2 %: a well-aligned bar; a lab that has measured its
    # bar's, e.g. with a triaxial sensor, states its own). Their product bounds a Type B row of
    # the DC gain and the shock sensitivity.
    transverse_sensitivity_rel: float = 0.05
    transverse_motion_rel: float = 0.02
    # A sinusoidal calibration of the same sensor (CSV), fitted with the shock (analysis.sine_joint)
    sine_calibration: str | None = None

    @classmethod
    def from_options(cls, **options: Any) -> AnalysisParams:
        """Build from keyword options, ignoring None (= default) and naming unknown keys."""
        return cls.from_dict({k: v for k, v in options.items() if v is not None})

    @classmethod
    def from_dict(cls, data: dict[str, Any], *, ignore_unknown: bool = False) -> AnalysisParams:
        """Build from `to_dict()` output (or a plan's options); unknown keys are an error unless
        `ignore_unknown` (reading results written by another version). Values are checked."""
        if not isinstance(data, dict):
            raise AnalysisError(f"analysis options must be a table of names and values, got {type(data).__name__}")
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown and not ignore_unknown:
            raise AnalysisError(
                f"unknown analysis option(s): {', '.join(unknown)}; known: {', '.join(sorted(known))}"
            )
        values = {k: v for k, v in data.items() if k in known}
        try:
            if "orders" in values:
                values["orders"] = tuple(int(o) for o in values["orders"])
            if "extra_poles" in values:
                values["extra_poles"] = tuple(_complex(p) for p in values["extra_poles"] or ())
        except (TypeError, ValueError):
            raise AnalysisError("analysis option orders / extra_poles: expected a list of numbers") from None
        params = cls(**values)
        params.check()
        return params

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: tuples as lists, complex poles as [re, im]."""
        d = asdict(self)
        d["orders"] = list(self.orders)
        d["extra_poles"] = [[p.real, p.imag] for p in self.extra_poles]
        return d

    def check(self) -> None:
        """Raise AnalysisError naming the first option whose value cannot be used."""
        _finite(self.grating_pitch_m, "grating_pitch_m", above=0.0, at_most=1e-3)
        if len(self.orders) != 2 or not all(_is_int(o) for o in self.orders) or self.orders[0] == self.orders[1]:
            raise AnalysisError(f"analysis option orders: two different integer diffraction orders, got {self.orders!r}")
        _finite(self.amp_gain, "amp_gain", nonzero=True)
        _finite(self.sensitivity_v_per_m_s2, "sensitivity_v_per_m_s2", nonzero=True)
        _finite(self.sample_rate_hz, "sample_rate_hz", above=0.0, at_most=1e10)
        _integer(self.max_order, "max_order", 1, MAX_ORDER_LIMIT)
        if self.order is not None:
            _integer(self.order, "order", 1, MAX_ORDER_LIMIT)
        problem = dcm_option_problem(self.dcm_ratio, self.dcm_damping, self.dcm_widening, self.dcm_noise_gain_limit,
                                     self.dcm_band_limit_hz, self.extra_poles, 0.5 * self.sample_rate_hz)
        if problem is not None:
            option, need = problem
            raise AnalysisError(f"analysis option {option}: {need}, got {_shown(getattr(self, option))}")
        if not isinstance(self.uncertainty, bool):
            raise AnalysisError(f"analysis option uncertainty: true or false, got {self.uncertainty!r}")
        _integer(self.draws, "draws", MIN_DRAWS, MAX_DRAWS)
        if self.seed is not None:
            _integer(self.seed, "seed", 0, 2**63 - 1)
        for name in ("u_grating_pitch_rel", "u_interferometer_rel", "u_amp_gain_rel", "u_digitizer_gain_rel"):
            _finite(getattr(self, name), name, at_least=0.0, at_most=0.5)
        _finite(self.u_channel_skew_s, "u_channel_skew_s", at_least=0.0, at_most=1e-3)
        for name in ("transverse_sensitivity_rel", "transverse_motion_rel"):
            _finite(getattr(self, name), name, at_least=0.0, at_most=1.0)
        if self.sine_calibration is not None and not (isinstance(self.sine_calibration, str) and self.sine_calibration):
            raise AnalysisError(f"analysis option sine_calibration: a file name, got {self.sine_calibration!r}")

    def identify_options(self) -> IdentifyOptions:
        """What analysis.identify may try, from these options."""
        return IdentifyOptions(max_order=self.max_order, order=self.order, sample_rate_hz=self.sample_rate_hz)

    def reference_chain(self) -> dict[str, float]:
        """Relative standard uncertainties of the reference chain, by source name."""
        return {
            "grating pitch": self.u_grating_pitch_rel,
            "interferometer": self.u_interferometer_rel,
            "amplifier gain": self.u_amp_gain_rel,
            "digitizer gain": self.u_digitizer_gain_rel,
        }


def dcm_option_problem(
    ratio: Any, damping: Any, widening: Any, noise_gain_limit: Any, band_limit_hz: Any, extra_poles: Any,
    nyquist_hz: float | None = None,
) -> tuple[str, str] | None:
    """The first DCM option the design refuses, as (AnalysisParams field, what it must be), or None.

    The rules of analysis.dcm.design_dcm and analysis.dcm_design (DcmOptions, the band limit):
    ratio None (automatic) or a finite number > 0; damping ζ_e in (0, 1]; widening None (sized
    to the pulse) or a finite number > 1; noise gain limit > 0 (inf: no bound); band limit None (from the shot), 0
    (none) or a finite frequency below Nyquist (`nyquist_hz`, when known); extra poles
    finite, inside the unit circle, each complex one with its conjugate. (How many extra
    poles fit depends on the model's poles: only the design can tell.)"""
    if ratio is not None and not (_real(ratio) and math.isfinite(ratio) and ratio > 0):
        return "dcm_ratio", "a finite number above 0 (or none: automatic)"
    if not (_real(damping) and 0 < damping <= 1):
        return "dcm_damping", "the damping ratio ζ_e, a number above 0 and at most 1"
    if widening is not None and not (_real(widening) and math.isfinite(widening) and widening > 1):
        return "dcm_widening", "a finite number above 1 (or none: sized to the pulse)"
    if not (_real(noise_gain_limit) and noise_gain_limit > 0):
        return "dcm_noise_gain_limit", "a number above 0 (inf: no bound)"
    if band_limit_hz is not None:
        if not (_real(band_limit_hz) and math.isfinite(band_limit_hz) and band_limit_hz >= 0):
            return "dcm_band_limit_hz", "a frequency of at least 0 Hz (0: none; none: from the shot)"
        if nyquist_hz is not None and band_limit_hz > 0 and not band_limit_hz < nyquist_hz:
            return "dcm_band_limit_hz", f"a frequency below Nyquist ({nyquist_hz:g} Hz at the analysis rate)"
    poles = list(extra_poles)
    for p in poles:
        if not (isinstance(p, (complex, float, int)) and not isinstance(p, bool)
                and math.isfinite(complex(p).real) and math.isfinite(complex(p).imag) and abs(p) < 1.0):
            return "extra_poles", f"finite poles inside the unit circle ({p!r} is not)"
    unmatched = [complex(p) for p in poles if abs(complex(p).imag) > CONJUGATE_TOLERANCE * max(1.0, abs(p))]
    while unmatched:
        x = unmatched.pop(0)
        partner = next((i for i, y in enumerate(unmatched)
                        if abs(y - x.conjugate()) <= CONJUGATE_TOLERANCE * max(1.0, abs(x))), None)
        if partner is None:
            return "extra_poles", f"both members of every complex pair ({x!r} has no conjugate partner)"
        unmatched.pop(partner)
    return None


def _real(value: Any) -> bool:
    """An int or float that is not NaN (bool is not a number here)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) and not math.isnan(value)


def _shown(value: Any) -> str:
    if isinstance(value, tuple):
        return "[" + ", ".join(repr(v) for v in value) + "]"
    return repr(value)


def _complex(p: Any) -> complex:
    if isinstance(p, complex):
        return p
    if isinstance(p, (list, tuple)) and len(p) == 2:
        return complex(float(p[0]), float(p[1]))
    return complex(p)


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _integer(value: Any, name: str, low: int, high: int) -> None:
    if not _is_int(value) or not low <= value <= high:
        raise AnalysisError(f"analysis option {name}: an integer from {low} to {high}, got {value!r}")


def _finite(
    value: Any,
    name: str,
    *,
    above: float | None = None,
    at_least: float | None = None,
    at_most: float | None = None,
    nonzero: bool = False,
) -> None:
    """A real finite number within the bounds, or AnalysisError naming the option."""
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
    if ok and above is not None and not value > above:
        ok = False
    if ok and at_least is not None and not value >= at_least:
        ok = False
    if ok and at_most is not None and not value <= at_most:
        ok = False
    if ok and nonzero and value == 0:
        ok = False
    if ok:
        return
    bounds = []
    if above is not None:
        bounds.append(f"above {above:g}")
    if at_least is not None:
        bounds.append(f"at least {at_least:g}")
    if at_most is not None:
        bounds.append(f"at most {at_most:g}")
    if nonzero:
        bounds.append("non-zero")
    need = "a finite number" + (f" ({', '.join(bounds)})" if bounds else "")
    raise AnalysisError(f"analysis option {name}: {need}, got {value!r}")
