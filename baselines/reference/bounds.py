"""Bounds and regret: the arithmetic of the optimality yardstick (see :mod:`baselines.reference`).

* ``lower_bound`` -- a cost no plan can beat [J/kg]. Edge cost = fuel + kinetic - g dh with
  fuel, kinetic >= 0, so the height terms telescope: J >= -g (h_end - h_start). A plan ends with the
  edge that enters the goal region; the env charges that edge to its end (Ts), after its first
  point inside the region, so h_end <= goal top + w_max (Ts - Ts/N), where w_max bounds the updraft
  of any thermal that can reach the goal region (powered climbing never lowers the cost: it pays
  at least g dh / eta >= g dh in fuel). Without such a thermal the bound is -g (goal top - h_start).
* Regret ``r = (J - J_best) / (J_direct - J_best)``: 0 = as good as the best known plan, 1 = no
  better than ignoring the thermals, > 1 worse, < 0 better than the reference (the search is not
  exact). Where ``J_direct - J_best`` is below :data:`MIN_GAP` the thermals offer (almost) nothing
  and r is undefined (NaN); report the absolute cost there. "Thermal benefit captured" is ``1 - r``.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from soaring_env._validation import ConfigError
from soaring_env.model import SoaringModel
from soaring_env.physics.atmosphere import G

#: Below this gap between the direct and the best cost [J/kg] (2.5 m of height) regret is undefined.
MIN_GAP = 25.0


def height_cap(model: SoaringModel) -> float:
    """Highest height [m] a plan can end at, for the bound (:meth:`SoaringModel.end_height_cap`)."""
    return model.end_height_cap()


def lower_bound(model: SoaringModel) -> float:
    """The hard lower bound on the cost of any plan [J/kg] (module docstring)."""
    return -G * (height_cap(model) - model.scenario.start[3])


def without_thermals(model: SoaringModel) -> SoaringModel:
    """The same model in the same wind with every thermal removed."""
    sc = model.scenario
    return dataclasses.replace(model, scenario=sc.replace(field=dataclasses.replace(sc.field, thermals=())))


def regret(cost: float, best: float, direct: float) -> float:
    """``(cost - best) / (direct - best)``; NaN if a value is missing or the gap is below MIN_GAP."""
    for name, v in (("cost", cost), ("best", best), ("direct", direct)):
        if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
            raise ConfigError(f"{name}={v!r} must be a number [J/kg]")
    if not (math.isfinite(cost) and math.isfinite(best) and math.isfinite(direct)) or direct - best < MIN_GAP:
        return math.nan
    return (cost - best) / (direct - best)
