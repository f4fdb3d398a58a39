"""hopkinson.fileio: atomic writes, refused outputs, the private runtime folder."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from hopkinson.fileio import (
    UnsafeOutputError,
    atomic_open,
    atomic_write,
    check_output_path,
    private_runtime_dir,
)


def _litter(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.endswith(".tmp"))


def test_atomic_write_bytes_text_and_callback(tmp_path: Path) -> None:
    atomic_write(tmp_path / "a.bin", b"\x00\x01")
    atomic_write(tmp_path / "b.txt", "héllo")
    atomic_write(tmp_path / "c.txt", lambda p: p.write_text("from a writer"))
    assert (tmp_path / "a.bin").read_bytes() == b"\x00\x01"
    assert (tmp_path / "b.txt").read_text(encoding="utf-8") == "héllo"
    assert (tmp_path / "c.txt").read_text() == "from a writer"
    assert _litter(tmp_path) == []
    mask = os.umask(0)
    os.umask(mask)
    assert (tmp_path / "b.txt").stat().st_mode & 0o777 == 0o666 & ~mask


def test_failed_writer_leaves_the_old_file_and_no_temporary(tmp_path: Path) -> None:
    target = tmp_path / "model.json"
    target.write_text("old")

    def broken(path: Path) -> None:
        path.write_text("half")
        raise RuntimeError("disk on fire")

    with pytest.raises(RuntimeError):
        atomic_write(target, broken)
    with pytest.raises(KeyboardInterrupt), atomic_open(target) as handle:
        handle.write("partial")
        raise KeyboardInterrupt
    assert target.read_text() == "old"
    assert _litter(tmp_path) == []


def test_a_planted_symlink_is_replaced_not_written_through(tmp_path: Path) -> None:
    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    planted = tmp_path / "out.html"
    planted.symlink_to(victim)
    atomic_write(planted, "report")
    assert victim.read_text() == "precious"
    assert not planted.is_symlink() and planted.read_text() == "report"


def test_sigterm_during_a_streamed_write_leaves_no_file_under_the_final_name(tmp_path: Path) -> None:
    target = tmp_path / "out.csv"
    script = textwrap.dedent(f"""
        import signal, sys, time
        from hopkinson.fileio import atomic_open
        signal.signal(signal.SIGTERM, lambda *a: sys.exit(3))
        with atomic_open({str(target)!r}) as f:
            for i in range(10**9):
                f.write("1,2,3\\n")
                if i == 1000:
                    print("writing", flush=True)
                    time.sleep(30)
    """)
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    assert proc.stdout is not None and proc.stdout.readline().strip() == "writing"
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(timeout=20) == 3
    assert not target.exists()
    assert _litter(tmp_path) == []


def test_check_output_path_refuses_inputs_shot_files_and_folders(tmp_path: Path) -> None:
    record = tmp_path / "s.csv"
    record.write_text("time_s,reference,response\n")
    with pytest.raises(UnsafeOutputError, match="is the input"):
        check_output_path(record, [record])
    with pytest.raises(UnsafeOutputError, match="is the input"):
        check_output_path(tmp_path / "." / "s.csv", [record])
    link = tmp_path / "alias.csv"
    link.symlink_to(record)
    with pytest.raises(UnsafeOutputError, match="is the input"):
        check_output_path(link, [record])
    shot = tmp_path / "shot.h5"
    shot.write_bytes(b"\x89HDF\r\n\x1a\n" + b"\x00" * 100)
    with pytest.raises(UnsafeOutputError, match="shot file"):
        check_output_path(shot, [record])
    with pytest.raises(UnsafeOutputError, match="folder"):
        check_output_path(tmp_path, [record])
    with pytest.raises(UnsafeOutputError, match="does not exist"):
        check_output_path(tmp_path / "missing" / "x.csv")
    assert check_output_path(tmp_path / "new.csv", [record]) == tmp_path / "new.csv"


def test_private_runtime_dir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("XDG_RUNTIME_DIR", str(tmp_path))
    folder = private_runtime_dir()
    assert folder == tmp_path / "hopkinson"
    assert folder.stat().st_mode & 0o777 == 0o700
    assert private_runtime_dir() == folder  # idempotent
    os.chmod(folder, 0o755)
    with pytest.raises(UnsafeOutputError, match="not a private folder"):
        private_runtime_dir()
    os.rmdir(folder)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir(mode=0o700)
    folder.symlink_to(elsewhere)
    with pytest.raises(UnsafeOutputError, match="not a private folder"):
        private_runtime_dir()


def test_temporary_names_are_unique_and_hidden(tmp_path: Path) -> None:
    seen: list[str] = []

    def writer(path: Path) -> None:
        seen.append(path.name)
        time.sleep(0)
        path.write_text("x")

    atomic_write(tmp_path / "a.txt", writer)
    atomic_write(tmp_path / "a.txt", writer)
    assert len(set(seen)) == 2 and all(name.startswith(".a.txt.") for name in seen)
