"""`hopkinson report`: the report of a shot file and of a campaign run folder, from shots fired
on the simulated rig, and one clear line with exit code 2 for bad input."""

from __future__ import annotations

import json
import re
import shutil
import zlib
from pathlib import Path

import pytest

from hopkinson.analysis.key_figures import KeyFigures
from hopkinson.rig.cli.main import main
from hopkinson.rig.cli.report import default_outputs
from hopkinson.rig.shotfile import read_shot
from hopkinson.rig.shotfile_writer import add_analysis

PLAN = """
name = "rep"
operator = "tester"
authorise_firing = true
[accelerometer]
model = "SIM-ACC"
serial = "R1"
[defaults]
projectile = 3
[defaults.analysis]
max_order = 6
draws = 50  # the uncertainty shown in the report, with the fewest draws allowed
[[shots]]
pressure_bar = 1.3
[[shots]]
pressure_bar = 2.4
"""


@pytest.fixture(scope="module")
def run_folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A campaign of two shots fired on the simulated rig (100x faster than real time)."""
    base = tmp_path_factory.mktemp("report")
    plan = base / "plan.toml"
    plan.write_text(PLAN, encoding="utf-8")
    sim = base / "sim-fast.toml"
    sim.write_text("[world]\ntime_scale = 100.0\n", encoding="utf-8")
    run = base / "run"
    rc = main(["campaign", "run", str(plan), "--sim", "--sim-config", str(sim), "--out", str(run), "--no-report"])
    assert rc == 0
    return run


def pdf_pages(data: bytes) -> int:
    return len(re.findall(rb"/Type\s*/Page\b", data))


def pdf_text(data: bytes) -> str:
    streams = b""
    for m in re.finditer(rb"stream\r?\n(.*?)endstream", data, re.S):
        try:  # (a decompressor object stops at the stream's end, whatever line break follows it)
            streams += zlib.decompressobj().decompress(m.group(1))
        except zlib.error:
            pass
    parts = [b"".join(re.findall(rb"\(((?:[^()\\]|\\.)*)\)", m.group(0)))
             for m in re.finditer(rb"\[(.*?)\]\s*TJ|\(((?:[^()\\]|\\.)*)\)\s*Tj", streams, re.S)]
    return b" ".join(parts).decode("latin-1")


def one_error_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("hopkinson: error: ") and "Traceback" not in err[0]
    return err[0]


def test_run_folder_report_with_spread_and_cross_validation(run_folder: Path, capsys) -> None:
    out = run_folder / "report" / "campaign.html"
    assert main(["report", str(run_folder), "-o", str(out), "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["reports"] == [str(out)]
    assert [(s["id"], s["state"], s["analysed"]) for s in result["shots"]] == [
        ("s001-r1", "ANALYSED", True), ("s002-r1", "ANALYSED", True)]
    campaign = result["campaign"]
    cv = campaign["cross_validation_percent"]
    assert len(cv) == 2 and all(len(row) == 2 for row in cv)
    # Each shot's own fit is the identification's; the other shot's model predicts it about as well.
    for i, sid in enumerate(("s001-r1", "s002-r1")):
        results = read_shot(run_folder / "shots" / f"{sid}.h5", load_raw=False).results
        assert cv[i][i] == pytest.approx(results["identification"]["fit_percent"], abs=1e-9)
        assert cv[1 - i][i] > cv[i][i] - 1.0
    truth_fn = read_shot(run_folder / "shots" / "s001-r1.h5", load_raw=False).meta.simulated_truth[
        "accelerometer"]["modes"][0]["natural_frequency_hz"]
    assert campaign["spread"]["natural_frequency_hz"]["mean"] == pytest.approx(truth_fn, rel=0.01)
    assert campaign["spread"]["natural_frequency_hz"]["n"] == 2
    # every shot's key figures are the analysis' own (analysis.key_figures), and the campaign's
    # combined f_n is their mean
    for shot in result["shots"]:
        stored = read_shot(run_folder / "shots" / f"{shot['id']}.h5", load_raw=False).results
        assert shot["key_figures"] == json.loads(json.dumps(KeyFigures.from_results(stored).to_dict()))
    means = [s["key_figures"]["natural_frequency_hz"]["value"] for s in result["shots"]]
    assert campaign["combined"]["natural_frequency_hz"]["mean"] == pytest.approx(sum(means) / 2)
    page = out.read_text(encoding="utf-8")
    for needle in ("campaign run", "SIM-ACC, serial R1", "<h2>Cross-validation</h2>", "Shot s002-r1",
                   "Spread across 2 analysed shots", "SIMULATED", "Hopkinson-Sim,SIMDIG-"):  # the digitizer's identity
        assert needle in page, needle
    assert page.count("<img ") == 2 + 4 * 2
    assert not list(run_folder.rglob("*.tmp"))


def test_shot_file_report_beside_the_shot(run_folder: Path, tmp_path: Path, capsys) -> None:
    shot = tmp_path / "s001-r1.h5"
    shutil.copyfile(run_folder / "shots" / "s001-r1.h5", shot)
    assert main(["report", str(shot)]) == 0
    assert capsys.readouterr().out.strip() == f"report: {tmp_path / 's001-r1.pdf'}"
    data = (tmp_path / "s001-r1.pdf").read_bytes()
    assert pdf_pages(data) in (5, 6)  # a summary of one or two pages (with the uncertainty), the shot's 4 pages
    text = pdf_text(data)
    fbsd = read_shot(shot, load_raw=False).results["fbsd_hz"]
    for needle in ("SIM-ACC, serial R1", "shot s001-r1", "SIMULATED", "Results", f"{fbsd['5'] / 1e3:.4g} kHz",
                   "shock sensitivity", "Pole analysis"):
        assert needle in text, needle


def test_a_failed_analysis_is_reported_not_hidden(run_folder: Path, tmp_path: Path, capsys) -> None:
    shot = tmp_path / "failed.h5"
    shutil.copyfile(run_folder / "shots" / "s002-r1.h5", shot)
    add_analysis(shot, {}, error="analysis failed: no beat in the Doppler channel")
    out = tmp_path / "failed.html"
    assert main(["report", str(shot), "-o", str(out)]) == 0
    page = out.read_text(encoding="utf-8")
    assert "No analysis: analysis failed: no beat in the Doppler channel" in page
    assert "analysis_failed" in page


def test_default_outputs() -> None:
    assert default_outputs(Path("runs/r1/shots/s1.h5")) == [Path("runs/r1/shots/s1.pdf")]
    here = Path(__file__).resolve().parent
    assert default_outputs(here) == [here / "report" / "report.pdf"]


def test_bad_input_is_one_line_exit_2(run_folder: Path, tmp_path: Path, capsys) -> None:
    assert main(["report", str(tmp_path / "nothing.h5")]) == 2
    assert "nothing.h5: no such shot file or run folder" in one_error_line(capsys)
    assert main(["report", str(run_folder), "-o", str(tmp_path / "r.txt")]) == 2
    assert "a report is .pdf or .html" in one_error_line(capsys)
    assert main(["report", str(run_folder), "-o", str(tmp_path / "no" / "r.pdf")]) == 2
    assert "does not exist" in one_error_line(capsys)
    fake = tmp_path / "fake.h5"
    fake.write_text("not hdf5")
    assert main(["report", str(fake)]) == 2
    assert "fake.h5: not a readable HDF5 shot file" in one_error_line(capsys)
    assert main(["report", str(tmp_path)]) == 2
    assert "not a campaign run folder" in one_error_line(capsys)
    empty = tmp_path / "empty-run"
    (empty / "shots").mkdir(parents=True)
    shutil.copyfile(run_folder / "plan.toml", empty / "plan.toml")
    assert main(["report", str(empty)]) == 2
    assert "no shot files yet" in one_error_line(capsys)


def test_a_plan_naming_a_sine_calibration_gets_the_comparison(run_folder: Path, tmp_path: Path, capsys) -> None:
    """The plan copy names the sensor's sine calibration (here: the simulated sensor's true
    response, as a lab's sine calibrator would measure it): the report compares every shot's model."""
    import numpy as np

    from hopkinson.drivers.sim.shot_truth import accelerometer_truth

    run = tmp_path / "run"
    shutil.copytree(run_folder, run)
    truth = read_shot(run / "shots" / "s001-r1.h5", load_raw=False).meta.simulated_truth
    f = np.geomspace(500.0, 15e3, 10)
    h = accelerometer_truth(truth).frequency_response(f)
    rows = "".join(f"{fi:.10g},{abs(hi):.10g},{np.degrees(np.angle(hi)):.10g},0.005\n" for fi, hi in zip(f, h, strict=True))
    (run / "sine.csv").write_text("frequency_hz,magnitude,phase_deg,u_magnitude_rel\n" + rows)
    plan = (run / "plan.toml").read_text().replace('serial = "R1"', 'serial = "R1"\nsine_calibration = "sine.csv"')
    (run / "plan.toml").write_text(plan)
    out = tmp_path / "r.html"
    assert main(["report", str(run), "-o", str(out), "--json"]) == 0
    sine = json.loads(capsys.readouterr().out)["campaign"]["sine_comparison"]
    assert sorted(sine) == ["s001-r1", "s002-r1"]
    for comparison in sine.values():  # each shot's model against the true sensor, up to 15 kHz
        assert max(abs(e) for e in comparison["magnitude_error_pct"]) < 1.0
    page = out.read_text(encoding="utf-8")
    assert "Against the sinusoidal calibration" in page and "sine.csv (10 points)" in page
    assert page.count("<img ") == 3 + 4 * 2


def _flip(path: Path, dataset: str, count: int = 64) -> None:
    """Flip `count` bytes inside a dataset's stored data (as a failing disk or a bad copy would)."""
    import h5py

    with h5py.File(path, "r") as f:
        ds = f[dataset]
        offset = ds.id.get_chunk_info(0).byte_offset if ds.chunks else ds.id.get_offset()
    with path.open("r+b") as fh:
        fh.seek(offset + 16)
        data = bytearray(fh.read(count))
        fh.seek(offset + 16)
        fh.write(bytes(b ^ 0xFF for b in data))


@pytest.mark.parametrize("where", ["raw/response", "derived/record/reference", "entry/signals/doppler",
                                   "analysis/results_json"])
def test_a_damaged_shot_is_refused_by_report_and_analyse(run_folder: Path, tmp_path: Path, capsys,
                                                         where: str) -> None:
    # issue 18: with 64 bytes of /raw/response flipped `report` exited 0 and never said so
    import h5py

    shot = tmp_path / "damaged.h5"
    shutil.copyfile(run_folder / "shots" / "s001-r1.h5", shot)
    if where == "analysis/results_json":
        with h5py.File(shot, "r+") as f:
            f["analysis"].attrs["results_json"] = f["analysis"].attrs["results_json"].replace('"order"', '"ordeR"')
        damage = "/analysis: its results do not match their SHA-256"
    else:
        _flip(shot, where)
        damage = f"/{where} fails its checksum"
    assert main(["report", str(shot), "-o", str(tmp_path / "r.html")]) == 2
    line = one_error_line(capsys)
    assert f"{shot}: damaged shot file: " in line and damage in line
    assert not (tmp_path / "r.html").exists()
    assert main(["analyse", str(shot)]) == 4  # its analysis failed (docs/exit-codes.md)
    out = capsys.readouterr().out
    assert out.startswith(f"{shot}: FAILED: {shot}: damaged shot file") and damage in out


def test_a_run_folders_damaged_shot_is_listed_as_unreadable(run_folder: Path, tmp_path: Path, capsys) -> None:
    run = tmp_path / "run"
    shutil.copytree(run_folder, run, ignore=shutil.ignore_patterns("*.lock", "report"))
    _flip(run / "shots" / "s002-r1.h5", "raw/response")
    assert main(["report", str(run), "-o", str(tmp_path / "r.html"), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    (bad,) = data["unreadable"]
    assert bad["id"] == "s002-r1" and "/raw/response fails its checksum" in bad["reason"]
    assert [s["id"] for s in data["shots"]] == ["s001-r1"]
