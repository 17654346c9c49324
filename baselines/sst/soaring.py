"""The soaring adapter: plugs the flight model (:class:`soaring_env.model.SoaringModel`) into the
generic SST core as a :class:`~baselines.sst.core.Problem`.

State vector seen by the core (6 floats): ``[Pn, Pe, chi, h, t, v_prev]`` -- the model's state
``[Pn [m], Pe [m], chi [rad], h [m]]``, the time [s] (it matters for drifting thermals) and the
airspeed of the edge that led here [m/s] (NaN at the start: the first edge pays no kinetic term,
as in the env); with a battery (the cross-country task's motor energy budget) a 7th, the battery
left [J/kg]. Only ``Pn, Pe, h, chi`` enter the distance:

    d^2 = dPn^2 + dPe^2 + (height_scale dh)^2 + (heading_scale wrap(dchi))^2      [m^2]

with ``wrap`` taking the course difference into [-pi, pi] and ``heading_scale`` in m/rad (default
100 m/rad: a half-turn counts as 314 m, about one 10 m/s primitive). Selection targets are drawn
uniformly over the flight domain (north, east, height) and all courses (a ``thermal_targets`` share
of them over the thermals, off by default).

Controls: ``"primitive"`` -- an index into the 174 primitives (by default only among those within
the model's bank and stall limits, ``model.allowed_primitives()``); ``"continuous"`` -- a normalized action in [-1, 1]^3
mapped by ``model.action_to_control`` onto the envelope of the primitives ((v_a, chi_dot, gamma) in
[10, 20] m/s x +-1080 deg/Ts x +-45 deg), held for Ts. Both are exactly the actions of the discrete
and continuous envs. The paper's planner (``SST_CONFIGS["paper"]``) draws them uniformly; the
soaring configuration mixes in zero-thrust glides, adds the admissible cost bound and the greedy
goal completions (glide to a thermal, climb, glide home) -- see :class:`SoaringSSTConfig` and
:meth:`SoaringProblem.goal_controls`; the default (``SST_CONFIGS["seeded"]``) seeds it with
reference beam searches as well (:class:`baselines.sst.planner.SeededSST`).

An edge is propagated with the same calls ``env.step`` makes (``model.rollout_primitive`` or
``model.rollout_control`` with ``t0`` and ``airspeed_prev``, then ``model.classify``): its cost is
the full edge cost, its end state the first goal point for goal edges; crash and out-of-bounds
edges are invalid, and so is, with a battery, an edge that leaves none (the env's
``"battery_empty"``: the battery is charged fuel + kinetic per edge, exactly as the env charges it;
a goal edge counts as reached even if it overdraws, as in the env).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from baselines.sst.core import EDGE_GOAL, EDGE_INVALID, EDGE_VALID, Edges, SSTError, StateSpace
from baselines.sst.samplers import BoxSampler, IndexSampler
from soaring_env._validation import (
    ConfigError,
    as_float_array,
    check_bool,
    check_finite,
    check_int,
    check_positive,
    check_range,
)
from soaring_env.model import FLYING, GOAL, SoaringModel
from soaring_env.physics.atmosphere import G
from soaring_env.physics.thermals import COL_BIRTH, COL_DEATH
from soaring_env.primitives import COL_AIRSPEED, COL_CHI_DOT_1, COL_CHI_DOT_2, COL_GAMMA, control_rows

SAMPLERS = ("primitive", "continuous")
#: Columns of the core's state vector.
S_N, S_E, S_CHI, S_H, S_T, S_V, S_B = range(7)


@dataclass(frozen=True)
class SoaringSSTConfig:
    """Planner settings for the soaring problem.

    The defaults are the planner that soars best (``SST_CONFIGS["seeded"]``: the soaring measures and
    the seeding reference search); ``SST_CONFIGS["soaring"]`` is the same without the seeding
    search (``seed_width=0``), ``SST_CONFIGS["paper"]`` the paper's planner (uniform control
    samplers, no bound, no seed), kept unchanged for ``scripts/reproduce_paper.py``. Each setting
    earns its place in the README's ablation table (``scripts/ablation_sst.py``).

    Radii: delta_s = 250 m, a little under half a 20 m/s primitive (600 m) and about one 10 m/s
    primitive's displacement in a turn; delta_BN = 2 delta_s, the ratio of OMPL's defaults.
    K expansions per round: batching changes the search (see :mod:`baselines.sst.core`);
    ``batch_size=1`` is the published one-at-a-time algorithm.

    Control mixture (continuous sampler; the density stays positive over the whole envelope, so
    SST's probabilistic completeness and asymptotic near-optimality are kept): each drawn action is
    uniform, except that with probability ``glide_share`` its path angle is replaced by the
    zero-thrust glide angle of its (airspeed, course rate) (:meth:`Aircraft.glide_angle`, rounded so
    that no thrust is needed), and with probability ``circle_share`` its course rate is replaced by
    one of a circle of radius uniform in ``circle_radius`` (clipped to the envelope) with a random
    sign. The primitive sampler draws, with probability ``circle_share``, uniformly among the
    circling primitives (turn radius within ``circle_radius``), else uniformly among all allowed.

    :param selection_radius: delta_BN [m] (in the distance of this module's docstring).
    :param pruning_radius: delta_s [m].
    :param heading_scale: weight of the course angle in the distance [m/rad].
    :param height_scale: weight of the height in the distance [-].
    :param batch_size: expansions per round (1 = one-at-a-time SST, see ``baselines.sst.core``).
    :param mask_primitives: draw only the primitives within the model's bank and stall limits.
    :param max_edges: most edges (env steps) a plan may have, e.g. the env's ``max_episode_steps``
        (None: unlimited, as in the paper).
    :param glide_share: probability of a zero-thrust glide path angle (continuous) [-].
    :param circle_share: probability of a thermal-scale circle [-].
    :param circle_radius: (smallest, largest) circle radius of those draws [m].
    :param thermal_targets: share of SST's selection targets drawn over the thermals instead of
        uniformly over the domain: (north, east) uniform in a disc of ``thermal_target_radius``
        around a thermal's centre at the start time (picked uniformly), height and course uniform
        (the uniform share keeps every region reachable) [-].
    :param thermal_target_radius: radius of those discs [m].
    :param cost_bound: drop children that cannot beat the best solution by the admissible bound
        ``-g (h_cap - h)`` on the cost still to go (:meth:`SoaringModel.end_height_cap`).
    :param completions: greedy goal completions per round (``goal_controls``; 0: none).
    :param completion_depth: most edges of one completion.
    :param refinements: completions per round that leave the best plan's path on a random control
        (see :class:`~baselines.sst.core.SSTParams`; 0: none).
    :param seed_width: widest beam of the seeding search (0: none): after SST's first solution,
        the reference beam search (:func:`baselines.reference.search`, the same action set) runs
        with the scout width, then iterative widening from ``seed_start_width`` up to this width,
        within ``seed_share`` of the budget, and each plan is inserted into the tree
        (:meth:`~baselines.sst.core.SST.insert_path`), so that the random expansions, completions
        and refinements go on from it (``SST_CONFIGS["seeded"]``; see
        :class:`baselines.sst.planner.SeededSST`).
    :param seed_start_width: first width of the seeding search's doubling (after the scout).
    :param seed_scout_width: a narrower beam run first, for an early plan (0, or not below
        ``seed_start_width``: none). A beam's time grows with its width (a continuous beam over the
        ~460-control grid flies width x 460 edges per depth, 40 depths): an 8-wide one gives the
        tree a beam's plan within the first seconds of a 20 s budget, where the 32-wide one took
        about half of it on the held-out scenarios; doubling on from 8 instead (16, 32) costs the
        time that some scenarios need for the 32-wide beam (docs/sst.md, "The scout beam").
    :param seed_share: share of the planning budget (seconds or iterations) the seeding search may
        use [-].
    :param seed_progress_weight: the seeding search's ``progress_weight``
        (:class:`~baselines.reference.ReferenceConfig`: nearer the goal ranks first among nodes
        alike in energy, ranking only): narrow beams without it often never reach the goal (on
        4 hard held-out scenarios at width 32: no plan or regret 1.2 without, 0.00-0.04 with 0.5).
    :param seed_polish: with the primitive sampler, after the beams, polish the tree's best plan
        by local search (:func:`baselines.reference.polish.polish`, moves of up to this many
        consecutive primitives) and insert the result (0: no polish). The reference is polished so
        (``ReferenceConfig.polish``); without it the planner keeps the beam's local defects
        (held-out, 20 s: median primitive regret 0.16 without, 0.08 with; evaluation: 0.12 without,
        0.02 with). The continuous sampler is not polished: its beams need the time (evaluation,
        polished to depth 1 in 25 % of the budget taken from the beams: median regret 0.01 -> 0.03,
        mean 0.05 -> 0.12).
    :param seed_polish_share: share of the budget for that polish, taken from ``seed_share`` (the
        primitive beams then get ``seed_share - seed_polish_share``) [-].
    """

    selection_radius: float = 500.0
    pruning_radius: float = 250.0
    heading_scale: float = 100.0
    height_scale: float = 1.0
    batch_size: int = 1024
    mask_primitives: bool = True
    max_edges: int | None = None
    glide_share: float = 0.5
    circle_share: float = 0.0
    circle_radius: tuple[float, float] = (15.0, 60.0)
    thermal_targets: float = 0.0
    thermal_target_radius: float = 100.0
    cost_bound: bool = True
    completions: int = 8
    completion_depth: int = 20
    refinements: int = 8
    seed_width: int = 512
    seed_start_width: int = 32
    seed_scout_width: int = 8
    seed_share: float = 0.75
    seed_progress_weight: float = 0.5
    seed_polish: int = 2
    seed_polish_share: float = 0.25

    def __post_init__(self) -> None:
        for name in ("selection_radius", "pruning_radius", "heading_scale", "height_scale"):
            object.__setattr__(self, name, check_positive(name, getattr(self, name)))
        check_int("batch_size", self.batch_size, 1, 1 << 20)
        check_bool("mask_primitives", self.mask_primitives)
        if self.max_edges is not None:
            check_int("max_edges", self.max_edges, 1)
        object.__setattr__(
            self, "thermal_target_radius", check_positive("thermal_target_radius", self.thermal_target_radius)
        )
        for name in ("glide_share", "circle_share", "thermal_targets"):
            object.__setattr__(self, name, check_range(name, getattr(self, name), 0.0, 1.0))
        r = as_float_array("circle_radius", self.circle_radius)
        if r.shape != (2,) or not (np.all(np.isfinite(r)) and 0.0 < r[0] <= r[1]):
            raise ConfigError(
                f"circle_radius={self.circle_radius!r} must be (smallest, largest) radii [m]; "
                "allowed: 0 < smallest <= largest"
            )
        object.__setattr__(self, "circle_radius", (float(r[0]), float(r[1])))
        check_bool("cost_bound", self.cost_bound)
        check_int("completions", self.completions, 0, 1 << 20)
        check_int("completion_depth", self.completion_depth, 1, 1 << 20)
        check_int("refinements", self.refinements, 0, 1 << 20)
        check_int("seed_width", self.seed_width, 0, 100_000)
        check_int("seed_start_width", self.seed_start_width, 1, 100_000)
        check_int("seed_scout_width", self.seed_scout_width, 0, 100_000)
        object.__setattr__(self, "seed_share", check_range("seed_share", self.seed_share, 0.0, 1.0))
        object.__setattr__(
            self, "seed_progress_weight", check_range("seed_progress_weight", self.seed_progress_weight, 0.0, 100.0)
        )
        if self.seed_width and not self.seed_share > 0.0:
            raise ConfigError(f"seed_share={self.seed_share!r} must be > 0 when seed_width > 0; allowed: (0, 1]")
        check_int("seed_polish", self.seed_polish, 0, 2)
        object.__setattr__(
            self, "seed_polish_share", check_range("seed_polish_share", self.seed_polish_share, 0.0, 1.0)
        )
        if self.seed_width and self.seed_polish and not 0.0 < self.seed_polish_share < self.seed_share:
            raise ConfigError(
                f"seed_polish_share={self.seed_polish_share!r} must lie in (0, seed_share={self.seed_share!r}) "
                "when seed_polish > 0"
            )

    def acting_settings(self, sampler: str | None = None) -> dict[str, Any]:
        """The settings as a dict (``dataclasses.asdict``) without those that do nothing here: the
        ``seed_*`` fields when ``seed_width`` is 0, the ``seed_polish*`` ones when ``seed_polish``
        is 0 or ``sampler`` is ``"continuous"`` (the polish is for the primitives only). Results
        keyed by a configuration (the evaluation, the ablation) use it, so that adding a setting
        that is off does not make them stale."""
        out = asdict(self)
        if not self.seed_width:
            for name in [k for k in out if k.startswith("seed_")]:
                del out[name]
        elif not self.seed_polish or sampler == "continuous":
            for name in [k for k in out if k.startswith("seed_polish")]:
                del out[name]
        return out


#: Version of the completions' steering rule (:meth:`SoaringProblem.goal_controls`): bump it when
#: the rule's behaviour changes, so that results keyed by it (the evaluation's agent settings) are
#: redone. 2: final glide aimed at the goal's top - r/20; the primitives' homeward choice through
#: the model (2026-12-02).
STEERING_VERSION = 2

#: Named planner configurations: ``"paper"`` is the paper's SST (uniform samplers, no cost bound);
#: ``"soaring"`` adds the four measures of the README's ablation table; ``"seeded"`` (the default,
#: ``SoaringSSTConfig()``) adds to it a reference beam search, an 8-wide one and then widths from 32
#: up to 512 nodes per depth while the next width fits into 50 % of the budget (on ``paper``: a 32-wide primitive beam
#: takes about 1 s, a 256-wide one 5 s on this machine; widths below 256 return costlier primitive
#: plans), then the polish of its plan in the next 25 % (``seed_polish``).
SST_CONFIGS: dict[str, SoaringSSTConfig] = {
    "paper": SoaringSSTConfig(
        glide_share=0.0,
        circle_share=0.0,
        thermal_targets=0.0,
        cost_bound=False,
        completions=0,
        refinements=0,
        seed_width=0,
    ),
    "soaring": SoaringSSTConfig(seed_width=0),
    "seeded": SoaringSSTConfig(),
}
#: The name of the default configuration (``SoaringSSTConfig()``).
DEFAULT_SST_CONFIG = "seeded"


def planner_record(planner: str, sampler: str) -> dict[str, Any]:
    """What identifies the named configuration ``planner`` acting with ``sampler`` in a results
    record (the evaluation's and the tasks' SST episodes): its name, its acting settings and the
    steering rule's version; a change of either makes such records stale."""
    return {"planner": planner, "config": SST_CONFIGS[planner].acting_settings(sampler), "steering": STEERING_VERSION}


class SoaringProblem:
    """The soaring planning problem for the SST core.

    :param model: the flight model (scenario, aircraft, primitives).
    :param sampler: ``"primitive"`` or ``"continuous"``.
    :param config: distance weights (and the mask option); radii are used by the planner.
    :param start: start state ``[Pn, Pe, chi, h]`` [m, m, rad, m]; default the scenario's start.
    :param t0: start time [s].
    :param airspeed_prev: airspeed of the edge flown before the start [m/s], or None (no kinetic
        charge for the first edge, as after ``env.reset``).
    :param battery: the motor energy left at the start [J/kg] (the cross-country task's
        ``battery_left``), or None: no battery. With one, the state has a 7th column (``S_B``, the
        battery left) and edges that empty it are invalid (see the module docstring).
    """

    def __init__(
        self,
        model: SoaringModel,
        sampler: str = "primitive",
        config: SoaringSSTConfig | None = None,
        *,
        start: np.ndarray | None = None,
        t0: float = 0.0,
        airspeed_prev: float | None = None,
        battery: float | None = None,
    ) -> None:
        if not isinstance(model, SoaringModel):
            raise SSTError(f"model={model!r} must be a soaring_env.model.SoaringModel")
        if sampler not in SAMPLERS:
            raise SSTError(f"sampler={sampler!r} is unknown; allowed: {', '.join(map(repr, SAMPLERS))}")
        self.model = model
        self.kind = sampler
        self.config = config or SoaringSSTConfig()
        sc = model.scenario
        b = sc.bounds
        x0 = sc.start_state if start is None else np.array(as_float_array("start", start))
        if x0.shape != (4,) or not np.all(np.isfinite(x0)):
            raise SSTError(f"start={start!r} must be 4 finite numbers [Pn, Pe, chi, h]")
        if not bool(b.contains(x0[0], x0[1], x0[3])):
            raise SSTError(
                f"start position (north={x0[0]:g}, east={x0[1]:g}, height={x0[3]:g}) is outside the domain "
                f"north [{b.north_min:g}, {b.north_max:g}], east [{b.east_min:g}, {b.east_max:g}], "
                f"height (0, {b.height_max:g}]"
            )
        g = sc.require_goal()
        if bool(g.contains(x0[0], x0[1], x0[3])):
            raise SSTError("start lies inside the goal region; there is nothing to plan")
        t0 = check_finite("t0", t0)
        if airspeed_prev is not None:
            airspeed_prev = check_finite("airspeed_prev", airspeed_prev)
            if not airspeed_prev > 0:
                raise SSTError(f"airspeed_prev={airspeed_prev!r} must be None or > 0 m/s")
        if battery is not None:
            battery = check_finite("battery", battery)
            if not battery > 0.0:
                raise SSTError(f"battery={battery!r} must be None or > 0 J/kg (the motor energy left)")
        #: the motor energy left at the start [J/kg] (None: no battery)
        self.battery = battery
        check_goal_reachable(model)
        root = [*x0, t0, np.nan if airspeed_prev is None else airspeed_prev]
        self._root = np.array(root if battery is None else [*root, battery])
        cfg = self.config
        self.space = StateSpace(
            dim=len(self._root),
            dims=(S_N, S_E, S_H, S_CHI),
            scales=(1.0, 1.0, cfg.height_scale, cfg.heading_scale),
            periods=(0.0, 0.0, 0.0, 2 * math.pi),
            low=(b.north_min, b.east_min, 0.0, -math.pi),
            high=(b.north_max, b.east_max, b.height_max, math.pi),
        )
        table = model.library.table
        if sampler == "primitive":
            allowed = model.allowed_primitives() if cfg.mask_primitives else np.ones(model.n_primitives, bool)
            self.sampler: IndexSampler | BoxSampler = IndexSampler(model.n_primitives, allowed)
            # circling primitives: every segment turns on a circle within the radius band
            turn = np.minimum(np.abs(table[:, COL_CHI_DOT_1]), np.abs(table[:, COL_CHI_DOT_2]))
            radius = table[:, COL_AIRSPEED] / np.maximum(turn, 1e-300)
            circling = allowed & (radius >= cfg.circle_radius[0]) & (radius <= cfg.circle_radius[1])
            self._circling = IndexSampler(model.n_primitives, circling) if circling.any() else None
            self.control_dim = 1
        else:
            self.sampler = BoxSampler(3)
            self._circling = None
            self.control_dim = 3
        self._airspeeds = table[:, COL_AIRSPEED]
        lib = model.library
        self._point_times = lib.duration * np.arange(1, lib.n_points + 1) / lib.n_points  # as Rollout.times
        self._h_cap = model.end_height_cap()
        self._thermal_centres = sc.field.centres(t0)
        self._t0 = t0
        speeds, glide = model.straight_glides(41)
        self._glide_speed = float(speeds[int(np.argmax(glide))])  # flattest zero-thrust glide
        self._glide_angle = float(glide.max())
        self._speeds, self._speed_glide = speeds, glide
        # the completions climb until a glide at the circling airspeed reaches the goal (the
        # primitives fly home level: their glides are steep)
        self._tan_slow = 0.0 if sampler == "primitive" else math.tan(-float(glide[0]))
        v_min = float(model.control_low[0])
        rate = min(v_min / cfg.circle_radius[0], float(model.control_high[1]))
        # sink of the tightest circle at zero thrust [m/s]: the completions' "in lift" threshold
        self._circle_sink = -v_min * math.sin(float(model.aircraft.glide_angle(v_min, rate, b.height_max)))
        # the arcs the completions circle on: 41 course rates over the envelope, or the rates of
        # the slowest level single-segment primitives; "tight": +-3/4 and +-1 of the largest rate
        # (primitives: the two largest of each sign)
        top = float(model.control_high[1])
        self._arc_rates = np.linspace(-top, top, 41)
        if sampler == "primitive":
            ok = np.flatnonzero(allowed & (table[:, COL_CHI_DOT_1] == table[:, COL_CHI_DOT_2]))
            self._steer_ids = ok
            self._steer_actions = np.clip(
                model.control_to_action(table[ok][:, [COL_AIRSPEED, COL_CHI_DOT_1, COL_GAMMA]]), -1.0, 1.0
            )
            slow = ok[(table[ok, COL_AIRSPEED] == v_min) & (table[ok, COL_GAMMA] == 0.0)]
            if len(slow):
                self._arc_rates = np.unique(table[slow, COL_CHI_DOT_1])
            level = allowed & (table[:, COL_GAMMA] == 0.0)
            self._near_ids = np.flatnonzero(level if level.any() else allowed)
            self._home_ids = np.flatnonzero(allowed)
            # powered level flight per edge [J/kg] at each airspeed (still air, start height): the
            # homeward primitives' price of the distance they leave
            self._level_speeds = np.unique(table[allowed, COL_AIRSPEED])
            power = model.aircraft.fuel_power(self._level_speeds, 0.0, 0.0, float(x0[3]))
            self._level_edge_cost = power * model.library.duration
        rates = self._arc_rates
        self._tight_rates = np.array([-top, -0.75 * top, 0.75 * top, top])
        if sampler == "primitive":
            self._tight_rates = np.unique(
                np.concatenate([np.sort(rates[rates < 0])[:2], np.sort(rates[rates > 0])[-2:]])
            )
        # sink of each arc at zero thrust [m/s] (for the primitives' level arcs: the fuel's equivalent)
        self._arc_sink = -v_min * np.sin(model.aircraft.glide_angle(v_min, self._arc_rates, b.height_max))
        self._tight_sink = -v_min * np.sin(model.aircraft.glide_angle(v_min, self._tight_rates, b.height_max))

    # --- Problem protocol ---------------------------------------------------------------------
    def root_state(self) -> np.ndarray:
        return self._root.copy()

    def sample_targets(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """n selection targets (north, east, height, course) [m, m, m, rad]: uniform over the domain,
        a ``thermal_targets`` share of them over the thermals (see :class:`SoaringSSTConfig`)."""
        q = self.space.sample(rng, n)
        cfg = self.config
        if cfg.thermal_targets > 0.0 and len(self._thermal_centres):
            pick = np.flatnonzero(rng.random(n) < cfg.thermal_targets)
            j = rng.integers(0, len(self._thermal_centres), size=len(pick))
            r = cfg.thermal_target_radius * np.sqrt(rng.random(len(pick)))
            phi = rng.uniform(0.0, 2.0 * math.pi, size=len(pick))
            q[pick, 0] = self._thermal_centres[j, 0] + r * np.cos(phi)
            q[pick, 1] = self._thermal_centres[j, 1] + r * np.sin(phi)
        return q

    def sample_controls(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """n controls of the mixture of :class:`SoaringSSTConfig` (uniform when both shares are 0:
        then exactly the paper's samplers and random stream)."""
        cfg = self.config
        if self.kind == "primitive":
            u = self.sampler.sample(rng, n)
            if cfg.circle_share > 0.0 and self._circling is not None:
                pick = rng.random(n) < cfg.circle_share
                u[pick] = self._circling.sample(rng, int(pick.sum()))
            return u
        if cfg.glide_share == 0.0 and cfg.circle_share == 0.0:
            return self.sampler.sample(rng, n)
        u = rng.uniform(-1.0, 1.0, size=(n, 3))
        m = self.model
        lo, hi = m.control_low, m.control_high
        if cfg.circle_share > 0.0:
            pick = rng.random(n) < cfg.circle_share
            radius = rng.uniform(cfg.circle_radius[0], cfg.circle_radius[1], n)
            sign = np.where(rng.random(n) < 0.5, -1.0, 1.0)
            v = lo[0] + 0.5 * (u[:, 0] + 1.0) * (hi[0] - lo[0])
            chi_dot = sign * np.minimum(v / radius, hi[1])
            u[pick, 1] = np.clip(2.0 * (chi_dot - lo[1]) / (hi[1] - lo[1]) - 1.0, -1.0, 1.0)[pick]
        u = u.astype(np.float32).astype(np.float64)
        if cfg.glide_share > 0.0:
            pick = rng.random(n) < cfg.glide_share
            u[pick, 2] = self.glide_action(u[pick])
        return u

    def goal_controls(self, states: np.ndarray) -> np.ndarray:
        """The steering rule of the greedy goal completions: glide home, or climb in a thermal first.

        Per core state, with ``aim = goal top - radius / 20`` (continuous; primitives: ``- radius / 4``)
        and the flattest zero-thrust glide (best-glide airspeed, still air):

        * high enough to glide to the aim height over the remaining distance: turn towards the goal
          centre (course rate = course error / Ts, within the envelope) on the path angle that
          arrives at the aim height -- a zero-thrust glide or steeper -- at the present airspeed
          if its own glide suffices (no kinetic charge), else at the best-glide airspeed;
        * too low (below the aim plus the remaining distance times the glide ratio at the circling
          airspeed), in lift (updraft above the sink of a slow circle + 0.2 m/s): circle there at the
          slowest airspeed and the zero-thrust glide angle, on the circle tangent to the course whose
          centre comes closest to the thermal's centre (radius within ``circle_radius``);
        * too low, and in lift or within one slow edge of a thermal: the slowest-airspeed arc with
          the most lift two edges ahead (:meth:`_best_circle`) if one climbs;
        * too low otherwise: glide towards the thermal with the shortest detour (distance to it
          plus its distance to the goal) at the best-glide airspeed (the slowest one within one
          such edge of it, so as not to overshoot), powered only if a glide would arrive below 50 m;
        * no thermals: fly to the aim height (a powered climb where needed).

        The primitive sampler takes the nearest single-segment primitive in normalized controls to
        reach a thermal, the model-scored level arc in it (:meth:`_best_primitive_arc`), and on the
        way home the primitive that leaves the least to fly (:meth:`_best_home_primitive`).
        """
        m = self.model
        lo, hi = m.control_low, m.control_high
        g = m.scenario.require_goal()
        f = m.scenario.field
        n_, e_, chi, h = states[:, S_N], states[:, S_E], states[:, S_CHI], states[:, S_H]
        ts = m.library.duration

        def towards(tn: np.ndarray, te: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            err = np.mod(np.arctan2(te - e_, tn - n_) - chi + math.pi, 2.0 * math.pi) - math.pi
            return np.clip(err / ts, lo[1], hi[1]), np.hypot(tn - n_, te - e_)

        chi_dot, d_goal = towards(np.full_like(n_, g.north), np.full_like(e_, g.east))
        dist = np.maximum(d_goal - 0.5 * g.radius, 1.0)
        # aim just below the top (continuous: every metre kept is energy; 0.9 r cost ~50 J/kg more on
        # `paper`); the primitives arrive level, so lower, inside the region
        aim = g.height + (0.75 if self.kind == "primitive" else 0.95) * g.radius
        gamma = np.arctan2(aim - h, dist)
        # glide home at the present airspeed (no kinetic charge) where its glide suffices
        v_now = np.clip(np.where(np.isfinite(states[:, S_V]), states[:, S_V], self._glide_speed), lo[0], hi[0])
        tan_now = np.tan(-np.interp(v_now, self._speeds, self._speed_glide))
        v = np.where(h >= aim + dist * tan_now, v_now, self._glide_speed)
        exact_glide = np.zeros(len(states), bool)
        if f.thermals:
            # climb until a glide at the circling airspeed reaches the aim: height is free in lift,
            # and a slow glide home pays no kinetic charge
            low = h < aim + dist * self._tan_slow
            cen = self._thermal_centres[None, :, :] + (states[:, S_T] - self._t0)[:, None, None] * (
                f.wind if f.drift else np.zeros(2)
            )
            d_th = np.hypot(cen[:, :, 0] - n_[:, None], cen[:, :, 1] - e_[:, None])
            d_home = np.hypot(cen[:, :, 0] - g.north, cen[:, :, 1] - g.east)
            detour = d_th + d_home
            if not f.steady:  # only thermals alive at each state's time are worth a detour
                tt = states[:, S_T, None]
                live = (f.packed[None, :, COL_BIRTH] < tt) & (tt < f.packed[None, :, COL_DEATH])
                detour = np.where(live, detour, np.inf)
                low = low & live.any(axis=1)  # none alive: fly home as without thermals
            j = np.argmin(detour, axis=1)
            rows = np.arange(len(states))
            cn, ce = cen[rows, j, 0], cen[rows, j, 1]
            cd_th, dd = towards(cn, ce)
            lift = f.updraft(n_, e_, h, states[:, S_T]) > self._circle_sink + 0.2
            # in lift, or the thermal within one slow edge: pick the slow arc that leads to most lift
            reach = (hi[0] if self.kind == "primitive" else lo[0]) * ts  # primitives: any level one
            near = low & (lift | (dd < reach))
            circle = np.zeros(len(states), bool)
            prim = np.full(len(states), -1, np.int64)
            if near.any():
                idx = np.flatnonzero(near)
                if self.kind == "primitive":
                    pid, gain, h_end = self._best_primitive_arc(states[near])
                    # no net climb within reach: go on; and stop below the goal's top (the
                    # primitives fly home level and their descents are steep)
                    full = h_end >= g.height + 0.95 * g.radius
                    ok = (gain > 0.0) & ~full
                    low[idx[full]] = False  # high enough: home
                    prim[idx[ok]] = pid[ok]
                else:
                    rate, gain = self._best_circle(states[near])
                    ok = gain > 0.0
                    chi_dot[idx[ok]] = rate[ok]
                circle[idx[ok]] = True
            go = low & ~circle
            g_th = np.maximum(self._glide_angle, np.arctan2(50.0 - h, np.maximum(dd, 1.0)))
            chi_dot = np.where(go, cd_th, chi_dot)
            gamma = np.where(go, g_th, gamma)
            # the last approach at the slowest airspeed, so that the edge does not overshoot the core
            v = np.where(circle | (go & (dd < self._glide_speed * ts)), lo[0], np.where(go, self._glide_speed, v))
            exact_glide = circle | (go & (g_th == self._glide_angle))
        ctrl = np.stack([v, chi_dot, np.clip(gamma, lo[2], hi[2])], axis=1)
        act = np.clip(m.control_to_action(ctrl), -1.0, 1.0)
        if self.kind == "primitive":  # the nearest single-segment primitive in normalized controls
            if exact_glide.any():  # circle and glide level: the primitives' glides are steep
                act[exact_glide, 2] = m.control_to_action(np.array([lo[0], 0.0, 0.0]))[2]
            d2 = ((act[:, None, :] - self._steer_actions[None, :, :]) ** 2).sum(axis=2)
            pick = self._steer_ids[np.argmin(d2, axis=1)]
            if f.thermals:
                pick = np.where(prim >= 0, prim, pick)
                home = ~(low | circle)
            else:
                home = np.ones(len(states), bool)
            if home.any():  # homeward: the primitive that leaves the least to fly, through the model
                pick[home] = self._best_home_primitive(states[home])
            return pick.astype(np.float64)[:, None]
        out = act.astype(np.float32).astype(np.float64)
        if exact_glide.any():
            out[exact_glide, 2] = self.glide_action(out[exact_glide])
        return out

    def _arcs(self, n0, e0, chi0, rates):
        """Still-air kinematics of constant-rate arcs at the slowest airspeed: for starts of any
        shape S and rates (K,), 10 points along each Ts-long arc (S + (K, 10)) and the end
        positions and courses (S + (K,))."""
        ts = self.model.library.duration
        v = float(self.model.control_low[0])
        t = (np.arange(10) + 0.5) / 10.0 * ts
        w = rates[:, None]
        small = np.abs(w) < 1e-9
        ws = np.where(small, 1.0, w)
        c0 = np.asarray(chi0)[..., None, None]
        sin0, cos0 = np.sin(c0), np.cos(c0)
        k_n, k_e = v / ws, -v / ws

        def at(tt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            c = c0 + ws * tt
            dn = np.where(small, v * tt * cos0, k_n * (np.sin(c) - sin0))
            de = np.where(small, v * tt * sin0, k_e * (np.cos(c) - cos0))
            return np.asarray(n0)[..., None, None] + dn, np.asarray(e0)[..., None, None] + de

        pn, pe = at(t)
        en, ee = at(np.array([ts]))
        return pn, pe, en[..., 0], ee[..., 0], c0[..., 0] + rates * ts

    def _mean_lift(self, pn: np.ndarray, pe: np.ndarray, h: np.ndarray, t0: np.ndarray) -> np.ndarray:
        """Mean updraft [m/s] over the last axis of points (the arcs' 10 points, flown from time
        ``t0``); ``h`` and ``t0`` are per start (the leading axis)."""
        ts = self.model.library.duration
        t = (np.arange(10) + 0.5) / 10.0 * ts
        extra = (1,) * (pn.ndim - 1)
        hh = h.reshape(h.shape + extra)
        tt = t0.reshape(t0.shape + extra[:-1] + (1,)) + t
        return self.model.scenario.field.updraft(pn, pe, hh, tt).mean(axis=-1)

    def _tight_gain(self, en, ee, ec, h: np.ndarray, t1: np.ndarray) -> np.ndarray:
        """Best net climb [m/s] (mean updraft minus sink) of the tight circles from given ends."""
        pn, pe, _, _, _ = self._arcs(en, ee, ec, self._tight_rates)
        return (self._mean_lift(pn, pe, h, t1) - self._tight_sink).max(axis=-1)

    def _best_circle(self, states: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Course rate [rad/s] and score [m/s] of the slowest-airspeed arc that leads to the most
        lift, two edges ahead: for each arc rate, the mean updraft at 10 points along the arc it
        flies in Ts (still-air kinematics at the start height) minus its zero-thrust sink, plus
        the best net climb of the tight circles flown from the arc's end (:meth:`_tight_gain`) --
        so that an arc that moves towards the core wins over a circle that stays off it."""
        ts = self.model.library.duration
        h, t0 = states[:, S_H], states[:, S_T]
        pn, pe, en, ee, ec = self._arcs(states[:, S_N], states[:, S_E], states[:, S_CHI], self._arc_rates)
        first = self._mean_lift(pn, pe, h, t0) - self._arc_sink
        score = first + self._tight_gain(en, ee, ec, h, t0 + ts)
        k = np.argmax(score, axis=1)
        return self._arc_rates[k], score[np.arange(len(states)), k]

    def _best_primitive_arc(self, states: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The primitive sampler's :meth:`_best_circle`: every level primitive (within the bank
        limit) is flown through the model (its exact cost, in m/s of climb: -cost / (g Ts)), plus the
        tight circles' net climb from its end; returns the best primitive, its score and its end
        height [m]."""
        ts = self.model.library.duration
        ids = self._near_ids
        n, k = len(states), len(ids)
        e = self.propagate(np.repeat(states, k, axis=0), np.tile(ids, n).astype(np.float64)[:, None])
        end = e.states.reshape(n, k, -1)
        gain = -e.cost.reshape(n, k) / (G * ts)
        gain = np.where(e.outcome.reshape(n, k) == EDGE_INVALID, -np.inf, gain)
        score = gain + self._tight_gain(
            end[..., S_N], end[..., S_E], end[..., S_CHI], states[:, S_H], states[:, S_T] + ts
        )
        j = np.argmax(score, axis=1)
        return ids[j], score[np.arange(n), j], end[np.arange(n), j, S_H]

    def _best_home_primitive(self, states: np.ndarray) -> np.ndarray:
        """The homeward primitive of each state: every allowed primitive is flown through the model
        and scored by its exact cost plus the cheapest level flight [J/kg per m] over the horizontal
        distance it leaves to the goal region (zero on a goal edge), so that lift on the way home
        and a slow, cheap airspeed in it are used where they pay."""
        ids = self._home_ids
        n, k = len(states), len(ids)
        e = self.propagate(np.repeat(states, k, axis=0), np.tile(ids, n).astype(np.float64)[:, None])
        g = self.model.scenario.require_goal()
        end = e.states
        # the region is a ball: at height h it reaches sqrt(r^2 - (h - h_goal)^2) out; height above
        # it must be lost on the way (charged as potential: g per metre)
        dh = end[:, S_H] - g.height
        reach = np.sqrt(np.maximum(g.radius**2 - dh**2, 0.0))
        dn, de = g.north - end[:, S_N], g.east - end[:, S_E]
        left = np.maximum(np.hypot(dn, de) - reach, 0.0)
        # facing away costs a turn: about its arc on a 100 m circle (a 10 m/s half turn per edge)
        err = np.abs(np.mod(np.arctan2(de, dn) - end[:, S_CHI] + math.pi, 2.0 * math.pi) - math.pi)
        left = left + np.where(left > 0.0, 100.0 * err, 0.0)
        above = np.maximum(dh - 0.95 * g.radius, 0.0)
        # level flight home at the best airspeed v: whole edges (a goal edge is charged in full),
        # plus the kinetic charge of speeding up from the edge's airspeed
        v, edge, eta = self._level_speeds, self._level_edge_cost, self.model.aircraft.eta_ec * self.model.aircraft.eta_p
        ts = self.model.library.duration
        v0 = end[:, S_V][:, None]
        n_legs = left[:, None] / (v[None, :] * ts)
        legs = (np.ceil(n_legs) + 0.1 * n_legs) * edge[None, :]  # whole edges; the rest breaks ties
        togo = (legs + np.maximum(0.5 * (v[None, :] ** 2 - v0**2), 0.0) / eta).min(axis=1) + G * above
        score = e.cost + np.where(e.outcome == EDGE_GOAL, 0.0, togo)
        score = np.where(e.outcome == EDGE_INVALID, np.inf, score).reshape(n, k)
        return ids[np.argmin(score, axis=1)]

    def glide_action(self, actions: np.ndarray) -> np.ndarray:
        """The float32-exact normalized path-angle component of the zero-thrust glide for each
        action's (airspeed, course rate): the largest float32 whose path angle needs no thrust."""
        m = self.model
        lo, hi = m.control_low, m.control_high
        c = m.action_to_control(actions)
        gam = m.aircraft.glide_angle(c[:, 0], c[:, 1], self.model.scenario.bounds.height_max)
        a = np.clip(2.0 * (gam - lo[2]) / (hi[2] - lo[2]) - 1.0, -1.0, 1.0).astype(np.float32)
        back = lo[2] + 0.5 * (a.astype(np.float64) + 1.0) * (hi[2] - lo[2])  # as action_to_control maps it
        a = np.where((back > gam) & (a > -1.0), np.nextafter(a, np.float32(-1.0)), a)
        return a.astype(np.float64)

    def propagate(self, states: np.ndarray, controls: np.ndarray) -> Edges:
        """Fly ``controls`` (primitive indices (n, 1), or normalized actions (n, 3)) from core
        ``states`` (n, 6) through the model's propagator -- the kernel and arguments ``env.step``
        uses, so a plan's edges replay bit for bit. ``rollout``'s argument checks are skipped (they
        cost about 0.5 ms a call, most of a small batch's time): every start lies in the domain
        (the root is checked, and only valid edges' ends become nodes) and the controls are checked
        here."""
        m = self.model
        prop = m.propagator
        t0 = np.array(states[:, S_T])  # fresh C-contiguous copies (see Propagator.run)
        vp = np.array(states[:, S_V])
        if self.kind == "primitive":
            idx = controls[:, 0].astype(np.int64)
            if len(idx) and (idx.min() < 0 or idx.max() >= len(self._airspeeds)):
                raise SSTError(f"primitive controls must lie in 0..{len(self._airspeeds) - 1}; got {controls[:, 0]!r}")
            ctrl = np.take(prop.ctrl_table, idx, axis=0)
            v = self._airspeeds[idx]
        else:
            u = m.action_to_control(controls)  # raises for actions outside [-1, 1]
            ctrl = control_rows(u)
            v = u[:, 0]
        points, terms = prop.run(np.array(states[:, :4], order="C"), t0, vp, ctrl)
        code, k = m.classify_points(points)
        rows = np.arange(len(k))
        out = np.empty((len(k), states.shape[1]))
        out[:, :4] = points[rows, k]
        # the env advances its clock by Ts per step; a goal edge counts up to its first goal point
        dur = np.where(code == GOAL, self._point_times[k], prop.duration)
        out[:, S_T] = t0 + dur
        out[:, S_V] = v
        outcome = np.where(code == FLYING, EDGE_VALID, np.where(code == GOAL, EDGE_GOAL, EDGE_INVALID))
        if self.battery is not None:  # the env's charge and test, in its order of operations
            out[:, S_B] = states[:, S_B] - (terms[:, 0] + terms[:, 2])
            outcome = np.where((outcome == EDGE_VALID) & (out[:, S_B] <= 0.0), EDGE_INVALID, outcome)
        # no plan ends above h_cap, and fuel + kinetic >= 0: from height h at least -g (h_cap - h) to go
        togo = -G * (self._h_cap - out[:, S_H]) if self.config.cost_bound else None
        return Edges(states=out, cost=terms[:, 3], duration=dur, outcome=outcome, togo=togo)

    # --- env actions ----------------------------------------------------------------------------
    def to_action(self, control: np.ndarray) -> int | np.ndarray:
        """The env action of a core control row: a primitive index (int) or a float32 (3,) array."""
        if self.kind == "primitive":
            return int(control[0])
        return np.asarray(control, dtype=np.float32).reshape(3)


def check_goal_reachable(model: SoaringModel) -> None:
    """Raise if the goal region cannot be reached in principle.

    An edge reaches the goal when one of its N output points lies inside the region; consecutive
    points are at most ``(v_max + |wind|) Ts / N`` apart. A region narrower than half that spacing
    can be crossed without any point landing inside it, so it is refused (the scenario already
    guarantees that the goal centre lies inside the domain).
    """
    sc = model.scenario
    lib = model.library
    wind = math.hypot(sc.field.wind_north, sc.field.wind_east)
    spacing = (float(model.control_high[0]) + wind) * lib.duration / lib.n_points
    radius = sc.require_goal().radius
    if radius < 0.5 * spacing:
        raise SSTError(
            f"goal.radius={radius!r} m is too small to be reached in principle: flown points are up to "
            f"{spacing:.3g} m apart (Ts={lib.duration:g} s, N={lib.n_points}); allowed: radius >= {0.5 * spacing:.3g} m"
        )
