"""PPO baselines: train stable-baselines3 ``PPO`` / sb3-contrib ``MaskablePPO`` on the soaring envs.

Four algorithms share one code path (:data:`ALGOS`):

* ``"discrete"`` -- PPO on ``soaring/Soaring-v0`` (174 primitives, no masks);
* ``"masked"`` -- sb3-contrib ``MaskablePPO`` on the same env, with the env's ``action_masks()``;
* ``"continuous"`` -- PPO with a Gaussian policy on ``soaring/SoaringContinuous-v0``;
* ``"grid"`` -- PPO with a categorical policy on ``soaring/SoaringContinuous-v0`` over the
  continuous reference search's control set (:func:`control_grid`: 5 airspeeds x 15 course changes
  x the fixed path angles and the zero-thrust glide; cross-country: its own search's 4 x 7 x 2).
  Why: the reference plans a policy is cloned
  from (:mod:`baselines.imitation`) circle in lift with 360, 540, 720 ... degree turns in either
  direction, which cost about the same but leave on different headings; a Gaussian mean fitted to
  them averages the modes (a 450-degree turn that leaves the thermal sideways), a categorical
  policy keeps them apart.

``TrainConfig(task=...)`` picks the task (:data:`TASKS`): goal reaching (default), the thermal climb
or cross-country (``soaring_env.env.tasks``), with validation on that task's scenario family.

Training draws a new random scenario from each env's ``np_random`` at every reset
(``scenario="random"``); periodic evaluation runs on a fixed *validation* set of scenarios made by
:func:`soaring_env.scenario.make_scenario` from seeds ``VALIDATION_SEED0 + k``, disjoint from the
held-out test seeds ``HELDOUT_SEED0 + k`` of :mod:`baselines.evaluation`.

A run directory holds ``model.zip`` (final), ``best_model.zip`` (best validation return),
``config.json`` (the exact :class:`TrainConfig`, library versions, timings; ``status`` "running",
"done", or "failed" with the ``error`` that ended the run), ``evaluations.npz``
(SB3's EvalCallback log), ``eval_log.json`` (the same per evaluation with success rate, energy and
wall-clock time), ``learning_curve.png``, ``checkpoints/`` and, optionally, ``tb/`` (TensorBoard).

torch runs with one thread per process by default (:func:`torch.set_num_threads`): on a small CPU
machine the environments, not the 2 x 128 MLP, are the bottleneck of PPO. Cloning alone (no env
steps) is the MLP's, and ``torch_threads=2`` speeds it up when nothing else runs.
"""

from __future__ import annotations

import dataclasses
import json
import math
import platform
import signal
import sys
import threading
import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from soaring_env._validation import (
    ConfigError,
    as_float_array,
    check_array_finite,
    check_bool,
    check_positive,
)
from soaring_env.physics import glide_height_loss
from soaring_env.scenario import HELDOUT_SEED0, VALIDATION_SEED0, Scenario, atomic_write_text, get_scenario

DISCRETE_ID = "soaring/Soaring-v0"
CONTINUOUS_ID = "soaring/SoaringContinuous-v0"
#: Algorithm name -> env id it trains on (goal reaching).
ALGOS: dict[str, str] = {
    "discrete": DISCRETE_ID,
    "masked": DISCRETE_ID,
    "continuous": CONTINUOUS_ID,
    "grid": CONTINUOUS_ID,
}
#: Policy parametrisations (``TrainConfig.policy``).
POLICIES = ("mlp", "scoring", "successor")
#: The algorithms that fly the continuous env ids.
CONTINUOUS_ALGOS = ("continuous", "grid")
#: Task -> (env id of the primitive algorithms, env id of ``continuous``, scenario family).
TASKS: dict[str, tuple[str, str, str]] = {
    "goal": (DISCRETE_ID, CONTINUOUS_ID, "random"),
    "climb": ("soaring/ThermalClimb-v0", "soaring/ThermalClimbContinuous-v0", "climb"),
    "xc": ("soaring/CrossCountry-v0", "soaring/CrossCountryContinuous-v0", "xc"),
}
#: ``"native"``: one natively batched env (:class:`~soaring_env.env.sb3.SoaringSB3VecEnv`);
#: ``"dummy"`` / ``"subproc"``: SB3's vector envs over single ``gym.make`` envs.
VEC_ENVS = ("native", "dummy", "subproc")


def _module_qualified(env_id: str) -> str:
    """``"soaring_env:<id>"``: makes subprocess workers import (and so register) the package."""
    return env_id if ":" in env_id else f"soaring_env:{env_id}"


@dataclass(frozen=True)
class TrainConfig:
    """Everything that defines a training run; saved verbatim as ``config.json`` beside the model.

    :param algo: ``"discrete"``, ``"masked"``, ``"continuous"`` or ``"grid"`` (see :data:`ALGOS`).
    :param task: ``"goal"`` (goal reaching, default), ``"climb"`` (thermal climb) or ``"xc"``
        (cross-country): the env ids of :data:`TASKS`; validation on that task's scenario family.
    :param total_timesteps: environment steps (one primitive or control segment each) to train for;
        0 with ``demos``: behaviour cloning alone (``model.zip`` is then the cloned policy).
    :param max_minutes: wall-clock cap on training [min]; stops early, saving the model (None: no cap).
    :param n_envs: parallel environments; more give PPO more diverse scenarios per update.
    :param vec_env: ``"native"`` (default: the natively batched env, one rollout call per step for
        all ``n_envs``), ``"dummy"`` (SB3's in-process loop over single envs) or ``"subproc"``.
        All three give the same transitions for the same seed.
    :param seed: seeds the policy, the env resets and hence the random training scenarios.
    :param learning_rate: Adam step size; decays linearly to ``lr_final_fraction`` of it.
    :param lr_final_fraction: learning-rate fraction left at the end (1.0: constant).
    :param n_steps: rollout length per env and update (n_steps * n_envs samples per update).
    :param batch_size: minibatch size of the PPO epochs.
    :param n_epochs: passes over each rollout.
    :param gamma: discount; episodes are ~10 steps of 30 s. Below 1 the goal bonus rewards arriving
        sooner: fine-tuning a soaring policy with 0.99, PPO unlearns the circling
        (docs/learning-to-soar.md, round twenty-two).
    :param gae_lambda: GAE bias/variance trade-off.
    :param clip_range: PPO ratio clip.
    :param ent_coef: entropy bonus; None: 0.03 for the 174-way discrete policies (with 0.01 they
        stalled at ~70 % validation success, never learning to climb to a higher goal), 0.01 for
        the Gaussian and the grid policies.
    :param vf_coef: value-loss weight.
    :param max_grad_norm: gradient clipping.
    :param net_arch: hidden layers of the separate policy and value MLPs (with ``policy="scoring"``:
        the value MLP's; the scorer's own are ``scorer_hidden``).
    :param policy: ``"mlp"`` (default: SB3's MLP policy) or ``"scoring"`` (``algo="discrete"`` only:
        :class:`baselines.scoring.PrimitiveScoringPolicy`, each primitive's logit computed by one
        MLP shared by all primitives from the observation and where that primitive would take the
        aircraft -- its path in the observed wind, relative to the goal and the observed thermals),
        or ``"successor"`` (likewise: :class:`baselines.scoring.SuccessorPolicy`, each primitive
        flown through the thermals the observation shows and its successor state scored).
    :param scorer_hidden: with ``policy="scoring"`` or ``"successor"``: the widths of the shared
        scoring MLP.
    :param scorer_estimate: with ``policy="successor"``: also give the scorer the reference search's
        cost-to-go estimate at each successor (:meth:`baselines.scoring.SuccessorFeatures.estimates`,
        the heuristic the demonstrations' beam ranks by), in the field the observation shows.
    :param scorer_lift: with ``policy="successor"``: also give the scorer the updraft the observed
        field has at each successor's end point and on a 20 m ring around it
        (:meth:`baselines.scoring.SuccessorFeatures.lift_at`): where the next edge can climb.
    :param scorer_skip: with ``policy="successor"``: add a linear layer from the successor features
        to the logit beside the scorer's MLP (initialised as SB3 initialises the others; zero where
        ``init_from`` a policy without it, which then starts from that policy unchanged). Default off.
    :param demo_equivalents: with ``policy="successor"`` and ``demos``: each row's label is the set
        of primitives whose successor is near-equivalent to the demonstrated one's (end point
        within 50 m, height within 10 m, edge cost within 20 J/kg:
        :func:`baselines.scoring.near_equivalent`), and the cloning fits the set's summed
        probability, so the policy need not learn the search's tie-breaks. Default off.
    :param demo_q_weight: discrete policies with ``demos``: weight of the cloning's cost fit
        (:func:`baselines.imitation.pretrain`'s ``q_weight``): the demonstrated primitive's logit,
        read as ``beta - alpha * logit`` [kJ/kg], is fitted to the plan's cost from that state on
        (edge costs plus the search's time weight times the time left), beside the cross-entropy.
        0 (default): off.
    :param demo_soft_temperature: discrete policies with ``demos`` [J/kg]: where a plan was improved
        by lookahead (``scripts/demos.py --self-imitate RUN --lookahead C``, which records what each
        tried primitive cost), the row's label is the distribution ``exp(-(J - J_min) / T)`` over the
        primitives tried there rather than the one kept (:func:`baselines.imitation.demonstrations`).
        0 (default): hard labels.
    :param log_std_init: initial log standard deviation of the continuous policy.
    :param shaping: weight of this module's extra potential-based shaping (Ng et al. 1999),
        ``shaping * (gamma * phi(s') - phi(s))`` with ``phi = -d_goal / 1 km``; 0 (default) leaves
        the env's own reward (which already has a telescoping progress term) unchanged.
    :param body_frame: observe through :class:`BodyFrameObservation` (goal, wind and thermal offsets
        in the aircraft's frame, plus goal distance and bearing): the policy need not learn rotations.
        None (default): on (:class:`BodyFrame` finds the pairs of any task's layout by name).
    :param final_glide: append the :class:`FinalGlide` margin to the body-frame observation (the
        height left over the goal after the flattest zero-thrust glide to it in the wind): when to
        leave a thermal becomes a threshold on one input. Goal tasks only; default off.
    :param turn_exponent: continuous only: the policy's turn channel is mapped through
        :class:`TurnCurveAction` (``sign(u) |u|^p``) for fine steering; 1 switches it off.
    :param env_kwargs: keyword arguments for ``gym.make`` (config fields of the env); the scenario
        is forced to ``"random"`` for training.
    :param init_from: start from the policy of an earlier run (its directory or a ``.zip``) with the
        same observation and action spaces -- a curriculum: e.g. learn to thermal with no goal
        reward first, then to reach the goal. The value function, the optimizer and the continuous
        policy's spread (``log_std_init``) start fresh: the earlier values belong to the earlier
        rewards (a critic that learnt "the goal costs 50" keeps a policy from trying it again), and
        a policy that had become nearly deterministic (std 0.02) would not explore the new task.
        None (default): fresh weights.
    :param ensemble_of: with ``policy="successor"``: two or more earlier runs (directories or
        ``.zip`` paths) of successor policies with this run's scorer settings, loaded into one
        policy whose logits are the mean of theirs (each run a member of the scorer; the features are
        computed once for all). E.g. the stages of one chain of tuning rounds, which pick different
        thermals on many scenarios (docs/learning-to-soar.md, round twenty). The value function starts fresh as with
        ``init_from`` (which cannot be given too), so ``net_arch`` need not be the runs'. Empty
        (default): one scorer.
    :param demos: a folder of reference-search files (``scripts/reference.py --out DIR``): before
        PPO, the policy is fitted to their plans replayed through this run's env and the critic to
        their returns (:mod:`baselines.imitation`, behaviour cloning), after ``init_from`` if both
        are given; the fitted model is saved as ``bc_model.zip``. The env must fly the reference's
        dynamics (the task's default duration and envelope); reward settings may differ. The
        continuous policy's spread is then reset to ``log_std_init``. None (default): no cloning.
    :param demo_match: with ``demos``: only the files whose scenario name matches this regular
        expression as a whole (e.g. the base plans and one DAgger round of a folder that holds more
        rounds: ``xc-20([01]\\d\\d|2[0-3]\\d)(-f1s\\d+)?``). None (default): every file.
    :param demo_mirror: clone the mirror images of the plans too (east -> -east, every turn
        reversed: the turn channel, the grid's mirrored row or the mirrored primitive,
        :meth:`~soaring_env.primitives.PrimitiveLibrary.mirror_indices`;
        :func:`baselines.imitation.with_mirror_images`).
    :param demo_visit_weight: the weight of each DAgger plan's first row, the state the policy
        visited, in the cloning (:func:`baselines.imitation.demonstrations`; e.g. the round's
        ``--every``). 1 (default): every row alike.
    :param demo_start_weight: the weight of each plan's row at the scenario's start (a plan flown
        from time 0, not a DAgger plan): the first decision, which picks the thermal a flight heads
        for (docs/learning-to-soar.md, round fourteen: a lookahead at that step alone closes half the gap to a
        lookahead at every step), is one row in a plan's seven or so. 1 (default): every row alike.
    :param demo_epochs: passes of the behaviour cloning over the demonstrations (0: none, e.g. to
        rehearse the demonstrations of a policy that ``init_from`` cloned before).
    :param demo_learning_rate: Adam step size of the behaviour cloning.
    :param demo_batch_size: rows per minibatch of the behaviour cloning (a smaller one takes more
        steps per pass over the demonstrations at about the same cost per pass).
    :param demo_lr_final_fraction: the cloning's step size falls linearly, minibatch by minibatch,
        from ``demo_learning_rate`` to this fraction of it (1, default: constant). For the
        successor policy a decay to 2 % fitted worse and flew no better (docs/learning-to-soar.md, round ten).
    :param demo_rehearsal: with ``demos``: after every PPO update, this many minibatches of the
        demonstrations are fitted again (the actor's log-likelihood, with PPO's own optimizer), so
        that PPO improves on the cloned policy without forgetting it (0: PPO alone).
    :param critic_warmup: env steps at the start of PPO whose updates train only the value
        function, the policy's parameters frozen (0, default: none). After ``init_from`` or a cloning
        the critic starts afresh, and PPO's first updates follow its untrained advantages; a
        warm-up lets it learn the policy's returns first (docs/learning-to-soar.md, round twenty-two).
    :param demo_starts: with ``demos``: the share of the training resets that start part-way along
        one of their plans instead of at a random scenario's start (:class:`baselines.imitation.DemoStarts`:
        a plan and a step drawn uniformly, the plan flown to that step), so that PPO practises the
        climb and the glide on where the plans fly them. 0 (default): every episode from its start.
        Needs ``vec_env="dummy"`` or ``"subproc"`` (the wrapper wraps single envs).
    :param eval_freq: evaluate every this many total timesteps.
    :param n_eval_scenarios: validation scenarios per evaluation (one episode each).
    :param checkpoint_freq: save a checkpoint every this many total timesteps (0: never).
    :param tensorboard: write TensorBoard logs to ``<out_dir>/tb``.
    :param progress_bar: show SB3's progress bar (tqdm + rich).
    :param verbose: SB3 verbosity (1: training stats); -1 also silences the line per evaluation.
    :param torch_threads: torch's threads in this process (default 1). More help the cloning
        (``demos``) on an otherwise idle machine; results are deterministic for a fixed count.
    """

    algo: str = "masked"
    task: str = "goal"
    total_timesteps: int = 1_000_000
    max_minutes: float | None = None
    n_envs: int = 8
    vec_env: str = "native"
    seed: int = 0
    learning_rate: float = 3e-4
    lr_final_fraction: float = 0.1
    n_steps: int = 256
    batch_size: int = 256
    n_epochs: int = 5
    gamma: float = 0.99
    gae_lambda: float = 0.95
    clip_range: float = 0.2
    ent_coef: float | None = None
    vf_coef: float = 0.5
    max_grad_norm: float = 0.5
    net_arch: tuple[int, ...] = (128, 128)
    policy: str = "mlp"
    scorer_hidden: tuple[int, ...] = (64, 64)
    scorer_estimate: bool = False
    scorer_lift: bool = False
    scorer_skip: bool = False
    demo_equivalents: bool = False
    demo_q_weight: float = 0.0
    demo_soft_temperature: float = 0.0
    log_std_init: float = -0.5
    shaping: float = 0.0
    body_frame: bool | None = None
    final_glide: bool = False
    turn_exponent: float = 3.0
    env_kwargs: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    init_from: str | None = None
    ensemble_of: tuple[str, ...] = ()
    demos: str | None = None
    demo_match: str | None = None
    demo_mirror: bool = True
    demo_visit_weight: float = 1.0
    demo_start_weight: float = 1.0
    demo_epochs: int = 200
    demo_learning_rate: float = 1e-3
    demo_lr_final_fraction: float = 1.0
    demo_batch_size: int = 256
    demo_rehearsal: int = 0
    critic_warmup: int = 0
    demo_starts: float = 0.0
    eval_freq: int = 25_000
    n_eval_scenarios: int = 40
    checkpoint_freq: int = 500_000
    tensorboard: bool = False
    progress_bar: bool = True
    verbose: int = 0
    torch_threads: int = 1

    def __post_init__(self) -> None:
        if self.algo not in ALGOS:
            raise ValueError(f"algo={self.algo!r} is unknown; known: {', '.join(ALGOS)}")
        if self.task not in TASKS:
            raise ValueError(f"task={self.task!r} is unknown; known: {', '.join(TASKS)}")
        if self.algo == "grid" and self.task == "climb":
            raise ValueError("algo='grid' needs a goal task (goal or xc): its controls are the goal search's")
        if self.body_frame is None:
            object.__setattr__(self, "body_frame", True)
        if not isinstance(self.final_glide, bool):
            raise ValueError(f"final_glide={self.final_glide!r} must be true or false")
        if self.final_glide and (not self.body_frame or self.task == "climb"):
            raise ValueError("final_glide needs body_frame=True and a task with a goal (goal or xc)")
        if self.vec_env not in VEC_ENVS:
            raise ValueError(f"vec_env={self.vec_env!r} is unknown; known: {', '.join(VEC_ENVS)}")
        if self.vec_env == "native" and self.shaping:
            raise ValueError("shaping needs vec_env='dummy' or 'subproc' (GoalDistanceShaping wraps single envs)")
        for name in ("total_timesteps", "n_envs", "n_steps", "batch_size", "n_epochs", "n_eval_scenarios"):
            # 0 timesteps: the cloning alone, or the ensemble of earlier runs as it is
            zero_ok = name == "total_timesteps" and (self.demos is not None or bool(self.ensemble_of))
            if int(getattr(self, name)) < (0 if zero_ok else 1):
                raise ValueError(
                    f"{name}={getattr(self, name)!r} must be >= 1 (total_timesteps: 0 with demos or ensemble_of)"
                )
        if self.eval_freq < 1 or self.checkpoint_freq < 0:
            raise ValueError("eval_freq must be >= 1 and checkpoint_freq >= 0")
        if self.max_minutes is not None and not self.max_minutes > 0:
            raise ValueError(f"max_minutes={self.max_minutes!r} must be > 0 or None")
        if not 0.0 < self.gamma <= 1.0:
            raise ValueError(f"gamma={self.gamma!r} must lie in (0, 1]")
        object.__setattr__(self, "net_arch", tuple(int(n) for n in self.net_arch))
        if self.policy not in POLICIES:
            raise ValueError(f"policy={self.policy!r} is unknown; known: {', '.join(POLICIES)}")
        if self.policy != "mlp" and (self.algo != "discrete" or not self.body_frame or self.task != "goal"):
            raise ValueError(
                f"policy={self.policy!r} needs algo='discrete' on the goal task with body_frame=True "
                f"(got algo={self.algo!r}, task={self.task!r}, body_frame={self.body_frame!r})"
            )
        hidden = self.scorer_hidden
        if isinstance(hidden, (str, bytes)) or not hasattr(hidden, "__iter__") or not hidden:
            raise ValueError(f"scorer_hidden={hidden!r} must be a non-empty list of layer widths")
        if any(isinstance(n, bool) or not isinstance(n, int) or n < 1 for n in hidden):
            raise ValueError(f"scorer_hidden={hidden!r} must hold integers >= 1")
        object.__setattr__(self, "scorer_hidden", tuple(int(n) for n in hidden))
        if not isinstance(self.scorer_estimate, bool):
            raise ValueError(f"scorer_estimate={self.scorer_estimate!r} must be true or false")
        if self.scorer_estimate and self.policy != "successor":
            raise ValueError(f"scorer_estimate=True needs policy='successor' (got policy={self.policy!r})")
        if not isinstance(self.scorer_lift, bool):
            raise ValueError(f"scorer_lift={self.scorer_lift!r} must be true or false")
        if self.scorer_lift and self.policy != "successor":
            raise ValueError(f"scorer_lift=True needs policy='successor' (got policy={self.policy!r})")
        if not isinstance(self.scorer_skip, bool):
            raise ValueError(f"scorer_skip={self.scorer_skip!r} must be true or false")
        if self.scorer_skip and self.policy != "successor":
            raise ValueError(f"scorer_skip=True needs policy='successor' (got policy={self.policy!r})")
        if not isinstance(self.demo_equivalents, bool):
            raise ValueError(f"demo_equivalents={self.demo_equivalents!r} must be true or false")
        if self.demo_equivalents and self.policy != "successor":
            raise ValueError(f"demo_equivalents=True needs policy='successor' (got policy={self.policy!r})")
        if self.ent_coef is None:
            object.__setattr__(self, "ent_coef", 0.01 if self.algo in CONTINUOUS_ALGOS else 0.03)
        object.__setattr__(self, "env_kwargs", dict(self.env_kwargs))
        if self.init_from is not None:
            if not isinstance(self.init_from, (str, Path)):
                raise ValueError(f"init_from={self.init_from!r} must be a run directory or .zip path (a string)")
            object.__setattr__(self, "init_from", str(self.init_from))
            _init_model_path(self.init_from)
        runs = self.ensemble_of
        if isinstance(runs, (str, bytes)) or not hasattr(runs, "__iter__"):
            raise ValueError(f"ensemble_of={runs!r} must be a list of run directories or .zip paths")
        runs = tuple(runs)
        if runs:
            if len(runs) < 2 or not all(isinstance(r, (str, Path)) for r in runs):
                raise ValueError(f"ensemble_of={list(runs)!r} must name at least two runs (directories or .zip paths)")
            if self.policy != "successor" or self.init_from is not None:
                raise ValueError(
                    f"ensemble_of needs policy='successor' and no init_from (got policy={self.policy!r}, "
                    f"init_from={self.init_from!r})"
                )
            runs = tuple(str(r) for r in runs)
            for k, r in enumerate(runs):
                _init_model_path(r, f"ensemble_of[{k}]")
        object.__setattr__(self, "ensemble_of", runs)
        if self.demos is not None:
            if not isinstance(self.demos, (str, Path)) or not Path(self.demos).is_dir():
                raise ValueError(f"demos={self.demos!r} must be a folder of reference files (scripts/reference.py)")
            object.__setattr__(self, "demos", str(self.demos))
        if self.demo_match is not None:
            if self.demos is None:
                raise ValueError("demo_match needs demos")
            from baselines.imitation import demo_pattern

            demo_pattern(self.demo_match)
        if isinstance(self.demo_rehearsal, bool) or not isinstance(self.demo_rehearsal, int) or self.demo_rehearsal < 0:
            raise ValueError(f"demo_rehearsal={self.demo_rehearsal!r} must be an integer >= 0")
        if self.demo_rehearsal and self.demos is None:
            raise ValueError("demo_rehearsal needs demos")
        if isinstance(self.critic_warmup, bool) or not isinstance(self.critic_warmup, int) or self.critic_warmup < 0:
            raise ValueError(f"critic_warmup={self.critic_warmup!r} must be an integer >= 0 [env steps]")
        if self.demo_equivalents and self.demos is None:
            raise ValueError("demo_equivalents=True needs demos")
        qw = self.demo_q_weight
        if isinstance(qw, bool) or not isinstance(qw, (int, float)) or not 0.0 <= qw < math.inf:
            raise ValueError(f"demo_q_weight={qw!r} must be a finite number >= 0")
        object.__setattr__(self, "demo_q_weight", float(qw))
        if qw > 0.0 and (self.demos is None or self.algo in CONTINUOUS_ALGOS):
            raise ValueError(f"demo_q_weight={qw!r} needs demos and a discrete algo (got algo={self.algo!r})")
        st = self.demo_soft_temperature
        if isinstance(st, bool) or not isinstance(st, (int, float)) or not 0.0 <= st < math.inf:
            raise ValueError(f"demo_soft_temperature={st!r} must be a finite number >= 0 [J/kg]")
        object.__setattr__(self, "demo_soft_temperature", float(st))
        if st > 0.0 and (self.demos is None or self.algo in CONTINUOUS_ALGOS or self.demo_equivalents):
            raise ValueError(
                f"demo_soft_temperature={st!r} needs demos and a discrete algo, without demo_equivalents "
                f"(got algo={self.algo!r})"
            )
        f = self.demo_starts
        if isinstance(f, bool) or not isinstance(f, (int, float)) or not 0.0 <= f <= 1.0:
            raise ValueError(f"demo_starts={f!r} must be a number in [0, 1]")
        object.__setattr__(self, "demo_starts", float(f))
        if f > 0.0 and self.demos is None:
            raise ValueError("demo_starts needs demos")
        if f > 0.0 and self.vec_env == "native":
            raise ValueError("demo_starts needs vec_env='dummy' or 'subproc' (DemoStarts wraps single envs)")
        for field in ("demo_visit_weight", "demo_start_weight"):
            w = getattr(self, field)
            if isinstance(w, bool) or not isinstance(w, (int, float)) or not 0.0 < w < math.inf:
                raise ValueError(f"{field}={w!r} must be a finite number > 0")
        if not isinstance(self.demo_mirror, bool):
            raise ValueError(f"demo_mirror={self.demo_mirror!r} must be true or false")
        if int(self.demo_epochs) < 0 or not 0.0 < float(self.demo_learning_rate) < 1.0:
            raise ValueError(
                f"demo_epochs={self.demo_epochs!r} must be >= 0 and "
                f"demo_learning_rate={self.demo_learning_rate!r} in (0, 1)"
            )
        bs = self.demo_batch_size
        if isinstance(bs, bool) or not isinstance(bs, int) or bs < 1:
            raise ValueError(f"demo_batch_size={bs!r} must be an integer >= 1")
        ff = self.demo_lr_final_fraction
        if isinstance(ff, bool) or not isinstance(ff, (int, float)) or not 0.0 <= ff <= 1.0:
            raise ValueError(f"demo_lr_final_fraction={ff!r} must be a number in [0, 1]")
        if "scenario" in self.env_kwargs:
            raise ValueError("env_kwargs must not set 'scenario': training always draws random scenarios")
        nt = self.torch_threads
        if isinstance(nt, bool) or not isinstance(nt, int) or not 1 <= nt <= 64:
            raise ValueError(f"torch_threads={nt!r} must be an integer in [1, 64]")

    @property
    def env_id(self) -> str:
        """The env this algorithm trains on (the task's, :data:`TASKS`)."""
        discrete, continuous, _ = TASKS[self.task]
        return continuous if self.algo in CONTINUOUS_ALGOS else discrete

    @property
    def family(self) -> str:
        """The task's scenario family (validation scenarios ``<family>-5000 ...``)."""
        return TASKS[self.task][2]

    def to_dict(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        d["net_arch"] = list(self.net_arch)
        d["scorer_hidden"] = list(self.scorer_hidden)
        d["env_kwargs"] = dict(self.env_kwargs)
        d["env_id"] = self.env_id
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> TrainConfig:
        names = {f.name for f in dataclasses.fields(cls)}
        return cls(**{k: v for k, v in d.items() if k in names})


# --- environments -------------------------------------------------------------------------------
class GoalDistanceShaping(gym.Wrapper):
    """Potential-based reward shaping towards the goal (Ng, Harada & Russell 1999).

    Adds ``weight * (gamma * phi(s') - phi(s))`` with ``phi(s) = -d(s) / scale``, ``d`` the 3-D
    distance [m] to the goal centre, and ``phi = 0`` at terminal states (goal, crash, out of
    bounds) -- the form that provably keeps the optimal policies of the discounted problem.
    Truncated (time-limit) steps keep ``phi(s')``: PPO bootstraps them.

    :param weight: shaping weight [reward per ``scale``].
    :param gamma: the discount of the learner.
    :param scale: distance unit [m].
    """

    def __init__(self, env: gym.Env, weight: float = 1.0, gamma: float = 0.99, scale: float = 1000.0) -> None:
        super().__init__(env)
        self.weight = float(weight)
        self.gamma = float(gamma)
        self.scale = float(scale)
        self._phi = 0.0

    def potential(self) -> float:
        """phi of the current state of the base env."""
        base: Any = self.env.unwrapped
        s = np.asarray(base.state, dtype=np.float64)
        g = base.scenario.require_goal()
        d = float(g.distance(s[0], s[1], s[3]))
        return -d / self.scale

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        obs, info = self.env.reset(**kwargs)
        self._phi = self.potential()
        return obs, info

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        phi_next = 0.0 if terminated else self.potential()
        bonus = self.weight * (self.gamma * phi_next - self._phi)
        self._phi = phi_next
        info = dict(info)
        info["shaping"] = bonus
        return obs, float(reward) + bonus, terminated, truncated, info


def body_frame(obs: np.ndarray, n_base: int = 11, n_thermal_features: int = 5) -> np.ndarray:
    """Rotate the horizontal vectors of an observation into the aircraft's frame and append the
    goal's horizontal distance and bearing.

    The env reports the goal, wind and thermal offsets as (north, east) and the course as
    (sin chi, cos chi); a policy must then learn a rotation (products of inputs) before it can steer.
    Here each (north, east) pair becomes (ahead, right) = (n cos chi + e sin chi, -n sin chi + e cos chi),
    and ``[|goal|, sin(bearing - chi), cos(bearing - chi)]`` are appended (distance in the env's
    position units). Works on one observation (D,) or a batch (B, D); float32 in, float32 out.
    """
    o = np.asarray(obs, dtype=np.float32)
    x = o.reshape(-1, o.shape[-1]).astype(np.float64)
    s, c = x[:, 3], x[:, 4]
    pairs = [(0, 1), (9, 10)]
    n_th = (x.shape[1] - n_base) // n_thermal_features
    pairs += [(n_base + n_thermal_features * j + 1, n_base + n_thermal_features * j + 2) for j in range(n_th)]
    out = x.copy()
    for i, k in pairs:
        out[:, i] = x[:, i] * c + x[:, k] * s
        out[:, k] = -x[:, i] * s + x[:, k] * c
    dist = np.hypot(x[:, 0], x[:, 1])
    safe = np.where(dist > 1e-9, dist, 1.0)
    extra = np.stack(
        [dist, np.where(dist > 1e-9, out[:, 1] / safe, 0.0), np.where(dist > 1e-9, out[:, 0] / safe, 1.0)], axis=1
    )
    res = np.concatenate([out, extra], axis=1).astype(np.float32)
    return res.reshape(*o.shape[:-1], res.shape[-1])


#: Observation entries that the mirror image (east -> -east) leaves as they are.
_MIRROR_INVARIANT = frozenset({"cos_course", "height", "updraft", "edge_lift", "airspeed", "battery", "time_left"})


@dataclass(frozen=True)
class FinalGlide:
    """The final-glide margin, what a glider pilot's final-glide computer shows: the height [m]
    the aircraft would have left over the goal centre after the flattest straight zero-thrust glide
    to it in the observed wind (negative: it cannot glide there). It turns "when to leave a
    thermal" into a threshold on one number, where a policy would otherwise have to learn the
    product of distance, polar and wind.

    Built by :meth:`of` from an env's aircraft, envelope and observation scales; picklable.

    :param airspeeds: airspeeds of the straight glides considered [m/s].
    :param angles: their zero-thrust path angles [rad] (< 0).
    :param position_scale: the env's horizontal distance scale [m]; :param height_scale: height
        scale [m]; :param wind_scale: horizontal wind scale [m/s] (the observation's units).
    """

    airspeeds: tuple[float, ...]
    angles: tuple[float, ...]
    position_scale: float
    height_scale: float
    wind_scale: float

    #: The margin's bound in height units (clipped, as every observation entry).
    BOUND = 3.0

    def __post_init__(self) -> None:
        v = as_float_array("airspeeds", self.airspeeds)
        g = as_float_array("angles", self.angles)
        if v.ndim != 1 or v.size < 1 or g.shape != v.shape:
            raise ConfigError(
                f"airspeeds ({v.size}) and angles ({g.size}) must be non-empty 1-D sequences of one length"
            )
        check_array_finite("airspeeds", v)
        check_array_finite("angles", g)
        if np.any(v <= 0.0) or np.any(g >= 0.0) or np.any(g <= -math.pi / 2):
            raise ConfigError("airspeeds must be > 0 m/s and angles in (-pi/2, 0) rad (descending glides)")
        for name in ("position_scale", "height_scale", "wind_scale"):
            check_positive(name, getattr(self, name))

    @classmethod
    def of(cls, env: Any) -> FinalGlide:
        """From a goal env (unwrapped or not): 21 airspeeds across its envelope, the zero-thrust
        angles that hold up to the domain's ceiling (:meth:`Aircraft.glide_angle`)."""
        u = env.unwrapped
        cfg = u.config
        speeds, angles = u.model.straight_glides(21)
        return cls(
            tuple(float(v) for v in speeds),
            tuple(float(g) for g in angles),
            float(cfg.position_scale),
            float(cfg.height_scale),
            float(cfg.wind_scale),
        )

    def margin(
        self,
        goal_north: np.ndarray,
        goal_east: np.ndarray,
        goal_up: np.ndarray,
        wind_north: np.ndarray,
        wind_east: np.ndarray,
    ) -> np.ndarray:
        """The margin in height units, clipped to +-:attr:`BOUND`, from the raw (scaled) observation
        entries (arrays of one shape). The glide flies the goal's bearing, crabbing into the
        crosswind; an airspeed whose ground speed is not positive is skipped.

        :raises ConfigError: a non-finite entry (observations are finite and clipped)."""
        arrays = []
        for name, x in zip(
            ("goal_north", "goal_east", "goal_up", "wind_north", "wind_east"),
            (goal_north, goal_east, goal_up, wind_north, wind_east),
            strict=True,
        ):
            arrays.append(as_float_array(name, x))
            check_array_finite(name, arrays[-1])
        shape = arrays[0].shape
        if any(a.shape != shape for a in arrays):
            raise ConfigError(f"the margin's inputs must share one shape; got {[a.shape for a in arrays]}")
        gn_, ge_, up_, wn_, we_ = (a.ravel() for a in arrays)
        v = np.asarray(self.airspeeds)[None, :]
        g = np.asarray(self.angles)[None, :]
        gn, ge = gn_ * self.position_scale, ge_ * self.position_scale
        d = np.hypot(gn, ge)
        safe = np.where(d > 1e-9, d, 1.0)
        un, ue = np.where(d > 1e-9, gn / safe, 1.0), np.where(d > 1e-9, ge / safe, 0.0)
        wn, we = wn_ * self.wind_scale, we_ * self.wind_scale
        along, cross = wn * un + we * ue, -wn * ue + we * un
        loss = glide_height_loss(d[:, None], v, g, along[:, None], cross[:, None]).min(axis=1)
        above = -up_ * self.height_scale  # height over the goal centre [m]
        reach = np.isfinite(loss)
        m = np.where(reach, (above - np.where(reach, loss, 0.0)) / self.height_scale, -self.BOUND)
        return np.clip(m, -self.BOUND, self.BOUND).reshape(shape)


class BodyFrame:
    """:func:`body_frame` for any observation layout, found by the entries' names (``sin_course``,
    ``cos_course`` and every ``*_north`` / ``*_east`` pair: goal, wind, thermal slots); the goal's
    distance and bearing are appended only where the layout has a goal. For the goal-reaching
    layout it computes exactly :func:`body_frame`. Picklable (it holds only indices).

    :param names: the env's ``observation_names``.
    :param glide: also append the :class:`FinalGlide` margin (a goal layout only); None: not.
    """

    def __init__(self, names: Sequence[str], glide: FinalGlide | None = None) -> None:
        names = list(names)
        where = {n: i for i, n in enumerate(names)}
        self.course = (where["sin_course"], where["cos_course"])
        self.pairs = [(i, where[n[: -len("north")] + "east"]) for i, n in enumerate(names) if n.endswith("_north")]
        self.goal = (where["goal_north"], where["goal_east"]) if "goal_north" in where else None
        self.size = len(names)
        if glide is not None and self.goal is None:
            raise ConfigError("final_glide needs a task with a goal (goal reaching or cross-country)")
        self.glide = glide
        self._glide_inputs = (
            tuple(where[n] for n in ("goal_north", "goal_east", "goal_up", "wind_north", "wind_east"))
            if glide is not None
            else ()
        )

    @property
    def n_extra(self) -> int:
        """Entries appended to the observation (goal distance and bearing, the final-glide margin)."""
        return (3 if self.goal is not None else 0) + (1 if self.glide is not None else 0)

    def __call__(self, obs: Any) -> np.ndarray:
        o = np.asarray(obs, dtype=np.float32)
        x = o.reshape(-1, o.shape[-1]).astype(np.float64)
        s, c = x[:, self.course[0]], x[:, self.course[1]]
        out = x.copy()
        for i, k in self.pairs:
            out[:, i] = x[:, i] * c + x[:, k] * s
            out[:, k] = -x[:, i] * s + x[:, k] * c
        parts = [out]
        if self.goal is not None:
            gi, gk = self.goal
            dist = np.hypot(x[:, gi], x[:, gk])
            safe = np.where(dist > 1e-9, dist, 1.0)
            parts.append(
                np.stack(
                    [
                        dist,
                        np.where(dist > 1e-9, out[:, gk] / safe, 0.0),
                        np.where(dist > 1e-9, out[:, gi] / safe, 1.0),
                    ],
                    axis=1,
                )
            )
        if self.glide is not None:
            parts.append(self.glide.margin(*(x[:, i] for i in self._glide_inputs))[:, None])
        res = np.concatenate(parts, axis=1).astype(np.float32)
        return res.reshape(*o.shape[:-1], res.shape[-1])

    def mirror_signs(self, names: Sequence[str]) -> np.ndarray:
        """Signs that turn a transformed observation into that of the mirror-image world (east ->
        -east, course chi -> -chi): the ``right`` half of every rotated pair, ``sin_course`` and the
        goal bearing's sine flip, the rest stays. The model is mirror-symmetric (axisymmetric
        thermals, no Coriolis), so a plan with every turn reversed is as good in the mirrored world.

        :param names: the env's ``observation_names`` (those this transform was built from).
        :raises ConfigError: an entry whose mirror image is not known (e.g. the sensed tiers).
        """
        names = list(names)
        out = np.ones(self.size + self.n_extra, np.float32)  # the glide margin is mirror-invariant
        flips = {k for _, k in self.pairs} | {self.course[0]}
        for i, n in enumerate(names):
            if i in flips:
                out[i] = -1.0
            elif not (n in _MIRROR_INVARIANT or n.endswith(("_north", "_up", "_present", "_peak", "_radius"))):
                raise ConfigError(f"observation entry {n!r} has no known mirror image (sensed tiers)")
        if self.goal is not None:
            out[self.size + 1] = -1.0  # sin(bearing - chi)
        return out

    def space(self, space: gym.spaces.Box) -> gym.spaces.Box:
        """The observation space after the transform: rotated pairs widen by sqrt(2)."""
        low = space.low.astype(np.float64).copy()
        high = space.high.astype(np.float64).copy()
        for i, k in self.pairs:
            for j in (i, k):
                m = max(abs(low[j]), abs(high[j]))
                low[j], high[j] = -m * math.sqrt(2.0), m * math.sqrt(2.0)
        if self.goal is not None:
            r = float(np.hypot(space.high[self.goal[0]], space.high[self.goal[1]]))  # |(n, e)| at most
            low = np.concatenate([low, [0.0, -1.0, -1.0]])
            high = np.concatenate([high, [r, 1.0, 1.0]])
        if self.glide is not None:
            low = np.concatenate([low, [-FinalGlide.BOUND]])
            high = np.concatenate([high, [FinalGlide.BOUND]])
        return gym.spaces.Box(low.astype(np.float32), high.astype(np.float32), dtype=np.float32)


def policy_frame(env: Any, final_glide: bool = False) -> BodyFrame:
    """The :class:`BodyFrame` of ``env``'s layout (a single env, wrapped or not, or a batched env's
    template), with the :class:`FinalGlide` margin where ``final_glide``."""
    u = env.unwrapped if hasattr(env, "unwrapped") else env
    return BodyFrame(u.observation_names, FinalGlide.of(u) if check_bool("final_glide", final_glide) else None)


class BodyFrameObservation(gym.ObservationWrapper):
    """Observation wrapper applying :class:`BodyFrame` of the env's layout; bounds widen accordingly.

    :param final_glide: append the :class:`FinalGlide` margin.
    """

    def __init__(self, env: gym.Env, final_glide: bool = False) -> None:
        super().__init__(env)
        space = env.observation_space
        assert isinstance(space, gym.spaces.Box)
        self.transform = policy_frame(env, final_glide)
        self.observation_space = self.transform.space(space)

    def observation(self, observation: np.ndarray) -> np.ndarray:
        return self.transform(observation)


def turn_curve(action: Any, exponent: float) -> np.ndarray:
    """Map the policy's turn channel ``u`` (index 1) to the env's as ``sign(u) |u|^exponent``.

    The continuous env spans +-1080 deg of turn per 30 s step, so an action of 0.1 already turns
    108 deg: precise steering needs tiny actions. With exponent 3, u = 0.46 turns 108 deg, and the
    full envelope (tight thermalling spirals) stays reachable at |u| = 1.
    """
    a = np.array(action, dtype=np.float32, copy=True)
    u = np.abs(a[..., 1].astype(np.float64))
    p = float(exponent)
    if p.is_integer() and 1 <= p <= 8:
        # repeated products round the same in numpy's SIMD loops and its scalar path (float32
        # powers do not), so one env and a batch of envs fly the same controls bit for bit
        m = u.copy()
        for _ in range(int(p) - 1):
            m *= u
    else:
        m = u**p
    a[..., 1] = np.sign(a[..., 1]) * m.astype(np.float32)
    return a


def inverse_turn_curve(action: Any, exponent: float) -> np.ndarray:
    """The policy action that :func:`turn_curve` maps to the env action ``action`` (turn channel
    ``sign(a) |a|^(1/exponent)``; the others unchanged): how a reference plan is flown by a policy."""
    a = np.array(action, dtype=np.float64, copy=True)
    a[..., 1] = np.sign(a[..., 1]) * np.abs(a[..., 1]) ** (1.0 / float(exponent))
    return a.astype(np.float32)


class TurnCurveAction(gym.ActionWrapper):
    """Action wrapper applying :func:`turn_curve` (see there) before the continuous env."""

    def __init__(self, env: gym.Env, exponent: float = 3.0) -> None:
        super().__init__(env)
        self.exponent = float(exponent)

    def action(self, action: Any) -> np.ndarray:
        return turn_curve(np.clip(action, -1.0, 1.0), self.exponent)


def control_grid(env: Any) -> np.ndarray:
    """The ``"grid"`` policy's actions: the control set of the task's continuous reference search
    (:func:`baselines.reference.control_set` with :func:`baselines.reference.tasks.reference_config`:
    the yardstick's for goal reaching, the cross-country search's own for cross-country), as
    ``(M, 3)`` float32 normalized actions of ``env`` (a continuous env of either task). The
    zero-thrust glide angles in it hold up to the scenario's ceiling; every random scenario of a
    task shares one ceiling, so the env's default scenario gives the table of every episode.

    :raises ConfigError: a task without a goal (the thermal climb's search has another control set).
    """
    from baselines.reference import ReferenceConfig, control_set  # lazy: the SST core's kernels
    from baselines.reference.tasks import reference_config

    cfg = reference_config(env)
    if not isinstance(cfg, ReferenceConfig):
        raise ConfigError(f"algo='grid' needs a goal task; {type(env.unwrapped).__name__} has no goal")
    return control_set(env.unwrapped.model, "continuous", cfg).astype(np.float32)


def grid_index(table: np.ndarray, action: Any) -> int:
    """The row of ``table`` (:func:`control_grid`) equal to the env ``action`` (to 1e-6): how a
    reference plan's control is flown by the grid policy.

    :raises ConfigError: no row matches (a plan of another control set)."""
    d = np.max(np.abs(table - np.asarray(action, np.float32)[None, :]), axis=1)
    k = int(np.argmin(d))
    if not d[k] <= 1e-6:
        raise ConfigError(
            f"action={np.asarray(action).tolist()!r} is not in the control grid (nearest row {k}, off by {d[k]:.3g})"
        )
    return k


class ControlGridAction(gym.ActionWrapper):
    """``Discrete(M)`` actions over a continuous env: action ``k`` flies row ``k`` of
    :func:`control_grid` (built from the env's own model)."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.table = control_grid(env)
        self.action_space = gym.spaces.Discrete(len(self.table))

    def action(self, action: Any) -> np.ndarray:
        k = np.asarray(action)
        if k.size != 1 or k.dtype.kind not in "iu" or not 0 <= int(k.item()) < len(self.table):
            raise ConfigError(
                f"action={action!r}; allowed: an integer in [0, {len(self.table) - 1}] (a control-grid row)"
            )
        return self.table[int(k.item())]


class ScenarioCycle(gym.Wrapper):
    """Resets walk through a fixed list of scenarios in order (for repeatable validation).

    :param scenarios: the scenarios, passed as ``options={"scenario": ...}`` to the base env.
    """

    def __init__(self, env: gym.Env, scenarios: Sequence[Scenario]) -> None:
        super().__init__(env)
        if not scenarios:
            raise ValueError("ScenarioCycle needs at least one scenario")
        self.scenarios = list(scenarios)
        self._k = 0

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        opts = dict(options or {})
        opts.setdefault("scenario", self.scenarios[self._k % len(self.scenarios)])
        self._k += 1
        return self.env.reset(seed=seed, options=opts)


def validation_scenarios(
    n: int, random_scenario: Mapping[str, Any] | None = None, family: str = "random"
) -> list[Scenario]:
    """The ``n`` validation scenarios ``<family>-5000 ...`` (seeds ``VALIDATION_SEED0 ...``),
    disjoint from the test seeds."""
    if n > HELDOUT_SEED0 - VALIDATION_SEED0:
        raise ValueError(f"at most {HELDOUT_SEED0 - VALIDATION_SEED0} validation scenarios")
    return [get_scenario(f"{family}-{VALIDATION_SEED0 + k}", random_scenario) for k in range(n)]


def make_train_env(
    env_id: str,
    env_kwargs: Mapping[str, Any] | None = None,
    shaping: float = 0.0,
    gamma: float = 0.99,
    body_frame: bool = True,
    turn_exponent: float = 1.0,
    grid: bool = False,
    final_glide: bool = False,
    demo_plans: Sequence[tuple[Scenario, Sequence[Any]]] = (),
    demo_starts: float = 0.0,
) -> gym.Env:
    """One training env: random scenario at every reset, optional extra goal shaping and
    body-frame observations (``grid``: :class:`ControlGridAction`; else the turn curve;
    ``final_glide``: the :class:`FinalGlide` margin appended; ``demo_starts``: that share of the
    episodes starts part-way along one of ``demo_plans``, :class:`baselines.imitation.DemoStarts`).

    Module-level (picklable) so that ``SubprocVecEnv`` workers can build it.
    """
    import soaring_env  # noqa: F401  (registers the env ids in this process)

    env = gym.make(_module_qualified(env_id), scenario="random", **dict(env_kwargs or {}))
    if demo_starts:
        from baselines.imitation import DemoStarts

        env = DemoStarts(env, demo_plans, demo_starts)
    if shaping:
        env = GoalDistanceShaping(env, weight=shaping, gamma=gamma)
    return _wrap_policy_io(env, body_frame, turn_exponent, grid, final_glide)


def _wrap_policy_io(
    env: gym.Env, body_frame: bool, turn_exponent: float, grid: bool, final_glide: bool = False
) -> gym.Env:
    if final_glide and not body_frame:
        raise ValueError("final_glide needs body_frame=True (the margin is appended to the aircraft-frame observation)")
    if body_frame:
        env = BodyFrameObservation(env, final_glide)
    if grid:
        env = ControlGridAction(env)
    elif turn_exponent != 1.0 and isinstance(env.action_space, gym.spaces.Box):
        env = TurnCurveAction(env, turn_exponent)
    return env


def make_native_train_env(
    env_id: str,
    n_envs: int,
    env_kwargs: Mapping[str, Any] | None = None,
    body_frame: bool = True,
    turn_exponent: float = 1.0,
    grid: bool = False,
    final_glide: bool = False,
) -> Any:
    """``n_envs`` training envs as one natively batched SB3 ``VecEnv`` (random scenario at every
    reset), with SB3's ``VecMonitor`` episode statistics and the same body-frame observations and
    turn curve or control grid as :func:`make_train_env` -- the same transitions as SB3's
    ``DummyVecEnv`` over it."""
    from stable_baselines3.common.vec_env import VecEnvWrapper, VecMonitor

    from soaring_env.env.sb3 import SoaringSB3VecEnv

    venv: Any = SoaringSB3VecEnv(n_envs, env_id=env_id, scenario="random", **dict(env_kwargs or {}))
    if final_glide and not body_frame:
        raise ValueError("final_glide needs body_frame=True (the margin is appended to the aircraft-frame observation)")
    obs_fn = policy_frame(venv.venv.template, final_glide) if body_frame else None
    act_fn: Callable[[np.ndarray], np.ndarray] | None = None
    act_space = None
    if grid:
        table = control_grid(venv.venv.template)
        act_space = gym.spaces.Discrete(len(table))

        def act_fn(a: np.ndarray) -> np.ndarray:
            return table[np.asarray(a, np.int64).reshape(-1)]

    elif turn_exponent != 1.0 and isinstance(venv.action_space, gym.spaces.Box):
        p = float(turn_exponent)

        def act_fn(a: np.ndarray) -> np.ndarray:
            return turn_curve(np.clip(a, -1.0, 1.0), p)

    class PolicyIO(VecEnvWrapper):  # type: ignore[misc]
        """Batched :class:`BodyFrameObservation` / :class:`TurnCurveAction` / :class:`ControlGridAction`."""

        def __init__(self, inner: Any) -> None:
            space = inner.observation_space
            super().__init__(
                inner, observation_space=space if obs_fn is None else obs_fn.space(space), action_space=act_space
            )

        def reset(self) -> np.ndarray:
            obs: Any = self.venv.reset()
            return obs if obs_fn is None else obs_fn(obs)

        def step_async(self, actions: np.ndarray) -> None:
            self.venv.step_async(actions if act_fn is None else act_fn(actions))

        def step_wait(self) -> Any:
            obs, reward, done, infos = self.venv.step_wait()
            if obs_fn is not None:
                obs = obs_fn(obs)
                for info in infos:
                    if "terminal_observation" in info:
                        info["terminal_observation"] = obs_fn(info["terminal_observation"])
            return obs, reward, done, infos

    return VecMonitor(PolicyIO(venv), info_keywords=("is_success",))


def make_eval_env(
    env_id: str,
    scenarios: Sequence[Scenario],
    env_kwargs: Mapping[str, Any] | None = None,
    body_frame: bool = True,
    turn_exponent: float = 1.0,
    grid: bool = False,
    final_glide: bool = False,
) -> gym.Env:
    """One validation env cycling through ``scenarios`` (env reward only, no extra shaping)."""
    import soaring_env  # noqa: F401

    env: gym.Env = ScenarioCycle(gym.make(_module_qualified(env_id), **dict(env_kwargs or {})), scenarios)
    return _wrap_policy_io(env, body_frame, turn_exponent, grid, final_glide)


def observation_transform(run_record: Mapping[str, Any]) -> Callable[[Any], Any] | None:
    """The observation transform a saved run was trained with (``config.json``), or None.

    :class:`~baselines.agents.PPOAgent` applies it to the raw env observations, so a trained
    policy runs in the plain registered env.
    """
    cfg = run_record.get("config", run_record)
    if not cfg.get("body_frame", False):
        return None
    if cfg.get("final_glide", False):
        import soaring_env  # noqa: F401  (registers the ids)

        env_kwargs = {k: v for k, v in dict(cfg.get("env_kwargs", {})).items() if k != "scenario"}
        return policy_frame(gym.make(_module_qualified(run_record.get("env_id", CONTINUOUS_ID)), **env_kwargs), True)
    names = run_record.get("observation_names")
    return body_frame if names is None else BodyFrame(names)  # runs saved before the tasks: goal layout


def action_transform(run_record: Mapping[str, Any]) -> Callable[[Any], Any] | None:
    """The action transform a saved continuous or grid run was trained with (``config.json``), or None."""
    cfg = run_record.get("config", run_record)
    if cfg.get("algo") == "grid":
        import soaring_env  # noqa: F401  (registers the ids)

        env_kwargs = {k: v for k, v in dict(cfg.get("env_kwargs", {})).items() if k != "scenario"}
        env = gym.make(_module_qualified(run_record.get("env_id", CONTINUOUS_ID)), **env_kwargs)
        table = control_grid(env)
        return lambda a: table[int(np.asarray(a).item())]
    p = float(cfg.get("turn_exponent", 1.0))
    if cfg.get("algo") != "continuous" or p == 1.0:
        return None
    return lambda a: turn_curve(np.clip(a, -1.0, 1.0), p)


def random_scenario_kwargs(env_kwargs: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The ``make_scenario`` keywords the env uses in random mode (so validation matches training)."""
    return dict((env_kwargs or {}).get("random_scenario", {}))


# --- models ----------------------------------------------------------------------------------------
def _algo_class(algo: str) -> Any:
    if algo == "masked":
        from sb3_contrib import MaskablePPO

        return MaskablePPO
    from stable_baselines3 import PPO

    return PPO


def load_model(path: str | Path, algo: str) -> Any:
    """Load a saved model of algorithm ``algo`` on the CPU."""
    if algo not in ALGOS:
        raise ValueError(f"algo={algo!r} is unknown; known: {', '.join(ALGOS)}")
    import torch

    torch.set_num_threads(1)
    return _algo_class(algo).load(str(path), device="cpu")


def _linear_schedule(start: float, final_fraction: float) -> Callable[[float], float]:
    def schedule(progress_remaining: float) -> float:
        return start * (final_fraction + (1.0 - final_fraction) * progress_remaining)

    return schedule


def _versions() -> dict[str, str]:
    import importlib.metadata as md

    out = {"python": sys.version.split()[0], "platform": platform.platform()}
    for pkg in ("soaring-env", "numpy", "gymnasium", "stable-baselines3", "sb3-contrib", "torch"):
        try:
            out[pkg] = md.version(pkg)
        except md.PackageNotFoundError:
            out[pkg] = "not installed"
    return out


def _eval_callback(config: TrainConfig, eval_env: Any, out_dir: Path, t_start: float, n_eval_envs: int) -> Any:
    """EvalCallback (MaskableEvalCallback for ``masked``) that also logs success, energy and time."""
    from sb3_contrib.common.maskable.callbacks import MaskableEvalCallback
    from stable_baselines3.common.callbacks import EvalCallback

    base: Any = MaskableEvalCallback if config.algo == "masked" else EvalCallback

    class LoggedEval(base):  # type: ignore[misc, valid-type]
        """Adds energy of successful episodes and wall-clock time to every evaluation."""

        def __init__(self, *args: Any, **kwargs: Any) -> None:
            super().__init__(*args, **kwargs)
            self.records: list[dict[str, Any]] = []
            self._energy: list[float] = []

        def _log_success_callback(self, locals_: dict[str, Any], globals_: dict[str, Any]) -> None:
            super()._log_success_callback(locals_, globals_)
            if locals_["done"]:
                info = locals_["info"]
                # goal tasks: the energy of successful episodes; the climb (no goal): of every episode
                if (info.get("is_success") or config.task == "climb") and "energy_spent" in info:
                    self._energy.append(float(info["energy_spent"]))

        def _on_step(self) -> bool:
            n_before = len(self.evaluations_timesteps)
            self._energy = []
            cont = super()._on_step()
            if len(self.evaluations_timesteps) > n_before:
                succ = self.evaluations_successes[-1] if self.evaluations_successes else []
                rec: dict[str, Any] = {
                    "timesteps": int(self.num_timesteps),
                    "wall_s": round(time.perf_counter() - t_start, 2),
                    "mean_return": float(np.mean(self.evaluations_results[-1])),
                    "std_return": float(np.std(self.evaluations_results[-1])),
                    "success_rate": float(np.mean(succ)) if len(succ) else float("nan"),
                    "mean_energy_success": float(np.mean(self._energy)) if self._energy else None,
                    "mean_length": float(np.mean(self.evaluations_length[-1])),
                }
                self.records.append(rec)
                self.logger.record("eval/success_rate_validation", rec["success_rate"])
                if config.verbose >= 0:
                    e = rec["mean_energy_success"]
                    what = "energy"
                    if config.task == "climb" and e is not None:
                        e, what = -e, "energy gained"
                    print(
                        f"[{config.algo}] {rec['timesteps']:>9d} steps {rec['wall_s'] / 60:5.1f} min: "
                        f"validation success {100 * rec['success_rate']:5.1f} %, return {rec['mean_return']:6.2f}, "
                        f"{what} {'-' if e is None else f'{e / 1000:.2f} kJ/kg'}",
                        flush=True,
                    )
                atomic_write_text(out_dir / "eval_log.json", json.dumps(self.records, indent=1))
            return cont

    return LoggedEval(
        eval_env,
        n_eval_episodes=config.n_eval_scenarios,
        eval_freq=max(1, config.eval_freq // config.n_envs),
        log_path=str(out_dir),
        best_model_save_path=str(out_dir),
        deterministic=True,
        verbose=0,
        warn=False,
    )


def _rehearsal_callback(demos: Any, minibatches: int, batch_size: int, seed: int) -> Any:
    """After every PPO update (at the next rollout's start), ``minibatches`` minibatches of
    ``demos`` fitted with the policy's own optimizer (:func:`baselines.imitation.pretrain`)."""
    from stable_baselines3.common.callbacks import BaseCallback

    from baselines.imitation import pretrain, rows

    class Rehearsal(BaseCallback):
        def __init__(self) -> None:
            super().__init__()
            self.gen = np.random.default_rng(seed)
            self.updates = 0

        def _on_rollout_start(self) -> None:
            if self.model.num_timesteps == 0:  # nothing learnt from the env yet
                return
            pick = self.gen.choice(len(demos), size=min(len(demos), minibatches * batch_size), replace=False)
            pol = self.model.policy
            pretrain(pol, rows(demos, pick), epochs=1, batch_size=batch_size, value_weight=0.0, optimizer=pol.optimizer)
            self.updates += 1

        def _on_step(self) -> bool:
            return True

    return Rehearsal()


#: Parameter-name prefixes of the value function in SB3's actor-critic policies (the rest is the policy's).
CRITIC_PREFIXES = ("mlp_extractor.value_net.", "value_net.")


def _critic_warmup_callback(steps: int) -> Any:
    """Freeze every parameter of the policy but the value function's for the PPO updates on the
    first ``steps`` env steps (``TrainConfig.critic_warmup``): those updates move the critic alone."""
    from stable_baselines3.common.callbacks import BaseCallback

    class CriticWarmup(BaseCallback):
        def __init__(self) -> None:
            super().__init__()
            self.frozen: list[Any] = []

        def _on_training_start(self) -> None:
            named = self.model.policy.named_parameters()
            self.frozen = [p for n, p in named if p.requires_grad and not n.startswith(CRITIC_PREFIXES)]
            for p in self.frozen:
                p.requires_grad_(False)

        def _on_step(self) -> bool:
            if self.frozen and self.model.num_timesteps > steps:  # a rollout past the warm-up
                for p in self.frozen:
                    p.requires_grad_(True)
                self.frozen = []
            return True

    return CriticWarmup()


def _wall_clock_callback(max_minutes: float, t_start: float) -> Any:
    from stable_baselines3.common.callbacks import BaseCallback

    class StopOnWallClock(BaseCallback):
        """Stops training once ``max_minutes`` of wall-clock time have passed."""

        def _on_step(self) -> bool:
            return time.perf_counter() - t_start < 60.0 * max_minutes

    return StopOnWallClock()


class _StopSignals:
    """Between :meth:`install` and :meth:`restore`, SIGTERM and SIGINT ask training to stop at the
    next step instead of killing it: the run then ends as a wall-clock cap ends it, with
    ``model.zip`` and ``config.json`` written. A second signal acts as usual (the handlers are
    restored at the first). Main thread only (elsewhere nothing is installed)."""

    SIGNALS = ("SIGTERM", "SIGINT")

    def __init__(self) -> None:
        self.received: str | None = None
        self._old: dict[int, Any] = {}

    def _handle(self, signum: int, _frame: Any) -> None:
        self.received = signal.Signals(signum).name
        self.restore()

    def install(self) -> _StopSignals:
        if threading.current_thread() is threading.main_thread():
            for name in self.SIGNALS:
                num = getattr(signal, name)
                self._old[num] = signal.signal(num, self._handle)
        return self

    def restore(self) -> None:
        for num, old in self._old.items():
            signal.signal(num, old)
        self._old = {}

    def callback(self) -> Any:
        from stable_baselines3.common.callbacks import BaseCallback

        stop = self

        class StopOnSignal(BaseCallback):
            def _on_step(self) -> bool:
                return stop.received is None

        return StopOnSignal()


def _probe(config: TrainConfig) -> Any:
    """A raw env of ``config`` (for its observation layout)."""
    return gym.make(_module_qualified(config.env_id), **dict(config.env_kwargs)).unwrapped


def _init_policy_from(model: Any, init_from: str, log_std_init: float) -> None:
    """Load ``init_from``'s weights into ``model``, then re-initialise the value function (SB3's
    orthogonal initialisation and gains), the Gaussian policy's log std and the optimizer."""
    import torch
    from stable_baselines3.common.save_util import load_from_zip_file

    pol = model.policy
    try:
        _, params, _ = load_from_zip_file(str(_init_model_path(init_from)), device="cpu")
        saved = dict((params or {})["policy"])
        # a layer this run adds beside the saved ones (``scorer_skip``) starts at zero: the saved policy
        # exactly (SB3's orthogonal initialisation has already drawn it)
        saved.update({k: torch.zeros_like(v) for k, v in pol.state_dict().items() if k not in saved and ".skip." in k})
        pol.load_state_dict(saved, strict=True)
    except (RuntimeError, ValueError, KeyError) as e:  # torch's size mismatch: other spaces or layers
        raise ConfigError(f"init_from={init_from!r} does not fit this run's spaces and layers: {e}") from e
    _fresh_critic(model, log_std_init)


def _ensemble_policy_from(model: Any, runs: Sequence[str]) -> None:
    """Load the successor scorers of ``runs`` (``ensemble_of``) into the members of ``model``'s
    scorer, the first run's into its first member, then re-initialise the value function (whose
    widths need not match the runs') and the optimizer as :func:`_init_policy_from` does.

    :raises ConfigError: a run that is not a single successor scorer with exactly this run's scorer
        settings (features, widths, skip layer), naming it (``ensemble_of[k]``) and what differs.
    """
    from stable_baselines3.common.save_util import load_from_zip_file

    pol = model.policy
    mine = {k: v for k, v in dict(getattr(pol, "scorer", {})).items() if k != "members"}
    state: dict[str, Any] = {}
    prefix = "mlp_extractor.policy_net."
    for k, run in enumerate(runs):
        data, params, _ = load_from_zip_file(str(_init_model_path(run, f"ensemble_of[{k}]")), device="cpu")
        theirs = dict(((data or {}).get("policy_kwargs") or {}).get("scorer") or {})
        members = int(theirs.pop("members", 1))
        if members != 1 or json.dumps(theirs, sort_keys=True) != json.dumps(mine, sort_keys=True):
            differ = sorted(n for n in set(theirs) | set(mine) if theirs.get(n) != mine.get(n))
            raise ConfigError(
                f"ensemble_of[{k}]={run!r} is not a single successor scorer with this run's settings "
                f"(members={members}; differs in: {', '.join(differ) or 'nothing'}); give each member's "
                "policy, scorer_hidden, scorer_estimate, scorer_lift and scorer_skip"
            )
        saved = dict((params or {})["policy"])
        for name, value in saved.items():
            for part, into in (
                ("head.", "head." if k == 0 else f"more.{k - 1}."),
                ("skip.", "skip." if k == 0 else f"more_skip.{k - 1}."),
            ):
                if name.startswith(prefix + part):
                    state[prefix + into + name[len(prefix + part) :]] = value
    # the scorers alone: the critic starts fresh below, so its widths (net_arch) need not match the members'
    mine_keys = {n for n in pol.state_dict() if n.startswith(prefix)}
    if set(state) != mine_keys:
        raise ConfigError(
            f"ensemble_of={list(runs)!r} does not fit this run's scorer layers: {sorted(set(state) ^ mine_keys)[:4]}"
        )
    try:
        pol.load_state_dict(state, strict=False)
    except (RuntimeError, KeyError) as e:  # torch's size mismatch: other spaces or layers
        raise ConfigError(f"ensemble_of={list(runs)!r} does not fit this run's spaces and layers: {e}") from e
    _fresh_critic(model, 0.0)


def _fresh_critic(model: Any, log_std_init: float) -> None:
    """Re-initialise ``model``'s value function (SB3's orthogonal initialisation and gains, seeded by
    the run's seed), the Gaussian policy's log std and the optimizer: after loading earlier weights."""
    import torch

    pol = model.policy
    torch.manual_seed(model.seed if model.seed is not None else 0)  # the fresh critic is seeded too
    pol.mlp_extractor.value_net.apply(lambda m: pol.init_weights(m, gain=math.sqrt(2.0)))
    pol.init_weights(pol.value_net, gain=1.0)
    if hasattr(pol, "log_std"):
        with torch.no_grad():
            pol.log_std.fill_(log_std_init)
    pol.optimizer = pol.optimizer_class(pol.parameters(), lr=model.lr_schedule(1.0), **pol.optimizer_kwargs)


def _clone_demos(model: Any, config: TrainConfig, out: Path) -> tuple[dict[str, Any], Any]:
    """Behaviour cloning of ``config.demos`` into ``model`` (see :mod:`baselines.imitation`);
    saves ``bc_model.zip`` and returns what was fitted (for ``config.json``) and the demonstrations."""
    import torch

    from baselines.imitation import demonstrations, pretrain, with_mirror_images

    t0 = time.perf_counter()
    p = config.turn_exponent
    grid = config.algo == "grid"
    probe = _probe(config)
    flip = np.array([1.0, -1.0, 1.0], np.float32)  # the mirror image of a control: the turn reversed
    to_policy_action: Callable[[Any], Any] | None = None
    mirror_action: Callable[[np.ndarray], np.ndarray] = lambda a: a * flip  # noqa: E731
    if grid:
        table = control_grid(probe)
        to_policy_action = lambda a: grid_index(table, a)  # noqa: E731
        mirror_row = np.array([grid_index(table, r * flip) for r in table])
        mirror_action = lambda a: mirror_row[a]  # noqa: E731
    elif config.algo == "continuous" and p != 1.0:
        to_policy_action = lambda a: inverse_turn_curve(a, p)  # noqa: E731  (odd in the turn: mirrors as is)
    elif config.algo not in CONTINUOUS_ALGOS:
        mirror_prim = probe.library.mirror_indices()
        mirror_action = lambda a: mirror_prim[a]  # noqa: E731
    plans = demonstrations(
        str(config.demos),
        lambda sc: make_eval_env(
            config.env_id, [sc], config.env_kwargs, bool(config.body_frame), p, grid, config.final_glide
        ),
        sampler="continuous" if config.algo in CONTINUOUS_ALGOS else "primitive",
        gamma=config.gamma,
        to_policy_action=to_policy_action,
        match=config.demo_match,
        visit_weight=float(config.demo_visit_weight),
        start_weight=float(config.demo_start_weight),
        soft_temperature=float(config.demo_soft_temperature),
    )
    mirrored = bool(config.demo_mirror)
    demos = plans
    if mirrored:
        if not config.body_frame:
            raise ValueError("demo_mirror needs body_frame=True (the mirror image is taken in the aircraft's frame)")
        signs = policy_frame(probe, config.final_glide).mirror_signs(probe.observation_names)
        demos = with_mirror_images(plans, signs, mirror_action)
    if config.demo_equivalents:
        from baselines.scoring import accepted_successors

        scorer = model.policy.mlp_extractor.policy_net
        acc = accepted_successors(scorer.features, demos.observations, demos.actions, bool(config.progress_bar))
        demos = dataclasses.replace(demos, accepted=acc)
    torch.manual_seed(config.seed)
    losses: list[dict[str, float]] = []
    if config.demo_epochs:
        losses = pretrain(
            model.policy,
            demos,
            epochs=config.demo_epochs,
            learning_rate=config.demo_learning_rate,
            final_fraction=float(config.demo_lr_final_fraction),
            batch_size=int(config.demo_batch_size),
            q_weight=float(config.demo_q_weight),
            seed=config.seed,
            progress=bool(config.progress_bar),
        )
    model.save(str(out / "bc_model.zip"))
    pol = model.policy
    if hasattr(pol, "log_std"):
        with torch.no_grad():
            pol.log_std.fill_(config.log_std_init)
    pol.optimizer = pol.optimizer_class(pol.parameters(), lr=model.lr_schedule(1.0), **pol.optimizer_kwargs)
    print(
        f"[{config.algo}] behaviour cloning: {len(demos)} steps of {len(plans.scenarios)} reference plans"
        f"{' and their mirror images' if mirrored else ''}, "
        f"{config.demo_epochs} epochs in {time.perf_counter() - t0:.0f} s"
        + (f"; loss {losses[0]['nll']:.3f} -> {losses[-1]['nll']:.3f}" if losses else " (kept for rehearsal)")
        + (
            f"; cost fit {losses[0]['q_mse']:.4f} -> {losses[-1]['q_mse']:.4f} (kJ/kg)^2"
            if losses and "q_mse" in losses[0]
            else ""
        ),
        flush=True,
    )
    return {
        "steps": len(demos),
        "plans": len(plans.scenarios),
        "mirrored": mirrored,
        "mean_plan_cost": float(np.mean(plans.plan_costs)),
        "scenarios": list(plans.scenarios),
        "first_epoch": losses[0] if losses else None,
        "last_epoch": losses[-1] if losses else None,
        "seconds": round(time.perf_counter() - t0, 1),
    }, demos


def _demo_start_plans(config: TrainConfig) -> list[tuple[Scenario, tuple[Any, ...]]]:
    """The plans :class:`baselines.imitation.DemoStarts` starts on (none without ``demo_starts``)."""
    if not config.demo_starts:
        return []
    from baselines.imitation import demo_plans

    sampler = "continuous" if config.algo in CONTINUOUS_ALGOS else "primitive"
    return demo_plans(str(config.demos), sampler=sampler, match=config.demo_match)


def _init_model_path(init_from: str, field: str = "init_from") -> Path:
    """The ``.zip`` of ``init_from`` (a run directory's ``model.zip``, or the file itself); ``field``
    names the setting in the error."""
    p = Path(init_from)
    z = p / "model.zip" if p.is_dir() else p
    if not z.is_file():
        raise ConfigError(f"{field}={init_from!r}: no model at {z}")
    return z


def train(config: TrainConfig, out_dir: str | Path) -> Path:
    """Train ``config`` and write the run directory ``out_dir`` (see the module docstring).

    :returns: ``out_dir`` as a :class:`~pathlib.Path`.
    """
    import torch
    from stable_baselines3.common.callbacks import CallbackList, CheckpointCallback
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.monitor import Monitor
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    torch.set_num_threads(config.torch_threads)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    record: dict[str, Any] = {
        "config": config.to_dict(),
        "env_id": config.env_id,
        "algo": config.algo,
        "status": "running",
        # the layout the policy was trained on (its body-frame transform is built from it)
        "observation_names": list(_probe(config).observation_names),
        "versions": _versions(),
        "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
    }
    signals = _StopSignals().install()  # from here a SIGTERM or SIGINT ends the run gracefully
    atomic_write_text(out / "config.json", json.dumps(record, indent=2))
    grid = config.algo == "grid"
    try:
        train_env: Any
        if config.vec_env == "native":
            train_env = make_native_train_env(
                config.env_id,
                config.n_envs,
                config.env_kwargs,
                bool(config.body_frame),
                config.turn_exponent,
                grid,
                config.final_glide,
            )
            train_env.seed(config.seed)  # as make_vec_env seeds: env i resets with seed + i
        else:
            train_env = make_vec_env(
                make_train_env,
                n_envs=config.n_envs,
                seed=config.seed,
                vec_env_cls=SubprocVecEnv if config.vec_env == "subproc" else DummyVecEnv,
                env_kwargs={
                    "env_id": config.env_id,
                    "env_kwargs": config.env_kwargs,
                    "shaping": config.shaping,
                    "gamma": config.gamma,
                    "body_frame": bool(config.body_frame),
                    "turn_exponent": config.turn_exponent,
                    "grid": grid,
                    "final_glide": config.final_glide,
                    "demo_plans": _demo_start_plans(config),
                    "demo_starts": config.demo_starts,
                },
            )
        scenarios = validation_scenarios(
            config.n_eval_scenarios, random_scenario_kwargs(config.env_kwargs), config.family
        )
        eval_env = DummyVecEnv(
            [
                lambda: Monitor(
                    make_eval_env(
                        config.env_id,
                        scenarios,
                        config.env_kwargs,
                        bool(config.body_frame),
                        config.turn_exponent,
                        grid,
                        config.final_glide,
                    )
                )
            ]
        )

        algo_cls = _algo_class(config.algo)
        policy_kwargs: dict[str, Any] = {"net_arch": {"pi": list(config.net_arch), "vf": list(config.net_arch)}}
        policy_cls: Any = "MlpPolicy"
        if config.algo == "continuous":
            policy_kwargs["log_std_init"] = config.log_std_init
        if config.policy != "mlp":
            from baselines.scoring import PrimitiveScoringPolicy, SuccessorPolicy, scorer_kwargs, successor_kwargs

            policy_cls, make_scorer = {
                "scoring": (PrimitiveScoringPolicy, scorer_kwargs),
                "successor": (SuccessorPolicy, successor_kwargs),
            }[config.policy]
            policy_kwargs = {
                "net_arch": {"pi": [], "vf": list(config.net_arch)},
                "scorer": {**make_scorer(_probe(config)), "hidden": list(config.scorer_hidden)},
            }
            if config.scorer_estimate:
                policy_kwargs["scorer"]["estimate"] = True
            if config.scorer_lift:
                policy_kwargs["scorer"]["lift"] = True
            if config.scorer_skip:
                policy_kwargs["scorer"]["skip"] = True
            if config.ensemble_of:
                policy_kwargs["scorer"]["members"] = len(config.ensemble_of)
        model = algo_cls(
            policy_cls,
            train_env,
            learning_rate=_linear_schedule(config.learning_rate, config.lr_final_fraction),
            n_steps=config.n_steps,
            batch_size=config.batch_size,
            n_epochs=config.n_epochs,
            gamma=config.gamma,
            gae_lambda=config.gae_lambda,
            clip_range=config.clip_range,
            ent_coef=config.ent_coef,
            vf_coef=config.vf_coef,
            max_grad_norm=config.max_grad_norm,
            policy_kwargs=policy_kwargs,
            tensorboard_log=str(out / "tb") if config.tensorboard else None,
            seed=config.seed,
            device="cpu",
            verbose=max(config.verbose, 0),
        )
        if config.init_from is not None:
            _init_policy_from(model, config.init_from, config.log_std_init)
        if config.ensemble_of:
            _ensemble_policy_from(model, config.ensemble_of)
        if config.demos is not None:
            record["behaviour_cloning"], demos = _clone_demos(model, config, out)
            atomic_write_text(out / "config.json", json.dumps(record, indent=2))
        t_start = time.perf_counter()
        # the native training env and the validation env are different VecEnv classes, by design
        warnings.filterwarnings("ignore", message="Training and eval env are not of the same type")
        eval_cb = _eval_callback(config, eval_env, out, t_start, 1)
        callbacks: list[Any] = [eval_cb]
        if config.checkpoint_freq:
            callbacks.append(
                CheckpointCallback(
                    save_freq=max(1, config.checkpoint_freq // config.n_envs),
                    save_path=str(out / "checkpoints"),
                    name_prefix=config.algo,
                )
            )
        if config.max_minutes is not None:
            callbacks.append(_wall_clock_callback(config.max_minutes, t_start))
        if config.demo_rehearsal:
            callbacks.append(_rehearsal_callback(demos, config.demo_rehearsal, config.batch_size, config.seed))
        if config.critic_warmup:
            callbacks.append(_critic_warmup_callback(config.critic_warmup))
        progress = config.progress_bar
        if progress:
            try:
                import rich  # noqa: F401
                import tqdm  # noqa: F401
            except ImportError:
                print("tqdm/rich are not installed: training without a progress bar", file=sys.stderr)
                progress = False
        callbacks.append(signals.callback())
        try:
            if config.total_timesteps > 0:  # 0: behaviour cloning alone (demos)
                model.learn(
                    total_timesteps=config.total_timesteps,
                    callback=CallbackList(callbacks),
                    progress_bar=progress,
                    tb_log_name=config.algo,
                )
        finally:
            signals.restore()
            train_env.close()
            eval_env.close()
    except BaseException as exc:
        signals.restore()
        # the record says the run failed and why, rather than "running" for ever
        failed = {"finished": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "error": f"{type(exc).__name__}: {exc}"}
        record.update(status="failed", **failed)
        atomic_write_text(out / "config.json", json.dumps(record, indent=2))
        raise
    if signals.received is not None:
        print(f"[train_ppo] {signals.received}: stopped early; saving the model", file=sys.stderr)
    wall = time.perf_counter() - t_start
    model.save(str(out / "model.zip"))
    record.update(
        status="done",
        finished=time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        train_wall_s=round(wall, 1),
        timesteps_done=int(model.num_timesteps),
        steps_per_s=round(model.num_timesteps / max(wall, 1e-9), 1),
        stopped_by_wall_clock=bool(
            signals.received is None and config.max_minutes is not None and model.num_timesteps < config.total_timesteps
        ),
        stopped_by_signal=signals.received,
        final_eval=eval_cb.records[-1] if eval_cb.records else None,
        best_eval=max(eval_cb.records, key=lambda r: r["mean_return"]) if eval_cb.records else None,
    )
    atomic_write_text(out / "config.json", json.dumps(record, indent=2))
    if eval_cb.records:
        title = f"{config.algo} on {config.env_id}"
        try:
            plot_learning_curve(out / "eval_log.json", out / "learning_curve.png", title=title)
        except ImportError:  # matplotlib is in the "plot" extra, not in "ppo"
            print("matplotlib is not installed: no learning_curve.png (pip install '.[plot]')", file=sys.stderr)
    return out


def plot_learning_curve(
    eval_logs: str | Path | Sequence[str | Path], png: str | Path, title: str = "", labels: Sequence[str] | None = None
) -> Path:
    """Learning curve(s) from ``eval_log.json`` file(s), on the fixed validation scenarios: success
    rate against timesteps and against wall-clock minutes, mean return, and the mean energy of the
    successful episodes [kJ/kg]. Thermal-climb runs (no goal: ``config.json`` beside the log) show
    the mean energy gained [kJ/kg] where the others show success, and the energy of every episode."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paths = [eval_logs] if isinstance(eval_logs, (str, Path)) else list(eval_logs)
    names = list(labels) if labels is not None else [Path(p).parent.name for p in paths]
    fig, axes = plt.subplots(2, 2, figsize=(11, 7.5), constrained_layout=True)
    (ax_s, ax_w), (ax_r, ax_e) = axes
    climbs = []
    for p, name in zip(paths, names, strict=True):
        recs = json.loads(Path(p).read_text())
        if not recs:
            continue
        cfg = Path(p).parent / "config.json"
        climb = cfg.is_file() and json.loads(cfg.read_text()).get("config", {}).get("task") == "climb"
        climbs.append(climb)
        ts = np.array([r["timesteps"] for r in recs])
        wall = np.array([r["wall_s"] for r in recs]) / 60.0
        energy = [np.nan if r["mean_energy_success"] is None else r["mean_energy_success"] / 1000 for r in recs]
        succ = [-e for e in energy] if climb else [100.0 * r["success_rate"] for r in recs]
        (line,) = ax_s.plot(ts, succ, marker=".", label=name)
        ax_w.plot(wall, succ, marker=".", color=line.get_color(), label=name)
        ax_r.plot(ts, [r["mean_return"] for r in recs], marker=".", color=line.get_color(), label=name)
        ax_e.plot(ts, energy, marker=".", color=line.get_color(), label=name)
    top = "validation success rate [%]"
    if climbs and all(climbs):
        top = "validation energy gained [kJ/kg]"
    elif any(climbs):
        top = "validation success [%] / energy gained (climb) [kJ/kg]"
    ax_s.set_ylabel(top)
    ax_w.set_ylabel(top)
    ax_w.set_xlabel("wall-clock training time [min]")
    ax_r.set_ylabel("validation mean return")
    ax_e.set_ylabel("energy spent [kJ/kg]: successful episodes (climb: all)")
    for ax in (ax_s, ax_r, ax_e):
        ax.set_xlabel("timesteps")
    if not any(climbs):
        for ax in (ax_s, ax_w):
            ax.set_ylim(-2, 102)
    if not any(line.get_ydata().size and np.isfinite(np.asarray(line.get_ydata(), float)).any() for line in ax_e.lines):
        ax_e.text(0.5, 0.5, "no successful validation episode", transform=ax_e.transAxes, ha="center", fontsize=10)
    for ax in axes.ravel():
        ax.grid(alpha=0.3)
        ax.legend(loc="best", fontsize=8)
    if title:
        fig.suptitle(title)
    out = Path(png)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
