"""Writing files so that nothing is ever half-written, overwritten by mistake or redirected.

Every file the application writes (records, models, DCMs, reports, shot files, state and
address files) goes through `atomic_write` or `atomic_open`:

- the data goes to a new temporary file in the target's own folder, created exclusively with a
  random name (`tempfile.mkstemp`: O_CREAT|O_EXCL|O_NOFOLLOW, so never through a planted
  symlink), flushed and fsynced;
- it is then renamed over the target (`os.replace`, atomic on POSIX) and the folder is fsynced;
  a symlink at the target's name is replaced, never written through;
- on any failure, an exception or an interrupt, the temporary file is removed: the target is
  either the old file or the complete new one, never a truncated one.

`check_output_path` refuses an output that is one of the command's inputs or an existing shot
file (HDF5), before anything is computed. `private_runtime_dir` is the per-user folder for
the simulated rig's pty link, addresses and state (never a fixed name in the shared /tmp).

This module is the root package's, so every layer (analysis, drivers, reports, rig, ui) may use
it; it imports only the standard library.
"""

from __future__ import annotations

import contextlib
import os
import stat
import tempfile
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import IO, Any

HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"


class UnsafeOutputError(ValueError):
    """An output path that would destroy an input or a shot file, or an unusable folder."""


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _fsync_folder(folder: Path) -> None:
    with contextlib.suppress(OSError):  # not every file system lets a folder be opened
        fd = os.open(folder, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def _temporary_beside(target: Path) -> tuple[int, Path]:
    folder = target.parent if str(target.parent) else Path(".")
    if not folder.is_dir():
        raise UnsafeOutputError(f"{target}: the folder {folder} does not exist")
    fd, name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=folder)
    return fd, Path(name)


def _publish(tmp: Path, target: Path, mode: int | None) -> None:
    os.chmod(tmp, mode if mode is not None else 0o666 & ~_umask())
    os.replace(tmp, target)
    _fsync_folder(target.parent if str(target.parent) else Path("."))


def atomic_write(path: str | os.PathLike[str], data: bytes | bytearray | memoryview | str | Callable[[Path], Any], *,
                 encoding: str = "utf-8", mode: int | None = None) -> Path:
    """Write `data` to `path` atomically (module docstring); returns the path.

    data: the bytes or text to write, or a function that writes the file at the temporary path
    it is given (for writers that want a file name: h5py, matplotlib, numpy.savez). mode: the
    file's permissions (default: 0o666 less the umask, as open() would give).
    """
    target = Path(path)
    fd, tmp = _temporary_beside(target)
    try:
        if callable(data):
            os.close(fd)
            fd = -1
            data(tmp)
            fd = os.open(tmp, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0))
            os.fsync(fd)
        else:
            view = memoryview(data.encode(encoding) if isinstance(data, str) else data)
            while view:
                written = os.write(fd, view)
                view = view[written:]
            os.fsync(fd)
        os.close(fd)
        fd = -1
        _publish(tmp, target, mode)
    except BaseException as exc:
        if fd >= 0:
            os.close(fd)
        with contextlib.suppress(OSError):
            tmp.unlink()
        if isinstance(exc, OSError) and exc.filename is None and exc.errno is not None:
            raise OSError(exc.errno, exc.strerror, str(target)) from exc  # name the file (a full disk)
        raise
    return target


@contextlib.contextmanager
def atomic_open(path: str | os.PathLike[str], text_mode: str = "w", *, encoding: str = "utf-8",
                newline: str | None = None, mode: int | None = None) -> Iterator[IO[Any]]:
    """A file object for writing `path` block by block; published atomically when the block
    ends without an error, removed otherwise (module docstring). text_mode: "w" or "wb"."""
    if text_mode not in ("w", "wb"):
        raise ValueError(f"atomic_open writes a new file: mode 'w' or 'wb', got {text_mode!r}")
    target = Path(path)
    fd, tmp = _temporary_beside(target)
    try:
        if text_mode == "wb":
            handle: IO[Any] = os.fdopen(fd, "wb")
        else:
            handle = os.fdopen(fd, "w", encoding=encoding, newline=newline)
    except BaseException:
        os.close(fd)
        tmp.unlink(missing_ok=True)
        raise
    try:
        with handle:
            yield handle
            handle.flush()
            os.fsync(handle.fileno())
        _publish(tmp, target, mode)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


def is_hdf5_file(path: str | os.PathLike[str]) -> bool:
    """Does `path` hold an HDF5 file (the shot file format)? False when it cannot be read."""
    try:
        with open(path, "rb") as handle:
            return handle.read(len(HDF5_SIGNATURE)) == HDF5_SIGNATURE
    except OSError:
        return False


def _same_file(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        try:
            return a.resolve(strict=False) == b.resolve(strict=False)
        except (OSError, RuntimeError):  # a symlink loop: reading it fails later, with its own error
            return False


def check_writes(outputs: Iterable[tuple[str, str | os.PathLike[str]]],
                 inputs: Iterable[str | os.PathLike[str]]) -> None:
    """Refuse (UnsafeOutputError) before anything moves: an output (`(flag, path)` pairs) that
    is one of the `inputs` or another output (through symlinks and hard links: the same file),
    an existing HDF5 shot file, or a folder. Every command's write flags go through it."""
    seen: list[tuple[str, Path]] = []
    sources = [Path(i) for i in inputs]
    for flag, output in outputs:
        out = Path(output)
        for source in sources:
            if _same_file(out, source):
                raise UnsafeOutputError(f"{flag} {out}: that is the input {source}: choose another name (an "
                                        "input is never written over)")
        for other_flag, other in seen:
            if _same_file(out, other):
                raise UnsafeOutputError(f"{flag} {out}: that is also {other_flag}'s file: choose another name")
        if out.is_dir():
            raise UnsafeOutputError(f"{flag} {out}: that is a folder, not a file name")
        if out.exists() and is_hdf5_file(out):
            raise UnsafeOutputError(f"{flag} {out}: an HDF5 shot file exists under that name: shot files are "
                                    "never written over; choose another name")
        seen.append((flag, out))


def check_output_path(output: str | os.PathLike[str], inputs: Iterable[str | os.PathLike[str]] = (),
                      *, what: str = "output") -> Path:
    """Refuse (UnsafeOutputError) an output that is one of `inputs`, an existing shot file
    (HDF5), a folder, or in a folder that does not exist; returns the output as a Path.

    Call it before any work, so that a refused command has done nothing.
    """
    out = Path(output)
    for source in inputs:
        if _same_file(out, Path(source)):
            raise UnsafeOutputError(f"{out}: the {what} is the input {source}: choose another name "
                                    "(an input is never overwritten)")
    if out.is_dir():
        raise UnsafeOutputError(f"{out}: the {what} is a folder, not a file name")
    if out.exists() and is_hdf5_file(out):
        raise UnsafeOutputError(f"{out}: an HDF5 shot file exists under that name: shot files are never "
                                "overwritten; choose another name")
    folder = out.parent if str(out.parent) else Path(".")
    if not folder.is_dir():
        raise UnsafeOutputError(f"{out}: the folder {folder} does not exist")
    return out


def _owned_private_folder(folder: Path) -> bool:
    info = os.lstat(folder)
    return (stat.S_ISDIR(info.st_mode) and info.st_uid == os.getuid()
            and stat.S_IMODE(info.st_mode) & 0o077 == 0)


def private_runtime_dir(app: str = "hopkinson") -> Path:
    """This user's private runtime folder for `app` (created 0700 when missing).

    `$XDG_RUNTIME_DIR/<app>` when XDG_RUNTIME_DIR is set, else `<tmp>/<app>-<uid>`. A folder
    that exists but is a symlink, belongs to another user or is open to others is refused
    (UnsafeOutputError): another local user may have planted it.
    """
    base = os.environ.get("XDG_RUNTIME_DIR")
    folder = Path(base) / app if base else Path(tempfile.gettempdir()) / f"{app}-{os.getuid()}"
    try:
        os.mkdir(folder, 0o700)
    except FileExistsError:
        pass
    if not _owned_private_folder(folder):
        raise UnsafeOutputError(f"{folder}: the runtime folder is not a private folder of this user "
                                "(a symlink, another owner, or open to others): remove it or set XDG_RUNTIME_DIR")
    return folder


def append_json_line(path: str | os.PathLike[str], entry: dict[str, Any]) -> None:
    """Append `entry` as one JSON line (a witness log, a history) and fsync it before returning:
    a line is either whole on disk or absent (one write of O_APPEND)."""
    import json

    line = json.dumps(entry, default=str) + "\n"
    fd = os.open(Path(path), os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
    try:
        os.write(fd, line.encode())
        os.fsync(fd)
    finally:
        os.close(fd)
