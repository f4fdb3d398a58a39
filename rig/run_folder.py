"""The run folder of a campaign: plan copy, journal, shot files, report; lock and leftovers.

Layout::

    <parent>/<plan name>-<UTC yyyymmddTHHMMSSZ>/   the campaign id is the folder name
        plan.toml           copy of the plan as it was when the run started (byte for byte, but
                            for its [accelerometer] sine_calibration, which names the copy below)
        <sine>.csv          copy of the plan's sine calibration, when it names one (its file
                            name; sine_calibration.csv if that is one of the run folder's own)
        journal.sqlite      the shot journal (rig.journal), with SQLite's -wal/-shm files
        run.lock            held (flock) by the one process running or resuming the campaign
        shots/<shot id>.h5  one shot file per fired shot (rig.shotfile)
        report/             the campaign report

Leftovers are files ending in ".tmp" anywhere in the folder: writes that were interrupted
before their rename (rig.shotfile's `<name>.h5.tmp` and `<name>.h5.analysis.tmp`). A final
name is only ever created by a rename of a complete file, so a leftover never holds anything
that a final file depends on. They are removed only while the run lock is held, i.e. when no
other process can be in the middle of writing them.
"""

from __future__ import annotations

import os
import re
import tomllib
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

from hopkinson.fileio import atomic_write
from hopkinson.rig.errors import ConfigError
from hopkinson.rig.plan import CampaignPlan, load_plan

PLAN_NAME = "plan.toml"
JOURNAL_NAME = "journal.sqlite"
LOCK_NAME = "run.lock"
SHOTS_DIR = "shots"
REPORT_DIR = "report"
LEFTOVER_SUFFIX = ".tmp"

try:  # POSIX
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None  # type: ignore[assignment]
    import msvcrt


class RunLock:
    """An exclusive, non-blocking lock on a run folder; the OS drops it if the process dies."""

    def __init__(self, folder: Path) -> None:
        self.path = folder / LOCK_NAME
        self._fd: int | None = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            if fcntl is not None:
                fcntl.flock(self._fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            else:  # pragma: no cover - Windows
                msvcrt.locking(self._fd, msvcrt.LK_NBLCK, 1)
        except OSError:
            holder = _read_pid(self._fd)
            os.close(self._fd)
            self._fd = None
            raise ConfigError(
                f"{folder}: the run folder is in use by another process (pid {holder})"
            ) from None
        os.ftruncate(self._fd, 0)
        os.lseek(self._fd, 0, os.SEEK_SET)
        os.write(self._fd, f"{os.getpid()}\n".encode())

    @property
    def held(self) -> bool:
        return self._fd is not None

    def release(self) -> None:
        if self._fd is not None:
            os.close(self._fd)  # closing the descriptor drops the flock
            self._fd = None


def _read_pid(fd: int) -> str:
    """The pid the lock holder wrote into the lock file (for the error message)."""
    try:
        os.lseek(fd, 0, os.SEEK_SET)
        return os.read(fd, 32).decode(errors="replace").strip() or "unknown"
    except OSError:
        return "unknown"


@dataclass(frozen=True)
class RunFolder:
    """Paths of one campaign run."""

    path: Path

    @property
    def campaign_id(self) -> str:
        return self.path.name

    @property
    def plan_path(self) -> Path:
        return self.path / PLAN_NAME

    @property
    def journal_path(self) -> Path:
        return self.path / JOURNAL_NAME

    @property
    def shots_dir(self) -> Path:
        return self.path / SHOTS_DIR

    @property
    def report_dir(self) -> Path:
        return self.path / REPORT_DIR

    def shot_path(self, shot_id: str) -> Path:
        """Where the shot file of `shot_id` lives (its name is fixed by the id)."""
        return self.shots_dir / f"{shot_id}.h5"

    def load_plan(self) -> CampaignPlan:
        """The plan copy of this run."""
        return load_plan(self.plan_path)

    def lock(self) -> RunLock:
        """Take the run lock (ConfigError when another process holds it)."""
        return RunLock(self.path)

    def find_leftovers(self) -> list[Path]:
        """Interrupted writes (`*.tmp` files) anywhere in the run folder."""
        return sorted(p for p in self.path.rglob(f"*{LEFTOVER_SUFFIX}") if p.is_file())

    def clean_leftovers(self, lock: RunLock) -> list[Path]:
        """Delete the leftovers; needs the held run lock (no writer can be active)."""
        if not lock.held or lock.path.parent != self.path:
            raise ConfigError(f"{self.path}: leftovers are cleaned only under this folder's run lock")
        removed = []
        for path in self.find_leftovers():
            path.unlink(missing_ok=True)
            removed.append(path)
        return removed


def create_run_folder(plan_path: str | Path, parent: str | Path, name: str | None = None) -> RunFolder:
    """Validate a plan and create a new run folder for it under `parent`.

    The folder is named `name`, or `<plan name>-<UTC time>` (with -2, -3, … if taken).
    """
    plan_path = Path(plan_path)
    plan = load_plan(plan_path)
    sine = _sine_calibration(plan)  # read and checked before anything is created
    parent = Path(parent)
    parent.mkdir(parents=True, exist_ok=True)
    if name is not None:
        folder = parent / name
        if folder.exists():
            raise ConfigError(f"{folder}: a run folder of that name exists; use --resume to continue it")
        folder.mkdir()
    else:
        stamp = datetime.now(UTC).strftime("%Y%m%dT%H%M%SZ")
        folder = parent / f"{plan.name}-{stamp}"
        suffix = 1
        while True:
            try:
                folder.mkdir()
                break
            except FileExistsError:
                suffix += 1
                folder = parent / f"{plan.name}-{stamp}-{suffix}"
    run = RunFolder(folder)
    run.shots_dir.mkdir()
    run.report_dir.mkdir()
    # Copies: each an exclusive temporary, fsynced and renamed (hopkinson.fileio): whole or absent.
    plan_text = plan.text  # the text that was validated (read once: an edit meanwhile cannot slip in)
    if sine is not None:
        name, data = sine
        atomic_write(run.path / name, data)
        plan_text = plan_naming_sine_calibration(plan_text, name)
    atomic_write(run.plan_path, plan_text.encode("utf-8"))
    return run


RUN_FOLDER_NAMES = (PLAN_NAME, JOURNAL_NAME, LOCK_NAME, SHOTS_DIR, REPORT_DIR)


def _sine_calibration(plan: CampaignPlan) -> tuple[str, bytes] | None:
    """(name of its copy in the run folder, its bytes) for the plan's sine calibration, or None;
    ConfigError naming the plan's key when it cannot be read as a sine calibration."""
    path = plan.accelerometer.sine_calibration
    if not path:
        return None
    from hopkinson.analysis.errors import AnalysisError
    from hopkinson.analysis.sine_comparison import read_sine_calibration

    try:
        read_sine_calibration(path)  # a regular file of bounded size, as a sine calibration
        data = Path(path).read_bytes()
    except (AnalysisError, OSError) as exc:
        raise ConfigError(f"{plan.path}: accelerometer.sine_calibration: {exc}") from None
    name = Path(path).name
    if name in RUN_FOLDER_NAMES or name.startswith(JOURNAL_NAME) or name.endswith(LEFTOVER_SUFFIX):
        name = "sine_calibration.csv"  # never one of the run folder's own files, nor a leftover
    return name, data


_SINE_KEY = re.compile(r"""^([ \t]*(?:accelerometer[ \t]*\.[ \t]*)?sine_calibration[ \t]*=[ \t]*)"""
                       r"""("(?:[^"\\\n]|\\.)*"|'[^'\n]*')""", re.M)


def plan_naming_sine_calibration(text: str, name: str) -> str:
    """The plan's TOML text with [accelerometer] sine_calibration set to `name` (a file beside
    it). Only that value changes, comments and layout are kept; where the key is written in a
    way this does not recognise (an inline table, a multi-line string), the plan is written
    out again with tomli_w (same content, without its comments)."""
    wanted = tomllib.loads(text)
    wanted["accelerometer"]["sine_calibration"] = name
    value = '"' + name.replace("\\", "\\\\").replace('"', '\\"') + '"'
    changed, count = _SINE_KEY.subn(lambda m: m.group(1) + value, text)
    try:
        if count == 1 and tomllib.loads(changed) == wanted:
            return changed
    except tomllib.TOMLDecodeError:
        pass
    import tomli_w

    return tomli_w.dumps(wanted)


def open_run_folder(path: str | Path) -> RunFolder:
    """An existing run folder (to resume it); ConfigError when it is not one."""
    run = RunFolder(Path(path))
    if not run.path.is_dir():
        raise ConfigError(f"{run.path}: no such run folder")
    if not run.plan_path.is_file():
        raise ConfigError(f"{run.path}: not a campaign run folder (no {PLAN_NAME})")
    run.shots_dir.mkdir(exist_ok=True)
    run.report_dir.mkdir(exist_ok=True)
    return run
