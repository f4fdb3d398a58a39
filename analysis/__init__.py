"""Hopkinson-bar calibration: pure NumPy/SciPy analysis (no drivers, no Qt)."""
