"""The paper's 174 motion primitives and the one rollout function of the project.

Every propagation in soaring-env -- the Gymnasium envs, the SST planner, the benchmarks and the
plots -- goes through :func:`rollout`. It integrates the paper's 4-DOF kinematics (eqs. 2-5)

    dPn/dt = v_a cos(chi) cos(gamma) + w_n     dchi/dt = chi_dot
    dPe/dt = v_a sin(chi) cos(gamma) + w_e     dh/dt   = v_a sin(gamma) + w_up(Pn, Pe, h, t)

for piecewise-constant controls. The horizontal motion is the exact circle-arc / line closed form
plus the wind drift; only the updraft term is integrated numerically (Simpson's rule on substeps of
at most ``max_substep`` seconds, and only where the path is within a thermal's reach -- elsewhere the
updraft is exactly zero and the height is linear in time).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from soaring_env._jit import ERROR_MODEL as _EM
from soaring_env._jit import FASTMATH as _FM
from soaring_env._threads import SERIAL, RowThreads
from soaring_env._validation import (
    ConfigError,
    as_float_array,
    check_array_finite,
    check_int,
    check_pair,
    check_range,
    check_type,
)
from soaring_env.physics.aircraft import _AC_ETA, _AC_MASS, _AC_MODEL, Aircraft, _thrust_at, _thrust_coeffs
from soaring_env.physics.atmosphere import (
    DENSITY_SERIES_MAX_X,
    LAPSE,
    MAX_HEIGHT,
    T0,
    G,
    _density,
    _density_near,
    density_offset,
    density_series,
)
from soaring_env.physics.thermals import (
    _GAUSSIAN,
    COL_PEAK,
    GAUSSIAN_CUTOFF,
    PACKED_COLUMNS,
    WindField,
    updraft_at,
    within_allen_reach,
)

FAMILIES = ("straight", "curve", "spiral", "spline")
STRAIGHT, CURVE, SPIRAL, SPLINE = range(4)
#: Paper section III-B: airspeeds U1 [m/s], path angles U3 [deg], total turn per Ts [deg].
SPEEDS = (10.0, 20.0)
GAMMAS_DEG = (-45.0, -15.0, 0.0, 15.0, 45.0)
CURVE_TURN_DEG = (-90.0, -60.0, -30.0, 30.0, 60.0, 90.0)
SPIRAL_TURN_DEG = (-1080.0, -720.0, -360.0, -180.0, 180.0, 360.0, 720.0, 1080.0)
SPLINE_TURN_DEG = (-90.0, -60.0, 60.0, 90.0)
N_PRIMITIVES = 174
#: Every height a rollout reaches must lie below the ISA troposphere's top [m] (re-exported from
#: ``physics.atmosphere``): :func:`rollout` refuses edges that could climb past it.
#: Shortest and longest edge [s]: below 10 ms the closed-form turn terms lose all precision (1e-300 s
#: divided by zero inside the kernel); above an hour a single edge is no longer a motion primitive,
#: and the substep count (duration / max_substep) must stay bounded so that no call can hang.
MIN_DURATION = 0.01
MAX_DURATION = 3600.0
#: Finest integration substep [s]: 500x finer than the default, far past any accuracy gain (10x
#: finer already moves heights by < 1 cm), and at most 3.6 million substeps per edge.
MIN_SUBSTEP = 1e-3
#: Most output points per edge (each is 4 floats per rollout row).
MAX_POINTS = 100_000

#: Default largest integration substep near thermals [s]; a 10x finer step moves the height after a
#: primitive through a thermal core by < 1 cm (tests; 8.4 mm in the worst tested case). Across
#: discontinuities of the field (the updraft cut at zi, the nearest-thermal boundary between
#: overlapping Allen thermals) fixed steps are first order: the error there is at most about the
#: jump times one substep.
DEFAULT_MAX_SUBSTEP = 0.5

# Columns of PrimitiveLibrary.table.
COL_FAMILY, COL_AIRSPEED, COL_GAMMA, COL_CHI_DOT_1, COL_CHI_DOT_2 = range(5)


@dataclass(frozen=True)
class PrimitiveLibrary:
    """The 174 motion primitives of the paper, in a fixed order (the discrete action index).

    Order: family (straight 0-9, curve 10-69, spiral 70-149, spline 150-173), then airspeed
    (10, 20 m/s), then turn rate (ascending; for splines the ordered pair (first, second half),
    first ascending), then path angle (-45 ... 45 deg). Spline primitives switch their turn rate
    at output point ``N // 2`` (time ``(N // 2) Ts / N``, i.e. ``Ts / 2`` for even N), as the
    paper's eq. 11 defines them on the discrete time grid.

    :param duration: primitive duration Ts [s] (not given in the paper; default 30 s), in
        [``MIN_DURATION``, ``MAX_DURATION``] = [0.01, 3600] s.
    :param n_points: number N of output points per primitive (default 30, 2 ... ``MAX_POINTS``).
    """

    duration: float = 30.0
    n_points: int = 30
    table: np.ndarray = field(init=False, repr=False, compare=False)
    #: (174, 4) kernel control rows ``(v_a, gamma, chi_dot_1, chi_dot_2)``; treat as constant.
    kernel_rows: np.ndarray = field(init=False, repr=False, compare=False)
    #: the same rows as 174 separate (1, 4) arrays, for single-edge calls without allocation.
    kernel_row: tuple[np.ndarray, ...] = field(init=False, repr=False, compare=False)
    #: fastest climb of any primitive, v_a sin(gamma) [m/s] (20 sin 45 deg): bounds the height an edge reaches.
    max_climb_rate: float = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "duration", check_duration("duration", self.duration))
        object.__setattr__(self, "n_points", check_int("n_points", self.n_points, 2, MAX_POINTS))
        rows: list[tuple[float, float, float, float, float]] = []
        ts = self.duration

        def rate(deg: float) -> float:
            return math.radians(deg) / ts

        for v in SPEEDS:
            for g in GAMMAS_DEG:
                rows.append((STRAIGHT, v, math.radians(g), 0.0, 0.0))
        for fam, turns in ((CURVE, CURVE_TURN_DEG), (SPIRAL, SPIRAL_TURN_DEG)):
            for v in SPEEDS:
                for a in turns:
                    for g in GAMMAS_DEG:
                        rows.append((fam, v, math.radians(g), rate(a), rate(a)))
        for v in SPEEDS:
            for a in SPLINE_TURN_DEG:
                for b in SPLINE_TURN_DEG:
                    if a != b:
                        rows.append((SPLINE, v, 0.0, rate(a), rate(b)))
        table = np.array(rows, dtype=np.float64)
        assert table.shape == (N_PRIMITIVES, 5)
        table.setflags(write=False)
        object.__setattr__(self, "table", table)
        # Kernel control rows (v_a, gamma, chi_dot_1, chi_dot_2). Writable on purpose, like every
        # array handed to the kernel: numba compiles another specialization for read-only arrays.
        rows_k = np.ascontiguousarray(table[:, [COL_AIRSPEED, COL_GAMMA, COL_CHI_DOT_1, COL_CHI_DOT_2]])
        object.__setattr__(self, "kernel_rows", rows_k)
        object.__setattr__(self, "kernel_row", tuple(rows_k[i : i + 1].copy() for i in range(N_PRIMITIVES)))
        object.__setattr__(self, "max_climb_rate", float(np.max(table[:, COL_AIRSPEED] * np.sin(table[:, COL_GAMMA]))))

    def __len__(self) -> int:
        return N_PRIMITIVES

    @property
    def family(self) -> np.ndarray:
        """Family code per primitive (0 straight, 1 curve, 2 spiral, 3 spline)."""
        return self.table[:, COL_FAMILY].astype(np.int64)

    def mirror_indices(self) -> np.ndarray:
        """(174,) int64: the index of each primitive's mirror image (its turn rates negated, the
        same airspeed and path angle; straight primitives are their own). The model is
        mirror-symmetric, so a plan flown with every primitive mirrored is a plan of the mirrored
        world (east -> -east) at the same cost."""
        rows = self.kernel_rows
        flipped = rows * np.array([1.0, 1.0, -1.0, -1.0])
        match = np.all(flipped[:, None, :] == rows[None, :, :], axis=2)
        if not np.all(match.sum(axis=1) == 1):
            raise RuntimeError("internal error: the primitive library is not mirror-symmetric")
        return np.argmax(match, axis=1).astype(np.int64)

    def describe(self, index: int) -> str:
        """Human-readable description of primitive ``index``."""
        f, v, g, w1, w2 = self.table[self.check_index(index)]
        turn = math.degrees(w1) * self.duration
        s = f"{FAMILIES[int(f)]} v_a={v:g} m/s gamma={math.degrees(g):+g} deg turn={turn:+g} deg"
        if f == SPLINE:
            s += f" then {math.degrees(w2) * self.duration:+g} deg"
        return s

    def check_index(self, index) -> int:
        if isinstance(index, bool) or not isinstance(index, (int, np.integer)) or not 0 <= index < N_PRIMITIVES:
            raise ConfigError(f"primitive index {index!r} is invalid; allowed: integers 0..{N_PRIMITIVES - 1}")
        return int(index)

    def control_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """The continuous envelope spanned by the primitives: low, high of (v_a [m/s],
        chi_dot [rad/s], gamma [rad]) = ([10, 20], +-1080 deg / Ts, +-45 deg)."""
        w = math.radians(max(SPIRAL_TURN_DEG)) / self.duration
        g = math.radians(max(GAMMAS_DEG))
        return np.array([min(SPEEDS), -w, -g]), np.array([max(SPEEDS), w, g])


ENVELOPES = ("paper", "physical")


@dataclass(frozen=True)
class ControlEnvelope:
    """The continuous controls ``(v_a [m/s], chi_dot [rad/s], gamma [rad])`` that normalized
    actions in [-1, 1]^3 map onto (one home for the mapping: envs, model and planners call it).

    * ``"paper"``: affine onto the box spanned by the primitives, v_a in [10, 20] m/s,
      chi_dot in +-1080 deg / Ts, gamma in +-45 deg (:meth:`PrimitiveLibrary.control_bounds`).
      Its turn rates scale with 1 / Ts, so it is meant for Ts near the paper's 30 s.
    * ``"physical"``: set by physical limits, independent of Ts: a0 -> airspeed affine in
      ``airspeed``; a1 -> bank angle ``phi = a1 * phi_lim(v_a)`` with chi_dot = g tan(phi) / v_a
      (coordinated turn), ``phi_lim(v) = min(max_bank, stall bank)`` where the stall bank keeps
      ``C_L = 2 m g / (rho v^2 S cos phi) <= cl_max`` in the thinnest air of the domain (its
      ceiling), so every action is flyable anywhere in it; a2 -> gamma affine in ``gamma``.

    :param kind: ``"paper"`` or ``"physical"``.
    :param airspeed: (low, high) [m/s].
    :param gamma: (low, high) flight-path angle [rad].
    :param chi_dot_max: ``"paper"``: largest course rate [rad/s] (the box is +-it).
    :param max_bank: ``"physical"``: bank-angle limit [rad].
    :param stall_k: ``"physical"``: ``2 m g / (rho_ceiling S cl_max)`` [m^2/s^2] (0: no stall limit):
        level flight at v_a stalls beyond ``cos(phi) < stall_k / v_a^2``.
    """

    kind: str
    airspeed: tuple[float, float]
    gamma: tuple[float, float]
    chi_dot_max: float = 0.0
    max_bank: float = 0.0
    stall_k: float = 0.0

    @classmethod
    def paper(cls, library: PrimitiveLibrary) -> ControlEnvelope:
        """The envelope of the primitives (the default of the paper's envs)."""
        lo, hi = library.control_bounds()
        return cls("paper", (float(lo[0]), float(hi[0])), (float(lo[2]), float(hi[2])), chi_dot_max=float(hi[1]))

    @classmethod
    def physical(
        cls,
        aircraft: Aircraft,
        *,
        max_bank_deg: float,
        height_max: float,
        airspeed: tuple[float, float] = (12.0, 25.0),
        gamma_deg: tuple[float, float] = (-30.0, 20.0),
    ) -> ControlEnvelope:
        """The physical envelope of ``aircraft`` in a domain whose ceiling is ``height_max`` [m].

        :raises ConfigError: for a bad range, or an airspeed low end at which even wings-level
            flight stalls at the ceiling (naming the least airspeed allowed).
        """
        v_lo, v_hi = check_pair("airspeed", airspeed, 0.0, 100.0)
        if v_lo <= 0.0 or v_hi <= v_lo:
            raise ConfigError(f"airspeed={airspeed!r} must be (low, high) with 0 < low < high <= 100 m/s")
        g_lo, g_hi = check_pair("gamma_deg", gamma_deg, -60.0, 60.0)
        if g_hi <= g_lo:
            raise ConfigError(f"gamma_deg={gamma_deg!r} must be (low, high) with low < high within +-60 deg")
        bank = check_range("max_bank_deg", max_bank_deg, 0.0, 90.0, low_open=True, high_open=True)
        k = 0.0
        if aircraft.cl_max is not None:
            rho = _density(min(max(float(height_max), 0.0), MAX_HEIGHT - 1.0))
            k = 2.0 * aircraft.weight / (rho * aircraft.wing_area * aircraft.cl_max)
            if k >= v_lo * v_lo:
                raise ConfigError(
                    f"airspeed={airspeed!r}: {v_lo:g} m/s stalls at the ceiling ({height_max:g} m) with "
                    f"cl_max={aircraft.cl_max:g}; allowed: low > {math.sqrt(k):.3f} m/s"
                )
        return cls(
            "physical", (v_lo, v_hi), (math.radians(g_lo), math.radians(g_hi)), max_bank=math.radians(bank), stall_k=k
        )

    def bank_limit(self, airspeed) -> np.ndarray:
        """``"physical"``: phi_lim [rad] at airspeed(s) [m/s]."""
        v = np.asarray(airspeed, dtype=np.float64)
        if self.stall_k == 0.0:
            return np.full(v.shape, self.max_bank)
        return np.minimum(self.max_bank, np.arccos(np.minimum(self.stall_k / (v * v), 1.0)))

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """The smallest box (low, high) of (v_a, chi_dot, gamma) holding the envelope."""
        if self.kind == "paper":
            w = self.chi_dot_max
        else:
            v = np.linspace(self.airspeed[0], self.airspeed[1], 1001)
            w = float(np.max(G * np.tan(self.bank_limit(v)) / v))
        return (
            np.array([self.airspeed[0], -w, self.gamma[0]]),
            np.array([self.airspeed[1], w, self.gamma[1]]),
        )

    def to_control(self, action: np.ndarray) -> np.ndarray:
        """Map normalized actions (..., 3) in [-1, 1] onto controls (..., 3) (no checks: callers validate)."""
        a = np.asarray(action, dtype=np.float64)
        if self.kind == "paper":
            lo, hi = self.bounds()
            return lo + 0.5 * (a + 1.0) * (hi - lo)
        out = np.empty(a.shape)
        v = self.airspeed[0] + 0.5 * (a[..., 0] + 1.0) * (self.airspeed[1] - self.airspeed[0])
        out[..., 0] = v
        out[..., 1] = G * np.tan(a[..., 1] * self.bank_limit(v)) / v
        out[..., 2] = self.gamma[0] + 0.5 * (a[..., 2] + 1.0) * (self.gamma[1] - self.gamma[0])
        return out

    def to_action(self, control: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`to_control` (controls outside the envelope map outside [-1, 1])."""
        c = np.asarray(control, dtype=np.float64)
        if self.kind == "paper":
            lo, hi = self.bounds()
            return 2.0 * (c - lo) / (hi - lo) - 1.0
        out = np.empty(c.shape)
        v = c[..., 0]
        out[..., 0] = 2.0 * (v - self.airspeed[0]) / (self.airspeed[1] - self.airspeed[0]) - 1.0
        out[..., 1] = np.arctan(v * c[..., 1] / G) / self.bank_limit(v)
        out[..., 2] = 2.0 * (c[..., 2] - self.gamma[0]) / (self.gamma[1] - self.gamma[0]) - 1.0
        return out


@dataclass(frozen=True)
class Rollout:
    """Result of :func:`rollout` for a batch of B start states (SI units, specific energy [J/kg]).

    ``states[b, k]`` is ``[Pn, Pe, chi, h]`` at ``times[k] = (k + 1) duration / N``; chi is
    wrapped to [-pi, pi). Cost terms: ``fuel`` = integral of T v_a / (m eta_ec eta_p) (>= 0),
    ``potential`` = -g (h_end - h_start), ``kinetic`` = max(0, (v_a^2 - v_prev^2) / 2) / (eta_ec eta_p)
    (the motor's work to change speed from the previous edge), ``cost`` = their sum: the net
    specific energy spent, negative in strong lift.
    """

    states: np.ndarray
    times: np.ndarray
    fuel: np.ndarray
    potential: np.ndarray
    kinetic: np.ndarray
    cost: np.ndarray
    duration: np.ndarray
    max_bank: np.ndarray
    min_height: np.ndarray

    @property
    def final(self) -> np.ndarray:
        """Final states (B, 4)."""
        return self.states[:, -1]

    def __len__(self) -> int:
        return self.states.shape[0]


def rollout(
    states,
    field: WindField,
    aircraft: Aircraft,
    *,
    primitive=None,
    control=None,
    library: PrimitiveLibrary | None = None,
    duration: float | None = None,
    t0=0.0,
    airspeed_prev=None,
    max_substep: float = DEFAULT_MAX_SUBSTEP,
) -> Rollout:
    """Propagate a batch of start states under a primitive or a constant control.

    :param states: start states ``[Pn, Pe, chi, h]`` [m, m, rad, m], shape (4,) or (B, 4).
    :param field: ambient wind and thermals.
    :param aircraft: aircraft and thrust model.
    :param primitive: primitive index (int, or (B,) ints) -- exactly one of ``primitive``/``control``.
    :param control: constant control ``(v_a [m/s], chi_dot [rad/s], gamma [rad])``, shape (3,) or (B, 3).
    :param library: primitive library (Ts, N); default ``PrimitiveLibrary()``.
    :param duration: how long the control is held [s]; default the library's Ts.
    :param t0: start time [s], scalar or (B,); matters only for drifting thermals and those with a
        life cycle or a fluctuating strength.
    :param airspeed_prev: airspeed of the previous edge [m/s] (scalar or (B,)), for the kinetic
        term; None or NaN entries charge nothing.
    :param max_substep: largest integration substep near thermals [s], at least ``MIN_SUBSTEP``.
    :returns: a :class:`Rollout`; always batched (B >= 1).
    :raises ConfigError: naming the argument, for bad shapes and values, start heights below the
        ground (h < 0), and edges that could climb to ``MAX_HEIGHT`` (11 km, the top of the ISA
        troposphere the energy model holds in): start height + duration x (climb rate + the field's
        updraft bound) must stay below it.
    """
    if library is not None:
        check_type("library", library, PrimitiveLibrary)
    check_type("field", field, WindField)
    check_type("aircraft", aircraft, Aircraft)
    lib = library if library is not None else _default_library()
    x = as_float_array("states", states)
    if x.ndim == 1:
        x = x[None, :]
    if x.ndim != 2 or x.shape[1] != 4 or x.shape[0] == 0:
        raise ConfigError(f"states has shape {np.shape(states)}; expected (4,) or (B, 4) [Pn, Pe, chi, h] with B >= 1")
    check_array_finite("states", x)
    if x.shape[0] == 1:  # batch-1 calls (the planners' replays, action masks) skip two reductions
        h_top = h_low = float(x[0, 3])
    else:
        h_top, h_low = float(x[:, 3].max()), float(x[:, 3].min())
    if h_top >= MAX_HEIGHT:
        raise ConfigError(f"states height {h_top!r} m is outside the model's range: below {MAX_HEIGHT:g} m")
    if h_low < 0.0:
        raise ConfigError(f"states height {h_low!r} m is below the ground; allowed: 0 <= h < {MAX_HEIGHT:g} m")
    if (primitive is None) == (control is None):
        raise ConfigError("rollout needs exactly one of primitive= or control=")
    if primitive is not None:
        idx = np.asarray(primitive)
        if (
            idx.ndim > 1
            or idx.size == 0
            or idx.dtype.kind not in "iu"
            or np.any(idx < 0)
            or np.any(idx >= N_PRIMITIVES)
        ):
            raise ConfigError(
                f"primitive={primitive!r} is invalid; allowed: an integer or 1-D integer array in 0..{N_PRIMITIVES - 1}"
            )
        b = _batch(x.shape[0], idx.size if idx.ndim else 1, "primitive")
        ctrl = np.take(lib.kernel_rows, np.broadcast_to(idx, (b,)), axis=0)  # 5x faster than [idx]
        climb = lib.max_climb_rate
    else:
        u = as_float_array("control", control)
        if u.ndim == 1:
            u = u[None, :]
        if u.ndim != 2 or u.shape[1] != 3 or u.shape[0] == 0:
            raise ConfigError(f"control has shape {np.shape(control)}; expected (3,) or (B, 3) [v_a, chi_dot, gamma]")
        check_array_finite("control", u)
        b = _batch(x.shape[0], u.shape[0], "control")
        u = np.broadcast_to(u, (b, 3))
        if np.any(u[:, 0] <= 0.0):
            raise ConfigError(f"control airspeed {u[:, 0].min()!r} must be > 0 m/s")
        if np.any(np.abs(u[:, 2]) >= math.pi / 2):
            raise ConfigError(f"control gamma {np.abs(u[:, 2]).max()!r} must lie in (-pi/2, pi/2) rad")
        ctrl = control_rows(u)
        climb = float(np.max(u[:, 0] * np.sin(np.abs(u[:, 2]))))
    dur = lib.duration if duration is None else check_duration("duration", duration)
    check_substep("max_substep", max_substep)
    # The energy model holds below MAX_HEIGHT only: refuse an edge that could climb to it rather
    # than return a cost computed with the troposphere's density above its top.
    reach = h_top + dur * (max(climb, 0.0) + field.updraft_bound)
    if reach >= MAX_HEIGHT:
        raise ConfigError(
            f"states height {h_top:g} m is too close to the model's ceiling: an edge of {dur:g} s could climb to "
            f"{reach:.6g} m; allowed: every height below {MAX_HEIGHT:g} m (the ISA troposphere)"
        )
    t0a = _per_row("t0", t0, b)
    check_array_finite("t0", t0a)
    if airspeed_prev is None:
        vp = np.full(b, np.nan)
    else:
        vp = _per_row("airspeed_prev", airspeed_prev, b)
        known = vp[~np.isnan(vp)]
        if np.any(~np.isfinite(known) | (known <= 0.0)):
            raise ConfigError(
                f"airspeed_prev={airspeed_prev!r} must be > 0 m/s and finite, or NaN/None for 'no previous edge'"
            )
    prop = Propagator(field, aircraft, lib, max_substep, dur)
    # Fresh writable C-contiguous copies: the kernel must always see the same array flags.
    out_states, out_terms = prop.run(
        np.array(np.broadcast_to(x, (b, 4)), dtype=np.float64, order="C"),
        np.array(t0a, dtype=np.float64, order="C"),
        np.array(vp, dtype=np.float64, order="C"),
        np.array(ctrl, dtype=np.float64, order="C"),
    )
    n_pts = lib.n_points
    return Rollout(
        states=out_states,
        times=dur * np.arange(1, n_pts + 1) / n_pts,
        fuel=out_terms[:, 0],
        potential=out_terms[:, 1],
        kinetic=out_terms[:, 2],
        cost=out_terms[:, 3],
        duration=np.full(b, dur),
        max_bank=out_terms[:, 4],
        min_height=out_terms[:, 5],
    )


def control_rows(control: np.ndarray) -> np.ndarray:
    """Kernel rows ``(v_a, gamma, chi_dot_1, chi_dot_2)`` (B, 4), C-contiguous, of constant
    physical controls ``(v_a [m/s], chi_dot [rad/s], gamma [rad])`` (B, 3) (no validation)."""
    return np.ascontiguousarray(np.stack([control[:, 0], control[:, 2], control[:, 1], control[:, 1]], axis=1))


class Propagator:
    """The kernel arguments of one (field, aircraft, library, substep) packed once: the fast entry
    point behind :func:`rollout`, for callers that step many edges of one scenario (the envs).

    :meth:`run` does no validation: pass C-contiguous, writable float64 arrays -- ``x0`` (B, 4)
    start states, ``t0`` (B,) start times [s], ``v_prev`` (B,) previous airspeeds [m/s] (NaN: none),
    ``ctrl`` (B, 4) kernel rows ``(v_a [m/s], gamma [rad], chi_dot_1, chi_dot_2 [rad/s])`` (see
    :attr:`PrimitiveLibrary.kernel_rows`). It returns ``states`` (B, N, 4) and ``terms`` (B, 6) =
    (fuel, potential, kinetic, cost [J/kg], max bank [rad], min height [m]).

    :meth:`run_fields` rolls each row out in a field of its own (many scenarios in one call).
    """

    def __init__(
        self,
        field: WindField,
        aircraft: Aircraft,
        library: PrimitiveLibrary | None = None,
        max_substep: float = DEFAULT_MAX_SUBSTEP,
        duration: float | None = None,
    ) -> None:
        lib = library if library is not None else _default_library()
        self.library = lib
        self.n_points = lib.n_points
        self.duration = lib.duration if duration is None else duration
        self.ctrl_table = lib.kernel_rows
        self.ctrl_rows = lib.kernel_row
        self._pre = (self.duration, lib.n_points, lib.n_points // 2, max_substep)
        self._field = _field_table(field)
        self._ac = aircraft.packed()

    def run(
        self, x0: np.ndarray, t0: np.ndarray, v_prev: np.ndarray, ctrl: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        return self.run_fields(x0, t0, v_prev, ctrl, _NO_FIELD_INDEX, *self._field)

    @property
    def kernel_constants(self) -> tuple[float, int, int, float, np.ndarray]:
        """The rollout kernel's arguments that stay fixed for this propagator: (duration [s], points
        per edge, index of the second control segment's first point, largest substep [s], packed
        aircraft row), for compiled callers that run the kernel inside their own (the envs' step)."""
        return (*self._pre, self._ac)

    @property
    def field_tables(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """This propagator's own field as :meth:`run_fields` reads it: (thermals, n_thermals, params)."""
        return self._field

    def run_fields(
        self,
        x0: np.ndarray,
        t0: np.ndarray,
        v_prev: np.ndarray,
        ctrl: np.ndarray,
        field_index: np.ndarray,
        thermals: np.ndarray,
        n_thermals: np.ndarray,
        params: np.ndarray,
        threads: RowThreads = SERIAL,
    ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`run` with row b in field ``field_index[b]`` (int64, (B,); empty: field 0 for all) of a
        packed table of F fields: ``thermals`` (F, n_max, PACKED_COLUMNS) rows of :attr:`WindField.packed` (the
        first ``n_thermals[f]`` used), ``params`` (F, 6) rows of :func:`field_params`. No validation:
        every index must be < F. The aircraft, library and substep are this propagator's.
        ``threads`` splits the rows over worker threads (same result bit for bit)."""
        b = x0.shape[0]
        out = np.empty((b, self.n_points, 4))
        terms = np.empty((b, 6))
        per_row = field_index.size > 0

        def block(r: slice) -> None:
            fidx = field_index[r] if per_row else field_index
            _rollout_kernel(
                x0[r], t0[r], ctrl[r], v_prev[r], fidx, *self._pre, thermals, n_thermals, params, self._ac,
                out[r], terms[r],
            )  # fmt: skip

        threads.run(b, block)
        return out, terms


#: Columns of :func:`field_params`.
FP_WIND_NORTH, FP_WIND_EAST, FP_ZI, FP_MODEL, FP_DRIFT_NORTH, FP_DRIFT_EAST = range(6)
_NO_FIELD_INDEX = np.empty(0, dtype=np.int64)


def pack_fields(fields: Sequence[WindField]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Wind fields as the table :meth:`Propagator.run_fields` reads: ``thermals`` (F, n_max, PACKED_COLUMNS)
    (row f starts with ``fields[f].packed``, zero-padded), ``n_thermals`` (F,) int64 and ``params``
    (F, 6) rows of :func:`field_params`; all fresh writable arrays (the kernel's one specialization)."""
    if len(fields) == 0:
        raise ConfigError("pack_fields needs at least one WindField")
    n = np.array([len(f.thermals) for f in fields], dtype=np.int64)
    thermals = np.zeros((len(fields), max(1, int(n.max())), PACKED_COLUMNS))
    for i, f in enumerate(fields):
        thermals[i, : n[i]] = f.packed
    return thermals, n, np.stack([field_params(f) for f in fields])


@functools.lru_cache(maxsize=256)
def _field_table(field: WindField) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``pack_fields([field])``, kept: every validated :func:`rollout` call builds a Propagator, and
    packing costs as much as a batch-1 rollout (WindField is frozen and hashable; never written)."""
    return pack_fields([field])


def field_params(field: WindField) -> np.ndarray:
    """The field's scalars as the (6,) float64 row the kernels read: ambient wind north, east [m/s],
    zi [m], model code, thermal drift velocity north, east [m/s] (zero unless ``drift``)."""
    dvx, dvy = (field.wind_north, field.wind_east) if field.drift else (0.0, 0.0)
    return np.array([field.wind_north, field.wind_east, field.zi, float(field.model_code), dvx, dvy])


def check_duration(name: str, value: float) -> float:
    """An edge duration [s] in [``MIN_DURATION``, ``MAX_DURATION``]."""
    return check_range(name, value, MIN_DURATION, MAX_DURATION)


def check_substep(name: str, value: float) -> float:
    """A largest integration substep [s] of at least ``MIN_SUBSTEP`` (finer ones can hang a rollout)."""
    v = check_range(name, value, MIN_SUBSTEP, math.inf, high_open=True)
    return v


def _per_row(name: str, value: object, b: int) -> np.ndarray:
    """A scalar or (B,) argument as a (B,) float64 array, or a ConfigError naming it."""
    a = as_float_array(name, value)
    if a.ndim > 1 or (a.ndim == 1 and a.shape[0] not in (1, b)):
        raise ConfigError(f"{name} has shape {a.shape}; expected a scalar, (1,) or ({b},) (one per rollout row)")
    return np.ascontiguousarray(np.broadcast_to(a, (b,)))


def _batch(n_states: int, n_controls: int, what: str) -> int:
    if n_states != n_controls and 1 not in (n_states, n_controls):
        raise ConfigError(f"{n_states} states and {n_controls} {what} rows do not broadcast; give 1 or B of each")
    return max(n_states, n_controls)


_DEFAULT_LIBRARY: list[PrimitiveLibrary] = []


def _default_library() -> PrimitiveLibrary:
    if not _DEFAULT_LIBRARY:
        _DEFAULT_LIBRARY.append(PrimitiveLibrary())
    return _DEFAULT_LIBRARY[0]


@njit(cache=True, inline="always", fastmath=_FM, error_model=_EM)
def _advance(n, e, c, s, u, om, tau, cd, sd, wn, we):
    """Exact arc (or line) of horizontal air speed u and turn rate om over tau, plus wind drift.

    (c, s) = cos/sin of the course at the start; (cd, sd) = cos/sin(om tau) precomputed.
    """
    c2 = c * cd - s * sd
    s2 = s * cd + c * sd
    a = om * tau
    if abs(a) > 1e-5:
        k = u / om
        n2 = n + k * (s2 - s) + wn * tau
        e2 = e + k * (c - c2) + we * tau
    else:  # second-order series: avoids u/om cancellation, error < u tau a^2 / 6
        n2 = n + u * tau * (c - 0.5 * a * s) + wn * tau
        e2 = e + u * tau * (s + 0.5 * a * c) + we * tau
    return n2, e2, c2, s2


@njit(cache=True, inline="always", fastmath=_FM, error_model=_EM)
def _thrust_trapezoid(hb, fb, lo, hi, kt, tmodel, h_ref, rho_ref, theta_ref, series_ok):
    """Sum over the intervals ``lo .. hi - 1`` of the mean thrust [N] at their ends ``hb[i]``,
    ``hb[i + 1]`` [m] (the trapezoid rule without its dt); ``fb`` is scratch. ``series_ok``: every
    height is near enough to ``h_ref`` for :func:`density_series`, whose loop (unlike the power
    function's) vectorizes."""
    if hi <= lo:  # no interval (a one-point edge's empty first segment)
        return 0.0
    if series_ok:
        for i in range(lo, hi + 1):
            fb[i] = _thrust_at(density_series(density_offset(hb[i], h_ref, theta_ref), rho_ref), kt, tmodel)
    else:
        for i in range(lo, hi + 1):
            fb[i] = _thrust_at(_density_near(hb[i], h_ref, rho_ref, theta_ref), kt, tmodel)
    total = 0.5 * (fb[lo] + fb[hi])
    for i in range(lo + 1, hi):
        total += fb[i]
    return total


@njit(cache=True, fastmath=_FM, nogil=True, error_model=_EM)
def _rollout_kernel(
    x0, t0, ctrl, v_prev, fidx, dur, n_pts, k_switch, max_substep, th_all, nth_all, fpar, ac, out, terms
):
    dt = dur / n_pts
    m_sub = max(1, int(math.ceil(dt / max_substep - 1e-9)))
    hs = dt / m_sub
    mass_eta = ac[_AC_MASS] * ac[_AC_ETA]
    tmodel = ac[_AC_MODEL]
    two_pi = 2.0 * math.pi
    infl = np.empty(th_all.shape[1])
    cand = np.empty(th_all.shape[1], dtype=np.int64)
    hb = np.empty(n_pts + 1)  # heights of the start and of the points [m]
    fb = np.empty(n_pts + 1)  # thrust [N] at them
    cb = np.empty(n_pts)  # courses at the points [rad]
    fld_prev = -1
    th = th_all[0, :0]
    nth = model = 0
    zi = wn = we = dvx = dvy = wind = w_bound = 0.0
    for b in range(x0.shape[0]):
        fld = fidx[b] if fidx.size > 0 else 0
        if fld != fld_prev:  # this row's field: unpack once per run of rows that share it
            fld_prev = fld
            nth = nth_all[fld]
            th = th_all[fld, :nth]
            wn = fpar[fld, FP_WIND_NORTH]
            we = fpar[fld, FP_WIND_EAST]
            zi = fpar[fld, FP_ZI]
            model = int(fpar[fld, FP_MODEL])
            dvx = fpar[fld, FP_DRIFT_NORTH]
            dvy = fpar[fld, FP_DRIFT_EAST]
            wind = math.sqrt(wn * wn + we * we)
            w_bound = 0.0  # |updraft| <= 1.2 w* (1 + a) (Allen's peak/w* stays below 1.1)
            for j in range(nth):
                w_bound = max(w_bound, 1.2 * th[j, COL_PEAK])
                infl[j] = GAUSSIAN_CUTOFF * th[j, 3] if model == _GAUSSIAN else th[j, 3]
        v = ctrl[b, 0]
        gam = ctrl[b, 1]
        u = v * math.cos(gam)
        climb = v * math.sin(gam)
        n = x0[b, 0]
        e = x0[b, 1]
        h = x0[b, 3]
        h_start = h
        rho_start = _density(h)
        theta_start = 1.0 - LAPSE * h / T0
        c = math.cos(x0[b, 2])
        s = math.sin(x0[b, 2])
        # Relative to a (possibly drifting) thermal the aircraft moves at most u + 2|wind|.
        reach = (u + 2.0 * wind) * dt
        # Thermals the whole edge can come near: an arc stays within its diameter 2u/|om| of its
        # start, a spline within the sum over its two arcs, any path within u * dur. These checks
        # use positions only, so they hold at any time: an unborn or dead thermal only makes an
        # interval integrated that needed not be (its updraft there is exactly zero).
        span = u * dur
        w1 = abs(ctrl[b, 2])
        w2 = abs(ctrl[b, 3])
        if w1 > 0.0 and w2 > 0.0:
            span = min(span, 2.0 * u / w1 + 2.0 * u / w2)
        span += 2.0 * wind * dur
        n_cand = 0
        for j in range(nth):
            dx = n - th[j, 0] - dvx * t0[b]
            dy = e - th[j, 1] - dvy * t0[b]
            lim = infl[j] + span + reach
            if dx * dx + dy * dy < lim * lim:
                cand[n_cand] = j
                n_cand += 1
        max_bank = 0.0
        om = cd = sd = ch = sh = 0.0
        g0 = 0.0
        g0_ok = False
        two_seg = ctrl[b, 3] != ctrl[b, 2]
        # Courses in closed form, into a contiguous buffer (a loop that vectorizes; out's stride does not).
        w1 = ctrl[b, 2]
        w2 = ctrl[b, 3]
        for k in range(n_pts):
            chi_k = x0[b, 2] + (w1 * min(k + 1, k_switch) + w2 * max(0, k + 1 - k_switch)) * dt
            chi_k -= two_pi * math.floor((chi_k + math.pi) / two_pi)
            if chi_k >= math.pi:  # rounding can land exactly on +pi
                chi_k -= two_pi
            cb[k] = chi_k
        hb[0] = h
        for k in range(n_pts):
            # A second segment that turns at the first one's rate needs none of this again.
            if k == 0 or (k == k_switch and two_seg):
                om = ctrl[b, 2] if k < k_switch else ctrl[b, 3]
                cd = math.cos(om * dt)
                sd = math.sin(om * dt)
                ch = math.cos(0.5 * om * hs)
                sh = math.sin(0.5 * om * hs)
                max_bank = max(max_bank, abs(math.atan(v * om / G)))
            t_start = t0[b] + k * dt
            n1, e1, c1, s1 = _advance(n, e, c, s, u, om, dt, cd, sd, wn, we)
            near = False
            for jc in range(n_cand):
                j = cand[jc]
                dx = n - th[j, 0] - dvx * t_start
                dy = e - th[j, 1] - dvy * t_start
                lim = infl[j] + reach
                d2 = dx * dx + dy * dy
                if d2 < lim * lim:
                    # Allen: refine with 2 r2 at the highest height this interval can reach.
                    if model == _GAUSSIAN or within_allen_reach(
                        math.sqrt(d2) - reach, h + (abs(climb) + w_bound) * dt, zi
                    ):
                        near = True
                        break
            if near:
                # Simpson's rule on each substep. The rates at the mid and end points use heights
                # predicted from the start rate (the updraft depends on h only weakly), so the two
                # evaluations are independent and overlap in the CPU; the end rate is reused as the
                # next substep's start rate: two updraft evaluations per substep.
                pn, pe, pc, ps = n, e, c, s
                hh = h
                if not g0_ok:
                    g0 = climb + updraft_at(pn, pe, hh, t_start, th, model, zi, dvx, dvy)
                for m in range(m_sub):
                    ts = t_start + m * hs
                    pn, pe, pc, ps = _advance(pn, pe, pc, ps, u, om, 0.5 * hs, ch, sh, wn, we)
                    gm = climb + updraft_at(pn, pe, hh + 0.5 * hs * g0, ts + 0.5 * hs, th, model, zi, dvx, dvy)
                    pn, pe, pc, ps = _advance(pn, pe, pc, ps, u, om, 0.5 * hs, ch, sh, wn, we)
                    ge = climb + updraft_at(pn, pe, hh + hs * g0, ts + hs, th, model, zi, dvx, dvy)
                    hh += hs / 6.0 * (g0 + 4.0 * gm + ge)
                    g0 = ge
                g0_ok = True
                h1 = hh
            else:
                g0_ok = False
                h1 = h + climb * dt
            out[b, k, 0] = n1
            out[b, k, 1] = e1
            out[b, k, 2] = cb[k]
            out[b, k, 3] = h1
            hb[k + 1] = h1
            n, e, c, s, h = n1, e1, c1, s1, h1
        # The rest has no serial dependency from point to point: loops the compiler vectorizes.
        min_h = hb[0]
        max_h = hb[0]
        for k in range(1, n_pts + 1):
            min_h = min(min_h, hb[k])
            max_h = max(max_h, hb[k])
        series = max(abs(density_offset(min_h, h_start, theta_start)), abs(density_offset(max_h, h_start, theta_start)))
        series_ok = series <= DENSITY_SERIES_MAX_X
        # Propulsive energy: the trapezoid rule over the points, with each control segment's own
        # thrust (a second segment starts at the first one's last point).
        k_seg = k_switch if two_seg else n_pts
        tan_phi = v * ctrl[b, 2] / G
        kt = _thrust_coeffs(v, gam, 1.0 / math.sqrt(1.0 + tan_phi * tan_phi), ac)
        fuel = _thrust_trapezoid(hb, fb, 0, k_seg, kt, tmodel, h_start, rho_start, theta_start, series_ok)
        if two_seg:
            tan_phi = v * ctrl[b, 3] / G
            kt = _thrust_coeffs(v, gam, 1.0 / math.sqrt(1.0 + tan_phi * tan_phi), ac)
            fuel += _thrust_trapezoid(hb, fb, k_seg, n_pts, kt, tmodel, h_start, rho_start, theta_start, series_ok)
        fuel *= dt * v / mass_eta
        h = hb[n_pts]
        kinetic = 0.0
        vp = v_prev[b]
        if vp == vp and v > vp:  # NaN-safe: no previous edge charges nothing
            kinetic = 0.5 * (v * v - vp * vp) / ac[_AC_ETA]
        potential = -G * (h - h_start)
        terms[b, 0] = fuel
        terms[b, 1] = potential
        terms[b, 2] = kinetic
        terms[b, 3] = fuel + potential + kinetic
        terms[b, 4] = max_bank
        terms[b, 5] = min_h
