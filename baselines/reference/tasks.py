"""The reference searches of the soaring tasks (``soaring_env.env.tasks``): which search, with which
settings, for a task env -- one home for the results table (:mod:`baselines.tasks`), the
demonstrations of behaviour cloning (``scripts/demos.py --task xc``) and the ``"grid"`` PPO
policy's control set (:func:`baselines.ppo.control_grid`).

* thermal climb (no goal): :func:`~baselines.reference.horizon.energy_search`, the most energy
  gained over the time limit;
* cross-country (goal and battery): the goal-reaching beam search
  (:func:`~baselines.reference.beam.search`) with the battery as a budget, a progress term in its
  ranking and a control set of its own (:data:`XC_SPEEDS` x :data:`XC_TURNS_DEG`, level and at the
  zero-thrust glide angle);
* goal reaching: the yardstick's search (:class:`~baselines.reference.beam.ReferenceConfig` defaults);
  on the physical envelope (``envelope="physical"``, whose airspeeds and turn rates exclude the
  yardstick's 10 m/s and 1080-degree controls) the cross-country grid with a powered climb
  (:data:`GOAL_PHYSICAL_GAMMAS_DEG`) and its progress term.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Mapping, Sequence
from typing import Any

import gymnasium as gym
import numpy as np

from baselines.reference.beam import (
    XC_SPEEDS,
    XC_TURNS_DEG,
    ReferenceConfig,
    envelope_grid,
    search,
)
from baselines.reference.bounds import lower_bound, without_thermals
from baselines.reference.horizon import HorizonConfig, energy_search
from baselines.reference.yardstick import SamplerReference, ScenarioReference, sampler_config
from soaring_env._validation import ConfigError
from soaring_env.scenario import Scenario

#: Beam width of the tasks' reference searches (the accuracy knob; ``scripts/tasks.py --beam-width``).
DEFAULT_BEAM_WIDTH = 500
#: The cross-country ranking's progress weight (see ReferenceConfig.progress_weight); its grid:
#: :data:`~baselines.reference.beam.XC_SPEEDS` x :data:`~baselines.reference.beam.XC_TURNS_DEG`.
XC_PROGRESS_WEIGHT = 0.5
#: First beam width of the cross-country reference's iterative widening (then doubled up to the knob).
XC_START_WIDTH = 125
#: Time weight [J/kg per s] of the cross-country demonstrations (``scripts/demos.py --task xc``;
#: ReferenceConfig.time_weight): plans alike in energy that arrive sooner win, so the demonstrator
#: leaves a thermal once it climbs slower than about 0.1 m/s instead of circling at its top until
#: the time limit nears (a choice a policy cannot copy: it depends on the minutes left, not on
#: what the lift does). The results table's reference keeps 0: the least energy.
XC_DEMO_TIME_WEIGHT = 1.0
#: Floor [m] of the cross-country demonstrations (ReferenceConfig.min_height): the least-energy
#: plans glide to a thermal with little height to spare (some within metres of the ground), a
#: margin a cloned policy's judgement does not have; above the floor it can still motor on.
XC_DEMO_MIN_HEIGHT = 150.0
#: Bumped when the tasks' reference settings change (records of another version are redone).
REFERENCE_VERSION = 2


def env_keywords(env_kwargs: Mapping[str, Any] | None) -> dict[str, Any]:
    """``env_kwargs`` (``gym.make`` keywords of a task env, or None: the id's defaults) as a dict;
    anything but a mapping raises a :class:`ConfigError` naming it."""
    if env_kwargs is not None and not isinstance(env_kwargs, Mapping):
        raise ConfigError(f"env_kwargs={env_kwargs!r} must be a mapping of gym.make keywords or None")
    return dict(env_kwargs or {})


def goal_config(beam_width: int) -> ReferenceConfig:
    """The yardstick's search at ``beam_width``, iterative widening from the same first width (or
    from ``beam_width`` itself where that is narrower): goal reaching's demonstrations and grid."""
    return ReferenceConfig(beam_width=beam_width, start_width=min(beam_width, ReferenceConfig.start_width))


def reference_config(
    env: gym.Env, beam_width: int = DEFAULT_BEAM_WIDTH, time_weight: float = 0.0, min_height: float = 0.0
) -> HorizonConfig | ReferenceConfig:
    """The reference search settings of a task env, or of the goal-reaching env (the yardstick's
    :class:`ReferenceConfig` with ``beam_width``); ``time_weight`` [J/kg per s] and ``min_height``
    [m]: the goal searches' (:attr:`ReferenceConfig.time_weight`, ``.min_height``; cross-country and
    goal reaching; the thermal climb, which has no goal, refuses any but 0)."""
    base: Any = env.unwrapped
    xc = base.has_goal and getattr(base, "has_battery", False)
    for name, v in (("time_weight", time_weight), ("min_height", min_height)):
        if v != 0.0 and not base.has_goal:
            raise ConfigError(f"{name}={v!r}; allowed: 0 (the thermal climb's search has none)")
    if not base.has_goal:
        return HorizonConfig(beam_width=beam_width)
    if not xc:
        cfg = goal_config(beam_width)
        grid = envelope_grid(base.model) if base.continuous else {}
        if grid:
            # measured on held-out scenarios at Ts = 10 s: without the progress term the beam keeps
            # the straight glide and misses the climbs the 30 s yardstick finds (docs/learning-to-soar.md, round six)
            cfg = dataclasses.replace(cfg, **grid, progress_weight=XC_PROGRESS_WEIGHT)
        return dataclasses.replace(cfg, max_edges=_episode_steps(base), time_weight=time_weight, min_height=min_height)
    steps = _episode_steps(base)
    # iterative widening from a fixed first width: the best plan can only improve as the knob doubles
    kw: dict[str, Any] = {"beam_width": beam_width, "start_width": min(XC_START_WIDTH, beam_width), "max_edges": steps}
    if base.continuous:
        kw.update(speeds=XC_SPEEDS, turns_deg=XC_TURNS_DEG, gammas_deg=(0.0,))
    return ReferenceConfig(**kw, progress_weight=XC_PROGRESS_WEIGHT, time_weight=time_weight, min_height=min_height)


def _episode_steps(base: Any) -> int:
    """The most steps an episode of the env ``base`` has (:attr:`~soaring_env.env.core.SoaringBaseEnv.episode_steps`;
    neither a step nor a time limit: the search's default depth)."""
    steps = base.episode_steps
    return ReferenceConfig.max_edges if steps is None else int(steps)


def reference_plan(
    env: gym.Env, beam_width: int = DEFAULT_BEAM_WIDTH, time_weight: float = 0.0, min_height: float = 0.0
) -> tuple[list[Any], dict[str, Any]]:
    """The reference search's plan from the state ``env`` is in: (env actions, stats).

    Goal tasks plan from any state of an episode (its time, the airspeed flown last, the battery
    and the steps left), so a plan from a state a policy reached replays exactly from there; the
    thermal climb plans from a fresh reset only.

    ``stats["predicted_energy"]`` is the energy the plan gains from that state [J/kg]
    (``-energy_spent`` when replayed through ``env.step`` from a reset); ``stats["found"]`` whether
    it reaches the goal (goal tasks).

    :param time_weight, min_height: see :func:`reference_config`.
    :raises ConfigError: a thermal climb that is not at its start.
    """
    base: Any = env.unwrapped
    sampler = "continuous" if base.continuous else "primitive"
    cfg = reference_config(env, beam_width, time_weight, min_height)
    t0 = time.perf_counter()
    stats: dict[str, Any]
    if isinstance(cfg, HorizonConfig):
        if base.steps:
            raise ConfigError(f"the thermal-climb reference plans from a reset; this env is at step {base.steps}")
        r = energy_search(base.model, sampler, base.config.time_limit, cfg)
        actions = list(r.actions)
        predicted = r.energy
        stats = {"rollouts": r.rollouts, "n_controls": r.n_controls, "found": math.isfinite(r.energy)}
    else:
        if base.steps:  # mid-episode: the state as a start, the steps and battery left
            cfg = dataclasses.replace(cfg, max_edges=max(_episode_steps(base) - base.steps, 1))
        sc = base.scenario
        model = dataclasses.replace(base.model, scenario=sc.replace(start=tuple(float(v) for v in base.state[:4])))
        v_prev = float(base.airspeed_prev)
        t_now, v0 = float(base.time), (v_prev if math.isfinite(v_prev) else None)
        seeds: list[np.ndarray] = []
        n_direct = 0
        if not getattr(base, "has_battery", False):  # goal reaching: seeded with the direct plan, as
            # the yardstick's search is, so that it finds a plan wherever flying past the thermals does
            direct = search(without_thermals(model), sampler, cfg, t0=t_now, airspeed_prev=v0)
            seeds = [direct.plan.controls()] if direct.plan.solved else []
            n_direct = direct.rollouts
        s = search(
            model, sampler, cfg, seed_controls=seeds, battery=float(base.battery_left), t0=t_now, airspeed_prev=v0
        )
        actions = list(s.plan.actions)
        predicted = -s.cost
        stats = {"rollouts": s.rollouts + n_direct, "n_controls": s.n_controls, "found": bool(s.plan.solved)}
    stats.update(seconds=time.perf_counter() - t0, predicted_energy=predicted, settings=dataclasses.asdict(cfg))
    return actions, stats


def task_reference(
    env_id: str,
    scenario: Scenario,
    beam_width: int = DEFAULT_BEAM_WIDTH,
    prefix: Sequence[Any] = (),
    time_weight: float = 0.0,
    min_height: float = 0.0,
    env_kwargs: Mapping[str, Any] | None = None,
) -> ScenarioReference:
    """The reference plan of a goal task (``env_id``, e.g. the cross-country's) in ``scenario``, as
    the content of a reference file: the env's action set only, its ``best_cost`` the energy the
    whole plan spends when replayed through ``env.step`` [J/kg] (inf: it does not reach the goal);
    ``direct_cost`` is NaN (not searched).

    :param prefix: env actions flown first (a DAgger start: the steps a policy took to reach the
        state the search plans from); the plan's ``actions`` begin with them, ``demo_from`` is
        their number.
    :param time_weight: the search's time weight [J/kg per s] (:func:`reference_config`;
        :data:`XC_DEMO_TIME_WEIGHT` for demonstrations), recorded in the file's settings.
    :param min_height: the search's floor [m] (likewise; :data:`XC_DEMO_MIN_HEIGHT`).
    :param env_kwargs: ``gym.make`` keywords of the env (e.g. goal reaching at Ts = 10 s on the
        physical envelope), recorded in the file.
    :raises ConfigError: a task without a goal (the thermal climb has no plan to reach anything),
        or a prefix that ends the episode.
    """
    if not isinstance(scenario, Scenario):
        raise ConfigError(f"scenario={scenario!r} must be a soaring_env.scenario.Scenario")
    if isinstance(beam_width, bool) or not isinstance(beam_width, int) or beam_width < 1:
        raise ConfigError(f"beam_width={beam_width!r} must be an integer >= 1")
    kwargs = env_keywords(env_kwargs)
    try:
        env = gym.make(env_id, **kwargs)
    except gym.error.Error as exc:  # not a registered id
        raise ConfigError(f"env_id={env_id!r} is not a registered soaring env ({exc})") from None
    try:
        base: Any = env.unwrapped
        if not base.has_goal:
            raise ConfigError(f"env_id={env_id!r} has no goal; task references need a goal task (cross-country)")
        sampler = "continuous" if base.continuous else "primitive"
        prefix = [np.asarray(a, np.float32) if sampler == "continuous" else int(a) for a in prefix]
        env.reset(seed=0, options={"scenario": scenario})
        for k, a in enumerate(prefix):
            _, _, terminated, truncated, _ = env.step(a)
            if terminated or truncated:
                raise ConfigError(f"prefix: the episode ends at step {k + 1} of {len(prefix)}; nothing to plan")
        settings = reference_config(env, beam_width, time_weight, min_height)
        assert isinstance(settings, ReferenceConfig)
        suffix, stats = reference_plan(env, beam_width, time_weight, min_height)
        actions = [*prefix, *suffix]
        cost = math.inf
        if stats["found"]:  # the whole plan, flown from the reset: the energy it spends
            env.reset(seed=0, options={"scenario": scenario})
            info: dict[str, Any] = {}
            for a in actions:
                *_, info = env.step(a)
            if info.get("is_success"):
                cost = float(base.energy_spent)
        ref = SamplerReference(
            best_cost=cost,
            direct_cost=math.nan,
            actions=[np.asarray(a).tolist() if sampler == "continuous" else int(a) for a in actions],
            direct_actions=[],
            flight_time=len(actions) * float(base.library.duration),
            settings=sampler_config(settings, sampler).to_dict(),
            rollouts=int(stats["rollouts"]),
            seconds=float(stats["seconds"]),
            demo_from=len(prefix),
            env_kwargs=kwargs,
        )
        return ScenarioReference(scenario=scenario, lower_bound=lower_bound(base.model), samplers={sampler: ref})
    finally:
        env.close()
