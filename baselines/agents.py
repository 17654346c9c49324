"""The common agent interface of the baselines, and the agents that need no planner.

Every agent that :mod:`baselines.evaluation` runs follows :class:`Agent`: ``reset(env, seed)`` once
per episode, right after ``env.reset`` (a planner plans there, from ``env.unwrapped``), then
``predict(obs)`` once per ``env.step`` -- the signature of stable-baselines3's ``predict``, so an SB3
model, :func:`stable_baselines3.common.evaluation.evaluate_policy` and these agents are
interchangeable. Execution and scoring always go through ``env.step``.

* :class:`RandomAgent` -- uniform random actions from its own seeded generator, optionally only
  among the actions that the env's ``action_masks()`` allows.
* :class:`HeuristicAgent` -- a hand-written rule, no search: circle while the updraft measured at
  the aircraft is strong and height is still useful, otherwise turn towards the goal and pick the
  path angle that brings the aircraft down (or up) to the goal region on arrival.
* :class:`ReplayAgent` -- a fixed plan of env actions (the reference search's), one per step.
* :class:`SSTPlannerAgent` -- :class:`baselines.sst.SSTAgent` (plans on reset with the model the
  env exposes; knows the thermal field) behind this interface, seeded per episode.
* :class:`PPOAgent` -- a saved stable-baselines3 / sb3-contrib model with the JSON configuration it
  was trained with (see :mod:`baselines.ppo`); acts deterministically by default. torch is imported
  only when one is loaded.
* :class:`RolloutAgent` -- a discrete successor policy improved at every decision by one-step
  lookahead in the model its observation shows (the rollout algorithm, the policy as base policy).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, Protocol, cast, runtime_checkable

import gymnasium as gym
import numpy as np

from soaring_env._validation import (
    ConfigError,
    check_choice,
    check_finite,
    check_int,
    check_positive,
    check_range,
    check_type,
)
from soaring_env.physics import glide_height_loss
from soaring_env.primitives import COL_AIRSPEED, COL_CHI_DOT_1, COL_CHI_DOT_2, COL_FAMILY, COL_GAMMA, SPIRAL

__all__ = [
    "Agent",
    "HeuristicAgent",
    "PPOAgent",
    "RandomAgent",
    "ReplayAgent",
    "RolloutAgent",
    "SSTPlannerAgent",
    "ThermallingAgent",
    "action_mask_of",
]


@runtime_checkable
class Agent(Protocol):
    """What :mod:`baselines.evaluation` needs from an agent.

    ``name`` labels results. ``reset`` is called once per episode after ``env.reset`` and may plan
    (its time counts as compute time). ``predict`` returns ``(action, state)`` like SB3.
    """

    name: str

    def reset(self, env: gym.Env, seed: int | None = None) -> None:
        """Prepare for a new episode of ``env`` (already reset); ``seed`` seeds the agent's randomness."""
        ...

    def predict(
        self,
        observation: Any,
        state: Any = None,
        episode_start: Any = None,
        deterministic: bool = True,
    ) -> tuple[Any, Any]:
        """The action for ``observation`` and the recurrent state (``None`` here)."""
        ...


def action_mask_of(env: gym.Env) -> np.ndarray | None:
    """The env's boolean action mask (``action_masks()`` of the base env), or ``None`` if it has none."""
    fn = getattr(env.unwrapped, "action_masks", None)
    if fn is None:
        return None
    mask = np.asarray(fn(), dtype=bool)
    return mask if mask.any() else None


class RandomAgent:
    """Uniformly random actions from a seeded generator of its own.

    :param use_masks: on a ``Discrete`` env with ``action_masks()``, draw only among allowed actions
        (a fairer baseline: it never picks a primitive the env forbids).
    :param name: label in results.
    """

    def __init__(self, *, use_masks: bool = True, name: str = "random") -> None:
        self.name = name
        self.use_masks = use_masks
        self._env: gym.Env | None = None
        self._rng = np.random.default_rng()

    def reset(self, env: gym.Env, seed: int | None = None) -> None:
        """Remember ``env`` (for its action space and masks) and reseed the generator with ``seed``."""
        self._env = env
        self._rng = np.random.default_rng(seed)

    def predict(
        self, observation: Any, state: Any = None, episode_start: Any = None, deterministic: bool = True
    ) -> tuple[Any, None]:
        """A random action; ``deterministic`` is ignored (the generator is seeded in :meth:`reset`)."""
        if self._env is None:
            raise RuntimeError("RandomAgent.predict called before reset(env, seed)")
        space = self._env.action_space
        if isinstance(space, gym.spaces.Discrete):
            mask = action_mask_of(self._env) if self.use_masks else None
            if mask is not None:
                return np.int64(self._rng.choice(np.flatnonzero(mask))), None
            return np.int64(space.start + self._rng.integers(space.n)), None
        if isinstance(space, gym.spaces.Box):
            a = self._rng.uniform(space.low, space.high)
            return a.astype(space.dtype), None
        raise TypeError(f"RandomAgent supports Discrete and Box action spaces, not {space!r}")


#: Where :class:`HeuristicAgent` aims to enter the goal region: ``ARRIVE`` x its radius above the
#: goal's height when a glide gets there (height kept is energy not spent), as far below it when the
#: motor must help (each metre climbed under power costs ``1 / eta`` of its potential energy).
ARRIVE = 0.8
#: Steepest path angle [rad] :class:`HeuristicAgent` asks of a primitive: the paper's primitives
#: descend at 0, -15 or -45 deg, and a -45 deg edge at 20 m/s drops 420 m in 30 s.
PRIMITIVE_DESCENT = math.radians(15.0)
#: Candidate total turns of one step for :class:`HeuristicAgent`'s steering (2.5 deg apart).
TURN_GRID = np.linspace(-math.pi, math.pi, 145)


def flattest_glide(model: Any) -> tuple[float, float]:
    """(airspeed [m/s], path angle [rad]) of the flattest zero-thrust straight glide in the model's
    continuous envelope (21 airspeeds; the glide angle that needs no thrust anywhere below the
    domain's ceiling): the best-L/D cruise."""
    speeds, glide = model.straight_glides(21)
    k = int(np.argmax(glide))
    return float(speeds[k]), float(glide[k])


def _wrap(angle: float) -> float:
    """Angle wrapped to [-pi, pi)."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


class HeuristicAgent:
    """Head for the goal, circle in lift: a hand-written rule with no search and no thermal map.

    It reads only what an aircraft measures (position, course, height, and the updraft at its own
    position and at two probe points ``probe`` metres to its left and right, like a variometer) and
    where the goal is. Each decision:

    1. **Circle in lift** -- if the updraft here is at least ``lift_threshold`` and the aircraft is
       below ``ceiling`` of the boundary-layer depth and not already high enough to glide into the
       goal region (:meth:`climb_useful`), fly a full circle at the slow airspeed, level, turning
       towards the side where the probes measure more lift.
    2. **Head for the goal** -- otherwise fly as a pilot flies a straight final glide
       (:meth:`cruise`): at the speed to fly (the airspeed that loses least height per metre over
       the ground in the wind along the track), gliding at zero thrust where the glide reaches the
       goal region, else on the straight line to the region's lower part under power (arriving
       high costs potential energy the motor pays at 1/eta); each step turns by the amount whose
       arc ends nearest the goal and facing it. Within a step of the goal, the pursuit arc through
       it. On a battery (cross-country) it never climbs under power.

    Without a goal (the thermal-climb task) step 2 becomes **search**: fly straight at the
    flattest zero-thrust glide (level below 120 m, to stay airborne) until lift is found, turning
    back towards the start beyond ``search_radius``.

    On the discrete env it picks the primitive nearest to that intent (among those the action mask
    allows); on the continuous env it commands the control directly.

    :param lift_threshold: updraft [m/s] that counts as lift worth circling in.
    :param ceiling: fraction of the thermal field's ``zi`` above which it stops circling.
    :param probe: lateral distance [m] of the left/right updraft probes.
    :param search_radius: without a goal: the distance [m] from the start beyond which it turns back.
    :param name: label in results.
    """

    #: The rule's version, recorded with every result it flies (a changed rule flies again). v2
    #: (2026-12-08): the speed to fly, zero-thrust glides, arrival low under power and steering by
    #: the step's arc replaced v1's fast cruise to the region's upper half by pure pursuit (held-out
    #: median regret 2.49 -> 1.07 on the primitives, 1.45 -> 1.00 continuous; README).
    RULE = "v2"

    def __init__(
        self,
        *,
        lift_threshold: float = 0.8,
        ceiling: float = 0.75,
        probe: float = 60.0,
        search_radius: float = 1000.0,
        name: str = "heuristic",
    ) -> None:
        self.name = name
        self.search_radius = check_positive("search_radius", search_radius)
        # inf: never circle (the "direct" flyer)
        self.lift_threshold = math.inf if lift_threshold == math.inf else check_finite("lift_threshold", lift_threshold)
        self.ceiling = check_range("ceiling", ceiling, 0.0, 1.0, low_open=True)
        self.probe = check_positive("probe", probe)
        self._env: gym.Env | None = None

    def reset(self, env: gym.Env, seed: int | None = None) -> None:
        """Remember ``env``; the rule is deterministic, so ``seed`` is unused."""
        self._env = env

    def settings(self) -> dict[str, Any]:
        """The rule's version: what a results record keys this agent by."""
        return {"rule": self.RULE}

    # --- the rule ----------------------------------------------------------------------------
    def intent(self) -> tuple[float, float, float]:
        """The wanted control for the next step: (airspeed [m/s], total turn [rad], path angle [rad])."""
        base: Any = self._require_env().unwrapped
        pn, pe, chi, h = (float(v) for v in np.asarray(base.state, dtype=np.float64)[:4])
        t = float(getattr(base, "time", 0.0))
        v_slow = float(base.model.library.table[:, COL_AIRSPEED].min())
        w_here = float(base.scenario.field.updraft(pn, pe, h, t))
        if w_here >= self.lift_threshold and self.climb_useful():
            return v_slow, self._circle_side(pn, pe, chi, h, t) * 2.0 * math.pi, 0.0
        return self.cruise()

    def climb_useful(self) -> bool:
        """Whether gaining height is still worth a circle: below ``ceiling`` of the boundary-layer
        depth and 150 m under the domain top, and (with a goal) outside the goal region and lower
        than the height from which the cruise glides to the region's top (at the speed to fly in
        the wind; on the primitives, which glide no shallower than -15 deg, level): height beyond it
        is lost again before the goal."""
        base: Any = self._require_env().unwrapped
        sc = base.scenario
        pn, pe, _, h = (float(v) for v in np.asarray(base.state, dtype=np.float64)[:4])
        if h >= self.ceiling * sc.field.zi or h >= sc.bounds.height_max - 150.0:
            return False
        goal = sc.goal
        if goal is None:
            return True
        dist = math.hypot(goal.north - pn, goal.east - pe)
        if dist <= goal.radius:
            return False
        if isinstance(self._require_env().action_space, gym.spaces.Discrete):
            slope = 0.0
        else:  # the cruise's glide: its speed to fly in the wind on the goal's bearing
            slope = self._speed_to_fly(base.model, math.atan2(goal.east - pe, goal.north - pn))[2]
        return h < goal.height + ARRIVE * goal.radius + slope * (dist - goal.radius)

    def cruise(self) -> tuple[float, float, float]:
        """The control away from lift: (airspeed [m/s], total turn [rad], path angle [rad]) towards
        the goal (see the class docstring), or the search glide without a goal."""
        base: Any = self._require_env().unwrapped
        sc = base.scenario
        model = base.model
        pn, pe, chi, h = (float(v) for v in np.asarray(base.state, dtype=np.float64)[:4])
        ts = self._step_duration()
        goal = sc.goal
        if goal is None:
            v, glide = flattest_glide(model)
            # search within search_radius of the start (where the task's thermals are): beyond it, turn back
            dn, de = sc.start[0] - pn, sc.start[1] - pe
            turn = 0.0
            if math.hypot(dn, de) > self.search_radius:
                err = _wrap(math.atan2(de, dn) - chi)
                turn = max(-math.pi, min(math.pi, err))
            return v, turn, (0.0 if h < 120.0 else glide)
        primitives = isinstance(self._require_env().action_space, gym.spaces.Discrete)
        dist = math.hypot(goal.north - pn, goal.east - pe)
        bearing = math.atan2(goal.east - pe, goal.north - pn)
        v, glide, slope = self._speed_to_fly(model, bearing)
        if primitives and dist < v * ts + goal.radius:
            # the last step: the slowest primitives turn tightest and drop least
            v, glide, slope = self._speed_to_fly(model, bearing, slowest=True)
        r = goal.radius

        def run_to(aim: float) -> float:  # ground distance to where the region's sphere is at height aim
            return max(dist - math.sqrt(max(r * r - (aim - goal.height) ** 2, 0.0)), 1.0)

        low, high = goal.height - ARRIVE * r, goal.height + ARRIVE * r
        if h - slope * run_to(low) >= low:  # a zero-thrust glide reaches the region: glide, steeper if too high
            gamma = min(glide, math.atan2(high - h, run_to(high)))
        else:  # the motor must help: arrive as low as the region allows
            gamma = math.atan2(low - h, run_to(low))
        if primitives and dist >= v * ts:
            # no shallow glides among the primitives: lose a surplus over the region's top at -15 deg as
            # early as it allows (a descent covers ground without the motor), else fly level
            gamma = -PRIMITIVE_DESCENT if h - high >= v * ts * math.sin(PRIMITIVE_DESCENT) else max(gamma, 0.0)
        elif primitives and abs(h - goal.height) < 0.95 * r:
            gamma = 0.0  # the last step: the arc through the goal's centre enters the region level
        if primitives:
            gamma = max(-PRIMITIVE_DESCENT, min(PRIMITIVE_DESCENT, gamma))
        if getattr(base, "has_battery", False):
            gamma = min(gamma, 0.0)  # on a battery: no powered climbs
        return v, self._turn_to_goal(pn, pe, chi, v * ts, ts), gamma

    def _speed_to_fly(self, model: Any, bearing: float, slowest: bool = False) -> tuple[float, float, float]:
        """(airspeed [m/s], zero-thrust glide angle [rad], height lost per ground metre) of the
        airspeed that loses least height per metre over the ground on ``bearing`` [rad] in the
        wind (a pilot's speed to fly in still air, without a climb rate to wait for): among the
        envelope's straight glides (:meth:`~soaring_env.model.SoaringModel.straight_glides`), or
        on the primitives among their airspeeds (:func:`~soaring_env.physics.glide_height_loss`;
        inf per metre where none makes headway); ``slowest``: the slowest of them."""
        sc = cast(Any, self._require_env().unwrapped).scenario
        if isinstance(self._require_env().action_space, gym.spaces.Discrete):
            speeds = np.unique(model.library.table[:, COL_AIRSPEED])
            glides = model.aircraft.glide_angle(speeds, 0.0, sc.bounds.height_max)
        else:
            speeds, glides = model.straight_glides(21)
        wn, we = sc.field.wind_north, sc.field.wind_east
        along, cross = wn * math.cos(bearing) + we * math.sin(bearing), we * math.cos(bearing) - wn * math.sin(bearing)
        per_metre = glide_height_loss(1.0, speeds, glides, along, cross)
        k = 0 if slowest else int(np.argmin(per_metre))
        return float(speeds[k]), float(glides[k]), float(per_metre[k])

    def _turn_to_goal(self, pn: float, pe: float, chi: float, length: float, ts: float) -> float:
        """Total turn [rad] of the next step (an arc of ``length`` [m] through the air over ``ts``
        [s], the wind's drift added): the one of :data:`TURN_GRID` whose end lies nearest the goal,
        each radian still to turn there counting as the arc of a half circle a step (``length / pi``
        metres); within one step of the goal, the pursuit arc through it (twice the bearing error)."""
        sc = cast(Any, self._require_env().unwrapped).scenario
        goal = sc.goal
        dn, de = goal.north - pn, goal.east - pe
        err = _wrap(math.atan2(de, dn) - chi)
        if math.hypot(dn, de) < length:
            return max(-math.pi, min(math.pi, 2.0 * err))
        th = TURN_GRID
        straight = np.abs(th) < 1e-9
        k = np.where(straight, 1.0, th)
        ahead = np.where(straight, length, length / k * np.sin(th))
        right = np.where(straight, 0.0, length / k * (1.0 - np.cos(th)))
        en = pn + ahead * math.cos(chi) - right * math.sin(chi) + sc.field.wind_north * ts
        ee = pe + ahead * math.sin(chi) + right * math.cos(chi) + sc.field.wind_east * ts
        left = np.abs((np.arctan2(goal.east - ee, goal.north - en) - (chi + th) + math.pi) % (2.0 * math.pi) - math.pi)
        return float(th[int(np.argmin(np.hypot(goal.north - en, goal.east - ee) + length / math.pi * left))])

    def _circle_side(self, pn: float, pe: float, chi: float, h: float, t: float) -> float:
        """+1 to circle right, -1 left: towards the probe that measures more lift."""
        field = cast(Any, self._require_env().unwrapped).scenario.field
        # Right of the course chi (clockwise from north) is chi + 90 deg: (-sin chi, cos chi).
        right = float(field.updraft(pn - self.probe * math.sin(chi), pe + self.probe * math.cos(chi), h, t))
        left = float(field.updraft(pn + self.probe * math.sin(chi), pe - self.probe * math.cos(chi), h, t))
        return 1.0 if right >= left else -1.0  # chi_dot > 0 turns right (clockwise seen from above)

    def predict(
        self, observation: Any, state: Any = None, episode_start: Any = None, deterministic: bool = True
    ) -> tuple[Any, None]:
        """The action for the current env state (``observation`` is not needed: the rule reads the
        aircraft's own measurements from ``env.unwrapped``)."""
        env = self._require_env()
        v, turn, gamma = self.intent()
        space = env.action_space
        model = cast(Any, env.unwrapped).model
        if isinstance(space, gym.spaces.Discrete):
            return np.int64(self._nearest_primitive(model, v, turn, gamma, action_mask_of(env))), None
        ts = self._step_duration()
        lo, hi = model.control_low, model.control_high
        control = np.clip(np.array([v, turn / ts, gamma]), lo, hi)
        return np.clip(model.control_to_action(control), -1.0, 1.0).astype(np.float32), None

    @staticmethod
    def _nearest_primitive(model: Any, v: float, turn: float, gamma: float, mask: np.ndarray | None) -> int:
        """The primitive closest to (airspeed, total turn, path angle) in a weighted distance."""
        tab = model.library.table
        ts = model.library.duration
        total_turn = 0.5 * (tab[:, COL_CHI_DOT_1] + tab[:, COL_CHI_DOT_2]) * ts
        d = (
            ((tab[:, COL_AIRSPEED] - v) / 10.0) ** 2
            + ((total_turn - turn) / math.radians(30.0)) ** 2
            + ((tab[:, COL_GAMMA] - gamma) / math.radians(15.0)) ** 2
        )
        # A circle in lift must be a spiral (curves and splines turn at most 90 deg in total).
        if abs(turn) >= 1.5 * math.pi:
            d = d + 1e6 * (tab[:, COL_FAMILY] != SPIRAL)
        if mask is not None:
            d = np.where(mask, d, np.inf)
        return int(np.argmin(d))

    def _step_duration(self) -> float:
        """Seconds one env step holds an action: Ts of the env's primitive library (both envs)."""
        base: Any = self._require_env().unwrapped
        return float(base.model.library.duration)

    def _require_env(self) -> gym.Env:
        if self._env is None:
            raise RuntimeError(f"{type(self).__name__}.predict called before reset(env, seed)")
        return self._env


#: Largest distance [m] between the fitted thermal centre and the lift-weighted centroid that the
#: thermalling agent trusts: a fit beyond it (few samples, all on one side) falls back to the centroid.
FIT_MAX_JUMP = 80.0


def fit_gaussian_thermal(
    north: np.ndarray, east: np.ndarray, lift: np.ndarray, start: tuple[float, float], radius: float
) -> tuple[float, float, float, float] | None:
    """Least-squares fit of a Gaussian thermal ``w = W exp(-d^2 / R^2)`` (d: distance from its centre)
    to lift samples (Levenberg-Marquardt, at most 100 iterations, from ``start`` and ``radius``).

    :param north, east: sample positions [m]; :param lift: updraft there [m/s].
    :param start: first guess of the centre (north, east) [m]; :param radius: first guess of R [m].
    :returns: (W [m/s], centre north [m], centre east [m], R [m], R kept in [15, 300]), or None when
        the fit does not give a finite centre with W > 0.
    :raises ConfigError: samples of unequal length or fewer than 3, a non-finite value, radius <= 0.

    Samples on one circle fix only the lift's amplitude on it, its direction and ``D / R^2`` (D: the
    centre's distance from the circle's), not D itself; an orbit that walks (and the edge that
    entered it) samples enough more to recover the thermal (tested).
    """
    try:
        x, y, w = (np.asarray(a, dtype=np.float64).ravel() for a in (north, east, lift))
        p = np.array([0.0, float(start[0]), float(start[1]), float(radius)])
    except (TypeError, ValueError, IndexError) as err:
        raise ConfigError(f"fit_gaussian_thermal: samples and start must be numbers ({err})") from None
    if not (len(x) == len(y) == len(w) >= 3):
        raise ConfigError(f"north, east, lift must hold as many samples, at least 3; got {len(x)}, {len(y)}, {len(w)}")
    if not (np.isfinite(x).all() and np.isfinite(y).all() and np.isfinite(w).all() and np.isfinite(p).all()):
        raise ConfigError("north, east, lift and start must be finite")
    check_positive("radius", radius)
    p[0] = max(float(w.max()), 0.1)

    def residual(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        e = np.exp(-((x - q[1]) ** 2 + (y - q[2]) ** 2) / q[3] ** 2)
        return q[0] * e - w, e

    r, e = residual(p)
    cost, lam = float(r @ r), 1e-2
    for _ in range(100):
        if lam > 1e8 or cost < 1e-20:  # no step helps any more, or an exact fit
            break
        dx, dy = x - p[1], y - p[2]
        g = 2.0 * p[0] * e / p[3] ** 2
        jac = np.stack([e, g * dx, g * dy, g * (dx * dx + dy * dy) / p[3]], axis=1)
        a = jac.T @ jac
        try:
            step = np.linalg.solve(a + lam * np.diag(np.diag(a) + 1e-9), -(jac.T @ r))
        except np.linalg.LinAlgError:
            break
        q = p + step
        q[3] = min(max(q[3], 15.0), 300.0)
        rq, eq = residual(q)
        cq = float(rq @ rq)
        if cq < cost:  # accept, trust the linear model more
            p, r, e, cost, lam = q, rq, eq, cq, lam * 0.3
        else:
            lam *= 10.0
    if not (p[0] > 0.0 and math.isfinite(p[1]) and math.isfinite(p[2])):
        return None
    return float(p[0]), float(p[1]), float(p[2]), float(p[3])


#: Mean course rate [rad/s] over the last edge (a circle in 21 s) from which :class:`ThermallingAgent`
#: takes the way round it circles from the flown path: only a policy it shadows turns that hard the
#: other way (its own orbit turns its own way round, and its search turns less before it enters).
ADOPT_RATE = 0.3

#: :class:`ThermallingAgent`'s ``search``: where the search spiral's phase comes from.
SEARCH_RULES = ("spiral", "arm", "time")
#: :class:`ThermallingAgent`'s ``entry``: which lift samples decide entering a thermal.
ENTRY_RULES = ("edge", "now")


class ThermallingAgent(HeuristicAgent):
    """A thermalling autopilot on sensed lift alone: a variometer log along its own path, a thermal
    model fitted to it, and an orbit that keeps its circle on the fitted centre.

    It knows nothing of the thermal field but what it measured where it flew: at every decision it
    logs the updraft at each of the last edge's N event points, at the time it passed them (what a
    netto variometer with GPS records), plus its own position, course, height and the wind (as an
    autopilot estimates it). It never reads the field elsewhere, nor the observation's thermal slots.
    Each decision:

    1. **Enter** -- cruising (:meth:`HeuristicAgent.cruise`: towards the goal, or the search glide),
       when the lift logged along the last edge, averaged over ``entry_samples`` consecutive samples
       (a noisy variometer's single peaks are no thermal), peaked at ``enter_lift`` or more and a climb is useful
       (:meth:`climb_useful`), and not within ``tabu_radius`` of a thermal it left less than
       ``tabu_time`` ago: start circling, towards the side where the last edge's lift grew. Where the
       last edge already turned at :data:`ADOPT_RATE` or more, the circle goes that way round, and
       keeps to the way the aircraft turns while circling: flying itself that is always its own way,
       but shadowing a policy (a DAgger round) it continues the policy's circle instead of reversing it.
    2. **Centre** -- a Gaussian thermal ``W exp(-d^2 / R^2)`` is fitted to the points logged in the last
       ``centre_window`` seconds (:func:`fit_gaussian_thermal`; the thermal model of ArduSoar, Tabor,
       Guilliard & Kassab, IROS 2018, fitted by least squares over a window instead of their EKF),
       started from the last estimate or the lift-weighted centroid of the window (Allen & Lin 2007,
       "Guidance and control of an autonomous soaring UAV", AIAA 2007-867; weights: lift above the
       window's least). The fit can place the centre outside the flown circle, which the centroid
       cannot; where it strays more than :data:`FIT_MAX_JUMP` from the centroid, the centroid is used.
    3. **Orbit** -- circle at the tightest turn the envelope allows within ``radius`` (the slowest
       airspeed whose circle fits, else the tightest circle), at the zero-thrust glide angle of that
       turn. Each step's turn rate is chosen (21 rates from straight to the circling rate, the same
       way round) so that the circle flown after the step, wind drift included, is centred nearest
       the estimate: the circle walks onto the core instead of the estimate following the aircraft.
    4. **Leave** -- after at least ``min_circle`` seconds of circling, when the mean lift over the last
       ``exit_window`` seconds is below ``exit_lift``; or when a climb stops being useful. The estimate
       is remembered as tabu.

    Without a goal (the thermal climb) it searches along an Archimedean spiral about the start,
    ``search_spacing`` metres between turns (out to ``search_radius``, then inwards again), at the
    flattest zero-thrust glide (level below 120 m), steering by pure pursuit at a point two steps
    ahead on the spiral (aiming one step ahead made it zigzag). With ``search="spiral"`` (default)
    the spiral keeps its own phase, which advances only as the aircraft reaches the target point and
    pauses while it circles; with ``search="arm"`` the phase is that of the spiral arm through the
    aircraft's own position, so the search command is a function of where the aircraft is and
    heads (what a policy that observes its position can imitate), but between two arms it jumps
    from one to the other; with ``search="time"`` it circles the start clockwise at the radius the
    spiral would have reached by now (:meth:`_time_search_turn`), a smooth function of the start's
    offset, the course and the time left, all in the sensed tier's observation.

    On the discrete env the nearest allowed primitive is flown (as :class:`HeuristicAgent`).

    The defaults were chosen on validation climb scenarios ``climb-5000 ... climb-5199`` with
    ``soaring/ThermalClimbContinuous-v0`` (docs/learning-to-soar.md, "A thermalling controller that
    climbs"); :attr:`RULE` names this version of the rule, and :meth:`settings` (the rule and every
    setting) keys its results records.

    :param enter_lift: updraft [m/s] along the last edge that starts circling.
    :param exit_lift: mean updraft [m/s] over ``exit_window`` below which it leaves.
    :param exit_window: seconds of log that decide leaving (at least one step is used).
    :param centre_window: seconds of log the thermal fit uses (at least one step).
    :param radius: largest orbit radius [m] wanted (at least the tightest turn the envelope allows).
    :param min_circle: seconds of circling before the lift may decide to leave.
    :param entry_samples: consecutive lift samples averaged for the entry test (1: the single peak).
    :param sensor_noise: standard deviation [m/s] of Gaussian noise added to every logged lift sample
        (a variometer's), drawn from a generator seeded by ``reset``'s seed; 0 (default): exact. With
        0.1 m/s the defaults still climb on validation scenarios; with 0.3 m/s they enter on noise, and
        ``enter_lift=0.4, entry_samples=5`` is needed (docs/learning-to-soar.md).
    :param tabu_radius: distance [m] to a left thermal within which it does not enter again.
    :param tabu_time: how long [s] a left thermal stays tabu.
    :param search_spacing: distance [m] between the search spiral's turns.
    :param search: ``"spiral"`` (default), ``"arm"`` or ``"time"``: where the search spiral's phase
        (or, ``"time"``, its radius) comes from.
    :param entry: ``"edge"`` (default): the smoothed samples of the whole last edge decide entering;
        ``"now"``: the lift at the aircraft alone, the sensed tier's ``updraft`` entry (what a policy
        that sees only the observation can imitate).
    :param ceiling, search_radius: as :class:`HeuristicAgent`.
    :param name: label in results.
    """

    #: The rule's version, recorded with every result it flies (a changed rule flies again).
    RULE = "sensed-v3"

    def __init__(
        self,
        *,
        search_spacing: float = 150.0,
        enter_lift: float = 0.2,
        exit_lift: float = 0.2,
        exit_window: float = 30.0,
        centre_window: float = 40.0,
        radius: float = 25.0,
        min_circle: float = 30.0,
        entry_samples: int = 3,
        sensor_noise: float = 0.0,
        tabu_radius: float = 250.0,
        tabu_time: float = 300.0,
        ceiling: float = 0.75,
        search_radius: float = 1000.0,
        search: str = "spiral",
        entry: str = "edge",
        name: str = "thermalling",
    ) -> None:
        super().__init__(lift_threshold=enter_lift, ceiling=ceiling, search_radius=search_radius, name=name)
        self.enter_lift = check_finite("enter_lift", enter_lift)
        self.exit_lift = check_range("exit_lift", exit_lift, -math.inf, self.enter_lift)
        self.exit_window = check_positive("exit_window", exit_window)
        self.centre_window = check_positive("centre_window", centre_window)
        self.radius = check_positive("radius", radius)
        self.min_circle = check_range("min_circle", min_circle, 0.0, 1e6)
        self.entry_samples = check_int("entry_samples", entry_samples, 1)
        self.sensor_noise = check_range("sensor_noise", sensor_noise, 0.0, 10.0)
        self._noise = np.random.default_rng(0)
        self.tabu_radius = check_range("tabu_radius", tabu_radius, 0.0, 1e6)
        self.tabu_time = check_range("tabu_time", tabu_time, 0.0, 1e7)
        self.search_spacing = check_range("search_spacing", search_spacing, 1.0, 1e5)
        check_type("search", search, str)
        self.search = check_choice("search", search, SEARCH_RULES)
        check_type("entry", entry, str)
        self.entry = check_choice("entry", entry, ENTRY_RULES)
        self._reset_memory()

    def settings(self) -> dict[str, Any]:
        """The rule's version, the cruise's (:attr:`HeuristicAgent.RULE`) and every setting: what a
        results record keys this agent by."""
        names = ("enter_lift", "exit_lift", "exit_window", "centre_window", "radius", "min_circle", "entry_samples")
        more = ("sensor_noise", "tabu_radius", "tabu_time", "search_spacing", "ceiling", "search_radius")
        extra = {"search": self.search} if self.search != "spiral" else {}  # older records stay current
        extra |= {"entry": self.entry} if self.entry != "edge" else {}
        # the cruise towards a goal is HeuristicAgent's: its version keys the goal tasks' records too
        own = {n: getattr(self, n) for n in names + more}
        return {"rule": self.RULE, "cruise": HeuristicAgent.RULE, **own, **extra}

    def _reset_memory(self) -> None:
        self._log: list[tuple[float, float, float, float]] = []  # (north, east, time, lift) since entering
        self._circling = False
        self._side = 1.0
        self._entered = 0.0  # when it started circling [s]
        self._estimate: tuple[float, float] | None = None  # the last fitted centre (north, east) [m]
        self._tabu: list[tuple[float, float, float]] = []  # (north, east, time left)
        self._logged_steps = -1
        self._phi = 0.0  # the search spiral's angle [rad] (r = spacing phi / 2 pi)

    def reset(self, env: gym.Env, seed: int | None = None) -> None:
        """Remember ``env`` and forget the last episode's log; ``seed`` seeds the sensor noise (None: 0)."""
        super().reset(env, seed)
        self._reset_memory()
        self._noise = np.random.default_rng(0 if seed is None else seed)

    def _smoothed(self, edge: list[tuple[float, float, float, float]]) -> np.ndarray:
        """The edge's lift samples as a moving average over ``entry_samples`` of them (fewer on a short
        edge); with ``entry="now"`` only the last one, the lift at the aircraft."""
        w = np.array([x[3] for x in edge], dtype=np.float64)
        if self.entry == "now":
            return w[-1:]
        k = min(self.entry_samples, len(w))
        return np.convolve(w, np.full(k, 1.0 / k), mode="valid")

    def _last_edge(self) -> list[tuple[float, float, float, float]]:
        """(north, east, time, lift) at the last edge's flown points (none before the first step),
        with ``sensor_noise`` added."""
        base: Any = self._require_env().unwrapped
        steps = int(getattr(base, "steps", 0))
        if steps == 0 or steps == self._logged_steps:
            return []
        self._logged_steps = steps
        lib = base.model.library
        n = int(lib.n_points)
        pts = np.asarray(base.path, dtype=np.float64)[-n:]
        dt = float(lib.duration) / n
        t_end = float(base.time)
        field = base.scenario.field
        times = t_end - dt * np.arange(len(pts) - 1, -1, -1, dtype=np.float64)
        lift = field.updraft(pts[:, 0], pts[:, 1], pts[:, 3], times)
        lift = np.atleast_1d(lift)
        if self.sensor_noise > 0.0:
            lift = lift + self.sensor_noise * self._noise.standard_normal(len(lift))
        return [(float(p[0]), float(p[1]), float(t), float(w)) for p, t, w in zip(pts, times, lift, strict=True)]

    def _edge_turn(self) -> float:
        """Course change [rad] over the last edge flown (positive: right), from the env's flown points."""
        base: Any = self._require_env().unwrapped
        n = int(base.model.library.n_points)
        chi = np.asarray(base.path, dtype=np.float64)[-n - 1 :, 2]
        return float(np.sum((np.diff(chi) + math.pi) % (2.0 * math.pi) - math.pi))

    def centre(self) -> tuple[float, float] | None:
        """The thermal centre (north, east) [m] fitted to the recent log (see the class docstring), or None."""
        if not self._log:
            return None
        log = np.asarray(self._log, dtype=np.float64)
        log = log[log[:, 2] >= log[-1, 2] - max(self.centre_window, self._step_duration())]
        w = log[:, 3] - log[:, 3].min()
        if w.sum() <= 0.0:  # no lift gradient in the window: keep what was known
            return self._estimate
        centroid = float(w @ log[:, 0] / w.sum()), float(w @ log[:, 1] / w.sum())
        fit = fit_gaussian_thermal(log[:, 0], log[:, 1], log[:, 3], self._estimate or centroid, 60.0)
        if fit is None or math.hypot(fit[1] - centroid[0], fit[2] - centroid[1]) > FIT_MAX_JUMP:
            self._estimate = centroid
        else:
            self._estimate = fit[1], fit[2]
        return self._estimate

    def climb_useful(self) -> bool:
        """:meth:`HeuristicAgent.climb_useful`, and with a goal and a time limit: enough time left to
        fly to the goal at the slowest airspeed (the cruise's near the goal) in the wind, with half as
        much again to spare (a climb that ends the episode short of the goal is worth nothing)."""
        if not super().climb_useful():
            return False
        base: Any = self._require_env().unwrapped
        goal, limit = base.scenario.goal, getattr(base, "episode_steps", None)
        if goal is None or limit is None:
            return True
        pn, pe = (float(v) for v in np.asarray(base.state, dtype=np.float64)[:2])
        ts = self._step_duration()
        dn, de = goal.north - pn, goal.east - pe
        dist = math.hypot(dn, de)
        field = base.scenario.field
        # closing speed: the slowest airspeed (the cruise flies at least as fast) plus the wind along the way
        along = (field.wind_north * dn + field.wind_east * de) / max(dist, 1e-9)
        closing = max(float(base.model.library.table[:, COL_AIRSPEED].min()) + along, 1.0)
        need = 1.5 * max(dist - goal.radius, 0.0) / closing + 2.0 * ts
        return (limit - int(base.steps)) * ts >= need

    def intent(self) -> tuple[float, float, float]:
        base: Any = self._require_env().unwrapped
        model = base.model
        pn, pe, chi = (float(v) for v in np.asarray(base.state, dtype=np.float64)[:3])
        t = float(base.time)
        edge = self._last_edge()
        self._tabu = [(n, e, until) for n, e, until in self._tabu if until > t]
        turned = self._edge_turn() if edge else 0.0  # [rad]
        # the way round the aircraft circles, where it does: its own, or a shadowed policy's
        way = math.copysign(1.0, turned) if abs(turned) >= ADOPT_RATE * self._step_duration() else None
        if self._circling:
            self._log.extend(edge)
            self._side = way or self._side
            recent = [w for (_, _, tw, w) in self._log if tw >= t - max(self.exit_window, self._step_duration())]
            weak = t - self._entered >= self.min_circle and recent and float(np.mean(recent)) < self.exit_lift
            if not self.climb_useful() or weak:
                c = self.centre() or (pn, pe)
                self._tabu.append((c[0], c[1], t + self.tabu_time))
                self._circling = False
                self._log = []
                self._estimate = None
        elif edge and (smooth := self._smoothed(edge)).max() >= self.enter_lift and self.climb_useful():
            if all(math.hypot(pn - n, pe - e) > self.tabu_radius for n, e, _ in self._tabu):
                self._circling = True
                self._entered = t
                self._log = list(edge)
                # turn towards where the lift grew along the last edge: its side of the course
                k = int(np.argmax(smooth)) + (len(edge) - len(smooth)) // 2  # the average's middle sample
                dn, de = edge[k][0] - edge[0][0], edge[k][1] - edge[0][1]
                cross = math.cos(chi) * de - math.sin(chi) * dn  # > 0: the strongest point lies right
                self._side = way or (1.0 if cross >= 0.0 else -1.0)
        if not self._circling:
            return self.cruise()
        return self._orbit(model, pn, pe, chi)

    def cruise(self) -> tuple[float, float, float]:
        """Towards the goal as :class:`HeuristicAgent`; without one, along the search spiral."""
        base: Any = self._require_env().unwrapped
        sc = base.scenario
        if sc.goal is not None:
            return super().cruise()
        model = base.model
        pn, pe, chi, h = (float(v) for v in np.asarray(base.state, dtype=np.float64)[:4])
        v, glide = flattest_glide(model)
        if self.search == "time":
            return v, self._time_search_turn(pn, pe, chi, float(base.time), v), (0.0 if h < 120.0 else glide)
        ahead = 2.0 * v * self._step_duration()
        # the spiral's radius grows out to search_radius, then shrinks again (a triangle wave in phi)
        period = 2.0 * math.pi * self.search_radius / self.search_spacing

        def point(phi: float) -> tuple[float, float]:
            m = phi % (2.0 * period)
            r = self.search_spacing * min(m, 2.0 * period - m) / (2.0 * math.pi)
            return sc.start[0] + r * math.cos(phi + sc.start[2]), sc.start[1] + r * math.sin(phi + sc.start[2])

        if self.search == "arm":  # the phase of the arm through the aircraft (the growing branch)
            theta = (math.atan2(pe - sc.start[1], pn - sc.start[0]) - sc.start[2]) % (2.0 * math.pi)
            turns = 2.0 * math.pi * math.hypot(pn - sc.start[0], pe - sc.start[1]) / self.search_spacing
            k = max(0, round((turns - theta) / (2.0 * math.pi)))
            while k > 0 and theta + 2.0 * math.pi * k > period:
                k -= 1
            self._phi = theta + 2.0 * math.pi * k
        for _ in range(10_000):  # advance the target until it lies two steps ahead
            tn, te = point(self._phi)
            if math.hypot(tn - pn, te - pe) >= ahead:
                break
            self._phi += 0.02
        # pure pursuit: the arc tangent to the course through the target turns by twice the bearing
        # error over its two steps, so one step turns by the bearing error
        turn = max(-math.pi, min(math.pi, _wrap(math.atan2(te - pe, tn - pn) - chi)))
        return v, turn, (0.0 if h < 120.0 else glide)

    def _time_search_turn(self, pn: float, pe: float, chi: float, t: float, v: float) -> float:
        """``search="time"``: the turn [rad] of one step round the start clockwise at the radius an
        Archimedean spiral of ``search_spacing`` flown at ``v`` [m/s] reaches after ``t`` seconds
        (the area flown equals the area swept: r = sqrt(spacing v t / pi), at most ``search_radius``),
        steering out or in by atan((r - r_t) / spacing): a smooth function of the start's offset, the
        course and the time."""
        sc = cast(Any, self._require_env().unwrapped).scenario
        dn, de = pn - sc.start[0], pe - sc.start[1]
        r_t = min(math.sqrt(self.search_spacing * v * t / math.pi), self.search_radius)
        out = math.atan2(de, dn)  # the bearing of the aircraft seen from the start
        want = out + 0.5 * math.pi + math.atan((math.hypot(dn, de) - r_t) / self.search_spacing)
        return max(-math.pi, min(math.pi, _wrap(want - chi)))

    def _orbit(self, model: Any, pn: float, pe: float, chi: float) -> tuple[float, float, float]:
        """(airspeed, total turn, path angle) of the next step in the thermal (class docstring, 3)."""
        ts = self._step_duration()
        top = float(model.scenario.bounds.height_max)
        lo = max(float(model.control_low[0]), float(model.library.table[:, COL_AIRSPEED].min())) + 0.5
        speeds = np.linspace(lo, max(lo, float(model.control_high[0])), 27)
        # the tightest circle at each airspeed: bank <= 45 deg and the stall limit, and the envelope's turn rate
        bank = np.minimum(math.radians(45.0), model.aircraft.max_bank(speeds, top))
        with np.errstate(divide="ignore"):
            r_min = np.where(bank > 0.0, speeds**2 / (9.80665 * np.tan(np.maximum(bank, 1e-9))), np.inf)
        chi_dot_max = float(model.control_high[1])
        if math.isfinite(chi_dot_max) and chi_dot_max > 0.0:
            r_min = np.maximum(r_min, speeds / chi_dot_max)
        fits = np.flatnonzero(r_min <= self.radius)
        i = int(fits[0]) if fits.size else int(np.argmin(r_min))  # the slowest that fits, else the tightest
        v = float(speeds[i])
        r = max(self.radius, float(r_min[i])) * 1.001  # a hair wider: the rate stays inside the envelope
        rate = self._side * v / r  # the circling turn rate [rad/s]
        c = self.centre()
        if c is not None:
            wn, we = float(model.scenario.field.wind_north), float(model.scenario.field.wind_east)
            om = np.linspace(0.0, rate, 21)
            straight = np.abs(om) < 1e-9
            safe = np.where(straight, 1.0, om)
            # where one step at each rate leaves the aircraft (an arc of constant rate, plus the drift)
            dn = np.where(straight, v * ts * math.cos(chi), v / safe * (np.sin(chi + om * ts) - math.sin(chi)))
            de = np.where(straight, v * ts * math.sin(chi), -v / safe * (np.cos(chi + om * ts) - math.cos(chi)))
            course = chi + om * ts
            # the centre of the circle flown from there (right turn: the centre lies to the right)
            cn = pn + dn + wn * ts - self._side * r * np.sin(course)
            ce = pe + de + we * ts + self._side * r * np.cos(course)
            rate = float(om[int(np.argmin(np.hypot(cn - c[0], ce - c[1])))])
        gamma = float(model.aircraft.glide_angle(v, rate, top))
        return v, rate * ts, gamma


class ReplayAgent:
    """Fly a fixed sequence of env actions (a plan, e.g. the reference search's), one per step.

    :param actions: the env actions in order.
    :param name: label in results.
    """

    def __init__(self, actions: Any, *, name: str = "replay") -> None:
        self.name = name
        self._actions = list(actions)
        self._i = 0

    def reset(self, env: gym.Env, seed: int | None = None) -> None:
        """Start the plan from its first action (``env`` must be reset to the plan's start)."""
        self._i = 0

    def predict(
        self, observation: Any, state: Any = None, episode_start: Any = None, deterministic: bool = True
    ) -> tuple[Any, None]:
        """The plan's next action; a RuntimeError once the plan is used up (the episode outlived it)."""
        if self._i >= len(self._actions):
            raise RuntimeError(f"{self.name}: the plan of {len(self._actions)} actions is used up, the episode goes on")
        a = self._actions[self._i]
        self._i += 1
        return a, None


class PPOAgent:
    """A trained stable-baselines3 (or sb3-contrib ``MaskablePPO``) policy behind the agent interface.

    :param path: the run directory written by :func:`baselines.ppo.train` (holding ``model.zip`` and
        ``config.json``), or the ``.zip`` itself with ``config.json`` beside it.
    :param deterministic: act with the policy's mode (default) rather than sampling.
    :param name: label in results; default ``"ppo-<algo>"`` from the configuration.
    """

    def __init__(self, path: str | Path, *, deterministic: bool = True, name: str | None = None) -> None:
        p = Path(path)
        run_dir = p.parent if p.suffix == ".zip" else p
        zip_path = p if p.suffix == ".zip" else p / "model.zip"
        cfg_path = run_dir / "config.json"
        if not zip_path.is_file():
            raise FileNotFoundError(f"no trained model at {zip_path}; train one with scripts/train_ppo.py")
        if not cfg_path.is_file():
            raise FileNotFoundError(f"no config.json beside {zip_path}; a model is loaded with its configuration")
        self.config: dict[str, Any] = json.loads(cfg_path.read_text())
        self.algo: str = self.config["algo"]
        self.env_id: str = self.config["env_id"]
        self.name = name or f"ppo-{self.algo}"
        self.deterministic = deterministic
        self.model_path = zip_path
        from baselines.ppo import action_transform, load_model, observation_transform  # lazy: torch

        self.model = load_model(zip_path, self.algo)
        self._obs_fn = observation_transform(self.config)
        self._act_fn = action_transform(self.config)
        self._env: gym.Env | None = None

    def policy_observation(self, observation: Any) -> Any:
        """``observation`` as the policy sees it: after the run's observation transform (e.g. the body frame)."""
        return self._obs_fn(observation) if self._obs_fn is not None else observation

    def reset(self, env: gym.Env, seed: int | None = None) -> None:
        """Remember ``env`` (for its action space and action masks); the policy is deterministic."""
        if env.spec is not None and env.spec.id.split(":")[-1] != self.env_id.split(":")[-1]:
            raise ValueError(f"{self.name} was trained on {self.env_id!r}, not on {env.spec.id!r}")
        self._env = env

    def predict(
        self, observation: Any, state: Any = None, episode_start: Any = None, deterministic: bool | None = None
    ) -> tuple[Any, Any]:
        """The policy's action; masked PPO also passes the env's current action mask."""
        det = self.deterministic if deterministic is None else deterministic
        obs = self.policy_observation(observation)
        kwargs: dict[str, Any] = {}
        if self.algo == "masked":
            if self._env is None:
                raise RuntimeError("PPOAgent.predict for a masked policy needs reset(env, seed) first")
            kwargs["action_masks"] = action_mask_of(self._env)
        action, st = self.model.predict(obs, state=state, episode_start=episode_start, deterministic=det, **kwargs)
        if self._act_fn is not None:
            action = self._act_fn(action)
        if isinstance(self._env, gym.Env) and isinstance(self._env.action_space, gym.spaces.Discrete):
            action = np.int64(np.asarray(action).item())
        return action, st

    def logits(self, observation: Any) -> np.ndarray:
        """The discrete policy's logits over the primitives (one per action) for one env observation,
        after the run's observation transform; a ConfigError for a continuous policy."""
        if self.algo not in ("discrete", "masked"):
            raise ConfigError(f"{self.name}: logits need a discrete policy, not algo={self.algo!r}")
        import torch

        t, _ = self.model.policy.obs_to_tensor(self.policy_observation(observation))
        with torch.no_grad():
            return np.asarray(self.model.policy.get_distribution(t).distribution.logits[0].numpy())


class RolloutAgent:
    """A discrete successor policy (:class:`PPOAgent`, ``policy="successor"``) improved at every
    decision by one-step lookahead in the model its observation shows: Bertsekas' rollout
    algorithm, the policy's mode as base policy (docs/learning-to-soar.md, round twenty-one).

    At each step the policy's ``candidates`` likeliest primitives are each flown in a copy of the
    env whose scenario is rebuilt from the observation alone
    (:meth:`baselines.scoring.SuccessorFeatures.scenario`: goal, wind and the observed thermal
    slots, in the aircraft's frame, the last edge's airspeed carried over), the policy's mode
    flying on to the end; the primitive whose episode reaches the goal within the steps left with
    the least energy is flown (the likelier one on ties, the mode where none does). Nothing beyond
    the observation, the aircraft and the primitives is used: where the observed slots hold every
    thermal (goal reaching with up to 3), the model's episodes are the env's. With one candidate it
    is the policy itself. Deterministic.

    :param path: a discrete successor run, as for :class:`PPOAgent`.
    :param candidates: primitives tried per decision (>= 1; with 8, 42-51 ms a decision on this
        project's 2-core machine, each candidate's episode flown to its end in the model).
    :param name: label in results; default ``"ppo-discrete-rollout"``.
    """

    def __init__(self, path: str | Path, *, candidates: int = 8, name: str | None = None) -> None:
        self.candidates = check_int("candidates", candidates, 1)
        self.policy = PPOAgent(path, name=name or "ppo-discrete-rollout")
        cfg = self.policy.config
        if self.policy.algo != "discrete" or cfg.get("config", {}).get("policy") != "successor":
            raise ConfigError(
                f"{self.policy.model_path}: the rollout agent needs a discrete successor policy "
                f"(--algo discrete --set 'policy=\"successor\"'), not algo={self.policy.algo!r}, "
                f"policy={cfg.get('config', {}).get('policy')!r}"
            )
        self.name = self.policy.name
        self.env_id = self.policy.env_id
        self.features: Any = self.policy.model.policy.mlp_extractor.policy_net.features
        self._inner: gym.Env | None = None  # the model: the same env, on rebuilt scenarios
        self._steps = 0

    def reset(self, env: gym.Env, seed: int | None = None) -> None:
        """Remember ``env``'s settings (the model is the same env with them) and start counting steps."""
        self.policy.reset(env, seed)
        if env.spec is None:
            raise ConfigError(f"{self.name} needs an env made by gym.make (its model is made the same way)")
        if self._inner is None or self._inner.spec != env.spec:
            if self._inner is not None:
                self._inner.close()
            self._inner = gym.make(env.spec)
        self._steps = 0

    def _fly(self, scenario: Any, first: int, airspeed_prev: float | None, steps_left: float) -> float:
        """Energy [J/kg] of ``first`` then the policy's mode in the model from ``scenario``'s start
        (inf: no goal within ``steps_left`` steps)."""
        assert self._inner is not None
        obs, _ = self._inner.reset(seed=0, options={"scenario": scenario, "airspeed_prev": airspeed_prev})
        a, n = first, 0
        while True:
            obs, _, terminated, truncated, info = self._inner.step(a)
            n += 1
            if terminated or truncated or n >= steps_left:
                break
            a = int(np.argmax(self.policy.logits(obs)))
        return float(info["energy_spent"]) if info.get("is_success") else math.inf

    def predict(
        self, observation: Any, state: Any = None, episode_start: Any = None, deterministic: bool = True
    ) -> tuple[Any, None]:
        """The primitive whose episode in the model spends least (see the class docstring)."""
        if self._inner is None:
            raise RuntimeError(f"{self.name}.predict called before reset(env, seed)")
        z = self.policy.logits(observation)
        order = [int(a) for a in np.argsort(-z, kind="stable")[: self.candidates]]  # likeliest first
        best = order[0]
        if len(order) > 1:
            x = np.asarray(self.policy.policy_observation(observation), np.float64).ravel()
            lay = self.features.layout
            v_prev = float(x[lay.airspeed]) * lay.speed_scale  # 0: no edge flown yet
            scenario = self.features.scenario(x)
            limit = self._inner.unwrapped.episode_steps  # type: ignore[attr-defined]
            steps_left = math.inf if limit is None else limit - self._steps
            cost = math.inf
            for a in order:
                c = self._fly(scenario, a, v_prev if v_prev > 0.0 else None, steps_left)
                if c < cost:
                    best, cost = a, c
        self._steps += 1
        return np.int64(best), None


class SSTPlannerAgent:
    """The SST planner (:class:`baselines.sst.SSTAgent`) behind the common interface.

    ``reset(env, seed)`` builds a fresh planner seeded with the episode seed and plans from the
    env's current state (that time is compute time); ``predict`` returns the plan's actions and
    replans when the plan is used up or the state deviates (see :class:`baselines.sst.SSTAgent`).
    The primitive or continuous sampler follows the env's action space.

    :param time_limit: wall-clock budget per planning call [s] (None: iterations only).
    :param max_iterations: iteration budget per planning call (None: time only; with an iteration
        budget alone the plans, and so the evaluation, are deterministic).
    :param name: label in results.
    :param planner: the named planner configuration (``SST_CONFIGS``: ``"seeded"``, ``"soaring"`` or
        ``"paper"``; None: the default, ``"seeded"``).
    """

    def __init__(
        self,
        *,
        time_limit: float | None = 20.0,
        max_iterations: int | None = None,
        name: str = "sst",
        planner: str | None = None,
    ) -> None:
        from baselines.sst.soaring import DEFAULT_SST_CONFIG, SST_CONFIGS

        planner = DEFAULT_SST_CONFIG if planner is None else planner

        if planner not in SST_CONFIGS:
            raise ConfigError(f"planner={planner!r} is unknown; allowed: {', '.join(map(repr, SST_CONFIGS))}")
        self.name = name
        self.time_limit = time_limit
        self.max_iterations = max_iterations
        self.config = SST_CONFIGS[planner]
        self.planner: Any = None

    def reset(self, env: gym.Env, seed: int | None = None) -> None:
        """Plan for the episode that ``env`` (already reset) is in."""
        from baselines.sst import SSTAgent

        self.planner = SSTAgent(
            env, time_limit=self.time_limit, max_iterations=self.max_iterations, seed=int(seed or 0), config=self.config
        )
        self.planner.reset()

    def predict(
        self, observation: Any, state: Any = None, episode_start: Any = None, deterministic: bool = True
    ) -> tuple[Any, None]:
        """The next action of the plan."""
        if self.planner is None:
            raise RuntimeError("SSTPlannerAgent.predict called before reset(env, seed)")
        return self.planner.predict(observation, state, episode_start, deterministic)
