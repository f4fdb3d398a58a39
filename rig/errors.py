"""Errors of the rig layer, with the exit code the command line gives each, and the operator's
hint for a failure (chosen from the error's type, never from the words of its message)."""

from __future__ import annotations

from hopkinson.drivers.errors import InstrumentConnectionError, InstrumentError, InstrumentTimeout

# The exit codes of every `hopkinson` command (docs/exit-codes.md; `hopkinson --help` lists them).
EXIT_DONE = 0
EXIT_CHECK_FAILED = 1
EXIT_BAD_INPUT = 2
EXIT_ABORTED = 3
EXIT_ANALYSIS_FAILED = 4
EXIT_CODES: dict[str, str] = {
    "0": "done: the shot, campaign or command completed (for a shot: fired, recorded and analysed)",
    "1": "probe/status/sim check: something did not answer, or read a value that cannot be true",
    "2": "bad input or configuration, or the rig held by another process: nothing was moved or fired",
    "3": "aborted to the safe state, a FAULT (the safe state not confirmed; `safe` too), or interrupted by a "
         "signal; a campaign stopped with shots left",
    "4": "recorded but its analysis failed: the raw shot is kept (`hopkinson analyse` it); a campaign "
         "complete with failed analyses",
    "5": "done, but its lab record is in neither the database nor the spool: `hopkinson lab import` the "
         "shot file (rig/lab_record.py EXIT_NOT_RECORDED)",
    "130, 128+N": "Ctrl-C, or signal N, in a command that drives no rig",
}


def exit_codes_help() -> str:
    """The exit codes as `--help` shows them (an argparse epilog)."""
    width = max(len(code) for code in EXIT_CODES)
    return "exit codes (docs/exit-codes.md):\n" + "\n".join(f"  {code:<{width}}  {text}"
                                                            for code, text in EXIT_CODES.items())


class ConfigError(ValueError):
    """A configuration or plan file that is wrong: names the file, the key and the reason."""

    exit_code = EXIT_BAD_INPUT


class ShotAborted(RuntimeError):
    """A shot that ended in the safe state before completing (exit code 3)."""

    exit_code = EXIT_ABORTED


class Interrupted(BaseException):
    """A termination signal (SIGTERM, SIGHUP) in a command that drives no rig: unwinds like
    KeyboardInterrupt, so that half-written files are removed on the way out."""

    def __init__(self, signal_name: str, exit_code: int) -> None:
        super().__init__(f"interrupted ({signal_name})")
        self.exit_code = exit_code


HINT_TIMEOUT = "An instrument did not answer in time: check its cable and power."
HINT_CONNECTION = ("Check the instrument's cable/network and power, and its address in the rig configuration; "
                   "it is retried automatically.")
HINT_INSTRUMENT = "The instrument refused or answered badly: check its settings and its front panel."
HINT_NOT_CONFIRMED = "The shot was not confirmed in time; ARM again when ready."
HINT_SAFE_NOT_CONFIRMED = "Check the rig by hand: valves and reservoir pressure."
HINT_OPERATOR_ABORT = "The rig is safe; ARM again when ready."
HINT_WATCHDOG = ("The PC missed the controller's heartbeat (overloaded, or the network to the controller "
                 "dropped): check the link, then ARM again.")


def instrument_hint(exc: BaseException) -> str:
    """What the operator does about an instrument error, by its type ("" for other errors)."""
    if isinstance(exc, InstrumentTimeout):
        return HINT_TIMEOUT
    if isinstance(exc, InstrumentConnectionError):
        return HINT_CONNECTION
    if isinstance(exc, InstrumentError):
        return HINT_INSTRUMENT
    return ""


class InstrumentUnreachable(ConfigError):
    """An instrument that could not be reached or set up before anything moved (exit 2)."""


def unreachable(exc: InstrumentError, fix: str | None = None) -> InstrumentUnreachable:
    """One line for an instrument that failed before the shot: the instrument and the step,
    the gist of the reason (the first clause: a library's long text cut), that nothing moved,
    and the fix (`fix`, else by the cause)."""
    gist = exc.problem.split(":")[0].strip() or exc.problem[:80]
    fix = f"{fix}." if fix else (instrument_hint(exc) or HINT_INSTRUMENT)
    return InstrumentUnreachable(f"{exc.instrument}: could not be reached before the shot ('{exc.command}': "
                                 f"{gist}); nothing was moved. Fix: {fix} `hopkinson probe` shows what answers")


def with_hint(message: str, hint: str) -> str:
    """A message and its hint as the operator reads them ("text\\n→ hint")."""
    return f"{message}\n→ {hint}" if hint else message
