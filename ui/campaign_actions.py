"""What the Campaign tab does with a run folder besides firing, each a plain function the tab runs
on its background worker: re-analyse a shot (rig.reanalysis, then the journal), write the
campaign's report (rig.report_data), issue its certificate (the lab's record, as `hopkinson lab
certificate RUN_FOLDER`), read a shot's row of the table (rig.shot_verdict), and say how a campaign
ended."""

from __future__ import annotations

import getpass
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hopkinson.rig.config import RigConfig
from hopkinson.rig.journal import DONE_STATES, Journal, ShotState
from hopkinson.rig.plan import CampaignPlan
from hopkinson.rig.run_folder import RunFolder
from hopkinson.rig.shot_verdict import ShotJudgement, shot_judgement

CERTIFICATE_NAME = "certificate"
_DONE = frozenset(state.value for state in DONE_STATES)


@dataclass(frozen=True)
class ShotRow:
    """What the table shows of one shot file: the pressure it was fired at, its judgement (the
    verdict, the sensitivity in the sensor's unit), and why its analysis failed."""

    pressure_bar: float
    judgement: ShotJudgement
    analysis_error: str | None


def read_shot_row(path: Path) -> ShotRow:
    """A shot file's row (ShotFileError when it cannot be read)."""
    from hopkinson.rig.shotfile import read_shot

    shot = read_shot(path, load_raw=False)
    return ShotRow(shot.meta.pressure_bar, shot_judgement(shot), shot.analysis_error)


def reanalyse_shot(run: RunFolder, plan: CampaignPlan, shot_id: str) -> tuple[str, str | None]:
    """Analyse a campaign shot again from its raw data (a new analysis version in its file, as
    `hopkinson analyse`) and record the outcome in the run's journal: (journal state, error)."""
    from hopkinson.rig.campaign_results import result_info
    from hopkinson.rig.reanalysis import reanalyse

    recorded = reanalyse(run.shot_path(shot_id))
    with Journal.open(run, plan) as journal:
        if recorded.error is None:
            journal.mark(shot_id, ShotState.ANALYSED, **result_info(recorded.results))
            return ShotState.ANALYSED.value, None
        journal.mark(shot_id, ShotState.ANALYSIS_FAILED, error=recorded.error, redo=recorded.to_redo)
        return ShotState.ANALYSIS_FAILED.value, recorded.error


def write_campaign_report(run: RunFolder, formats: tuple[str, ...] = ("pdf", "html")) -> list[Path]:
    """The campaign's report into the run folder's report folder (as `hopkinson report RUN_FOLDER`)."""
    from hopkinson.rig.report_data import write_run_report

    return write_run_report(run.path, formats)


def issue_certificate(config: RigConfig, run: RunFolder, authorised_by: str, specimen: bool,
                      formats: tuple[str, ...] = ("pdf", "html")) -> tuple[str, list[Path]]:
    """Record the run's shots in the lab's record and issue its numbered certificate (in
    `formats`) in the run folder's report folder, as `hopkinson lab certificate RUN_FOLDER -o …
    --authorised-by NAME [--specimen]` (lab.issuing: the number only with its documents):
    (number, files). LabError says why not (not a signatory, a shot refused, the reference
    chain, simulated shots without `specimen`)."""
    from hopkinson.lab.certificate import Request, certificate_content, write_documents
    from hopkinson.lab.issuing import issue
    from hopkinson.lab.repository import open_repository
    from hopkinson.rig.lab_record import campaign_ref, lab_identity
    from hopkinson.rig.shotfile import software_version

    identity = lab_identity(config)
    identity.role_of(authorised_by, specimen)  # refused before anything is imported
    request = Request(authorised_by, software_version(), specimen=specimen)
    run.report_dir.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []

    def documents(content: dict[str, Any]) -> list[Path]:
        paths = [run.report_dir / f"{CERTIFICATE_NAME}-{content['number']}.{suffix}" for suffix in formats]
        written.extend(write_documents(content, paths, identity))
        return written

    with open_repository(config.database.url) as repo:
        ref = campaign_ref(repo, run.path, getpass.getuser())
        issued = issue(repo, campaign=ref, prefix=identity.certificate_prefix, authorised_by=authorised_by,
                       specimen=specimen, content=lambda uow, campaign: certificate_content(uow, campaign, identity,
                                                                                            request),
                       documents=documents)
    return issued.number, written


def campaign_end_message(outcome: Any, failure: str = "") -> tuple[str, str]:
    """(banner level, text) for how a campaign ended, written for the panel (no command lines)."""
    if outcome is None:
        return "error", failure or "The campaign was not run."
    summary = outcome.summary
    counts = summary.get("by_state", {})
    done = sum(counts.get(s, 0) for s in _DONE)
    total = summary.get("total", 0)
    failed = counts.get("ANALYSIS_FAILED", 0)
    if outcome.complete:  # exit 0, or 4 when some analyses failed (rig.errors, docs/exit-codes.md)
        note = f" ({failed} with a failed analysis: re-analyse them from the table)" if failed else ""
        return "ok", (f"Campaign complete: {done} of {total} shots done{note}. Its report and certificate: the "
                      "buttons under the Campaign table.")
    last = outcome.last_shot
    if last is not None and last.final_state == "FAULT":
        return "error", f"Campaign stopped by a FAULT: {last.error}. Check the rig by hand before anything else."
    if summary.get("needs_decision"):
        ids = ", ".join(summary["needs_decision"])
        return "error", (f"Campaign stopped: {ids} may have been fired without a record; an operator decides whether "
                         "to retry or skip it (hopkinson campaign decide) before it resumes.")
    if "paused" in outcome.message:
        return "warning", f"Campaign paused: {done} of {total} shots done. Press Resume in the Campaign tab to go on."
    why = last.error if last is not None and last.error else outcome.message.split("; ")[1] \
        if "; " in outcome.message else "stopped"
    return "warning", f"Campaign stopped ({why}): {done} of {total} shots done. Resume continues it."


def journal_summary(run: RunFolder, plan: CampaignPlan) -> dict[str, Any]:
    """The journal's summary of a run folder (opens it briefly: takes and releases the run lock)."""
    journal = Journal.open(run, plan)
    try:
        return journal.summary()
    finally:
        journal.close()
