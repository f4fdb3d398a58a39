"""The shipped configurations (package data): rig.toml, rig-sim.toml, sim.toml, campaigns/."""
