"""Fixtures for the panel tests: a simulated rig on free ports (100× faster than the wall clock
unless asked otherwise), the panel's main window pointed at it (offscreen, settings in a
temporary INI file), and a clean teardown that deletes every widget while Qt still runs
(PySide6 6.12 with many pyqtgraph items can crash in the interpreter's final garbage
collection otherwise)."""

from __future__ import annotations

import contextlib
import dataclasses
import socket
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from PySide6.QtCore import QCoreApplication, QSettings

from hopkinson.drivers.sim.simulated_rig import ServerParams, SimConfig
from hopkinson.drivers.sim.world import WorldParams
from hopkinson.rig.config import RigConfig, load_rig_config
from hopkinson.rig.sim_session import SimSession, sim_session

REPO = Path(__file__).resolve().parents[2]
TIME_SCALE = 100.0
CONNECT_TIMEOUT_MS = 15_000


def fast_sim_config(time_scale: float = TIME_SCALE) -> SimConfig:
    return SimConfig(world=WorldParams(time_scale=time_scale), servers=ServerParams(modbus_slow_delay_s=0.3))


def rig_config_for_tests() -> RigConfig:
    """config/rig-sim.toml with timeouts for a fast simulator (wall seconds)."""
    base = load_rig_config(REPO / "config" / "rig-sim.toml")
    t = dataclasses.replace(base.timeouts, check_s=5.0, evacuate_s=10.0, charge_s=10.0, arm_s=5.0, fire_s=3.0,
                            capture_s=3.0, safe_s=10.0, store_s=20.0, analyse_s=60.0)
    return dataclasses.replace(
        base, timeouts=t,
        valve_controller=dataclasses.replace(base.valve_controller, timeout_s=0.5),
        amplifier=dataclasses.replace(base.amplifier, timeout_s=0.5),
        digitizer=dataclasses.replace(base.digitizer, timeout_s=3.0),
    )


def quick_config(draws: int = 60) -> RigConfig:
    """The test configuration with fewer Monte Carlo draws (the least analysis.options takes): for
    tests of what the panel shows, not of the uncertainty itself."""
    base = rig_config_for_tests()
    return dataclasses.replace(base, uncertainty=dataclasses.replace(base.uncertainty, draws=draws))


def free_port() -> int:
    """A loopback port nothing listens on (bound, then released)."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def unreachable_config(tmp_path: Path, keep: tuple[str, ...] = (), base: RigConfig | None = None) -> RigConfig:
    """The test configuration with the instruments not in `keep` pointed where nothing answers."""
    config = base or rig_config_for_tests()
    if "valve_controller" not in keep:
        config = dataclasses.replace(config, valve_controller=dataclasses.replace(
            config.valve_controller, host="127.0.0.1", port=free_port()))
    if "digitizer" not in keep:
        config = dataclasses.replace(config, digitizer=dataclasses.replace(
            config.digitizer, resource=f"TCPIP0::127.0.0.1::{free_port()}::SOCKET"))
    if "amplifier" not in keep:
        config = dataclasses.replace(config, amplifier=dataclasses.replace(
            config.amplifier, port=str(tmp_path / "no-such-serial-port")))
    return config


def dispose(widget: Any) -> None:
    """Close and delete a widget now (ui.app.dispose; see the module docstring); a deleted one
    is left alone."""
    import shiboken6

    from hopkinson.ui.app import dispose as dispose_now

    if shiboken6.isValid(widget):
        dispose_now(QCoreApplication.instance(), widget)


@dataclasses.dataclass
class Panel:
    """A running panel on a simulated rig."""

    window: Any
    session: SimSession | None
    settings_path: Path
    out_dir: Path
    runs_dir: Path

    @property
    def world(self) -> Any:
        assert self.session is not None
        return self.session.world

    @property
    def faults(self) -> Any:
        assert self.session is not None
        return self.session.rig.faults


@pytest.fixture
def make_panel(qtbot: Any, tmp_path: Path) -> Iterator[Callable[..., Panel]]:
    """make_panel(time_scale=100, faults=(), config=None, connect=True) -> Panel (stopped after the test)."""
    from hopkinson.ui.main_window import MainWindow

    stack = contextlib.ExitStack()
    windows: list[Any] = []

    def make(time_scale: float = TIME_SCALE, faults: tuple[str, ...] = (), config: RigConfig | None = None,
             simulate: bool = True, connect: bool = True) -> Panel:
        session = None
        rig_config = config or rig_config_for_tests()
        truth = None
        if simulate:
            session = stack.enter_context(sim_session(rig_config, fast_sim_config(time_scale), faults))
            rig_config, truth = session.config, session.simulated_truth
        n = len(windows)
        settings_path = tmp_path / f"settings{n}.ini"
        out_dir, runs_dir = tmp_path / f"shots{n}", tmp_path / f"runs{n}"
        window = MainWindow(rig_config, settings=QSettings(str(settings_path), QSettings.Format.IniFormat),
                            simulated_truth=truth, out_dir=out_dir, runs_dir=runs_dir, poll_interval_ms=150)
        windows.append(window)
        # the dialogs a test does not answer itself: a set-up off its target is armed (the tests of
        # that check answer it), and closing with a shot running aborts it (as before the question)
        window.set_up_answers = []
        window.confirm_setup = lambda problems: window.set_up_answers.append(problems) or True
        window.ask_close = lambda: "abort"
        window.resize(1280, 800)
        window.show()
        window.start()
        if connect and simulate:
            qtbot.waitUntil(lambda: window.link.all_connected and window.last_reading is not None,
                            timeout=CONNECT_TIMEOUT_MS)
        return Panel(window, session, settings_path, out_dir, runs_dir)

    yield make
    for window in reversed(windows):
        dispose(window)  # closing aborts a running shot and waits for SAFE
    stack.close()


def save_shot(widget: Any, path: Path) -> Path:
    """Grab a widget (or the whole window) into a PNG for people to look at."""
    QCoreApplication.processEvents()
    assert widget.grab().save(str(path)), f"could not write {path}"
    return path
