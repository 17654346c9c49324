"""Plans: what the SST planner (and the reference search) hands to an agent -- a list of env
actions with the states and the cost it predicts (:func:`baselines.sst.planner.plan_soaring` is the
one-call planner that makes them).

Executing ``plan.actions`` through ``env.step`` from the state the plan starts at (after
``env.reset(options={"scenario": model.scenario})`` for the default start) reproduces
``plan.states`` and ``plan.edge_costs`` exactly: the planner propagates with the same model calls
the env makes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from baselines.sst.core import SSTResult, SSTStats
from baselines.sst.soaring import S_T, S_V, SoaringProblem
from soaring_env.model import GOAL


@dataclass(frozen=True)
class Plan:
    """A sequence of env actions with its predicted outcome.

    :param kind: ``"primitive"`` (actions are ints, ``soaring/Soaring-v0``) or ``"continuous"``
        (float32 (3,) arrays in [-1, 1], ``soaring/SoaringContinuous-v0``).
    :param actions: the env actions, in order.
    :param states: predicted states ``[Pn, Pe, chi, h]`` [m, m, rad, m] (n + 1, 4), start first;
        the last one is the first point inside the goal region if ``solved``.
    :param times: predicted times [s] (n + 1,).
    :param airspeeds: airspeed of each edge [m/s] (n,).
    :param edge_costs: predicted full cost of each edge [J/kg] (n,) (the env's ``info["edge_cost"]``).
    :param cost: their sum [J/kg] (the env's ``info["energy_spent"]`` at the end).
    :param solved: whether the plan ends in the goal region (else it ends at the tree node closest
        to the goal, or is empty).
    :param trajectory: every flown output point (M, 4), start first, for plots.
    """

    kind: str
    actions: tuple[Any, ...]
    states: np.ndarray
    times: np.ndarray
    airspeeds: np.ndarray
    edge_costs: np.ndarray
    cost: float
    solved: bool
    trajectory: np.ndarray

    def __len__(self) -> int:
        return len(self.actions)

    @property
    def flight_time(self) -> float:
        """Flight time from the start to the end of the plan [s] (the goal edge counts up to its
        first point inside the goal region)."""
        return float(self.times[-1] - self.times[0]) if len(self.times) else math.nan

    def controls(self) -> np.ndarray:
        """The actions as rows of the SST core's (and the reference search's) control vectors:
        (n, 1) primitive indices or (n, 3) normalized actions, as float64."""
        width = 1 if self.kind == "primitive" else 3
        return np.array([np.asarray(a, np.float64).reshape(width) for a in self.actions]).reshape(-1, width)

    def to_dict(self) -> dict[str, Any]:
        """JSON-able form (floats round-trip exactly through ``json``)."""
        acts = [int(a) if self.kind == "primitive" else np.asarray(a, np.float64).tolist() for a in self.actions]
        return {
            "kind": self.kind,
            "actions": acts,
            "states": self.states.tolist(),
            "times": self.times.tolist(),
            "airspeeds": self.airspeeds.tolist(),
            "edge_costs": self.edge_costs.tolist(),
            "cost": self.cost,
            "solved": self.solved,
            "flight_time": self.flight_time,
            "trajectory": self.trajectory.tolist(),
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Plan:
        kind = d["kind"]
        acts = tuple(int(a) if kind == "primitive" else np.asarray(a, np.float32) for a in d["actions"])
        return cls(
            kind=kind,
            actions=acts,
            states=np.asarray(d["states"], np.float64).reshape(-1, 4),
            times=np.asarray(d["times"], np.float64),
            airspeeds=np.asarray(d["airspeeds"], np.float64),
            edge_costs=np.asarray(d["edge_costs"], np.float64),
            cost=float(d["cost"]),
            solved=bool(d["solved"]),
            trajectory=np.asarray(d["trajectory"], np.float64).reshape(-1, 4),
        )


def plan_from_result(problem: SoaringProblem, res: SSTResult) -> Plan:
    """Turn a core result (a path of core states and controls) into a :class:`Plan`; the dense
    trajectory is re-flown edge by edge with the model."""
    n = len(res.controls)
    if len(res.states) == 0:
        root = problem.root_state()
        return Plan(
            kind=problem.kind,
            actions=(),
            states=root[None, :4].copy(),
            times=root[S_T : S_T + 1].copy(),
            airspeeds=np.zeros(0),
            edge_costs=np.zeros(0),
            cost=0.0,
            solved=False,
            trajectory=root[None, :4].copy(),
        )
    pts = [res.states[0, :4][None, :]]
    for i in range(n):
        s = res.states[i]
        m = problem.model
        if problem.kind == "primitive":
            r = m.rollout_primitive(s[:4], int(res.controls[i, 0]), t0=s[S_T], airspeed_prev=s[S_V])
        else:
            r = m.rollout_control(s[:4], m.action_to_control(res.controls[i]), t0=s[S_T], airspeed_prev=s[S_V])
        code, k = m.classify(r)
        kk = int(k[0]) if code[0] == GOAL else r.states.shape[1] - 1
        pts.append(r.states[0, : kk + 1])
        if not (np.array_equal(r.states[0, kk], res.states[i + 1, :4]) and r.cost[0] == res.edge_costs[i]):
            raise RuntimeError(f"internal error: edge {i} of the planned path does not re-fly to its tree node")
    return Plan(
        kind=problem.kind,
        actions=tuple(problem.to_action(u) for u in res.controls),
        states=res.states[:, :4].copy(),
        times=res.states[:, S_T].copy(),
        airspeeds=res.states[1:, S_V].copy(),
        edge_costs=res.edge_costs.copy(),
        cost=float(res.cost),
        solved=res.solved,
        trajectory=np.concatenate(pts, axis=0),
    )


@dataclass(frozen=True)
class PlanningResult:
    """A plan and the statistics of the planner run that produced it."""

    plan: Plan
    stats: SSTStats
