"""The model API shared by the environments and the planners.

:class:`SoaringModel` bundles a scenario, the aircraft, the primitive library and the integration
settings, and rolls out any primitive or control from any batch of states without touching an
environment's state. ``env.step`` calls exactly these methods, so a plan made with the model
replays through the env bit for bit.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from soaring_env._jit import ERROR_MODEL as _EM
from soaring_env._validation import (
    ConfigError,
    as_float_array,
    check_array_finite,
    check_int,
    check_range,
    check_type,
)
from soaring_env.physics.aircraft import Aircraft, bank_angle
from soaring_env.physics.atmosphere import MAX_HEIGHT
from soaring_env.primitives import (
    COL_AIRSPEED,
    COL_CHI_DOT_1,
    COL_CHI_DOT_2,
    COL_GAMMA,
    DEFAULT_MAX_SUBSTEP,
    N_PRIMITIVES,
    ControlEnvelope,
    PrimitiveLibrary,
    Propagator,
    Rollout,
    check_substep,
    rollout,
)
from soaring_env.scenario import Scenario, paper_scenario

#: Edge outcome codes returned by :meth:`SoaringModel.classify`.
FLYING, GOAL, CRASH, OUT_OF_BOUNDS = 0, 1, 2, 3
#: Episode outcome of the cross-country task's envs (never an edge's: the battery is the env's).
BATTERY_EMPTY = 4
#: Episode outcome of the primitive envs with a stall limit: the agent chose a primitive the wing
#: cannot fly (:meth:`SoaringModel.stall_ok`; masked agents never do).
STALL = 5
OUTCOMES = ("flying", "goal", "crash", "out_of_bounds", "battery_empty", "stall")

#: Layout of the classification row (:func:`classify_params`): goal north, east, height, radius [m],
#: domain north min/max, east min/max, height max [m]. Longer rows (the envs') start with it.
N_CLASSIFY_PARAMS = 9


def classify_params(scenario: Scenario) -> np.ndarray:
    """Goal region and domain of ``scenario`` as the float64 row read by :func:`classify_row`."""
    g, bd = scenario.goal, scenario.bounds
    # no goal: a region of radius -1 m, which no point is ever within
    gn, ge, gh, gr = (0.0, 0.0, 0.0, -1.0) if g is None else (g.north, g.east, g.height, g.radius)
    return np.array([gn, ge, gh, gr, bd.north_min, bd.north_max, bd.east_min, bd.east_max, bd.height_max])


@njit(cache=True, error_model=_EM)
def classify_row(s: np.ndarray, b: int, prm: np.ndarray) -> tuple[int, int]:
    """First event along edge ``b`` of ``s`` (B, N, 4): (outcome code, output point index).

    At the first point that is in the goal region (distance <= radius), on or below the ground, or
    outside the domain -- in that priority at one point; ``FLYING`` edges give N - 1. The one
    implementation of the rule: :meth:`SoaringModel.classify` and the envs call it.
    """
    gn, ge, gh, gr = prm[0], prm[1], prm[2], prm[3]
    nmin, nmax, emin, emax, hmax = prm[4], prm[5], prm[6], prm[7], prm[8]
    n_pts = s.shape[1]
    for k in range(n_pts):
        n = s[b, k, 0]
        e = s[b, k, 1]
        h = s[b, k, 3]
        dn = n - gn
        de = e - ge
        dh = h - gh
        if math.sqrt(dn * dn + de * de + dh * dh) <= gr:
            return GOAL, k
        if h <= 0.0:
            return CRASH, k
        if not (n >= nmin and n <= nmax and e >= emin and e <= emax and h <= hmax):
            return OUT_OF_BOUNDS, k
    return FLYING, n_pts - 1


@njit(cache=True, error_model=_EM)
def classify_batch(s: np.ndarray, prm: np.ndarray, codes: np.ndarray, ks: np.ndarray) -> None:
    """:func:`classify_row` for every edge b of ``s`` with its row ``prm[b]``, into ``codes``, ``ks``."""
    for b in range(s.shape[0]):
        c, k = classify_row(s, b, prm[b])
        codes[b] = c
        ks[b] = k


@dataclass(frozen=True)
class SoaringModel:
    """Scenario + aircraft + primitive library: everything needed to propagate and score edges.

    :param scenario: thermal field, wind, start, goal and domain.
    :param aircraft: aircraft and thrust model.
    :param library: the 174 primitives (Ts, N).
    :param max_substep: largest integration substep near thermals [s].
    :param max_bank_deg: bank-angle limit [deg] used by action masks and planners (the tightest
        spiral needs 52 deg at Ts = 30 s).
    :param envelope: the continuous controls actions map onto (default ``None``: the paper's
        envelope of the primitives, :meth:`ControlEnvelope.paper`).

    The domain's ceiling must leave room for one edge below ``MAX_HEIGHT`` (11 km):
    ``bounds.height_max + Ts (fastest climb + the field's updraft bound) < MAX_HEIGHT``. Every edge of
    the env and the planner starts inside the domain, so an edge that climbs past the ceiling ends
    as an ``out_of_bounds`` event and is never integrated above the troposphere.
    """

    scenario: Scenario = dataclasses.field(default_factory=paper_scenario)
    aircraft: Aircraft = dataclasses.field(default_factory=Aircraft)
    library: PrimitiveLibrary = dataclasses.field(default_factory=PrimitiveLibrary)
    max_substep: float = DEFAULT_MAX_SUBSTEP
    max_bank_deg: float = 60.0
    envelope: ControlEnvelope | None = None

    def __post_init__(self) -> None:
        check_type("scenario", self.scenario, Scenario)
        if self.envelope is None:
            object.__setattr__(self, "envelope", ControlEnvelope.paper(self.library))
        check_type("envelope", self.envelope, ControlEnvelope)
        check_type("aircraft", self.aircraft, Aircraft)
        check_type("library", self.library, PrimitiveLibrary)
        object.__setattr__(self, "max_substep", check_substep("max_substep", self.max_substep))
        bank = check_range("max_bank_deg", self.max_bank_deg, 0.0, 90.0, low_open=True, high_open=True)
        object.__setattr__(self, "max_bank_deg", bank)
        hmax = self.scenario.bounds.height_max
        reach = hmax + self.library.duration * (self.library.max_climb_rate + self.scenario.field.updraft_bound)
        if reach >= MAX_HEIGHT:
            raise ConfigError(
                f"bounds.height_max={hmax!r} m is too high for Ts={self.library.duration:g} s: an edge from the "
                f"ceiling could climb to {reach:.6g} m; allowed: ceiling + Ts x (climb rate + updraft bound) "
                f"< {MAX_HEIGHT:g} m"
            )

    # --- propagation -----------------------------------------------------------------------
    def rollout_primitive(self, states, primitive, *, t0=0.0, airspeed_prev=None) -> Rollout:
        """Fly primitive(s) ``primitive`` (int or (B,)) for Ts from ``states`` ((4,) or (B, 4))."""
        return rollout(
            states,
            self.scenario.field,
            self.aircraft,
            primitive=primitive,
            library=self.library,
            t0=t0,
            airspeed_prev=airspeed_prev,
            max_substep=self.max_substep,
        )

    def rollout_control(self, states, control, *, duration=None, t0=0.0, airspeed_prev=None) -> Rollout:
        """Hold physical control(s) ``(v_a [m/s], chi_dot [rad/s], gamma [rad])`` for ``duration``
        (default Ts) from ``states``."""
        return rollout(
            states,
            self.scenario.field,
            self.aircraft,
            control=control,
            library=self.library,
            duration=duration,
            t0=t0,
            airspeed_prev=airspeed_prev,
            max_substep=self.max_substep,
        )

    # --- the continuous action envelope --------------------------------------------------------
    @property
    def control_envelope(self) -> ControlEnvelope:
        """The continuous envelope (``envelope``, resolved)."""
        env = self.envelope
        assert env is not None  # set in __post_init__
        return env

    @property
    def control_low(self) -> np.ndarray:
        """Lower corner of the box holding the continuous envelope (v_a [m/s], chi_dot [rad/s], gamma [rad])."""
        return self.control_envelope.bounds()[0]

    @property
    def control_high(self) -> np.ndarray:
        return self.control_envelope.bounds()[1]

    def straight_glides(self, n: int = 21) -> tuple[np.ndarray, np.ndarray]:
        """(airspeeds [m/s], path angles [rad]) of ``n`` straight zero-thrust glides at airspeeds
        evenly spread over the continuous envelope's range; each angle needs no thrust at any height
        up to the domain's ceiling (:meth:`~soaring_env.physics.aircraft.Aircraft.glide_angle`).
        The glide polar the planner, the heuristic agent and the final-glide input read."""
        speeds = np.linspace(self.control_low[0], self.control_high[0], check_int("n", n, 2, 10_000))
        return speeds, self.aircraft.glide_angle(speeds, 0.0, self.scenario.bounds.height_max)

    def action_to_control(self, action) -> np.ndarray:
        """Map normalized actions in [-1, 1]^3 affinely onto the physical envelope."""
        a = np.asarray(action, dtype=np.float64)
        if a.shape[-1:] != (3,):
            raise ConfigError(f"action has shape {a.shape}; expected (..., 3) in [-1, 1]")
        check_array_finite("action", a)
        if np.any(np.abs(a) > 1.0):
            raise ConfigError(f"action {a.tolist()!r} is outside [-1, 1]^3")
        return self.control_envelope.to_control(a)

    def control_to_action(self, control) -> np.ndarray:
        """Inverse of :meth:`action_to_control`."""
        return self.control_envelope.to_action(control)

    @functools.cached_property
    def propagator(self) -> Propagator:
        """The packed fast path of :func:`~soaring_env.primitives.rollout` for this model."""
        return Propagator(self.scenario.field, self.aircraft, self.library, self.max_substep)

    # --- outcomes ------------------------------------------------------------------------------
    @functools.cached_property
    def classify_params(self) -> np.ndarray:
        """Goal region and domain as the (N_CLASSIFY_PARAMS,) row read by :func:`classify_row`."""
        return classify_params(self.scenario)

    def classify(self, result: Rollout) -> tuple[np.ndarray, np.ndarray]:
        """First event along each edge: (outcome code (B,), index of the output point (B,)).

        An edge reaches the goal if one of its N points lies in the goal region before any point
        hits the ground or leaves the domain; ``FLYING`` edges have index N - 1.
        """
        return self.classify_points(result.states)

    def classify_points(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`classify` of edges given by their output points (B, N, 4) [Pn, Pe, chi, h]
        (``Rollout.states``, or the ``states`` of :meth:`Propagator.run`)."""
        s = np.ascontiguousarray(as_float_array("points", points))
        if s.ndim != 3 or s.shape[2] != 4 or s.shape[1] == 0:
            raise ConfigError(f"points has shape {s.shape}; expected (B, N, 4) [Pn, Pe, chi, h] with N >= 1")
        b = s.shape[0]
        codes = np.empty(b, dtype=np.int64)
        ks = np.empty(b, dtype=np.int64)
        classify_batch(s, np.broadcast_to(self.classify_params, (b, N_CLASSIFY_PARAMS)), codes, ks)
        return codes, ks

    def bank_ok(self) -> np.ndarray:
        """(174,) bool: primitives whose coordinated-turn bank stays within ``max_bank_deg``."""
        t = self.library.table
        bank = np.arctan(t[:, 1:2] * np.abs(t[:, 3:5]) / 9.80665).max(axis=1)
        return bank <= math.radians(self.max_bank_deg) + 1e-12

    def stall_ok(self) -> np.ndarray:
        """(174,) bool: primitives whose coordinated turns stay within ``aircraft.cl_max`` in the
        thinnest air of the domain (its ceiling: an allowed primitive is allowed anywhere in it);
        all True without a stall limit."""
        ac = self.aircraft
        if ac.cl_max is None:
            return np.ones(N_PRIMITIVES, dtype=np.bool_)
        t = self.library.table
        v = t[:, COL_AIRSPEED]
        rate = np.maximum(np.abs(t[:, COL_CHI_DOT_1]), np.abs(t[:, COL_CHI_DOT_2]))
        cl = ac.lift_coefficient(v, t[:, COL_GAMMA], bank_angle(v, rate), self.scenario.bounds.height_max)
        return cl <= ac.cl_max * (1.0 + 1e-12)

    def allowed_primitives(self) -> np.ndarray:
        """(174,) bool: the primitives action masks and planners may use, within the bank limit
        (:meth:`bank_ok`) and the stall limit (:meth:`stall_ok`)."""
        return self.bank_ok() & self.stall_ok()

    def end_height_cap(self) -> float:
        """Highest height [m] at which any plan can end: the end of its goal edge.

        The env charges the goal edge to its end (Ts), after its first point inside the goal
        region, so a plan ends at most ``w_max (Ts - Ts/N)`` above the goal's top, where ``w_max``
        bounds the updraft of any thermal that can reach the goal region within one edge, at any
        time (1.2 times its peak strength w* (1 + a); no thermal near the goal: the goal's top).
        Powered climbing does not count: it costs more fuel energy than the height it gains, which
        is what makes ``-g (cap - h)`` an admissible bound on the cost still to go from height h
        (used by the planners and the reference search).
        """
        sc = self.scenario
        g = sc.require_goal()
        f = sc.field
        top = g.height + g.radius
        if not f.thermals:
            return min(top, sc.bounds.height_max)
        lib = self.library
        reach = (float(self.control_high[0]) + math.hypot(f.wind_north, f.wind_east)) * lib.duration
        infl = f.influence_radius()
        w_max = 0.0
        for t, r in zip(f.thermals, infl, strict=True):
            if f.drift or math.hypot(t.north - g.north, t.east - g.east) <= g.radius + reach + r:
                # |updraft| <= 1.2 w* (1 + a) at any time (as in the rollout kernel)
                w_max = max(w_max, 1.2 * t.peak_strength)
        return min(top + w_max * (lib.duration - lib.duration / lib.n_points), sc.bounds.height_max)

    @property
    def n_primitives(self) -> int:
        return N_PRIMITIVES
