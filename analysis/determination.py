"""Which of a shot's figures the record determines, and why not where it does not: a typed answer, never a number with an absurd interval.

A figure is not determined where:
- its 95 % interval is wider than its value (U > DETERMINED_U_REL·|value|): the record does not
  pin it (a shot whose pulse barely reaches the sensor's dynamics: a DC gain of 72.8 ± 5 000);
- it is a resonance's natural frequency or damping and no resonance is claimed in the band
  (analysis.claims: none inside it, or the resonance lies beyond it);
- it is an FBSD edge beyond the supported band (only "above the band's top" is known);
- it is the ISO 16063-13 shock sensitivity S_sh (a peak ratio) and the pulse does not meet the
  standard's condition that the sensor follow it quasi-statically: where the model's peak
  response differs from DC gain × peak reference by more than SHOCK_OVERSHOOT_LIMIT, the peak
  ratio reads the resonance's ringing, not the sensitivity ("not the sensitivity for this
  pulse"; the DC gain is).

A shot whose DC gain is not determined is no result (`is_result`): its figures are not reported.
"""

from __future__ import annotations

from typing import Any

DETERMINED_U_REL = 0.5  # U / |value| above which a figure is not determined
SHOCK_OVERSHOOT_LIMIT = 0.01  # |model peak ratio ÷ DC gain − 1| at most, for S_sh to be the sensitivity
FIGURE_PATHS = {"dc_gain": ("dc_gain",), "shock_sensitivity": ("shock_sensitivity",),
                "natural_frequency_hz": ("main_mode", "natural_frequency_hz"),
                "damping_ratio": ("main_mode", "damping_ratio"),
                "fbsd_5_hz": ("fbsd_hz", "5"), "fbsd_10_hz": ("fbsd_hz", "10")}


def not_determined(results: dict[str, Any]) -> dict[str, str]:
    """figure -> why the shot does not determine it (the module docstring's rules), from a
    results dict (ShotAnalysis.to_dict() without this key)."""
    out: dict[str, str] = {}
    ident = results.get("identification") or {}
    unc = results.get("uncertainty") or {}
    for figure, path in FIGURE_PATHS.items():
        entry: Any = unc
        for key in path:
            entry = entry.get(key) if isinstance(entry, dict) else None
        wide = _too_wide(entry)
        if wide:
            out[figure] = wide
    if ident.get("main_mode") is None:
        above = ident.get("resonance_above_hz")
        why = (f"no resonance is claimed: it lies above {above / 1e3:.3g} kHz, beyond what the pulse supports (a "
               "shorter pulse would excite it)" if above else
               "no resonance is claimed inside the band the pulse supports")
        out["natural_frequency_hz"] = out["damping_ratio"] = why
    for level, bound in (results.get("fbsd_bounds") or {}).items():
        if isinstance(bound, dict) and bound.get("lower_bound_hz") is not None:
            out[f"fbsd_{level}_hz"] = f"above {bound['lower_bound_hz'] / 1e3:.3g} kHz: {bound.get('reason', '')}"
    overshoot = results.get("peak_overshoot")
    if (results.get("reduction") or {}).get("shock_sensitivity") is not None and overshoot is not None:
        if not abs(overshoot - 1.0) <= SHOCK_OVERSHOOT_LIMIT:
            out["shock_sensitivity"] = (
                f"not the sensitivity for this pulse: the pulse excites the sensor's dynamics (the model's peak "
                f"response is {overshoot:.3f}× the DC gain times the peak reference, beyond the "
                f"{SHOCK_OVERSHOOT_LIMIT:.0%} in which ISO 16063-13's peak ratio measures the sensitivity); the "
                "DC gain is the sensitivity")
    return out


def is_result(determination: dict[str, str]) -> tuple[bool, str]:
    """Whether a shot is a result (its DC gain determined), and why not."""
    why = determination.get("dc_gain")
    return (why is None, "" if why is None else f"the shot is no result: its DC gain is not determined ({why})")


def _too_wide(entry: Any) -> str:
    """Why an uncertainty entry's interval is too wide to determine its figure ("" when it is not)."""
    if not isinstance(entry, dict):
        return ""
    value, interval = entry.get("value"), entry.get("interval")
    if value is None or not isinstance(interval, (list, tuple)) or None in interval:
        return ""
    lo, hi = interval
    if 0.5 * (hi - lo) <= DETERMINED_U_REL * abs(value):
        return ""
    return (f"the record does not determine it: its 95 % interval [{lo:.4g}, {hi:.4g}] is wider than "
            f"{DETERMINED_U_REL:.0%} of the value ({value:.4g})")
