"""Behaviour cloning from the reference search: demonstrations that soar, for the PPO agents.

PPO on the goal task finds the straight line within minutes and never the detour through a
thermal (docs/learning-to-soar.md): the climb pays only once it has been flown to the
end, and random exploration around a straight-flying policy does not fly one. The reference search
(:mod:`baselines.reference`) does: per scenario it returns a plan in the env's own action space
(continuous ``[-1, 1]^3`` controls or primitive indices) that replays bit for bit through
``env.step`` and circles in lift where that pays. This module turns such plans into a start for PPO:

* :func:`demonstrations` replays every reference plan of a folder through the training env's
  policy interface (body-frame observations, the inverse of the turn curve), recording the
  policy's observation, the action that reproduces the plan's control, and the discounted
  return-to-go of the training reward -- a replay that does not end in the goal (the thermal climb:
  that does not fly to the time limit) is an error, since the env then does not fly the dynamics the
  plans were searched in;
* :func:`pretrain` fits the policy to the actions (negative log-likelihood of the policy's
  distribution: least squares on the Gaussian mean with a learnt spread, cross-entropy over the
  primitives) and the critic to the returns, by minibatch Adam.

The demonstrations come from scenarios drawn with seeds of their own (``random-20000 ...``,
:data:`DEMO_SEED0`), disjoint from the validation (5 000 ...) and held-out (10 000 ...) seeds, and
are written by ``scripts/demos.py`` (:mod:`baselines.cli.demos`), which also runs the DAgger rounds.
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from baselines._runs import progress_bar
from baselines.reference import ReferenceConfig, ScenarioReference, load_references
from baselines.reference.tasks import goal_config
from soaring_env._validation import ConfigError, check_int, check_positive
from soaring_env.scenario import Scenario

#: Seed of the first training scenario of the demonstrations (``random-20000``).
DEMO_SEED0 = 20_000


def demo_reference_config(beam_width: int = 125) -> ReferenceConfig:
    """The reference search of the demonstrations: the yardstick's search at a 16x narrower beam
    (about 10 s a scenario instead of 3 min, on one core), iterative widening from the same width."""
    return goal_config(beam_width)


@dataclass(frozen=True)
class Demonstrations:
    """Replayed reference plans, one row per env step.

    :param observations: the policy's observations (after the training observation transform).
    :param actions: the policy's actions that fly the plan (before the training action transform):
        ``(N, A)`` float32 for the continuous envs, ``(N,)`` int64 primitive or control-grid indices.
    :param returns: discounted return-to-go of the env reward from each row [reward units].
    :param episode: index of the plan each row belongs to.
    :param scenarios: the scenario names, in episode order.
    :param plan_costs: the reference cost of each plan [J/kg].
    :param weights: the weight of each row in the fit (float32; 1 but for the states a DAgger round
        visited, see :func:`demonstrations`).
    :param accepted: discrete actions only, optional: ``(N, n_actions)`` bool, the actions each row
        accepts as its label (the demonstrated one among them): :func:`pretrain` then fits the
        probability of the set, not of the one action. None (default): the demonstrated action alone.
    :param costs_to_go: ``(N,)`` float32, the cost [J/kg] of each row's plan from that row on, in
        the objective its search minimised: the remaining edge costs plus the search's time weight
        [J/kg per s] times the remaining flight time (the env's clock: whole steps) -- what
        :func:`pretrain`'s ``q_weight`` fits the demonstrated action's logit to. None: not recorded.
    :param targets: discrete actions only, optional: ``(N, n_actions)`` float32, each row a
        distribution over the actions that :func:`pretrain` fits instead of the demonstrated action
        (cross-entropy against it): from a plan improved by lookahead, the actions tried at that
        state weighted by the energy each reached the goal with (:func:`demonstrations`'
        ``soft_temperature``); one-hot on the demonstrated action elsewhere. None: hard labels.
    """

    observations: np.ndarray
    actions: np.ndarray
    returns: np.ndarray
    episode: np.ndarray
    scenarios: tuple[str, ...]
    plan_costs: tuple[float, ...]
    weights: np.ndarray
    accepted: np.ndarray | None = None
    costs_to_go: np.ndarray | None = None
    targets: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.observations.shape[0])


def demonstrations(
    reference_dir: str | Path,
    make_env: Callable[[Scenario], gym.Env],
    *,
    sampler: str,
    gamma: float,
    to_policy_action: Callable[[Any], Any] | None = None,
    names: Sequence[str] | None = None,
    match: str | None = None,
    visit_weight: float = 1.0,
    start_weight: float = 1.0,
    soft_temperature: float = 0.0,
) -> Demonstrations:
    """Replay the ``sampler`` plans of every reference file in ``reference_dir`` through ``make_env``.

    :param reference_dir: a folder of ``scripts/reference.py`` JSON files.
    :param make_env: builds the training env (with its observation and action transforms) that
        starts in a given scenario at its first reset.
    :param sampler: ``"continuous"`` or ``"primitive"``: which plans, matching the env's actions.
    :param gamma: the learner's discount (for the returns-to-go).
    :param to_policy_action: the inverse of the training action transform (None: identity).
    :param names: only these scenarios (default: all files, sorted by name).
    :param match: only the scenarios whose name matches this regular expression as a whole
        (``re.fullmatch``), e.g. a recipe's base plans and one DAgger round of a folder that holds
        more (``xc-20(0|1)\\d\\d(-f1s\\d+)?``); None: every file.
    :param visit_weight: the weight of a DAgger plan's first imitated row, the state the policy
        visited (the plan's other rows are the search's own states, weight 1). A round that labels
        every k-th visited state samples the policy's states k times more sparsely than a plan's
        rows sample the search's, so weight k restores DAgger's mixture of the two; without it one
        label where a policy keeps circling at the top of a thermal ("leave") is outvoted by the
        thousands of circling rows of the plans' climbs.
    :param start_weight: the weight of the first row of a plan flown from the scenario's start (not
        a DAgger plan): its first decision.
    :param soft_temperature: > 0, primitive plans only: also build ``targets`` -- at a step of a
        plan improved by lookahead (``candidate_costs``) the actions tried there with weights
        ``exp(-(J - J_min) / soft_temperature)`` [J/kg], so that the fit learns how the
        alternatives rank under the policy's own continuation, not only which one won; one-hot
        elsewhere. 0 (default): no targets.
    :raises ConfigError: no usable plan, or a plan that does not reach the goal when replayed.
    """
    visit_weight = check_positive("visit_weight", visit_weight)
    start_weight = check_positive("start_weight", start_weight)
    if isinstance(soft_temperature, bool) or not isinstance(soft_temperature, (int, float)):
        raise ConfigError(f"soft_temperature={soft_temperature!r} must be a number >= 0 [J/kg]")
    if not 0.0 <= soft_temperature < math.inf or (soft_temperature > 0.0 and sampler != "primitive"):
        raise ConfigError(f"soft_temperature={soft_temperature!r} must be finite, >= 0, and > 0 only for primitives")
    refs, chosen = _chosen(reference_dir, names, match)
    obs_rows: list[np.ndarray] = []
    act_rows: list[Any] = []
    ret_rows: list[np.ndarray] = []
    ep_rows: list[np.ndarray] = []
    w_rows: list[np.ndarray] = []
    q_rows: list[np.ndarray] = []
    t_rows: list[np.ndarray] = []
    used: list[str] = []
    costs: list[float] = []
    for name in chosen:
        ref = refs[name].samplers.get(sampler)
        if ref is None or not math.isfinite(ref.best_cost) or not ref.actions:
            continue
        env = make_env(refs[name].scenario)
        n_actions = int(getattr(env.action_space, "n", 0))  # the primitives (soft targets only)
        try:
            obs, _ = env.reset(seed=0)
            rewards: list[float] = []
            edge_costs: list[float] = []
            times: list[float] = [0.0]
            info: dict[str, Any] = {}
            terminated = truncated = False
            first = int(ref.demo_from)  # a DAgger plan: the policy's own steps first, not imitated
            for k, a in enumerate(ref.actions):
                if terminated or truncated:
                    raise ConfigError(
                        f"demos: the {sampler} plan of {name!r} ends after {k} of {len(ref.actions)} steps "
                        "when replayed: the env's dynamics differ from the reference search's"
                    )
                u = _policy_action(a, sampler, to_policy_action)
                if k >= first:
                    obs_rows.append(np.asarray(obs, np.float32))
                    # a labelled plan: flown by a policy, imitating its expert's action there
                    act_rows.append(_policy_action(ref.labels[k], sampler, to_policy_action) if ref.labels else u)
                    if soft_temperature > 0.0:
                        tried = ref.candidate_costs[k] if k < len(ref.candidate_costs) else []
                        t_rows.append(_soft_target(n_actions, int(u), tried, soft_temperature))
                obs, r, terminated, truncated, info = env.step(u)
                rewards.append(float(r))
                edge_costs.append(float(info["edge_cost"]))
                times.append(float(info["time"]))
        finally:
            env.close()
        if ref.labels:  # a policy's episode, wherever it ended: replayed to its last step is enough
            ok, what = terminated or truncated, "end at its last step"
        elif getattr(env.unwrapped, "has_goal", True):
            ok, what = terminated and bool(info.get("is_success")), "reach the goal"
        else:  # the thermal climb: a plan flies to the time limit
            ok, what = truncated and not terminated, "fly to the time limit"
        if not ok:
            raise ConfigError(
                f"demos: the {sampler} plan of {name!r} does not {what} when replayed in this env "
                "(other duration, envelope or stall limit than the reference search?)"
            )
        g = np.empty(len(rewards))
        acc = 0.0
        for k in range(len(rewards) - 1, -1, -1):
            acc = rewards[k] + gamma * acc
            g[k] = acc
        ret_rows.append(g[first:])
        # the search's objective from each step on: edge costs plus its time weight times the time left
        time_weight = float(ref.settings.get("time_weight", 0.0))
        q = np.cumsum(edge_costs[::-1])[::-1] + time_weight * (times[-1] - np.asarray(times[:-1]))
        q_rows.append(q[first:])
        ep_rows.append(np.full(len(rewards) - first, len(used), np.int64))
        w = np.ones(len(rewards) - first, np.float32)
        w[0] = visit_weight if first > 0 else start_weight
        w_rows.append(w)
        used.append(name)
        costs.append(float(ref.best_cost))
    if not used:
        raise ConfigError(f"demos={str(reference_dir)!r}: no {sampler} plan (with a finite cost)")
    if all(isinstance(a, (int, np.integer)) for a in act_rows):  # primitives, or control-grid rows
        actions = np.asarray(act_rows, np.int64)
    else:
        actions = np.stack([np.asarray(a, np.float32) for a in act_rows])
    return Demonstrations(
        observations=np.stack(obs_rows),
        actions=actions,
        returns=np.concatenate(ret_rows).astype(np.float32),
        episode=np.concatenate(ep_rows),
        scenarios=tuple(used),
        plan_costs=tuple(costs),
        weights=np.concatenate(w_rows),
        costs_to_go=np.concatenate(q_rows).astype(np.float32),
        targets=np.stack(t_rows) if t_rows else None,
    )


def _policy_action(a: Any, sampler: str, to_policy_action: Callable[[Any], Any] | None) -> Any:
    """A plan's env action (a primitive index or a control triple) as the learner's action."""
    env_action: Any = int(a) if sampler == "primitive" else np.asarray(a, np.float32)
    return to_policy_action(env_action) if to_policy_action is not None else env_action


def _soft_target(n_actions: int, action: int, tried: Sequence[Sequence[Any]], temperature: float) -> np.ndarray:
    """One row of :attr:`Demonstrations.targets`: over the ``[action, energy]`` pairs ``tried`` at
    a state (None: missed the goal) the weights ``exp(-(J - J_min) / temperature)``, normalised;
    one-hot on ``action`` where none of them reached the goal (or nothing was tried)."""
    row = np.zeros(n_actions, np.float32)
    costs = {int(a): float(c) for a, c in tried if c is not None and math.isfinite(float(c))}
    if not costs:
        row[action] = 1.0
        return row
    j_min = min(costs.values())
    for a, c in costs.items():
        row[a] = math.exp(-(c - j_min) / temperature)
    return row / row.sum()


def _chosen(
    reference_dir: str | Path, names: Sequence[str] | None, match: str | None
) -> tuple[dict[str, ScenarioReference], list[str]]:
    """The reference files of ``reference_dir`` that :func:`demonstrations` uses (only those are
    read) and their names."""
    pattern = demo_pattern(match) if match is not None else None
    wanted = None if names is None else set(names)

    def select(name: str) -> bool:
        return (wanted is None or name in wanted) and (pattern is None or pattern.fullmatch(name) is not None)

    refs = load_references(reference_dir, select)
    if not refs and not any(Path(reference_dir).glob("*.json")):
        raise ConfigError(f"demos={str(reference_dir)!r}: no reference files there (run scripts/reference.py)")
    chosen = sorted(refs) if names is None else list(names)
    if pattern is not None:
        chosen = [n for n in chosen if pattern.fullmatch(n)]
        if not chosen:
            raise ConfigError(f"demo_match={match!r}: no scenario in {str(reference_dir)!r} matches it")
    for name in chosen:
        if name not in refs:
            raise ConfigError(f"demos: no reference file for scenario {name!r} in {str(reference_dir)!r}")
    return refs, chosen


def demo_plans(
    reference_dir: str | Path, *, sampler: str, match: str | None = None
) -> list[tuple[Scenario, tuple[Any, ...]]]:
    """The ``sampler`` plans of ``reference_dir`` as ``(scenario, env actions)`` pairs, sorted by
    scenario name (``match`` as for :func:`demonstrations`): the starts of :class:`DemoStarts`."""
    refs, chosen = _chosen(reference_dir, None, match)
    out: list[tuple[Scenario, tuple[Any, ...]]] = []
    for name in chosen:
        ref = refs[name].samplers.get(sampler)
        if ref is None or not math.isfinite(ref.best_cost) or not ref.actions:
            continue
        acts = tuple(int(a) if sampler == "primitive" else np.asarray(a, np.float32) for a in ref.actions)
        out.append((refs[name].scenario, acts))
    if not out:
        raise ConfigError(f"demos={str(reference_dir)!r}: no {sampler} plan")
    return out


class DemoStarts(gym.Wrapper):  # type: ignore[type-arg]
    """Start a share of the episodes part-way along a reference plan (a reverse curriculum).

    PPO explores from the start of an episode, so a thermal that pays only after the detour, the
    climb and the glide on have all been flown is rarely found; a policy cloned from the plans
    drifts, and fine-tuning from the scenario start alone unlearns the circling (docs/learning-to-soar.md, "PPO that
    soars toward a goal"). Starting episodes at the states the plans pass through -- on the way to
    a thermal, in it at every height, on the final glide -- lets PPO practise each stage where the
    plans reach it, and its critic learns what those states are worth, which then shows at the
    start as the advantage of heading for the lift (Florensa et al. 2017, reverse curriculum
    generation; Salimans & Chen 2018, learning from a single demonstration).

    At a reset without a ``scenario`` option, with probability ``fraction`` a plan is drawn
    uniformly and a step ``k`` uniformly from ``0 .. len(plan) - 1``; the env is reset into the
    plan's scenario and its first ``k`` actions are flown (the episode's clock and step count run
    on from there: the time limit is the plan's); otherwise the env draws its own scenario. The
    draws use a generator of this wrapper, seeded by the first seeded reset: same seed, same starts.
    A start on a plan returns the info of its last flown step with ``scenario`` (the plan's name)
    and ``demo_step`` (``k``) added.
    Wrap the raw env (the plans hold env actions), under the policy's observation and action
    transforms.

    :param plans: ``(scenario, env actions)`` pairs (:func:`demo_plans`).
    :param fraction: share of the resets that start on a plan, in [0, 1].
    """

    def __init__(self, env: gym.Env, plans: Sequence[tuple[Scenario, Sequence[Any]]], fraction: float) -> None:
        super().__init__(env)
        if isinstance(fraction, bool) or not isinstance(fraction, (int, float)) or not 0.0 <= fraction <= 1.0:
            raise ConfigError(f"demo_starts={fraction!r} must be a number in [0, 1]")
        if fraction > 0.0 and not plans:
            raise ConfigError("demo_starts > 0 needs at least one plan")
        for scenario, actions in plans:
            if not isinstance(scenario, Scenario) or len(actions) == 0:
                raise ConfigError(f"plans: {scenario!r} needs a Scenario and at least one action")
        self.plans = list(plans)
        self.fraction = float(fraction)
        self._rng = np.random.default_rng(0)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        if seed is not None:
            if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
                raise ConfigError(f"seed={seed!r} must be an integer >= 0 or None")
            self._rng = np.random.default_rng([int(seed), 0x5EED])
        if (options and "scenario" in options) or not self._rng.random() < self.fraction:
            return self.env.reset(seed=seed, options=options)
        scenario, actions = self.plans[int(self._rng.integers(len(self.plans)))]
        k = int(self._rng.integers(len(actions)))
        obs, info = self.env.reset(seed=seed, options={**(options or {}), "scenario": scenario})
        for a in actions[:k]:
            obs, _, terminated, truncated, info = self.env.step(a)
            if terminated or truncated:  # a plan of other dynamics: fly this one from its start
                return self.env.reset(options={**(options or {}), "scenario": scenario})
        return obs, {**info, "scenario": scenario.name, "demo_step": k}


def demo_pattern(match: str) -> re.Pattern[str]:
    """``match`` compiled (:func:`demonstrations`); a ConfigError naming it if it is no regular expression."""
    if not isinstance(match, str) or not match:
        raise ConfigError(f"demo_match={match!r} must be a regular expression (a non-empty string)")
    try:
        return re.compile(match)
    except re.error as exc:
        raise ConfigError(f"demo_match={match!r} is not a regular expression: {exc}") from None


def rows(demos: Demonstrations, index: np.ndarray) -> Demonstrations:
    """The rows ``index`` of ``demos`` (the episode bookkeeping kept as it is)."""
    return dataclasses.replace(
        demos,
        observations=demos.observations[index],
        actions=demos.actions[index],
        returns=demos.returns[index],
        episode=demos.episode[index],
        weights=demos.weights[index],
        accepted=None if demos.accepted is None else demos.accepted[index],
        costs_to_go=None if demos.costs_to_go is None else demos.costs_to_go[index],
        targets=None if demos.targets is None else demos.targets[index],
    )


def with_mirror_images(
    demos: Demonstrations, obs_signs: np.ndarray, mirror_action: Callable[[np.ndarray], np.ndarray]
) -> Demonstrations:
    """``demos`` and their mirror images (east -> -east, every turn reversed): twice the rows.

    The model is mirror-symmetric, so the mirror image of a reference plan is a plan of the mirrored
    scenario with the same cost; a policy cloned from both circles a thermal on whichever side the
    observation says, rather than on the side the search happened to break a tie.

    :param obs_signs: per observation entry, +1 or -1 (:meth:`baselines.ppo.BodyFrame.mirror_signs`).
    :param mirror_action: the policy actions of the mirrored plan, for a batch of actions.
    """
    signs = np.asarray(obs_signs, np.float32)
    if signs.shape != demos.observations.shape[1:]:
        raise ConfigError(f"obs_signs has shape {signs.shape}; expected {demos.observations.shape[1:]}")

    def flipped(per_action: np.ndarray | None) -> np.ndarray | None:
        """A per-action table and its mirror image below it: the mirrored row's entry of an action is
        the row's entry of the action's mirror image."""
        if per_action is None:
            return None
        image = np.asarray(mirror_action(np.arange(per_action.shape[1])), np.int64)
        out = np.empty_like(per_action)
        out[:, image] = per_action
        return np.concatenate([per_action, out])

    return Demonstrations(
        observations=np.concatenate([demos.observations, demos.observations * signs]),
        actions=np.concatenate([demos.actions, np.asarray(mirror_action(demos.actions), demos.actions.dtype)]),
        returns=np.concatenate([demos.returns, demos.returns]),
        episode=np.concatenate([demos.episode, demos.episode + len(demos.scenarios)]),
        scenarios=demos.scenarios + tuple(f"{n}~mirror" for n in demos.scenarios),
        plan_costs=demos.plan_costs + demos.plan_costs,
        weights=np.concatenate([demos.weights, demos.weights]),
        accepted=flipped(demos.accepted),
        costs_to_go=None if demos.costs_to_go is None else np.concatenate([demos.costs_to_go, demos.costs_to_go]),
        targets=flipped(demos.targets),
    )


def _visits(
    scenarios: Sequence[Scenario],
    make_env: Callable[[Scenario], gym.Env],
    act: Callable[[Any], Any],
    every: int,
    until: int | None = None,
    failed_only: bool = False,
) -> Iterator[tuple[Scenario, int, np.ndarray, list[Any]]]:
    """Fly each scenario once with ``act``; after every ``every``-th step while the episode runs
    (and, given ``until``, within its first ``until`` steps), yield (scenario, step, a copy of the
    raw env's state, the actions so far).

    With ``failed_only`` an episode's states are yielded only once it has ended without reaching
    the goal (``info["is_success"]`` False), so a DAgger round spends its searches where the policy
    fails.
    """
    every = check_int("every", every, 1)
    if until is not None:
        until = check_int("until", until, 1)
    for sc in scenarios:
        env = make_env(sc)
        try:
            obs, _ = env.reset(seed=0)
            taken: list[Any] = []
            held: list[tuple[Scenario, int, np.ndarray, list[Any]]] = []
            while True:
                a = act(obs)
                taken.append(a)
                obs, _, terminated, truncated, info = env.step(a)
                if terminated or truncated:
                    if failed_only and not info.get("is_success", False):
                        yield from held
                    break
                k = len(taken)
                if k % every == 0 and (until is None or k <= until):
                    raw: Any = env.unwrapped  # a SoaringEnv: its state (Pn, Pe, chi, h, ...)
                    visit = (sc, k, np.array(raw.state, copy=True), list(taken))
                    if failed_only:
                        held.append(visit)
                    else:
                        yield visit
        finally:
            env.close()


def visited_starts(
    scenarios: Sequence[Scenario],
    make_env: Callable[[Scenario], gym.Env],
    act: Callable[[Any], Any],
    *,
    every: int,
    tag: str = "",
    until: int | None = None,
    failed_only: bool = False,
) -> list[Scenario]:
    """The states a policy visits, as scenarios that start there (DAgger's data, Ross et al. 2011).

    A cloned policy drifts from the plans it learnt from, into states no plan passes; searching
    the reference again from those states (:func:`baselines.reference.runner.run_references`) gives
    plans that correct the drift. Each scenario is flown once with ``act`` (deterministic), and the
    state after every ``every``-th step (while the episode runs) becomes the start of a copy of the
    scenario named ``<name>-<tag>s<step>``. The env's state is the scenario's start state
    ``(Pn, Pe, chi, h)``, so a plan from such a start replays there exactly (from time 0, with a
    fresh episode: for tasks with a battery use :func:`visited_prefixes`).

    :param scenarios: where to fly.
    :param make_env: the env (with the policy's transforms) starting in a given scenario.
    :param act: policy observation -> policy action.
    :param every: steps between recorded states (>= 1).
    :param tag: marks a DAgger round in the names (the policies of two rounds visit other states).
    :param until: only states within the first this many steps (None: the whole episode).
    :param failed_only: only states of episodes that end without reaching the goal.
    """
    out: list[Scenario] = []
    for sc, k, state, _ in _visits(scenarios, make_env, act, every, until, failed_only):
        pn, pe, chi, h = (float(v) for v in state[:4])
        try:
            out.append(dataclasses.replace(sc, start=(pn, pe, chi, h), name=f"{sc.name}-{tag}s{k}"))
        except ConfigError:  # inside the goal region or outside the domain: nothing to plan
            pass
    return out


def visited_prefixes(
    scenarios: Sequence[Scenario],
    make_env: Callable[[Scenario], gym.Env],
    act: Callable[[Any], Any],
    *,
    every: int,
    tag: str = "",
    until: int | None = None,
    failed_only: bool = False,
) -> list[tuple[Scenario, list[Any]]]:
    """The states a policy visits, as the actions that reach them: DAgger for tasks whose state is
    more than the position (the cross-country battery, the time).

    Each scenario is flown once with ``act``; after every ``every``-th step (while the episode
    runs) the actions so far become the prefix of a copy of the scenario named
    ``<name>-<tag>s<step>`` (the same air and start): the task's reference search
    (:func:`baselines.reference.tasks.task_reference`) flies the prefix, then plans from the state
    it reaches with the battery, time and airspeed it has there.

    :param make_env: the raw env (no policy transforms: the prefix is in env actions).
    :param act: observation -> env action.
    :param every, tag, until, failed_only: as for :func:`visited_starts`.
    """
    return [
        (dataclasses.replace(sc, name=f"{sc.name}-{tag}s{k}"), taken)
        for sc, k, _, taken in _visits(scenarios, make_env, act, every, until, failed_only)
    ]


def controller_plan(
    make_env: Callable[[Scenario], gym.Env],
    agent: Any,
    scenario: Scenario,
    prefix: Sequence[Any] = (),
    policy: Any = None,
) -> dict[str, Any]:
    """A hand-written controller's episode as a plan: ``prefix`` flown first (a DAgger start: a
    policy's actions), the controller shadowing it -- it sees every observation, so its memory
    (a thermalling controller's variometer log, its search spiral) is that of this path -- then
    the controller acting to the end. The demonstrator of the tasks a reference search cannot
    teach, such as the thermal climb on sensed lift (the search knows where the thermals are).

    With ``policy`` the policy flies the whole episode instead and the shadowing controller labels
    every state it visits (DAgger's expert queried along the learner's own path, Ross, Gordon &
    Bagnell 2011): ``labels`` holds the controller's action at each step, ``actions`` the policy's.

    :param make_env: the raw env of the task, starting in the given scenario at its first reset.
    :param agent: ``reset(env, seed)`` and ``predict(obs) -> (env action, state)``, e.g.
        :class:`baselines.agents.ThermallingAgent`.
    :param prefix: env actions flown before the controller takes over.
    :param policy: an agent as ``agent`` (e.g. :class:`baselines.agents.PPOAgent`) that flies
        every step; only without ``prefix``.
    :returns: ``actions`` (the prefix's, then the controller's, as lists), ``labels`` (with
        ``policy``: the controller's actions, one per step; else empty), ``demo_from`` (the
        prefix's length), ``energy_spent`` [J/kg], ``flight_time`` [s], ``terminated`` (ended by
        a crash, the domain's edge or a stall) and ``truncated``.
    """
    if policy is not None and len(prefix):
        raise ConfigError("controller_plan: a prefix or a policy that flies the whole episode, not both")
    env = make_env(scenario)
    try:
        obs, _ = env.reset(seed=0)
        agent.reset(env, 0)
        if policy is not None:
            policy.reset(env, 0)
        actions: list[Any] = []
        labels: list[Any] = []
        terminated = truncated = False
        info: dict[str, Any] = {"energy_spent": 0.0, "time": 0.0}
        for a in prefix:
            agent.predict(obs)  # shadowing: the controller's memory follows the flown path
            actions.append(np.asarray(a).tolist())
            obs, _, terminated, truncated, info = env.step(a)
            if terminated or truncated:
                break
        while not (terminated or truncated):
            a, _ = agent.predict(obs)
            if policy is not None:
                labels.append(np.asarray(a).tolist())
                a, _ = policy.predict(obs)
            actions.append(np.asarray(a).tolist())
            obs, _, terminated, truncated, info = env.step(a)
    finally:
        env.close()
    return {
        "actions": actions,
        "labels": labels,
        "demo_from": len(prefix),
        "energy_spent": float(info["energy_spent"]),
        "flight_time": float(info["time"]),
        "terminated": bool(terminated),
        "truncated": bool(truncated),
    }


def sampled_episodes(
    env: gym.Env,
    logits: Callable[[Any], np.ndarray],
    scenario: Scenario,
    *,
    samples: int,
    temperature: float,
    seed: int,
) -> list[dict[str, Any]]:
    """Fly ``scenario`` once with the policy's mode and ``samples`` times drawing each action from
    ``softmax(logits / temperature)``: the episodes self-imitation chooses from.

    :param env: a discrete env with the policy's observation transform (reset with the scenario).
    :param logits: observation -> the policy's logits over the actions.
    :param samples: sampled episodes (>= 1).
    :param temperature: > 0; 1 samples the policy itself, smaller values stay nearer its mode.
    :param seed: the draws of sampled episode k come from ``default_rng([seed, k])``.
    :returns: the greedy episode, then the sampled ones: per episode its ``actions``,
        ``energy_spent`` [J/kg], ``flight_time`` [s] and ``success`` (reached the goal).
    """
    samples = check_int("samples", samples, 1)
    if not (isinstance(temperature, (int, float)) and 0.0 < temperature < math.inf):
        raise ConfigError(f"temperature={temperature!r} must be a finite number > 0")
    out: list[dict[str, Any]] = []
    for k in range(-1, samples):
        gen = None if k < 0 else np.random.default_rng([int(seed), k])
        obs, info = env.reset(seed=0, options={"scenario": scenario})
        actions: list[int] = []
        terminated = truncated = False
        while not (terminated or truncated):
            z = np.asarray(logits(obs), np.float64)
            if gen is None:
                a = int(np.argmax(z))
            else:  # the Gumbel-max trick: argmax of logits / T plus Gumbel noise samples softmax(logits / T)
                a = int(np.argmax(z / temperature + gen.gumbel(size=z.shape)))
            actions.append(a)
            obs, _, terminated, truncated, info = env.step(a)
        base: Any = env.unwrapped
        out.append(
            {
                "actions": actions,
                "energy_spent": float(info["energy_spent"]),
                "flight_time": float(base.time),
                "success": bool(terminated and info.get("is_success", False)),
            }
        )
    return out


def _fly_mode(
    env: gym.Env, logits: Callable[[Any], np.ndarray], scenario: Scenario, prefix: Sequence[int], candidates: int
) -> dict[str, Any]:
    """One episode: ``prefix`` replayed, then the policy's mode to the end. Besides
    :func:`sampled_episodes`' keys, ``options[t]`` holds the ``candidates`` actions of largest logit
    at each step ``t`` the policy chose (empty tuples for the prefix)."""
    obs, info = env.reset(seed=0, options={"scenario": scenario})
    actions: list[int] = []
    options: list[tuple[int, ...]] = []
    terminated = truncated = False
    while not (terminated or truncated):
        top: tuple[int, ...] = ()
        if len(actions) < len(prefix):
            a = int(prefix[len(actions)])
        else:
            z = np.asarray(logits(obs), np.float64)
            # stable order (largest logit first, lower index on ties): the same candidates every run
            order = np.argsort(-z, kind="stable")
            a, top = int(order[0]), tuple(int(i) for i in order[:candidates])
        actions.append(a)
        options.append(top)
        obs, _, terminated, truncated, info = env.step(a)
    base: Any = env.unwrapped
    return {
        "actions": actions,
        "options": options,
        "energy_spent": float(info["energy_spent"]),
        "flight_time": float(base.time),
        "success": bool(terminated and info.get("is_success", False)),
    }


def rollout_improved(
    env: gym.Env,
    logits: Callable[[Any], np.ndarray],
    scenario: Scenario,
    *,
    candidates: int,
    steps: int | None = None,
    follow: str = "improved",
) -> tuple[dict[str, Any], dict[str, Any]]:
    """The policy's mode improved by one-step lookahead with the mode as base policy (Bertsekas'
    rollout algorithm, the policy-improvement step of approximate policy iteration).

    From the first step on, each of the ``candidates`` actions of largest logit is tried, and the
    episode is flown on by the mode; the action whose episode reaches the goal with the least
    energy is kept (the incumbent's on ties), and the next step is decided the same way along the
    kept episode. Since the kept episode is always among those tried, the result reaches the goal
    whenever the mode does and spends no more energy [J/kg]; unlike the best of sampled episodes
    (:func:`sampled_episodes`) it departs from the mode only where a departure pays.

    :param env: a discrete env with the policy's observation transform (reset with the scenario);
        deterministic, since every tried episode is replayed from the start.
    :param logits: observation -> the policy's logits over the actions.
    :param candidates: actions tried per step (>= 1; 1 gives the mode).
    :param steps: decide only the first ``steps`` steps so (None: every step).
    :param follow: ``"improved"`` (default): the steps are decided along the kept episode, as
        above; ``"mode"``: the actions are tried at every state of the mode's own episode and the
        mode's episode is returned with them, however much better a tried one was -- the states the
        policy itself visits, labelled with what each action there is worth (the state distribution
        of classification-based approximate policy iteration, Lagoudakis & Parr 2003), where the
        kept episode leaves the mode's path at the first step that pays and never labels the states
        the mode goes wrong in.
    :returns: ``(mode, improved)`` episodes with :func:`sampled_episodes`' keys; ``improved`` also
        has ``tried``, the episodes flown, and ``candidate_costs``: per step of its ``actions`` the
        ``(action, energy [J/kg])`` of each action tried there, the mode flying on (None: that
        episode missed the goal; empty lists for the steps not decided) --
        the base policy's action values at that state, :class:`SamplerReference.candidate_costs`.
    """
    candidates = check_int("candidates", candidates, 1)
    horizon = math.inf if steps is None else check_int("steps", steps, 0)
    if follow not in ("improved", "mode"):
        raise ConfigError(f"follow={follow!r} must be 'improved' or 'mode'")
    mode = _fly_mode(env, logits, scenario, (), candidates)

    def key(ep: dict[str, Any]) -> float:
        return ep["energy_spent"] if ep["success"] else math.inf

    def cost(ep: dict[str, Any]) -> float | None:
        return ep["energy_spent"] if ep["success"] else None

    best, tried, t = mode, 1, 0
    costs: list[list[tuple[int, float | None]]] = []  # per decided step: (action, its episode's energy)
    while t < min(horizon, len(best["actions"])):
        prefix = best["actions"][:t]
        here = [(best["actions"][t], cost(best))]
        for a in best["options"][t]:
            if a == here[0][0]:
                continue
            ep = _fly_mode(env, logits, scenario, [*prefix, a], candidates)
            tried += 1
            here.append((a, cost(ep)))
            if follow == "improved" and key(ep) < key(best):  # later steps are decided along the new episode
                best = ep
        costs.append(here)
        t += 1
    costs += [[] for _ in range(len(best["actions"]) - len(costs))]
    return mode, {**best, "tried": tried, "candidate_costs": costs}


def best_reached(episodes: Sequence[dict[str, Any]]) -> dict[str, Any] | None:
    """The episode of :func:`sampled_episodes` that reaches the goal with the least energy (None: none does)."""
    reached = [e for e in episodes if e["success"]]
    return min(reached, key=lambda e: e["energy_spent"]) if reached else None


def _label_log_prob(lp: Any, act: Any, accepted: Any, targets: Any, idx: Any) -> Any:
    """Per row ``idx`` of a minibatch, the log-likelihood :func:`pretrain` maximises, from the
    policy's log-probabilities ``lp`` of those rows: of the demonstrated action (``act``), of the
    accepted set (the log of its summed probability), or the expectation under the row's target
    distribution (a cross-entropy). ``act``, ``accepted`` and ``targets`` hold every row."""
    import torch

    if accepted is not None:
        return torch.logsumexp(lp.masked_fill(~accepted[idx], -math.inf), dim=1)
    if targets is not None:
        return (targets[idx] * lp).sum(dim=1)
    return lp.gather(1, act[idx].long()[:, None]).squeeze(1)


def pretrain(
    policy: Any,
    demos: Demonstrations,
    *,
    epochs: int,
    learning_rate: float = 1e-3,
    final_fraction: float = 1.0,
    batch_size: int = 256,
    value_weight: float = 0.5,
    q_weight: float = 0.0,
    seed: int = 0,
    optimizer: Any = None,
    progress: bool = False,
) -> list[dict[str, float]]:
    """Fit an SB3 ``ActorCriticPolicy`` to ``demos``: the actor by the negative log-likelihood of the
    demonstrated actions (with ``demos.accepted``: of the set of actions each row accepts, the log
    of their summed probability; with ``demos.targets``: the cross-entropy against each row's
    target distribution), the critic by least squares on the returns-to-go, each row
    weighted by ``demos.weights`` (a weighted mean per minibatch; with all weights 1 the plain mean).

    By default the policy's own optimizer is left alone (a fresh Adam here, so that PPO's starts
    clean); ``optimizer`` fits with a given one instead (PPO's, when rehearsing the demonstrations
    between PPO updates). Deterministic for a fixed ``seed`` (minibatch order; torch on one thread).

    :param policy: ``model.policy`` of a PPO / MaskablePPO model on the demonstrations' spaces.
    :param epochs: passes over the demonstrations.
    :param learning_rate: Adam step size (of a fresh optimizer: at the first minibatch).
    :param final_fraction: with a fresh optimizer, the step size falls linearly per minibatch to
        this fraction of ``learning_rate`` at the last one (1: constant; ignored with ``optimizer``).
    :param batch_size: rows per minibatch.
    :param value_weight: weight of the critic's loss beside the actor's.
    :param q_weight: discrete policies with ``demos.costs_to_go``: weight of a loss that reads the
        raw logits as costs, ``Q(s, a) = beta - alpha * logit(s, a)`` [kJ/kg] (``alpha > 0`` and
        ``beta`` fitted alongside), and fits the demonstrated action's ``Q`` to the plan's cost from
        that row on, by least squares (DQfD's supervised loss, without its TD part). The cross-entropy
        alone leaves each row's logits free up to a constant; this ties them across rows to what the
        successor is worth, so that states seen in other plans inform a row's ranking. 0 (default): off.
        Needs a fresh optimizer.
    :param seed: minibatch order.
    :param optimizer: a torch optimizer over the policy's parameters (None: a fresh Adam).
    :param progress: show a progress bar over the minibatches (with the last epoch and its loss).
    :returns: per epoch the mean actor loss (``nll``), critic loss (``value_mse``) and, for
        Gaussian policies, the mean absolute error of the mean action (``mae``); with ``q_weight``
        also the cost fit's mean squared error (``q_mse``, [(kJ/kg)^2]) and ``alpha`` at the end of
        the epoch [kJ/kg per logit].
    """
    import torch

    if epochs < 1 or batch_size < 1:
        raise ConfigError(f"pretrain: epochs={epochs!r} and batch_size={batch_size!r} must be >= 1")
    if not 0.0 <= final_fraction <= 1.0:
        raise ConfigError(f"pretrain: final_fraction={final_fraction!r} must be in [0, 1]")
    obs = torch.as_tensor(demos.observations)
    act = torch.as_tensor(demos.actions)
    ret = torch.as_tensor(demos.returns)
    wts = torch.as_tensor(demos.weights) if bool(np.any(demos.weights != 1.0)) else None
    accepted = None if demos.accepted is None else torch.as_tensor(demos.accepted, dtype=torch.bool)
    if accepted is not None and (act.dtype.is_floating_point or accepted.shape[0] != len(act)):
        raise ConfigError(f"pretrain: accepted of shape {tuple(accepted.shape)} needs one row per discrete action")
    targets = None if demos.targets is None else torch.as_tensor(demos.targets, dtype=torch.float32)
    if targets is not None and (act.dtype.is_floating_point or targets.shape[0] != len(act) or accepted is not None):
        raise ConfigError(
            f"pretrain: targets of shape {tuple(targets.shape)} need one row per discrete action, and no accepted sets"
        )
    if isinstance(q_weight, bool) or not isinstance(q_weight, (int, float)) or not 0.0 <= q_weight < math.inf:
        raise ConfigError(f"pretrain: q_weight={q_weight!r} must be a finite number >= 0")
    fit_q = q_weight > 0.0
    params = list(policy.parameters())
    if fit_q:
        if demos.costs_to_go is None or act.dtype.is_floating_point or optimizer is not None:
            raise ConfigError("pretrain: q_weight > 0 needs discrete actions, demos.costs_to_go and a fresh optimizer")
        q_target = torch.as_tensor(demos.costs_to_go, dtype=torch.float32) / 1000.0  # kJ/kg
        # alpha starts at 50 J/kg per logit: a few logits between a good successor and a poor one
        log_alpha = torch.tensor(math.log(0.05), requires_grad=True)
        beta = torch.tensor(float(q_target.mean()), requires_grad=True)
        params += [log_alpha, beta]
    opt = optimizer if optimizer is not None else torch.optim.Adam(params, lr=learning_rate)
    gen = np.random.default_rng(seed)
    n = len(demos)
    per_epoch = -(-n // batch_size)
    total = int(epochs) * per_epoch
    decay = optimizer is None and final_fraction != 1.0
    log: list[dict[str, float]] = []
    # per minibatch: a successor policy's first epoch computes every row's features (minutes)
    bar = progress_bar(total, 0, progress, "behaviour cloning", "batch")
    policy.set_training_mode(True)
    for e in range(int(epochs)):
        order = gen.permutation(n)
        sums = {"nll": 0.0, "value_mse": 0.0, "mae": 0.0, "q_mse": 0.0}
        for b, start in enumerate(range(0, n, batch_size)):
            if decay:  # linear from learning_rate at the first minibatch to the final fraction at the last
                frac = (e * per_epoch + b) / max(total - 1, 1)
                for g in opt.param_groups:
                    g["lr"] = learning_rate * (1.0 - (1.0 - final_fraction) * frac)
            idx = torch.as_tensor(order[start : start + batch_size])
            raw = None
            if fit_q:  # the raw logits, before Categorical normalises them
                feats = policy.extract_features(obs[idx], policy.pi_features_extractor)
                raw = policy.action_net(policy.mlp_extractor.forward_actor(feats))
                values = policy.predict_values(obs[idx])
                log_prob = _label_log_prob(torch.log_softmax(raw, dim=1), act, accepted, targets, idx)
            elif accepted is None and targets is None:
                values, log_prob, _ = policy.evaluate_actions(obs[idx], act[idx])
            else:  # Categorical's logits are log-probabilities
                values = policy.predict_values(obs[idx])
                lp = policy.get_distribution(obs[idx]).distribution.logits
                log_prob = _label_log_prob(lp, act, accepted, targets, idx)
            sq = (values.flatten() - ret[idx]) ** 2
            if wts is None:
                nll, vloss = -log_prob.mean(), torch.mean(sq)
            else:
                wb = wts[idx]
                nll, vloss = -(wb * log_prob).sum() / wb.sum(), (wb * sq).sum() / wb.sum()
            loss = nll + value_weight * vloss
            if raw is not None:
                q_hat = beta - torch.exp(log_alpha) * raw.gather(1, act[idx].long()[:, None]).squeeze(1)
                qsq = (q_hat - q_target[idx]) ** 2
                qloss = torch.mean(qsq) if wts is None else (wts[idx] * qsq).sum() / wts[idx].sum()
                loss = loss + q_weight * qloss
                sums["q_mse"] += float(qloss.detach()) * len(idx)
            opt.zero_grad()
            loss.backward()
            opt.step()
            if bar is not None:
                bar.update(1)
            w = len(idx)
            sums["nll"] += float(nll.detach()) * w
            sums["value_mse"] += float(vloss.detach()) * w
            if act.dtype.is_floating_point:
                with torch.no_grad():
                    mean = policy.get_distribution(obs[idx]).distribution.mean
                    sums["mae"] += float(torch.mean(torch.abs(mean - act[idx]))) * w
        log.append(
            {
                k: v / n
                for k, v in sums.items()
                if (k != "mae" or act.dtype.is_floating_point) and (k != "q_mse" or fit_q)
            }
        )
        if fit_q:
            log[-1]["alpha"] = float(torch.exp(log_alpha).detach())
        if bar is not None:
            bar.set_postfix(epoch=f"{e + 1}/{epochs}", nll=f"{log[-1]['nll']:.3f}")
    if bar is not None:
        bar.close()
    policy.set_training_mode(False)
    return log


__all__ = [
    "DEMO_SEED0",
    "Demonstrations",
    "best_reached",
    "demo_reference_config",
    "demonstrations",
    "pretrain",
    "rollout_improved",
    "rows",
    "sampled_episodes",
    "visited_prefixes",
    "visited_starts",
    "with_mirror_images",
]
