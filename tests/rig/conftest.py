"""Fixtures for the sequencer tests: a running in-process simulated rig (free ports, a pty),
a RigConfig pointing at it with short timeouts, the connected instruments, and an event
recorder. The simulator runs 100x faster than the wall clock so that evacuating, charging and
venting take a few tens of milliseconds.
"""

from __future__ import annotations

import contextlib
import dataclasses
import threading
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from hopkinson.analysis.options import AnalysisOptions
from hopkinson.drivers.sim.simulated_rig import ServerParams, SimConfig
from hopkinson.drivers.sim.world import WorldParams
from hopkinson.rig.config import RigConfig, load_rig_config
from hopkinson.rig.events import EventBus, RigEvent, StateEntered
from hopkinson.rig.instruments import Instruments, open_instruments
from hopkinson.rig.sequencer import FireAuthorisation, Sequencer
from hopkinson.rig.shot import AnalysisResult, ShotRequest
from hopkinson.rig.shotfile import RawShot
from hopkinson.rig.sim_session import SimSession, sim_session

REPO = Path(__file__).resolve().parents[2]
TIME_SCALE = 100.0
SLOW_DELAY_S = 0.8  # the `modbus-slow` fault's reply delay: longer than the controller timeout
CONTROLLER_TIMEOUT_S = 0.4  # generous for loopback, also on a loaded machine


def fast_sim_config(time_scale: float = TIME_SCALE) -> SimConfig:
    return SimConfig(world=WorldParams(time_scale=time_scale),
                     servers=ServerParams(modbus_slow_delay_s=SLOW_DELAY_S))


def short_timeouts_config(**timeouts: float) -> RigConfig:
    """config/rig-sim.toml with short timeouts (wall seconds) for a 100x simulator."""
    base = load_rig_config(REPO / "config" / "rig-sim.toml")
    t = dataclasses.replace(base.timeouts, check_s=5.0, evacuate_s=1.0, charge_s=2.0, arm_s=2.0, fire_s=2.0,
                            capture_s=3.0, safe_s=2.0, store_s=20.0, analyse_s=60.0)
    t = dataclasses.replace(t, **timeouts)
    return dataclasses.replace(
        base, timeouts=t,
        valve_controller=dataclasses.replace(base.valve_controller, timeout_s=CONTROLLER_TIMEOUT_S),
        amplifier=dataclasses.replace(base.amplifier, timeout_s=1.0),
        digitizer=dataclasses.replace(base.digitizer, timeout_s=2.0),
    )


SHORT_TIMEOUTS = {"check_s": 5.0, "evacuate_s": 2.0, "charge_s": 3.0, "arm_s": 1.0, "capture_s": 2.0, "safe_s": 3.0}


def rig_toml(session: SimSession, path: Path, **timeouts: float) -> Path:
    """A rig TOML file (config/rig-sim.toml with short timeouts) that reaches a running in-process
    simulated rig: for a command line, or another process, to drive the test's own simulator."""
    import re

    text = (REPO / "config" / "rig-sim.toml").read_text(encoding="utf-8")
    c = session.config
    for pattern, value in ((r"^port = 5020\b.*$", f"port = {c.valve_controller.port}"),
                           (r"^resource = .*$", f'resource = "{c.digitizer.resource}"'),
                           (r'^port = "sim:amplifier".*$', f'port = "{c.amplifier.port}"'),
                           *((rf"^{k} = .*$", f"{k} = {v}") for k, v in {**SHORT_TIMEOUTS, **timeouts}.items())):
        text, n = re.subn(pattern, value, text, count=1, flags=re.M)
        assert n == 1, pattern
    path.write_text(text, encoding="utf-8")
    return path


def rig_config_with_few_draws(folder: Path) -> Path:
    """config/rig-sim.toml with the fewest Monte Carlo draws allowed (50), written into `folder`:
    for a command that still prints every figure as value ± U, in a fraction of the time (the
    intervals' coverage is tested in tests/analysis)."""
    import re

    text = (REPO / "config" / "rig-sim.toml").read_text(encoding="utf-8")
    text, n = re.subn(r"^draws = \d+", "draws = 50", text, count=1, flags=re.M)
    assert n == 1
    path = folder / "rig-sim-50-draws.toml"
    path.write_text(text, encoding="utf-8")
    return path


def read_until(proc: Any, stream: Any, pattern: str, timeout_s: float = 60.0) -> str:
    """What a process writes on `stream` up to (at least) the first text matching `pattern`
    (regular expression, multi-line); the process is killed and the test fails when none comes
    in time.

    Reads the pipe's file descriptor itself: `select` on a buffered text stream misses lines
    that `readline` already pulled into Python's buffer, so a line that arrived together with
    the one before would only be seen with the next write (a signal meant for ANALYSE then
    came after the analysis)."""
    import os
    import re
    import select
    import time

    fd = stream.fileno()
    received = b""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if not select.select([fd], [], [], 0.2)[0]:
            continue
        chunk = os.read(fd, 65536)
        if not chunk:
            break
        received += chunk
        text = received.decode("utf-8", errors="replace")
        if re.search(pattern, text, re.MULTILINE):
            return text
    proc.kill()
    raise AssertionError(f"{pattern!r} never came; got {received.decode('utf-8', errors='replace')!r}")


class Recorder:
    """Keeps every event; `states()` lists the state changes in order."""

    def __init__(self, bus: EventBus) -> None:
        self.events: list[RigEvent] = []
        self._lock = threading.Lock()
        bus.subscribe(self._add)

    def _add(self, event: RigEvent) -> None:
        with self._lock:
            self.events.append(event)

    def of(self, *types: type[RigEvent]) -> list[RigEvent]:
        with self._lock:
            return [e for e in self.events if isinstance(e, types)]

    def states(self) -> list[str]:
        return [e.state for e in self.of(StateEntered)]


def quick_analysis(raw: RawShot, params: AnalysisOptions) -> AnalysisResult:
    """A stand-in for the shot analysis where a test is not about it (the real one takes ~1 s)."""
    return AnalysisResult({"peak_response_v": float(raw.volts("response").max()), "params": params.to_dict()})


class Rig:
    """Everything a sequencer test needs, wired together (analysis: `quick_analysis`)."""

    def __init__(self, session: SimSession, instruments: Instruments, out_dir: Path) -> None:
        self.session = session
        self.world = session.world
        self.faults = session.rig.faults
        self.config = session.config
        self.instruments = instruments
        self.out_dir = out_dir
        self.bus = EventBus()
        self.recorder = Recorder(self.bus)
        self.sequencer = Sequencer(instruments, self.config, self.bus, analyse=quick_analysis)

    def request(self, **kw: object) -> ShotRequest:
        kw.setdefault("pressure_bar", 1.0)
        kw.setdefault("out_dir", self.out_dir)
        kw.setdefault("operator", "test")
        return ShotRequest(**kw)  # type: ignore[arg-type]

    def on_state(self, state: str, action: Callable[[], None]) -> None:
        """Run `action` (in the sequencer's thread) when the sequencer enters `state`."""
        def callback(event: RigEvent) -> None:
            if isinstance(event, StateEntered) and event.state == state:
                action()
        self.bus.subscribe(callback)

    def run(self, authorisation: FireAuthorisation | None = None, **request: object):
        return self.sequencer.run_shot(self.request(**request), authorisation or FireAuthorisation.pre_given())

    def assert_safe(self, vented: bool = True, stuck: tuple[str, ...] = (), read_back: bool = True,
                    digitizer: bool = True) -> None:
        """Everything SAFE promises, judged from the simulated rig itself (`assert_safe`), the
        reservoir also as the controller reads it back (read_back=False: the link is down);
        digitizer=False only for a digitizer that hangs (SAFE cannot disarm it, and says so)."""
        before = self.world.reservoir_pressure_bar()  # the world may still be venting: bracket the reading
        reading = self.instruments.valves.reservoir_pressure_bar() if read_back and vented else None
        assert_safe(self.world, self.config, digitizer_state=self.session.rig.digitizer.state if digitizer else None,
                    reservoir_read_back_bar=reading, vented=vented, stuck=stuck, world_before_bar=before)


def assert_safe(world: Any, config: RigConfig, *, digitizer_state: str | None,
                reservoir_read_back_bar: float | None = None, vented: bool = True,
                stuck: tuple[str, ...] = (), world_before_bar: float | None = None) -> None:
    """What SAFE promises (rig/sequencer/safe.py), from the simulated world's own state, never
    from what the sequencer says: fire and fill commanded shut and shut, vent commanded open and
    open (a valve in `stuck` is physically stuck open: only its command is judged), the vacuum
    pump off, the digitizer not left armed (IDLE, or TRIGGERED holding the shot's record), and,
    when `vented`, the reservoir at or below limits.vent_done_bar in the world and as the
    controller reads it back (`reservoir_read_back_bar`, within one gauge count of the world's
    pressure between `world_before_bar`, read before it, and now).
    Every fault-injection test ends with it."""
    coils = world.coils()
    assert coils == {"fire": False, "fill": False, "vent": True, "pump": False}, f"coils {coils}"
    positions = world.valve_positions()
    for valve, wanted in (("fire", False), ("fill", False), ("vent", True)):
        if valve not in stuck:
            assert positions[valve] is wanted, f"{valve} valve {'open' if positions[valve] else 'shut'}: {positions}"
    if digitizer_state is not None:
        assert digitizer_state in ("IDLE", "TRIGGERED"), f"the digitizer was left {digitizer_state}"
    if vented:
        limit = config.limits.vent_done_bar
        pressure = world.reservoir_pressure_bar()
        assert pressure <= limit, f"reservoir {pressure:.4f} bar in the world, not vented (limit {limit:g} bar)"
        if reservoir_read_back_bar is not None:
            count = max(config.valve_controller.gauge_resolution_bar, 1e-6)
            low, high = sorted((pressure, pressure if world_before_bar is None else world_before_bar))
            assert reservoir_read_back_bar <= limit, f"reservoir read back at {reservoir_read_back_bar:.4f} bar"
            assert low - count <= reservoir_read_back_bar <= high + count, \
                f"read back {reservoir_read_back_bar:.4f} bar, the world had {low:.4f} .. {high:.4f} bar"


def assert_state_safe(state: dict[str, Any], config: RigConfig, *, vented: bool = True,
                      stuck: tuple[str, ...] = ()) -> None:
    """`assert_safe` on the simulator's state as `--sim-state-file` or `hopkinson sim` writes it
    (drivers/sim/simulated_rig.py world_state), for tests of commands in their own process."""
    commanded = {v: state[f"{v}_valve_commanded"] for v in ("fire", "fill", "vent")}
    assert commanded == {"fire": False, "fill": False, "vent": True}, f"commanded {commanded}"
    assert state["vacuum_pump_on"] is False, "the vacuum pump was left on"
    for valve, wanted in (("fire", False), ("fill", False), ("vent", True)):
        if valve not in stuck:
            assert state[f"{valve}_valve_open"] is wanted, f"{valve} valve: {state}"
    assert state["digitizer_state"] in ("IDLE", "TRIGGERED"), f"the digitizer was left {state['digitizer_state']}"
    if vented:
        assert state["reservoir_pressure_bar"] <= config.limits.vent_done_bar, state["reservoir_pressure_bar"]


@pytest.fixture
def make_rig(tmp_path: Path) -> Iterator[Callable[..., Rig]]:
    """make_rig(faults=(), config=None, time_scale=100) -> Rig; everything stopped after the test."""
    stacks: list[contextlib.ExitStack] = []

    def make(faults: tuple[str, ...] = (), config: RigConfig | None = None,
             time_scale: float = TIME_SCALE, sim: SimConfig | None = None,
             adjust: Callable[[RigConfig], RigConfig] | None = None, heartbeat: bool = False) -> Rig:
        """sim: the simulator's config (default `fast_sim_config`); adjust: changes the rig
        config that reaches it (e.g. another fire style than the simulated PLC's);
        heartbeat: run a heartbeat session, as `hopkinson shot` does."""
        stack = contextlib.ExitStack()
        stacks.append(stack)
        session = stack.enter_context(sim_session(config or short_timeouts_config(),
                                                  sim or fast_sim_config(time_scale), faults))
        if adjust is not None:
            session.config = adjust(session.config)
        instruments = stack.enter_context(open_instruments(session.config, session.simulated_truth))
        if heartbeat:
            instruments.valves.start_heartbeat()
        out = tmp_path / f"shots{len(stacks)}"
        out.mkdir()
        return Rig(session, instruments, out)

    yield make
    for stack in reversed(stacks):
        stack.close()


@pytest.fixture
def rig(make_rig: Callable[..., Rig]) -> Rig:
    return make_rig()
