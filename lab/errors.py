"""The lab record's one error type."""

from __future__ import annotations


class LabError(Exception):
    """Anything wrong with the lab's record or its input: one line naming what and why."""

    exit_code = 2


class TamperedShotError(LabError):
    """A shot file whose raw channels do not match their recorded SHA-256."""
