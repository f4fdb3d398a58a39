"""Named faults the simulated rig can inject (`hopkinson sim --fault NAME`).

A FaultSet is shared by the simulated instruments: each checks `faults.active(name)` at the
point where the fault bites. Faults can be switched on and off while the simulator runs.
"""

from __future__ import annotations

import threading

FAULTS: dict[str, str] = {
    "modbus-disconnect": "the valve/vacuum controller drops every Modbus TCP connection at its next request (RTU: stops answering)",
    "modbus-slow": "the valve/vacuum controller answers each Modbus request after a long delay (sim.toml modbus_slow_delay_s)",
    "visa-garbled-block": "the digitizer sends a waveform block with a corrupt length header",
    "visa-endless-reply": "the digitizer, once armed, streams every text reply without its terminator (a hung instrument)",
    "no-trigger": "the digitizer never triggers: the shot is fired but nothing is captured",
    "stuck-fill-valve": "the fill valve, once open, stays open when told to close and past the set-point; pressure climbs to the supply",
    "vacuum-leak": "the fixture vacuum cannot be pulled below the leak level (sim.toml fault_leak_floor_mbar, 500 mbar)",
    "door-open": "the door/guard interlock input reads open; the controller keeps the fire valve shut",
    "estop": "the e-stop interlock input reads tripped; the controller keeps the fire valve shut",
    "amp-overload": "the bridge amplifier reports overload (OVL? answers 1 even after OVL CLR)",
    "serial-noise": "the bridge amplifier's serial replies are corrupted by line noise (one flipped bit: bad checksum)",
}


class FaultSet:
    """Thread-safe set of active fault names (validated against FAULTS)."""

    def __init__(self, names: list[str] | tuple[str, ...] = ()) -> None:
        self._lock = threading.Lock()
        self._active: set[str] = set()
        for name in names:
            self.inject(name)

    def inject(self, name: str) -> None:
        """Switch a fault on; an unknown name raises ValueError listing the known ones."""
        if name not in FAULTS:
            raise ValueError(f"unknown simulator fault {name!r}; known: {', '.join(sorted(FAULTS))}")
        with self._lock:
            self._active.add(name)

    def clear(self, name: str | None = None) -> None:
        """Switch one fault (or all) off."""
        with self._lock:
            if name is None:
                self._active.clear()
            else:
                self._active.discard(name)

    def active(self, name: str) -> bool:
        with self._lock:
            return name in self._active

    def names(self) -> list[str]:
        with self._lock:
            return sorted(self._active)
