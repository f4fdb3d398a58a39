"""The pulse located in a record (the prepare stage of analysis.identify, before the noise):
where the reference carries the pulse and the response rings, each channel's pre-pulse baseline,
the fitted window, whether the record is cut short, and the quiet stretches (normalised units,
samples). Why the lead-in ends where it does: docs/decisions/0012.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.excitation import pulse_width

# Quiet stretches shorter than this are not used for a noise spectrum.
MIN_QUIET = 32
# The lead-in's end (_foot): where a FOOT_BOX-sample box-car of |x| last stands at FOOT_LEVEL × its
# median before the pulse.
FOOT_BOX = 5
FOOT_LEVEL = 2.0


@dataclass(frozen=True)
class Activity:
    """Stage "prepare": where the pulse is and where each channel is quiet (normalised units)."""

    u: np.ndarray  # the whole record, each channel's pre-pulse baseline removed
    y: np.ndarray
    baseline_u: float
    baseline_y: float
    pulse_start: int  # first sample of the reference's pulse (analysis.excitation.pulse_width)
    ref_busy: np.ndarray  # where the reference carries the pulse (bool per sample)
    start: int  # the fitted window [start, end)
    end: int
    truncated: bool  # the record ends before the response has died away
    cold_start: bool  # the pulse starts within the record's first samples
    noise_y0: float  # the response's rough noise level (pre-pulse RMS, or a robust level of the tail)
    u_segments: list[slice]  # the stretches where each channel is quiet (before motion is judged)
    y_segments: list[slice]
    lead_in_to_foot: bool = False  # the lead-in reaches the pulse's foot (the window's margins left none)

    @property
    def lead_in(self) -> int:
        """The lead-in at rest is samples [0, lead_in) (0: none)."""
        return self.u_segments[0].stop if self.u_segments and self.u_segments[0].start == 0 else 0


def locate_pulse(u: np.ndarray, y: np.ndarray, dt: float, max_delay: int) -> Activity:
    """Where each channel is busy: the reference above 2 % of its peak and 4× its noise floor
    (every pulse of a train, not only the largest), the response above 4 noise RMS until it
    stays quiet; each widened by the margins the filters and the delay need. The rest is quiet:
    there the noise is measured. The window runs from just before the pulse to where the
    response has died into its noise."""
    n = u.size
    try:
        pulse = pulse_width(u, dt)
    except AnalysisError as exc:
        raise AnalysisError(f"the reference has no pulse to identify from: {exc}") from None
    width = max(1, int(round(pulse.width_s / dt)))
    i_start = int(math.floor(pulse.start_s / dt))
    floor = float(np.median(np.convolve(np.abs(u), np.full(5, 0.2), mode="same")))  # the noise's level
    level = max(0.02 * float(np.max(np.abs(u))), 4.0 * floor)
    ref_busy = _busy(u, level, 2 * width + max_delay)
    first = int(np.argmax(ref_busy)) if np.any(ref_busy) else i_start
    pre_end = first
    if np.any(ref_busy) and first < MIN_QUIET:  # the margins leave no lead-in: it reaches the pulse's foot
        pre_end = max(first, _lead_in_end(u, y, int(np.argmax(_busy(u, level, 0))), width))
    base_u = float(np.mean(u[:pre_end])) if pre_end >= 16 else 0.0
    base_y = float(np.mean(y[:pre_end])) if pre_end >= 16 else 0.0
    u = u - base_u
    y = y - base_y
    noise_y0 = float(np.std(y[:pre_end])) if pre_end >= 16 else 0.0
    if noise_y0 == 0.0:  # no lead-in: a robust level from the record's last tenth
        tail = y[-max(n // 10, 16):]
        noise_y0 = float(1.4826 * np.median(np.abs(tail - np.median(tail))))
    resp_busy = ref_busy.copy()
    loud = _busy(y - _provisional_drift(y, pre_end, ref_busy), 4.0 * noise_y0, 0)
    for run in _runs(ref_busy):  # the response rings after each pulse until it stays quiet
        resp_busy[run.start : _settles(loud, run.start, max(50, 10 * width))] = True
    last_runs = _runs(resp_busy)
    last = last_runs[-1] if last_runs else slice(i_start, i_start + width)
    post_margin = max(20, 2 * width, (last.stop - last.start) // 4)
    end = min(n, last.stop + post_margin)
    truncated = last.stop + post_margin > n
    pre_window = max(3 * width, 32) + max_delay
    start = max(0, first - pre_window + 2 * width + max_delay) if np.any(ref_busy) else max(0, i_start - pre_window)
    cold_start = first < 16

    def quiet(busy: np.ndarray) -> list[slice]:
        """The runs outside `busy`, the first being the lead-in [0, pre_end) (to the margins, or to the
        pulse's foot when they leave none), each at least MIN_QUIET long."""
        runs = _runs(~busy)
        if np.any(ref_busy):
            runs = [slice(0, pre_end)] + [r for r in runs if r.start > 0]
        return [r for r in runs if r.stop - r.start >= MIN_QUIET]

    u_segments, y_segments = quiet(ref_busy), quiet(resp_busy)
    return Activity(u, y, base_u, base_y, i_start, ref_busy, start, end, truncated, cold_start, noise_y0, u_segments,
                    y_segments, pre_end > first)


def _busy(x: np.ndarray, level: float, widen: int) -> np.ndarray:
    """Samples where a 5-sample box-car of |x| exceeds `level`, widened by `widen` each side."""
    loud = np.convolve(np.abs(x), np.full(5, 0.2), mode="same") > level
    if widen > 0 and np.any(loud):
        loud = np.convolve(loud.astype(float), np.ones(2 * widen + 1), mode="same") > 0
    return loud


def _lead_in_end(u: np.ndarray, y: np.ndarray, cross: int, width: int) -> int:
    """Where the lead-in at rest ends when the window's margins leave none: before the earlier of
    the two channels' feet (_foot) ahead of `cross` (the reference's first sample at the pulse's
    level), less a guard of a quarter of the pulse's width and the box-car's length. The pulse's
    busy stretch is widened by twice its width and the delay for the window's margins, and the
    lead-in ends there when that leaves one (MIN_QUIET): the samples nearer the foot may hold its
    rise below the noise (on PTB's record the last 40 before its foot lift the reference's
    low-frequency noise 13 %, and taken always, the all-pole order on its hybrids went from 2 to 3
    and the FBSD ±5 % interval missed the known sensor on 7 of 8 seeds with half its lobe gain).
    A capture started 0.2 ms later than PTB's (the pulse's foot 0.16 ms in) had no lead-in left:
    its reference's noise was measured on the bar's motion after the pulse, ×11, the band stopped
    at 20 kHz and the FBSD intervals missed the sine's edges."""
    foot = min(_foot(u, cross), _foot(y, cross))
    end = foot - width // 4 - FOOT_BOX
    return end if end >= MIN_QUIET else 0  # a few samples are no lead-in (its noise, nor its baseline)


def _foot(x: np.ndarray, cross: int) -> int:
    """Where the pulse's foot leaves the lead-in's noise: scanning back from `cross` (past the
    foot), the last sample whose FOOT_BOX-sample box-car of |x| (its lead-in median removed) is
    at the lead-in's own level, FOOT_LEVEL × the box-car's median before `cross` (robust while
    the foot is the shorter part)."""
    if cross < 2 * MIN_QUIET:
        return 0
    part = x[:cross] - np.median(x[:cross])
    box = np.convolve(np.abs(part), np.full(FOOT_BOX, 1.0 / FOOT_BOX), mode="same")
    at_level = np.flatnonzero(box <= FOOT_LEVEL * np.median(box))
    return int(at_level[-1]) + 1 if at_level.size else 0


def _provisional_drift(y: np.ndarray, pre_end: int, ref_busy: np.ndarray) -> np.ndarray:
    """The line through the response's pre-pulse stretch and the record's last tenth (when both
    are clear of the reference's activity), against which its loudness is judged. A drifting
    response (a charge amplifier's drift, a zero shift after the shock) never returns to its
    pre-pulse level: judged against that level it stays loud to the record's end, the record is
    taken as cut short, its drift is never removed, and the fit chases the drift with a spare
    low-frequency pole-zero pair that moves the DC gain and the FBSD. Where the response still
    rings at the end, the ringing averages to the baseline: the line stays flat and the
    ringing stays loud."""
    n = y.size
    tail = max(n // 10, MIN_QUIET)
    busy = np.flatnonzero(ref_busy)
    if pre_end < 16 or busy.size == 0 or n - tail <= busy[-1]:
        return np.zeros(n)
    idx = np.concatenate((np.arange(pre_end), np.arange(n - tail, n)))
    slope, intercept = np.polyfit(idx, y[idx], 1)
    return slope * np.arange(n) + intercept


def _settles(loud: np.ndarray, start: int, quiet: int) -> int:
    """One past the last loud sample after `start` that is followed by `quiet` quiet samples (a
    stray loud sample of the noise further on does not count)."""
    idx = np.flatnonzero(loud[start:])
    if idx.size == 0:
        return start
    gaps = np.flatnonzero(np.diff(idx) > quiet)
    last = idx[gaps[0]] if gaps.size else idx[-1]
    return int(start + last + 1)


def _runs(mask: np.ndarray) -> list[slice]:
    """The contiguous runs of True in `mask`, as slices."""
    edges = np.flatnonzero(np.diff(np.concatenate(([0], mask.astype(np.int8), [0]))))
    return [slice(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2], strict=True)]
