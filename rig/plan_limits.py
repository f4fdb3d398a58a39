"""How many shots a campaign plan may hold, and above how many its number must be confirmed.

Apart from rig.plan so that the command line (which registers every subcommand at start) reads
them without loading the plan's validation (pydantic)."""

MAX_TOTAL_SHOTS = 10_000  # more is a typing error, not a campaign (a shot takes minutes)
CONFIRM_ABOVE_SHOTS = 50  # a plan of more shots needs its number confirmed
