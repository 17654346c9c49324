""":class:`SSTAgent`: an SST planner behind the ``predict`` interface of stable-baselines3 agents.

It plans with the model the env exposes (``env.unwrapped.model``, the env's current ``state``,
``time`` and ``airspeed_prev``) and then returns the plan's actions one per ``predict`` call, so it
is scored through ``env.step`` like any other agent. It never imports the env package: it is given
the env object. SST knows the thermal field; say so when comparing it with learned agents.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from baselines.sst.core import SSTError, SSTStats, check_budget
from baselines.sst.plan import Plan
from baselines.sst.planner import as_sst_config, plan_soaring
from baselines.sst.soaring import SoaringSSTConfig
from soaring_env._validation import check_int


class SSTAgent:
    """Plan on reset, then act through the env.

    Replanning: ``predict`` plans again (from the env's current state, time and airspeed) at the
    start of an episode, when the plan is used up, or when the env's state is not the one the plan
    predicted for this step. If no solution is found within the budget, the agent follows the
    path to the tree node closest to the goal and plans again from there (receding horizon).

    :param env: the env the agent acts in (wrappers allowed; for an SB3 ``DummyVecEnv`` pass
        ``vec_env.envs[0]``). Its ``unwrapped`` must expose ``model``, ``state``, ``time`` and
        ``airspeed_prev``; a ``Discrete`` action space selects the primitive sampler, a ``Box``
        the continuous one.
    :param time_limit: wall-clock planning budget per plan [s].
    :param max_iterations: iteration budget per plan (deterministic plans; at least one budget).
    :param seed: planner seed; the k-th plan of the agent uses ``seed + k``.
    :param config: planner settings (radii, distance weights, batch size). Unless it sets
        ``max_edges``, plans are limited to the steps left before the env's ``max_steps`` or
        ``time_limit`` (``episode_steps``) or an outer ``TimeLimit``'s ``max_episode_steps``.

    On a task with a battery (``unwrapped.has_battery``, cross-country) every plan keeps within
    the battery left (``unwrapped.battery_left``): edges that would empty it are invalid.
    """

    def __init__(
        self,
        env: Any,
        *,
        time_limit: float | None = 1.0,
        max_iterations: int | None = None,
        seed: int = 0,
        config: SoaringSSTConfig | Mapping[str, Any] | None = None,
    ) -> None:
        if not hasattr(env, "unwrapped") or not hasattr(env, "action_space"):
            raise SSTError(f"env={env!r} is not a gymnasium env (needs .unwrapped and .action_space)")
        self.time_limit, self.max_iterations = check_budget(time_limit, max_iterations)
        self.env = env
        self.seed = check_int("seed", seed, 0, 2**62)
        self.config = None if config is None else as_sst_config(config)
        self.sampler = "primitive" if hasattr(env.action_space, "n") else "continuous"
        self.plan_: Plan | None = None
        self.stats: SSTStats | None = None
        self.n_plans = 0
        self._step = 0
        self._vp0 = math.nan

    def reset(self, env: Any = None) -> Plan:
        """Plan from the env's current state (call after ``env.reset``); returns the plan."""
        if env is not None:
            self.env = env
        u = self.env.unwrapped
        model = u.model
        state = np.array(u.state, dtype=np.float64)
        vp = getattr(u, "airspeed_prev", None)
        vp = None if vp is None or not np.isfinite(vp) else float(vp)
        cfg = self.config or SoaringSSTConfig()
        limit = getattr(u, "episode_steps", None)  # the env's step or time limit
        spec_limit = getattr(getattr(self.env, "spec", None), "max_episode_steps", None)  # a TimeLimit
        if spec_limit is not None:
            limit = spec_limit if limit is None else min(int(limit), int(spec_limit))
        if limit is not None and cfg.max_edges is None:
            # plan within the steps the episode has left (the TimeLimit would truncate a longer plan)
            left = max(1, int(limit) - int(getattr(u, "steps", 0)))
            cfg = dataclasses.replace(cfg, max_edges=left)
        battery = float(u.battery_left) if getattr(u, "has_battery", False) else None
        res = plan_soaring(
            model,
            self.sampler,
            time_limit=self.time_limit,
            max_iterations=self.max_iterations,
            seed=self.seed + self.n_plans,
            config=cfg,
            start=state,
            t0=float(getattr(u, "time", 0.0)),
            airspeed_prev=vp,
            partial=True,
            battery=battery,
        )
        self.n_plans += 1
        self._vp0 = math.nan if vp is None else vp
        self.plan_ = res.plan
        self.stats = res.stats
        self._step = 0
        return res.plan

    plan = reset

    def _fallback(self) -> Any:
        """Straight and level at the highest primitive speed (when the tree has only its root)."""
        model = self.env.unwrapped.model
        table = model.library.table
        straight_level = np.flatnonzero((table[:, 0] == 0) & (table[:, 2] == 0.0))
        idx = int(straight_level[np.argmax(table[straight_level, 1])])
        if self.sampler == "primitive":
            return idx
        ctrl = np.array([table[idx, 1], 0.0, 0.0])
        return np.asarray(model.control_to_action(ctrl), np.float32)

    def _on_plan(self, u: Any, p: Plan) -> bool:
        """Whether the env is where the plan expects it before step ``self._step``."""
        i = self._step
        if not np.array_equal(np.asarray(u.state, np.float64), p.states[i]) or float(u.time) != p.times[i]:
            return False
        vp = getattr(u, "airspeed_prev", None)
        vp = math.nan if vp is None else float(vp)
        expected = self._vp0 if i == 0 else float(p.airspeeds[i - 1])
        return vp == expected or (math.isnan(vp) and math.isnan(expected))

    def predict(
        self,
        observation: Any,
        state: Any = None,
        episode_start: Any = None,
        deterministic: bool = True,
    ) -> tuple[Any, None]:
        """The next action of the plan (SB3 signature; ``state`` and ``deterministic`` are unused).

        :returns: ``(action, None)``; the action is batched (leading axis of 1) if the observation is.
        """
        u = self.env.unwrapped
        p = self.plan_
        if (
            p is None
            or (episode_start is not None and bool(np.any(episode_start)) and self._step > 0)
            or self._step >= len(p)
            or not self._on_plan(u, p)
        ):
            p = self.reset()
        if len(p) == 0:
            action = self._fallback()
        else:
            action = p.actions[self._step]
            self._step += 1
        obs_shape = getattr(getattr(self.env, "observation_space", None), "shape", None)
        if obs_shape is not None and np.ndim(observation) == len(obs_shape) + 1:
            action = np.asarray([action])
        return action, None
