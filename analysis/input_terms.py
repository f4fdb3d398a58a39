"""Input terms: what the sensor was driven by beyond what the reference shows, fitted with the model.

A bar's record carries systematic effects that no transfer function from the reference to the
response can follow (GUM: a known bias is corrected, and its estimate's uncertainty carried).
Each is a signal made from the reference, v_k(t), whose coefficient c_k is fitted with the model,
so the sensor is taken as driven by u + Σ c_k·v_k (analysis.frequency_fit, `SpectralData.inputs`):

- **tension/compression asymmetry** ("asymmetry"): v = the part of the reference of the sign
  opposite to the main pulse's peak. c = ε, the sensitivity in that direction over the sensitivity
  in the main pulse's direction, less one (a bonded mount's tension lobe, a lobe-dependent gain).
  The fit's B/A then holds the main direction's gain; the model this product reports is scaled to
  the **mean of both directions**, S = S_main·(1 + ε/2) (`mean_gain_factor`): what a sinusoidal
  calibration measures, what a fit without ε reads of a pulse with lobes of both signs, and what
  stays defined when the record cannot resolve ε. ε is reported beside it: the directions'
  sensitivities are S_main = S/(1 + ε/2) and S_other = S_main·(1 + ε). Fitted where the pulse has an
  opposite lobe of at least OPPOSITE_LOBE of its peak and both lobes span LOBE_SAMPLES samples
  (a dipole of a few samples is two lobes the model cannot tell apart from one lobe and a zero:
  its ε went to −1); else ε is not determined.
- **the bar's motion after the pulse** ("motion after the pulse"): v = the reference after the
  pulse's end, switched on smoothly (raised cosine) over MOTION_RAMP_S. c = γ: the sensor's base
  moves (1 + γ) times what the interferometer's spot shows there (the end face's radial profile,
  its rocking). The ramp keeps the pulse's own trailing ripple, which the base sees whole, out of
  the term while the bar's modes build up (switched on within 5 µs, γ scaled that ripple too and
  bent the model's gain by 0.1 % across the band: the FBSD ±5 % 1 % low on the simulator's bar);
  how much the result depends on the ramp is carried in the budget (analysis.systematics). Fitted
  where the record shows that motion in both channels (coherent, analysis.noise.is_motion): a
  reference that is only noisier in flight than at rest would otherwise be "explained" by a γ
  near −1 (the sensor did not see that noise), biasing the model with it.
- **onset disturbances** ("onset"): v_i = smooth bumps (Hann, two spacings wide, at a spacing
  of half the shortest period the band supports, so that no combination of them hides beyond
  the fitted bins) across the onset window, from ONSET_BEFORE_S before the pulse's foot to
  ONSET_AFTER_S after it. The reference there is taken as unknown and fitted: the interferometer's demodulation errors while the
  object jerks away (phase glitches, the beat's dip) and the lateral motion at the impact that
  reaches the sensor's mode through its transverse sensitivity, both short bursts the reference
  does not show truly, through the sensor's own dynamics. Kept only where the record is explained
  better with them than by any order of the model without them that it supports
  (analysis.onset_choice), so a record without them fits as before; never where the pulse peaks
  inside the window (a pulse that short is its own onset).

Pure NumPy.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hopkinson.analysis.excitation import glitch_window, pulse_peak_index
from hopkinson.analysis.sample_counts import ceil_count

ASYMMETRY = "asymmetry"
MOTION = "motion after the pulse"
ONSET = "onset"
OPPOSITE_LOBE = 0.1  # the opposite lobe's peak over the main pulse's, at least, for ε to be fitted
LOBE_SAMPLES = 8  # ... and each lobe this many samples wide at least (at 10 % of its own peak)
END_LEVEL = 0.1  # the pulse ends where it last stands at this fraction of its peak
MOTION_RAMP_S = 40e-6  # the motion term switches on over this long after the pulse's end
ONSET_BEFORE_S = 8e-6
ONSET_AFTER_S = 14e-6
ASYMMETRY_PRIOR_SD = 0.1
MOTION_PRIOR_SD = 0.5
ONSET_PRIOR = 1.0  # prior weight of each onset bump's coefficient (1/σ, σ in units of the pulse's peak)
ONSET_SPACING = 0.25  # the bumps' spacing × the band's top (samples per the shortest period it supports / 4)


@dataclass(frozen=True)
class InputTerms:
    """The input terms of one record (normalised units, the whole record's samples)."""

    names: tuple[str, ...] = ()  # per column: ASYMMETRY, MOTION, or ONSET (one per bump)
    signals: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))  # K × samples
    polarity: float = 1.0  # the main pulse's sign
    pulse_end: int | None = None  # the sample where the pulse ends (the motion term's start)
    onset: tuple[int, int] | None = None  # the onset window [first, stop) (samples)
    not_fitted: dict[str, str] = field(default_factory=dict)  # term -> why it is not fitted

    @property
    def count(self) -> int:
        return len(self.names)

    @property
    def prior(self) -> np.ndarray:
        """Each coefficient's prior weight (spectral_data.SpectralData.input_prior): the onset's
        bumps c ~ N(0, 1) in units of the pulse's peak (a disturbance no larger than the pulse),
        which settles the combinations of bumps the fitted bins do not see and costs a plausible
        disturbance nearly nothing; ε ~ N(0, ASYMMETRY_PRIOR_SD²) and γ ~ N(0, MOTION_PRIOR_SD²),
        wide against any mount's (a lobe-dependent gain of 2 %, a base seeing 15 % less) but
        closing the degenerate solutions a short pulse leaves open (a dipole of a few samples fitted
        ε = −1: one lobe and a zero explain two lobes)."""
        weight = {ONSET: ONSET_PRIOR, ASYMMETRY: 1.0 / ASYMMETRY_PRIOR_SD, MOTION: 1.0 / MOTION_PRIOR_SD}
        return np.array([weight[n] for n in self.names])

    def columns(self, name: str) -> np.ndarray:
        """The columns of the term `name` (several for the onset)."""
        return np.array([k for k, n in enumerate(self.names) if n == name], dtype=int)

    def without(self, name: str, why: str) -> InputTerms:
        """These terms less `name` (with the reason it is not fitted)."""
        keep = [k for k, n in enumerate(self.names) if n != name]
        return InputTerms(tuple(self.names[k] for k in keep), self.signals[keep], self.polarity, self.pulse_end,
                          self.onset if name != ONSET else None, {**self.not_fitted, name: why})

    def bins(self, start: int, stop: int, keep: np.ndarray) -> np.ndarray | None:
        """The DFT of each signal over the window [start, stop) at the kept bins (bins × K), None
        without terms."""
        if not self.count:
            return None
        return np.fft.rfft(self.signals[:, start:stop], axis=1)[:, keep].T

    def mean_gain_factor(self, coefficients: np.ndarray) -> float:
        """1 + ε/2: the main direction's gain (the fit's B/A) to the mean of both directions (the
        sensitivity reported); 1 without ε."""
        cols = self.columns(ASYMMETRY)
        c = np.asarray(coefficients, dtype=float)
        return 1.0 + 0.5 * float(c[cols[0]]) if cols.size and c.size == self.count else 1.0

    def correction(self, coefficients: np.ndarray) -> np.ndarray:
        """Σ c_k·v_k over the whole record (what the fit adds to the reference)."""
        c = np.asarray(coefficients, dtype=float)
        if not self.count or c.size != self.count:
            return np.zeros(self.signals.shape[1] if self.signals.ndim == 2 else 0)
        return c @ self.signals


def input_terms(u: np.ndarray, dt: float, pulse_start: int, noise_rms: float, busy: np.ndarray,
                top_hz: float, motion_shows: bool, *, motion_ramp_s: float = MOTION_RAMP_S,
                onset_s: tuple[float, float] = (ONSET_BEFORE_S, ONSET_AFTER_S)) -> InputTerms:
    """The candidate input terms of a record: `u` the whole reference (normalised, baseline
    removed), `pulse_start` the sample where its pulse starts (its 10 % crossing), `noise_rms`
    its noise at rest, `busy` where it carries the pulse (each pulse widened by its margins),
    `top_hz` the top of the band the fit uses, `motion_shows` whether both channels move together
    after the pulse (record_preparation: coherent motion); `motion_ramp_s` and `onset_s` (before,
    after the foot) as the module docstring, the defaults nominal (analysis.systematics varies them)."""
    n = u.size
    i_peak = pulse_peak_index(u, glitch_window(dt))  # the pulse's, not an onset glitch's
    polarity = 1.0 if u[i_peak] >= 0 else -1.0
    peak = abs(float(u[i_peak]))
    names: list[str] = []
    signals: list[np.ndarray] = []
    not_fitted: dict[str, str] = {}
    runs = _runs(busy)
    run = next((r for r in runs if r.start <= i_peak < r.stop), slice(0, n))
    main = np.zeros(n, dtype=bool)
    main[run] = True
    opposite = np.where(main & (polarity * u < 0), u, 0.0)
    low = float(np.max(np.abs(opposite), initial=0.0))
    wide = (_lobe_samples(polarity * u, peak) >= LOBE_SAMPLES and low > 0
            and _lobe_samples(-polarity * opposite, low) >= LOBE_SAMPLES)
    if low >= OPPOSITE_LOBE * peak and wide:
        names.append(ASYMMETRY)
        signals.append(opposite)
    else:
        not_fitted[ASYMMETRY] = (f"the pulse has no opposite lobe of {OPPOSITE_LOBE:.0%} of its peak and "
                                 f"{LOBE_SAMPLES} samples: the sensitivity in the other direction is not measured")
    loud = np.flatnonzero(main & (np.abs(u) >= END_LEVEL * peak))
    end = int(loud[-1]) + 1 if loud.size else i_peak
    ramp = max(1, int(round(motion_ramp_s / dt)))
    k = np.arange(n)
    switch = np.clip((k - end) / ramp, 0.0, 1.0)
    switch = 0.5 - 0.5 * np.cos(np.pi * switch)
    after = u * switch
    if motion_shows and end + ramp < n:
        names.append(MOTION)
        signals.append(after)
    else:
        not_fitted[MOTION] = "the channels do not move together after the pulse"
    foot = _foot(u, pulse_start, noise_rms)
    first = max(0, foot - ceil_count(onset_s[0] / dt))
    stop = min(end, foot + ceil_count(onset_s[1] / dt) + 1)
    onset = None
    if stop > i_peak:
        not_fitted[ONSET] = ("the pulse peaks within the onset's window: its onset is the pulse itself, which a free "
                             "onset would take as unknown")
    elif stop > first:
        onset = (first, stop)
        for v in onset_bumps(n, first, stop, max(1.0, ONSET_SPACING / (top_hz * dt))):
            names.append(ONSET)
            signals.append(v)
    return InputTerms(tuple(names), np.array(signals) if signals else np.zeros((0, n)), polarity, end, onset,
                      not_fitted)


def _lobe_samples(x: np.ndarray, peak: float) -> int:
    """Samples of the lobe around x's largest value that stand above 10 % of `peak`."""
    i = int(np.argmax(x))
    above = x >= 0.1 * peak
    lo = i - int(np.argmin(above[i::-1])) if not above[: i + 1].all() else 0
    hi = i + int(np.argmin(above[i:])) if not above[i:].all() else x.size
    return hi - lo - 1 if lo < i else hi - lo


def onset_bumps(n: int, first: int, stop: int, spacing: float) -> list[np.ndarray]:
    """Hann bumps two `spacing`s wide (samples), centred every `spacing` from `first` on to past
    `stop`: a partition of unity over the window whose combinations hold nothing above about
    1/(2·spacing) that a unit impulse per sample would."""
    k = np.arange(n, dtype=float)
    count = max(1, ceil_count((stop - first) / spacing) + 1)
    out = []
    for i in range(count):
        x = (k - (first + i * spacing)) / spacing
        bump = np.where(np.abs(x) < 1.0, 0.5 + 0.5 * np.cos(np.pi * x), 0.0)
        if np.any(bump > 0):
            out.append(bump)
    return out


def _foot(u: np.ndarray, pulse_start: int, noise_rms: float) -> int:
    """Where the pulse leaves the noise: scanning back from its start, the first sample where
    |u| falls under 3 noise RMS (or 1 % of the peak, whichever is higher)."""
    level = max(3.0 * noise_rms, 0.01 * float(np.max(np.abs(u))))
    below = np.flatnonzero(np.abs(u[: pulse_start + 1]) < level)
    return int(below[-1]) if below.size else 0


def _runs(mask: np.ndarray) -> list[slice]:
    edges = np.flatnonzero(np.diff(np.concatenate(([0], mask.astype(np.int8), [0]))))
    return [slice(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2], strict=True)]


def term_summary(terms: InputTerms, coefficients: np.ndarray, scale_u: float) -> dict[str, Any]:
    """What the fit found for each term (JSON-ready): ε, γ, and the onset correction's largest
    sample (in the reference's units) with its window."""
    c = np.asarray(coefficients, dtype=float)
    out: dict[str, Any] = {"not_fitted": dict(terms.not_fitted)}
    if c.size != terms.count:
        return out
    cols = terms.columns(ASYMMETRY)
    if cols.size:
        out[ASYMMETRY] = float(c[cols[0]])
    cols = terms.columns(MOTION)
    if cols.size:
        out[MOTION] = float(c[cols[0]])
    cols = terms.columns(ONSET)
    if cols.size and terms.onset is not None:
        out[ONSET] = {"window_samples": list(terms.onset), "largest_correction": float(np.max(np.abs(c[cols])) * scale_u)}
    return out
