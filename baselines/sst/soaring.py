"""The soaring adapter: plugs the flight model (:class:`soaring_env.model.SoaringModel`) into the
generic SST core as a :class:`~baselines.sst.core.Problem`.

State vector seen by the core (6 floats): ``[Pn, Pe, chi, h, t, v_prev]`` -- the model's state
``[Pn [m], Pe [m], chi [rad], h [m]]``, the time [s] (it matters for drifting thermals) and the
airspeed of the edge that led here [m/s] (NaN at the start: the first edge pays no kinetic term,
as in the env). Only ``Pn, Pe, h, chi`` enter the distance:

    d^2 = dPn^2 + dPe^2 + (height_scale dh)^2 + (heading_scale wrap(dchi))^2      [m^2]

with ``wrap`` taking the course difference into [-pi, pi] and ``heading_scale`` in m/rad (default
100 m/rad: a half-turn counts as 314 m, about one 10 m/s primitive). Selection targets are drawn
uniformly over the flight domain (north, east, height) and all courses.

Controls: ``"primitive"`` -- an index into the 174 primitives, drawn uniformly (by default only
among those within the model's bank limit, ``model.bank_ok()``); ``"continuous"`` -- a normalized
action in [-1, 1]^3 drawn uniformly and mapped by ``model.action_to_control`` onto the envelope of
the primitives ((v_a, chi_dot, gamma) in [10, 20] m/s x +-1080 deg/Ts x +-45 deg), held for Ts.
Both are exactly the actions of the discrete and continuous envs.

An edge is propagated with the same calls ``env.step`` makes (``model.rollout_primitive`` or
``model.rollout_control`` with ``t0`` and ``airspeed_prev``, then ``model.classify``): its cost is
the full edge cost, its end state the first goal point for goal edges; crash and out-of-bounds
edges are invalid.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from baselines.sst.core import EDGE_GOAL, EDGE_INVALID, EDGE_VALID, Edges, SSTError, StateSpace
from baselines.sst.samplers import BoxSampler, IndexSampler
from soaring_env._validation import as_float_array, check_bool, check_finite, check_int, check_positive
from soaring_env.model import FLYING, GOAL, SoaringModel
from soaring_env.primitives import COL_AIRSPEED

SAMPLERS = ("primitive", "continuous")
#: Columns of the core's state vector.
S_N, S_E, S_CHI, S_H, S_T, S_V = range(6)


@dataclass(frozen=True)
class SoaringSSTConfig:
    """Planner settings for the soaring problem.

    Defaults (chosen on the paper scenario, see the README): delta_s = 250 m, a little under half a
    20 m/s primitive (600 m) and about one 10 m/s primitive's displacement in a turn; delta_BN =
    2 delta_s, the ratio of OMPL's defaults; K = 1024 expansions per round (fast, and on the paper
    scenario it found cheaper solutions than smaller rounds -- batching changes the search, see
    :mod:`baselines.sst.core`; ``batch_size=1`` is the published one-at-a-time algorithm).

    :param selection_radius: delta_BN [m] (in the distance of this module's docstring).
    :param pruning_radius: delta_s [m].
    :param heading_scale: weight of the course angle in the distance [m/rad].
    :param height_scale: weight of the height in the distance [-].
    :param batch_size: expansions per round (1 = one-at-a-time SST, see ``baselines.sst.core``).
    :param mask_primitives: draw only the primitives within the model's bank limit.
    :param max_edges: most edges (env steps) a plan may have, e.g. the env's ``max_episode_steps``
        (None: unlimited, as in the paper).
    """

    selection_radius: float = 500.0
    pruning_radius: float = 250.0
    heading_scale: float = 100.0
    height_scale: float = 1.0
    batch_size: int = 1024
    mask_primitives: bool = True
    max_edges: int | None = None

    def __post_init__(self) -> None:
        for name in ("selection_radius", "pruning_radius", "heading_scale", "height_scale"):
            object.__setattr__(self, name, check_positive(name, getattr(self, name)))
        check_int("batch_size", self.batch_size, 1, 1 << 20)
        check_bool("mask_primitives", self.mask_primitives)
        if self.max_edges is not None:
            check_int("max_edges", self.max_edges, 1)


class SoaringProblem:
    """The soaring planning problem for the SST core.

    :param model: the flight model (scenario, aircraft, primitives).
    :param sampler: ``"primitive"`` or ``"continuous"``.
    :param config: distance weights (and the mask option); radii are used by the planner.
    :param start: start state ``[Pn, Pe, chi, h]`` [m, m, rad, m]; default the scenario's start.
    :param t0: start time [s].
    :param airspeed_prev: airspeed of the edge flown before the start [m/s], or None (no kinetic
        charge for the first edge, as after ``env.reset``).
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
        g = sc.goal
        if bool(g.contains(x0[0], x0[1], x0[3])):
            raise SSTError("start lies inside the goal region; there is nothing to plan")
        t0 = check_finite("t0", t0)
        if airspeed_prev is not None:
            airspeed_prev = check_finite("airspeed_prev", airspeed_prev)
            if not airspeed_prev > 0:
                raise SSTError(f"airspeed_prev={airspeed_prev!r} must be None or > 0 m/s")
        check_goal_reachable(model)
        self._root = np.array([*x0, t0, np.nan if airspeed_prev is None else airspeed_prev])
        cfg = self.config
        self.space = StateSpace(
            dim=6,
            dims=(S_N, S_E, S_H, S_CHI),
            scales=(1.0, 1.0, cfg.height_scale, cfg.heading_scale),
            periods=(0.0, 0.0, 0.0, 2 * math.pi),
            low=(b.north_min, b.east_min, 0.0, -math.pi),
            high=(b.north_max, b.east_max, b.height_max, math.pi),
        )
        if sampler == "primitive":
            allowed = model.bank_ok() if cfg.mask_primitives else None
            self.sampler: IndexSampler | BoxSampler = IndexSampler(model.n_primitives, allowed)
            self.control_dim = 1
        else:
            self.sampler = BoxSampler(3)
            self.control_dim = 3
        self._airspeeds = model.library.table[:, COL_AIRSPEED]

    # --- Problem protocol ---------------------------------------------------------------------
    def root_state(self) -> np.ndarray:
        return self._root.copy()

    def sample_controls(self, rng: np.random.Generator, n: int) -> np.ndarray:
        return self.sampler.sample(rng, n)

    def propagate(self, states: np.ndarray, controls: np.ndarray) -> Edges:
        x = states[:, :4]
        t0 = states[:, S_T]
        vp = states[:, S_V]
        m = self.model
        if self.kind == "primitive":
            idx = controls[:, 0].astype(np.int64)
            r = m.rollout_primitive(x, idx, t0=t0, airspeed_prev=vp)
            v = self._airspeeds[idx]
        else:
            u = m.action_to_control(controls)
            r = m.rollout_control(x, u, t0=t0, airspeed_prev=vp)
            v = u[:, 0]
        code, k = m.classify(r)
        rows = np.arange(len(k))
        out = np.empty((len(k), 6))
        out[:, :4] = r.states[rows, k]
        # the env advances its clock by Ts per step; a goal edge counts up to its first goal point
        dur = np.where(code == GOAL, r.times[k], self.model.library.duration)
        out[:, S_T] = t0 + dur
        out[:, S_V] = v
        outcome = np.where(code == FLYING, EDGE_VALID, np.where(code == GOAL, EDGE_GOAL, EDGE_INVALID))
        return Edges(states=out, cost=r.cost, duration=dur, outcome=outcome)

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
    if sc.goal.radius < 0.5 * spacing:
        raise SSTError(
            f"goal.radius={sc.goal.radius!r} m is too small to be reached in principle: flown points are up to "
            f"{spacing:.3g} m apart (Ts={lib.duration:g} s, N={lib.n_points}); allowed: radius >= {0.5 * spacing:.3g} m"
        )
