"""The shot sequencer: an explicit state machine with a transition table, as a small package.

- states.py: the states, the transition table, each state's text and timeout;
- context.py: what a shot carries through the steps (request, fire authorisation, the held
  abort, the state's clock, the event publisher, what the steps learn);
- steps.py: CHECK, EVACUATE, CHARGE, ARM, FIRE, CAPTURE, each a function of the context;
- safe.py: SAFE, the one procedure that makes the rig safe and confirms it by reading back,
  run on every way out (and by `hopkinson safe`);
- runner.py: `Sequencer`: the steps, then SAFE always, STORE and ANALYSE; `abort` held from
  the moment it is asked.

    sequencer = Sequencer(instruments, config, bus)
    outcome = sequencer.run_shot(ShotRequest(pressure_bar=2.0), FireAuthorisation.pre_given())
"""

from hopkinson.rig.sequencer.context import (
    POLL_INTERVAL_S,
    PROGRESS_INTERVAL_S,
    READINGS_INTERVAL_S,
    Abort,
    AbortRequest,
    FireAuthorisation,
    ShotContext,
)
from hopkinson.rig.sequencer.runner import Sequencer
from hopkinson.rig.sequencer.safe import DISPLAY_INTERLOCKS, SafeResult, make_rig_safe
from hopkinson.rig.sequencer.states import (
    ACTIVE_STATES,
    FINAL_STATES,
    STATE_TEXT,
    TRANSITIONS,
    State,
    state_timeout_s,
)

__all__ = [
    "ACTIVE_STATES", "DISPLAY_INTERLOCKS", "FINAL_STATES", "POLL_INTERVAL_S", "PROGRESS_INTERVAL_S",
    "READINGS_INTERVAL_S", "STATE_TEXT", "TRANSITIONS", "Abort", "AbortRequest", "FireAuthorisation",
    "SafeResult", "Sequencer", "ShotContext", "State", "make_rig_safe", "state_timeout_s",
]
