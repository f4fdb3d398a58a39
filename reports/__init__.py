"""Calibration reports (matplotlib pages, PDF and HTML writers) from analysis results.

Imports `analysis` and plotting libraries, never `rig`, `drivers` or `ui`.
"""
