"""A table file's clipped channel, told from its flat top (NumPy only: `hopkinson identify`
loads it for every table file, and the identification path loads no SciPy module).

A shot file's clipping is judged against its digitizer's full scale
(analysis.full_scale.check_not_clipped); a table file (CSV, NPZ) carries none, so a channel that
holds its extreme value much longer than a smooth peak would is warned about instead.
"""

from __future__ import annotations

import math

import numpy as np

from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.records import Record

# A table file's channel held at its extreme this many times longer than a smooth peak in its own
# quantisation steps would be, and for at least FLAT_TOP_MIN_SAMPLES samples, reads as clipped.
FLAT_TOP_FACTOR = 3.0
FLAT_TOP_MIN_SAMPLES = 4


def flat_top_warnings(record: Record, source: str) -> list[str]:
    """What `check_not_clipped` cannot judge for a table file (no digitizer full scale): each
    channel's longest run of samples exactly at its extreme (of its pulse's polarity), against
    the run a smooth peak holds in the channel's own quantisation step q (the smallest step
    between its distinct values near the peak): (3W/π)·√(2q/P) samples for a half-sine of
    half-height width W and peak P. A run FLAT_TOP_FACTOR times that, and at least
    FLAT_TOP_MIN_SAMPLES, is warned about: a clipped channel reads its peak, the sensitivity and
    the FBSD wrong. PTB's record (floats, W ≈ 600 samples at 10 MS/s) holds its extreme for 1
    sample; quantised in 12 bits over 1.25× its peak for 9–11, in 8 bits over 4× for 47–49 (none
    warned); its response clipped at 90 % of its peak for 124, at 99 % for 39 (both warned).
    A record resampled after it was clipped no longer holds exact values: not judged."""
    from hopkinson.analysis.excitation import pulse_width

    out = []
    for name, x in (("reference", record.reference), ("response", record.response)):
        x = np.asarray(x, dtype=float)
        if x.size == 0 or not np.all(np.isfinite(x)):  # not judged: the identification refuses such a channel
            continue
        centre = float(np.median(x))
        sign = 1.0 if np.max(x) - centre >= centre - np.min(x) else -1.0
        v = sign * (x - centre)
        peak = float(np.max(v))
        try:
            width = pulse_width(v, record.sample_interval_s).width_s / record.sample_interval_s
        except AnalysisError:
            continue
        at = np.concatenate(([0], (v == peak).astype(np.int8), [0]))
        edges = np.flatnonzero(np.diff(at))
        run = int(np.max(edges[1::2] - edges[::2]))
        near = np.unique(v[v >= 0.9 * peak])
        step = float(np.min(np.diff(near))) if near.size > 1 else peak
        expected = 3.0 * width / math.pi * math.sqrt(2.0 * step / peak) if peak > 0 else 0.0
        if run >= max(FLAT_TOP_MIN_SAMPLES, FLAT_TOP_FACTOR * expected):
            out.append(f"{source}: the {name} channel holds its extreme value for {run} samples "
                       f"({run * record.sample_interval_s * 1e6:.3g} µs, {run / width:.0%} of its pulse's half-height "
                       f"width; a smooth peak in its quantisation steps would hold it for ~{expected:.2g}): is it clipped? "
                       "A table file carries no digitizer full scale to judge it by; a clipped channel reads the "
                       "peak, the sensitivity and the FBSD wrong")
    return out
