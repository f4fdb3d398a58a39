"""Which dialect a digitizer speaks, from a plain *IDN? (IEEE 488.2, which every dialect
answers): for `hopkinson probe` and for a shot whose digitizer does not answer the configured
dialect (its one-line error then names the dialect to set)."""

from __future__ import annotations

import threading
import warnings
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from hopkinson.rig.config import RigConfig

PLAIN_IDN_S = 3.0  # the plain *IDN? of a digitizer that did not answer its dialect: bounded
DIALECT_BY_MAKER = (("KEYSIGHT", "keysight"), ("AGILENT", "keysight"), ("TEKTRONIX", "tektronix"),
                    ("LECROY", "lecroy"), ("TELEDYNE", "lecroy"))


def dialect_for(identity: str) -> str | None:
    """The dialect that speaks to an instrument of this *IDN? reply's maker, if one does."""
    maker = identity.split(",")[0].upper()
    return next((dialect for name, dialect in DIALECT_BY_MAKER if name in maker), None)


def plain_identity(config: RigConfig) -> str | None:
    """The digitizer's reply to a plain *IDN? through pyvisa (the configured library, resource
    and terminations), or None when nothing answers within PLAIN_IDN_S."""
    d = config.digitizer
    found: list[str] = []

    def ask() -> None:
        try:
            import pyvisa

            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                manager = pyvisa.ResourceManager(d.visa_library)
            try:
                instrument = manager.open_resource(d.resource, read_termination=d.read_termination,
                                                   write_termination=d.write_termination,
                                                   timeout=int(1000 * PLAIN_IDN_S))
                try:
                    found.append(str(instrument.query("*IDN?")).strip()[:200])
                finally:
                    instrument.close()
            finally:
                manager.close()
        except Exception:  # nothing (sensible) answers: the open step's failure already says why
            return

    thread = threading.Thread(target=ask, name="probe-idn", daemon=True)
    thread.start()
    thread.join(PLAIN_IDN_S + 1.0)
    return found[0] if found and found[0] else None


def dialect_fix(config: RigConfig, identity: str | None = None) -> str | None:
    """'the instrument is a KEYSIGHT: set [digitizer] dialect = "keysight" ...' when a plain
    *IDN? (asked here unless `identity` is given) names another maker's dialect than the
    configured one; None otherwise."""
    identity = identity if identity is not None else plain_identity(config)
    dialect = dialect_for(identity) if identity else None
    current = str(getattr(config.digitizer, "dialect", ""))
    if identity is None or dialect is None or dialect == current:
        return None
    return (f"the instrument is a {identity.split(',')[0].strip()}: set [digitizer] dialect = \"{dialect}\" in "
            f"rig.toml (it is \"{current}\") and name its channels as that dialect does")
