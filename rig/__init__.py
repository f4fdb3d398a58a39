"""Rig orchestration: sequencer, interlocks, shot files, campaigns, command line."""
