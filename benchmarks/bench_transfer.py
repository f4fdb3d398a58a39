"""Waveform transfer over VISA, in each digitizer dialect: the driver vs pyvisa's default vs a raw socket.

For each dialect, one int16 record (default 10 000 000 samples = 20 MB; a ramp over the full
code range plus a sine, so the payload holds many 0x0A bytes) is served by that dialect's
simulated digitizer on loopback and read three ways in the same run:
    raw socket      a plain socket client sending the dialect's data query and reading the block
                    by length into one buffer (the baseline)
    driver          drivers.digitizer.Digitizer.fetch_waveform (pyvisa-py, termination off,
                    bounded reads; the dialect's preamble/descriptor parsed)
    pyvisa default  inst.query_binary_values(<data query>, datatype="h") with read_termination "\\n"
All three must return the same codes. Figures are MB/s (1 MB = 1e6 bytes), best of the runs.
The aims (issue 12): driver >= 10x pyvisa's default and >= 1/4 of the raw socket, per dialect.
The last line of output is one JSON object.

Usage: .venv/bin/python benchmarks/bench_transfer.py [--samples N] [--repeats R] [--dialects a,b]
"""

from __future__ import annotations

import argparse
import json
import socket
import time
from collections.abc import Callable

import numpy as np
import pyvisa

from hopkinson.drivers.digitizer import Digitizer
from hopkinson.drivers.digitizer_settings import DigitizerSettings
from hopkinson.drivers.sim.faults import FaultSet
from hopkinson.drivers.sim.scpi_digitizer import SimDigitizerServer
from hopkinson.drivers.sim.scpi_instrument import AcquisitionSettings

RANGE_V = 10.0
DIALECTS = {  # channel names (1, 2); the data query of channel 2; bytes before the samples
    "generic": (("CH1", "CH2"), ":WAVeform:SOURce CH2", ":WAVeform:DATA?", 0),
    "keysight": (("CHAN1", "CHAN2"), ":WAVeform:SOURce CHANnel2", ":WAVeform:DATA?", 0),
    "tektronix": (("CH1", "CH2"), "DATa:SOUrce CH2", "CURVe?", 0),
    "lecroy": (("C1", "C2"), "", "C2:WF? ALL", 346),  # the WAVEDESC descriptor first
}
PYVISA_QUERY = {"lecroy": "C2:WF? DAT1"}  # pyvisa's default reader gets the samples alone


def make_capture(samples: int) -> Callable[[AcquisitionSettings], dict[int, np.ndarray]]:
    t = np.arange(samples)
    ramp = np.linspace(-RANGE_V, RANGE_V, samples) * 0.95 + 0.02 * RANGE_V * np.sin(t / 7.0)
    volts = {1: np.zeros(samples), 2: ramp}
    return lambda settings: volts


class RawSocketClient:
    """Baseline: one bare socket kept open (as the driver keeps its session); each read sends
    the data query and reads the block by length with recv_into one preallocated buffer."""

    def __init__(self, port: int, select: str, query: str, skip: int) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port))
        self.query, self.skip = query.encode() + b"\n", skip
        if select:
            self.sock.sendall(select.encode() + b"\n")

    def _read_into(self, buffer: bytearray | memoryview) -> None:
        view, got = memoryview(buffer), 0
        while got < len(view):
            k = self.sock.recv_into(view[got:])
            if not k:
                raise ConnectionError("connection closed mid-block")
            got += k

    def read(self) -> np.ndarray:
        self.sock.sendall(self.query)
        prefix = bytearray(2)
        self._read_into(prefix)
        if prefix[:1] != b"#":
            raise ValueError(f"not a block: {bytes(prefix)!r}")
        digits = bytearray(int(prefix[1:2]))
        self._read_into(digits)
        payload = bytearray(int(digits) + 1)
        self._read_into(payload)
        if payload[-1:] != b"\n":
            raise ValueError("block not followed by newline")
        return np.frombuffer(payload, dtype="<i2", count=(len(payload) - 1 - self.skip) // 2, offset=self.skip)

    def close(self) -> None:
        self.sock.close()


def best_rate_mb_s(read: Callable[[], np.ndarray], repeats: int, reference: np.ndarray | None) -> tuple[float, np.ndarray]:
    best_s, codes = float("inf"), np.empty(0, dtype=np.int16)
    for _ in range(repeats):
        t0 = time.perf_counter()
        codes = read()
        best_s = min(best_s, time.perf_counter() - t0)
        if reference is not None and not np.array_equal(codes, reference):
            raise AssertionError("transfer returned different samples than the raw socket")
    return codes.nbytes / best_s / 1e6, codes


def measure(dialect: str, samples: int, repeats: int, default_repeats: int) -> dict[str, float | int]:
    (ch1, ch2), select, query, skip = DIALECTS[dialect]
    with SimDigitizerServer(make_capture(samples), FaultSet(), dialect=dialect) as server:
        with Digitizer(server.resource, timeout_s=30.0, dialect=dialect, channels={"response": ch2}) as dig:
            dig.configure(DigitizerSettings(sample_rate_hz=100e6, record_length=samples, pre_trigger_samples=0,
                                            ranges_v={ch1: 1.0, ch2: RANGE_V}, trigger_source=ch2,
                                            trigger_level_v=0.1, trigger_slope="POS"))
            dig.arm_single()
            if not dig.wait_for_trigger(timeout_s=10.0):
                raise RuntimeError(f"simulated {dialect} digitizer did not trigger")
            raw = RawSocketClient(server.port, select, query, skip)
            try:
                raw_mb_s, reference = best_rate_mb_s(raw.read, repeats, None)
            finally:
                raw.close()
            driver_mb_s, _ = best_rate_mb_s(lambda: dig.fetch_waveform("response").codes, repeats, reference)
        rm = pyvisa.ResourceManager("@py")
        try:
            inst = rm.open_resource(server.resource, read_termination="\n", write_termination="\n", timeout=120_000)
            if select:
                inst.write(select)
            default_mb_s, _ = best_rate_mb_s(
                lambda: inst.query_binary_values(PYVISA_QUERY.get(dialect, query), datatype="h",
                                                 container=np.array),
                default_repeats, reference)
            inst.close()
        finally:
            rm.close()
    return {
        "bytes": int(reference.nbytes),
        "newline_bytes": reference.tobytes().count(b"\n"),
        "raw_socket_mb_s": round(raw_mb_s, 1),
        "driver_mb_s": round(driver_mb_s, 1),
        "pyvisa_default_mb_s": round(default_mb_s, 1),
        "driver_vs_raw": round(driver_mb_s / raw_mb_s, 3),
        "driver_vs_default": round(driver_mb_s / default_mb_s, 2),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=10_000_000)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--default-repeats", type=int, default=2, help="runs of the slow pyvisa default")
    parser.add_argument("--dialects", default=",".join(DIALECTS), help="comma-separated, of: " + ", ".join(DIALECTS))
    args = parser.parse_args(argv)
    dialects = [d.strip() for d in args.dialects.split(",") if d.strip()]
    unknown = [d for d in dialects if d not in DIALECTS]
    if unknown:
        parser.error(f"unknown dialect(s): {', '.join(unknown)}")

    rows = {d: measure(d, args.samples, args.repeats, args.default_repeats) for d in dialects}
    megabytes = 2 * args.samples / 1e6
    print(f"waveform: {args.samples} int16 samples = {megabytes:.1f} MB per read; MB/s, best of the runs")
    print(f"{'dialect':<11}{'raw socket':>12}{'driver':>10}{'pyvisa':>10}{'drv/raw':>10}{'drv/pyvisa':>12}")
    for d, r in rows.items():
        print(f"{d:<11}{r['raw_socket_mb_s']:>12.1f}{r['driver_mb_s']:>10.1f}{r['pyvisa_default_mb_s']:>10.1f}"
              f"{r['driver_vs_raw']:>10.2f}{r['driver_vs_default']:>12.1f}")
    worst_raw = min(r["driver_vs_raw"] for r in rows.values())
    worst_default = min(r["driver_vs_default"] for r in rows.values())
    print(f"worst driver / raw socket     = {worst_raw:.2f}  (aim: >= 0.25)")
    print(f"worst driver / pyvisa default = {worst_default:.1f}  (aim: >= 10)")
    print(json.dumps({"benchmark": "transfer", "samples": args.samples, "dialects": rows,
                      "worst_driver_vs_raw": worst_raw, "worst_driver_vs_default": worst_default}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
