"""IAAL (Choi et al. 2018, "Nonparametric motion flow model for human-robot cooperation"): the
paper's strongest baseline, the same motion-flow similarity planner with an *exact* GP per demo.

It shares everything with :class:`agents.nonparametric.NonparametricAgent` (velocity convention,
hyperparameter rule, Eq. d with kappa and the zero-velocity rule, top-K blending, streaming,
closed loop); only the flow model differs, so any difference in RMS or speed is the sparse
approximation's. Per query and demo the exact GP costs O(N_k) for the mean and O(N_k^2) for the
variance, against O(M_k) and O(M_k^2) for FITC with M_k = ratio * N_k.
"""

from __future__ import annotations

from dataclasses import replace

from agents.nonparametric import NonparametricAgent, NonparametricConfig
from agents.predictive import ClosedLoopConfig
from handover_env.config import HandoverParams
from handover_env.envs.observation import ObsLayout


class IAALAgent(NonparametricAgent):
    """The nonparametric planner with exact GP motion flows.

    ``config.exact`` is forced True and ``config.inducing_ratio`` to 1.0 (an exact GP uses every
    sample), so the config reports what the model uses.

    Args:
        config: the shared planner settings; its ``inducing_ratio`` does not apply.
        params, closed_loop, layout: as for :class:`NonparametricAgent`.
    """

    def __init__(
        self,
        config: NonparametricConfig | None = None,
        params: HandoverParams | None = None,
        closed_loop: ClosedLoopConfig | None = None,
        layout: ObsLayout | None = None,
    ) -> None:
        super().__init__(
            replace(config or NonparametricConfig(), exact=True, inducing_ratio=1.0),
            params,
            closed_loop,
            layout,
        )
