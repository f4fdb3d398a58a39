"""The shot set-up's planner: a target peak (g) and, optionally, the sensor's natural frequency
→ for each projectile of the rig's `[bar]`, the pressure, the pulse width δ, the supported band
and whether δ ≤ 1.06/f_n (analysis.bar.plan_shot, the same as `hopkinson plan-shot`), planned
again whenever a field changes; "Use" puts the chosen projectile and pressure into the form. Pure computation: nothing is fired.
"""

from __future__ import annotations

from collections.abc import Callable, Collection
from html import escape

from PySide6.QtWidgets import QLabel, QPushButton, QVBoxLayout, QWidget

from hopkinson.analysis.bar import G_M_S2, ShotPlan, plan_shot
from hopkinson.rig.config import RigConfig
from hopkinson.ui.inputs import UnitSpinBox


class ShotPlanner(QWidget):
    """Target peak and sensor f_n in (`target_g`, `sensor_fn_khz`: the owner's form lays them
    out), the plan shown (this widget), and its choice handed to `apply` (projectile,
    pressure_bar) when the technician presses "Use"."""

    def __init__(self, config: RigConfig, apply: Callable[[int, float], None], loadable: Collection[int],
                 parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self._loadable = frozenset(loadable)  # the projectiles the form (and the rig's loader) can take
        self._rig = config.bar.rig()
        self._limits = config.limits
        self._apply = apply
        self.plan: ShotPlan | None = None
        self.target_g = UnitSpinBox("Target peak", "g", (10.0, 2e6), 50_000.0, decimals=0, step=1000.0, special="—",
                                    tip="the peak acceleration the shot should reach (9.80665 m/s² per g)")
        self.sensor_fn_khz = UnitSpinBox("Sensor f_n", "kHz", (1.0, 2000.0), 0.0, decimals=1, step=1.0,
                                         special="not named",
                                         tip="the sensor's natural frequency in kHz: is δ ≤ 1.06/f_n (the paper's "
                                             "Eq. 36)?")
        self.use_button = QPushButton("Use")
        self.use_button.setToolTip("set the form's projectile and pressure to the plan's choice")
        self.use_button.setEnabled(False)
        self.use_button.clicked.connect(self._use)
        self.result = QLabel("")
        self.result.setWordWrap(True)
        self.result.setStyleSheet("color: #202124;")

        # The two fields go into the set-up's form (its rows); this widget is the plan and "Use".
        layout = QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.setSpacing(2)
        layout.addWidget(self.result)
        layout.addWidget(self.use_button)
        self.target_g.value_accepted.connect(self.update_plan)
        self.sensor_fn_khz.value_accepted.connect(self.update_plan)
        self.update_plan()

    def update_plan(self) -> None:
        """Plan the shot for the fields' target and f_n and show it."""
        target_m_s2 = self.target_g.value() * G_M_S2
        fn_hz = self.sensor_fn_khz.value() * 1e3 or None
        if target_m_s2 <= 0:
            self.plan = None
            self.result.setText("give a target peak")
            self.use_button.setEnabled(False)
            return
        try:
            self.plan = plan_shot(self._rig, target_m_s2, sensor_fn_hz=fn_hz,
                                  min_pressure_bar=self._limits.min_pressure_bar,
                                  max_pressure_bar=self._limits.max_pressure_bar)
        except ValueError as exc:  # a [bar] the model cannot use: said, nothing set
            self.plan = None
            self.result.setText(f"<span style='color:#b3261e'>cannot plan: {escape(str(exc))}</span>")
            self.use_button.setEnabled(False)
            return
        self.result.setText(plan_html(self.plan))
        chosen = self.chosen_option()
        self.use_button.setEnabled(chosen is not None and chosen[0] in self._loadable)
        if chosen is not None:
            self.use_button.setText(f"Use No. {chosen[0]} at {chosen[1]:.2f} bar" if chosen[0] in self._loadable
                                    else f"No. {chosen[0]} cannot be loaded here")

    def chosen_option(self) -> tuple[int, float] | None:
        """(projectile, pressure_bar) of the plan's choice, None when nothing reaches the target."""
        if self.plan is None or self.plan.chosen is None:
            return None
        option = next(o for o in self.plan.options if o.projectile == self.plan.chosen)
        return option.projectile, option.pressure_bar

    def _use(self) -> None:
        chosen = self.chosen_option()
        if chosen is not None:
            self._apply(*chosen)


def plan_html(plan: ShotPlan) -> str:
    """The plan as a small table (one row per projectile) and its verdict."""
    rows = ["<tr><th>No.</th><th>pressure</th><th>δ</th><th>band</th><th>excites</th></tr>"]
    for o in plan.options:
        rule = "—" if o.paper_rule_holds is None else ("yes" if o.paper_rule_holds else "no")
        style = "" if o.reachable else " style='color:#80868b'"
        pressure = f"{o.pressure_bar:.2f} bar" if o.reachable else f"{o.pressure_bar:.3g} bar ✗"
        mark = " ◀" if o.projectile == plan.chosen else ""
        rows.append(f"<tr{style}><td>{o.projectile}{mark}</td><td>{pressure}</td><td>{o.width_s * 1e6:.1f} µs</td>"
                    f"<td>{o.supported_band_hz / 1e3:.0f} kHz</td><td>{rule}</td></tr>")
    verdict = (f"load No. {plan.chosen}: {escape(plan.reason)}" if plan.chosen is not None
               else f"<span style='color:#b3261e'>{escape(plan.reason)}</span>")
    return f"<table cellspacing='0' cellpadding='2'>{''.join(rows)}</table><div>{verdict}</div>"
