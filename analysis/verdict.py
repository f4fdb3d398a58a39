"""A shot's verdict: ACCEPT or REPEAT, with the main reason in one line.

`shot_verdict(figures, ...)` reads a shot's key figures (analysis.key_figures) and judges each
thing a technician checks before moving on, as a `Finding`:

- analysis: the shot was analysed (a failed analysis gives no calibration: REPEAT, or
  re-analyse the file);
- fit: the model reproduces the response (`fit_percent` ≥ `min_fit_percent`);
- band: the excitation supports a band and the FBSD ±5 % is stated in it (a value, or a
  "> bound" where the edge lies beyond the band);
- resonance: the sensor's resonance (the main mode) was excited inside the supported band;
  when it was not, the FBSD is a bound and the DCM has nothing measured to cancel (a note,
  or a reason to repeat when `require_resonance`);
- level: the peak acceleration reached the target within `level_tolerance_rel`;
- sensitivity: determined, and its deviation from the nominal against the sensor's
  tolerance (outside it: flagged, not repeated: repeating does not change a sensor);
- DCM: recommended or not (a note; a shot is a calibration with or without its DCM).

A Finding's status: OK, NOTE (worth saying, no action), FLAG (look at it; the shot stands),
FAIL (the shot must be repeated). The decision is REPEAT when any finding FAILs.
`ShotVerdict.line()` is the one line the panel, the campaign table and a report show:
"REPEAT — fit 43.0 % (below 90 %) · band 0.06–66.3 kHz · resonance not excited · ...".

A figure the analysis could not determine (value None) is judged "not determined", with the
analysis' reason when it gives one (an attribute `reason` of the figure, when present).
Pure: no NumPy; typed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum
from typing import Any

from hopkinson.analysis.key_figures import Figure, KeyFigures
from hopkinson.analysis.sensitivity_units import G_M_S2, RATIO_UNITS

MIN_FIT_PERCENT = 90.0  # below: the model does not describe the response; its figures are not trusted
LEVEL_TOLERANCE_REL = 0.10  # a shot within ±10 % of its target level reached it
TOP_WARNINGS = 3  # warnings shown in full; the rest behind "details"
# Words that put a warning first: what makes the shot's figures wrong rather than less certain.
_URGENT_WORDS = ("clipp", "overload", "saturat", "failed", "not determined", "cannot", "no resonance",
                 "not excited", "outside the band", "leads the reference")


class Decision(StrEnum):
    ACCEPT = "ACCEPT"
    REPEAT = "REPEAT"


class Check(StrEnum):
    ANALYSIS = "analysis"
    FIT = "fit"
    BAND = "band"
    RESONANCE = "resonance"
    LEVEL = "level"
    SENSITIVITY = "sensitivity"
    DCM = "DCM"


class Status(StrEnum):
    OK = "ok"
    NOTE = "note"  # said, no action
    FLAG = "flag"  # look at it; the shot stands
    FAIL = "fail"  # the shot must be repeated


@dataclass(frozen=True)
class Finding:
    """One judged check: its status and a short phrase ("fit 97.6 %")."""

    check: Check
    status: Status
    text: str


@dataclass(frozen=True)
class VerdictCriteria:
    """What a shot must meet. tolerance_percent: the sensor's sensitivity tolerance (None: not
    judged); require_resonance: a shot that did not excite the resonance is repeated."""

    min_fit_percent: float = MIN_FIT_PERCENT
    level_tolerance_rel: float = LEVEL_TOLERANCE_REL
    tolerance_percent: float | None = None
    require_resonance: bool = False

    def __post_init__(self) -> None:
        if not 0.0 <= self.min_fit_percent <= 100.0:
            raise ValueError(f"min_fit_percent must be 0..100 %, got {self.min_fit_percent:g}")
        if not 0.0 < self.level_tolerance_rel < 1.0:
            raise ValueError(f"level_tolerance_rel must be between 0 and 1, got {self.level_tolerance_rel:g}")
        if self.tolerance_percent is not None and not 0.0 < self.tolerance_percent < 100.0:
            raise ValueError(f"tolerance_percent must be between 0 and 100 %, got {self.tolerance_percent:g}")


@dataclass(frozen=True)
class ShotVerdict:
    """ACCEPT or REPEAT and the findings behind it (module docstring)."""

    decision: Decision
    findings: tuple[Finding, ...]

    @property
    def reason(self) -> str:
        """The main reason: the first failing finding, else the first flag, else "every check passed"."""
        for status in (Status.FAIL, Status.FLAG):
            for f in self.findings:
                if f.status == status:
                    return f.text
        return "every check passed"

    def finding(self, check: Check) -> Finding | None:
        return next((f for f in self.findings if f.check == check), None)

    def line(self) -> str:
        """'ACCEPT — fit 97.6 % · band …' (failing findings first, then the others in order)."""
        first = [f for f in self.findings if f.status == Status.FAIL]
        rest = [f for f in self.findings if f.status != Status.FAIL]
        return f"{self.decision.value} — " + " · ".join(f.text for f in first + rest)

    def to_dict(self) -> dict[str, Any]:
        return {"decision": self.decision.value, "reason": self.reason, "line": self.line(),
                "findings": [{"check": f.check.value, "status": f.status.value, "text": f.text}
                             for f in self.findings]}


def shot_verdict(figures: KeyFigures | None, criteria: VerdictCriteria = VerdictCriteria(), *,
                 target_peak_m_s2: float | None = None, analysis_error: str | None = None) -> ShotVerdict:
    """Judge a shot (module docstring). figures: its key figures (None: not analysed);
    target_peak_m_s2: the level it was fired for (None: none named); analysis_error: why its
    analysis failed."""
    if figures is None or analysis_error:
        why = analysis_error or "the shot has not been analysed"
        return ShotVerdict(Decision.REPEAT, (Finding(Check.ANALYSIS, Status.FAIL, _one_line(why)),))
    findings = (
        _fit(figures, criteria),
        _band(figures),
        _resonance(figures, criteria),
        _level(figures, target_peak_m_s2, criteria),
        _sensitivity(figures, criteria),
        _dcm(figures),
    )
    failed = any(f.status == Status.FAIL for f in findings)
    return ShotVerdict(Decision.REPEAT if failed else Decision.ACCEPT, findings)


def rank_warnings(warnings: tuple[str, ...] | list[str]) -> tuple[str, ...]:
    """The warnings without repeats, those that make figures wrong (clipping, an overload, a
    figure not determined, …) first, each group in the analysis' order."""
    unique = list(dict.fromkeys(w.strip() for w in warnings if w and w.strip()))
    urgent = [w for w in unique if any(word in w.lower() for word in _URGENT_WORDS)]
    return tuple(urgent + [w for w in unique if w not in urgent])


def not_determined_text(figure: Figure | None, what: str) -> str:
    """'<what> not determined — <reason>' (the figure's own reason when it has one)."""
    reason = getattr(figure, "reason", None) if figure is not None else None
    return f"{what} not determined" + (f" — {reason}" if reason else "")


def _known(figure: Figure | None) -> bool:
    return figure is not None and figure.value is not None and math.isfinite(figure.value)


def _fit(kf: KeyFigures, c: VerdictCriteria) -> Finding:
    fit = kf.fit_percent
    if fit is None or not math.isfinite(fit):
        return Finding(Check.FIT, Status.FAIL, "fit not determined")
    if fit < c.min_fit_percent:
        return Finding(Check.FIT, Status.FAIL, f"fit {fit:.1f} % (below {c.min_fit_percent:g} %)")
    return Finding(Check.FIT, Status.OK, f"fit {fit:.1f} %")


def _band(kf: KeyFigures) -> Finding:
    band = kf.supported_band_hz
    if band is None:
        return Finding(Check.BAND, Status.FAIL, "no supported band (the excitation supports no frequency range)")
    text = f"band {_khz(band[0])}–{_khz(band[1])} kHz"
    if "5" in kf.fbsd_bounds:
        return Finding(Check.BAND, Status.OK, f"{text}, FBSD ±5 % > {_khz(kf.fbsd_bounds['5'].lower_bound_hz)} kHz")
    fbsd = kf.fbsd_hz.get("5")
    if not _known(fbsd):
        return Finding(Check.BAND, Status.FLAG, f"{text}, " + not_determined_text(fbsd, "FBSD ±5 %"))
    assert fbsd is not None and fbsd.value is not None
    return Finding(Check.BAND, Status.OK, f"{text}, FBSD ±5 % {_khz(fbsd.value)} kHz")


def _resonance(kf: KeyFigures, c: VerdictCriteria) -> Finding:
    f_n = kf.natural_frequency_hz
    if _known(f_n):
        assert f_n is not None and f_n.value is not None
        return Finding(Check.RESONANCE, Status.OK, f"resonance excited ({_khz(f_n.value)} kHz)")
    reason = getattr(f_n, "reason", None) if f_n is not None else None
    text = "resonance not excited" + (f" — {reason}" if reason else " (no resonance inside the supported band)")
    return Finding(Check.RESONANCE, Status.FAIL if c.require_resonance else Status.NOTE, text)


def _level(kf: KeyFigures, target_m_s2: float | None, c: VerdictCriteria) -> Finding:
    peak = kf.peak_acceleration_m_s2
    if not _known(peak):
        return Finding(Check.LEVEL, Status.FAIL, not_determined_text(peak, "peak acceleration"))
    assert peak is not None and peak.value is not None
    reached = abs(peak.value)
    text = f"level {_g(reached)} g"
    if target_m_s2 is None or not target_m_s2 > 0:
        return Finding(Check.LEVEL, Status.OK, text)
    off = reached / target_m_s2 - 1.0
    text += f" (target {_g(target_m_s2)} g, {_signed(100 * off)} %)"
    if abs(off) > c.level_tolerance_rel:
        return Finding(Check.LEVEL, Status.FAIL, text + f": outside ±{100 * c.level_tolerance_rel:g} %")
    return Finding(Check.LEVEL, Status.OK, text)


def _sensitivity(kf: KeyFigures, c: VerdictCriteria) -> Finding:
    s = kf.sensitivity
    if not _known(s):
        return Finding(Check.SENSITIVITY, Status.FAIL, not_determined_text(s, "sensitivity"))
    assert s.value is not None
    if kf.response_unit not in RATIO_UNITS:
        return Finding(Check.SENSITIVITY, Status.OK, "sensitivity determined (no nominal to compare with)")
    deviation = 100.0 * (s.value - 1.0)
    text = f"sensitivity {_signed(deviation)} % from nominal"
    if c.tolerance_percent is None:
        return Finding(Check.SENSITIVITY, Status.OK, text + " (no tolerance set)")
    if abs(deviation) > c.tolerance_percent:
        return Finding(Check.SENSITIVITY, Status.FLAG,
                       f"{text}: OUT OF TOLERANCE (±{c.tolerance_percent:g} %): check the nominal and the gain")
    return Finding(Check.SENSITIVITY, Status.OK, f"{text}, within ±{c.tolerance_percent:g} %")


def _dcm(kf: KeyFigures) -> Finding:
    if kf.dcm_recommended is True:
        return Finding(Check.DCM, Status.OK, "DCM recommended")
    if kf.dcm_recommended is False:
        why = kf.dcm_not_recommended_reason
        return Finding(Check.DCM, Status.NOTE, "DCM not recommended" + (f" ({_one_line(why)})" if why else ""))
    return Finding(Check.DCM, Status.NOTE, "no DCM")


def _khz(value_hz: float) -> str:
    """kHz to three significant digits, at least one decimal below 10 kHz ('0.06', '6.36', '66.3')."""
    return f"{value_hz / 1e3:.3g}" if value_hz >= 1e3 else f"{value_hz / 1e3:.2g}"


def _g(value_m_s2: float) -> str:
    """An acceleration in g, thousands apart by a no-break space: '50\u00a0614'."""
    return f"{value_m_s2 / G_M_S2:,.0f}".replace(",", "\u00a0")


def _signed(value: float) -> str:
    """'+1.2', '−37.3' (a typographic minus, as the panel writes numbers); '0.0' for what rounds to
    zero (no '−0.0')."""
    text = f"{value:+.1f}"
    return "0.0" if float(text) == 0.0 else text.replace("-", "−")


def _one_line(text: str) -> str:
    return " ".join(text.split())
