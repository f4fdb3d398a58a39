"""The modes of a discrete model (stage 7 of analysis.identify, "claims"): each pole pair or real
pole as a natural frequency and damping ratio, whether the excitation's band supports it, and
whether a zero nearly cancels it (a pole–zero doublet: no mode)."""

from __future__ import annotations

from typing import Any

import numpy as np

# A pole pair damped more than this is no resonance (it shapes the response without a peak that
# could be called the sensor's natural frequency): never a mode claimed, never the main mode.
RESONANCE_MAX_DAMPING = 0.3
# A zero closer to a pole than this fraction of the pole's distance to the unit circle cancels it
# (a pole–zero doublet changes the response by at most about that fraction near the pole).
DOUBLET_DISTANCE = 0.5


def modes_of(
    poles: np.ndarray, sample_interval_s: float, supported_band_hz: tuple[float, float] | None = None
) -> list[dict[str, Any]]:
    """Natural frequency (Hz) and damping ratio per complex pole pair or real pole (s = ln(z)/T).

    Sorted by natural frequency. `kind` is "complex" (a pair, listed once with its positive
    imaginary part) or "real". A real pole gives a damping ratio of 1 (over-damped section with
    time constant 1/(2π·f_n)); a negative real pole sits at Nyquist (an artefact of the
    discretisation: `nyquist` True, never supported); a pole at the origin has no frequency.
    `supported`: the natural frequency lies inside `supported_band_hz` (the band the excitation
    supports; None: not judged, True). `resonance`: a complex pair damped at most
    RESONANCE_MAX_DAMPING (only a resonance is ever claimed as a mode).
    """
    modes = []
    for p in np.asarray(poles, dtype=complex):
        if p.imag < 0:
            continue
        if p == 0:
            modes.append({"kind": "real", "pole": [0.0, 0.0], "natural_frequency_hz": None, "damping_ratio": None,
                          "nyquist": False, "supported": False})
            continue
        s = np.log(p) / sample_interval_s
        wn = float(abs(s))
        f_n = wn / (2 * np.pi)
        nyquist = bool(p.imag == 0 and p.real < 0)
        supported = not nyquist and (
            supported_band_hz is None or supported_band_hz[0] <= f_n <= supported_band_hz[1]
        )
        zeta = float(-s.real / wn) if wn > 0 else None
        modes.append(
            {
                "kind": "complex" if p.imag > 0 else "real",
                "pole": [float(p.real), float(p.imag)],
                "natural_frequency_hz": f_n,
                "damping_ratio": zeta,
                "nyquist": nyquist,
                "supported": bool(supported),
                "resonance": bool(p.imag > 0 and zeta is not None and zeta <= RESONANCE_MAX_DAMPING),
            }
        )
    return sorted(modes, key=lambda m: m["natural_frequency_hz"] or 0.0)


def mark_doublets(modes: list[dict[str, Any]], zeros: np.ndarray) -> list[dict[str, Any]]:
    """Each complex mode with `cancelled` (a zero within DOUBLET_DISTANCE of the pole's distance
    to the unit circle: a pole–zero doublet, whose effect on the response is at most that
    fraction — the fit following a ripple of the data, not a resonance; issue 17's 17 kHz "main
    mode" on PTB's record was one). A cancelled mode is not supported: it is no main mode and
    no pole a DCM may cancel."""
    z = np.asarray(zeros, dtype=complex)
    out = []
    for m in modes:
        m = dict(m)
        m["cancelled"] = False
        if m["kind"] == "complex" and z.size:
            p = complex(*m["pole"])
            if float(np.min(np.abs(z - p))) < DOUBLET_DISTANCE * (1.0 - abs(p)):
                m["cancelled"], m["supported"] = True, False
        out.append(m)
    return out


def claimed(mode: dict[str, Any]) -> bool:
    """Whether a mode is claimed: a resonance (ζ ≤ RESONANCE_MAX_DAMPING) the band supports, not
    cancelled by a zero (results written before `resonance` was kept: judged by its damping)."""
    zeta = mode.get("damping_ratio")
    resonance = mode.get("resonance", zeta is not None and zeta <= RESONANCE_MAX_DAMPING)
    return mode["kind"] == "complex" and bool(mode["supported"]) and bool(resonance) and not mode.get("cancelled")


def main_mode(modes: list[dict[str, Any]]) -> dict[str, Any] | None:
    """The sensor's main mode: the lowest claimed resonance (`claimed`; None if there is none)."""
    pairs = [m for m in modes if claimed(m)]
    return min(pairs, key=lambda m: m["natural_frequency_hz"]) if pairs else None


def has_doublet(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether a complex pole pair of A(z) = 0 is nearly cancelled by a zero of B (`mark_doublets`'s
    test; the sample interval does not enter it, so any is given)."""
    if a.size < 2 or b.size < 2:
        return False
    return any(m["cancelled"] for m in mark_doublets(modes_of(np.roots(a), 1.0), np.roots(b)))
