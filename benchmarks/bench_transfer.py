"""Waveform transfer over VISA: the driver's fetch vs pyvisa's default vs a raw socket.

One 10 000 000-sample int16 record (20 MB; a ramp over the full code range plus a sine, so the
payload holds many 0x0A bytes) is served by the simulated digitizer on loopback and read three
ways in the same run:
    raw socket   a plain socket client reading the block by length into one buffer (baseline)
    driver       drivers.digitizer.Digitizer.fetch_waveform (pyvisa-py, termination char off)
                 (also shown with pyvisa-py's stock 4 KiB receive size)
    pyvisa default  inst.query_binary_values(..., datatype="h") with read_termination "\\n"
All three must return the same codes. Figures are MB/s (1 MB = 1e6 bytes), best of the runs.
The last line of output is one JSON object.

Usage: .venv/bin/python benchmarks/bench_transfer.py [--samples N] [--repeats R]
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
from hopkinson.drivers.ieee488_block import digit_count, payload_length
from hopkinson.drivers.sim.faults import FaultSet
from hopkinson.drivers.sim.scpi_digitizer import AcquisitionSettings, SimDigitizerServer

CHANNEL = 2
RANGE_V = 10.0


def make_capture(samples: int) -> Callable[[AcquisitionSettings], dict[int, np.ndarray]]:
    t = np.arange(samples)
    ramp = np.linspace(-RANGE_V, RANGE_V, samples) * 0.95 + 0.02 * RANGE_V * np.sin(t / 7.0)
    volts = {1: np.zeros(samples), 2: ramp}
    return lambda settings: volts


class RawSocketClient:
    """Baseline: one bare socket kept open (as the driver keeps its session); each read sends
    the data query and reads the block by length with recv_into one preallocated buffer."""

    def __init__(self, port: int) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port))
        self.sock.sendall(f":WAVeform:SOURce CH{CHANNEL}\n".encode())

    def _read_into(self, buffer: bytearray) -> None:
        view, got = memoryview(buffer), 0
        while got < len(buffer):
            k = self.sock.recv_into(view[got:])
            if not k:
                raise ConnectionError("connection closed mid-block")
            got += k

    def read(self) -> np.ndarray:
        self.sock.sendall(b":WAVeform:DATA?\n")
        prefix = bytearray(2)
        self._read_into(prefix)
        digits = bytearray(digit_count(bytes(prefix)))
        self._read_into(digits)
        length = payload_length(bytes(digits))
        payload = bytearray(length + 1)
        self._read_into(payload)
        if payload[-1:] != b"\n":
            raise ValueError("block not followed by newline")
        return np.frombuffer(payload, dtype="<i2", count=length // 2)

    def close(self) -> None:
        self.sock.close()


def read_driver(dig: Digitizer) -> np.ndarray:
    return dig.fetch_waveform(CHANNEL).codes


def read_pyvisa_default(inst: pyvisa.resources.MessageBasedResource) -> np.ndarray:
    inst.write(f":WAVeform:SOURce CH{CHANNEL}")
    return inst.query_binary_values(":WAVeform:DATA?", datatype="h", container=np.array)


def best_rate_mb_s(read: Callable[[], np.ndarray], repeats: int, reference: np.ndarray | None) -> tuple[float, np.ndarray]:
    best_s, codes = float("inf"), np.empty(0, dtype=np.int16)
    for _ in range(repeats):
        t0 = time.perf_counter()
        codes = read()
        best_s = min(best_s, time.perf_counter() - t0)
        if reference is not None and not np.array_equal(codes, reference):
            raise AssertionError("transfer returned different samples than the raw socket")
    return codes.nbytes / best_s / 1e6, codes


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=10_000_000)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--default-repeats", type=int, default=2, help="runs of the slow pyvisa default")
    args = parser.parse_args(argv)

    with SimDigitizerServer(make_capture(args.samples), FaultSet()) as server:
        with Digitizer(server.resource, timeout_s=30.0) as dig:
            dig.configure(record_length=args.samples, pre_trigger_samples=0, ch2_range_v=RANGE_V)
            dig.arm_single()
            if not dig.wait_for_trigger(timeout_s=10.0):
                raise RuntimeError("simulated digitizer did not trigger")

            raw = RawSocketClient(server.port)
            try:
                raw_mb_s, reference = best_rate_mb_s(raw.read, args.repeats, None)
            finally:
                raw.close()
            newlines = reference.tobytes().count(b"\n")
            driver_mb_s, _ = best_rate_mb_s(lambda: read_driver(dig), args.repeats, reference)
            # The same driver with pyvisa-py's own 4 KiB receive size (what _enlarge_receive_size
            # changes), to show what that setting is worth.
            session = dig._inst.visalib.sessions[dig._inst.session]  # type: ignore[union-attr]
            session.max_recv_size = 4096
            driver_4k_mb_s, _ = best_rate_mb_s(lambda: read_driver(dig), args.repeats, reference)

        rm = pyvisa.ResourceManager("@py")
        try:
            inst = rm.open_resource(
                server.resource, read_termination="\n", write_termination="\n", timeout=120_000
            )
            default_mb_s, _ = best_rate_mb_s(lambda: read_pyvisa_default(inst), args.default_repeats, reference)
            inst.close()
        finally:
            rm.close()

    megabytes = reference.nbytes / 1e6
    print(f"waveform: {args.samples} int16 samples = {megabytes:.1f} MB, {newlines} bytes 0x0A in the payload")
    print(f"{'method':<20}{'MB/s':>10}{'time (s)':>12}")
    rows = (
        ("raw socket", raw_mb_s),
        ("driver fetch", driver_mb_s),
        ("driver, 4 KiB recv", driver_4k_mb_s),
        ("pyvisa default", default_mb_s),
    )
    for label, rate in rows:
        print(f"{label:<20}{rate:>10.1f}{megabytes / rate:>12.3f}")
    print(f"driver / raw socket     = {driver_mb_s / raw_mb_s:.2f}  (aim: within a small factor of 1)")
    print(f"driver / pyvisa default = {driver_mb_s / default_mb_s:.1f}  (aim: >= 10)")
    print(
        json.dumps(
            {
                "benchmark": "transfer",
                "samples": args.samples,
                "bytes": int(reference.nbytes),
                "newline_bytes": newlines,
                "raw_socket_mb_s": round(raw_mb_s, 1),
                "driver_mb_s": round(driver_mb_s, 1),
                "driver_4k_recv_mb_s": round(driver_4k_mb_s, 1),
                "pyvisa_default_mb_s": round(default_mb_s, 1),
                "driver_vs_raw": round(driver_mb_s / raw_mb_s, 3),
                "driver_vs_default": round(driver_mb_s / default_mb_s, 2),
            }
        )
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
