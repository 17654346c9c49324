"""The optimality yardstick: bounds, the direct-flight baseline, the reference per scenario, regret.

Per scenario and action set (``"primitive"``: the 174 primitives; ``"continuous"``: the Box envs):

* ``lower_bound`` -- a cost no plan can beat [J/kg] (:func:`~baselines.reference.bounds.lower_bound`).
* ``direct_cost`` -- the cost of the best plan the reference search finds in the same wind with
  the thermals removed ("ignoring the thermals").
* ``best_cost`` -- the best plan known in the real field: the reference search seeded with the
  direct plan (so it never does worse than flying that plan through the thermals), and with
  ``planner_iterations`` the cheaper of that and a second search seeded with the plans of
  ``planner_seeds`` soaring-planner runs too (never worse than any of those plans); with
  ``polish``, that plan then polished by local search (:mod:`baselines.reference.polish`).

Regret: :func:`~baselines.reference.bounds.regret` against ``best_cost`` and ``direct_cost``.
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from baselines.reference.beam import MAX_POLISH_DEPTH, ReferenceConfig, search
from baselines.reference.bounds import MIN_GAP, lower_bound, regret, without_thermals
from baselines.reference.polish import polish
from baselines.sst.planner import plan_soaring
from baselines.sst.soaring import SAMPLERS
from soaring_env._validation import ConfigError, check_choice, check_int
from soaring_env.model import SoaringModel
from soaring_env.primitives import N_PRIMITIVES
from soaring_env.scenario import Scenario, atomic_write_text

#: Version of the reference file layout.
SCHEMA = 1


@dataclass(frozen=True)
class SamplerReference:
    """The reference of one action set in one scenario.

    :param best_cost: best known plan cost [J/kg] (inf: none found).
    :param direct_cost: best plan cost with the thermals removed [J/kg] (inf: none found).
    :param actions: env actions of the best plan (ints, or lists of 3 floats).
    :param direct_actions: env actions of the direct plan.
    :param flight_time: flight time of the best plan [s].
    :param settings: the search settings (:meth:`ReferenceConfig.to_dict`).
    :param rollouts: edges flown by both searches.
    :param seconds: wall-clock time of both searches [s].
    :param demo_from: the first step of ``actions`` that is the search's: a plan from a state a
        policy visited (DAgger) starts with the policy's own steps, flown to reach that state.
    :param env_kwargs: a task's own search: the ``gym.make`` keywords of the env it planned in
        (its control interval, envelope, step limit; empty: the id's defaults), which a replay needs.
    :param candidate_costs: a plan improved by lookahead (:func:`baselines.imitation.rollout_improved`):
        per step of ``actions`` the ``[action, energy]`` pairs of the actions tried there, each
        followed by the policy's mode to the end [J/kg] (None: that episode missed the goal); empty
        lists where nothing was tried, and an empty list for a searched plan.
    :param labels: a labelled plan (DAgger with a shadowing expert,
        :func:`baselines.imitation.controller_plan`): per step of ``actions`` -- here the policy's,
        flown to reach the states -- the expert's action there, which a cloning imitates; empty: the
        plan imitates its own ``actions``.
    """

    best_cost: float
    direct_cost: float
    actions: list[Any]
    direct_actions: list[Any]
    flight_time: float
    settings: dict[str, Any]
    rollouts: int
    seconds: float
    demo_from: int = 0
    env_kwargs: dict[str, Any] = dataclasses.field(default_factory=dict)
    candidate_costs: list[list[list[Any]]] = dataclasses.field(default_factory=list)
    labels: list[Any] = dataclasses.field(default_factory=list)

    def regret(self, cost: float) -> float:
        return regret(cost, self.best_cost, self.direct_cost)


def _sampler_dict(ref: SamplerReference) -> dict[str, Any]:
    """``ref`` as JSON-ready data; ``candidate_costs`` and ``labels`` only where there are some
    (searched plans' files stay as they were before the fields existed)."""
    d = dataclasses.asdict(ref)
    for optional in ("candidate_costs", "labels"):
        if not d[optional]:
            del d[optional]
    return d


def _is_pair(p: Any) -> bool:
    """An ``[action, energy]`` pair of ``candidate_costs``: a primitive index 0 ... 173 and a number or None."""
    return (
        isinstance(p, list)
        and len(p) == 2
        and isinstance(p[0], int)
        and not isinstance(p[0], bool)
        and 0 <= p[0] < N_PRIMITIVES
        and (p[1] is None or (isinstance(p[1], (int, float)) and not isinstance(p[1], bool)))
    )


def _sampler_from_dict(v: Mapping[str, Any], source: str) -> SamplerReference:
    """One sampler's entry of a reference file; malformed ``candidate_costs`` (hand-edited files)
    raise a ConfigError naming the file, not an error deep inside a cloning."""
    ref = SamplerReference(**v)
    cc = ref.candidate_costs
    if cc and not (
        isinstance(cc, list)
        and len(cc) == len(ref.actions)
        and all(isinstance(step, list) and all(_is_pair(q) for q in step) for step in cc)
    ):
        raise ConfigError(
            f"{source}: candidate_costs must hold, per step of its {len(ref.actions)} actions, a list of "
            f"[action (integer 0 ... {N_PRIMITIVES - 1}), energy (number or null)] pairs; got {str(cc)[:80]!r}"
        )
    if ref.labels and not (isinstance(ref.labels, list) and len(ref.labels) == len(ref.actions)):
        raise ConfigError(
            f"{source}: labels must hold one action per step of its {len(ref.actions)} actions; "
            f"got {str(ref.labels)[:80]!r}"
        )
    return ref


@dataclass(frozen=True)
class ScenarioReference:
    """Bounds and references of one scenario (the content of one ``results/reference/*.json``)."""

    scenario: Scenario
    lower_bound: float
    samplers: dict[str, SamplerReference]

    def regret(self, cost: float, sampler: str) -> float:
        """Regret of ``cost`` [J/kg] against this scenario's reference for ``sampler`` (NaN if absent)."""
        ref = self.samplers.get(sampler)
        return ref.regret(cost) if ref is not None else math.nan

    def to_dict(self) -> dict[str, Any]:
        return {
            "schema": SCHEMA,
            "scenario": self.scenario.to_dict(),
            "lower_bound": self.lower_bound,
            "samplers": {k: _sampler_dict(v) for k, v in self.samplers.items()},
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], source: str = "reference") -> ScenarioReference:
        try:
            if d.get("schema") != SCHEMA:
                raise ConfigError(f"{source}: schema={d.get('schema')!r}; this version reads schema {SCHEMA}")
            return cls(
                scenario=Scenario.from_dict(d["scenario"]),
                lower_bound=float(d["lower_bound"]),
                samplers={k: _sampler_from_dict(v, f"{source}, sampler {k!r}") for k, v in d["samplers"].items()},
            )
        except (KeyError, TypeError, AttributeError) as exc:
            raise ConfigError(f"{source} is not a reference file: {exc!r}") from None


def reference_path(out_dir: str | Path, name: str) -> Path:
    """``out_dir/<scenario name>.json``."""
    return Path(out_dir) / f"{name}.json"


def load_reference(path: str | Path) -> ScenarioReference:
    """Read one reference file; a missing, unreadable or malformed file raises a ConfigError naming it."""
    p = Path(path)
    try:
        d = json.loads(p.read_text())
    except (OSError, ValueError) as exc:
        raise ConfigError(f"reference file {str(p)!r} cannot be read: {exc}") from None
    if not isinstance(d, dict):
        raise ConfigError(f"reference file {str(p)!r} is not a JSON object")
    return ScenarioReference.from_dict(d, source=f"reference file {str(p)!r}")


def load_references(out_dir: str | Path, select: Callable[[str], bool] | None = None) -> dict[str, ScenarioReference]:
    """Every reference file in ``out_dir`` by scenario name ({} if the folder does not exist).

    :param select: only the files whose name without ``.json`` it accepts are read (a folder of
        demonstrations holds tens of thousands, of which a cloning takes a few).
    """
    if select is not None and not callable(select):
        raise ConfigError(f"select={select!r} must be None or a function of a file name (without .json) to bool")
    d = Path(out_dir)
    if not d.is_dir():
        return {}
    return {p.stem: load_reference(p) for p in sorted(d.glob("*.json")) if select is None or select(p.stem)}


#: Search settings: one :class:`ReferenceConfig` for every action set, or one per action set.
Settings = ReferenceConfig | Mapping[str, ReferenceConfig]


def compute_reference(
    scenario: Scenario,
    samplers: Sequence[str] = SAMPLERS,
    config: Settings | None = None,
    *,
    model_kwargs: Mapping[str, Any] | None = None,
    progress: Callable[[str, int, int], None] | None = None,
) -> ScenarioReference:
    """Bounds, direct cost and best plan per action set for ``scenario``.

    :param scenario: the scenario (its ``name`` is the file name under ``results/reference/``).
    :param samplers: action sets, ``"primitive"`` and/or ``"continuous"``.
    :param config: search settings (the same for the direct and the real field): one for both
        action sets or one per action set (:func:`sampler_config`).
    :param model_kwargs: further :class:`SoaringModel` arguments (aircraft, library, ...).
    :param progress: called as ``progress(stage, depth, max_edges)`` (stage e.g. ``"primitive/direct"``).
    """
    if not isinstance(scenario, Scenario):
        raise ConfigError(f"scenario={scenario!r} must be a soaring_env.scenario.Scenario")
    cfg = config if config is not None else ReferenceConfig()
    settings_by_sampler(cfg, samplers)  # checks the action sets and settings before any search
    model = SoaringModel(scenario=scenario, **dict(model_kwargs or {}))
    direct_model = without_thermals(model)
    out: dict[str, SamplerReference] = {}
    for sampler in samplers:
        check_choice("sampler", sampler, SAMPLERS)
        cfg_s = sampler_config(cfg, sampler)
        t0 = time.perf_counter()

        def cb(stage: str, sampler: str = sampler) -> Callable[[int, int], None] | None:
            if progress is None:
                return None
            return lambda d, n: progress(f"{sampler}/{stage}", d, n)

        direct = search(direct_model, sampler, cfg_s, progress=cb("direct"))
        seed = [direct.plan.controls()] if direct.plan.solved else []
        best = search(model, sampler, cfg_s, seed_controls=seed, progress=cb("thermals"))
        rollouts = direct.rollouts + best.rollouts
        if cfg_s.planner_iterations:
            # the search is not monotone in its seeds (a seed's nodes take beam slots and cells), so
            # the planners' plans seed a second search and the cheaper of the two is kept
            plans: list[np.ndarray] = []
            for k in range(cfg_s.planner_seeds):
                sst = plan_soaring(
                    model, sampler, max_iterations=cfg_s.planner_iterations, seed=k, config=cfg_s.planner_config
                )
                rollouts += sst.stats.iterations
                if sst.plan.solved and not any(np.array_equal(sst.plan.controls(), c) for c in plans):
                    plans.append(sst.plan.controls())
            if plans:
                alt = search(model, sampler, cfg_s, seed_controls=[*seed, *plans], progress=cb("planner"))
                rollouts += alt.rollouts
                if alt.cost < best.cost:
                    best = alt
        ref = SamplerReference(
            best_cost=best.cost,
            direct_cost=direct.cost,
            actions=best.plan.to_dict()["actions"],
            direct_actions=direct.plan.to_dict()["actions"],
            flight_time=best.plan.flight_time,
            settings=dataclasses.replace(cfg_s, polish=0).to_dict(),
            rollouts=rollouts,
            seconds=time.perf_counter() - t0,
        )
        out[sampler] = polish_reference(model, sampler, ref, cfg_s.polish)
    return ScenarioReference(scenario=scenario, lower_bound=lower_bound(model), samplers=out)


def polish_reference(model: SoaringModel, sampler: str, ref: SamplerReference, depth: int) -> SamplerReference:
    """``ref`` with its best plan polished to ``depth`` (:func:`~baselines.reference.polish.polish`;
    0 or a plan already polished that deep: ``ref`` unchanged). The last step of
    :func:`compute_reference`, and how a stored reference computed without it is brought up to
    date (the same result: the search before it is deterministic). Its rollouts and seconds are
    added to the reference's."""
    check_int("depth", depth, 0, MAX_POLISH_DEPTH)
    cfg = ReferenceConfig(**ref.settings)
    if depth <= cfg.polish or not ref.actions:
        return ref
    t0 = time.perf_counter()
    cfg = dataclasses.replace(cfg, polish=depth)
    width = 1 if sampler == "primitive" else 3
    res = polish(model, sampler, np.asarray(ref.actions, np.float64).reshape(-1, width), cfg)
    return dataclasses.replace(
        ref,
        best_cost=res.cost,
        actions=res.plan.to_dict()["actions"],
        flight_time=res.plan.flight_time,
        settings=cfg.to_dict(),
        rollouts=ref.rollouts + res.rollouts,
        seconds=ref.seconds + time.perf_counter() - t0,
    )


def settings_by_sampler(config: Settings, samplers: Sequence[str]) -> dict[str, ReferenceConfig]:
    """:func:`sampler_config` of each action set in ``samplers`` (a non-empty sequence of names)."""
    if isinstance(samplers, str) or not all(isinstance(s, str) for s in samplers) or len(samplers) == 0:
        raise ConfigError(f"samplers={samplers!r} must be a non-empty sequence of {', '.join(map(repr, SAMPLERS))}")
    return {s: sampler_config(config, s) for s in samplers}


def sampler_config(config: Settings, sampler: str) -> ReferenceConfig:
    """The settings the search of one action set runs with (and its file records): ``config``
    itself, or its entry for ``sampler`` if it maps action sets to settings (a continuous planner
    plan's controls join the beam's control set for that search, see
    :func:`~baselines.reference.beam.search`), except that the continuous plans are polished to
    depth 1 at most: a depth-2 move there tries every pair of the ~400 controls at every position
    (~160,000 edited plans each, ~25x the primitives')."""
    check_choice("sampler", sampler, SAMPLERS)
    if isinstance(config, Mapping):
        if sampler not in config:
            raise ConfigError(f"config has no settings for the action set {sampler!r}; it has {sorted(config)!r}")
        config = config[sampler]
    if not isinstance(config, ReferenceConfig):
        raise ConfigError(f"config={config!r} must be a ReferenceConfig (or a mapping of action sets to them)")
    cfg = config
    if sampler == "continuous" and cfg.polish > 1:
        return dataclasses.replace(cfg, polish=1)
    return cfg


def save_reference(ref: ScenarioReference, path: str | Path) -> None:
    """Write ``ref`` as JSON, atomically."""
    atomic_write_text(path, json.dumps(ref.to_dict(), indent=1))


__all__ = [
    "MIN_GAP",
    "SamplerReference",
    "ScenarioReference",
    "Settings",
    "compute_reference",
    "load_reference",
    "load_references",
    "polish_reference",
    "reference_path",
    "save_reference",
    "settings_by_sampler",
]
