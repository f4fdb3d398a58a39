"""The Qt binding the panel runs on keeps None's reference count (the PySide6-Essentials pin in
pyproject.toml): PySide6 6.12.0 drops a reference to None on every void call, and on Python 3.11
the interpreter aborts with "none_dealloc" once None's count (~5 000 at start) runs out; a panel
makes that many calls in minutes. Run in a child process: the failure is a fatal abort."""

from __future__ import annotations

import subprocess
import sys

CHILD = """
import sys
from PySide6.QtCore import QObject
obj = QObject()
before = sys.getrefcount(None)
for _ in range(20_000):
    obj.setObjectName("x")  # a void call
print(before - sys.getrefcount(None))
"""


def test_void_qt_calls_keep_the_references_to_none() -> None:
    done = subprocess.run([sys.executable, "-c", CHILD], capture_output=True, text=True, timeout=120,
                          env={"QT_QPA_PLATFORM": "offscreen", "PATH": "/usr/bin:/bin"})
    assert done.returncode == 0, done.stderr[-500:]
    assert abs(int(done.stdout)) < 100  # references to None lost over 20 000 void calls
