"""Demonstrations for behaviour cloning: reference plans on training scenarios, and (DAgger) from
the states a trained policy visits.

    # reference plans on random-20000 ... random-20199 (seeds disjoint from validation and held-out)
    python scripts/demos.py --scenarios 200 --out results/reference-train
    # a DAgger round: fly a run's policy on the same scenarios, plan again from every 4th state it visits
    python scripts/demos.py --scenarios 200 --dagger results/ppo-bc/grid --every 4 --tag r1 \\
        --out results/reference-train
    # ... or only from the episodes it fails, every 10th state within the first 120 steps
    python scripts/demos.py --task xc --scenarios 200 --dagger results/ppo-bc-xc/r1/grid --every 10 --until 120 \
        --failed-only --tag f1 --out results/reference-train-xc
    # cross-country: the task's own reference (battery, its control set) on xc-20000 ...
    python scripts/demos.py --task xc --scenarios 200 --out results/reference-train-xc
    # goal reaching with a time weight [J/kg per s]: the goal env's own search (DAgger keeps prefixes)
    python scripts/demos.py --scenarios 200 --time-weight 1 --out results/reference-train-goal-t1
    # self-imitation: a discrete run's own best of 8 sampled episodes where it beats its mode by 20 J/kg
    python scripts/demos.py --scenarios 200 --first 2000 --self-imitate results/ppo-score/m3-s0 --samples 8 \
        --tag x1 --out results/reference-train-prim-t1
    # ... or its mode improved by one-step lookahead over its 8 likeliest primitives (policy iteration)
    python scripts/demos.py --scenarios 200 --first 5000 --self-imitate results/ppo-score/m3-s0 --lookahead 8 \
        --margin 0 --tag p1 --out results/reference-train-prim-t1
    # thermal climb on sensed lift: the thermalling controller's episodes on climb-20000 ... (no search),
    # then a DAgger round: a run's policy flown, the controller shadowing it and taking over at every 6th step
    python scripts/demos.py --task climb --scenarios 400 --out results/demos-climb
    python scripts/demos.py --task climb --scenarios 200 --dagger results/ppo-climb-clone/c1/continuous --every 6 \
        --tag p1 --out results/demos-climb
    # ... or the run's policy flying every episode to its end, the controller labelling each step
    python scripts/demos.py --task climb --scenarios 400 --dagger results/ppo-climb-clone/c1/continuous --shadow \
        --tag s1 --out results/demos-climb
    # goal reaching at Ts = 10 s on the physical envelope: the goal env's own search in that env
    python scripts/demos.py --scenarios 600 --out results/reference-train-ts10 \
        --env-kwargs '{"duration": 10, "envelope": "physical", "n_points": 10, "max_steps": 120, "time_limit": 1200}'

Then ``python scripts/train_ppo.py --algo grid --set 'demos="results/reference-train"'`` clones the
plans into a policy before PPO (:mod:`baselines.imitation`). One JSON per plan, written atomically
as soon as it is done (the reference search's own files: ``scripts/reference.py``); a rerun resumes
and skips finished files with the same settings. A DAgger start ``<scenario>-<tag>s<k>`` is the
state after the policy's k-th step, taken as the start of a copy of the scenario (the thermals as
at time 0). With ``--task xc`` the copy keeps its start, and the policy's first k actions become
the plan's prefix: the search plans from where they lead, with the battery, time and airspeed the
policy had there (``demo_from`` marks where the imitated part begins).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import time
from pathlib import Path
from typing import Any

from baselines._runs import add_backend_args, check_cli_args, cli_workers, read_json
from baselines.evaluation import PPO_MODELS
from baselines.imitation import DEMO_SEED0, demo_reference_config, visited_starts
from baselines.reference import ReferenceConfig, SamplerReference
from baselines.reference.runner import reference_table, run_references
from baselines.reference.tasks import XC_DEMO_MIN_HEIGHT, XC_DEMO_TIME_WEIGHT, reference_config
from soaring_env._validation import ConfigError
from soaring_env.scenario import atomic_write_text, get_scenario

#: ``--task``: (the env id of the task's own reference search, scenario family, the default time
#: weight [J/kg per s] and floor [m]). Goal reaching with neither runs the yardstick's search
#: (:func:`~baselines.reference.yardstick.compute_reference`: the direct cost too; DAgger starts are
#: copies of the scenario at the visited state, with a fresh time limit); with either, the env's own
#: (:func:`~baselines.reference.tasks.task_reference`: DAgger keeps the policy's steps as a prefix).
DEMO_TASKS: dict[str, tuple[str, str, float, float]] = {
    "goal": ("soaring/SoaringContinuous-v0", "random", 0.0, 0.0),
    "xc": ("soaring/CrossCountryContinuous-v0", "xc", XC_DEMO_TIME_WEIGHT, XC_DEMO_MIN_HEIGHT),
    # no search: the sensed-lift thermalling controller demonstrates (_controller_demos)
    "climb": ("soaring/ThermalClimbContinuous-v0", "climb", 0.0, 0.0),
}


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point; returns the exit status."""
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument(
        "--task",
        choices=DEMO_TASKS,
        default="goal",
        help="goal reaching (default), cross-country, or the thermal climb (the thermalling controller demonstrates)",
    )
    p.add_argument("--scenarios", type=int, default=200, help=f"training scenarios <family>-{DEMO_SEED0} ... (200)")
    p.add_argument("--first", type=int, default=0, help="skip this many training scenarios (default 0)")
    p.add_argument("--sampler", choices=["continuous", "primitive"], default="continuous", help="action set")
    p.add_argument("--beam-width", type=int, default=125, help="the reference search's accuracy knob (125)")
    p.add_argument(
        "--time-weight",
        type=float,
        default=None,
        help=f"the search's time weight [J/kg per s] (--task xc: {XC_DEMO_TIME_WEIGHT:g}, goal: 0 by default; "
        "0: least energy)",
    )
    p.add_argument(
        "--min-height",
        type=float,
        default=None,
        help=f"the search's floor [m] (--task xc: {XC_DEMO_MIN_HEIGHT:g}, goal: 0 by default; 0: down to the ground)",
    )
    p.add_argument("--dagger", default=None, metavar="RUN", help="plan from the states this PPO run visits")
    p.add_argument("--ppo-model", choices=PPO_MODELS, default="final", help="which model of RUN")
    p.add_argument("--every", type=int, default=None, help="with --dagger: every this many steps (default 4)")
    p.add_argument(
        "--shadow",
        action="store_true",
        help="--task climb with --dagger: the run's policy flies every episode to its end and the shadowing "
        "controller labels each step (one plan <name>-<tag> per scenario) instead of taking over at every "
        "--every-th step",
    )
    p.add_argument(
        "--until", type=int, default=None, help="with --dagger: only states within the first this many steps"
    )
    p.add_argument(
        "--failed-only", action="store_true", help="with --dagger: only states of episodes that miss the goal"
    )
    p.add_argument("--tag", default="", help="with --dagger: marks the round in the names (<name>-<tag>s<k>)")
    p.add_argument(
        "--self-imitate",
        default=None,
        metavar="RUN",
        help="no search: fly this discrete run's policy (its mode, and --samples draws) and keep its best "
        "sampled episode where that beats the mode by --margin: a plan the policy can fly (<name>-<tag>s0)",
    )
    p.add_argument("--samples", type=int, default=8, help="with --self-imitate: sampled episodes (default 8)")
    p.add_argument(
        "--temperature", type=float, default=1.0, help="with --self-imitate: of the sampled logits (default 1)"
    )
    p.add_argument(
        "--margin", type=float, default=20.0, help="with --self-imitate: least gain over the mode [J/kg] (20)"
    )
    p.add_argument(
        "--lookahead",
        type=int,
        default=None,
        metavar="C",
        help="with --self-imitate: instead of sampling, improve the mode by one-step lookahead over its C "
        "likeliest primitives at every step, the mode flying on (baselines.imitation.rollout_improved)",
    )
    p.add_argument(
        "--follow",
        choices=["improved", "mode"],
        default="improved",
        help="with --lookahead: decide the steps along the improved episode (default) or try the C primitives "
        "at every state of the mode's own episode and keep that episode, labelled (the policy's own states)",
    )
    p.add_argument(
        "--env-kwargs",
        default=None,
        metavar="JSON",
        help="the task env's gym.make keywords, a JSON object (the env's own search; default: the id's "
        "defaults, or with --dagger the run's), e.g. goal reaching at Ts = 10 s: "
        '\'{"duration": 10, "envelope": "physical", "n_points": 10, "max_steps": 120, "time_limit": 1200}\'',
    )
    p.add_argument(
        "--controller-kwargs",
        default=None,
        metavar="JSON",
        help="--task climb: the thermalling controller's keywords, a JSON object (ThermallingAgent), e.g. "
        '\'{"search": "arm"}\'',
    )
    p.add_argument("--out", type=Path, default=Path("results/reference-train"), help="output directory")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_backend_args(p, "one per CPU core")
    args = p.parse_args(argv)
    check_cli_args(p, args, counts=("scenarios", "beam_width", "every", "until", "workers"), dirs=("out",))
    if args.first < 0:
        p.error(f"--first={args.first} must be >= 0")
    if args.shadow and (args.task != "climb" or args.dagger is None or args.every is not None or not args.tag):
        p.error("--shadow goes with --task climb, --dagger RUN and a --tag, without --every (every step is labelled)")
    if args.every is None:
        args.every = 4
    if not args.tag.isalnum() and args.tag != "":
        p.error(f"--tag={args.tag!r}: letters and digits only")
    env_kwargs = _env_kwargs(p, args.env_kwargs)
    if args.task == "climb":
        searched = (args.self_imitate, args.lookahead, args.time_weight, args.min_height)
        controller = _json_object(p, "--controller-kwargs", args.controller_kwargs, "ThermallingAgent keywords") or {}
        if any(v is not None for v in searched) or args.sampler != "continuous" or args.failed_only:
            p.error("--task climb: the controller's continuous episodes (no search settings: --self-imitate, "
                    "--lookahead, --time-weight, --min-height, --sampler primitive or --failed-only)")  # fmt: skip
        try:
            return _controller_demos(args, env_kwargs, controller)
        except (ConfigError, FileNotFoundError, ValueError) as exc:
            p.error(str(exc))
    if args.controller_kwargs is not None:
        p.error("--controller-kwargs goes with --task climb")
    if args.self_imitate is not None:
        if args.dagger is not None or args.task != "goal" or env_kwargs:
            p.error("--self-imitate goes with goal reaching alone (no --dagger, --task xc or --env-kwargs)")
        if not (0.0 < args.temperature < float("inf")) or not (0.0 <= args.margin < float("inf")):
            p.error(f"--temperature={args.temperature} must be > 0 and --margin={args.margin} >= 0 (finite)")
        if args.samples < 1:
            p.error(f"--samples={args.samples} must be >= 1")
        if args.lookahead is not None and args.lookahead < 1:
            p.error(f"--lookahead={args.lookahead} must be >= 1 (primitives tried per step)")
        if args.follow != "improved" and args.lookahead is None:
            p.error(f"--follow={args.follow} goes with --lookahead")
        try:
            return _self_imitation(args)
        except (ConfigError, FileNotFoundError) as exc:
            p.error(f"--self-imitate={args.self_imitate!r}: {exc}")
    try:
        task_id, family, tw, floor = DEMO_TASKS[args.task]
        tw = tw if args.time_weight is None else args.time_weight
        floor = floor if args.min_height is None else args.min_height
        env_id: str | None = None
        if args.dagger is not None:  # plans for a run's states are made in the env it flew
            env_kwargs = _run_env_kwargs(args.dagger, args.ppo_model, env_kwargs)
        if args.task == "goal" and not tw and not floor and not env_kwargs:  # the yardstick's search, as published
            cfg = demo_reference_config(args.beam_width)
        else:
            import gymnasium as gym

            env_id = {"continuous": task_id, "primitive": task_id.replace("Continuous", "")}[args.sampler]
            probe = gym.make(env_id, **(env_kwargs or {}))
            task_cfg = reference_config(probe, args.beam_width, tw, floor)
            probe.close()
            assert isinstance(task_cfg, ReferenceConfig)
            cfg = task_cfg
        scenarios = [get_scenario(f"{family}-{DEMO_SEED0 + args.first + k}") for k in range(args.scenarios)]
        prefixes: dict[str, list] = {}
        if args.dagger is not None:
            try:
                scenarios, prefixes = _dagger_starts(args, scenarios, task=env_id is not None)
            except (FileNotFoundError, ValueError) as exc:  # no such run, or a run of another env
                p.error(f"--dagger={args.dagger!r}: {exc}")
        t0 = time.perf_counter()
        workers = cli_workers(args, os.cpu_count() or 1)
        print(f"demonstrations: {len(scenarios)} reference searches ({args.sampler}, beam width {cfg.beam_width}) "
              f"-> {args.out}", flush=True)  # fmt: skip
        refs = run_references(
            scenarios,
            args.out,
            samplers=(args.sampler,),
            config=cfg,
            workers=workers,
            progress=not args.no_progress,
            backend=args.backend,
            address=args.address,
            env_id=env_id,
            prefixes=prefixes,
            env_kwargs=env_kwargs,
        )
    except ConfigError as exc:
        p.error(str(exc))
    from baselines.reference import load_references

    everything = load_references(args.out)
    atomic_write_text(args.out / "table.md", reference_table(everything, [args.sampler]) + "\n")
    print(f"{len(refs)} plans in {time.perf_counter() - t0:.0f} s; {len(everything)} in {args.out} (table.md)")
    return 0


def _json_object(p: argparse.ArgumentParser, flag: str, text: str | None, what: str) -> dict[str, Any] | None:
    """``flag``'s JSON object as a dict (None: not given); bad JSON or a non-object is a usage error."""
    if text is None:
        return None
    try:
        value = json.loads(text)
    except json.JSONDecodeError as exc:
        p.error(f"{flag}={text!r} is not JSON ({exc.msg}); a JSON object of {what} is required")
    if not isinstance(value, dict):
        p.error(f"{flag}={text!r}: a JSON object of {what} is required")
    return value


def _env_kwargs(p: argparse.ArgumentParser, text: str | None) -> dict[str, Any] | None:
    """``--env-kwargs`` as a dict (None: not given); bad JSON, a non-object or a scenario is a usage error."""
    value = _json_object(p, "--env-kwargs", text, "gym.make keywords (no 'scenario': --scenarios)")
    if value is not None and "scenario" in value:
        p.error(f"--env-kwargs={text!r}: a JSON object of gym.make keywords (no 'scenario': --scenarios) is required")
    return value


def _run_env_kwargs(run: str, which: str, given: dict[str, Any] | None) -> dict[str, Any]:
    """The env keywords a DAgger round plans in: those the run flew with (its ``config.json``,
    reward-only keywords left out; none: the yardstick's search where the task allows it, as
    before), and ``--env-kwargs`` given too must say the same."""
    from baselines.evaluation import REWARD_ONLY_KWARGS, ppo_env_kwargs, ppo_model_path

    path = ppo_model_path(run, which)
    cfg_path = path.parent / "config.json"
    if not cfg_path.is_file():
        raise ConfigError(f"--dagger={run!r}: no config.json beside {path}")
    own = ppo_env_kwargs(read_json(cfg_path, "--dagger run record"))
    if given is not None and {k: v for k, v in given.items() if k not in REWARD_ONLY_KWARGS} != own:
        raise ConfigError(f"--env-kwargs={given!r}: the run {run} flew with {own!r}; the plans must be made in its env")
    return own


def _dagger_starts(args: argparse.Namespace, scenarios: list, task: bool) -> tuple[list, dict[str, list]]:
    """The DAgger starts of ``args.dagger``'s policy on ``scenarios``: (scenarios, prefixes by name).
    The yardstick's search (``task`` false): copies of the scenarios starting at the visited states
    (no prefixes); an env's own search (``task``: its time, steps and battery carry over): the
    scenarios with the policy's actions up to each visited state as prefixes
    (:func:`baselines.imitation.visited_prefixes`)."""
    from baselines.agents import PPOAgent
    from baselines.evaluation import make_env, ppo_env_kwargs, ppo_model_path
    from baselines.imitation import visited_prefixes

    agent = PPOAgent(ppo_model_path(args.dagger, args.ppo_model))
    task_id = DEMO_TASKS[args.task][0]
    if agent.env_id not in (task_id, task_id.replace("Continuous", "")):
        raise ValueError(f"a run of {agent.env_id}, not of the --task {args.task} env")
    kwargs = ppo_env_kwargs(agent.config)

    def make(sc):  # type: ignore[no-untyped-def]
        env = make_env(agent.env_id, {**kwargs, "scenario": sc})
        agent.reset(env)
        return env

    def act(obs):  # type: ignore[no-untyped-def]
        return agent.predict(obs)[0]

    visits = {"every": args.every, "tag": args.tag, "until": args.until, "failed_only": args.failed_only}
    if task:
        found = visited_prefixes(scenarios, make, act, **visits)
        starts, prefixes = [sc for sc, _ in found], {sc.name: prefix for sc, prefix in found}
    else:
        starts, prefixes = visited_starts(scenarios, make, act, **visits), {}
    print(f"dagger: {len(starts)} states visited by {agent.model_path} on {len(scenarios)} scenarios", flush=True)
    return starts, prefixes


def _flown_plan(episode: dict[str, Any], settings: dict[str, Any], seconds: float, **extra: Any) -> SamplerReference:
    """A flown (not searched) episode -- its ``actions``, ``energy_spent`` [J/kg] and
    ``flight_time`` [s] -- as a reference-format plan (no direct plan, no rollouts)."""
    return SamplerReference(
        best_cost=episode["energy_spent"],
        direct_cost=math.nan,
        actions=episode["actions"],
        direct_actions=[],
        flight_time=episode["flight_time"],
        settings=settings,
        rollouts=0,
        seconds=round(seconds, 3),
        **extra,
    )


def _controller_demos(args: argparse.Namespace, env_kwargs: dict[str, Any] | None, controller: dict[str, Any]) -> int:
    """``--task climb``: the thermalling controller (:class:`baselines.agents.ThermallingAgent`,
    sensed lift only) flies each scenario, or with ``--dagger`` each state the run visits after
    shadowing the run's steps there (:func:`baselines.imitation.controller_plan`); each episode
    that flies to the time limit becomes a plan file in the reference format (one per scenario,
    atomically; a rerun skips files with the same settings). Episodes the controller ends on the
    ground or outside the domain are counted, not written. With ``--shadow`` the run's policy flies
    each scenario to its end instead and the controller labels every step (the plan's ``labels``;
    written however the episode ends). ``controller``: the controller's keywords
    (``--controller-kwargs``), recorded with its settings in every plan."""
    from baselines._runs import progress_bar
    from baselines.agents import PPOAgent, ThermallingAgent
    from baselines.evaluation import make_env, ppo_model_path
    from baselines.imitation import controller_plan
    from baselines.reference import ScenarioReference, save_reference
    from baselines.reference.yardstick import load_reference

    task_id, family, _, _ = DEMO_TASKS["climb"]
    scenarios = [get_scenario(f"{family}-{DEMO_SEED0 + args.first + k}") for k in range(args.scenarios)]
    prefixes: dict[str, list] = {}
    policy: PPOAgent | None = None
    if args.dagger is not None:
        env_kwargs = _run_env_kwargs(args.dagger, args.ppo_model, env_kwargs)
        if args.shadow:
            policy = PPOAgent(ppo_model_path(args.dagger, args.ppo_model))
            scenarios = [dataclasses.replace(sc, name=f"{sc.name}-{args.tag}") for sc in scenarios]
        else:
            scenarios, prefixes = _dagger_starts(args, scenarios, task=True)
    kwargs = dict(env_kwargs or {})
    try:
        demonstrator = ThermallingAgent(**controller)
    except TypeError as exc:  # an unknown keyword
        raise ConfigError(f"--controller-kwargs={controller!r}: {exc}") from None
    settings: dict[str, Any] = {"demonstrator": "thermalling", **demonstrator.settings()}
    if args.dagger is not None:
        how = {"shadow": True} if args.shadow else {"every": args.every}
        settings |= {"dagger": str(args.dagger), "ppo_model": args.ppo_model, **how}
    if kwargs:
        settings["env_kwargs"] = kwargs
    args.out.mkdir(parents=True, exist_ok=True)

    def done(name: str) -> bool:
        path = args.out / f"{name}.json"
        if not path.is_file():
            return False
        plan = load_reference(path).samplers.get("continuous")
        return plan is not None and plan.settings == settings

    todo = [sc for sc in scenarios if not done(sc.name)]
    print(f"demonstrations: {len(todo)} of {len(scenarios)} thermalling-controller episodes to fly -> {args.out}",
          flush=True)  # fmt: skip
    bar = progress_bar(len(todo), 0, not args.no_progress, "controller", "episode")
    t0 = time.perf_counter()
    written = ended = 0
    for sc in todo:
        t1 = time.perf_counter()
        plan = controller_plan(
            lambda s: make_env(task_id, {**kwargs, "scenario": s}),
            ThermallingAgent(**controller),
            sc,
            prefixes.get(sc.name, ()),
            policy,
        )
        ended += plan["terminated"]
        if policy is not None or not plan["terminated"]:  # a policy's crash is labelled too: "pull up"
            ref = _flown_plan(
                plan, settings, time.perf_counter() - t1, demo_from=plan["demo_from"], labels=plan["labels"]
            )
            save_reference(ScenarioReference(sc, math.nan, {"continuous": ref}), args.out / f"{sc.name}.json")
            written += 1
        if bar is not None:
            bar.update(1)
    if bar is not None:
        bar.close()
    kept = " (written: labelled)" if policy is not None else " (not written)"
    print(f"{written} plans written, {ended} episodes ended early{kept}, in {time.perf_counter() - t0:.0f} s "
          f"-> {args.out}", flush=True)  # fmt: skip
    return 0


def _self_imitation(args: argparse.Namespace) -> int:
    """``--self-imitate``: per scenario the run's greedy episode and ``--samples`` sampled ones
    (:func:`baselines.imitation.sampled_episodes`, seeded by the scenario's seed); the best
    sampled episode that reaches the goal becomes a plan file ``<name>-<tag>s0.json`` where it
    spends at least ``--margin`` J/kg less than the greedy one. With ``--lookahead C`` the greedy
    episode improved by one-step lookahead (:func:`baselines.imitation.rollout_improved`) takes the
    sampled ones' place (the log's ``best_sampled``). Every scenario's outcome goes to
    ``self-imitation/<tag>-<first seed>+<count>.json`` in ``--out`` (atomically, after each
    scenario), which the same command resumes from."""
    import dataclasses

    from baselines._runs import progress_bar
    from baselines.agents import PPOAgent
    from baselines.evaluation import make_env, ppo_env_kwargs, ppo_model_path
    from baselines.imitation import best_reached, rollout_improved, sampled_episodes
    from baselines.reference import ScenarioReference, save_reference

    agent = PPOAgent(ppo_model_path(args.self_imitate, args.ppo_model))
    if agent.algo != "discrete" or agent.env_id != "soaring/Soaring-v0":
        raise ConfigError(f"a run of {agent.env_id} ({agent.algo}); self-imitation needs a discrete goal run")
    env = make_env(agent.env_id, ppo_env_kwargs(agent.config))
    agent.reset(env)
    args.out.mkdir(parents=True, exist_ok=True)
    # one log per command (tag and scenario range), so that two commands side by side lose nothing;
    # in a subfolder, since every JSON file of --out is read as a plan
    log_path = args.out / "self-imitation" / f"{args.tag}-{DEMO_SEED0 + args.first}+{args.scenarios}.json"
    log_path.parent.mkdir(exist_ok=True)
    method: dict[str, Any] = (
        {"samples": args.samples, "temperature": args.temperature}
        if args.lookahead is None
        else {"lookahead": args.lookahead, **({"follow": args.follow} if args.follow != "improved" else {})}
    )
    settings = {
        "self_imitate": str(agent.model_path),
        **method,
        "margin": args.margin,
        "time_weight": 0.0,  # chosen by energy alone
    }
    log = read_json(log_path, "self-imitation log") if log_path.exists() else {"settings": settings, "scenarios": {}}
    if log.get("settings") != settings:
        raise ConfigError(f"{log_path} was written with other settings: {log.get('settings')}")
    names = [f"random-{DEMO_SEED0 + args.first + k}" for k in range(args.scenarios)]
    todo = [n for n in names if n not in log["scenarios"]]
    how = f"{args.samples} samples" if args.lookahead is None else f"lookahead over {args.lookahead} primitives"
    print(f"self-imitation: {len(todo)} of {len(names)} scenarios to fly, {how} each", flush=True)
    bar = progress_bar(len(todo), 0, not args.no_progress, "self-imitation", "scenario")
    t0 = time.perf_counter()
    for name in todo:
        sc = get_scenario(name)
        t1 = time.perf_counter()
        if args.lookahead is None:
            greedy, *drawn = sampled_episodes(
                env, agent.logits, sc, samples=args.samples, temperature=args.temperature, seed=int(name.split("-")[1])
            )
            best = best_reached(drawn)
            flown = {"reached": sum(e["success"] for e in drawn)}
        else:
            greedy, improved = rollout_improved(env, agent.logits, sc, candidates=args.lookahead, follow=args.follow)
            best = improved if improved["success"] else None
            flown = {"tried": improved["tried"]}
        greedy_cost = greedy["energy_spent"] if greedy["success"] else math.inf
        kept = best is not None and best["energy_spent"] <= greedy_cost - args.margin
        if kept and best is not None:
            plan = _flown_plan(
                best,
                {**settings, "greedy_cost": greedy["energy_spent"] if greedy["success"] else None},
                time.perf_counter() - t1,
                candidate_costs=[[[a, c] for a, c in step] for step in best.get("candidate_costs", [])],
            )
            copy = dataclasses.replace(sc, name=f"{name}-{args.tag}s0")
            save_reference(ScenarioReference(copy, math.nan, {"primitive": plan}), args.out / f"{copy.name}.json")
        log["scenarios"][name] = {
            "greedy": greedy["energy_spent"] if greedy["success"] else None,
            "best_sampled": best["energy_spent"] if best is not None else None,
            **flown,
            "kept": kept,
        }
        atomic_write_text(log_path, json.dumps(log, indent=1) + "\n")
        if bar is not None:
            bar.update(1)
    if bar is not None:
        bar.close()
    env.close()
    rows = [log["scenarios"][n] for n in names]
    kept_rows = [r for r in rows if r["kept"]]
    gain = sum(r["greedy"] - r["best_sampled"] for r in kept_rows if r["greedy"] is not None)
    print(
        f"{len(kept_rows)} of {len(rows)} scenarios kept ({'best sampled' if args.lookahead is None else 'improved'} "
        f"episode beats the mode by >= "
        f"{args.margin:g} J/kg; {gain / max(len(kept_rows), 1):.0f} J/kg on average where the mode reached the goal) "
        f"in {time.perf_counter() - t0:.0f} s -> {args.out} ({log_path.name})",
        flush=True,
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
