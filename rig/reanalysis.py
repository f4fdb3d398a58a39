"""Re-analysing stored shots with today's method: `hopkinson analyse`, and how a lab
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

import dataclasses
import os
import tempfile
import time
from collections import Counter, defaultdict
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hopkinson.analysis.options import AnalysisOptions, AnalysisOverrides
from hopkinson.rig.config import RigConfig, load_rig_config
from hopkinson.rig.errors import ConfigError
from hopkinson.rig.plan import load_plan
from hopkinson.rig.run_folder import PLAN_NAME, SHOTS_DIR, RunFolder, open_run_folder
from hopkinson.rig.shot import (
    SENSOR_STATED,
    AnalyseFn,
    RecordedAnalysis,
    ShotRequest,
    analyse_and_record,
    analyse_raw,
    analysis_params,
    shot_analyser,
)
from hopkinson.rig.shotfile import Shot, ShotFileError, analysis_results, read_shot
from hopkinson.rig.shotfile_integrity import require_sound

SNAPSHOT_EXTRAS = ("path", "shot_settings")
SHOT_SUFFIX = ".h5"  # keys of a shot's config snapshot that rig.toml has not


def snapshot_config(shot: Shot) -> RigConfig | None:
    """The rig configuration the shot was fired with (from its snapshot), or None when the
    snapshot does not load as a configuration today."""
    import tomli_w

    table = _without_none({k: v for k, v in shot.meta.config.items() if k not in SNAPSHOT_EXTRAS})
    try:
        with tempfile.TemporaryDirectory() as folder:
            path = Path(folder) / "rig.toml"
            path.write_text(tomli_w.dumps(table), encoding="utf-8")
            return load_rig_config(path)
    except (ConfigError, TypeError, ValueError, OSError):
        return None


def _without_none(value: Any) -> Any:
    """The snapshot with its unset keys (None: TOML has no null) left out, as the file had them."""
    if isinstance(value, dict):
        return {k: _without_none(v) for k, v in value.items() if v is not None}
    if isinstance(value, list | tuple):
        return [_without_none(v) for v in value]
    return value


def stored_params(shot: Shot, config: RigConfig | None) -> AnalysisOptions:
    """The analysis options the shot was first analysed with (a later re-analysis' changed
    options are not inherited), or (never analysed) its rig's with the options its request asked
    and its sensor's sensitivity, as the shot file's settings recorded them."""
    first = analysis_results(shot.path, shot.analyses[0]["version"]) if shot.analyses else None
    params = (first or {}).get("params")
    if isinstance(params, dict):
        return AnalysisOptions.from_dict(params, ignore_unknown=True)
    if config is None:
        raise ShotFileError(f"{shot.path}: no stored analysis options and no usable configuration snapshot: "
                            "it cannot be re-analysed as it was")
    settings = dict(shot.meta.config.get("shot_settings", {}))
    asked = dict(settings.get("analysis_options") or {})
    for sensor_own in ("sensitivity_v_per_m_s2", *SENSOR_STATED):  # recorded under their own keys
        if settings.get(sensor_own) is not None:
            asked[sensor_own] = settings[sensor_own]
    known = {f.name for f in dataclasses.fields(AnalysisOverrides)}
    request = ShotRequest(pressure_bar=shot.meta.pressure_bar, projectile=shot.meta.projectile,
                          operator=shot.meta.operator, out_dir=shot.path.parent,
                          analysis=AnalysisOverrides(**{k: v for k, v in asked.items() if k in known}))
    return analysis_params(request, config, settings)


def reanalyse(path: str | Path, overrides: dict[str, Any] | None = None) -> RecordedAnalysis:
    """Analyse a stored shot again with today's method and store it as a new analysis version."""
    path = Path(path)
    from hopkinson.rig.lab_record import kept_raw_sha256  # the lab's record only when asked

    # a damaged raw channel is never analysed again as if it were whole; the raw SHA-256 the
    # lab's record kept is checked too (channels and their written SHA-256 both rewritten)
    require_sound(path, kept_raw_sha256(path))
    shot = read_shot(path)
    if shot.raw is None:
        raise ShotFileError(f"{path}: holds no raw data")
    config = snapshot_config(shot)
    params = stored_params(shot, config)
    if overrides:
        params = AnalysisOptions.from_dict({**params.to_dict(), **overrides}, ignore_unknown=True)
    analyse: AnalyseFn = shot_analyser(config) if config is not None else analyse_raw
    settings = shot.meta.config.get("shot_settings", {})
    return analyse_and_record(path, shot.raw, params, analyse,
                              amplifier_overloaded=bool(settings.get("amplifier_overloaded")))


# ------------------------------------------------------------------------ many shots at once
@dataclass(frozen=True)
class Target:
    """A shot file to analyse again, and the run folder (with the shot's id) whose journal follows."""

    path: Path
    run_folder: Path | None = None
    shot_id: str | None = None


def find_targets(sources: Sequence[Path]) -> list[Target]:
    """The shot files `sources` name, each once: a shot file itself; a campaign run folder (its
    plan copy beside it): its plan's shot files; any other folder: every campaign run folder and
    every other `*.h5` file in it or below (hidden names skipped, symlinked folders not
    followed). A shot file in a run folder's `shots/` named by its plan keeps its run folder,
    however it was named. ConfigError (bad input, before anything moves) for a source that does
    not exist, a run folder named alone with no shot file yet, or a folder with none."""
    plans: dict[Path, frozenset[str]] = {}
    found: list[Target] = []
    for source in sources:
        if source.is_file():
            found.append(_target_of_file(source, plans))
        elif not source.is_dir():
            raise ConfigError(f"{source}: no such shot file or run folder")
        elif _is_run_folder(source):
            found += _run_targets(source, plans, required=True)
        else:
            tree = _tree_targets(source, plans)
            if not tree:
                raise ConfigError(f"{source}: holds no shot files (*.h5) and is not a campaign run folder "
                                  f"(no {PLAN_NAME})")
            found += tree
    seen: set[Path] = set()
    unique = []
    for target in found:
        key = target.path.resolve()
        if key not in seen:
            seen.add(key)
            unique.append(target)
    return unique


def _is_run_folder(folder: Path) -> bool:
    return (folder / PLAN_NAME).is_file()


def _plan_shot_ids(run_folder: Path, plans: dict[Path, frozenset[str]]) -> frozenset[str]:
    """The shot ids of a run folder's plan copy (none when it does not load)."""
    if run_folder not in plans:
        try:
            plans[run_folder] = frozenset(s.id for s in load_plan(run_folder / PLAN_NAME).shots)
        except (ConfigError, OSError, ValueError):
            plans[run_folder] = frozenset()
    return plans[run_folder]


def _target_of_file(path: Path, plans: dict[Path, frozenset[str]]) -> Target:
    run = path.parent.parent
    if path.parent.name == SHOTS_DIR and _is_run_folder(run) and path.stem in _plan_shot_ids(run, plans):
        return Target(path, run, path.stem)
    return Target(path)


def _run_targets(run: Path, plans: dict[Path, frozenset[str]], *, required: bool) -> list[Target]:
    ids = [s.id for s in open_run_folder(run).load_plan().shots]
    plans[run] = frozenset(ids)
    found = [Target(run / SHOTS_DIR / f"{i}.h5", run, i) for i in ids if (run / SHOTS_DIR / f"{i}.h5").exists()]
    if required and not found:
        raise ConfigError(f"{run}: no shot files yet; nothing to analyse")
    return found


def _tree_targets(root: Path, plans: dict[Path, frozenset[str]]) -> list[Target]:
    found: list[Target] = []
    for folder, subfolders, files in os.walk(root):
        here = Path(folder)
        if here != root and _is_run_folder(here):
            subfolders[:] = []
            found += _run_targets(here, plans, required=False)
            continue
        subfolders[:] = sorted(d for d in subfolders if not d.startswith("."))
        found += [_target_of_file(here / name, plans) for name in sorted(files)
                  if name.endswith(SHOT_SUFFIX) and not name.startswith(".")]
    return found


def reanalysis_row(path: Path, overrides: dict[str, Any]) -> dict[str, Any]:
    """Analyse one shot file again and store it (`reanalyse`), as one row of `hopkinson analyse`:
    path, version, ok, error, key_figures, summary, cpu_s (the CPU seconds it took), and
    `journal` (what its run's journal records, or None when nothing was stored). A bad file is a
    failed row, never an exception: many shots are analysed in one go, in worker processes."""
    from hopkinson.analysis.key_figures import KeyFigures
    from hopkinson.rig.campaign_results import result_info, result_line
    from hopkinson.rig.shot import analysis_error_text
    from hopkinson.rig.shot_verdict import judge, settings_of

    row: dict[str, Any] = {"path": str(path), "version": None, "ok": False, "error": None, "key_figures": None,
                           "summary": None, "verdict": None, "cpu_s": None, "journal": None}
    started = time.process_time()
    try:
        recorded = reanalyse(path, overrides)
        shot = read_shot(path, load_raw=False)  # once: the version stored and the settings the verdict reads
        if recorded.stored:
            row["version"] = shot.analyses[-1]["version"]
    except (ShotFileError, ConfigError) as exc:
        row["error"] = str(exc)
        return row
    except OSError as exc:
        row["error"] = f"{path}: {exc.strerror or exc}"
        return row
    except Exception as exc:  # noqa: BLE001 - one bad file must not stop the rest
        row["error"] = f"{path}: {analysis_error_text(exc)}"
        return row
    finally:
        row["cpu_s"] = time.process_time() - started
    row["ok"] = recorded.error is None
    row["error"] = recorded.error
    if recorded.results is not None:
        row["key_figures"] = KeyFigures.from_results(recorded.results).to_dict()
        row["summary"] = result_line(recorded.results)
    row["verdict"] = judge(recorded.results, settings_of(shot), recorded.error).verdict.to_dict()
    if recorded.stored:
        row["journal"] = {"error": recorded.error, "info": result_info(recorded.results)}
    return row


class RunJournals:
    """The journals of the run folders among the targets follow their re-analysed shots. A
    journal is opened once its run's shots are all done: opening it clears the run folder's
    unfinished writes, which a shot still being analysed would be."""

    def __init__(self, targets: Sequence[Target]) -> None:
        self._left = Counter(t.run_folder for t in targets if t.run_folder is not None)
        self._done: dict[Path, list[tuple[str, dict[str, Any]]]] = defaultdict(list)
        self.problems: list[str] = []

    def done(self, target: Target, row: dict[str, Any]) -> None:
        """One target's row is in; its run's journal is written when it was the run's last."""
        run = target.run_folder
        if run is None or target.shot_id is None:
            return
        if row.get("journal") is not None:
            self._done[run].append((target.shot_id, row["journal"]))
        self._left[run] -= 1
        if self._left[run] == 0:
            self._write(run)

    def close(self) -> list[str]:
        """Write what is left (after an interruption: the shots done so far); the problems."""
        for run in list(self._done):
            self._write(run)
        return self.problems

    def check_free(self) -> None:
        """ConfigError (bad input, before anything moves) when another process holds a run
        folder: a campaign running there."""
        for run in self._left:
            RunFolder(run).lock().release()

    def _write(self, run: Path) -> None:
        from hopkinson.rig.journal import Journal, JournalError, ShotState

        shots = self._done.pop(run, [])
        if not shots:
            return
        try:
            with Journal.open(run) as journal:
                for shot_id, outcome in shots:
                    state = journal.status(shot_id).state
                    if state not in (ShotState.RECORDED, ShotState.ANALYSED, ShotState.ANALYSIS_FAILED):
                        continue
                    if outcome["error"] is None:
                        journal.mark(shot_id, ShotState.ANALYSED, redo=False, **outcome["info"])
                    else:
                        journal.mark(shot_id, ShotState.ANALYSIS_FAILED, error=outcome["error"], redo=False)
        except (JournalError, ConfigError) as exc:
            self.problems.append(f"{run}: the journal was not updated ({exc})")
