"""Applying a DCM to data: whole, block by block with carried state, or aligned in time.

A stream may remove the latency (`DcmStream(align=True)`): whole samples are held back, the
fraction is removed by a fractional-delay FIR, and `flush()` returns the held-back tail.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from scipy import signal

from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.records import MAX_ABS_VALUE

if TYPE_CHECKING:
    from hopkinson.analysis.dcm import DCM


# Fractional part of a latency removed by a windowed-sinc FIR of 2·16 + 1 taps (Kaiser, β = 8):
# its response is within 2e-4 of the exact fractional delay below 0.3 × the sample rate
# (measured), far above where a compensated record (band-limited by its DCM) has content.
_ALIGN_HALF_TAPS = 16
_ALIGN_KAISER_BETA = 8.0


def fractional_delay_fir(delay_samples: float, half_taps: int = _ALIGN_HALF_TAPS) -> np.ndarray:
    """Taps of an FIR that delays by `delay_samples` (within ±1 of `half_taps`): a Kaiser-windowed
    sinc centred on the delay, normalised to unit DC gain (scipy's firwin gives only integer or
    half-integer delays)."""
    k = np.arange(2 * half_taps + 1, dtype=float) - delay_samples
    window = np.i0(_ALIGN_KAISER_BETA * np.sqrt(np.clip(1 - (k / (half_taps + 1)) ** 2, 0, None))) / np.i0(
        _ALIGN_KAISER_BETA
    )
    taps = np.sinc(k) * window
    return taps / np.sum(taps)


def fir_steady_state(taps: np.ndarray) -> np.ndarray:
    """scipy.signal.lfilter_zi(taps, [1.0]): the state of an FIR in its steady state for a unit
    input, zi[k] = Σ_{j>k} taps[j]. lfilter_zi solves an (N−1)² system for it (38 ms for the
    band limit's 1001 taps); for an FIR that system is bidiagonal with unit pivots, and its
    back-substitution is exactly this sum accumulated from the last tap: the same numbers
    (checked bit for bit against lfilter_zi), without the system."""
    b = np.asarray(taps, dtype=float)
    return np.cumsum(b[:0:-1])[::-1]


class DcmStream:
    """Apply a DCM block by block, carrying the filter state between blocks.

    initial="rest": the filter starts from zero state (as lfilter does by default);
    initial="steady": it starts in the steady state for a constant input equal to the
    first sample (no start-up transient on a record with an offset).
    align=True: the output is advanced by the DCM's latency (`DCM.latency_samples`, else its
    own group delay) so that it lines up with the reference: the whole samples are held back
    at the start (`process` returns fewer samples than it was given until they are used up),
    the fraction is removed by a fractional-delay FIR, and `flush()` returns the tail,
    computed by continuing the input with its last sample. A latency below zero (a response
    that leads its reference by more than the FIR's half length: the channels' skew, which the
    latency includes) is removed by delaying the output instead: it starts with that many
    samples of its initial level, and its last ones, past the input's length, are dropped.
    Every output is checked: a non-finite sample (an overflowing DCM) is an AnalysisError.
    """

    def __init__(self, dcm: DCM, initial: str = "rest", align: bool = False) -> None:
        if initial not in ("rest", "steady"):
            raise AnalysisError(f"DCM stream: initial must be 'rest' or 'steady', got {initial!r}")
        self.dcm = dcm
        self.initial = initial
        self.align = align
        self._sos = dcm.sos()
        self._fir: np.ndarray | None = None
        self._hold = 0
        self._delay = 0  # output samples to delay by (a latency below zero)
        if align:
            latency = dcm.latency_s / dcm.sample_interval_s
            whole = math.floor(latency)
            fraction = latency - whole
            if fraction > 1e-9:
                self._fir = fractional_delay_fir(_ALIGN_HALF_TAPS - fraction)
                whole += _ALIGN_HALF_TAPS
            self._hold, self._delay = max(whole, 0), max(-whole, 0)
        self.reset()

    @property
    def held_samples(self) -> int:
        """Output samples held back at the start to remove the latency (0 without align)."""
        return self._hold

    @property
    def delayed_samples(self) -> int:
        """Output samples the output is delayed by to remove a latency below zero (0 otherwise)."""
        return self._delay

    def reset(self) -> None:
        """Forget the carried state: the next block starts a new stream."""
        self._zi: np.ndarray | None = None
        self._band_zi: np.ndarray | None = None  # the DCM's own FIR stage
        self._fir_zi: np.ndarray | None = None  # the alignment's fractional delay
        self._to_drop = self._hold
        self._queue: np.ndarray | None = None  # the delay line (None: not started)
        self._last = 0.0
        self.samples_processed = 0
        self.samples_returned = 0

    def process(self, block: np.ndarray) -> np.ndarray:
        """Compensate the next block of samples and return what is ready (the same length
        without align)."""
        x = np.asarray(block, dtype=float)
        if x.ndim != 1:
            raise AnalysisError("DCM stream: a block must be a 1-D array of samples")
        if x.size == 0:
            return x.copy()
        if not np.all(np.isfinite(x)):
            raise AnalysisError(f"DCM stream: NaN or infinite sample at {self.samples_processed + int(np.flatnonzero(~np.isfinite(x))[0])}")
        y = self._filter(x)
        self.samples_processed += x.size
        self._last = float(x[-1])
        return self._release(y)

    def flush(self) -> np.ndarray:
        """The held-back tail (align only): the input continued by its last sample through the
        filter, so the whole output is as long as the whole input. Ends the stream."""
        missing = self.samples_processed - self.samples_returned
        if missing <= 0:
            return np.zeros(0)
        y = self._release(self._filter(np.full(self._hold, self._last)))
        return y[:missing]

    def _filter(self, x: np.ndarray) -> np.ndarray:
        if self._zi is None:
            steady = self.initial == "steady"
            self._zi = signal.sosfilt_zi(self._sos) * x[0] if steady else np.zeros((self._sos.shape[0], 2))
        y, self._zi = signal.sosfilt(self._sos, x, zi=self._zi)
        band = self.dcm.fir
        if band is not None:
            if self._band_zi is None:
                level = y[0] if self.initial == "steady" else 0.0
                self._band_zi = fir_steady_state(band) * level
            y, self._band_zi = signal.lfilter(band, [1.0], y, zi=self._band_zi)
        if self._fir is not None:
            if self._fir_zi is None:
                level = y[0] if self.initial == "steady" else 0.0
                self._fir_zi = fir_steady_state(self._fir) * level
            y, self._fir_zi = signal.lfilter(self._fir, [1.0], y, zi=self._fir_zi)
        bad = ~(np.abs(y) <= MAX_ABS_VALUE)  # NaN and ±inf are bad too
        if np.any(bad):
            at = self.samples_processed + int(np.flatnonzero(bad)[0])
            raise AnalysisError(
                f"the DCM's output is not a finite number within ±{MAX_ABS_VALUE:g} from input sample {at} on (it "
                f"overflows: gain {self.dcm.gain:g}, DC gain {self.dcm.dc_gain:g}); this DCM cannot compensate "
                "this record"
            )
        return y

    def _release(self, y: np.ndarray) -> np.ndarray:
        if self._delay:
            if self._queue is None:  # the initial level: the filter's first output from rest or steady state
                self._queue = np.full(self._delay, y[0] if self.initial == "steady" else 0.0)
            line = np.concatenate([self._queue, y])
            y, self._queue = line[: y.size], line[y.size :]
        if self._to_drop:
            drop = min(self._to_drop, y.size)
            self._to_drop -= drop
            y = y[drop:]
        self.samples_returned += y.size
        return y


# apply_rows filters only the samples asked for when no sample it leaves out could have
# overflowed: the input's largest magnitude × the DCM's and the alignment's Σ|h| stays this far
# below MAX_ABS_VALUE (the impulse response is cut where it has decayed to 1e-10: a wide margin).
_BOUND_MARGIN = 1e6


def apply_rows(dcm: DCM, rows: np.ndarray, align: bool = False, samples: int | None = None) -> np.ndarray:
    """`apply(dcm, row, align=align)` from rest for every row of `rows` (records of one length)
    in one filter call per stage: the same sections, FIR, held samples and tail (the input
    continued by its last sample) as DcmStream, so the same numbers; for many records (the
    compensated peak's model draws) without a DcmStream, its sections and its FIR per record.
    `samples`: only the first this many output samples are returned (None: all): the filters
    are causal, so the input past them is not filtered, unless an output there could overflow
    (it would be refused, as over the whole record)."""
    x = np.atleast_2d(np.asarray(rows, dtype=float))
    stream = DcmStream(dcm, "rest", align)
    if x.shape[1] == 0:
        return x.copy()
    if not np.all(np.isfinite(x)):
        raise AnalysisError("DCM: NaN or infinite sample in a record to compensate")
    n, hold, delay = x.shape[1], stream.held_samples, stream.delayed_samples
    keep = n if samples is None else min(n, max(int(samples), 0))
    if keep + hold < n and _cannot_overflow(dcm, stream, x):
        x = x[:, : keep + hold]
        n = keep
    if hold:
        x = np.concatenate([x, np.repeat(x[:, -1:], hold, axis=1)], axis=1)
    if delay:  # from rest: the delayed output starts at zero (DcmStream._release)
        x = np.concatenate([np.zeros((x.shape[0], delay)), x], axis=1)
    y = dcm.filter(x, axis=1)
    if stream._fir is not None:
        y = signal.lfilter(stream._fir, [1.0], y, axis=1)
    bad = ~(np.abs(y) <= MAX_ABS_VALUE)
    if np.any(bad):
        raise AnalysisError(
            f"the DCM's output is not a finite number within ±{MAX_ABS_VALUE:g} (it overflows: gain {dcm.gain:g}, DC "
            f"gain {dcm.dc_gain:g}); this DCM cannot compensate this record"
        )
    return y[:, hold : hold + keep]


def _cannot_overflow(dcm: DCM, stream: DcmStream, x: np.ndarray) -> bool:
    """No output of the DCM (and the stream's alignment) from rest can pass MAX_ABS_VALUE for
    this input, by its Σ|h| (False: not known, or it could)."""
    try:
        gain = dcm.l1_gain()
    except AnalysisError:
        return False
    if stream._fir is not None:
        gain *= float(np.sum(np.abs(stream._fir)))
    return float(np.max(np.abs(x))) * gain * _BOUND_MARGIN <= MAX_ABS_VALUE


def apply(
    dcm: DCM, data: np.ndarray, initial: str = "rest", block_samples: int | None = None, align: bool = False
) -> np.ndarray:
    """Compensate a record: at once, or in blocks of `block_samples` through a DcmStream.

    Both give the same samples (the stream carries the filter state between blocks). align:
    the output is advanced by the DCM's latency (see DcmStream), same length as the input.
    """
    stream = DcmStream(dcm, initial, align)
    x = np.asarray(data, dtype=float)
    if block_samples is not None and block_samples < 1:
        raise AnalysisError(f"DCM: block_samples must be at least 1, got {block_samples}")
    step = x.size if block_samples is None else block_samples
    parts = [stream.process(x[i : i + step]) for i in range(0, x.size, max(step, 1))]
    parts.append(stream.flush())
    return np.concatenate(parts) if x.size else x.copy()
