"""Sample decoding, full scale and clipping of a Waveform, and the settings comparison ARM uses."""

from __future__ import annotations

import numpy as np
import pytest

from hopkinson.drivers.digitizer_settings import DigitizerSettings
from hopkinson.drivers.digitizer_waveform import (
    SampleFormatError,
    Waveform,
    decode_samples,
    sample_dtype,
)


@pytest.mark.parametrize("order", ["little", "big"])
def test_unsigned_and_signed_words_keep_their_values(order: str) -> None:
    values = [40000, 0, 65535, 32768, 1]
    raw = np.array(values, dtype=sample_dtype("uint16", order)).tobytes()
    codes = decode_samples(raw, sample_dtype("uint16", order), 5)
    assert codes.dtype == np.uint16 and codes.dtype.isnative and codes.tolist() == values
    raw = np.array([-32768, -1, 32767], dtype=sample_dtype("int16", order)).tobytes()
    assert decode_samples(raw, sample_dtype("int16", order), 3).tolist() == [-32768, -1, 32767]


def test_what_cannot_be_represented_is_an_error() -> None:
    with pytest.raises(SampleFormatError, match="block has 5 bytes, the preamble announced 3 int16"):
        decode_samples(b"\x00" * 5, np.dtype("<i2"), 3)
    raw = np.array([1.0, np.inf, -np.inf], dtype=">f4").tobytes()
    with pytest.raises(SampleFormatError, match="2 float samples are not finite numbers .first: sample 1"):
        decode_samples(raw, np.dtype(">f4"), 3)
    with pytest.raises(SampleFormatError, match="unknown sample format 'int24'"):
        sample_dtype("int24")


def test_clipping_is_judged_at_the_format_rails_not_the_record_extremes() -> None:
    small = Waveform("CH2", np.array([0, 100, 200, 150], dtype=np.int16), 1e-4, 0.0, 1e-8, 0, (-32768.0, 32767.0))
    assert small.clipped_samples() == 0  # a small pulse on a wide range is not clipped at its own peak
    railed = Waveform("C2", np.array([0, 127, 127, -128, 5], dtype=np.int8), 0.08, 0.0, 1e-8, 1, (-128.0, 127.0))
    assert railed.clipped_samples() == 3
    assert railed.full_scale_v() == pytest.approx((-10.24, 10.16))
    assert railed.time_s()[1] == 0.0 and railed.volts()[1] == pytest.approx(10.16)


def test_differences_allow_the_instruments_rounding_and_name_the_rest() -> None:
    wanted = DigitizerSettings(100e6, 200_000, 20_000, {"CH1": 1.0, "CH2": 10.0}, "CH2", 0.2, "POS")
    rounded = DigitizerSettings(100e6 * (1 + 1e-9), 200_000, 20_001, {"CH1": 1.0, "CH2": 10.0}, "CH2", 0.2, "POS")
    assert wanted.differences(rounded) == []
    other = DigitizerSettings(50e6, 100_000, 50_000, {"CH1": 1.0}, "EXT", -0.2, "NEG")
    lines = wanted.differences(other)
    assert [line.split(":")[0] for line in lines] == [
        "sample_rate_hz", "record_length", "pre_trigger_samples", "range of CH2 (V)", "trigger_source",
        "trigger_level_v", "trigger_slope"]
    assert lines[3] == "range of CH2 (V): 10 configured, None on the instrument"
