"""What an identification found besides its model, as typed records: why this order
(`OrderEvidence`) and the noise (`NoiseReport`). Each `to_dict()` writes the results'
`identification.order_evidence` / `identification.noise` as the results JSON holds them."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

from hopkinson.analysis.model_error import ModelError
from hopkinson.analysis.order_choice import OrderStability
from hopkinson.analysis.structure import Structure
from hopkinson.analysis.trail import NoiseLevels, Stretch


@dataclass(frozen=True)
class DelayBranch:
    """A delay branch the final fit weighed: the model's delay (samples) and its cost V."""

    delay_samples: float
    cost: float

    def to_dict(self) -> dict[str, Any]:
        return {"delay_samples": self.delay_samples, "cost": self.cost}


@dataclass(frozen=True)
class OrderEvidence:
    """Why this order: the order test's comparisons and figures by order, the structure and why,
    the order's stability on noise draws (None: not measured).

    `settled_stability` was measured by the settle stage (options.stability_draws),
    `later_stability` by the uncertainty's draws (`with_stability`); `stability` is either.
    """

    comparisons: Any  # the order test's comparisons (analysis.order_choice.choose_order)
    structure: Structure
    structure_reason: str
    criterion: str  # the order test's rule in words
    chosen: int | None  # the order test's choice (None: no candidate)
    selection: str  # "order_test" or "asked"
    bins: int  # fitted bins
    parameters_by_order: dict[int, int]
    cost_by_order: dict[int, float]  # V
    response_change_to_next_order: dict[int, float]  # relative RMS change of the weighted response
    settled_stability: OrderStability | None = None
    unstable_when_converged: tuple[int, ...] = ()  # orders whose converged fit was unstable
    delay_branches: tuple[DelayBranch, ...] = ()  # the final fit's branch first (none: one branch)
    later_stability: OrderStability | None = None

    @property
    def stability(self) -> OrderStability | None:
        return self.settled_stability or self.later_stability

    def with_stability(self, stability: OrderStability) -> OrderEvidence:
        """This evidence with the stability the uncertainty measured (kept: the settle stage's)."""
        if self.stability is not None:
            return self
        return replace(self, later_stability=stability)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready but for NumPy numbers (the caller's `jsonable`), in the results' order."""
        out: dict[str, Any] = {}
        if self.settled_stability is not None:
            out["stability"] = self.settled_stability.to_dict()
        if self.unstable_when_converged:
            out["unstable_when_converged"] = list(self.unstable_when_converged)
        if self.delay_branches:
            out["delay_branches"] = [b.to_dict() for b in self.delay_branches]
        out.update({
            "comparisons": self.comparisons,
            "structure": self.structure.value,
            "structure_reason": self.structure_reason,
            "criterion": self.criterion,
            "chosen": self.chosen,
            "selection": self.selection,
            "bins": self.bins,
            "parameters_by_order": {str(n): v for n, v in self.parameters_by_order.items()},
            "cost_by_order": {str(n): v for n, v in self.cost_by_order.items()},
            "response_change_to_next_order": {str(n): v for n, v in self.response_change_to_next_order.items()},
        })
        if self.later_stability is not None:
            out["stability"] = self.later_stability.to_dict()
        return out


@dataclass(frozen=True)
class LeadIn:
    """The lead-in at rest the noise was measured on (s on the record's clock)."""

    start_s: float
    stop_s: float
    to_foot: bool  # it reaches to a quarter of the pulse's width before its foot

    def to_dict(self) -> dict[str, Any]:
        return {"start_s": self.start_s, "stop_s": self.stop_s, "to_foot": self.to_foot}


@dataclass(frozen=True)
class NoiseReport:
    """The noise of an identification: each channel's level and where it was measured (channel
    units), the final fit's residual, the model error, the lead-in and the motion after the pulse."""

    levels: NoiseLevels
    residual_rms: float  # response units
    v_per_degree_of_freedom: float
    model_error: ModelError
    lead_in: LeadIn | None  # None: the pulse starts too near the record's start
    motion_after_pulse: tuple[Stretch, ...]

    @property
    def reference_rms(self) -> float | None:
        return self.levels.reference_rms

    @property
    def response_rms(self) -> float | None:
        return self.levels.response_rms

    def to_dict(self) -> dict[str, Any]:
        return {
            **self.levels.to_dict(),
            "residual_rms": self.residual_rms,
            "v_per_degree_of_freedom": self.v_per_degree_of_freedom,
            "model_error": self.model_error.to_dict(),
            "lead_in": self.lead_in.to_dict() if self.lead_in is not None else None,
            "motion_after_pulse": [m.to_dict() for m in self.motion_after_pulse],
        }
