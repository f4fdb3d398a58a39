"""`hopkinson lab` on real shot files: import (idempotent, re-analysis, tampering), a sensor's
history, certificates (numbered, re-issued, drawn as PDF and HTML), and bad input."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import h5py
import numpy as np
import pytest
import sqlalchemy as sa
from scipy.stats import t as student_t

from hopkinson.lab.database import head_revision, make_engine
from hopkinson.rig.cli.main import main
from hopkinson.rig.shotfile_writer import add_analysis
from tests.lab.records import made_up_results, write_made_up_shot

REPO = Path(__file__).resolve().parents[2]
LAB_SECTION = """
[lab]
name = "Shock Calibration Lab, Example Institute"
address = "1 Bar Street, Testville"
accreditation = "ISO/IEC 17025, accreditation No. D-K-00000-00-00 (example)"
certificate_prefix = "XL"
rig = "HB-1"
decision_rule = "guarded"
country = "DE"

[[lab.signatories]]
name = "Dr. Q. Manager"
role = "Head of the shock laboratory"

[[lab.signatories]]
name = "Q"
role = "Deputy head"

[[lab.reference_chain]]
item = "laser Doppler interferometer (grating pitch)"
certificate = "PTB-2025-0815"
issued_by = "PTB"
u_rel = 0.0001
due = "2030-06-30"
"""


@pytest.fixture
def lab_config(tmp_path: Path) -> Path:
    path = tmp_path / "rig.toml"
    path.write_text((REPO / "config" / "rig-sim.toml").read_text() + LAB_SECTION)
    return path


@pytest.fixture
def run_folder(tmp_path: Path) -> Path:
    """A campaign's run folder with three analysed shots of SN-7 (sensitivity 1.000, 1.004, 1.002)."""
    run = tmp_path / "run-2026-03"
    (run / "shots").mkdir(parents=True)
    snapshot = {"lab": {"rig": "HB-1", "reference_chain": [
        {"item": "laser Doppler interferometer (grating pitch)", "certificate": "PTB-2025-0815", "issued_by": "PTB",
         "u_rel": 0.0001, "due": "2030-06-30"}]}}
    for i, s in enumerate((1.000, 1.004, 1.002)):
        write_made_up_shot(run / "shots" / f"s00{i}.h5", campaign=run.name, sensitivity=s, u=0.002,
                           utc=f"2026-03-01T10:0{i}:00Z", config=snapshot)
    return run


def lab(capsys: pytest.CaptureFixture[str], url: str, *args: str) -> tuple[int, str, str]:
    code = main(["lab", args[0], "--database", url, *args[1:]])
    out, err = capsys.readouterr()
    return code, out, err


def save_pages(url: str, number: str, pdf: Path, stem: Path) -> None:
    """The PDF's pages as PNG for people to look at (pdftoppm, else the same pages drawn by
    matplotlib), and the PDF's own page count against its "page n of N" footers."""
    from hopkinson.lab.repository import open_repository
    from hopkinson.reports.certificate_pages import png_pages

    with open_repository(url) as repo:
        content = repo.certificate(number).content
    if shutil.which("pdftoppm"):
        subprocess.run(["pdftoppm", "-png", "-r", "60", str(pdf), str(stem)], check=True)
    else:
        for i, png in enumerate(png_pages(content), start=1):
            stem.with_name(f"{stem.name}-{i}.png").write_bytes(png)
    assert pdf.read_bytes().count(b"/Type /Page\n") == len(png_pages(content)) or b"/Count" in pdf.read_bytes()


def assert_valid_dcc(xml: bytes, number: str, expanded: float) -> None:
    """The DCC validates against PTB's released schema 3.2.0 (loaded here from the shipped copies,
    independently of the writer) and states the number and the sensitivity with its U and k."""
    from lxml import etree

    schemas = REPO / "lab" / "schemas"
    tree = etree.parse(str(schemas / "dcc_3_2_0.xsd"))
    for imp in tree.getroot().iter("{http://www.w3.org/2001/XMLSchema}import"):
        local = {"https://ptb.de/si/v2.1.0/SI_Format.xsd": "SI_Format_2_1_0.xsd"}.get(imp.get("schemaLocation"),
                                                                                   "xmldsig-core-schema.xsd")
        imp.set("schemaLocation", (schemas / local).as_uri())
    schema = etree.XMLSchema(tree)
    doc = etree.fromstring(xml)
    assert schema.validate(doc), schema.error_log
    ns = {"dcc": "https://ptb.de/dcc", "si": "https://ptb.de/si"}
    assert doc.get("schemaVersion") == "3.2.0"
    assert doc.findtext(".//dcc:coreData/dcc:uniqueIdentifier", namespaces=ns) == number
    assert doc.findtext(".//dcc:coreData/dcc:receiptDate", namespaces=ns) == "2026-02-20"
    stated = doc.find(".//dcc:result/dcc:data/dcc:quantity/si:real", namespaces=ns)
    assert float(stated.findtext("si:value", namespaces=ns)) == pytest.approx(1.002)
    assert stated.findtext("si:unit", namespaces=ns) == r"\one"
    assert float(stated.findtext("si:expandedUnc/si:uncertainty", namespaces=ns)) == pytest.approx(expanded)
    assert doc.findtext(".//dcc:respPerson/dcc:role", namespaces=ns) == "Head of the shock laboratory"


def record_job(capsys: pytest.CaptureFixture[str], url: str, run: Path, config: Path) -> None:
    code, _out, err = lab(capsys, url, "job", str(run), "--received", "2026-02-20", "--condition",
                          "as new, no visible damage", "--location", "shock lab, room 0.12", "--config", str(config))
    assert code == 0, err


def test_import_is_idempotent_and_records_each_analysis(run_folder: Path, lab_url: str, lab_config: Path,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = lab(capsys, lab_url, "import", str(run_folder), "--json", "--config", str(lab_config))
    assert code == 0 and [s["outcome"] for s in json.loads(out)["shots"]] == ["new"] * 3
    code, out, _ = lab(capsys, lab_url, "import", str(run_folder), "--json", "--config", str(lab_config))
    assert [s["outcome"] for s in json.loads(out)["shots"]] == ["known"] * 3
    add_analysis(run_folder / "shots" / "s000.h5", made_up_results(1.010, 0.002))  # a re-analysis rewrites it
    code, out, _ = lab(capsys, lab_url, "import", str(run_folder / "shots" / "s000.h5"), "--json",
                       "--config", str(lab_config))
    assert [s["outcome"] for s in json.loads(out)["shots"]] == ["analysis added"]

    plot = run_folder / "history.png"
    code, out, _ = lab(capsys, lab_url, "sensor", "SN-7", "--json", "--tolerance-percent", "0.5",
                       "--interval-days", "365", "--plot", str(plot), "--config", str(lab_config))
    history = json.loads(out)
    assert plot.read_bytes().startswith(b"\x89PNG")
    (calibration,) = history["calibrations"]  # a calibration is the campaign: its three shots
    sensitivities = [s["figures"]["sensitivity"]["value"] for s in calibration["shots"]]
    assert sensitivities == pytest.approx([1.010, 1.004, 1.002])  # the newest analysis of each shot
    assert calibration["shots"][0]["figures"]["sensitivity"]["U"] == pytest.approx(0.004)
    assert calibration["rig"] == "HB-1" and not calibration["simulated"]
    assert history["sensor"]["tolerance_percent"] == 0.5
    assert history["conformity"]["rule"] == "guarded"  # from the configuration's [lab]
    # the campaign combined (GUM G.4): mean 1.00533, s = 0.004163, ū = 0.002, ν_eff = 5.7
    values = [1.010, 1.004, 1.002]
    mean = sum(values) / 3
    s = (sum((v - mean) ** 2 for v in values) / 2) ** 0.5
    u_c = (s ** 2 / 3 + 0.002 ** 2) ** 0.5
    expanded = student_t.ppf(0.975, u_c ** 4 / ((s ** 2 / 3) ** 2 / 2)) * u_c
    assert history["conformity"]["deviation_percent"] == pytest.approx(100 * (mean - 1))
    assert history["conformity"]["expanded_percent"] == pytest.approx(100 * expanded)
    # 0.533 % with U 0.78 %: 0.533 − 0.78 ≤ 0.5 < 0.533 -> a conditional fail under guarded acceptance
    assert history["conformity"]["verdict"] == "conditional fail"


@pytest.fixture
def sqlite_url(tmp_path: Path) -> str:
    """The commands' own paths on SQLite only (the repository's tests run on both databases)."""
    return f"sqlite:///{tmp_path / 'lab.sqlite'}"


def test_a_tampered_shot_file_is_refused_with_one_line(run_folder: Path, sqlite_url: str, lab_config: Path,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    shot = run_folder / "shots" / "s001.h5"
    with h5py.File(shot, "r+") as f:  # the codes rewritten whole: the HDF5 checksums are valid again
        codes = f["raw/response"][...]
        codes[100] += 1
        f["raw/response"][...] = codes
    code, out, err = lab(capsys, sqlite_url, "import", str(run_folder), "--config", str(lab_config))
    assert code == 2
    assert err == f"hopkinson: error: {shot.resolve()}: raw channels do not match their SHA-256 written with the " \
                  f"shot (tampered or damaged); refused\n"
    assert out.count("new: ") == 2  # the others are recorded all the same


def test_a_certificate_is_numbered_immutable_and_reissued_under_a_new_number(
        run_folder: Path, sqlite_url: str, lab_config: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
        artifacts_dir: Path) -> None:
    lab(capsys, sqlite_url, "import", str(run_folder), "--config", str(lab_config))
    lab(capsys, sqlite_url, "sensor", "SN-7", "--owner", "ACME Aerospace", "--model", "ACC-20k",
        "--tolerance-percent", "2", "--interval-days", "365", "--config", str(lab_config))
    record_job(capsys, sqlite_url, run_folder, lab_config)
    pdf, page, dcc = tmp_path / "cert.pdf", tmp_path / "cert.html", tmp_path / "cert.xml"
    code, out, err = lab(capsys, sqlite_url, "certificate", str(run_folder), "-o", str(pdf), "-o", str(page), "-o", str(dcc),
                         "--authorised-by", "Dr. Q. Manager", "--conditions", "(23 ± 2) °C", "--json",
                         "--config", str(lab_config))
    assert code == 0, err
    first = json.loads(out)
    assert first["number"].startswith("XL-20") and first["number"].endswith("-0001")
    assert first["conformity"] == "pass"
    text = page.read_text()
    for expected in (first["number"], "Shock Calibration Lab, Example Institute", "ACME Aerospace", "SN-7",
                     "ACC-20k", "Yang", "PTB-2025-0815", "(23 ± 2) °C", "ILAC-G8:2019 guarded acceptance", "Dr. Q. Manager",
                     "s000", "shall not be reproduced"):
        assert expected in text, expected
    # the three shots combined (GUM G.4): mean 1.002, s = 0.002, ū = 0.002, ν_eff = 32
    u_c = (0.002 ** 2 / 3 + 0.002 ** 2) ** 0.5
    k = student_t.ppf(0.975, u_c ** 4 / ((0.002 ** 2 / 3) ** 2 / 2))
    assert f"<td>stated sensitivity</td><td>1.0020 ± {k * u_c:.4f} × nominal</td>" in text
    assert f"<td>coverage factor k</td><td>{k:.2f}</td>" in text
    assert pdf.read_bytes().startswith(b"%PDF")
    save_pages(sqlite_url, first["number"], pdf, artifacts_dir / "lab-certificate")
    assert_valid_dcc(dcc.read_bytes(), first["number"], k * u_c)

    again = tmp_path / "cert-2.html"
    code, out, _ = lab(capsys, sqlite_url, "certificate", run_folder.name, "-o", str(again), "--authorised-by",
                       "Dr. Q. Manager", "--replaces", first["number"], "--json", "--config", str(lab_config))
    second = json.loads(out)
    assert code == 0 and second["replaces"] == first["number"] and second["number"].endswith("-0002")
    assert f"certificate {first['number']}, which is withdrawn" in again.read_text()
    code, out, _ = lab(capsys, sqlite_url, "audit", "--json", "--config", str(lab_config))
    actions = [(a["action"], a["subject"]) for a in json.loads(out)["audit"]]
    assert actions[:2] == [("certificate replaced", second["number"]), ("certificate issued", first["number"])]


def test_a_simulated_campaign_gets_no_certificate_only_a_marked_specimen(
        run_folder: Path, sqlite_url: str, lab_config: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
        artifacts_dir: Path) -> None:
    write_made_up_shot(run_folder / "shots" / "s003.h5", campaign=run_folder.name, sensitivity=1.001,
                       utc="2026-03-01T10:04:00Z", simulated=True)
    page = tmp_path / "cert.html"
    code, out, err = lab(capsys, sqlite_url, "certificate", str(run_folder), "-o", str(page), "--authorised-by",
                         "Dr. Q. Manager", "--config", str(lab_config))
    assert code == 2 and not page.exists()
    assert err == (f"hopkinson: error: campaign {run_folder.name}: 1 of its 4 shots were made by the simulator (s003): "
                   "no certificate; --specimen issues a specimen marked as simulated data\n")
    code, out, err = lab(capsys, sqlite_url, "audit", "--json", "--config", str(lab_config))
    assert not [a for a in json.loads(out)["audit"] if a["action"].startswith("certificate")]

    pdf = tmp_path / "specimen.pdf"
    code, out, err = lab(capsys, sqlite_url, "certificate", str(run_folder), "-o", str(page), "-o", str(pdf),
                         "--authorised-by", "Dr. Q. Manager", "--specimen", "--json", "--config", str(lab_config))
    assert code == 0, err
    number = json.loads(out)["number"]
    assert number.startswith("XL-SIM-20") and number.endswith("-0001")  # never a certificate's number
    text = page.read_text()
    assert "Specimen calibration certificate" in text
    assert "SPECIMEN: simulated data, not a calibration (1 of 4 shots simulated)" in text
    if shutil.which("pdftoppm"):
        subprocess.run(["pdftoppm", "-png", "-r", "60", "-f", "1", "-l", "1", str(pdf),
                        str(artifacts_dir / "lab-specimen")], check=True)
    # the real series is untouched: the next real certificate (of real shots only) is -0001
    (run_folder / "shots" / "s003.h5").unlink()
    other = tmp_path / "run-2026-04"
    (other / "shots").mkdir(parents=True)
    write_made_up_shot(other / "shots" / "r000.h5", campaign=other.name, utc="2026-04-01T10:00:00Z")
    record_job(capsys, sqlite_url, other, lab_config)
    code, out, err = lab(capsys, sqlite_url, "certificate", str(other), "-o", str(tmp_path / "real.html"),
                         "--authorised-by", "Dr. Q. Manager", "--json", "--config", str(lab_config))
    assert code == 0, err
    real = json.loads(out)["number"]
    assert real.startswith("XL-20") and real.endswith("-0001")


@pytest.mark.parametrize("case", ["bad url", "unreachable", "newer schema", "unknown campaign", "bad suffix"])
def test_bad_input_is_one_line_and_exit_2(case: str, tmp_path: Path, lab_config: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    url = f"sqlite:///{tmp_path / 'lab.sqlite'}"
    args = ["status"]
    expected = ""
    if case == "bad url":
        url, expected = "mysql://x@host/db", "only sqlite and postgresql are supported"
    elif case == "unreachable":
        url, expected = "postgresql://nobody@127.0.0.1:9/none", "cannot be reached"
    elif case == "newer schema":
        main(["lab", "upgrade", "--database", url, "--config", str(lab_config)])
        engine = make_engine(url)
        with engine.begin() as connection:
            connection.execute(sa.text("UPDATE alembic_version SET version_num = '0042'"))
        engine.dispose()
        expected = f"schema version 0042 is newer than this software's ({head_revision()}); use a newer hopkinson"
    elif case == "unknown campaign":
        args, expected = ["certificate", "no-such-run", "-o", str(tmp_path / "c.pdf"), "--authorised-by", "Q"], \
            "campaign no-such-run: not in the lab's record"
    else:
        args, expected = ["certificate", "x", "-o", str(tmp_path / "c.docx"), "--authorised-by", "Q"], \
            "a certificate is written as .pdf, .html, .xml"
    capsys.readouterr()
    code, out, err = lab(capsys, url, *args, "--config", str(lab_config))
    assert code == 2
    assert err.startswith("hopkinson: error: ") and err.count("\n") == 1 and expected in err, err
    assert "Traceback" not in err and "password" not in err


def test_the_raw_hash_ignores_the_analysis_and_follows_the_codes(tmp_path: Path) -> None:
    from hopkinson.rig.shotfile import read_shot
    from hopkinson.rig.shotfile_integrity import raw_sha256

    path = tmp_path / "one.h5"
    write_made_up_shot(path)
    shot = read_shot(path)
    with h5py.File(path) as f:
        assert f.attrs["raw_sha256"] == raw_sha256(shot.raw)
    add_analysis(path, made_up_results(1.2, 0.01))
    assert raw_sha256(read_shot(path).raw) == raw_sha256(shot.raw)
    channels = dict(shot.raw.channels)
    codes, scale, offset, *_ = channels["doppler"]
    channels["doppler"] = (np.where(np.arange(codes.size) == 3, codes + 1, codes).astype(codes.dtype), scale, offset)
    assert raw_sha256(type(shot.raw)(channels, shot.raw.sample_interval_s, shot.raw.trigger_index)) != \
        raw_sha256(shot.raw)


def test_no_certificate_rests_on_an_overdue_reference(tmp_path: Path, sqlite_url: str, lab_config: Path,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    run = tmp_path / "run-overdue"
    (run / "shots").mkdir(parents=True)
    snapshot = {"lab": {"rig": "HB-2", "reference_chain": [
        {"item": "digitizer gain", "certificate": "DKD-1", "u_rel": 0.002, "due": "2026-02-28"}]}}
    write_made_up_shot(run / "shots" / "s000.h5", campaign=run.name, utc="2026-03-01T10:00:00Z", config=snapshot)
    record_job(capsys, sqlite_url, run, lab_config)
    code, out, err = lab(capsys, sqlite_url, "certificate", str(run), "-o", str(tmp_path / "c.html"),
                         "--authorised-by", "Q", "--config", str(lab_config))
    assert code == 2 and not (tmp_path / "c.html").exists()
    assert err == ("hopkinson: error: campaign run-overdue: reference chain overdue at the calibration: "
                   "digitizer gain (DKD-1, due 2026-02-28); no certificate\n")
    code, out, _ = lab(capsys, sqlite_url, "audit", "--json", "--config", str(lab_config))
    assert not [a for a in json.loads(out)["audit"] if a["action"].startswith("certificate")]
