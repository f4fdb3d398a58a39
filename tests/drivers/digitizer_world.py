"""A small world for the digitizer tests: signals with a known closed form, served the way
drivers/sim/world.py serves them (one record's length before the shot as well, so that the
simulated digitizer places the record around its own trigger), plus the expected codes of each
sample format computed here, independently of the simulators and the drivers."""

from __future__ import annotations

import threading

import numpy as np

from hopkinson.drivers.sim.scpi_instrument import AcquisitionSettings

# dialect -> its names of channels 1..4 and what the sim calls its channels
CHANNELS = {
    "generic": ("CH1", "CH2", "CH3", "CH4"),
    "keysight": ("CHAN1", "CHAN2", "CHAN3", "CHAN4"),
    "tektronix": ("CH1", "CH2", "CH3", "CH4"),
    "lecroy": ("C1", "C2", "C3", "C4"),
}
FORMATS = {
    "generic": ("int8", "uint8", "int16", "uint16", "float32"),
    "keysight": ("int8", "uint8", "int16", "uint16"),
    "tektronix": ("int8", "uint8", "int16", "uint16", "float32"),
    "lecroy": ("int8", "int16"),
}
STEP_AT = 0.75  # the response steps up at this fraction of a record into the served span
STEP_V = 6.0


def doppler_v(t: np.ndarray, range_v: float) -> np.ndarray:
    """Channel 1: a sine that reaches past its range late in the served span (clipped there)."""
    return 0.9 * range_v * np.sin(2 * np.pi * t / 97.31) * np.where(t > 0.75 * t.size, 1.3, 1.0)


def response_v(t: np.ndarray, n: int) -> np.ndarray:
    """Channel 2: 0 V, then a step to STEP_V with a ramp of 20 samples, plus a small sine."""
    start = STEP_AT * n
    return STEP_V * np.clip((t - start) / 20.0, 0.0, 1.0) + 0.05 * np.sin(2 * np.pi * t / 50.0)


class World:
    """capture(settings): None until fire(); then the two channels over two records' length
    around the shot, cut by the digitizer's own trigger (settings.trigger_index)."""

    def __init__(self) -> None:
        self.fired = threading.Event()
        self.seen: list[AcquisitionSettings] = []
        self.captures = 0

    def fire(self) -> None:
        self.fired.set()

    def __call__(self, settings: AcquisitionSettings) -> dict[int, np.ndarray] | None:
        self.seen.append(settings)
        if not self.fired.is_set():
            return None
        self.fired.clear()  # a shot is delivered once
        n, pre = settings.record_length, settings.pre_trigger_samples
        wide = self.wide(settings)
        k = settings.trigger_index(wide, pre, pre + n)
        if k is None:
            return None
        self.captures += 1
        return {ch: v[k - pre:k - pre + n] for ch, v in wide.items()}

    @staticmethod
    def wide(settings: AcquisitionSettings) -> dict[int, np.ndarray]:
        n = settings.record_length
        t = np.arange(2 * n, dtype=float)
        return {1: doppler_v(t, settings.ch_range_v[1]), 2: response_v(t, n)}

    def record(self, settings: AcquisitionSettings) -> dict[int, np.ndarray]:
        """The record the digitizer keeps with these settings (trigger on CH2 at its level)."""
        n, pre = settings.record_length, settings.pre_trigger_samples
        wide = self.wide(settings)
        k = settings.trigger_index(wide, pre, pre + n)
        assert k is not None
        return {ch: v[k - pre:k - pre + n] for ch, v in wide.items()}


# Keysight: the format's lowest code is a hole (no data); the converter clips one code above it
# (0x01 clipped low, 0xFF clipped high; shifted by half the range when signed).
HOLE_CODE = {"keysight": True}


def rails(sample_format: str, dialect: str = "generic") -> tuple[int, int]:
    """The codes at which a dialect's converter clips, low and high."""
    bits = 8 if sample_format.endswith("8") else 16
    low, high = (-(2 ** (bits - 1)), 2 ** (bits - 1) - 1) if sample_format.startswith("int") else (0, 2 ** bits - 1)
    return low + int(HOLE_CODE.get(dialect, False)), high


def expected_codes(volts: np.ndarray, range_v: float, sample_format: str, dialect: str = "generic") -> np.ndarray:
    """What an ideal converter sends: ±range over the format's codes (zero at mid-scale for
    the unsigned formats), clipped at the rails; float32: the volts clipped at ±range."""
    if sample_format == "float32":
        return np.clip(volts, -range_v, range_v).astype(np.float32)
    bits = 8 if sample_format.endswith("8") else 16
    half = 2 ** (bits - 1) - 1
    zero = 0 if sample_format.startswith("int") else half + 1
    low, high = rails(sample_format, dialect)
    return np.clip(np.rint(volts / (range_v / half)) + zero, low, high).astype(sample_format)
