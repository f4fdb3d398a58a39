"""One controller per rig: an exclusive lock per rig, taken before anything is commanded.

    with RigLock.acquire(config, "hopkinson shot --pressure-bar 2"):   # RigLockError (exit 2) when held
        ... connect, start the heartbeat, fire ...
    current_holder(config)  -> LockHolder | None                         # for `hopkinson status`

The key is the valve controller's address (`ValveControllerConfig.address`, e.g.
"modbus-tcp://127.0.0.1:5020/1"): whoever commands the controller drives the rig.

Where the locks live. Two users on one PC must exclude each other, so the lock cannot live in a
per-user folder. The lock folder is, in this order:

1. `$HOPKINSON_LOCK_DIR` (a lab sets it, e.g. to a folder its administrator created with
   `install -d -m 1777 /var/lib/hopkinson-locks`; a folder on a network file system that
   supports locks extends the exclusion to every PC that mounts it);
2. `/run/lock/hopkinson` (the system's folder for lock files, shared by every user);
3. `<system temp>/hopkinson-rig-locks`.

A folder this module creates is made world-writable with the sticky bit (mode 1777, like
/tmp): every user can create a lock file, nobody can remove another user's. A folder that is a
symlink, or writable by others without the sticky bit, is refused (another user could swap the
lock file under a holder). Lock files are opened with O_NOFOLLOW (never through a planted
symlink), must be regular files, are never removed, and are made readable and writable by
every user (0666) so that the next user can take the lock after the first.

How it works. `fcntl.flock(LOCK_EX | LOCK_NB)` on the rig's lock file: the kernel releases it
when the holder's process ends in any way (kill -9 included), so a lock left by a dead process
is free and simply taken again; the holder's details in the file (pid, user, command, since)
are then stale and reported as reclaimed. After locking, the file is checked to still be the
one at the lock's path (same inode), so a file swapped in between is never trusted. The
descriptor is close-on-exec: a program the holder starts does not inherit the lock.

What it is not. The lock stops accidents (a second program on the same rig), not malice: a
local user can always talk Modbus to the controller directly. The controller's link watchdog
and the hardware interlocks (e-stop, door) are what make the rig safe whatever the PC does.
"""

from __future__ import annotations

import contextlib
import getpass
import hashlib
import json
import os
import re
import socket
import stat
import sys
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from hopkinson.rig.errors import ConfigError
from hopkinson.rig.events import utc_now_iso

try:  # POSIX
    import fcntl
except ImportError:  # pragma: no cover - Windows: no rig lock (documented)
    fcntl = None  # type: ignore[assignment]

LOCK_DIR_ENV = "HOPKINSON_LOCK_DIR"
SYSTEM_LOCK_DIR = Path("/run/lock")
LOCK_SUFFIX = ".lock"
# A lock that looks taken by nobody alive: a reader (`status`) may hold it shared for an
# instant. Try again for this long before calling it held by an unknown process.
TRANSIENT_RETRY_S = 0.5
_MAX_INFO_BYTES = 4096


class RigLockError(ConfigError):
    """The rig is held by another process (or its lock cannot be used); exit code 2."""

    def __init__(self, message: str, holder: LockHolder | None = None) -> None:
        super().__init__(message)
        self.holder = holder


@dataclass(frozen=True)
class LockHolder:
    """Who holds (or held) a rig: written into the lock file by the holder."""

    pid: int
    command: str
    since: str  # UTC, ISO 8601
    user: str = ""
    host: str = ""
    address: str = ""

    def describe(self) -> str:
        who = f"pid {self.pid}" + (f" of {self.user}" if self.user else "") + (f" on {self.host}" if self.host else "")
        return f"{who} ({self.command}) since {self.since}"

    def alive(self) -> bool:
        """Is the holder's process still running (on this host)?"""
        if self.host and self.host != socket.gethostname():
            return True  # another PC's process: cannot tell, assume it runs
        return pid_alive(self.pid)


def pid_alive(pid: int) -> bool:
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    return True


def rig_address(config: Any) -> str:
    """The rig's identity for its lock: the valve controller's address."""
    vc = config.valve_controller
    address = getattr(vc, "address", None)
    if address:
        return str(address)
    return f"modbus-tcp://{vc.host}:{vc.port}/{getattr(vc, 'device_id', getattr(vc, 'unit_id', 1))}"


def lock_dir() -> Path:
    """The lock folder (module docstring), created when missing; RigLockError when unusable."""
    configured = os.environ.get(LOCK_DIR_ENV)
    if configured:
        folder = Path(configured)
    elif SYSTEM_LOCK_DIR.is_dir() and os.access(SYSTEM_LOCK_DIR, os.W_OK | os.X_OK):
        folder = SYSTEM_LOCK_DIR / "hopkinson"
    else:
        folder = Path(tempfile.gettempdir()) / "hopkinson-rig-locks"
    try:
        os.mkdir(folder, 0o777)
        os.chmod(folder, 0o1777)  # the umask took bits off: every user may add a lock, nobody remove another's
    except FileExistsError:
        pass
    except OSError as exc:
        raise RigLockError(f"{folder}: cannot create the rig lock folder ({exc.strerror or exc}); "
                           f"set {LOCK_DIR_ENV} to a folder every user of the rig can write") from None
    _check_folder(folder)
    return folder


def _check_folder(folder: Path) -> None:
    try:
        info = os.lstat(folder)
    except OSError as exc:
        raise RigLockError(f"{folder}: the rig lock folder cannot be used ({exc.strerror or exc})") from None
    if not stat.S_ISDIR(info.st_mode):
        raise RigLockError(f"{folder}: the rig lock folder is not a folder (a symlink or a file): remove it or set "
                           f"{LOCK_DIR_ENV}")
    mode = stat.S_IMODE(info.st_mode)
    if mode & 0o022 and not mode & stat.S_ISVTX:
        raise RigLockError(f"{folder}: the rig lock folder is writable by others without the sticky bit (another "
                           f"user could replace a lock): chmod +t it, or set {LOCK_DIR_ENV}")


def lock_path(address: str, folder: Path | None = None) -> Path:
    """The lock file of a rig address: readable name plus a hash (one file per address)."""
    readable = re.sub(r"[^A-Za-z0-9.-]+", "_", address).strip("_")[:80]
    digest = hashlib.sha256(address.encode()).hexdigest()[:12]
    return (folder or lock_dir()) / f"{readable}-{digest}{LOCK_SUFFIX}"


def _open_lock_file(path: Path) -> int:
    flags = os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)
    try:
        fd = os.open(path, flags, 0o666)
    except PermissionError:  # a file of another user that is not writable: read-only still locks
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0))
    except OSError as exc:
        raise RigLockError(f"{path}: the rig lock file cannot be opened ({exc.strerror or exc}; a symlink is "
                           "never followed)") from None
    info = os.fstat(fd)
    if not stat.S_ISREG(info.st_mode):
        os.close(fd)
        raise RigLockError(f"{path}: the rig lock file is not a regular file")
    if info.st_uid == os.getuid():
        with contextlib.suppress(OSError):
            os.fchmod(fd, 0o666)  # the next user of the rig may take it after us
    return fd


def _read_holder(fd: int) -> LockHolder | None:
    try:
        data = os.pread(fd, _MAX_INFO_BYTES, 0)
        info = json.loads(data.decode("utf-8")) if data.strip() else None
        if not isinstance(info, dict):
            return None
        return LockHolder(int(info["pid"]), str(info.get("command", "")), str(info.get("since", "")),
                          str(info.get("user", "")), str(info.get("host", "")), str(info.get("address", "")))
    except (OSError, ValueError, KeyError, TypeError):
        return None


def _same_file(fd: int, path: Path) -> bool:
    try:
        a, b = os.fstat(fd), os.lstat(path)
    except OSError:
        return False
    return (a.st_dev, a.st_ino) == (b.st_dev, b.st_ino)


def command_line() -> str:
    """This process's command, for the lock's holder details."""
    program = Path(sys.argv[0]) if sys.argv and sys.argv[0] else Path("python")
    name = program.parent.name if program.name == "__main__.py" else program.name  # python -m hopkinson
    return " ".join([name, *sys.argv[1:]])[:300]


class RigLock:
    """The held lock of one rig (module docstring); release() or leave the `with` block."""

    def __init__(self, fd: int, path: Path, holder: LockHolder, reclaimed: LockHolder | None) -> None:
        self._fd: int | None = fd
        self.path = path
        self.holder = holder
        self.reclaimed = reclaimed  # the details a dead holder left, when its lock was taken again

    @classmethod
    def acquire(cls, config: Any, command: str | None = None, *, address: str | None = None) -> RigLock:
        """Take the rig's lock now or raise RigLockError naming the holder (never waits for a
        live holder)."""
        address = address or rig_address(config)
        path = lock_path(address)
        if fcntl is None:  # pragma: no cover
            raise RigLockError("the rig lock needs POSIX file locks (fcntl)")
        deadline = time.monotonic() + TRANSIENT_RETRY_S
        while True:
            fd = _open_lock_file(path)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                holder = _read_holder(fd)
                os.close(fd)
                if holder is not None and holder.alive():
                    raise RigLockError(f"the rig {address} is held by {holder.describe()}: it was not touched; "
                                       "wait for it to finish or stop it (hopkinson safe says how)", holder) from None
                if time.monotonic() >= deadline:
                    raise RigLockError(f"the rig {address} is held by another process ({path}): it was not "
                                       "touched", holder) from None
                time.sleep(0.05)
                continue
            if not _same_file(fd, path):  # swapped while we locked: try the file now there
                os.close(fd)
                continue
            break
        previous = _read_holder(fd)
        reclaimed = previous if previous is not None and previous.pid != os.getpid() else None
        holder = LockHolder(os.getpid(), command or command_line(), utc_now_iso(), current_user(), socket.gethostname(),
                            address)
        try:
            os.ftruncate(fd, 0)
            os.pwrite(fd, (json.dumps(asdict(holder)) + "\n").encode(), 0)
        except OSError:
            pass  # a read-only lock file (another user's, not opened for writing): the lock holds anyway
        return cls(fd, path, holder, reclaimed)

    @property
    def held(self) -> bool:
        return self._fd is not None

    def release(self) -> None:
        """Release the lock (idempotent). The file stays: removing it would let a waiting
        process lock a file no longer at the path while a new one is created."""
        if self._fd is not None:
            with contextlib.suppress(OSError):
                os.ftruncate(self._fd, 0)  # no stale details for the next reader
            os.close(self._fd)  # closing the descriptor drops the flock
            self._fd = None

    def __enter__(self) -> RigLock:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


def current_user() -> str:
    """This process's user name (its uid when there is none)."""
    try:
        return getpass.getuser()
    except Exception:  # no user name (a container): the uid will do
        return str(os.getuid())


def current_holder(config: Any, *, address: str | None = None) -> LockHolder | None:
    """Who holds the rig now (None: nobody). Reads only: never blocks a holder for longer than
    an instant (a shared lock tried and dropped at once)."""
    address = address or rig_address(config)
    try:
        path = lock_path(address)
    except RigLockError:
        return None
    if fcntl is None or not path.exists():  # pragma: no cover - Windows
        return None
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0))
    except OSError:
        return None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except OSError:  # held exclusively: by whom?
            holder = _read_holder(fd)
            return holder or LockHolder(0, "unknown process", "", address=address)
        fcntl.flock(fd, fcntl.LOCK_UN)
        return None
    finally:
        os.close(fd)
