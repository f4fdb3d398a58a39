"""The simulated rig: the world the drivers talk to. Imports nothing of rig, ui or analysis."""
