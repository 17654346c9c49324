"""Stable Sparse RRT (Li, Littlefield, Bekris 2016) for energy-aware soaring path planning.

* :mod:`baselines.sst.core` -- the generic batched SST (knows nothing about aircraft);
* :mod:`baselines.sst.reference` -- a plain unbatched SST (yardstick and test oracle);
* :mod:`baselines.sst.samplers` -- control samplers (finite index set, normalized box);
* :mod:`baselines.sst.soaring` -- the adapter that plugs :class:`soaring_env.model.SoaringModel` in;
* :mod:`baselines.sst.plan` -- plans (env actions + predicted states and cost);
* :mod:`baselines.sst.planner` -- ``plan_soaring`` / ``make_planner`` for named or given
  configurations, and :class:`SeededSST` (SST that starts from a reference search's plan);
* :mod:`baselines.sst.agent` -- :class:`SSTAgent`, which plans on reset and acts through an env.
"""

from baselines.sst.agent import SSTAgent
from baselines.sst.core import SST, Edges, Problem, SSTError, SSTParams, SSTResult, SSTStats, StateSpace
from baselines.sst.plan import Plan, PlanningResult, plan_from_result
from baselines.sst.planner import SeededSST, make_planner, plan_soaring
from baselines.sst.reference import ReferenceSST
from baselines.sst.samplers import BoxSampler, IndexSampler
from baselines.sst.soaring import SoaringProblem, SoaringSSTConfig

__all__ = [
    "SST",
    "BoxSampler",
    "Edges",
    "IndexSampler",
    "Plan",
    "PlanningResult",
    "Problem",
    "ReferenceSST",
    "SSTAgent",
    "SSTError",
    "SSTParams",
    "SSTResult",
    "SSTStats",
    "SeededSST",
    "SoaringProblem",
    "SoaringSSTConfig",
    "StateSpace",
    "make_planner",
    "plan_from_result",
    "plan_soaring",
]
