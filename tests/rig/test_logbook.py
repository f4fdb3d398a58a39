"""The lab record (rig/logbook.py): a JSON-lines log beside every shot file and in every campaign
run folder (UTC times, every event, warning, error and instrument identity), `--trace` with
every instrument command and reply (binary blocks summarised), `--json-events` for scripts,
`--log-file`, `-v`; and the command line's one-line errors for unsafe or unwritable outputs."""

from __future__ import annotations

import errno
import json
import os
import re
import signal
from pathlib import Path

from hopkinson.fileio import UnsafeOutputError, atomic_write
from hopkinson.rig.cli.main import main
from hopkinson.rig.logbook import Logbook, read_log

REPO = Path(__file__).resolve().parents[2]
QUICK = ("--sample-rate", "20000")  # an analysis that fails at once (too few samples): not what is tested here
ANALYSIS_FAILED = 4  # so such a shot exits 4 (docs/exit-codes.md): recorded, its analysis failed


def _fast_sim(tmp_path: Path) -> Path:
    path = tmp_path / "sim-fast.toml"
    path.write_text("[world]\ntime_scale = 100.0\n", encoding="utf-8")
    return path


def test_shot_log_trace_json_events_and_log_file(tmp_path: Path, capsys) -> None:
    extra = tmp_path / "all.log.jsonl"
    assert main(["shot", "--sim", "--sim-config", str(_fast_sim(tmp_path)), "--yes", "--pressure-bar", "1.0",
                 "--out", str(tmp_path / "shots"), "--shot-name", "s1", "--trace", "--json-events",
                 "--log-file", str(extra), *QUICK]) == ANALYSIS_FAILED
    out = capsys.readouterr().out
    stream = [json.loads(line) for line in out.splitlines()]  # every line of stdout is one JSON event
    assert stream[0]["type"] == "StateEntered" and stream[-1]["type"] == "ShotFinished"
    assert stream[-1]["final_state"] == "DONE" and stream[-1]["shot_path"].endswith("s1.h5")

    log = read_log(tmp_path / "shots" / "s1.log.jsonl")
    assert log[0]["type"] == "LogOpened" and log[0]["pid"] == os.getpid() and log[0]["software_version"]
    assert all(re.fullmatch(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d{6}Z", e["utc"]) for e in log)
    types = [e["type"] for e in log]
    assert {"StateEntered", "Reading", "Identified", "Fired", "Stored", "Analysed", "ShotFinished"} <= set(types)
    (identified,) = [e for e in log if e["type"] == "Identified"]
    assert "SIMDIG" in identified["identities"]["digitizer"]
    traces = [e for e in log if e["type"] == "Trace"]
    assert {e["direction"] for e in traces} == {"->", "<-"}
    instruments = {e["instrument"] for e in traces}
    assert any("digitizer" in i for i in instruments) and any("valve controller" in i for i in instruments)
    assert any(re.search(r"<binary block: \d+ bytes>", e["text"]) for e in traces)  # the waveforms, summarised
    assert max(len(e["text"]) for e in traces) <= 400
    # The events on stdout are the ones in the log (the log adds the trace and its header).
    assert [e for e in log if e["type"] not in ("Trace", "LogOpened")] == stream
    copy = read_log(extra)
    assert [e for e in copy if e["type"] not in ("Trace", "LogOpened")] == stream


def test_verbose_lines_carry_times_readings_and_identities(tmp_path: Path, capsys) -> None:
    assert main(["shot", "--sim", "--sim-config", str(_fast_sim(tmp_path)), "--yes", "--pressure-bar", "1.0",
                 "--out", str(tmp_path), "-v", *QUICK]) == ANALYSIS_FAILED
    lines = capsys.readouterr().out.splitlines()  # (the quick analysis failed: no results line)
    timed = [ln for ln in lines if re.match(r"\d\d:\d\d:\d\d\.\d{3} [A-Z]+ ", ln)]
    assert any(" CHECK     instruments: " in ln for ln in timed)
    assert any(re.search(r" CHARGE +\d\.\d{3} bar, \d+\.\d mbar; interlocks all hold", ln) for ln in timed)
    assert lines[-2].startswith("shot file: ") and lines[-1].startswith("log:       ")


def test_a_log_that_cannot_be_written_is_reported_once_and_closed(tmp_path: Path) -> None:
    book = Logbook(tmp_path / "x.log.jsonl")
    os.close(book._fd)  # the disk went away
    book._fd = os.open(os.devnull, os.O_RDONLY)  # writes now fail with EBADF
    book.write({"type": "Note", "utc": "", "message": "lost"})
    assert book.failure is not None and "could not be written" in book.failure and not book.open
    book.close()
    book.write({"type": "Note"})  # closed: ignored, never raises


def test_a_symlinked_log_is_never_followed(tmp_path: Path) -> None:
    target = tmp_path / "victim"
    target.write_text("keep", encoding="utf-8")
    (tmp_path / "evil.log.jsonl").symlink_to(target)
    try:
        Logbook(tmp_path / "evil.log.jsonl")
    except OSError as exc:
        assert exc.errno == errno.ELOOP
    else:
        raise AssertionError("a symlink was followed")
    assert target.read_text(encoding="utf-8") == "keep"


# -- the command line: unsafe or unwritable outputs, termination of commands that drive no rig ---------
def _run_patched(monkeypatch, action, capsys) -> tuple[int, str]:
    import hopkinson.rig.cli.campaign as module

    # register() binds the function when main() builds the parser: patched before that
    monkeypatch.setattr(module, "status_command", lambda args: action())
    rc = main(["campaign", "status", "anything"])
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    return rc, err.strip()


def test_unsafe_and_unwritable_outputs_are_one_line_exit_2(monkeypatch, capsys, tmp_path: Path) -> None:
    def unsafe() -> int:
        raise UnsafeOutputError("out.h5: is an existing shot file: never written over")

    def denied() -> int:
        raise PermissionError(errno.EACCES, "Permission denied", str(tmp_path / "ro" / "out.csv"))

    def folder() -> int:
        raise IsADirectoryError(errno.EISDIR, "Is a directory", str(tmp_path))

    assert _run_patched(monkeypatch, unsafe, capsys) == (2, "hopkinson: error: out.h5: is an existing shot file: "
                                                            "never written over")
    assert _run_patched(monkeypatch, denied, capsys) == (2, f"hopkinson: error: {tmp_path / 'ro' / 'out.csv'}: "
                                                            "Permission denied")
    assert _run_patched(monkeypatch, folder, capsys) == (2, f"hopkinson: error: {tmp_path}: Is a directory")


def test_sigterm_ends_a_command_cleanly_and_an_atomic_write_leaves_no_file(monkeypatch, capsys, tmp_path) -> None:
    target = tmp_path / "out.csv"

    def write_then_terminated() -> int:
        def writer(tmp: Path) -> None:
            tmp.write_text("half a file", encoding="utf-8")
            os.kill(os.getpid(), signal.SIGTERM)  # arrives mid-write

        atomic_write(target, writer)
        return 0

    rc, err = _run_patched(monkeypatch, write_then_terminated, capsys)
    assert (rc, err) == (143, "hopkinson: error: interrupted (SIGTERM)")
    assert list(tmp_path.iterdir()) == []  # neither the target nor a temporary file
