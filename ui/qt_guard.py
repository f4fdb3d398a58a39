"""Guard against a reference-count bug of PySide6 6.12.0 on Python 3.11.

Measured here (PySide6-Essentials 6.12.0, shiboken6 6.12.0, CPython 3.11.7): every call of a
Qt method that returns nothing (QLabel.setText, QWidget.setEnabled, …) takes one reference
from `None` without having given one; a bool-returning override does the same to True/False.
`None` starts with ~16 000 references, so a panel that updates its widgets a few hundred times
a second dies within a minute with "Fatal Python error: none_dealloc". PySide6 6.11.3 does not
do this, and Python 3.12+ is immune (None, True and False are immortal there).

`guard_singletons()` detects the bug with a probe (100 calls of QObject.setObjectName) and,
only when it is present, makes None, True and False effectively immortal the way Python 3.12
does: their reference counts are raised by 2**40, so the leak can never bring them to zero.
These three objects are never freed in a running interpreter anyway; nothing else changes.
The proper fix is a PySide6 without the bug (pin PySide6-Essentials != 6.12.0); the guard
keeps the panel alive until then.
"""

from __future__ import annotations

import ctypes
import sys

_PIN = 1 << 40
_guarded = False


def leaks_none_references() -> bool:
    """Does a void Qt method call take a reference from None? (100-call probe)"""
    from PySide6.QtCore import QObject

    probe = QObject()
    before = sys.getrefcount(None)
    for _ in range(100):
        probe.setObjectName("probe")
    return sys.getrefcount(None) - before <= -50


def guard_singletons() -> bool:
    """Apply the guard when this PySide6 leaks None references; returns whether it did."""
    global _guarded
    if _guarded or sys.version_info >= (3, 12) or sys.implementation.name != "cpython":
        return _guarded
    try:
        leaking = leaks_none_references()
    except ImportError:  # no Qt here: `hopkinson panel` says so in one line
        return False
    if not leaking:
        return False
    for singleton in (None, True, False):
        # ob_refcnt is the first field of every CPython 3.11 object (Py_ssize_t at id(obj)).
        ctypes.c_ssize_t.from_address(id(singleton)).value += _PIN
    _guarded = True
    return True
