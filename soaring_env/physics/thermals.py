"""The air: constant ambient wind plus thermal updrafts (Allen 2006 or Gaussian).

Allen's model: M. J. Allen, "Updraft model for development of autonomous soaring uninhabited air
vehicles", AIAA 2006-1510, eqs. 1-8 and the MATLAB routine of its appendix; the formulas and the
decisions it leaves open are in ``shared/design/physics.md``. The Gaussian thermal
``w = W exp(-r^2 / R^2)`` summed over thermals is the one of ArduPilot's SITL soaring simulation.

Life cycle and fluctuation (optional, per thermal; both off by default). A thermal's strength
(Allen's w*, or the Gaussian peak W) at time t [s] is

    w(t) = w0 * E(t) * (1 + a sin(2 pi t / P + phi))

with w0 = ``strength``, the fluctuation amplitude a = ``amplitude`` in [0, 1), period P = ``period``
[s] and phase phi = ``phase`` [rad], and the life-cycle envelope E (``lifetime`` L, ``birth`` t_b,
death t_d = t_b + L, ``rise`` T_r and ``decay`` T_d, with T_r + T_d <= L):

    E(t) = 0                                   t <= t_b or t >= t_d (unborn or dead)
    E(t) = sin^2(pi/2 (t - t_b) / T_r)         t_b < t < t_b + T_r  (growing)
    E(t) = 1                                   t_b + T_r <= t <= t_d - T_d (mature)
    E(t) = sin^2(pi/2 (t_d - t) / T_d)         t_d - T_d < t < t_d (decaying)

(sin^2 ramps: continuous with zero slope at both ends; T_r = 0 or T_d = 0 switch abruptly). A
thermal without a lifetime (``lifetime=None``) has E = 1 at all times. Since a < 1 the strength is
positive exactly while the thermal lives (t_b < t < t_d); a thermal with E = 0 is *absent*: Allen's
"nearest thermal" rule skips it (the next nearest living thermal rules there), Gaussian sums add
nothing for it, and the observation's thermal slots do not list it. Both updraft models are linear
in the strength (Allen's wbar, w_peak and downdraft all scale with w*), so the updraft of a thermal
at t is the steady thermal's updraft times E(t) (1 + a sin(...)) wherever it is the one that rules.
The shape (radii r1, r2 over height, Gaussian R) and the drift do not change with time.

A *steady* thermal (no lifetime, a = 0) takes exactly the code path and the numbers of the model
without these options: the kernels multiply by the factor only for thermals that have one
(column ``COL_DYNAMIC`` of :attr:`WindField.packed`). Every bound (``updraft_bound``, the rollout's
height bound, ``SoaringModel.end_height_cap``) uses the peak strength ``w0 (1 + a)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from soaring_env._jit import ERROR_MODEL as _EM
from soaring_env._jit import FASTMATH as _FM
from soaring_env._validation import (
    ConfigError,
    broadcast_flat,
    check_bool,
    check_choice,
    check_finite,
    check_positive,
    check_range,
    check_type,
)
from soaring_env.physics.atmosphere import MAX_HEIGHT

THERMAL_MODELS = ("allen", "gaussian")
_ALLEN, _GAUSSIAN = 0, 1

#: Allen (2006) shape constants, rows r1/r2 = 0.14 ... 0.80: columns r1/r2, k1, k2, k3, k4.
ALLEN_SHAPE = np.array(
    [
        [0.14, 1.5352, 2.5826, -0.0113, -0.1950],
        [0.25, 1.5265, 3.6054, -0.0176, -0.1265],
        [0.36, 1.4866, 4.8356, -0.0320, -0.0818],
        [0.47, 1.2042, 7.7904, 0.0848, -0.0445],
        [0.58, 0.8816, 13.9720, 0.3404, -0.0216],
        [0.69, 0.7067, 23.9940, 0.5689, -0.0099],
        [0.80, 0.6189, 42.7965, 0.7157, -0.0033],
    ]
)
#: Largest Allen r2 over 0 <= z <= zi is at z = zi: 0.102 * 0.75 = 0.0765 zi (floor 10 m).
ALLEN_R2_MAX_PER_ZI = 0.102 * 0.75
#: Gaussian thermals are treated as exactly zero beyond 6 R (exp(-36) < 3e-16 of the peak).
GAUSSIAN_CUTOFF = 6.0
#: Largest ambient wind component [m/s].
MAX_WIND = 100.0
#: Columns of :attr:`WindField.packed` (the kernels' thermal rows): north [m], east [m], strength
#: [m/s], radius-or-influence [m] (Allen: 2 r2 at zi; Gaussian: R), then the time dependence:
#: dynamic (1.0 where the thermal has a life cycle or a fluctuation, else 0.0: the kernels then take
#: the steady path and read no further column), birth [s], death [s] (-inf / +inf without a life
#: cycle), rise [s], decay [s], fluctuation amplitude [-], angular frequency 2 pi / P [rad/s], phase
#: [rad], and the peak strength w0 (1 + a) [m/s] that bounds the strength at any time.
(
    COL_NORTH,
    COL_EAST,
    COL_STRENGTH,
    COL_RADIUS,
    COL_DYNAMIC,
    COL_BIRTH,
    COL_DEATH,
    COL_RISE,
    COL_DECAY,
    COL_AMPLITUDE,
    COL_OMEGA,
    COL_PHASE,
    COL_PEAK,
) = range(13)
#: Width of the kernels' thermal rows; code that allocates thermal tables uses it.
PACKED_COLUMNS = 13
#: Shortest fluctuation period [s]: the rollout's default 0.5 s substeps then resolve a period with
#: at least 20 steps (Simpson's rule on a sine: relative error < 1e-4).
MIN_PERIOD = 10.0
#: Default fluctuation period [s] (used only where ``amplitude`` > 0).
DEFAULT_PERIOD = 600.0


@dataclass(frozen=True)
class Thermal:
    """One thermal column.

    :param north: centre north position at t = 0 [m].
    :param east: centre east position at t = 0 [m].
    :param strength: Allen's convective velocity scale w* [m/s], or the Gaussian peak W [m/s].
    :param radius: Gaussian radius R [m] (Allen's radii follow from zi and the height instead).
    :param birth: time [s] at which the thermal starts to grow (needs ``lifetime``; may be negative:
        born before t = 0).
    :param lifetime: time [s] from birth to death (> 0, at least ``rise + decay``); None (default):
        steady, the thermal exists at full strength at all times.
    :param rise: time [s] over which it grows from 0 to full strength (>= 0; needs ``lifetime``).
    :param decay: time [s] over which it decays from full strength to 0 before its death (>= 0).
    :param amplitude: relative strength fluctuation a in [0, 1) (default 0: none).
    :param period: fluctuation period P [s], at least ``MIN_PERIOD`` (10 s).
    :param phase: fluctuation phase phi [rad].

    The strength at time t is ``strength * E(t) * (1 + amplitude sin(2 pi t / period + phase))``
    (module docstring).
    """

    north: float
    east: float
    strength: float = 2.56
    radius: float = 80.0
    birth: float = 0.0
    lifetime: float | None = None
    rise: float = 0.0
    decay: float = 0.0
    amplitude: float = 0.0
    period: float = DEFAULT_PERIOD
    phase: float = 0.0

    def __post_init__(self) -> None:
        # stored as floats: a value given as a numpy scalar or int must not reach the kernels' packing as such
        object.__setattr__(self, "north", check_finite("thermal.north", self.north))
        object.__setattr__(self, "east", check_finite("thermal.east", self.east))
        object.__setattr__(self, "strength", check_positive("thermal.strength", self.strength))
        object.__setattr__(self, "radius", check_positive("thermal.radius", self.radius))
        object.__setattr__(self, "birth", check_finite("thermal.birth", self.birth))
        for name in ("rise", "decay"):
            v = check_finite(f"thermal.{name}", getattr(self, name))
            if v < 0.0:
                raise ConfigError(f"thermal.{name}={getattr(self, name)!r} must be >= 0 s (a duration)")
            object.__setattr__(self, name, v)
        if self.lifetime is None:
            for name in ("birth", "rise", "decay"):
                if getattr(self, name) != 0.0:
                    raise ConfigError(
                        f"thermal.{name}={getattr(self, name)!r} needs a thermal.lifetime: a thermal with "
                        "lifetime=None is steady (full strength at all times); give a lifetime [s] > 0"
                    )
        else:
            life = check_positive("thermal.lifetime", self.lifetime)
            if life < self.rise + self.decay:
                raise ConfigError(
                    f"thermal.lifetime={self.lifetime!r} is shorter than rise + decay = {self.rise + self.decay:g} s; "
                    "allowed: lifetime >= rise + decay"
                )
            object.__setattr__(self, "lifetime", life)
        a = check_finite("thermal.amplitude", self.amplitude)
        if not 0.0 <= a < 1.0:
            raise ConfigError(f"thermal.amplitude={self.amplitude!r} is outside the allowed range [0, 1)")
        object.__setattr__(self, "amplitude", a)
        p = check_finite("thermal.period", self.period)
        if p < MIN_PERIOD:
            raise ConfigError(f"thermal.period={self.period!r} must be >= {MIN_PERIOD:g} s")
        object.__setattr__(self, "period", p)
        object.__setattr__(self, "phase", check_finite("thermal.phase", self.phase))

    @property
    def steady(self) -> bool:
        """True without a life cycle and without fluctuation: today's constant-strength thermal."""
        return self.lifetime is None and self.amplitude == 0.0

    @property
    def death(self) -> float:
        """Time [s] at which the thermal has decayed to nothing (``inf`` without a lifetime)."""
        return math.inf if self.lifetime is None else self.birth + self.lifetime

    @property
    def peak_strength(self) -> float:
        """The largest strength it ever has, ``strength (1 + amplitude)`` [m/s]."""
        return self.strength * (1.0 + self.amplitude)

    def alive(self, t: float) -> bool:
        """True while the thermal exists at time ``t`` [s] (birth < t < death; always if no lifetime)."""
        return self.lifetime is None or self.birth < t < self.death

    def factor(self, t: float) -> float:
        """Strength at time ``t`` [s] relative to ``strength``: E(t) (1 + a sin(2 pi t / P + phi)),
        computed by the kernels' :func:`strength_factor`."""
        if self.steady:
            return 1.0
        r = self._row()
        return float(
            strength_factor(
                float(t),
                r[COL_BIRTH],
                r[COL_DEATH],
                r[COL_RISE],
                r[COL_DECAY],
                r[COL_AMPLITUDE],
                r[COL_OMEGA],
                r[COL_PHASE],
            )
        )

    def strength_at(self, t: float) -> float:
        """Strength [m/s] at time ``t`` [s] (w* or W), as the kernels compute it."""
        return self.strength if self.steady else self.strength * self.factor(t)

    def _row(self) -> list[float]:
        """This thermal's row of :attr:`WindField.packed` (``COL_*``), the radius-or-influence column
        left 0 (the field fills it in: it depends on the model)."""
        lifecycle = self.lifetime is not None
        return [
            self.north,
            self.east,
            self.strength,
            0.0,
            0.0 if self.steady else 1.0,
            self.birth if lifecycle else -math.inf,
            self.death,
            self.rise,
            self.decay,
            self.amplitude,
            2.0 * math.pi / self.period,
            self.phase,
            self.strength * (1.0 + self.amplitude),
        ]


@dataclass(frozen=True)
class WindField:
    """Ambient wind (constant, horizontal) plus the updrafts of any number of thermals.

    :param thermals: the thermal columns.
    :param model: ``"allen"`` (default) or ``"gaussian"``.
    :param zi: convective boundary layer depth [m]; no updraft at or above it.
    :param wind_north: ambient wind towards north [m/s].
    :param wind_east: ambient wind towards east [m/s].
    :param drift: thermals drift with the ambient wind (centre = centre0 + wind * t).
    """

    thermals: tuple[Thermal, ...] = ()
    model: str = "allen"
    zi: float = 1400.0
    wind_north: float = 0.0
    wind_east: float = 0.0
    drift: bool = False
    _packed: np.ndarray = field(init=False, repr=False, compare=False)
    #: an upper bound on the updraft anywhere at any time [m/s]: Allen 1.2 max w* (1 + a) (its peak
    #: stays below 1.1 w*), Gaussian the sum of the peaks W (1 + a) (overlapping thermals add up).
    updraft_bound: float = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if isinstance(self.thermals, (str, bytes, Thermal)) or not hasattr(self.thermals, "__iter__"):
            raise ConfigError(f"thermals={self.thermals!r} must be a sequence of Thermal")
        object.__setattr__(self, "thermals", tuple(self.thermals))
        for i, th in enumerate(self.thermals):
            if not isinstance(th, Thermal):
                raise ConfigError(f"thermals[{i}]={th!r} must be a Thermal")
        check_type("model", self.model, str)
        check_choice("model", self.model, THERMAL_MODELS)
        object.__setattr__(self, "zi", check_positive("zi", self.zi))
        if self.zi >= MAX_HEIGHT:
            raise ConfigError(f"zi={self.zi!r} is outside the model's range; allowed: 0 < zi < {MAX_HEIGHT:g} m")
        # |wind| <= 100 m/s: far past any soaring weather, and positions stay finite over any edge
        object.__setattr__(self, "wind_north", check_range("wind_north", self.wind_north, -MAX_WIND, MAX_WIND))
        object.__setattr__(self, "wind_east", check_range("wind_east", self.wind_east, -MAX_WIND, MAX_WIND))
        object.__setattr__(self, "drift", check_bool("drift", self.drift))
        allen = self.model == "allen"
        rows = []
        for t in self.thermals:
            row = t._row()
            row[COL_RADIUS] = self._influence(t) if allen else t.radius
            rows.append(row)
        packed = np.array(rows, dtype=np.float64).reshape(-1, PACKED_COLUMNS)
        packed.setflags(write=False)
        object.__setattr__(self, "_packed", packed)
        w = packed[:, COL_PEAK]  # = strength exactly for steady thermals (a = 0)
        object.__setattr__(self, "updraft_bound", float(1.2 * w.max() if allen else w.sum()) if w.size else 0.0)

    def _influence(self, t: Thermal) -> float:
        if self.model == "allen":
            return 2.0 * max(10.0, ALLEN_R2_MAX_PER_ZI * self.zi)
        return GAUSSIAN_CUTOFF * t.radius

    @property
    def packed(self) -> np.ndarray:
        """(n, ``PACKED_COLUMNS``) float64 rows read by the kernels: north, east, strength,
        radius-or-influence, then the life-cycle and fluctuation columns (see ``COL_*``)."""
        return self._packed

    @property
    def steady(self) -> bool:
        """True if every thermal is steady (no life cycle, no fluctuation)."""
        return all(t.steady for t in self.thermals)

    def alive(self, t: float = 0.0) -> np.ndarray:
        """(n,) bool: which thermals exist at time ``t`` [s]."""
        return np.array([th.alive(t) for th in self.thermals], dtype=bool)

    def strengths(self, t: float = 0.0) -> np.ndarray:
        """(n,) strengths [m/s] (w* or W) at time ``t`` [s]; 0 for unborn and dead thermals."""
        return np.array([th.strength_at(t) for th in self.thermals], dtype=np.float64)

    @property
    def model_code(self) -> int:
        return _ALLEN if self.model == "allen" else _GAUSSIAN

    @property
    def wind(self) -> np.ndarray:
        """Ambient wind (north, east) [m/s]."""
        return np.array([self.wind_north, self.wind_east])

    def influence_radius(self) -> np.ndarray:
        """Per thermal, the horizontal distance [m] beyond which its updraft is exactly zero."""
        return np.array([self._influence(t) for t in self.thermals])

    def centres(self, t: float = 0.0) -> np.ndarray:
        """Thermal centres (n, 2) [m] at time ``t`` [s] (they move only with ``drift``)."""
        c = self._packed[:, :2].copy()
        if self.drift:
            c += self.wind * t
        return c

    def updraft(self, north, east, height, t=0.0) -> np.ndarray:
        """Vertical wind w_up [m/s, positive up] at arrays of points (broadcast together).

        :param north: [m]; :param east: [m]; :param height: [m]; :param t: time [s] (drift, life
            cycle and fluctuation).
        """
        shape, arrays = broadcast_flat(north, east, height, t)
        n, e, h, tt = arrays
        out = np.empty(n.shape)
        dvx, dvy = (self.wind_north, self.wind_east) if self.drift else (0.0, 0.0)
        # the kernel checks the inputs (four numpy reductions cost more than the updrafts of a
        # few hundred points) and stops at the first non-finite one
        if _updraft_many(n, e, h, tt, self._packed, self.model_code, self.zi, dvx, dvy, out) >= 0:
            for name, a in zip(("north", "east", "height", "t"), arrays, strict=True):
                if not np.all(np.isfinite(a)):
                    raise ConfigError(f"{name} contains non-finite values; all points must be finite")
        return out.reshape(shape)

    def allen_profile(self, height: float, strength: float = 1.0) -> dict[str, float]:
        """Allen's radial scales at one height: r2, r1 [m], wbar, w_peak [m/s] (for w* = strength)."""
        zz = height / self.zi
        cb = zz ** (1.0 / 3.0)
        r2 = max(10.0, 0.102 * cb * (1.0 - 0.25 * zz) * self.zi)
        r1 = _r1_over_r2(r2) * r2
        wbar = strength * cb * (1.0 - 1.1 * zz)
        w_peak = 3.0 * wbar * (r2**3 - r2 * r2 * r1) / (r2**3 - r1**3)  # Allen eq. 4 as published
        return {"r2": r2, "r1": r1, "wbar": wbar, "w_peak": w_peak}


@njit(cache=True, inline="always", fastmath=_FM, error_model=_EM)
def allen_reach(z: float, zi: float) -> float:
    """2 r2 at height ``z`` [m]: no Allen updraft or downdraft beyond it (r2 grows with z below zi)."""
    zz = min(max(z, 0.0), zi) / zi
    return 2.0 * max(10.0, 0.102 * _pow(zz, 1.0 / 3.0) * (1.0 - 0.25 * zz) * zi)


@njit(cache=True, inline="always", fastmath=_FM, error_model=_EM)
def within_allen_reach(d: float, z: float, zi: float) -> bool:
    """``d < allen_reach(z, zi)`` for a distance ``d`` [m], decided without the cube root.

    ``d < 2 * 0.102 zz^(1/3) (1 - zz/4) zi`` is cubed into ``(d / (0.204 (1 - zz/4) zi))^3 < zz``:
    the rollout asks this for every output interval near a thermal, where a fractional power
    would cost as much as the rest of the interval.
    """
    if d < 20.0:  # 2 r2 >= 20 m at any height
        return True
    zz = min(max(z, 0.0), zi) / zi
    q = d / (0.204 * (1.0 - 0.25 * zz) * zi)
    return q * q * q < zz


@njit(cache=True, inline="always", fastmath=_FM, error_model=_EM)
def _pow(x: float, y: float) -> float:
    """``x ** y`` for ``x >= 0`` as ``exp(y log x)``, relative error about ``|y ln x| 2^-53`` (< 1e-14
    for results between 1e-39 and 1e39) at about half the latency of libm's pow: the updraft sits on
    the height integration's serial dependency chain, so its latency is the rollout's cost."""
    return math.exp(y * math.log(x))


@njit(cache=True, inline="always", fastmath=_FM, error_model=_EM)
def _r1_over_r2(r2: float) -> float:
    return 0.0011 * r2 + 0.14 if r2 < 600.0 else 0.8


@njit(cache=True, fastmath=_FM, error_model=_EM)
def _allen_shape() -> np.ndarray:
    return ALLEN_SHAPE


@njit(cache=True, inline="always", fastmath=_FM, error_model=_EM)
def strength_factor(
    t: float, birth: float, death: float, rise: float, decay: float, amp: float, omega: float, phase: float
) -> float:
    """E(t) (1 + amp sin(omega t + phase)): a thermal's strength at ``t`` [s] relative to its nominal
    one (module docstring); 0 outside birth < t < death [s], rise/decay [s] the sin^2 ramps."""
    if not birth < t < death:
        return 0.0
    f = 1.0
    # rise = 0 (or no life cycle: birth = -inf) never enters the ramps: no division by zero
    if t < birth + rise:
        s = math.sin(0.5 * math.pi * (t - birth) / rise)
        f = s * s
    elif t > death - decay:
        s = math.sin(0.5 * math.pi * (death - t) / decay)
        f = s * s
    if amp != 0.0:
        f *= 1.0 + amp * math.sin(omega * t + phase)
    return f


@njit(cache=True, inline="always", fastmath=_FM, error_model=_EM)
def row_factor(th: np.ndarray, j: int, t: float) -> float:
    """:func:`strength_factor` of packed thermal row ``j`` at time ``t`` [s]."""
    return strength_factor(
        t,
        th[j, COL_BIRTH],
        th[j, COL_DEATH],
        th[j, COL_RISE],
        th[j, COL_DECAY],
        th[j, COL_AMPLITUDE],
        th[j, COL_OMEGA],
        th[j, COL_PHASE],
    )


@njit(cache=True, inline="always", fastmath=_FM, error_model=_EM)
def row_absent(th: np.ndarray, j: int, t: float) -> bool:
    """True if packed thermal row ``j`` is unborn or dead at time ``t`` [s] (steady rows: never)."""
    return th[j, COL_DYNAMIC] != 0.0 and not th[j, COL_BIRTH] < t < th[j, COL_DEATH]


@njit(cache=True, fastmath=_FM, error_model=_EM)
def updraft_at(
    x: float, y: float, z: float, t: float, th: np.ndarray, model: int, zi: float, dvx: float, dvy: float
) -> float:
    """Updraft [m/s] at one point at time ``t`` [s]; the single definition every caller compiles in.

    Steady rows (``COL_DYNAMIC`` = 0) take the time-independent path unchanged; the others have
    their strength scaled by :func:`row_factor`, and unborn or dead ones are absent.
    """
    if z <= 0.0 or z >= zi:
        return 0.0
    n = th.shape[0]
    ox = dvx * t
    oy = dvy * t
    if model == _GAUSSIAN:
        w = 0.0
        for j in range(n):
            dx = x - th[j, 0] - ox
            dy = y - th[j, 1] - oy
            r = th[j, 3]
            d2 = dx * dx + dy * dy
            if d2 < (GAUSSIAN_CUTOFF * r) ** 2:
                if th[j, COL_DYNAMIC] == 0.0:
                    w += th[j, 2] * math.exp(-d2 / (r * r))
                else:  # 0 for unborn and dead thermals
                    w += th[j, 2] * row_factor(th, j, t) * math.exp(-d2 / (r * r))
        return w
    best = np.inf
    jb = -1
    for j in range(n):
        if row_absent(th, j, t):  # Allen's nearest-thermal rule: only living thermals count
            continue
        dx = x - th[j, 0] - ox
        dy = y - th[j, 1] - oy
        d2 = dx * dx + dy * dy
        if d2 < best:
            best = d2
            jb = j
    if jb < 0:
        return 0.0
    if best >= th[jb, 3] * th[jb, 3]:  # beyond 2 r2 at any height: skip the cube root
        return 0.0
    zz = z / zi
    cb = _pow(zz, 1.0 / 3.0)
    r2 = max(10.0, 0.102 * cb * (1.0 - 0.25 * zz) * zi)
    if best >= 4.0 * r2 * r2:
        return 0.0
    r = math.sqrt(best)
    wstar = th[jb, 2]
    if th[jb, COL_DYNAMIC] != 0.0:
        wstar *= row_factor(th, jb, t)  # > 0: jb lives
    wbar = wstar * cb * (1.0 - 1.1 * zz)
    r1r2 = _r1_over_r2(r2)
    r1 = r1r2 * r2
    # Allen eq. 4, 3 wbar (r2^3 - r2^2 r1) / (r2^3 - r1^3), with (r2 - r1) cancelled.
    w_peak = 3.0 * wbar / (1.0 + r1r2 + r1r2 * r1r2)
    row = int(round((r1r2 - 0.14) / 0.11))
    row = min(max(row, 0), 6)
    k = _allen_shape()
    xx = r / r2
    ws = 1.0 / (1.0 + _pow(k[row, 1] * abs(xx + k[row, 3]), k[row, 2])) + k[row, 4] * xx
    if ws < 0.0:
        ws = 0.0
    wd = 0.0
    if r > r1 and 0.5 < zz <= 0.9:
        wl = math.pi / 6.0 * math.sin(math.pi * xx)
        swd = 2.5 * (zz - 0.5)
        wd = min(swd * wl, 0.0)
    return ws * w_peak + wd * wbar


@njit(cache=True, fastmath=_FM, error_model=_EM)
def _updraft_many(n, e, h, t, th, model, zi, dvx, dvy, out) -> int:
    """``out[i]`` = the updraft at point i; returns -1, or the first i with a non-finite input
    (``out`` is then incomplete)."""
    for i in range(n.size):
        if not (math.isfinite(n[i]) and math.isfinite(e[i]) and math.isfinite(h[i]) and math.isfinite(t[i])):
            return i
        out[i] = updraft_at(n[i], e[i], h[i], t[i], th, model, zi, dvx, dvy)
    return -1
