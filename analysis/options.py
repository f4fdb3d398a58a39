"""The options of one shot's analysis, declared once: `AnalysisOptions`.

Each option is a field with its default, unit, description and rule (`Rule`, in the field's
metadata). The same declaration serves every place options come from: the rig's config file
(rig/config_analysis.py derives its [analysis] and [uncertainty] sections from it), a campaign
plan's [defaults.analysis], the command line, the panel, the shot file (/analysis/params,
`to_dict()` / `from_dict()`), and it is what `identify(record, options)`, the uncertainty's
`evaluate(ident, options)` and the DCM's `design_compensation(support, options)` take.
`check()` (AnalysisError naming the option) runs wherever options come in from outside:
`from_dict` / `from_options` (config, plan, command line, shot file), the shot analysis, and
the DCM design for its own options (`DCM_OPTIONS`); so the sequencer's check before FIRE refuses
exactly what the analysis would refuse after it.

Light on purpose: no NumPy or SciPy at import (the rig imports it early). Reference-chain
uncertainties (GUM: relative standard uncertainties, k = 1) are the lab's own, from its
calibration certificates; the defaults are typical values (config/rig.toml [uncertainty]).
"""

from __future__ import annotations

import math
from dataclasses import MISSING, asdict, dataclass, field, fields, make_dataclass
from typing import Any

from hopkinson.analysis.errors import AnalysisError

DEFAULT_ANALYSIS_RATE_HZ = 1e6
# The order test's level: a higher order must beat a lower one beyond chance at this level
# (analysis.order_choice; docs/decisions/0011).
SIGNIFICANCE = 0.01
DEFAULT_GRATING_PITCH_M = 2.0e-6  # the simulated rig's grating (drivers/sim/doppler_beat.py)
DEFAULT_DCM_WIDENING: float | None = None  # None: the compensated band sized to the pulse (analysis.dcm_ratio)
DEFAULT_DCM_NOISE_GAIN_LIMIT = 4.0  # DCM white-noise RMS gain allowed (12 dB; analysis.dcm_design)
DEFAULT_DCM_DAMPING = 0.707  # ζ_e of the DCM's new poles
# Two poles closer than this (relative) are one conjugate pair (analysis.pole_checks.check_conjugate_pairs).
CONJUGATE_TOLERANCE = 1e-9
# Monte Carlo draws per shot (GUM-S1 §7.9: enough for the 95 % interval's ends to be stable
# to about one significant digit of the standard uncertainty; see analysis.uncertainty).
DEFAULT_DRAWS = 400
ORDER_DRAWS = 40  # draws that re-run the whole order choice (its PDF's resolution: 2.5 %)
MAX_ORDER_LIMIT = 60
MAX_DRAWS = 1_000_000
MIN_DRAWS = 50  # fewer cannot locate the ends of a 95 % interval
MAX_SEED = 2**63 - 1


@dataclass(frozen=True)
class Rule:
    """What one option's value may be.

    kind: float, int, bool or str (bool is never a number). gt / ge / le: bounds of a number.
    optional: None is allowed (what it means: the option's description). infinite: +inf is
    allowed (no bound). nonzero: 0 is refused. need: the words of the error, when the bounds
    alone do not say enough.
    """

    kind: type = float
    gt: float | None = None
    ge: float | None = None
    le: float | None = None
    optional: bool = False
    infinite: bool = False
    nonzero: bool = False
    need: str = ""

    def problem(self, value: Any) -> str | None:
        """What `value` must be, or None when it may be used."""
        if value is None:
            return None if self.optional else self.text()
        if self.kind is bool:
            return None if isinstance(value, bool) else self.text()
        if self.kind is str:
            return None if isinstance(value, str) and value else self.text()
        if isinstance(value, bool) or not isinstance(value, int if self.kind is int else (int, float)):
            return self.text()
        ok = not math.isnan(value) and (math.isfinite(value) or (self.infinite and value > 0))
        ok = ok and (self.gt is None or value > self.gt) and (self.ge is None or value >= self.ge)
        ok = ok and (self.le is None or value <= self.le) and not (self.nonzero and value == 0)
        return None if ok else self.text()

    def text(self) -> str:
        """The rule in words ("a finite number (above 0, at most 0.001)")."""
        if self.need:
            return self.need
        if self.kind is bool:
            return "true or false"
        if self.kind is str:
            return "a file name"
        if self.kind is int:
            return f"an integer from {self.ge} to {self.le}"
        bounds = [f"{word} {bound:g}" for word, bound in (("above", self.gt), ("at least", self.ge),
                                                          ("at most", self.le)) if bound is not None]
        if self.nonzero:
            bounds.append("non-zero")
        return "a finite number" + (f" ({', '.join(bounds)})" if bounds else "")


def option(default: Any, unit: str, doc: str, rule: Rule | None = None) -> Any:
    """A field of AnalysisOptions: its default, unit ("" for a pure number), description and rule."""
    return field(default=default, metadata={"unit": unit, "doc": doc, "rule": rule})


REL = Rule(ge=0.0, le=0.5)  # a reference chain's relative standard uncertainty (k = 1)
FRACTION = Rule(ge=0.0, le=1.0)


@dataclass(frozen=True)
class AnalysisOptions:
    """Rig constants and analysis options of one shot (module docstring)."""

    # The reference and the sensor (analysis.reduce)
    grating_pitch_m: float = option(DEFAULT_GRATING_PITCH_M, "m", "interferometer grating pitch d",
                                    Rule(gt=0.0, le=1e-3))
    orders: tuple[int, int] = option((1, -1), "", "diffraction orders (phi, xi): beat = v*(phi - xi)/d",
                                     Rule(ge=-10, le=10, need="two integer diffraction orders from -10 to 10, which must differ"))
    amp_gain: float = option(1.0, "V/V", "bridge amplifier gain", Rule(nonzero=True))
    sensitivity_v_per_m_s2: float = option(1.0, "V/(m/s²)", "accelerometer nominal sensitivity at the amplifier "
                                           "input", Rule(nonzero=True))
    sample_rate_hz: float | None = option(DEFAULT_ANALYSIS_RATE_HZ, "Hz", "analysis rate after alignment and "
                                          "resampling (none: the record's own)", Rule(gt=0.0, le=1e10, optional=True))
    # Identification (analysis.identify)
    max_order: int = option(12, "", "highest model order tried", Rule(int, ge=1, le=MAX_ORDER_LIMIT))
    order: int | None = option(None, "", "a fixed order instead of the order test's choice (none: the test's)",
                               Rule(int, ge=1, le=MAX_ORDER_LIMIT, optional=True))
    significance: float = option(SIGNIFICANCE, "", "the order test's level", Rule(gt=0.0, le=0.5))
    max_delay_samples: int = option(32, "samples", "the largest input delay searched", Rule(int, ge=0, le=10_000))
    remove_delay: bool = option(True, "", "search the input delay (false: hold it at 0)", Rule(bool))
    patience: int | None = option(3, "orders", "stop this many orders past the choice without gain (none: try "
                                  "every order)", Rule(int, ge=1, le=MAX_ORDER_LIMIT, optional=True))
    max_evaluations: int = option(60, "", "each order's search budget", Rule(int, ge=1, le=100_000))
    stability_draws: int = option(0, "", "noise draws that re-run the order choice (0: none; the uncertainty "
                                  "does)", Rule(int, ge=0, le=MAX_DRAWS))
    # DCM (analysis.dcm_design)
    dcm_ratio: float | None = option(None, "", "DCM response-time ratio r (none: automatic, analysis.dcm_ratio)",
                                     Rule(gt=0.0, optional=True, need="a finite number above 0 (or none: automatic)"))
    dcm_damping: float = option(DEFAULT_DCM_DAMPING, "", "damping ζ_e of the DCM's new poles",
                                Rule(gt=0.0, le=1.0, need="the damping ratio ζ_e, a number above 0 and at most 1"))
    dcm_widening: float | None = option(DEFAULT_DCM_WIDENING, "", "automatic DCM: none sizes it to each shot's "
                                        "pulse; W widens the model's ±5 % band W times instead",
                                        Rule(gt=1.0, optional=True,
                                             need="a finite number above 1 (or none: sized to the pulse)"))
    extra_poles: tuple[complex, ...] = option((), "", "further DCM poles (z-plane, inside the unit circle, "
                                              "complex ones with their conjugates)",
                                              Rule(need="finite poles inside the unit circle"))
    dcm_noise_gain_limit: float = option(DEFAULT_DCM_NOISE_GAIN_LIMIT, "", "DCM's white-noise RMS gain allowed at "
                                         "the analysis rate (inf: no bound)",
                                         Rule(gt=0.0, infinite=True, need="a number above 0 (inf: no bound)"))
    dcm_band_limit_hz: float | None = option(None, "Hz", "DCM low-pass cut-off (none: from the shot, 0: none)",
                                             Rule(ge=0.0, optional=True, need="a frequency of at least 0 Hz (0: "
                                                                                "none; none: from the shot)"))
    # Uncertainty (analysis.uncertainty, GUM Supplement 1)
    uncertainty: bool = option(True, "", "the Monte Carlo (GUM-S1) uncertainty of the key figures", Rule(bool))
    draws: int = option(DEFAULT_DRAWS, "", "Monte Carlo draws per shot (GUM-S1)", Rule(int, ge=MIN_DRAWS, le=MAX_DRAWS))
    seed: int | None = option(None, "", "the draws' seed (none: fresh; the seed used is stored with the result)",
                              Rule(int, ge=0, le=MAX_SEED, optional=True))
    u_grating_pitch_rel: float = option(1e-4, "", "grating period d, relative standard uncertainty (k = 1)", REL)
    u_interferometer_rel: float = option(5e-4, "", "beat demodulation and beam alignment, relative standard "
                                         "uncertainty (k = 1)", REL)
    u_amp_gain_rel: float = option(2e-3, "", "bridge amplifier gain, relative standard uncertainty (k = 1)", REL)
    u_digitizer_gain_rel: float = option(2e-3, "", "the response channel's vertical gain, relative standard "
                                         "uncertainty (k = 1)", REL)
    u_channel_skew_s: float = option(1e-9, "s", "timing skew between the two digitizer channels (standard "
                                     "uncertainty)", Rule(ge=0.0, le=1e-3))
    order_draws: int = option(ORDER_DRAWS, "", "draws that re-run the whole order choice",
                              Rule(int, ge=1, le=MAX_DRAWS))
    # Transverse sensitivity (analysis.systematics): their product bounds a Type B row of the DC
    # gain and the shock sensitivity.
    transverse_sensitivity_rel: float = option(0.05, "", "the sensor's stated transverse sensitivity, a fraction "
                                               "(its datasheet's limit)", FRACTION)
    transverse_motion_rel: float = option(0.02, "", "the bar's transverse motion share at the sensor, a fraction "
                                          "(2 %: a well-aligned bar)", FRACTION)
    # Tension/compression asymmetry where the pulse drives one direction only (analysis.systematics)
    asymmetry_bound_rel: float = option(0.03, "", "a bound on the sensor's tension/compression asymmetry |ε|, a "
                                        "fraction, carried where the pulse drives one direction only (3 %: above "
                                        "the 2.2 % measured on PTB's record)", FRACTION)
    # A sinusoidal calibration of the same sensor (CSV), fitted with the shock (analysis.sine_joint)
    sine_calibration: str | None = option(None, "", "a sine calibration CSV of the sensor (none: no joint fit)",
                                          Rule(str, optional=True))

    @property
    def n_max(self) -> int:
        """The largest order the search may reach (an asked order above max_order included)."""
        return max(self.max_order, self.order or 0)

    @classmethod
    def from_options(cls, **options: Any) -> AnalysisOptions:
        """Build from keyword options, ignoring None (= default) and naming unknown keys."""
        return cls.from_dict({k: v for k, v in options.items() if v is not None})

    @classmethod
    def from_dict(cls, data: dict[str, Any], *, ignore_unknown: bool = False) -> AnalysisOptions:
        """Build from `to_dict()` output (a shot file's /analysis/params, any version) or a plan's
        options; unknown keys are an error unless `ignore_unknown` (results written by another
        version). Values are checked."""
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
        options = cls(**values)
        options.check()
        return options

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: tuples as lists, complex poles as [re, im]. The options of the first shot
        files always; those added since (`LATER`) only when not at their default, so the
        /analysis/params of a shot analysed with the defaults reads as it always has."""
        d = asdict(self)
        d["orders"] = list(self.orders)
        d["extra_poles"] = [[p.real, p.imag] for p in self.extra_poles]
        for name in LATER:
            if d[name] == _DEFAULTS[name]:
                del d[name]
        return d

    def check(self, names: tuple[str, ...] | None = None) -> None:
        """Raise AnalysisError (OptionError) naming the first option whose value cannot be used;
        `names`: only these options (default: all)."""
        for f in fields(self):
            if names is not None and f.name not in names:
                continue
            value = getattr(self, f.name)
            need = _special_problem(self, f.name, value) if f.name in _SPECIAL else f.metadata["rule"].problem(value)
            if need is not None:
                raise OptionError(f.name, need, value)

    def reference_chain(self) -> dict[str, float]:
        """Relative standard uncertainties of the reference chain, by source name."""
        return {name: value for name, (value, _) in self.chain().items()}

    def chain(self) -> dict[str, tuple[float, str]]:
        """Reference-chain sources: (relative standard uncertainty, channel it scales)."""
        return {
            "grating pitch": (self.u_grating_pitch_rel, "reference"),
            "interferometer": (self.u_interferometer_rel, "reference"),
            "amplifier gain": (self.u_amp_gain_rel, "response"),
            "digitizer gain": (self.u_digitizer_gain_rel, "response"),
        }


class OptionError(AnalysisError):
    """An analysis option that cannot be used: which (`option`), what it must be (`need`) and
    the value given."""

    def __init__(self, option: str, need: str, value: Any) -> None:
        super().__init__(f"analysis option {option}: {need}, got {_shown(value)}")
        self.option, self.need, self.value = option, need, value


def _given(self: Any) -> dict[str, Any]:
    """The options given, in their declared order (None: not given, left out)."""
    return {f.name: getattr(self, f.name) for f in fields(self) if getattr(self, f.name) is not None}


def _overrides_repr(self: Any) -> str:
    return f"AnalysisOverrides({', '.join(f'{k}={v!r}' for k, v in _given(self).items())})"


# Every option of AnalysisOptions, None meaning "not given": what a shot request asks over the
# rig's configuration (`given()` merged over it, then checked by AnalysisOptions.from_options).
AnalysisOverrides = make_dataclass(
    "AnalysisOverrides",
    [(f.name, f"{f.type} | None", field(default=None, metadata=f.metadata)) for f in fields(AnalysisOptions)],
    frozen=True, repr=False,
    namespace={"__doc__": "Analysis options asked over the configuration's (None: not given); `given()`: "
                          "the ones given.", "__module__": __name__, "given": _given, "__repr__": _overrides_repr})


# The DCM design's own options (analysis.dcm_design checks them before it designs).
DCM_OPTIONS = ("dcm_ratio", "dcm_damping", "dcm_widening", "extra_poles", "dcm_noise_gain_limit", "dcm_band_limit_hz")
# Options added after shot files were first written (to_dict leaves them out at their default).
LATER = ("significance", "max_delay_samples", "remove_delay", "patience", "max_evaluations", "stability_draws",
         "order_draws")
_DEFAULTS = {f.name: f.default for f in fields(AnalysisOptions) if f.default is not MISSING}
_SPECIAL = ("orders", "dcm_band_limit_hz", "extra_poles")


def declared(name: str) -> Any:
    """Option `name`'s declared default (what a command's flag or the panel shows)."""
    return _DEFAULTS[name]


def _special_problem(options: AnalysisOptions, name: str, value: Any) -> str | None:
    """The rules beyond a bound: two different orders; the band limit below Nyquist (when the
    analysis rate is known); extra poles inside the unit circle, in conjugate pairs. (How many
    extra poles fit depends on the model's poles: only the design can tell.)"""
    if name == "orders":
        ok = (isinstance(value, tuple) and len(value) == 2 and all(_is_int(o) and -10 <= o <= 10 for o in value)
              and value[0] != value[1])
        return None if ok else _rule(name).need
    if name == "dcm_band_limit_hz":
        rule = _rule(name)
        if (need := rule.problem(value)) is not None:
            return need
        nyquist = 0.5 * options.sample_rate_hz if _is_number(options.sample_rate_hz) else None
        if value is not None and value > 0 and nyquist is not None and not value < nyquist:
            return f"a frequency below Nyquist ({nyquist:g} Hz at the analysis rate)"
        return None
    poles = list(value)
    for p in poles:
        if not (isinstance(p, (complex, float, int)) and not isinstance(p, bool)
                and math.isfinite(complex(p).real) and math.isfinite(complex(p).imag) and abs(p) < 1.0):
            return f"finite poles inside the unit circle ({p!r} is not)"
    unmatched = [complex(p) for p in poles if abs(complex(p).imag) > CONJUGATE_TOLERANCE * max(1.0, abs(p))]
    while unmatched:
        x = unmatched.pop(0)
        partner = next((i for i, y in enumerate(unmatched)
                        if abs(y - x.conjugate()) <= CONJUGATE_TOLERANCE * max(1.0, abs(x))), None)
        if partner is None:
            return f"both members of every complex pair ({x!r} has no conjugate partner)"
        unmatched.pop(partner)
    return None


def _rule(name: str) -> Rule:
    return next(f.metadata["rule"] for f in fields(AnalysisOptions) if f.name == name)


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) and value > 0


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
