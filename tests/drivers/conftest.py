"""Fixtures that run the simulated rig in-process (loopback TCP and a pty) and stop it after."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from dataclasses import replace

import pytest
from hopkinson.drivers.sim.simulated_rig import SimConfig, SimulatedRig
from hopkinson.drivers.sim.world import WorldParams


class FakeClock:
    """A wall clock the test moves by hand: the world's state depends only on `advance`."""

    def __init__(self) -> None:
        self.now_s = 1000.0

    def __call__(self) -> float:
        return self.now_s

    def advance(self, seconds: float) -> None:
        self.now_s += seconds


def sim_config(time_scale: float = 1.0, slow_delay_s: float = 0.6, **world: object) -> SimConfig:
    """A simulator config on free ports with no pty symlink."""
    base = SimConfig()
    return replace(base, world=replace(WorldParams(time_scale=time_scale), **world),
                   servers=replace(base.servers, modbus_slow_delay_s=slow_delay_s))


def _sim_threads() -> list[str]:
    return [t.name for t in threading.enumerate() if t.name.startswith("sim-")]


@pytest.fixture
def clock() -> FakeClock:
    return FakeClock()


@pytest.fixture
def rig(clock: FakeClock) -> Iterator[SimulatedRig]:
    """The whole simulated rig on free loopback ports and a pty, its time moved by `clock`."""
    before = set(_sim_threads())
    with SimulatedRig(sim_config(), clock=clock) as sim:
        yield sim
    leftover = set(_sim_threads()) - before
    assert not leftover, f"simulator threads left running: {leftover}"
