"""The fringe tracker: the beat's phase where the grating leaves rest (step 3 of
analysis/doppler.py's method), read from the PM signal itself up to the hand-over frequency,
then joined to the analytic phase (analysis/beat_phase.py)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import signal

from hopkinson.analysis.errors import AnalysisError


def onset_phase(x: np.ndarray, dt: float, m: int, phase: np.ndarray, k_h: int, handover_hz: float,
                offset_v: float, smooth_hz: np.ndarray, power: np.ndarray, noise_power: float,
                low_hz: float, source: str) -> tuple[np.ndarray, int, float]:
    """Replace the analytic phase before the hand-over block k_h by the fringe tracker's.

    Returns the new phase (block means), the onset block and the beat amplitude used.
    """
    k_a, k_b = _onset_window(smooth_hz, k_h, handover_hz, low_hz, m * dt, phase.size, source)
    y, t_y, down = _tracker_signal(x, dt, m, k_a, k_b, offset_v, handover_hz)
    amplitude_h = float(np.sqrt(max(np.mean(power[k_h:k_b]) - noise_power, 1e-30)))
    rest = _Rest.of(y, t_y)
    turns, kinds = _turning_points(y, 0.5 * amplitude_h)
    first = _first_extreme(y, t_y, turns, kinds, rest, amplitude_h, down * dt)
    theta, rest_phase = _unfold(y, t_y, first, rest, amplitude_h)
    # Block means (the tracker phase at block centres) and the join with the analytic phase:
    # aligned on the tracker over the overlap, then cross-faded (raised cosine) so neither a
    # step nor a kink is left at the hand-over.
    centres = (np.arange(k_a, k_b) * m + 0.5 * (m - 1)) * dt
    tracked = np.interp(centres, t_y, theta)
    join = slice(k_h - k_a, k_b - k_a)
    out = phase + float(np.mean(tracked[join] - phase[k_h:k_b]))
    fade = 0.5 * (1.0 + np.cos(np.pi * np.arange(k_b - k_h) / (k_b - k_h)))
    out[k_h:k_b] = fade * tracked[join] + (1.0 - fade) * out[k_h:k_b]
    out[k_a:k_h] = tracked[: k_h - k_a]
    out[:k_a] = rest_phase
    moving = np.flatnonzero(theta > rest_phase + 0.1)
    k_on = k_a + int(np.searchsorted(centres, t_y[moving[0]])) if moving.size else k_h
    return out, k_on, amplitude_h


def _onset_window(smooth_hz: np.ndarray, k_h: int, handover_hz: float, low_hz: float, block_s: float,
                  n_blocks: int, source: str) -> tuple[int, int]:
    """Blocks [k_a, k_b) the fringe tracker reads: from well before the motion to past the
    hand-over block k_h.

    The analytic beat frequency, coarse below the hand-over but good enough for this, falls
    below a tenth of the hand-over frequency at block k_10; the motion began less than
    (k_h − k_10) before that for any onset whose velocity grows like tᵖ with p ≤ 3, so twice
    that span (and 5 µs more) reaches into rest. After the hand-over the tracker runs on until
    the analytic phase has settled (the step the PM level makes when the grating leaves rest
    rings in the analytic band's low edge for a few of its periods) or the beat nears the
    tracker's low-pass (3× the hand-over), whichever comes first.
    """
    slow = np.flatnonzero(smooth_hz[:k_h] < 0.1 * handover_hz)
    if slow.size < max(10, int(2e-6 / block_s)):  # ≥ 2 µs of rest (not just the record's edge)
        raise AnalysisError(
            f"{source}: the record starts while the object is already moving (no rest before the pulse): "
            f"record more pre-trigger"
        )
    k_10 = int(slow[-1])
    k_a = max(0, k_10 - 2 * max(k_h - k_10, 1) - int(round(5e-6 / block_s)))
    settle = int(np.ceil(5.0 / (low_hz * block_s)))
    fast = np.flatnonzero(smooth_hz[k_h:] > 3.0 * handover_hz)
    overlap = max(4, min(settle, int(fast[0]) if fast.size else settle))
    return k_a, min(n_blocks, k_h + overlap + 1)


def _tracker_signal(x: np.ndarray, dt: float, m: int, k_a: int, k_b: int, offset_v: float,
                    handover_hz: float) -> tuple[np.ndarray, np.ndarray, int]:
    """The PM signal of blocks [k_a, k_b) minus its offset, low-passed (zero-phase Kaiser FIR,
    ends padded with their edge value) at 5× the hand-over frequency and sampled at ~10× that
    cut-off; with its raw-record times and the down-sampling factor."""
    fs = 1.0 / dt
    cutoff_hz = 5.0 * handover_hz
    down = max(1, int(fs // (10.0 * cutoff_hz)))
    taps = signal.firwin(int(8 * fs / cutoff_hz) | 1, cutoff_hz, window=("kaiser", 8.0), fs=fs)
    raw = x[k_a * m : k_b * m].astype(float) - offset_v
    y = signal.oaconvolve(np.pad(raw, taps.size // 2, mode="edge"), taps, mode="valid")[::down]
    return y, (k_a * m + np.arange(y.size) * down) * dt, down


@dataclass(frozen=True)
class _Rest:
    """The rest at the start of the tracker's window (its first quarter): level and noise.

    The level drifts with the slow amplitude fluctuation (A·cos φ0 changes with A): over a rest
    of ≥ 20 µs a straight line through it is extrapolated; a shorter one is taken flat at the
    median of its second half (nearest the motion). The noise is y's robust spread there.
    """

    n: int  # samples of y in the rest
    line: np.ndarray  # polynomial (numpy.polyval order) in time since t0
    t0: float
    noise: float

    @classmethod
    def of(cls, y: np.ndarray, t_y: np.ndarray) -> _Rest:
        n = max(8, y.size // 4)
        if t_y[n - 1] - t_y[0] >= 20e-6:
            line = np.polyfit(t_y[:n] - t_y[0], y[:n], 1)
        else:
            line = np.array([0.0, float(np.median(y[n // 2 : n]))])
        noise = 1.4826 * float(np.median(np.abs(y[:n] - np.median(y[:n]))))
        return cls(n, line, float(t_y[0]), noise)

    def level(self, t: np.ndarray | float) -> np.ndarray | float:
        return np.polyval(self.line, np.asarray(t) - self.t0)


@dataclass(frozen=True)
class _FirstExtreme:
    """The fringe extremes from the rest on, after the decision about the rest's branch."""

    turns: np.ndarray  # indices into y
    kinds: np.ndarray  # +1 maximum, −1 minimum
    far: int  # index of the first extreme far from the rest level (the onset ends there)
    rest_on_extreme: bool  # the rest is put on turns[0], an extreme too close to tell
    y_smooth: np.ndarray
    noise: float  # what the smoothed signal must move to be seen (3 σ + 1 % of the amplitude)
    rest_level: float  # the rest level at the decision


def _first_extreme(y: np.ndarray, t_y: np.ndarray, turns: np.ndarray, kinds: np.ndarray, rest: _Rest,
                   amplitude_h: float, sample_s: float) -> _FirstExtreme:
    """Decide whether the grating passed a fringe's extreme right after leaving rest.

    The trigger's extremes before the first one far (≥ half an amplitude) from the rest level
    may be the rest's own noisy highs and lows. Between the rest and that far extreme the
    grating turned at most once, on the rest's side (a "near" extreme: the rest sat just short
    of a fringe's extreme). If it did, the signal reached that extreme shortly before it last
    crossed the rest level towards the far one; if not, it only left the rest level there. The
    peak of the signal, smoothed over a quarter of the first half-fringe, in the two
    half-fringes before that crossing decides: beyond the rest level by more than twice the
    noise, a near extreme; else none, unless the rest itself is that close to the extreme, in
    which case the rest is put on the extreme (in doubt this costs at most the small distance
    to it, instead of twice it).
    """
    width = max(1, int(0.25e-6 / sample_s)) | 1
    rest_level = float(rest.level(t_y[0]))
    far = np.flatnonzero(np.abs(y[turns] - rest.level(t_y[turns])) >= 0.5 * amplitude_h) if turns.size \
        else np.zeros(0, int)
    if not (far.size and far[0] + 1 < turns.size):
        return _FirstExtreme(turns, kinds, y.size, False, _boxcar(y, width),
                             _smoothed_noise(rest.noise, width) + 0.01 * amplitude_h, rest_level)
    j = int(far[0])
    big = int(turns[j])
    near_kind = -int(kinds[j])
    half_fringe = int(turns[j + 1] - big)
    width = max(1, half_fringe // 4) | 1
    y_smooth = _boxcar(y, width)
    near_side = np.flatnonzero((y_smooth[:big] - rest.level(t_y[:big])) * near_kind >= 0)
    crossing = int(near_side[-1]) if near_side.size else big
    search = np.arange(max(0, crossing - 2 * half_fringe), crossing + 1)
    best = int(search[np.argmax(y_smooth[search] * near_kind)])
    extreme = float(_parabolic_extreme(np.abs(y), turns[j : j + 1])[0])  # fringe amplitude
    noise = _smoothed_noise(rest.noise, width) + 0.01 * extreme
    rest_level = float(rest.level(t_y[best]))
    excursion = float(y_smooth[best]) * near_kind - rest_level * near_kind
    turns, kinds = turns[j:], kinds[j:]
    on_extreme = excursion <= 2.0 * noise and extreme - abs(rest_level) <= 2.0 * noise + 0.01 * extreme
    if on_extreme or excursion > 2.0 * noise:
        turns = np.concatenate([[best], turns])
        kinds = np.concatenate([[near_kind], kinds])
    return _FirstExtreme(turns, kinds, big, on_extreme, y_smooth, noise, rest_level)


def _unfold(y: np.ndarray, t_y: np.ndarray, first: _FirstExtreme, rest: _Rest,
            amplitude_h: float) -> tuple[np.ndarray, float]:
    """Monotonic phase θ of y = A·cos θ from the extremes' order, and the rest phase."""
    turns, kinds = first.turns, first.kinds
    idx = np.arange(y.size)
    # Amplitude through the extremes (each one's distance from the offset, a parabola fitted
    # around it), held before the first one and after the last one (a slow fluctuation changes
    # it by well under 1 % over an onset; extrapolating a slope from a few noisy extremes is
    # worse). A rest put on an extreme gives the amplitude there.
    if turns.size:
        amplitude = np.interp(t_y, t_y[turns], _parabolic_extreme(np.abs(y), turns))
        if first.rest_on_extreme:
            amplitude[: turns[1] if turns.size > 1 else y.size] = abs(first.rest_level)
    else:
        amplitude = np.full(y.size, amplitude_h)
    # Near a fringe's extreme (|cos θ| > 0.95) arccos amplifies noise (dθ = dc / sin θ). Before
    # the first far extreme (the onset, slow fringes) α is taken there from the smoothed signal;
    # later, where the fringes are fast and regular, θ is interpolated in time (below).
    alpha = np.arccos(np.clip(y / amplitude, -1.0, 1.0))
    ill = np.abs(y / amplitude) > 0.95
    early = ill & (idx < first.far)
    alpha[early] = np.arccos(np.clip(first.y_smooth / amplitude, -1.0, 1.0))[early]
    # Branch of each sample: after a maximum the fringe falls (θ = α), after a minimum it rises
    # (θ = 2π − α); before the first extreme, the branch that leads into it.
    if kinds.size:
        kind_next = np.concatenate([kinds, [-kinds[-1]]])[np.searchsorted(turns, idx, side="left")]
    else:  # no extreme: one direction throughout, taken from the trend of y
        kind_next = np.full(y.size, 1 if y[-1] > y[rest.n] else -1)
    theta = np.where(kind_next > 0, 2.0 * np.pi - alpha, alpha)
    theta += 2.0 * np.pi * np.searchsorted(turns[kinds > 0], idx, side="left")
    # Departure from rest: the last sample before the first real extreme (the far one when the
    # rest was put on an extreme) at which the smoothed signal is still within the noise of the
    # rest level. Up to there the phase is held at the rest phase: that of the rest level on the
    # branch leading into the first extreme (from the level, not from a median of noisy arccos
    # values, which are biased near an extreme), or the extreme's own phase.
    end = first.far if first.rest_on_extreme else (int(turns[0]) if turns.size else y.size)
    at_rest = np.flatnonzero(np.abs(first.y_smooth[:end] - rest.level(t_y[:end])) <= first.noise)
    held = max(int(at_rest[-1]) + 1 if at_rest.size else 0, rest.n // 2)
    if first.rest_on_extreme:
        rest_phase = float(theta[turns[0]])
    else:
        k = min(held, y.size - 1)
        alpha_rest = float(np.arccos(np.clip(rest.level(t_y[k]) / amplitude[k], -1.0, 1.0)))
        rest_phase = (2.0 * np.pi - alpha_rest if kind_next[k] > 0 else alpha_rest) \
            + 2.0 * np.pi * int(np.searchsorted(turns[kinds > 0], k, side="left"))
    theta[:held] = rest_phase
    good = ~ill | early
    good[:held] = True
    theta[~good] = np.interp(idx[~good], idx[good], theta[good])
    theta = np.maximum(theta, rest_phase)
    if first.rest_on_extreme:
        # On an extreme the signal hides the first part of the motion (1 − cos δ ≈ δ²/2 stays
        # within the noise): the phase there is continued back from where it is observable
        # along a power law δ = c·(t − t0)^p (any onset whose velocity grows like a power of
        # time; a half-sine gives p = 3).
        visible = float(np.sqrt(2.0 * first.noise / max(abs(first.rest_level), 1e-30)))
        _extrapolate_onset(theta, t_y, rest_phase, first.far, visible)
    return theta, rest_phase


def _extrapolate_onset(theta: np.ndarray, t: np.ndarray, rest_phase: float, end: int, visible: float) -> None:
    """In place: replace θ between the rest and the first sample where it has moved 1.5×
    `visible` from `rest_phase` by the power law δ = c·(t − t0)^p (1 ≤ p ≤ 4) fitted to the
    part that moved between 1.5× `visible` and π/2 (fit in log-log for each start t0 on a grid;
    the best one wins)."""
    delta = theta[:end] - rest_phase
    fit_range = np.flatnonzero((delta >= 1.5 * visible) & (delta <= 0.5 * np.pi))
    if fit_range.size < 8:
        return
    first = int(fit_range[0])
    t_first = t[first]
    span = t[fit_range[-1]] - t_first
    best: tuple[float, float, float, float] | None = None
    for t0 in t_first - span * np.linspace(0.05, 3.0, 60):
        if t0 < t[0]:
            break
        lt = np.log(t[fit_range] - t0)
        ld = np.log(delta[fit_range])
        p, logc = np.polyfit(lt, ld, 1)
        if not 1.0 <= p <= 4.0:
            continue
        err = float(np.sum((ld - (p * lt + logc)) ** 2))
        if best is None or err < best[0]:
            best = (err, float(t0), float(p), float(logc))
    if best is None:
        return
    _, t0, p, logc = best
    bridge = np.arange(max(0, int(np.searchsorted(t, t0))), first)
    theta[bridge] = rest_phase + np.exp(logc) * (t[bridge] - t0) ** p
    theta[: bridge[0] if bridge.size else first] = np.minimum(theta[: bridge[0] if bridge.size else first],
                                                              rest_phase)


def _boxcar(y: np.ndarray, width: int) -> np.ndarray:
    """Moving mean over `width` (odd) samples, ends padded with their edge value."""
    return np.convolve(np.pad(y, width // 2, mode="edge"), np.ones(width) / width, mode="valid")


def _smoothed_noise(noise_y: float, width: int) -> float:
    """Three standard deviations of y's noise after a `width`-sample boxcar (y is sampled at
    10× its low-pass cut-off, so ~5 consecutive samples are correlated)."""
    return 3.0 * noise_y / np.sqrt(max(width / 5.0, 1.0))


def _parabolic_extreme(y: np.ndarray, at: np.ndarray) -> np.ndarray:
    """Height of the peaks of `y` (≥ 0 near them) at the indices `at`: the vertex of a parabola
    fitted by least squares to the contiguous samples within 10 % of the peak sample (cos θ
    within 0.45 rad of its extreme; the quartic term costs < 0.2 %). Using many samples keeps
    the noise of single samples, and the upward bias of picking the largest, out of it."""
    heights = np.empty(len(at))
    for j, i in enumerate(np.asarray(at, dtype=int)):
        level = 0.9 * y[i]
        lo = i
        while lo > 0 and y[lo - 1] >= level:
            lo -= 1
        hi = i
        while hi < y.size - 1 and y[hi + 1] >= level:
            hi += 1
        if hi - lo < 2:
            lo, hi = max(0, i - 1), min(y.size - 1, i + 1)
        k = np.arange(lo, hi + 1) - i
        c2, c1, c0 = np.polyfit(k, y[lo : hi + 1], 2)
        heights[j] = c0 - 0.25 * c1 * c1 / c2 if c2 < 0 else y[i]
    return heights


def _turning_points(y: np.ndarray, hysteresis: float) -> tuple[np.ndarray, np.ndarray]:
    """Indices and kinds (+1 maximum, −1 minimum) of the extremes of `y` confirmed by a move of
    more than `hysteresis` away from them (a Schmitt trigger; noise smaller than that is ignored).

    A sequential scan (a few thousand samples of the onset window): numpy has no vector form
    of a hysteresis comparator.
    """
    idx: list[int] = []
    kinds: list[int] = []
    hi_i = lo_i = 0
    state = 0  # 0: undecided, +1: rising (looking for a maximum), −1: falling
    for i in range(1, y.size):
        v = y[i]
        if state >= 0 and v > y[hi_i]:
            hi_i = i
        if state <= 0 and v < y[lo_i]:
            lo_i = i
        if state >= 0 and v < y[hi_i] - hysteresis:
            idx.append(hi_i)
            kinds.append(1)
            state, lo_i = -1, i
        elif state <= 0 and v > y[lo_i] + hysteresis:
            idx.append(lo_i)
            kinds.append(-1)
            state, hi_i = 1, i
    return np.asarray(idx, dtype=int), np.asarray(kinds, dtype=int)
