"""The automatic response-time ratio r of a shot's DCM, sized to the pulse.

The paper leaves r to its user (Eq. 40: T'_rr = T'_r1 / r); a fixed widening of the model's
±5 % band ignores what the DCM is for (docs/decisions/0020). The automatic choice, in this
order of what the shot tells:

- **The pulse** (the shot's reference, `ShotPulse`): the smallest r beyond which widening no
  longer changes this pulse's compensated peak by more than PEAK_SETTLED (0.25 % of the peak),
  predicted through the model (the model's response to the reference, compensated, against the
  reference: no response noise enters). The compensated band then holds the pulse's content.
- **The band the shot supports** caps it: the band limit (analysis.dcm_design) passes at most
  its top, because beyond it the model is not measured; and the **noise-gain limit** caps it.
  Where the widest design they allow still changes the pulse's peak by more than PULSE_CUT (1 %),
  the note says which cap cuts the pulse and by how much (`RatioChoice.short`).
- Without a pulse but with the supported band: the widest ±5 % band allowed (the smallest r
  within 1 % of it), so the DCM reaches what the shot vouches for.
- With neither (a bare model or poles): FALLBACK_WIDENING (×3) of the model's ±5 % band, said so.
- An explicit widening W (`AnalysisOptions.dcm_widening`): the smallest r reaching ×W, as before.

Interface consumed (what identification provides): the model, the top edge of the supported
band (`ShotSupport.supported_band_hz[1]`, where the band limit puts its ±5 % edge; a band made
of several intervals between the pulse's nulls is consumed through its top edge alone: inside a
null the pulse has no content to compensate), and the record's reference (where the pulse's own
content ends is read from it here, as the widening at which its peak settles).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from enum import StrEnum
from functools import cache

import numpy as np
from scipy import signal

from hopkinson.analysis.dcm import DCM
from hopkinson.analysis.dcm_figures import compensated_fbsd_edges
from hopkinson.analysis.dcm_stream import apply_rows
from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.excitation import peak_estimate, pulse_width, pulse_window
from hopkinson.analysis.group_delay import passband_delay_samples
from hopkinson.analysis.model import DiscreteModel
from hopkinson.analysis.records import Record
from hopkinson.analysis.response import frequency_response, model_output, response_times_samples

PEAK_SETTLED = 0.0005  # widening further changes the pulse's compensated peak by less than this
PULSE_CUT = 0.01  # the widest design allowed changes the pulse's peak by more: a cap cuts the pulse
FALLBACK_WIDENING = 3.0  # neither a pulse nor a supported band known
WIDEST_WITHIN = 0.99  # "the widest band": the smallest r within 1 % of it
# Model draws up to this order are simulated through their direct form (see model_response).
DIRECT_FORM_MAX_ORDER = 4
_SEARCH_POINTS = 48
_MAX_DESIGNED_ANGLE = 0.45 * math.pi  # designed poles' ω_e·T at most 0.45 π (below 0.45 × Nyquist)


def model_response(model: DiscreteModel, u: np.ndarray) -> np.ndarray:
    """The model's response to u from rest (no input delay, as model_output): a low order
    through its direct form (lfilter; equal to the sections' output to rounding and ~40× faster
    than building the sections), a higher one through its second-order sections (model_output:
    better conditioned there)."""
    if model.a.size - 1 <= DIRECT_FORM_MAX_ORDER:
        return signal.lfilter(model.b, model.a, u)
    return model_output(model, u)


def compensated_delay_samples(model: DiscreteModel, dcm: DCM, model_fbsd5_hz: float, compensated_fbsd5_hz: float
                              ) -> float:
    """Delay (samples) of model × DCM over the band it passes flat (the wider of the two ±5 %
    bands, at most 0.4 × the rate): what aligning the compensated output removes besides the
    channel delay (analysis.group_delay.passband_delay_samples)."""
    dt = model.sample_interval_s
    band = min(max(compensated_fbsd5_hz, model_fbsd5_hz), 0.4 / dt)
    return passband_delay_samples(lambda f: frequency_response(model, f) * dcm.frequency_response(f), band, dt)


@dataclass(frozen=True)
class ShotPulse:
    """The shot's reference pulse at the model's rate: what the automatic ratio sizes the DCM to.

    reference_m_s2: the whole reference; window: the main pulse ± two widths
    (analysis.excitation.pulse_window); peak_m_s2: the pulse's peak (signed), read by
    analysis.excitation.peak_estimate (a fit over its lobe: no noise sample lifts it).
    """

    reference_m_s2: np.ndarray
    window: slice
    peak_m_s2: float

    @classmethod
    def of(cls, record: Record) -> ShotPulse:
        """From a record at the model's rate (AnalysisError without a pulse)."""
        dt = record.sample_interval_s
        reference = np.asarray(record.reference, dtype=float)
        pulse = pulse_width(reference, dt, record.start_time_s)
        window = pulse_window(pulse, record.n_samples, dt, record.start_time_s)
        return cls(reference, window, peak_estimate(reference[window], pulse.peak_m_s2)[0])

    @property
    def sign(self) -> float:
        return 1.0 if self.peak_m_s2 > 0 else -1.0

    def peak_ratios(self, models: Sequence[DiscreteModel], dcm: DCM, delay_samples: float) -> np.ndarray:
        """q_i = peak(G·H_i·u) / (S·peak(u)) for each model H_i (u the reference, S the first
        model's DC gain, G the DCM with `delay_samples` removed, every peak of u's polarity over
        the pulse window read by peak_estimate, as the reference's: the reference's noise passes
        through G·H_i too, and a largest sample would read it as signal): 1 when the compensation
        passes the pulse's peak unchanged."""
        return self.peak_ratios_of(self.responses(models), models[0].dc_gain, dcm, delay_samples)

    def responses(self, models: Sequence[DiscreteModel]) -> np.ndarray:
        """H_i·u for each model H_i (model_response), one row each."""
        return np.array([model_response(m, self.reference_m_s2) for m in models])

    def peak_ratios_of(self, responses: np.ndarray, dc_gain: float, dcm: DCM, delay_samples: float) -> np.ndarray:
        """`peak_ratios` from the models' responses (`responses`) and the first one's DC gain: for
        one model's response read through many DCMs (the ratio search)."""
        aligned = dcm.with_latency(delay_samples)
        out = apply_rows(aligned, responses, align=True, samples=self.window.stop)[:, self.window]
        peaks = np.array([peak_estimate(row, self.peak_m_s2)[0] for row in out])
        return peaks / (dc_gain * self.peak_m_s2)


class SizedTo(StrEnum):
    """What the automatic ratio was sized to (module docstring)."""

    PULSE = "pulse"
    BAND = "band"
    FALLBACK = "fallback"  # neither a pulse nor a band: ×FALLBACK_WIDENING
    WIDENING = "widening"  # the widening asked for
    NOISE = "noise"  # even r = 1 is above the noise-gain limit


@dataclass(frozen=True)
class RatioChoice:
    """The automatic r and why. note: the explanation (None: an asked widening reached);
    short: it fell short of what it aimed for (a warning); peak_error: the DCM's own predicted
    change of the pulse's peak at r (q − 1; None without a pulse); target_widening: the widening
    aimed for (None when sized to the pulse or band)."""

    ratio: float
    sized_to: SizedTo
    note: str | None
    short: bool
    peak_error: float | None = None
    target_widening: float | None = None


@dataclass
class _Search:
    """Designs along r from 1 to the largest the sample rate allows, until the noise gain
    passes its limit; `assemble(r)` designs the DCM at r."""

    model: DiscreteModel
    assemble: Callable[[float], DCM]
    noise_gain_limit: float
    model_fbsd5_hz: float
    cap: str
    cap_edge_hz: float | None

    def __post_init__(self) -> None:
        self._cache: dict[float, tuple[DCM | None, float]] = {}

    def design(self, r: float) -> tuple[DCM | None, float]:
        """(DCM, noise gain) at r; (None, NaN) for a design that cannot be evaluated."""
        if r not in self._cache:
            try:
                dcm = self.assemble(r)
                self._cache[r] = (dcm, dcm.noise_gain())
            except AnalysisError:
                self._cache[r] = (None, math.nan)
        return self._cache[r]

    def edge5(self, r: float) -> float:
        dcm, _ = self.design(r)
        return 0.0 if dcm is None else compensated_fbsd_edges(self.model, dcm, (0.05,))["5"].frequency_hz

    def admissible(self, r_max: float) -> tuple[list[float], bool]:
        """The evaluable ratios within the noise-gain limit, ascending, the last one at the limit
        when it stops them (bisected); and whether it did."""
        rs: list[float] = []
        for r in map(float, np.geomspace(1.0, r_max, _SEARCH_POINTS)):
            _, noise = self.design(r)
            if math.isnan(noise):
                continue
            if noise > self.noise_gain_limit:
                if rs:
                    rs.append(bisect(lambda x: self.design(x)[1] > self.noise_gain_limit, rs[-1], r) / 1.0005)
                else:
                    rs.append(r)  # even the smallest is above the limit: designed there, flagged
                return rs, True
            rs.append(r)
        return rs, False


def max_ratio(cancelled: np.ndarray, damping: float) -> float:
    """The largest r whose designed poles stay below 0.45 × Nyquist (ω_e·T ≤ 0.45 π)."""
    return _MAX_DESIGNED_ANGLE * damping * float(np.max(response_times_samples(cancelled))) / 3.0


def choose_ratio(model: DiscreteModel, cancelled: np.ndarray, assemble: Callable[[float], DCM], *,
                 damping: float, noise_gain_limit: float, model_fbsd5_hz: float, widening: float | None,
                 pulse: ShotPulse | None, band_known: bool, cap: str, cap_edge_hz: float | None
                 ) -> RatioChoice:
    """The automatic r (module docstring). `cap`: the band limit and why it sits there (for the
    notes); `cap_edge_hz`: its ±5 % edge (None: no band limit)."""
    r_max = max_ratio(cancelled, damping)
    if r_max <= 1.0:
        return RatioChoice(r_max, SizedTo.FALLBACK, f"the slowest cancelled pole already responds within "
                           f"{float(np.max(response_times_samples(cancelled))):.3g} samples: the designed poles "
                           "cannot be made faster at this sample rate", True)
    search = _Search(model, assemble, noise_gain_limit, model_fbsd5_hz, cap, cap_edge_hz)
    rs, noisy = search.admissible(r_max)
    if not rs:
        raise AnalysisError("DCM: no response-time ratio gives a design that can be evaluated (a pole too slow?)")
    if search.design(rs[0])[1] > noise_gain_limit:
        return RatioChoice(rs[0], SizedTo.NOISE, f"even the smallest ratio tried (r = {rs[0]:.3g}) has a noise gain above the "
                           f"limit {noise_gain_limit:g}; the DCM is designed there", True)
    if widening is None and pulse is not None:
        return _sized_to_pulse(search, rs, noisy, pulse)
    if widening is None and band_known:
        return _widest(search, rs, noisy)
    target = FALLBACK_WIDENING if widening is None else widening
    return _to_widening(search, rs, noisy, target, asked=widening is not None)


def _sized_to_pulse(search: _Search, rs: list[float], noisy: bool, pulse: ShotPulse) -> RatioChoice:
    widest = search.design(rs[-1])[0]
    assert widest is not None  # rs holds evaluable designs only
    # The widest design's delay over its band (as _finish aligns it); another r's differs by its
    # designed poles' own DC group delay (closed form): no band edge per reading.
    anchor = compensated_delay_samples(search.model, widest, search.model_fbsd5_hz, search.edge5(rs[-1]))
    try:
        response = pulse.responses([search.model])  # the same for every r: simulated once
    except AnalysisError:  # no reading then: as a top that is not finite
        return _widest(search, rs, noisy)
    @cache  # r → error: the scan, the bisection and the result share readings
    def error(r: float) -> float:
        dcm, _ = search.design(r)
        if dcm is None:
            return math.nan
        delay = anchor + dcm.group_delay_samples - widest.group_delay_samples
        try:
            return float(pulse.peak_ratios_of(response, search.model.dc_gain, dcm, delay)[0]) - 1.0
        except AnalysisError:
            return math.nan

    top = error(rs[-1])
    if not math.isfinite(top):
        return _widest(search, rs, noisy)
    # Scanned on every third ratio (the peak changes slowly with r; each reading costs a band
    # edge), then bisected where its last run within PEAK_SETTLED of the top begins.
    coarse = rs[::-3][::-1]
    settled = [abs(error(r) - top) <= PEAK_SETTLED for r in coarse]
    i = len(coarse) - 1
    while i > 0 and settled[i - 1]:
        i -= 1
    r = coarse[i] if i == 0 else bisect(lambda x: abs(error(x) - top) <= PEAK_SETTLED, coarse[i - 1], coarse[i])
    got = error(r)
    edge = search.edge5(r)
    widening = edge / search.model_fbsd5_hz if search.model_fbsd5_hz > 0 else math.nan
    noise = search.design(r)[1]
    text = (f"sized to the pulse: ×{widening:.2f} (compensated ±5 % band {edge / 1e3:.4g} kHz) is where this pulse's "
            f"compensated peak settles (a wider band changes it by less than {100 * PEAK_SETTLED:g} %; the DCM itself "
            f"changes it by {100 * got:+.2f} %, predicted through the model); noise gain {noise:.3g} "
            f"(limit {search.noise_gain_limit:g})")
    if abs(top) > PULSE_CUT:
        stop = (f"the noise gain limit {search.noise_gain_limit:g}" if noisy
                else f"the band the shot supports (band limit: {search.cap})")
        text += (f"; {stop} cuts the pulse's content: even the widest design allowed changes its peak by "
                 f"{100 * top:+.1f} %")
        return RatioChoice(r, SizedTo.PULSE, text, True, got)
    return RatioChoice(r, SizedTo.PULSE, text, False, got)


def _widest_ratio(search: _Search, rs: list[float]) -> tuple[float, float]:
    """(the smallest r within WIDEST_WITHIN of the widest ±5 % band, that band in Hz): scanned
    on every third ratio, then bisected where the band first comes within it."""
    coarse = rs[::-3][::-1]
    edges = np.array([search.edge5(r) for r in coarse])
    best = float(np.max(edges))
    i = int(np.flatnonzero(edges >= WIDEST_WITHIN * best)[0])
    if i == 0:
        return coarse[0], best
    return bisect(lambda x: search.edge5(x) >= WIDEST_WITHIN * best, coarse[i - 1], coarse[i]), best


def _widest(search: _Search, rs: list[float], noisy: bool) -> RatioChoice:
    r, best = _widest_ratio(search, rs)
    widening = search.edge5(r) / search.model_fbsd5_hz if search.model_fbsd5_hz > 0 else math.nan
    stop = f"the noise gain limit {search.noise_gain_limit:g}" if noisy else f"the band limit ({search.cap})"
    text = (f"sized to the band the shot supports (no pulse to size it to): ×{widening:.2f}, within "
            f"{100 * (1 - WIDEST_WITHIN):g} % of the widest ±5 % band {stop} allows ({best / 1e3:.4g} kHz)")
    return RatioChoice(r, SizedTo.BAND, text, False)


def _to_widening(search: _Search, rs: list[float], noisy: bool, target: float, asked: bool) -> RatioChoice:
    """The smallest r reaching ×target, else the r of the widest band and why (the former rule)."""
    goal = target * search.model_fbsd5_hz
    why = "" if asked else " (neither a pulse nor a supported band is known to size it to)"
    kind = SizedTo.WIDENING if asked else SizedTo.FALLBACK
    first = next((i for i, r in enumerate(rs) if search.edge5(r) >= goal), None)
    if first is not None:
        r = rs[0] if first == 0 else bisect(lambda x: search.edge5(x) >= goal, rs[first - 1], rs[first])
        return RatioChoice(r, kind, None if asked else f"aimed for ×{target:g}{why}", False, target_widening=target)
    r, best = _widest_ratio(search, rs)
    aim = f"{target:g}× (±5 % band {goal / 1e3:.4g} kHz){why} was not reached: "
    got = (f"the widest band is {best / 1e3:.4g} kHz (×{best / search.model_fbsd5_hz:.2f})"
           if search.model_fbsd5_hz > 0 else "")
    if noisy:
        stop = f"the noise gain limit {search.noise_gain_limit:g} stops the ratio; "
    elif search.cap_edge_hz is not None and best >= 0.8 * search.cap_edge_hz:
        stop = f"the band limit ({search.cap}) caps it; "
    else:
        stop = ("the dynamics the DCM does not cancel (unsupported modes, the model's zeros) or the sample rate "
                "cap it; ")
    return RatioChoice(r, kind, aim + stop + got, True, target_widening=target)


def bisect(reached: Callable[[float], bool], lo: float, hi: float) -> float:
    """Smallest r in (lo, hi] with reached(r) (reached(lo) False, reached(hi) True), on a log scale.
    By hand: the band is a step-like function of r near an edge, so no root-finder applies."""
    for _ in range(30):
        mid = math.sqrt(lo * hi)
        lo, hi = (lo, mid) if reached(mid) else (mid, hi)
        if hi / lo < 1.0005:
            break
    return hi
