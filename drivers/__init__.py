"""Instrument drivers (no Qt, no analysis); drivers.sim is the simulated rig."""
