"""Errors of the rig layer, with the exit code the command line gives each."""


class ConfigError(ValueError):
    """A configuration or plan file that is wrong: names the file, the key and the reason."""

    exit_code = 2


class ShotAborted(RuntimeError):
    """A shot that ended in the safe state before completing (exit code 3)."""

    exit_code = 3
