"""The Hopkinson bar's physics: materials, geometry and launcher, exact 1-D wave
propagation with contacts that carry compression only, the bar's geometric dispersion, the
calibrated object's acceleration and flight, and shot planning. Pure NumPy/SciPy."""

from hopkinson.analysis.bar.geometry import G_M_S2, PAPER_RIG, BarRig, Launcher, Projectile, Segment
from hopkinson.analysis.bar.materials import MATERIALS, Material
from hopkinson.analysis.bar.planning import PAPER_RULE, ShotPlan, plan_shot
from hopkinson.analysis.bar.predict import ShotPrediction, predict_shot, speed_for_peak

__all__ = ["G_M_S2", "MATERIALS", "PAPER_RIG", "PAPER_RULE", "BarRig", "Launcher", "Material", "Projectile", "Segment", "ShotPlan",
           "ShotPrediction", "plan_shot", "predict_shot", "speed_for_peak"]
