"""The paper's method as written (issue 17 item 5): the order rule on a curve with known
inflexions, Eq. 12's prefilter against plain least squares under coloured noise (a simulated
sensor with a known model), and PTB's record through the command line, where Eq. 12 diverges."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy import signal

from hopkinson.analysis.loss import arx_coefficients_by_order
from hopkinson.analysis.paper_method import inflexions, paper_order, prefiltered_arx
from hopkinson.drivers.sim.accelerometer import AccelerometerTruth, Mode
from hopkinson.drivers.sim.shock import half_sine_m_s2
from hopkinson.rig.cli.main import main
from tests.ptb_shock import write_ptb_record_csv


def test_the_order_is_the_second_inflexion_of_the_loss_trend() -> None:
    # log ||g2||² = 0, -1, -3, -3.5, -3.6, -5, -5.1 (orders 1..7): its second difference at orders
    # 2..6 is -1, +1.5, +0.4, -1.3, +1.3: the curvature changes at orders 3, 5 and 6
    loss = np.exp([0.0, -1.0, -3.0, -3.5, -3.6, -5.0, -5.1])
    assert inflexions(loss) == [3, 5, 6]
    assert paper_order(loss) == (5, "second inflexion")
    # no inflexion (log ||g2||² convex throughout): the first order after which the loss falls by
    # less than 1 % per order
    convex = np.array([1.0, 0.3, 0.1, 0.099, 0.0985])
    assert inflexions(convex) == [] and paper_order(convex) == (3, "stable loss")


def test_eq12_beats_plain_least_squares_under_coloured_noise() -> None:
    dt, n = 1e-6, 4000
    _, a_true = AccelerometerTruth(modes=(Mode(27_000.0, 0.05),)).discrete_tf(dt)
    b_true, _ = AccelerometerTruth(modes=(Mode(27_000.0, 0.05),)).discrete_tf(dt)
    u = half_sine_m_s2(np.arange(n) * dt, 38.6e-6, 1.0, start_s=200e-6)
    y0 = signal.lfilter(b_true, a_true, u)
    truth = np.sort_complex(np.roots(a_true))
    errors = []
    for seed in range(8):
        noise = np.random.default_rng(seed).normal(0.0, 0.01 * np.max(np.abs(y0)), n)
        y = y0 + signal.lfilter([1.0], [1.0, -0.95], noise)  # coloured output noise
        a_ls, _ = arx_coefficients_by_order(u, y, 2, method="qr")[-1]
        a_p, _, passes, converged = prefiltered_arx(u, y, 2)
        assert converged and passes > 1
        errors.append([np.max(np.abs(np.sort_complex(np.roots(a)) - truth)) for a in (a_ls, a_p)])
    errors = np.array(errors)
    assert np.all(errors[:, 1] < errors[:, 0])  # better in every seed
    assert np.median(errors[:, 1]) < 0.01 * np.abs(truth[0]) < np.median(errors[:, 0])


def test_ptb_through_the_command_line_as_the_paper_did(tmp_path: Path, capsys) -> None:
    # On the real record the trend of ||g2||² has its second inflexion at n = 4, the order the
    # paper chose; Eq. 12's first pass diverges (a pole outside the unit circle) and is said so.
    record = write_ptb_record_csv(tmp_path / "ptb.csv")
    model = tmp_path / "m.json"
    assert main(["identify", str(record), "--method", "paper", "--json", "-o", str(model)]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["order"] == 4 and result["order_rule"] == "second inflexion" and result["inflexions"][1] == 4
    assert not result["converged"] and "unstable" in result["warnings"][0]
    poles = np.array([complex(*p) for p in result["poles"]])
    assert np.all(np.abs(poles) < 1.0)  # the last stable estimate is what it keeps
    # the sine calibration's edges are 11.37 / 15.46 kHz: the literal method lands within 15 %
    assert result["fbsd_hz"]["5"] == pytest.approx(11.37e3, rel=0.15)
    assert result["fbsd_hz"]["10"] == pytest.approx(15.46e3, rel=0.15)
    assert main(["dcm", "--model", str(model), "--json"]) == 0  # the rest of the chain reads it
