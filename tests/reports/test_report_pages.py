"""Calibration reports' pages: the figures (bands and FBSD drawn where the analysis put them),
the PDF/HTML files (pages and text) and their layout (nothing off the page or overlapping, each
text in its cell, plain numbers). The statistics and the tables' rows are
test_report_statistics_and_tables.py's.

Records are simulated from known accelerometer models (drivers/sim) and analysed with the
shared shot analysis (tests/reports/simulated_shots.py, once per test run); the report must show
what the analysis found and the truth predicts.
"""

from __future__ import annotations

import re
import zlib
from pathlib import Path

import numpy as np
import pytest
from matplotlib.lines import Line2D
from matplotlib.text import Text

from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.key_figures import KeyFigures
from hopkinson.analysis.shot_analysis import ShotAnalysis
from hopkinson.analysis.sine_comparison import SineCalibration
from hopkinson.drivers.sim.accelerometer import AccelerometerTruth
from hopkinson.reports.data import CalibrationReport
from hopkinson.reports.layout import freeze_layout
from hopkinson.reports.pages import report_pages, title_pages
from hopkinson.reports.shot_pages import dcm_page, excitation_page, model_page, step_responses
from hopkinson.reports.statistics import campaign_statistics
from hopkinson.reports.tables import (
    budget_rows,
    combined_rows,
    compensation_rows,
    per_shot_rows,
    pole_rows,
    results_rows,
    sig,
    spread_rows,
    uncertainty_rows,
)
from hopkinson.reports.writers import write_pngs, write_report
from tests.reports.contract import contract_results
from tests.reports.simulated_shots import DT, SENSOR_A, entry

# ------------------------------------------------------------------ figures


def vertical_lines(ax) -> dict[str, float]:
    """label -> x of the vertical lines (axvline) of an axes."""
    out = {}
    for line in ax.get_lines():
        x = np.asarray(line.get_xdata(), dtype=float)
        if x.size == 2 and x[0] == x[1] and isinstance(line, Line2D):
            out[line.get_label()] = float(x[0])
    return out


def test_model_page_marks_the_bands_and_the_fbsd(analyses: dict[str, ShotAnalysis]) -> None:
    a = analyses["a1"]
    fig = model_page(entry("s001-r1", a))
    ax_db, ax_band, ax_phase = fig.axes
    lines = vertical_lines(ax_band)
    for key in ("5", "10"):
        label = next(k for k in lines if k.startswith(f"FBSD ±{key} % = "))
        assert lines[label] == pytest.approx(a.fbsd_hz[key] / 1e3)
        assert label.endswith(f"{a.fbsd_hz[key] / 1e3:.4g} kHz")
    # The bands are shaded at 1 ± 0.05 and 1 ± 0.10.
    y_bands = sorted((p.get_y(), p.get_y() + p.get_height()) for p in ax_band.patches
                     if p.get_label().endswith("% band"))  # (not the FBSD's 95 % intervals)
    assert len(y_bands) == 2
    assert y_bands[0] == pytest.approx((0.9, 1.1)) and y_bands[1] == pytest.approx((0.95, 1.05))
    # The normalised model curve crosses 1.05 at the FBSD ±5 % line.
    curve = ax_band.get_lines()[0]
    f, g = (np.asarray(v, dtype=float) for v in curve.get_data())
    assert np.interp(a.fbsd_hz["5"] / 1e3, f, g) == pytest.approx(1.05, abs=2e-3)
    assert "(kHz)" in ax_band.get_xlabel() and "|H(f)/H(0)|" in ax_band.get_ylabel()
    assert "(dB)" in ax_db.get_ylabel() and "(degrees)" in ax_phase.get_ylabel()


def test_model_page_shades_the_models_95_percent_band(analyses: dict[str, ShotAnalysis], artifacts_dir) -> None:
    """Issue 17: the model's response carries its own 95 % band (analysis.uncertainty.response_band)
    in the report, magnitude and phase, as the draws gave it."""
    from matplotlib.collections import PolyCollection

    a = analyses["a1"]
    band = a.uncertainty["response_band"]
    fig = model_page(entry("s001-r1", a))
    _ax_db, ax_band, ax_phase = fig.axes
    (shade,) = [c for c in ax_band.collections if isinstance(c, PolyCollection) and "band of the model" in c.get_label()]
    outline = shade.get_paths()[0].vertices
    f_khz = np.asarray(band["frequency_hz"]) / 1e3
    upper = np.array(sorted({(x, y) for x, y in outline if y >= np.interp(x, f_khz, band["magnitude_rel"])}))
    top = np.interp(f_khz, upper[:, 0], upper[:, 1])
    assert np.allclose(top, band["magnitude_rel_high"], rtol=1e-6)
    assert np.all(np.asarray(band["magnitude_rel_low"]) <= np.asarray(band["magnitude_rel"]))
    assert [c for c in ax_phase.collections if isinstance(c, PolyCollection) and "95 % band" in c.get_label()]
    fig.savefig(artifacts_dir / "report-model-band.png", dpi=60)


def test_dcm_page_and_step_responses(analyses: dict[str, ShotAnalysis]) -> None:
    a = analyses["a1"]
    fig = dcm_page(entry("s001-r1", a))
    lines = vertical_lines(fig.axes[0])
    label = next(k for k in lines if k.startswith("compensated FBSD ±5 %"))
    assert lines[label] == pytest.approx(a.compensated_fbsd_hz["5"] / 1e3)
    t, alone, both = step_responses(a)
    # Both step responses are normalised: they settle at 1 (unit DC gain of the DCM).
    assert alone[-1] == pytest.approx(1.0, abs=0.02) and both[-1] == pytest.approx(1.0, abs=0.02)
    assert t[1] - t[0] == pytest.approx(DT)


def test_excitation_page_shows_the_loss_by_order_and_the_chosen_order(analyses: dict[str, ShotAnalysis]) -> None:
    a = analyses["a1"]
    fig = excitation_page(entry("s001-r1", a))
    ax_loss = fig.axes[2]
    lines = vertical_lines(ax_loss)
    assert lines[f"chosen order {a.model.order}"] == a.model.order
    corrected = next(ln for ln in ax_loss.get_lines() if ln.get_label().startswith("bias-corrected"))
    np.testing.assert_allclose(corrected.get_ydata(), a.identification.loss_by_order)
    assert ax_loss.get_xlabel() == "model order n"
    # the pulse in km/s² as the results and the panel give it (it was in g only), g on the right
    ax_t = fig.axes[0]
    assert ax_t.get_ylabel() == "acceleration (km/s²)" and "(µs)" in ax_t.get_xlabel()
    reference = next(ln for ln in ax_t.get_lines() if ln.get_label().startswith("reference"))
    peak_m_s2 = a.to_dict()["excitation"]["peak_m_s2"]
    assert np.max(reference.get_ydata()) == pytest.approx(peak_m_s2 / 1e3, rel=0.03)
    (g_axis,) = ax_t.child_axes
    assert g_axis.get_ylabel() == "(g)"


# ------------------------------------------------------------------ files


def pdf_text(data: bytes) -> str:
    """The text drawn in a matplotlib PDF (content streams inflated, TJ/Tj strings joined)."""
    streams = b""
    for m in re.finditer(rb"stream\r?\n(.*?)endstream", data, re.S):
        try:  # (a decompressor object stops at the stream's end: the line break before endstream
            streams += zlib.decompressobj().decompress(m.group(1))  # may be \n or \r\n)
        except zlib.error:
            pass
    parts = []
    for m in re.finditer(rb"\[(.*?)\]\s*TJ|\(((?:[^()\\]|\\.)*)\)\s*Tj", streams, re.S):
        chunk = b"".join(re.findall(rb"\(((?:[^()\\]|\\.)*)\)", m.group(1))) if m.group(1) is not None else m.group(2)
        parts.append(chunk.replace(b"\\(", b"(").replace(b"\\)", b")"))
    return b" ".join(parts).decode("latin-1")


def pdf_pages(data: bytes) -> int:
    return len(re.findall(rb"/Type\s*/Page\b", data))


def true_sine_calibration(truth: AccelerometerTruth) -> SineCalibration:
    """A sine calibration of the true sensor (0.5–20 kHz, ±0.5 % standard uncertainty): what a lab's
    sine calibrator would measure, independent of any identification."""
    f = np.geomspace(500.0, 20e3, 12)
    h = truth.frequency_response(f)
    return SineCalibration(f, np.abs(h), np.degrees(np.angle(h)), np.full(f.size, 0.005), None, "sine-T1.csv")


@pytest.fixture(scope="module")
def single_report(analyses: dict[str, ShotAnalysis], artifacts_dir: Path) -> tuple[CalibrationReport, list]:
    """One shot's report, drawn once for the module; every page saved as a PNG for people to look at."""
    e = entry("s001-r1", analyses["a1"], SENSOR_A)
    report = CalibrationReport("Calibration report: SIM-ACC, serial T1, shot s001-r1", dict(e.identity), [e])
    pages = report_pages(report)
    write_pngs(pages, artifacts_dir, "report-shot", dpi=80)
    return report, pages


@pytest.fixture(scope="module")
def campaign_report(analyses: dict[str, ShotAnalysis], artifacts_dir: Path) -> tuple[CalibrationReport, list]:
    entries = [entry("s001-r1", analyses["a1"], SENSOR_A, results=contract_results(analyses["a1"])),
               entry("s002-r1", analyses["a2"], SENSOR_A, results=contract_results(analyses["a2"], recommended=False)),
               entry("s003-r1", None, error="analysis failed: no beat in the Doppler channel")]
    report = CalibrationReport("Calibration report: SIM-ACC, serial SIM0001, campaign 20260101T000000Z-example",
                               {"Campaign": "c-1"}, entries, campaign=True,
                               notes=["Shots without a shot file: s004-r1 (UNKNOWN)."],
                               sine_calibration=true_sine_calibration(SENSOR_A))
    pages = report_pages(report)
    write_pngs(pages[:4], artifacts_dir, "report-campaign", dpi=80)  # the shots' pages are as above
    return report, pages


def test_single_shot_report_files(tmp_path: Path, analyses: dict[str, ShotAnalysis], single_report) -> None:
    a = analyses["a1"]
    report, pages = single_report
    pdf, page_html = write_report(report, [tmp_path / "r.pdf", tmp_path / "r.html"], pages=pages)
    data = pdf.read_bytes()
    summaries = sum(1 for caption, _ in pages if caption.startswith("Summary"))
    assert summaries in (1, 2) and pdf_pages(data) == summaries + 4  # summary, excitation, model, poles, DCM
    assert b"/Title (Calibration report: SIM-ACC, serial T1, shot s001-r1)" in data
    text = pdf_text(data)
    f5 = f"{a.fbsd_hz['5'] / 1e3:.4g} kHz"
    for needle in ("Results", "model order", f5, "Band of small distortion", "Pole analysis", "SIM-ACC, serial T1",
                   "Step responses", "Loss by order", "simulated truth"):
        assert needle in text, needle
    page = page_html.read_text(encoding="utf-8")
    assert page.count("<img ") == 4 and page.count("data:image/png;base64,") == 4
    u5 = ((a.to_dict().get("uncertainty") or {}).get("fbsd_hz") or {}).get("5")
    if u5:  # the results give FBSD ±5 % as value ± U, U to two significant digits (GUM 7.2.6)
        big = (u5["interval"][1] - u5["interval"][0]) / 2 / 1e3
        decimals = max(0, 1 - int(np.floor(np.log10(big))))
        f5 = f"{a.fbsd_hz['5'] / 1e3:.{decimals}f} ± {big:.{decimals}f} kHz"
    for needle in ("FBSD ±5 %", f5, "Pole analysis (Table 1)", "SIM-ACC, serial T1", "zeros (= model poles)",
                   "pole error"):
        assert needle in page, needle
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]


def test_campaign_report_pdf(tmp_path: Path, campaign_report) -> None:
    report, pages = campaign_report
    entries = report.shots
    (pdf,) = write_report(report, [tmp_path / "c.pdf"], pages=pages)
    data = pdf.read_bytes()
    # summary, 4 campaign pages (one the sine, one the linearity: since issue 40 every analysed shot's DC gain
    # enters it, where the shots' S_sh did before), 2 shots, 1 failed
    assert pdf_pages(data) == 1 + 4 + 4 * 2 + 1
    text = pdf_text(data)
    stats = campaign_statistics(entries, report.sine_calibration)
    for needle in ("Cross-validation", "Spread across 2 analysed shots", "s004-r1 (UNKNOWN)",
                   "no beat in the Doppler channel", "s003-r1: no analysis",
                   f"{stats.spread['natural_frequency_hz']['mean'] / 1e3:.5g}",  # the spread table's mean f_n
                   f"{stats.cross_validation_percent[0, 1]:.2f}",  # a cross-validation matrix cell
                   "of the campaign: mean of the shots", "Welch", "DCM not recommended", "noise gain too high"):
        assert needle in text, needle
    # the campaign's f_n: the mean of the shots with U from their repeatability and their own u
    combined = stats.combined["natural_frequency_hz"]
    values = [KeyFigures.from_results(e.results).natural_frequency_hz for e in entries[:2]]
    assert combined.n == 2 and combined.mean == pytest.approx(np.mean([v.value for v in values]))
    decimals = 1 - int(np.floor(np.log10(combined.expanded / 1e3)))  # to the decimals of its U
    assert f"{combined.mean / 1e3:.{decimals}f}" in text
    # each shot's model against the true sensor's sine calibration: within 1 % up to 10 kHz
    assert [label for label, _ in stats.sine] == ["s001-r1", "s002-r1"]
    for _label, c in stats.sine:
        assert c.max_magnitude_error_below_pct(10e3) < 1.0
        assert c.compensated_magnitude is not None
    assert "against the sinusoidal calibration" in text and "sine-T1.csv" in text


@pytest.fixture(scope="module")
def uncertain_report(analyses: dict[str, ShotAnalysis], artifacts_dir: Path) -> tuple[CalibrationReport, list]:
    """A shot with its uncertainty and a DCM not recommended: the summary and the DCM page only."""
    a = analyses["a1"]
    e = entry("s001-r1", a, SENSOR_A, results=contract_results(a, recommended=False))
    report = CalibrationReport("Calibration report: SIM-ACC, serial T1, shot s001-r1 (with uncertainty)",
                               dict(e.identity), [e])
    pages = [("Summary", fig) for fig in title_pages(report, None)] + [
        ("s001-r1: dynamic compensation model", dcm_page(e))]
    for _, fig in pages:
        freeze_layout(fig)
    write_pngs(pages, artifacts_dir, "report-uncertainty", dpi=80)
    return report, pages


def test_the_uncertainty_and_the_compensation_check_are_shown(tmp_path: Path, uncertain_report) -> None:
    report, pages = uncertain_report
    (e,) = report.shots
    u = e.results["uncertainty"]
    header, rows = uncertainty_rows(e)
    by_label = {r[0]: r for r in rows}
    f_n = u["main_mode"]["natural_frequency_hz"]
    row = by_label["main mode f_n (kHz)"]
    assert float(row[1]) == pytest.approx(f_n["value"] / 1e3, abs=0.005)  # to the decimals of U (0.21)
    assert float(row[2]) == pytest.approx(f_n["u"] / 1e3, rel=0.05)
    assert float(row[3]) == pytest.approx(1.96 * f_n["u"] / 1e3, rel=0.05)  # U = half the 95 % interval
    assert row[5] == "0.40 %"  # two significant digits, the trailing zero kept
    assert header[3] == "U (k ≈ 2)" and "FBSD ±5 % (kHz)" in by_label and "main mode damping ζ" in by_label
    # the budget, largest source first, then the Monte Carlo's own u (the contract's budget gives
    # each source's share of the sensitivity only: one column)
    header, rows = budget_rows(e)
    assert [r[0] for r in rows] == ["amplifier gain", "response channel noise", "order choice", "grating pitch",
                                    "all sources (Monte Carlo)"]
    assert header == ["source", "sensitivity"] and rows[0][1] == "0.30" and rows[-1][1] == "0.40"
    check = dict(compensation_rows(e))
    assert check["verdict"].startswith("DCM NOT RECOMMENDED: the compensated RMS error (6.1 %)")
    assert check["RMS error over the pulse (of the peak), without → with DCM"] == "4.95 % → 6.1 %"
    assert check["band limit of the compensation (linear-phase low-pass, 4th-order Butterworth magnitude)"] == "40 kHz (−3 dB)"
    pdf, page_html = write_report(report, [tmp_path / "u.pdf", tmp_path / "u.html"], pages=pages)
    text = pdf_text(pdf.read_bytes())  # (matplotlib draws "fi" as a ligature: needles avoid it)
    big_u = 1.96 * f_n["u"] / 1e3
    decimals = 1 - int(np.floor(np.log10(big_u)))  # U to two significant digits (GUM 7.2.6)
    for needle in ("Measurement uncertainty", "Uncertainty budget", "grating pitch", "Monte Carlo",
                   "DCM NOT RECOMMENDED", "noise gain too high", "Compensation checked on the shot itself",
                   f"{f_n['value'] / 1e3:.{decimals}f} ± {big_u:.{decimals}f} kHz"):
        assert needle in text, needle
    page = page_html.read_text(encoding="utf-8")
    for needle in ("Measurement uncertainty", "U (k ≈ 2)", "DCM not recommended", "noise gain too high"):
        assert needle in page, needle


def test_report_input_errors(tmp_path: Path, analyses: dict[str, ShotAnalysis]) -> None:
    report = CalibrationReport("r", {}, [entry("s", analyses["a1"])])
    with pytest.raises(AnalysisError, match=r"r\.txt: a report is \.pdf or \.html"):
        write_report(report, [tmp_path / "r.txt"])
    with pytest.raises(AnalysisError, match="does not exist"):
        write_report(report, [tmp_path / "missing" / "r.pdf"])
    with pytest.raises(AnalysisError, match="no shots"):
        write_report(CalibrationReport("r", {}, []), [tmp_path / "r.pdf"])


# ------------------------------------------------------------------ layout


def laid_out(fig) -> None:
    """Lay a figure out as a draw does (ticks, tables, text extents at its dpi) without painting
    its pixels: the same extents as `fig.canvas.draw()` (checked on every report page at 80
    and 100 dpi), at half the cost."""
    fig.draw_without_rendering()


def text_boxes(fig) -> list[tuple[str, object]]:
    """(text, window extent in pixels) of every non-empty text drawn on a figure (after a draw)."""
    laid_out(fig)
    renderer = fig.canvas.get_renderer()
    out = []
    for t in fig.findobj(Text):
        if t.get_visible() and t.get_text().strip() and t.figure is fig:
            out.append((t.get_text(), t.get_window_extent(renderer)))
    return out


@pytest.mark.parametrize("which", ["single_report", "campaign_report", "uncertain_report"])
def test_summary_pages_stay_on_the_page_and_never_overlap(which: str, request) -> None:
    # The layout defects of issue 13: the title ran past the page edge, the shot table's headers ran together.
    report, pages = request.getfixturevalue(which)
    summaries = [fig for caption, fig in pages if caption.startswith("Summary")]
    assert summaries
    for fig, dpi in [(fig, dpi) for fig in summaries for dpi in (80, 100)]:  # as the PNGs and the PDF draw it
        fig.set_dpi(dpi)
        width, height = fig.canvas.get_width_height()
        boxes = [(text, box) for text, box in text_boxes(fig) if box.width > 0]
        assert any(text.startswith("Calibration report") for text, _ in boxes) or fig is not summaries[0]
        for text, box in boxes:
            assert box.x0 >= 0 and box.x1 <= width and box.y0 >= 0 and box.y1 <= height, f"off the page: {text!r}"
        for i, (text_a, a) in enumerate(boxes):
            for text_b, b in boxes[i + 1:]:
                overlap_x = min(a.x1, b.x1) - max(a.x0, b.x0)
                overlap_y = min(a.y1, b.y1) - max(a.y0, b.y0)
                assert overlap_x <= 0.5 or overlap_y <= 0.5, f"{text_a!r} overlaps {text_b!r} at {dpi} dpi"
        fig.set_dpi(100)
    for caption, fig in pages[:5]:  # every plot page's titles fit the page's width (a campaign's later
        # pages are its shots' pages, drawn as in the single-shot report)
        laid_out(fig)
        renderer, width = fig.canvas.get_renderer(), fig.canvas.get_width_height()[0]
        titles = [fig._suptitle] if fig._suptitle is not None else []
        titles += [ax.title for ax in fig.axes if ax.title.get_text()]
        for title in titles:
            box = title.get_window_extent(renderer)
            assert box.x0 >= 0 and box.x1 <= width, f"{caption}: {title.get_text()!r} runs off the page"


@pytest.mark.parametrize("which", ["single_report", "campaign_report", "uncertain_report"])
def test_plot_page_tables_keep_each_text_inside_its_cell(which: str, request) -> None:
    # A cell's text that runs past its cell's right edge is hidden under the next cell (the DCM
    # table's "latency removed (channel delay + DCM group delay)" lost its last word).
    _report, pages = request.getfixturevalue(which)
    checked = 0
    for caption, fig in pages:
        if caption.startswith("Summary"):
            continue  # laid out by TextPages (the test above)
        for dpi in (80, 100):
            fig.set_dpi(dpi)
            laid_out(fig)
            renderer = fig.canvas.get_renderer()
            for ax in fig.axes:
                for table in ax.tables:
                    for (_r, _c), cell in table.get_celld().items():
                        text = cell.get_text()
                        if not text.get_text().strip():
                            continue
                        box, inner = cell.get_window_extent(renderer), text.get_window_extent(renderer)
                        assert box.x0 - 0.5 <= inner.x0 and inner.x1 <= box.x1 + 0.5, \
                            f"{caption}: {text.get_text()!r} runs out of its cell at {dpi} dpi"
                        assert box.y0 - 0.5 <= inner.y0 and inner.y1 <= box.y1 + 0.5, \
                            f"{caption}: {text.get_text()!r} is taller than its cell at {dpi} dpi"
                        checked += 1
        fig.set_dpi(100)
    assert checked > 10


SCIENTIFIC = re.compile(r"\d[eE][+-]?\d")


@pytest.mark.parametrize("which", ["single_report", "campaign_report", "uncertain_report"])
def test_tables_print_no_scientific_notation_and_keep_significant_zeros(which: str, request) -> None:
    # A technician read "std 4.53e-05", "channel skew 3.9e-09" and "u 0.003" (for 0.0030) in
    # the report: every table cell in plain notation, a below-0.001 % budget share as "< 0.001".
    report, _pages = request.getfixturevalue(which)
    tables = [per_shot_rows(report.shots)] if report.campaign else []
    if report.campaign:
        stats = campaign_statistics(report.shots, None)
        tables += [spread_rows(stats), combined_rows(stats)]
    for e in report.shots:
        if e.analysis is not None:
            tables += [uncertainty_rows(e), budget_rows(e), (None, compensation_rows(e)), (None, results_rows(e))]
    for e in report.shots:  # the pole table (the paper's Table 1) keeps its significant zeros too
        if e.analysis is not None:
            tables.append(pole_rows(e.analysis))
            fn_cells = [row[2] for row in pole_rows(e.analysis)[1] if row[2] != "—"]
            assert fn_cells and all(len(c.replace(".", "")) == 5 for c in fn_cells), fn_cells
    cells = [str(c) for _header, rows in tables for row in rows for c in row]
    assert len(cells) > 20
    assert [c for c in cells if SCIENTIFIC.search(c)] == []
    assert sig(0.0030) == "0.0030" and sig(4.53e-5) == "0.000045" and sig(0.00996) == "0.010"
    assert sig(26999.9, 1e3, 5) == "27.000" and sig(0.05, digits=3) == "0.0500" and sig(123456.0, 1.0, 2) == "120000"


def test_log_frequency_axes_read_in_plain_numbers(single_report, campaign_report) -> None:
    # "10⁰, 10¹ kHz" (and only two labels on the 0.5–20 kHz sine axes) become 0.5, 1, 2, 5, 10, 20.
    checked = 0
    for caption, fig in single_report[1][:4] + campaign_report[1][:4]:
        laid_out(fig)
        for ax in fig.axes:
            if ax.get_xscale() != "log":
                continue
            labels = [t.get_text() for t in ax.get_xticklabels() + ax.get_xticklabels(minor=True)
                      if t.get_text() and t.get_visible()]
            lo, hi = ax.get_xlim()
            shown = [float(x) for x in labels if lo <= float(x) <= hi]
            assert "$" not in "".join(labels) and len(shown) >= 3, f"{caption}: {labels}"
            checked += 1
    assert checked >= 5


def test_the_spread_plots_give_mean_and_std_with_their_unit(campaign_report) -> None:
    # The legend read "mean 27" and "± 1 std (4.53e-05)": no unit, scientific notation.
    _report, pages = campaign_report
    fig = dict(pages)["Campaign: cross-validation and spread"]
    texts = [t.get_text() for ax in fig.axes if ax.get_legend() is not None for t in ax.get_legend().get_texts()]
    mean = next(t for t in texts if t.startswith("mean "))
    std = next(t for t in texts if t.startswith("± 1 std"))
    assert mean.endswith(" kHz") and std.endswith(" kHz)") and not SCIENTIFIC.search(mean + std), (mean, std)
    assert len(mean.split()[1].split(".")[1]) == len(std.split()[3].split(".")[1])  # to the decimals of the std


def test_the_cross_validation_numbers_contrast_with_their_cells(campaign_report) -> None:
    # Fits of 99.7-99.9 % on a 99-100 % scale sit on its light green-yellow end: the numbers were
    # white on it (the switch was at the midpoint of the data, not of the colour scale).
    _report, pages = campaign_report
    ax = dict(pages)["Campaign: cross-validation and spread"].axes[0]
    (image,) = ax.get_images()
    checked = 0
    for text in ax.texts:
        rgb = image.cmap(image.norm(float(text.get_text())))[:3]
        light = 0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2] > 0.45
        assert text.get_color() == ("black" if light else "white"), text.get_text()
        checked += 1
    assert checked == 4
