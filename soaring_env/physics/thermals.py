"""The air: constant ambient wind plus thermal updrafts (Allen 2006 or Gaussian).

Allen's model: M. J. Allen, "Updraft model for development of autonomous soaring uninhabited air
vehicles", AIAA 2006-1510, eqs. 1-8 and the MATLAB routine of its appendix; the formulas and the
decisions it leaves open are in ``shared/design/physics.md``. The Gaussian thermal
``w = W exp(-r^2 / R^2)`` summed over thermals is the one of ArduPilot's SITL soaring simulation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from soaring_env._jit import FASTMATH as _FM
from soaring_env._validation import (
    ConfigError,
    broadcast_flat,
    check_bool,
    check_choice,
    check_finite,
    check_positive,
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
#: Columns of :attr:`WindField.packed` (the kernels' thermal rows): north, east, strength,
#: radius-or-influence. Code that allocates thermal tables uses this width.
PACKED_COLUMNS = 4


@dataclass(frozen=True)
class Thermal:
    """One thermal column.

    :param north: centre north position at t = 0 [m].
    :param east: centre east position at t = 0 [m].
    :param strength: Allen's convective velocity scale w* [m/s], or the Gaussian peak W [m/s].
    :param radius: Gaussian radius R [m] (Allen's radii follow from zi and the height instead).
    """

    north: float
    east: float
    strength: float = 2.56
    radius: float = 80.0

    def __post_init__(self) -> None:
        # stored as floats: a value given as a numpy scalar or int must not reach the kernels' packing as such
        object.__setattr__(self, "north", check_finite("thermal.north", self.north))
        object.__setattr__(self, "east", check_finite("thermal.east", self.east))
        object.__setattr__(self, "strength", check_positive("thermal.strength", self.strength))
        object.__setattr__(self, "radius", check_positive("thermal.radius", self.radius))


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
    #: an upper bound on the updraft anywhere [m/s]: Allen 1.2 max w* (its peak stays below 1.1 w*),
    #: Gaussian the sum of the peaks (overlapping thermals add up).
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
        object.__setattr__(self, "wind_north", check_finite("wind_north", self.wind_north))
        object.__setattr__(self, "wind_east", check_finite("wind_east", self.wind_east))
        object.__setattr__(self, "drift", check_bool("drift", self.drift))
        allen = self.model == "allen"
        rows = [[t.north, t.east, t.strength, self._influence(t) if allen else t.radius] for t in self.thermals]
        packed = np.array(rows, dtype=np.float64).reshape(-1, PACKED_COLUMNS)
        packed.setflags(write=False)
        object.__setattr__(self, "_packed", packed)
        w = packed[:, 2]
        object.__setattr__(self, "updraft_bound", float(1.2 * w.max() if allen else w.sum()) if w.size else 0.0)

    def _influence(self, t: Thermal) -> float:
        if self.model == "allen":
            return 2.0 * max(10.0, ALLEN_R2_MAX_PER_ZI * self.zi)
        return GAUSSIAN_CUTOFF * t.radius

    @property
    def packed(self) -> np.ndarray:
        """(n, 4) float64 [north, east, strength, radius-or-influence] read by the kernels."""
        return self._packed

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

        :param north: [m]; :param east: [m]; :param height: [m]; :param t: time [s] (drift only).
        """
        shape, arrays = broadcast_flat(north, east, height, t)
        for name, a in zip(("north", "east", "height", "t"), arrays, strict=True):
            if not np.all(np.isfinite(a)):
                raise ConfigError(f"{name} contains non-finite values; all points must be finite")
        n, e, h, tt = arrays
        out = np.empty(n.shape)
        dvx, dvy = (self.wind_north, self.wind_east) if self.drift else (0.0, 0.0)
        _updraft_many(n, e, h, tt, self._packed, self.model_code, self.zi, dvx, dvy, out)
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


@njit(cache=True, inline="always", fastmath=_FM)
def allen_reach(z: float, zi: float) -> float:
    """2 r2 at height ``z`` [m]: no Allen updraft or downdraft beyond it (r2 grows with z below zi)."""
    zz = min(max(z, 0.0), zi) / zi
    return 2.0 * max(10.0, 0.102 * _pow(zz, 1.0 / 3.0) * (1.0 - 0.25 * zz) * zi)


@njit(cache=True, inline="always", fastmath=_FM)
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


@njit(cache=True, inline="always", fastmath=_FM)
def _pow(x: float, y: float) -> float:
    """``x ** y`` for ``x >= 0`` as ``exp(y log x)``, relative error about ``|y ln x| 2^-53`` (< 1e-14
    for results between 1e-39 and 1e39) at about half the latency of libm's pow: the updraft sits on
    the height integration's serial dependency chain, so its latency is the rollout's cost."""
    return math.exp(y * math.log(x))


@njit(cache=True, inline="always", fastmath=_FM)
def _r1_over_r2(r2: float) -> float:
    return 0.0011 * r2 + 0.14 if r2 < 600.0 else 0.8


@njit(cache=True, fastmath=_FM)
def _allen_shape() -> np.ndarray:
    return ALLEN_SHAPE


@njit(cache=True, fastmath=_FM)
def updraft_at(
    x: float, y: float, z: float, t: float, th: np.ndarray, model: int, zi: float, dvx: float, dvy: float
) -> float:
    """Updraft [m/s] at one point; the single definition every caller compiles in."""
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
                w += th[j, 2] * math.exp(-d2 / (r * r))
        return w
    best = np.inf
    jb = -1
    for j in range(n):
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
    wbar = th[jb, 2] * cb * (1.0 - 1.1 * zz)
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


@njit(cache=True, fastmath=_FM)
def _updraft_many(n, e, h, t, th, model, zi, dvx, dvy, out) -> None:
    for i in range(n.size):
        out[i] = updraft_at(n[i], e[i], h[i], t[i], th, model, zi, dvx, dvy)
