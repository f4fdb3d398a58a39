"""hopkinson: Hopkinson-bar shock calibration of high-g accelerometers.

The installed package maps the repository's top-level folders into one import name:
`hopkinson.analysis` (analysis/), `hopkinson.drivers` (drivers/), `hopkinson.rig` (rig/),
`hopkinson.reports` (reports/), `hopkinson.ui` (ui/) and the shipped configurations as
package data, `hopkinson.config` (config/).
"""

from typing import Any


def __getattr__(name: str) -> Any:
    """`__version__` read from the installed metadata when first asked (importlib.metadata
    costs ~30 ms of every command's start, and most never print the version)."""
    if name != "__version__":
        raise AttributeError(f"module 'hopkinson' has no attribute {name!r}")
    from importlib.metadata import PackageNotFoundError, version

    try:
        value = version("hopkinson")
    except PackageNotFoundError:  # running from a source tree that was never installed
        value = "0+unknown"
    globals()["__version__"] = value
    return value
