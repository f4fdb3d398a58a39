"""Results dicts shaped as the JSON contracts of issues 10 and 11 (CONTRACTS.md): the uncertainty
object and the DCM's check on its shot, added to a real analysis, for the tests of how the
report and the panel display them (independent of how the analysis computes them)."""

from __future__ import annotations

from typing import Any

from hopkinson.analysis.key_figures import KeyFigures


def contract_figure(value: float, u_rel: float) -> dict:
    """{"value", "u", "interval"} as issue 10's JSON contract has it (a normal 95 % interval)."""
    u = abs(value) * u_rel
    return {"value": value, "u": u, "interval": [value - 1.96 * u, value + 1.96 * u]}


BUDGET = [{"source": "response channel noise", "u_rel": 0.0021}, {"source": "grating pitch", "u_rel": 0.0005},
          {"source": "amplifier gain", "u_rel": 0.0030}, {"source": "order choice", "u_rel": 0.0008}]


def contract_results(analysis: Any, u_rel: float = 0.004, recommended: bool = True, check: bool = True) -> dict:
    """The shot's results dict (or a ShotAnalysis') with the uncertainty (issue 10) and, with
    `check`, the compensation check (issue 11) shaped as the JSON contracts (CONTRACTS.md) have
    them, for the display of both."""
    results = analysis if isinstance(analysis, dict) else analysis.to_dict()
    results = {**results, "dcm": dict(results.get("dcm") or {})}
    kf = KeyFigures.from_results(results)
    results["uncertainty"] = {
        "method": "monte-carlo", "draws": 200, "coverage_probability": 0.95,
        "dc_gain": contract_figure(kf.sensitivity.value, u_rel),
        "main_mode": {"natural_frequency_hz": contract_figure(kf.natural_frequency_hz.value, u_rel),
                      "damping_ratio": contract_figure(kf.damping_ratio.value, 10 * u_rel)},
        "fbsd_hz": {k: contract_figure(kf.fbsd_hz[k].value, 2 * u_rel) for k in ("5", "10")},
        "budget": BUDGET,
    }
    if kf.shock_sensitivity is not None and kf.shock_sensitivity.value is not None:
        results["uncertainty"]["shock_sensitivity"] = contract_figure(kf.shock_sensitivity.value, 1.5 * u_rel)
    if not check:
        return results
    results["dcm"].update({
        "recommended": recommended,
        "not_recommended_reason": None if recommended else "the compensated RMS error (6.1 %) exceeds the "
                                                           "uncompensated one (4.9 %): noise gain too high",
        "target_widening": 3.0, "reached_widening": 2.6, "widening_note": "the noise-gain limit stops r at 12",
        "noise_gain": 3.2, "noise_gain_limit": 10.0, "band_limit_hz": 40_000.0, "latency_s": 4.2e-6,
        "check": {"rms_error_pct": {"uncompensated": 4.95, "compensated": 1.8 if recommended else 6.1},
                  "peak_error_pct": {"uncompensated": 60.7, "compensated": -0.7}},
        "compensated_peak": contract_figure(2.94e5, 0.006),
    })
    return results
