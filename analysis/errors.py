"""Errors the analysis raises for bad input or a fit the data cannot support.

Every message is meant for a person: it names the file or quantity and what was wrong.
"""


class AnalysisError(ValueError):
    """Bad input data, or a result the data cannot support (unstable, not converged)."""


class RecordError(AnalysisError):
    """A record file that cannot be read: missing column, NaN, too short, wrong type."""
