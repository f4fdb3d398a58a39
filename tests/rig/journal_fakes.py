"""The fake digitizer's records and shot metadata of tests/rig/test_journal.py, in a module of
their own: the kill tests' child processes import them without pytest (a third of each child's
start-up)."""

from __future__ import annotations

import numpy as np

from hopkinson.rig.shotfile import RawShot, ShotMeta


def raw_for(index: int) -> RawShot:
    """The fake digitizer's record of shot `index` (known, so the file can be checked)."""
    codes = (np.arange(256) * (index + 1) % 30000).astype(np.int16)
    return RawShot({"doppler": (codes, 1e-3, 0.0), "response": (-codes, 2e-3, 0.1)}, 1e-8, 10)


def meta_for(shot_id: str, uuid: str, campaign: str, pressure: float) -> ShotMeta:
    return ShotMeta("op", "M", "S", pressure, 3, shot_id=shot_id, campaign_id=campaign, uuid=uuid)
