"""Find the class a rig.toml `driver = ...` names, and check that it can play its role.

    [amplifier]
    driver = "mylab.conditioners:ChargeAmp"   # package.module:Class (importable: installed, or
                                              # on PYTHONPATH)
    driver = "charge-amp"                     # or an entry point of the group below

A lab's package declares entry points in its own pyproject.toml:

    [project.entry-points."hopkinson.drivers"]
    charge-amp = "mylab.conditioners:ChargeAmp"

The check compares the class with the role's Protocol (drivers/roles.py) and names every
missing method, so a mistake shows at load time, not in the middle of a shot.
"""

from __future__ import annotations

import importlib
from importlib import metadata

from hopkinson.drivers.roles import ROLES, role_members
from hopkinson.rig.errors import ConfigError

ENTRY_POINT_GROUP = "hopkinson.drivers"
INSTANCE_MEMBERS = ("name", "trace")  # set by the constructor: checked on the instance


def driver_class(spec: str, role: str, where: str) -> type:
    """The class `spec` names ("package.module:Class" or an entry point name), checked against
    `role` ("valve_controller", "digitizer", "amplifier"); ConfigError naming `where`."""
    module_name, colon, attribute = spec.partition(":")
    if colon:
        try:
            module = importlib.import_module(module_name)
        except ImportError as exc:
            raise ConfigError(f"{where}: cannot import {module_name!r} for driver {spec!r}: {exc} "
                              "(is the lab's package installed or on PYTHONPATH?)") from None
        except Exception as exc:  # the lab's module itself failed
            raise ConfigError(f"{where}: importing {module_name!r} for driver {spec!r} failed: "
                              f"{type(exc).__name__}: {exc}") from None
        cls = getattr(module, attribute, None)
        if cls is None:
            raise ConfigError(f"{where}: module {module_name!r} has no {attribute!r} (driver {spec!r})")
    else:
        cls = _entry_point(spec, where)
    if not isinstance(cls, type):
        raise ConfigError(f"{where}: driver {spec!r} is not a class")
    missing = [m for m in role_members(ROLES[role]) if m not in INSTANCE_MEMBERS and not hasattr(cls, m)]
    if missing:
        raise ConfigError(f"{where}: driver {spec!r} cannot be the {role.replace('_', ' ')}: it has no "
                          f"{', '.join(missing)} (see docs/writing-a-driver.md)")
    return cls


def _entry_point(name: str, where: str) -> type:
    found = metadata.entry_points(group=ENTRY_POINT_GROUP, name=name)
    if not found:
        known = sorted(ep.name for ep in metadata.entry_points(group=ENTRY_POINT_GROUP))
        raise ConfigError(f"{where}: no driver {name!r}: not \"package.module:Class\" and no entry point of "
                          f"group {ENTRY_POINT_GROUP!r} has that name (installed: {', '.join(known) or 'none'})")
    try:
        return next(iter(found)).load()
    except Exception as exc:
        raise ConfigError(f"{where}: loading entry point {name!r} failed: {type(exc).__name__}: {exc}") from None
