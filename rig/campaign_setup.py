"""Before a campaign fires: its run folder (new, or the one to resume), the authorisation to fire,
and the whole plan checked against the rig; `shot_request` turns a planned shot into the
sequencer's request. The runner is rig/campaign.py.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import TYPE_CHECKING

from hopkinson.analysis.options import AnalysisOverrides
from hopkinson.rig.errors import ConfigError
from hopkinson.rig.level_control import (
    LevelChoice,
    LevelPoint,
    choose_pressure,
    needed_pressure_bar,
)
from hopkinson.rig.plan import CampaignPlan, PlannedShot, load_plan
from hopkinson.rig.run_folder import PLAN_NAME, RunFolder, create_run_folder, open_run_folder
from hopkinson.rig.shot import ShotRequest, sensor_stated

if TYPE_CHECKING:
    from hopkinson.rig.config import RigConfig

DEFAULT_RUNS_DIR = Path("runs")


class CampaignNotAuthorised(ConfigError):
    """Neither the plan (authorise_firing = true) nor the operator (--yes) authorised firing."""


def check_authorisation(plan: CampaignPlan, yes: bool) -> None:
    """Raise CampaignNotAuthorised (exit code 2, nothing fired) unless firing is authorised."""
    if not (plan.authorise_firing or yes):
        raise CampaignNotAuthorised(
            f"{plan.path}: firing is not authorised: set authorise_firing = true in the plan or give "
            "--yes; nothing was fired"
        )


def prepare_run(plan_path: str | Path, out: str | Path | None = None, resume: bool = False,
                runs_dir: str | Path = DEFAULT_RUNS_DIR) -> tuple[RunFolder, CampaignPlan]:
    """The run folder to use and the validated plan.

    New run: `out` is the run folder to create (it must not exist yet, or be an empty
    folder); without `out`, `<runs_dir>/<plan name>-<UTC time>`. Resume: `out` is the run folder
    to continue; without `out`, the newest `<runs_dir>/<plan name>-*` folder. The plan must
    be the one the run started with (the journal checks it when it opens).
    """
    plan = load_plan(plan_path)
    if out is not None:
        folder = Path(out)
        has_plan = (folder / PLAN_NAME).is_file()
        if resume:
            if has_plan:
                return open_run_folder(folder), plan
            if not folder.is_dir():
                raise ConfigError(f"{folder}: no such run folder to resume")
            if any(p.name != "run.lock" for p in _files(folder)):
                raise ConfigError(f"{folder}: not a campaign run folder (no {PLAN_NAME})")
            # A run that died while creating its folder: start it afresh in the same place.
        elif has_plan:
            raise ConfigError(f"{folder}: this run folder exists; give --resume to continue it")
        elif folder.is_dir() and any(folder.iterdir()):
            raise ConfigError(f"{folder}: the folder exists and is not empty; choose a new --out")
        if folder.is_dir():
            _remove_empty_tree(folder)
        return create_run_folder(plan_path, folder.parent, folder.name), plan
    runs = Path(runs_dir)
    if resume:
        candidates = sorted(p for p in runs.glob(f"{plan.name}-*") if (p / PLAN_NAME).is_file())
        if not candidates:
            raise ConfigError(f"{runs}: no run folder of plan {plan.name!r} to resume (give --out RUN_FOLDER)")
        return open_run_folder(max(candidates, key=lambda p: p.stat().st_mtime)), plan
    return create_run_folder(plan_path, runs), plan


def _files(folder: Path) -> list[Path]:
    return [p for p in folder.rglob("*") if p.is_file()]


def _remove_empty_tree(folder: Path) -> None:
    """Remove a folder holding nothing but empty folders (and a stale lock file)."""
    for path in sorted(folder.rglob("*"), key=lambda p: len(p.parts), reverse=True):
        if path.is_dir():
            path.rmdir()
        else:
            path.unlink()
    folder.rmdir()



def shot_request(plan: CampaignPlan, shot: PlannedShot, run: RunFolder, level: LevelChoice | None = None,
                 pressure_bar: float | None = None, campaign_uuid: str | None = None) -> ShotRequest:
    """The sequencer's request for a planned shot: file `shots/<id>.h5`, the plan's settings
    (for a target level, the pressure `level` chose, or the `pressure_bar` it was fired at).

    `confirm_timeout_s` 0: the runner only ever fires with the authorisation already given.
    """
    sensor = plan.accelerometer
    pressure = level.pressure_bar if level is not None else pressure_bar if pressure_bar is not None else shot.pressure_bar
    assert pressure is not None, f"{shot.id}: a target level needs its pressure chosen"
    return ShotRequest(
        pressure_bar=pressure, projectile=shot.projectile, operator=plan.operator,
        accelerometer_model=sensor.model, accelerometer_serial=sensor.serial,
        sensor_identities=plan.sensor_identities(),
        analysis=AnalysisOverrides(
            **shot.analysis.analysis_options(), sensitivity_v_per_m_s2=sensor.sensitivity_v_per_m_s2,
            sine_calibration=sensor.sine_calibration, **sensor_stated(sensor)),
        out_dir=run.shots_dir, shot_name=shot.id, campaign_id=run.campaign_id, campaign_uuid=campaign_uuid,
        shot_id=shot.id,
        shot_index=shot.index, confirm_timeout_s=0.0, level=level.to_dict() if level is not None else None,
        sensitivity_unit=sensor.sensitivity_unit, tolerance_percent=sensor.tolerance_percent,
    )


def check_plan(plan: CampaignPlan, config: RigConfig, history: list[LevelPoint] | None = None) -> None:
    """The whole plan against the rig, before anything moves: every shot's request (pressure
    within the rig's limits, projectile, every analysis option) is checked, and a target level
    the bar model (corrected by the rig's `history`) says needs more than the rig's
    maximum pressure is refused; ConfigError (exit 2) names the plan, the entry and the reason."""
    limits = config.limits
    rig = config.bar.rig()
    for shot in plan.shots:
        level = None
        if shot.target_peak_m_s2 is not None:
            try:
                level = needed_pressure_bar(shot.target_peak_m_s2, shot.projectile, history or (), rig)
            except ValueError as exc:  # e.g. a projectile the rig's [bar] does not describe
                raise ConfigError(f"{plan.path}: shots[{shot.entry}] ({shot.id}): a target level needs the bar model: "
                                  f"{exc} ({config.path or 'configuration'} [bar]); nothing was fired") from None
            if level.pressure_bar > limits.max_pressure_bar:
                raise ConfigError(
                    f"{plan.path}: shots[{shot.entry}] ({shot.id}): target peak {shot.target_peak_m_s2:.4g} m/s² "
                    f"({shot.target_peak_m_s2 / 9.80665:.4g} g) needs {level.pressure_bar:.3g} bar with projectile "
                    f"No. {shot.projectile} (bar model, {level.basis}), above the rig's maximum "
                    f"{limits.max_pressure_bar:g} bar ({config.path or 'configuration'} [limits]); nothing was fired")
            level = choose_pressure(shot.target_peak_m_s2, shot.projectile, history or (),
                                    min_pressure_bar=limits.min_pressure_bar, max_pressure_bar=limits.max_pressure_bar,
                                    rig=rig)
        request = dataclasses.replace(shot_request(plan, shot, RunFolder(Path(".")), level), out_dir=Path("."))
        try:
            request.check(config)
        except ConfigError as exc:
            raise ConfigError(f"{plan.path}: shots[{shot.entry}] ({shot.id}): {exc}") from None
