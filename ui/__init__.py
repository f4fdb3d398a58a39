"""The technician's PySide6 panel. Imports rig, never the other way round."""
