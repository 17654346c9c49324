"""The reference table: :func:`~baselines.reference.yardstick.compute_reference` for many scenarios
in parallel jobs (:func:`baselines.backends.run_jobs`: local worker processes or a Ray cluster),
one JSON file per scenario (written atomically by this process as soon as it is done, so an
interrupted run resumes), and the markdown table built from those files.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from baselines._runs import DirLock, progress_bar
from baselines.backends import check_backend, run_jobs
from baselines.reference.beam import ReferenceConfig
from baselines.reference.tasks import env_keywords, task_reference
from baselines.reference.yardstick import (
    ScenarioReference,
    Settings,
    compute_reference,
    load_reference,
    polish_reference,
    reference_path,
    sampler_config,
    save_reference,
    settings_by_sampler,
)
from baselines.sst.soaring import SAMPLERS
from soaring_env._validation import ConfigError
from soaring_env.model import SoaringModel
from soaring_env.scenario import Scenario


def _job(
    args: tuple[
        dict[str, Any], tuple[str, ...], dict[str, Any], str | None, list[Any], dict[str, Any] | None, dict[str, Any]
    ],
) -> ScenarioReference:
    sc_dict, samplers, cfg_dicts, env_id, prefix, stored, env_kwargs = args
    cfg = {s: ReferenceConfig(**d) for s, d in cfg_dicts.items()}  # the settings per action set
    if stored is not None:  # a finished reference that only lacks the polish
        old = ScenarioReference.from_dict(stored)
        model = SoaringModel(scenario=old.scenario)
        pol = {s: polish_reference(model, s, old.samplers[s], cfg[s].polish) for s in samplers}
        return dataclasses.replace(old, samplers={**old.samplers, **pol})
    if env_id is not None:  # a task's own search (its control set, battery and time limit)
        sc = Scenario.from_dict(sc_dict)
        c = cfg[samplers[0]]
        return task_reference(env_id, sc, c.beam_width, prefix, c.time_weight, c.min_height, env_kwargs)
    return compute_reference(Scenario.from_dict(sc_dict), samplers, cfg)


def _save(ref: ScenarioReference, path: Path) -> None:
    """Write ``ref``, keeping the other action sets of an existing file for the same scenario."""
    if path.exists():
        old = load_reference(path)
        if old.scenario == ref.scenario:
            ref = ScenarioReference(ref.scenario, ref.lower_bound, {**old.samplers, **ref.samplers})
    save_reference(ref, path)


def _status(
    path: Path, scenario: Scenario, samplers: Sequence[str], cfg: Settings, env_kwargs: Mapping[str, Any]
) -> str:
    """``"done"``: a finished file for the same scenario, samplers, settings and env keywords; ``"polish"``: one
    that differs from them only in being polished less deep (it is polished, not recomputed: the
    search before the polish is deterministic); ``"todo"`` otherwise (corrupt files raise, naming it)."""
    if not path.exists():
        return "todo"
    ref = load_reference(path)
    if ref.scenario != scenario:
        return "todo"
    status = "done"
    for s in samplers:
        if s not in ref.samplers or ref.samplers[s].env_kwargs != dict(env_kwargs):
            return "todo"
        # settings read back through ReferenceConfig: a file from before a new field holds its default
        have, want = ReferenceConfig(**ref.samplers[s].settings), sampler_config(cfg, s)
        if have.to_dict() == want.to_dict():
            continue
        if dataclasses.replace(have, polish=want.polish).to_dict() != want.to_dict() or have.polish > want.polish:
            return "todo"
        status = "polish"
    return status


def run_references(
    scenarios: Sequence[Scenario],
    out_dir: str | Path,
    *,
    samplers: Sequence[str] = SAMPLERS,
    config: Settings | None = None,
    workers: int | None = 1,
    fresh: bool = False,
    progress: bool = True,
    backend: str = "local",
    address: str | None = None,
    env_id: str | None = None,
    prefixes: Mapping[str, Sequence[Any]] | None = None,
    env_kwargs: Mapping[str, Any] | None = None,
) -> dict[str, ScenarioReference]:
    """Compute (or load, if already done with the same settings) the reference of every scenario.

    :param scenarios: scenarios with distinct names (the file names).
    :param out_dir: folder of the ``<name>.json`` files (one writer at a time: a lock file).
    :param samplers: action sets.
    :param config: search settings: one for every action set, or one per action set.
    :param workers: scenarios at a time, each single-threaded (None: every CPU of the backend).
    :param fresh: recompute even finished files.
    :param progress: show a progress bar (tqdm, if installed).
    :param backend: ``"local"`` (worker processes) or ``"ray"`` (see :mod:`baselines.backends`).
    :param address: with ``backend="ray"``: a running cluster's address (None: a local Ray instance).
    :param env_id: a goal task's env id (cross-country): its own reference search
        (:func:`~baselines.reference.tasks.task_reference`; ``config`` must then be that task's,
        :func:`~baselines.reference.tasks.reference_config`) instead of the yardstick's.
    :param prefixes: with ``env_id``: by scenario name, env actions flown before the search plans
        (DAgger starts, :func:`baselines.imitation.visited_prefixes`).
    :param env_kwargs: with ``env_id``: ``gym.make`` keywords of the task env (recorded per file;
        a file made with other keywords is done again).
    :returns: the references by scenario name, in the order given.
    """
    cfg = config if config is not None else ReferenceConfig()
    cfg_dicts = {s: c.to_dict() for s, c in settings_by_sampler(cfg, samplers).items()}  # checks them
    check_backend(backend, workers, address)
    kwargs = env_keywords(env_kwargs)
    if kwargs and env_id is None:
        raise ConfigError("env_kwargs need env_id (a task's own reference search)")
    if not all(isinstance(s, Scenario) for s in scenarios):
        raise ConfigError("scenarios must be soaring_env.scenario.Scenario objects")
    names = [s.name for s in scenarios]
    if len(set(names)) != len(names):
        raise ConfigError(f"scenario names must be distinct (they name the files); got {names!r}")
    out = Path(out_dir)
    with DirLock(out, "reference run"):  # refuses a file; creates the folder
        status = {
            s.name: "todo" if fresh else _status(reference_path(out, s.name), s, samplers, cfg, kwargs)
            for s in scenarios
        }
        if env_id is not None:  # a task's reference is never polished: its files are either done or not
            status = {k: "done" if v == "done" else "todo" for k, v in status.items()}
        todo = [s for s in scenarios if status[s.name] != "done"]
        done = len(scenarios) - len(todo)
        if done and progress:
            print(f"resuming: {done} of {len(scenarios)} scenarios already done in {out}", flush=True)
        if todo:
            bar = progress_bar(len(scenarios), done, progress, "reference (the first compiles the kernels)", "scenario")
            pre = dict(prefixes or {})
            if pre and env_id is None:
                raise ConfigError("prefixes need env_id (a task's own reference search)")
            jobs = [
                (
                    s.to_dict(),
                    tuple(samplers),
                    cfg_dicts,
                    env_id,
                    [np.asarray(a).tolist() for a in pre.get(s.name, ())],
                    load_reference(reference_path(out, s.name)).to_dict() if status[s.name] == "polish" else None,
                    kwargs,
                )
                for s in todo
            ]
            for i, ref in run_jobs(_job, jobs, workers=workers, backend=backend, address=address):
                _save(ref, reference_path(out, todo[i].name))
                if bar is not None:
                    bar.update(1)
            if bar is not None:
                bar.close()
    return {s.name: load_reference(reference_path(out, s.name)) for s in scenarios}


def _f(x: float) -> str:
    return f"{x:,.0f}" if math.isfinite(x) else "—"


def reference_table(refs: Mapping[str, ScenarioReference], samplers: Sequence[str] = SAMPLERS) -> str:
    """Markdown: per scenario the lower bound and, per action set, direct and best cost [J/kg], the
    thermal benefit (direct - best), the best plan's flight time and the search time."""
    head = ["scenario", "lower bound"]
    for s in samplers:
        head += [f"{s}: direct", f"{s}: best", f"{s}: benefit", f"{s}: flight [s]", f"{s}: search [s]"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for name, ref in refs.items():
        row = [name, _f(ref.lower_bound)]
        for s in samplers:
            r = ref.samplers.get(s)
            if r is None:
                row += ["—"] * 5
                continue
            row += [
                _f(r.direct_cost),
                _f(r.best_cost),
                _f(r.direct_cost - r.best_cost),
                _f(r.flight_time),
                f"{r.seconds:.0f}",
            ]
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines)


__all__ = ["reference_table", "run_references"]
