"""What a calibration report shows, gathered from a shot file or a campaign run folder.

    report = report_for(path)                          # a shot file (.h5) or a run folder
    write_report(report, ["report.pdf", "report.html"])  # reports.writers
    write_run_report(run_folder, ["pdf", "html"])      # into <run folder>/report/report.<fmt>

A shot's analysis is rebuilt from its shot file (`/analysis` results and `/derived/record`)
with `ShotAnalysis.from_dict`; a shot whose analysis failed or is missing is reported with
its error. A shot with further sensors (the results' "sensors", e.g. response_2) gives one
entry per sensor (`shot_entries`), each analysed against the same reference; the first keeps
the shot's label. A run folder's shots are listed in the plan's order with their journal state,
read from the journal without taking the run lock (read-only SQLite), so a report can be
made while a campaign still runs.
"""

from __future__ import annotations

import sqlite3
from pathlib import Path
from typing import Any

from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.reduce import interferometer_text
from hopkinson.analysis.shot_analysis import ShotAnalysis
from hopkinson.analysis.sine_comparison import read_sine_calibration
from hopkinson.reports.data import CalibrationReport, ShotEntry
from hopkinson.reports.tables import nominal_sensitivity_text
from hopkinson.reports.writers import write_report
from hopkinson.rig.errors import ConfigError
from hopkinson.rig.plan import CampaignPlan
from hopkinson.rig.run_folder import PLAN_NAME, RunFolder, open_run_folder
from hopkinson.rig.shot_verdict import judge, settings_of
from hopkinson.rig.shotfile import Shot, ShotFileError, read_shot, sensor_records
from hopkinson.rig.shotfile_integrity import require_sound

REPORT_NAME = "report"


def _sensitivity(shot: Shot) -> float | None:
    settings = shot.meta.config.get("shot_settings", {}) if isinstance(shot.meta.config, dict) else {}
    value = settings.get("sensitivity_v_per_m_s2")
    if value is None:
        value = shot.meta.config.get("analysis", {}).get("sensitivity_v_per_m_s2")
    return float(value) if value is not None else None


def accelerometer_text(model: str, serial: str) -> str:
    return f"{model or '(model not given)'}, serial {serial or '(not given)'}"


def analysis_version_text(analyses: tuple[dict[str, Any], ...]) -> str:
    """'version 3 of 3 (2026-11-24T22:20Z, hopkinson 0.2.0); earlier versions kept in the file: 1
    (2026-03-01, hopkinson 0.1.0, failed), 2 (...)': which analysis the report shows."""
    def text(a: dict[str, Any]) -> str:
        return (f"{a['utc_time'][:16].replace('T', ' ')} UTC, hopkinson {a['software_version']}"
                + (", failed" if a["status"] == "failed" else ""))

    current = analyses[-1]
    out = f"version {current['version']} of {len(analyses)} ({text(current)})"
    if len(analyses) > 1:
        out += "; earlier versions kept in the file: " + "; ".join(f"{a['version']} ({text(a)})" for a in analyses[:-1])
    return out


def shot_identity(shot: Shot) -> dict[str, str]:
    """Who, what, when and with what rig a shot was fired, as report rows."""
    m = shot.meta
    settings = m.config.get("shot_settings", {})
    rows = {
        "Accelerometer": accelerometer_text(m.accelerometer_model, m.accelerometer_serial),
    }
    s = _sensitivity(shot)
    if s is not None:
        rows["Nominal sensitivity"] = f"{nominal_sensitivity_text(s)} (amplifier input)"
    rows["Shot"] = (m.shot_id or shot.path.stem) + (f" of campaign {m.campaign_id}" if m.campaign_id else "")
    rows["Fired (UTC)"] = m.utc_time
    rows["Operator"] = m.operator or "—"
    fire_p = settings.get("pressure_at_fire_bar")
    rows["Reservoir pressure, projectile"] = (f"{m.pressure_bar:g} bar set "
                                              + (f"({fire_p:.3f} bar at fire)" if fire_p is not None else "")
                                              + f", projectile No. {m.projectile}")
    level = settings.get("level_control")
    if isinstance(level, dict) and isinstance(level.get("target_peak_m_s2"), int | float):  # automatic level control
        rows["Target level"] = (f"{level['target_peak_m_s2'] / 9.80665:,.0f} g; pressure chosen from "
                                f"{level.get('basis', '?')} (predicted {level.get('predicted_peak_m_s2', 0) / 9.80665:,.0f} g)"
                                + (", held at the rig's pressure limit" if level.get("held_at_limit") else ""))
    if "amplifier_gain" in settings:
        rows["Bridge amplifier"] = (f"gain {settings['amplifier_gain']:g}, excitation "
                                    f"{settings.get('amplifier_excitation_v', float('nan')):g} V, low-pass "
                                    f"{settings.get('amplifier_lowpass_hz', 0) / 1e3:g} kHz"
                                    + (" — OVERLOADED during the shot" if settings.get("amplifier_overloaded") else ""))
    names = {"valve_controller": "Valve/vacuum controller", "digitizer": "Digitizer", "amplifier": "Amplifier"}
    for key, identity in m.instruments.items():
        rows[names.get(key, key)] = identity
    if m.config.get("path"):
        rows["Rig configuration"] = str(m.config["path"])
    rows["Shot file"] = f"{shot.path.name} (uuid {m.uuid})"
    rows["Software"] = f"hopkinson {m.software_version}"
    if shot.analyses:
        rows["Analysis"] = analysis_version_text(shot.analyses)
    if m.simulated_truth is not None:
        rows["Rig"] = "SIMULATED (the true accelerometer model is recorded with the shot)"
    return rows


def shot_entry(path: str | Path, state: str | None = None, label: str | None = None) -> ShotEntry:
    """A report entry from a shot file: identity, analysis (rebuilt), or the reason there is none."""
    path = Path(path)
    from hopkinson.rig.lab_record import kept_raw_sha256  # the lab's record only when asked

    require_sound(path, kept_raw_sha256(path))  # a damaged or changed file is refused, never plotted as if whole
    shot = read_shot(path, load_raw=False)
    truth = shot.meta.simulated_truth
    truth_modes = None
    if truth is not None:
        truth_modes = [dict(m) for m in truth.get("accelerometer", {}).get("modes", [])] or None
    analysis: ShotAnalysis | None = None
    error: str | None = None
    if shot.state == "analysed" and shot.results:
        try:
            analysis = ShotAnalysis.from_dict(shot.results, record=shot.record)
        except AnalysisError as exc:
            error = f"{path}: {exc}"
    elif shot.state == "analysis_failed":
        error = shot.analysis_error or "the analysis failed"
    else:
        error = "not analysed yet (raw data only)"
    identity = shot_identity(shot)
    reduction = (shot.results or {}).get("reduction")
    if isinstance(reduction, dict) and reduction.get("interferometer"):
        identity["Interferometer"] = interferometer_text(reduction)
    return ShotEntry(
        label=label or shot.meta.shot_id or path.stem,
        identity=identity,
        analysis=analysis,
        error=error,
        state=state or shot.state,
        truth_modes=truth_modes,
        nominal_sensitivity_v_per_m_s2=_sensitivity(shot),
        pressure_bar=shot.meta.pressure_bar,
        results=shot.results if analysis is not None else None,
        verdict=judge(shot.results, settings_of(shot), error).verdict,
    )


# role -> (what the report calls the sensor, its key in the simulated truth)
SENSORS = {"response_2": ("second sensor", "accelerometer_2")}


def sensor_label(label: str, role: str) -> str:
    """The label of a further sensor's entry: "<shot label>, second sensor (response_2)"."""
    return f"{label}, {SENSORS.get(role, ('sensor',))[0]} ({role})"


def shot_entries(path: str | Path, state: str | None = None, label: str | None = None) -> list[ShotEntry]:
    """The entries of a shot file: its first sensor's (`shot_entry`), then one per further
    sensor in its results, with that sensor's analysis, record, truth and nominal sensitivity."""
    first = shot_entry(path, state, label)
    if first.results is None or not first.results.get("sensors"):
        return [first]
    shot = read_shot(path, load_raw=False)
    records = sensor_records(shot)
    truth = shot.meta.simulated_truth or {}
    entries = [first]
    for role, results in first.results["sensors"].items():
        name, truth_key = SENSORS.get(role, ("sensor", ""))
        results = results if isinstance(results, dict) else {"error": "no results stored"}
        analysis: ShotAnalysis | None = None
        error = str(results["error"]) if "error" in results and "model" not in results else None
        if error is None:
            try:
                analysis = ShotAnalysis.from_dict(results, record=records.get(role))
            except AnalysisError as exc:
                error = f"{path}: {role}: {exc}"
        named = shot.meta.sensor_identities.get(role)
        what = accelerometer_text(named.get("model", ""), named.get("serial", "")) + ", " if named else ""
        identity = {"Accelerometer": f"{what}{name}, digitizer role {role}" if named
                    else f"{name.capitalize()}, digitizer role {role}",
                    **{k: v for k, v in first.identity.items() if k not in ("Accelerometer", "Nominal sensitivity")}}
        params = results.get("params") or {}
        scaled = (results.get("reduction") or {}).get("response_unit") == "m/s^2"
        nominal = float(params["sensitivity_v_per_m_s2"]) if scaled and "sensitivity_v_per_m_s2" in params else None
        if nominal is not None:
            identity = {"Accelerometer": identity.pop("Accelerometer"),
                        "Nominal sensitivity": f"{nominal_sensitivity_text(nominal)} "
                                               f"(conditioner input; conditioner gain {params.get('amp_gain', 1):g})",
                        **identity}
        modes = (truth.get(truth_key) or {}).get("modes")
        entries.append(ShotEntry(
            label=sensor_label(first.label, role), identity=identity, analysis=analysis, error=error,
            state=first.state, truth_modes=[dict(m) for m in modes] if modes else None,
            nominal_sensitivity_v_per_m_s2=nominal, pressure_bar=first.pressure_bar,
            results=results if analysis is not None else None,
        ))
    return entries


def shot_report(path: str | Path) -> CalibrationReport:
    """The report of one shot file: a section and pages per sensor."""
    entries = shot_entries(path)
    entry = entries[0]
    title = f"Calibration report: {entry.identity['Accelerometer']}, shot {entry.label}"
    return CalibrationReport(title=title, identity=dict(entry.identity), shots=entries, campaign=False)


def journal_states(run: RunFolder) -> dict[str, dict[str, Any]]:
    """shot id -> {"state", "fire_count"} read from the journal without its lock (read-only).

    Empty when there is no journal yet or it cannot be read (the shot files still tell).
    """
    path = run.journal_path
    if not path.exists():
        return {}
    try:
        conn = sqlite3.connect(f"file:{path}?mode=ro", uri=True, timeout=5.0)
        try:
            rows = conn.execute("SELECT id, state, fire_count FROM shots ORDER BY idx").fetchall()
        finally:
            conn.close()
    except sqlite3.Error:
        return {}
    return {r[0]: {"state": r[1], "fire_count": r[2]} for r in rows}


def run_report(run_folder: str | Path) -> CalibrationReport:
    """The campaign report of a run folder: every planned shot that has a shot file, in plan order."""
    run = open_run_folder(run_folder)
    plan: CampaignPlan = run.load_plan()
    states = journal_states(run)
    entries: list[ShotEntry] = []
    missing: list[str] = []
    unreadable: list[dict[str, str]] = []
    for planned in plan.shots:
        path = run.shot_path(planned.id)
        state = states.get(planned.id, {}).get("state")
        if not path.exists():
            missing.append(f"{planned.id} ({state or 'no file'})")
            continue
        try:
            entries.append(shot_entry(path, state=state, label=planned.id))
        except ShotFileError as exc:
            missing.append(f"{planned.id} (unreadable: {exc})")
            unreadable.append({"id": planned.id, "path": str(path), "reason": str(exc)})
    if not entries:
        raise ConfigError(f"{run.path}: no shot files yet; nothing to report")
    first = entries[0]
    identity = {
        "Campaign": f"{run.campaign_id} (plan {plan.name!r}{': ' + plan.description if plan.description else ''})",
        "Accelerometer": accelerometer_text(plan.accelerometer.model, plan.accelerometer.serial),
    }
    if "Nominal sensitivity" in first.identity:
        identity["Nominal sensitivity"] = first.identity["Nominal sensitivity"]
    identity["Operator"] = plan.operator
    identity["Shots"] = (f"{len(plan.shots)} planned, {len(entries)} with a shot file, "
                         f"{sum(1 for e in entries if e.analysis is not None)} analysed")
    for key in ("Valve/vacuum controller", "Digitizer", "Amplifier", "Bridge amplifier", "Rig configuration",
                "Software", "Rig"):
        if key in first.identity:
            identity[key] = first.identity[key]
    identity["Fired (UTC)"] = f"{entries[0].identity['Fired (UTC)']} … {entries[-1].identity['Fired (UTC)']}"
    notes = [f"Shots without a shot file: {', '.join(missing)}."] if missing else []
    sine = None
    sine_path = getattr(plan.accelerometer, "sine_calibration", None)
    if sine_path:
        try:
            sine = read_sine_calibration(sine_path)
            identity["Sine calibration"] = f"{sine_path} ({sine.frequency_hz.size} points)"
        except AnalysisError as exc:  # the shots are still reported; the note says why not compared
            notes.append(f"The plan's sine calibration is not compared: {exc}")
    title = f"Calibration report: {identity['Accelerometer']}, campaign {run.campaign_id}"
    return CalibrationReport(title=title, identity=identity, shots=entries, campaign=True, notes=notes,
                             sine_calibration=sine, unreadable=unreadable)


def report_for(path: str | Path) -> CalibrationReport:
    """A shot file's report, or a run folder's campaign report."""
    path = Path(path)
    if path.is_dir():
        if not (path / PLAN_NAME).is_file():
            raise ConfigError(f"{path}: not a campaign run folder (no {PLAN_NAME}) and not a shot file")
        return run_report(path)
    if not path.exists():
        raise ConfigError(f"{path}: no such shot file or run folder")
    return shot_report(path)


def write_run_report(run_folder: str | Path, formats: list[str] | tuple[str, ...] = ("pdf", "html"),
                     report: CalibrationReport | None = None) -> list[Path]:
    """Write `<run folder>/report/report.<fmt>` for each format (from `report`, or gathered
    from the run folder); returns the paths."""
    run = open_run_folder(run_folder)
    report = report if report is not None else run_report(run.path)
    return write_report(report, [run.report_dir / f"{REPORT_NAME}.{fmt}" for fmt in formats])
