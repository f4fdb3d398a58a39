"""A certificate's amplitude linearity is the campaign statistics' line (issue 40 item 5): each
shot's quasi-static gain (analysis.static_gain) against the amplitude it is measured at, fitted
by reports.statistics.campaign_linearity, not the model's DC gain.

The campaign is tests/analysis/test_linearity.py's: the shipped realistic simulator's sensor with
a known non-linearity of −1 % per 100 km/s² (the Hammerstein input a·(1 + c·|a|)), four shots of
two projectiles at about 210–680 km/s², analysed as a rig's shots, written into shot files, imported
into the lab's record and certified (a specimen: simulated data). On these shots the quasi-static
gains find the slope (−0.92 ± 0.11 % per 100 km/s²) and tell it from zero; the DC gains do not
(−0.36 ± 0.18 %: a slope, not the sensor's; −0.27 ± 1.9 % before decision 0026): a certificate
fitted to them again fails here.
"""

from __future__ import annotations

import json
import sqlite3
from pathlib import Path

import pytest

from hopkinson.analysis.key_figures import KeyFigures
from hopkinson.analysis.linearity import fit_linearity
from hopkinson.lab.repository import open_repository
from hopkinson.reports.statistics import campaign_linearity, linearity_points
from hopkinson.rig.shotfile_writer import add_analysis
from tests.analysis.test_linearity import NONLINEARITY, campaign_results
from tests.lab.records import write_made_up_shot
from tests.lab.test_lab_cli import lab, lab_config, save_pages  # noqa: F401 (the fixture)


@pytest.fixture(scope="module")
def results(tmp_path_factory: pytest.TempPathFactory) -> tuple[dict, ...]:
    return campaign_results(NONLINEARITY, 0, tmp_path_factory)


def test_the_certificate_states_the_quasi_static_gains_line(results: tuple[dict, ...], tmp_path: Path,
                                                            lab_config: Path,  # noqa: F811 (the fixture)
                                                            capsys: pytest.CaptureFixture[str],
                                                            artifacts_dir: Path) -> None:
    run = tmp_path / "run-nonlinear"
    (run / "shots").mkdir(parents=True)
    for i, shot in enumerate(results):
        path = run / "shots" / f"n00{i}.h5"
        write_made_up_shot(path, campaign=run.name, utc=f"2026-03-01T10:0{i}:00Z", simulated=True)
        add_analysis(path, shot)  # the simulated sensor's analysis is the shot's newest
    url = f"sqlite:///{tmp_path / 'lab.sqlite'}"
    code, _out, err = lab(capsys, url, "import", str(run), "--config", str(lab_config))
    assert code == 0, err
    page, pdf = tmp_path / "cert.html", tmp_path / "cert.pdf"
    code, out, err = lab(capsys, url, "certificate", str(run), "-o", str(page), "-o", str(pdf), "--authorised-by",
                         "Dr. Q. Manager", "--specimen", "--json", "--config", str(lab_config))
    assert code == 0, err
    number = json.loads(out)["number"]
    with open_repository(url) as repo:
        linearity = repo.certificate(number).content["linearity"]

    figures = [KeyFigures.from_results(r) for r in results]
    campaign, _note = campaign_linearity(linearity_points((str(i), kf) for i, kf in enumerate(figures)))
    stated = linearity["fit"]
    assert stated is not None, linearity["text"]
    # the campaign statistics' line, through the same points
    assert stated["slope_rel_per_m_s2"] == pytest.approx(campaign.slope_rel_per_m_s2, rel=1e-9)
    assert stated["expanded_slope_rel_per_m_s2"] == pytest.approx(campaign.expanded_slope_rel_per_m_s2, rel=1e-9)
    assert sorted(p["sensitivity"] for p in linearity["points"]) == sorted(
        kf.static_gain.value for kf in figures if kf.is_result)
    # the known non-linearity inside its U, and told from a linear sensor's zero
    slope, big = stated["slope_rel_per_m_s2"], stated["expanded_slope_rel_per_m_s2"]
    assert abs(slope - NONLINEARITY) <= big and abs(slope) > big, linearity["text"]
    # the DC gains' line fails the same check (why the certificate no longer uses them): a linear
    # model's gain does not carry the sensor's level dependence whole. Its shots' U once hid it (it
    # could not tell the slope from zero: −0.27 ± 1.9 %); since the Type B rows leave out the
    # record's noise (decision 0026) it tells a slope from zero, the wrong one (−0.36 ± 0.18 %)
    shown = [kf for kf in figures if kf.is_result]
    dc = fit_linearity([kf.peak_acceleration_m_s2.value for kf in shown], [kf.sensitivity.value for kf in shown],
                       [kf.sensitivity.u for kf in shown])
    dc_slope, dc_big = dc.slope_rel_per_m_s2, dc.expanded_slope_rel_per_m_s2
    assert not (abs(dc_slope - NONLINEARITY) <= dc_big and abs(dc_slope) > dc_big), dc.text()
    # the certificate says which sensitivity it is, beside the stated one
    text = page.read_text()
    assert "of the quasi-static sensitivity in the main pulse's direction" in linearity["text"]
    assert "% per 100 km/s²" in linearity["text"] and "The stated sensitivity above is the model's DC gain" in \
        linearity["text"]
    assert linearity["text"].replace("'", "&#x27;") in text or linearity["text"] in text
    # `lab verify` checks the quasi-static gain a certificate now rests on against the shot file
    code, out, err = lab(capsys, url, "verify", "--config", str(lab_config))
    assert code == 0 and "verified: no discrepancy" in out, (out, err)
    with sqlite3.connect(tmp_path / "lab.sqlite") as db:  # the owner, dropping the trigger
        db.execute("DROP TRIGGER analyses_no_update")
        db.execute("UPDATE analyses SET static_gain = 1.01 * static_gain WHERE id = "
                   "(SELECT min(id) FROM analyses WHERE static_gain IS NOT NULL)")
    code, out, _ = lab(capsys, url, "verify", "--json", "--config", str(lab_config))
    problems = json.loads(out)["problems"]
    assert code == 1 and len(problems) == 1 and "holds figures no analysis in the shot file has" in problems[0]
    save_pages(url, number, pdf, artifacts_dir / "lab-certificate-linearity")
