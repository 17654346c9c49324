"""The optimality yardstick: a deterministic reference search over the model, bounds and regret.

* :mod:`baselines.reference.beam` -- the beam search with cell dominance over control sequences
  (primitives or a continuous control grid) that returns the same :class:`~baselines.sst.plan.Plan`
  as SST.
* :mod:`baselines.reference.bounds` -- the hard lower bound, the model without thermals, regret.
* :mod:`baselines.reference.yardstick` -- the reference of a scenario (bounds, direct cost, best
  plan per action set) and its JSON files under ``results/reference/``.
"""

from baselines.reference.beam import ReferenceConfig, SearchResult, control_set, glide_angle, search
from baselines.reference.bounds import MIN_GAP, height_cap, lower_bound, regret, without_thermals
from baselines.reference.yardstick import (
    SamplerReference,
    ScenarioReference,
    compute_reference,
    load_reference,
    load_references,
    reference_path,
    save_reference,
)

__all__ = [
    "MIN_GAP",
    "ReferenceConfig",
    "SamplerReference",
    "ScenarioReference",
    "SearchResult",
    "compute_reference",
    "control_set",
    "glide_angle",
    "height_cap",
    "load_reference",
    "load_references",
    "lower_bound",
    "reference_path",
    "regret",
    "save_reference",
    "search",
    "without_thermals",
]
