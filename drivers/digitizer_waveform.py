"""A digitizer channel's record (`Waveform`) and the sample formats it can come in.

Digitizers send samples as int8, uint8, int16, uint16 or float32 in either byte order, with a
preamble saying how codes become volts (volts = code·scale_v + offset_v). The codes are kept
exactly as sent, in their own dtype (native byte order for arithmetic): a uint16 40000 stays
40000, it never becomes −25536. A sample that cannot be represented (a float NaN or ±inf, a
block whose length is not a whole number of samples) is an error, never a silent wrap.

`code_range` is the format's full-scale codes (the rails): an integer format's whole range; for
float32 samples, the codes of ±(the channel's range) (the instrument clips its converter there).
`clipped_samples()` counts samples at or beyond either rail: clipping is judged against the
instrument, never against the record's own extremes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

SAMPLE_FORMATS = ("int8", "uint8", "int16", "uint16", "float32")
BYTE_ORDERS = ("little", "big")


class SampleFormatError(ValueError):
    """Samples that cannot be decoded or represented (the caller names instrument and command)."""


def sample_dtype(sample_format: str, byte_order: str = "little") -> np.dtype:
    """The NumPy dtype of a sample format as sent ("int16", "big" -> '>i2')."""
    if sample_format not in SAMPLE_FORMATS:
        raise SampleFormatError(f"unknown sample format {sample_format!r} (known: {', '.join(SAMPLE_FORMATS)})")
    if byte_order not in BYTE_ORDERS:
        raise SampleFormatError(f"unknown byte order {byte_order!r} (known: little, big)")
    return np.dtype(sample_format).newbyteorder("<" if byte_order == "little" else ">")


def integer_rails(dtype: np.dtype) -> tuple[float, float]:
    """The full-scale codes of an integer format (e.g. int16: (-32768.0, 32767.0))."""
    info = np.iinfo(dtype)
    return float(info.min), float(info.max)


def decode_samples(payload: bytes | memoryview, dtype: np.dtype, count: int) -> np.ndarray:
    """`count` samples of `dtype` from a block payload, in native byte order (values unchanged).

    Raises SampleFormatError for a payload that is not exactly `count` samples or that holds a
    float sample which is not a finite number.
    """
    dtype = np.dtype(dtype)
    expected = count * dtype.itemsize
    if len(payload) != expected:
        raise SampleFormatError(f"block has {len(payload)} bytes, the preamble announced {count} {dtype.name} "
                                f"samples ({expected} bytes)")
    codes = np.frombuffer(payload, dtype=dtype)
    if not dtype.isnative:
        codes = codes.astype(dtype.newbyteorder("="))  # the same values in native order: never a wrap
    if dtype.kind == "f":
        bad = np.flatnonzero(~np.isfinite(codes))
        if bad.size:
            raise SampleFormatError(f"{bad.size} float samples are not finite numbers (first: sample {bad[0]} "
                                    f"= {codes[bad[0]]!r})")
    return codes


@dataclass(frozen=True)
class Waveform:
    """One channel's record as the digitizer sent it.

    channel: the instrument's channel name (e.g. "CH2", "C2", "CHAN2").
    codes: the samples in their native dtype (int8/uint8/int16/uint16/float32), read-only.
    volts = codes * scale_v + offset_v. trigger_index: the sample at the trigger (t = 0).
    code_range: the format's full-scale codes (low, high); see the module docstring.
    """

    channel: str
    codes: np.ndarray
    scale_v: float
    offset_v: float
    sample_interval_s: float
    trigger_index: int
    code_range: tuple[float, float]

    @property
    def sample_rate_hz(self) -> float:
        return 1.0 / self.sample_interval_s

    def volts(self) -> np.ndarray:
        """The samples in volts (float64)."""
        return self.codes * self.scale_v + self.offset_v

    def time_s(self) -> np.ndarray:
        """Sample times in seconds, 0 at the trigger."""
        return (np.arange(self.codes.size) - self.trigger_index) * self.sample_interval_s

    def clipped_samples(self) -> int:
        """How many samples sit at (or beyond) either full-scale code."""
        low, high = self.code_range
        return int(np.count_nonzero((self.codes <= low) | (self.codes >= high)))

    def full_scale_v(self) -> tuple[float, float]:
        """The volts of the two rails (low, high)."""
        low, high = self.code_range
        ends = sorted((low * self.scale_v + self.offset_v, high * self.scale_v + self.offset_v))
        return ends[0], ends[1]
