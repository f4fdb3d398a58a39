"""Where the configuration files are: the shipped defaults (package data) and the lab's own.

Light on purpose (no drivers, no TOML parsing): the command-line parser uses it.

- The shipped configurations (`config/` in the repository, `hopkinson.config` when installed):
  `rig.toml` (a documented real-rig template), `rig-sim.toml` (the simulated rig), `sim.toml`
  (the simulator) and `campaigns/`.
- The lab's own `rig.toml` is given with `--config`, or found in the per-user config directory:
  `$HOPKINSON_CONFIG_DIR`, else `$XDG_CONFIG_HOME/hopkinson`, else `~/.config/hopkinson`.
"""

from __future__ import annotations

import os
from importlib.resources import files
from pathlib import Path

SHIPPED_CONFIG_DIR = Path(str(files("hopkinson.config")))
SHIPPED_RIG_CONFIG = SHIPPED_CONFIG_DIR / "rig.toml"
DEFAULT_SIM_CONFIG = SHIPPED_CONFIG_DIR / "sim.toml"
DEFAULT_SIM_RIG_CONFIG = SHIPPED_CONFIG_DIR / "rig-sim.toml"  # rig.toml's variant for the simulated rig
CAMPAIGNS_DIR = SHIPPED_CONFIG_DIR / "campaigns"


def user_config_dir() -> Path:
    """The per-user configuration folder (it need not exist)."""
    explicit = os.environ.get("HOPKINSON_CONFIG_DIR")
    if explicit:
        return Path(explicit)
    base = os.environ.get("XDG_CONFIG_HOME") or str(Path.home() / ".config")
    return Path(base) / "hopkinson"


def default_rig_config() -> Path:
    """The lab's `rig.toml` in the per-user config folder when there is one, else the shipped one."""
    own = user_config_dir() / "rig.toml"
    return own if own.is_file() else SHIPPED_RIG_CONFIG
