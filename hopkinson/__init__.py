"""hopkinson: Hopkinson-bar shock calibration of high-g accelerometers.

The installed package maps the repository's top-level folders into one import name:
`hopkinson.analysis` (analysis/), `hopkinson.drivers` (drivers/), `hopkinson.rig` (rig/),
`hopkinson.reports` (reports/), `hopkinson.ui` (ui/) and the shipped configurations as
package data, `hopkinson.config` (config/).
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("hopkinson")
except PackageNotFoundError:  # running from a source tree that was never installed
    __version__ = "0+unknown"
