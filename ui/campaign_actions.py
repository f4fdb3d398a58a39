"""What the Campaign tab does with a run folder besides firing, each a plain function the tab runs
on its background worker: re-analyse a shot (rig.reanalysis, then the journal), write the
campaign's report (rig.report_data), issue its certificate (the lab's record, as `hopkinson lab
certificate RUN_FOLDER`), and read a shot's row of the table (rig.shot_verdict)."""

from __future__ import annotations

import getpass
from dataclasses import dataclass
from pathlib import Path

from hopkinson.rig.config import RigConfig
from hopkinson.rig.journal import Journal, ShotState
from hopkinson.rig.plan import CampaignPlan
from hopkinson.rig.run_folder import RunFolder
from hopkinson.rig.shot_verdict import ShotJudgement, shot_judgement

CERTIFICATE_NAME = "certificate"


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
    from hopkinson.rig.campaign import result_info
    from hopkinson.rig.reanalysis import reanalyse

    recorded = reanalyse(run.shot_path(shot_id))
    with Journal.open(run, plan) as journal:
        if recorded.error is None:
            journal.mark(shot_id, ShotState.ANALYSED, **result_info(recorded.results))
            return ShotState.ANALYSED.value, None
        journal.mark(shot_id, ShotState.ANALYSIS_FAILED, error=recorded.error, redo=recorded.to_redo)
        return ShotState.ANALYSIS_FAILED.value, recorded.error


def write_campaign_report(run: RunFolder) -> list[Path]:
    """The campaign's report, PDF and HTML, into the run folder's report folder (as `hopkinson
    report RUN_FOLDER`)."""
    from hopkinson.rig.report_data import write_run_report

    return write_run_report(run.path)


def issue_certificate(config: RigConfig, run: RunFolder, authorised_by: str, specimen: bool) -> tuple[str, list[Path]]:
    """Record the run's shots in the lab's record and issue its numbered certificate, PDF and
    HTML in the run folder's report folder (as `hopkinson lab certificate RUN_FOLDER -o …
    --authorised-by NAME [--specimen]`): (number, files). LabError says why not (a shot refused,
    the reference chain overdue, simulated shots without `specimen`)."""
    from hopkinson.lab.certificate import (
        LabIdentity,
        certificate_content,
        with_number,
        write_certificate,
    )
    from hopkinson.lab.errors import LabError
    from hopkinson.lab.repository import open_repository
    from hopkinson.rig.lab_record import import_shots
    from hopkinson.rig.shotfile import software_version

    lab = config.lab
    identity = LabIdentity(lab.name, lab.address, lab.accreditation, lab.certificate_prefix, lab.decision_rule)
    campaign = run.path.resolve().name
    with open_repository(config.database.url) as repo:
        refused = [o for _p, o in import_shots(repo, [run.path], getpass.getuser()) if o.startswith("refused")]
        if refused:
            raise LabError(refused[0].removeprefix("refused: "))
        content = certificate_content(repo, campaign, identity, authorised_by=authorised_by,
                                      software_version=software_version(), specimen=specimen)
        prefix = f"{identity.certificate_prefix}-SIM" if specimen else identity.certificate_prefix
        issued = repo.issue_certificate(prefix, content, serial=content["serial"], subject=campaign,
                                        authorised_by=authorised_by,
                                        number_into=lambda c, number, utc: with_number(c, number, utc))
    run.report_dir.mkdir(parents=True, exist_ok=True)
    files = [write_certificate(issued.content, run.report_dir / f"{CERTIFICATE_NAME}-{issued.number}.{suffix}")
             for suffix in ("pdf", "html")]
    return issued.number, [Path(f) for f in files]
