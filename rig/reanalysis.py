"""Re-analysing stored shots with today's method (issue 18): `hopkinson analyse`, and how a lab
re-runs its archive after the method improves.

A shot is re-analysed from its raw channels with the options it was first analysed with (the
`params` stored with its first analysis, version 1: amplifier gain read back at the shot, nominal sensitivity,
analysis rate, model orders, the reference chain ...), changed only where the caller asks
(`overrides`, e.g. max_order). A shot that never had an analysis stored (a full disk, an
interrupted analysis) gets them from its configuration snapshot. The new analysis is written
beside the old ones (rig.shotfile: /analysis is the new version, /analyses/<n> the earlier
ones); the raw data is never rewritten.
"""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Any

from hopkinson.analysis.params import AnalysisParams
from hopkinson.rig.config import RigConfig, load_rig_config
from hopkinson.rig.errors import ConfigError
from hopkinson.rig.shot import (
    AnalyseFn,
    RecordedAnalysis,
    ShotRequest,
    analyse_and_record,
    analyse_raw,
    analysis_params,
    shot_analyser,
)
from hopkinson.rig.shotfile import Shot, ShotFileError, analysis_results, read_shot, require_sound

SNAPSHOT_EXTRAS = ("path", "shot_settings")  # keys of a shot's config snapshot that rig.toml has not


def snapshot_config(shot: Shot) -> RigConfig | None:
    """The rig configuration the shot was fired with (from its snapshot), or None when the
    snapshot does not load as a configuration today."""
    import tomli_w

    table = {k: v for k, v in shot.meta.config.items() if k not in SNAPSHOT_EXTRAS}
    try:
        with tempfile.TemporaryDirectory() as folder:
            path = Path(folder) / "rig.toml"
            path.write_text(tomli_w.dumps(table), encoding="utf-8")
            return load_rig_config(path)
    except (ConfigError, TypeError, ValueError, OSError):
        return None


def stored_params(shot: Shot, config: RigConfig | None) -> AnalysisParams:
    """The analysis options the shot was first analysed with (a later re-analysis' changed
    options are not inherited), or (never analysed) its rig's."""
    first = analysis_results(shot.path, shot.analyses[0]["version"]) if shot.analyses else None
    params = (first or {}).get("params")
    if isinstance(params, dict):
        return AnalysisParams.from_dict(params, ignore_unknown=True)
    if config is None:
        raise ShotFileError(f"{shot.path}: no stored analysis options and no usable configuration snapshot: "
                            "it cannot be re-analysed as it was")
    request = ShotRequest(pressure_bar=shot.meta.pressure_bar, projectile=shot.meta.projectile,
                          operator=shot.meta.operator, out_dir=shot.path.parent)
    return analysis_params(request, config, dict(shot.meta.config.get("shot_settings", {})))


def reanalyse(path: str | Path, overrides: dict[str, Any] | None = None) -> RecordedAnalysis:
    """Analyse a stored shot again with today's method and store it as a new analysis version."""
    path = Path(path)
    require_sound(path)  # a damaged raw channel is never analysed again as if it were whole
    shot = read_shot(path)
    if shot.raw is None:
        raise ShotFileError(f"{path}: holds no raw data")
    config = snapshot_config(shot)
    params = stored_params(shot, config)
    if overrides:
        params = AnalysisParams.from_dict({**params.to_dict(), **overrides}, ignore_unknown=True)
    analyse: AnalyseFn = shot_analyser(config) if config is not None else analyse_raw
    settings = shot.meta.config.get("shot_settings", {})
    return analyse_and_record(path, shot.raw, params, analyse,
                              amplifier_overloaded=bool(settings.get("amplifier_overloaded")))
