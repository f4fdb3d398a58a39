"""The lab record's error types."""

from __future__ import annotations


class LabError(Exception):
    """Anything wrong with the lab's record or its input: one line naming what and why."""

    exit_code = 2
    failure = "setup"  # what it means for a record on its way in (lab.database.Failure)


class DatabaseAway(LabError):
    """The database cannot be reached now (down, locked, the network): try again later."""

    failure = "away"


class RecordRejected(LabError):
    """A record the database must not take as it is (too long a field, a tampered shot, a
    rule broken): set aside with this reason (lab.spool's quarantine), never retried blindly."""

    failure = "rejected"


class TamperedShotError(RecordRejected):
    """A shot file whose raw channels do not match their recorded SHA-256."""
