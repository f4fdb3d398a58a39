"""The technician's PySide6 panel. Imports rig, never the other way round.

Importing the package applies ui.qt_guard (a PySide6 6.12.0 / Python 3.11 reference-count
bug that otherwise kills the panel within a minute; see that module).
"""

from ui.qt_guard import guard_singletons

guard_singletons()
