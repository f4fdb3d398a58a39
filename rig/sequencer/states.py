"""The sequencer's states and the transitions between them (the table is the rule).

    CHECK → EVACUATE → CHARGE → ARM → FIRE → CAPTURE → SAFE → STORE → ANALYSE → DONE
      any error, abort, timeout or interrupt in CHECK..CAPTURE ──► SAFE ──► (STORE) ──► ABORTED
      SAFE not confirmed, or the shot file (or its analysis) not written ────────────► FAULT
"""

from __future__ import annotations

from enum import StrEnum

from hopkinson.rig.config import RigConfig


class State(StrEnum):
    """The sequencer's states (their values are the names used in events and messages)."""

    IDLE = "IDLE"
    CHECK = "CHECK"
    EVACUATE = "EVACUATE"
    CHARGE = "CHARGE"
    ARM = "ARM"
    FIRE = "FIRE"
    CAPTURE = "CAPTURE"
    SAFE = "SAFE"
    STORE = "STORE"
    ANALYSE = "ANALYSE"
    DONE = "DONE"
    ABORTED = "ABORTED"
    FAULT = "FAULT"


_S = State
TRANSITIONS: dict[State, frozenset[State]] = {
    _S.IDLE: frozenset({_S.CHECK}),
    _S.CHECK: frozenset({_S.EVACUATE, _S.SAFE}),
    _S.EVACUATE: frozenset({_S.CHARGE, _S.SAFE}),
    _S.CHARGE: frozenset({_S.ARM, _S.SAFE}),
    _S.ARM: frozenset({_S.FIRE, _S.SAFE}),
    _S.FIRE: frozenset({_S.CAPTURE, _S.SAFE}),
    _S.CAPTURE: frozenset({_S.SAFE}),
    _S.SAFE: frozenset({_S.STORE, _S.ABORTED, _S.FAULT}),
    _S.STORE: frozenset({_S.ANALYSE, _S.ABORTED, _S.FAULT}),
    # FAULT: the analysis could not be stored; ABORTED: a signal or an abort came during the shot
    _S.ANALYSE: frozenset({_S.DONE, _S.ABORTED, _S.FAULT}),
    _S.DONE: frozenset({_S.CHECK}),
    _S.ABORTED: frozenset({_S.CHECK}),
    _S.FAULT: frozenset({_S.CHECK}),
}
FINAL_STATES = frozenset({_S.DONE, _S.ABORTED, _S.FAULT})
# The states in which the rig is driven towards a shot: an abort, a timeout or an error here
# goes to SAFE.
ACTIVE_STATES = (_S.CHECK, _S.EVACUATE, _S.CHARGE, _S.ARM, _S.FIRE, _S.CAPTURE)

# What each state does, for the StateEntered events.
STATE_TEXT: dict[State, str] = {
    _S.CHECK: "checking instruments and interlocks",
    _S.EVACUATE: "evacuating the fixture",
    _S.CHARGE: "charging the reservoir",
    _S.ARM: "arming the digitizer",
    _S.FIRE: "firing",
    _S.CAPTURE: "waiting for the trigger and fetching the record",
    _S.SAFE: "making the rig safe (fire and fill closed, reservoir vented)",
    _S.STORE: "storing the raw shot",
    _S.ANALYSE: "analysing the shot",
    _S.DONE: "shot done",
    _S.ABORTED: "shot aborted; the rig is safe",
    _S.FAULT: "FAULT: the rig may not be safe, check it",
}


def state_timeout_s(config: RigConfig, state: State) -> float | None:
    """The configured timeout of `state` (None for IDLE and the final states)."""
    return getattr(config.timeouts, f"{state.value.lower()}_s", None)


def check_transition(current: State, new: State) -> None:
    """RuntimeError unless the table allows `current` -> `new`."""
    if new not in TRANSITIONS[current]:
        raise RuntimeError(f"illegal sequencer transition {current.value} -> {new.value}")
