"""The rig's three instruments opened together from a RigConfig, as one context.

    with open_instruments(config) as instruments:
        sequencer = Sequencer(instruments, config, bus)

`open_instruments` connects the valve/vacuum controller (Modbus TCP), the digitizer (VISA)
and the bridge amplifier (serial) in that order; if one cannot be reached, the ones already
open are closed again and the InstrumentError (naming the instrument) propagates. On leaving
the context every instrument is closed, whatever happened.

The drivers are not thread-safe: one thread uses an Instruments at a time (the sequencer's
while a shot runs).

`sim_rig_config` makes a RigConfig that points at a running SimulatedRig (in-process, on
free ports): the addresses and the register map come from the simulator, everything else
(limits, timeouts, analysis constants) from the given base configuration.
"""

from __future__ import annotations

import contextlib
import dataclasses
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from hopkinson.drivers.amplifier import BridgeAmplifier
from hopkinson.drivers.digitizer import Digitizer
from hopkinson.drivers.errors import InstrumentError
from hopkinson.drivers.valve_controller import RegisterMap, ValveController
from hopkinson.rig.config import RigConfig

if TYPE_CHECKING:
    from hopkinson.drivers.sim.simulated_rig import SimAddresses


@dataclass
class Instruments:
    """The three connected drivers; `simulated_truth` returns the simulator's truth of the
    last shot (None on a real rig)."""

    valves: ValveController
    digitizer: Digitizer
    amplifier: BridgeAmplifier
    simulated_truth: Callable[[], dict[str, Any] | None] | None = None

    def identities(self) -> dict[str, str]:
        """name -> identity string of each instrument; an unanswered query is noted, not raised
        (Modbus device identification is optional)."""
        out: dict[str, str] = {}
        for key, instrument in (("valve_controller", self.valves), ("digitizer", self.digitizer),
                                ("amplifier", self.amplifier)):
            try:
                out[key] = instrument.identity()
            except InstrumentError as exc:
                out[key] = f"(no identification: {exc.problem})"
        return out

    def close(self) -> None:
        """Close all three (idempotent; never raises)."""
        for instrument in (self.amplifier, self.digitizer, self.valves):
            with contextlib.suppress(Exception):
                instrument.close()


def make_instruments(config: RigConfig) -> Instruments:
    """The three drivers configured from `config`, not yet connected."""
    vc = config.valve_controller
    amp = config.amplifier
    return Instruments(
        valves=ValveController(vc.host, vc.port, device_id=vc.device_id, timeout_s=vc.timeout_s,
                               retries=vc.retries, register_map=vc.register_map),
        digitizer=Digitizer(config.digitizer.resource, timeout_s=config.digitizer.timeout_s),
        amplifier=BridgeAmplifier(amp.port, baudrate=amp.baudrate, timeout_s=amp.timeout_s, retries=amp.retries),
    )


@contextlib.contextmanager
def open_instruments(config: RigConfig,
                     simulated_truth: Callable[[], dict[str, Any] | None] | None = None) -> Iterator[Instruments]:
    """Connect all three instruments of `config`; close them all on exit (module docstring)."""
    instruments = make_instruments(config)
    instruments.simulated_truth = simulated_truth
    try:
        instruments.valves.connect()
        instruments.digitizer.connect()
        instruments.amplifier.connect()
        yield instruments
    finally:
        instruments.close()


def sim_rig_config(base: RigConfig, addresses: SimAddresses, register_map: RegisterMap | None = None) -> RigConfig:
    """`base` with the instrument addresses (and register map) of a running simulated rig."""
    vc = dataclasses.replace(base.valve_controller, host=addresses.modbus_host, port=addresses.modbus_port)
    if register_map is not None:
        vc = dataclasses.replace(vc, coils=register_map.coils, discrete_inputs=register_map.discrete_inputs,
                                 holding_registers=register_map.holding_registers,
                                 input_registers=register_map.input_registers, scales=register_map.scales)
    return dataclasses.replace(
        base,
        valve_controller=vc,
        digitizer=dataclasses.replace(base.digitizer, resource=addresses.visa_resource),
        amplifier=dataclasses.replace(base.amplifier, port=addresses.serial_port),
    )
