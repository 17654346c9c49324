"""Aircraft parameters (Tempest UAS), coordinated-turn bank angle and the thrust / energy model.

Sources (see ``shared/design/physics.md`` and the README):

* Tempest UAS: Roadman, Elston, Argrow, Frew, "Mission performance of the Tempest unmanned aircraft
  system in supercell storms", J. Aircraft 49(6), 2012 -- mass 6.40 kg, wing area 0.668 m^2,
  aspect ratio 16.5 (span 3.32 m).
* Oswald factor 0.60: Raymer's estimate ``e = 1.78 (1 - 0.045 AR^0.68) - 0.64`` for AR 16.5.
* C_D0 = 0.015 (published Tempest-class range 0.011-0.019).
* eta_ec = 0.8, eta_p = 1.0: the paper (Ryu et al.), section III-C.
* Coordinated turn ``tan(phi) = v_a chi_dot / g``: Beard & McLain, *Small Unmanned Aircraft*, 2012,
  eq. 9.15 (still-air approximation).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from soaring_env._jit import ERROR_MODEL as _EM
from soaring_env._jit import FASTMATH as _FM
from soaring_env._validation import (
    ConfigError,
    as_float_array,
    broadcast_flat,
    check_array_finite,
    check_choice,
    check_positive,
    check_range,
    check_type,
)
from soaring_env.physics.atmosphere import MAX_HEIGHT, G, _density, air_density

THRUST_MODELS = ("trim", "paper")
#: A Tempest-like maximum lift coefficient [-]: the one that makes the reported stall speed of
#: 11 m/s at sea level (``stall_speed``) the wings-level stall, 2 m g / (rho0 v_s^2 S) = 1.27 for
#: 6.4 kg on 0.668 m^2 -- typical of the low-Reynolds-number sailplane airfoils of this class.
#: Used by the soaring tasks (thermal climb, cross-country); the paper's envs keep ``None``.
TEMPEST_CL_MAX = 1.27


#: Allowed ranges [low, high] of the aircraft's physical fields (units as in :class:`Aircraft`).
PHYSICAL_RANGES = {
    "mass": (1e-3, 1e5),
    "wing_area": (1e-4, 1e3),
    "aspect_ratio": (0.5, 100.0),
    "oswald": (0.05, 1.0),
    "eta_ec": (0.01, 1.0),
    "eta_p": (0.01, 1.0),
}


@dataclass(frozen=True)
class Aircraft:
    """Point-mass aircraft with a parabolic drag polar; defaults are the Tempest UAS.

    :param mass: take-off mass [kg].
    :param wing_area: reference wing area S [m^2].
    :param aspect_ratio: wing aspect ratio AR [-].
    :param oswald: Oswald span efficiency e [-].
    :param cd0: zero-lift drag coefficient C_D0 [-].
    :param cl0: fixed lift coefficient of the ``"paper"`` thrust model [-]; 0.5 is an assumption
        (the paper gives no value): the Tempest's trim C_L lies between 0.38 (20 m/s) and 1.5 (10 m/s).
    :param eta_ec: energy-source-to-shaft efficiency [-] (paper: 0.8).
    :param eta_p: propeller efficiency [-] (paper: 1.0).
    :param thrust_model: ``"trim"`` (default, lift balances weight in the coordinated turn) or
        ``"paper"`` (the paper's literal equations with a fixed C_L0).
    :param stall_speed: reported stall speed [m/s]; informative only (the paper's 10 m/s
        primitives fly below it).
    :param cl_max: maximum lift coefficient [-] (a stall limit), or ``None`` (default: the paper's
        unconstrained model). Edges whose coordinated turn needs more lift
        (:meth:`lift_coefficient`) are masked in the envs, invalid for the planners and outside the
        continuous envelope (:class:`~soaring_env.primitives.ControlEnvelope`). ``TEMPEST_CL_MAX``
        is the tasks' value.

    Mass, wing area, aspect ratio, Oswald factor and both efficiencies must lie in
    :data:`PHYSICAL_RANGES` (a ``ConfigError`` naming the field otherwise).
    """

    mass: float = 6.40
    wing_area: float = 0.668
    aspect_ratio: float = 16.5
    oswald: float = 0.60
    cd0: float = 0.015
    cl0: float = 0.5
    eta_ec: float = 0.8
    eta_p: float = 1.0
    thrust_model: str = "trim"
    stall_speed: float = 11.0
    cl_max: float | None = None

    def __post_init__(self) -> None:
        if self.cl_max is not None:
            object.__setattr__(self, "cl_max", check_range("cl_max", self.cl_max, 0.0, 5.0, low_open=True))
        # ranges that hold every fixed-wing aircraft from a micro UAV to a large sailplane; values
        # merely > 0 (e.g. a subnormal mass or efficiency) divide the thrust power to infinity
        for name, (low, high) in PHYSICAL_RANGES.items():
            object.__setattr__(self, name, check_range(name, getattr(self, name), low, high))
        object.__setattr__(self, "cl0", check_range("cl0", self.cl0, 0.0, 5.0, low_open=True))
        object.__setattr__(self, "stall_speed", check_positive("stall_speed", self.stall_speed))
        object.__setattr__(self, "cd0", check_range("cd0", self.cd0, 0.0, 1.0))
        check_type("thrust_model", self.thrust_model, str)
        check_choice("thrust_model", self.thrust_model, THRUST_MODELS)

    @property
    def weight(self) -> float:
        """Weight m g [N]."""
        return self.mass * G

    @property
    def max_lift_to_drag(self) -> float:
        """Best glide ratio (L/D)_max = sqrt(pi AR e / C_D0) / 2 of the parabolic polar [-]."""
        return 0.5 * math.sqrt(math.pi * self.aspect_ratio * self.oswald / self.cd0)

    def cruise_energy(self, distance: float) -> float:
        """Motor energy [J/kg] to fly ``distance`` [m] level in still air at the best L/D (the
        cheapest powered flight): ``distance g / ((L/D)_max eta_ec eta_p)``."""
        return float(distance) * G / (self.max_lift_to_drag * self.eta_ec * self.eta_p)

    @property
    def span(self) -> float:
        """Wing span sqrt(AR S) [m]."""
        return math.sqrt(self.aspect_ratio * self.wing_area)

    def packed(self) -> np.ndarray:
        """Parameters as the float64 vector the compiled kernels read (order: see ``_AC_*``)."""
        return np.array(
            [
                self.mass,
                self.wing_area,
                math.pi * self.aspect_ratio * self.oswald,
                self.cd0,
                self.cl0,
                self.eta_ec * self.eta_p,
                0.0 if self.thrust_model == "trim" else 1.0,
            ],
            dtype=np.float64,
        )

    def thrust(self, airspeed, gamma, bank, height) -> np.ndarray:
        """Required thrust [N] for steady flight (clipped at 0: no regeneration).

        :param airspeed: v_a [m/s]; :param gamma: flight path angle [rad];
        :param bank: bank angle phi [rad]; :param height: height [m] (for the ISA density).
        """
        v, g_, p, h = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (airspeed, gamma, bank, height)))
        for name, arr, ok in (
            ("airspeed", v, v > 0.0),
            ("gamma", g_, np.abs(g_) < math.pi / 2),
            ("bank", p, np.abs(p) < math.pi / 2),
            ("height", h, h < MAX_HEIGHT),
        ):
            if not np.all(ok & np.isfinite(arr)):
                raise ConfigError(
                    f"{name}={arr[~(ok & np.isfinite(arr))].ravel()[0]!r} is invalid; allowed: finite, airspeed > 0, "
                    "|gamma| < pi/2, |bank| < pi/2, height < 11000 m"
                )
        out = np.empty(v.shape)
        ac = self.packed()
        for i in np.ndindex(v.shape):
            out[i] = _thrust(float(v[i]), float(g_[i]), math.cos(p[i]), float(h[i]), ac)
        return out

    def glide_angle(self, airspeed, chi_dot, height_max: float) -> np.ndarray:
        """The shallowest path angle [rad] in [-45 deg, 0] at which steady coordinated flight at
        ``airspeed`` [m/s] and course rate ``chi_dot`` [rad/s] needs no thrust at any height in
        [0, ``height_max``] m (-45 deg where even that needs thrust). Broadcasts over its arguments.

        The trim thrust ``a rho + b / rho + c`` is convex in the air density rho, so it is zero on
        the whole height range when it is zero at both ends; the angle is found by bisection
        (60 halvings: to within 1e-17 rad, then the side that needs no thrust is kept).
        """
        shape, (v, w) = broadcast_flat(airspeed, chi_dot)
        if not (np.all(np.isfinite(v) & (v > 0.0)) and np.all(np.isfinite(w))):
            raise ConfigError("airspeed and chi_dot must be finite and airspeed > 0 m/s")
        h = check_range("height_max", height_max, 0.0, MAX_HEIGHT, high_open=True)
        out = np.empty(v.shape)
        _glide_angles(v, w, h, self.packed(), out)
        return out.reshape(shape)

    def lift_coefficient(self, airspeed, gamma, bank, height) -> np.ndarray:
        """Lift coefficient [-] of steady coordinated flight, ``C_L = 2 m g cos(gamma) / (rho v_a^2 S cos(phi))``
        (the lift balances weight in the turn: the "trim" model's lift, whichever thrust model).

        :param airspeed: v_a [m/s]; :param gamma: path angle [rad]; :param bank: bank angle [rad];
        :param height: height [m] (ISA density).
        """
        v, g_, p, h = (
            np.array(a)
            for a in np.broadcast_arrays(*(np.asarray(x, np.float64) for x in (airspeed, gamma, bank, height)))
        )
        if not (np.all(np.isfinite(v) & (v > 0.0)) and np.all(np.abs(p) < math.pi / 2) and np.all(np.isfinite(g_))):
            raise ConfigError("airspeed must be finite and > 0 m/s, bank within (-90, 90) deg, gamma finite")
        rho = air_density(h)
        return 2.0 * self.weight * np.cos(g_) / (rho * v * v * self.wing_area * np.cos(p))

    def max_bank(self, airspeed, height: float) -> np.ndarray:
        """Largest bank angle [rad] at which level coordinated flight at ``airspeed`` [m/s] stays within
        ``cl_max`` at ``height`` [m] (pi/2 without a stall limit; 0 where even wings level stalls)."""
        v = np.asarray(airspeed, dtype=np.float64)
        if self.cl_max is None:
            return np.full(v.shape, 0.5 * math.pi)
        rho = float(air_density(height))
        cos_min = 2.0 * self.weight / (rho * v * v * self.wing_area * self.cl_max)
        return np.arccos(np.clip(cos_min, 0.0, 1.0))

    def fuel_power(self, airspeed, gamma, bank, height) -> np.ndarray:
        """Specific fuel power ``T v_a / (m eta_ec eta_p)`` [W/kg] = [J/(kg s)]."""
        t = self.thrust(airspeed, gamma, bank, height)
        return t * np.asarray(airspeed, dtype=np.float64) / (self.mass * self.eta_ec * self.eta_p)


def bank_angle(airspeed, chi_dot) -> np.ndarray:
    """Bank angle of the coordinated turn ``phi = atan(v_a chi_dot / g)`` [rad].

    :param airspeed: v_a [m/s]; :param chi_dot: course rate [rad/s].
    """
    return np.arctan(np.asarray(airspeed, dtype=np.float64) * np.asarray(chi_dot, dtype=np.float64) / G)


def glide_height_loss(distance, airspeed, angle, along, cross) -> np.ndarray:
    """Height [m] a straight zero-thrust glide loses over ``distance`` [m] of ground track, at
    ``airspeed`` [m/s] and path angle ``angle`` [rad] (< 0), with the wind ``along`` the track and
    ``cross`` it [m/s] (crabbing into the crosswind); inf where the ground speed along the track is
    not above 0.1 m/s. Arrays broadcast. What a final-glide computer shows, and the speed to fly
    in still air: the airspeed of least loss.

    :raises ConfigError: naming the argument, for a value that is not a finite number.
    """
    given = {"distance": distance, "airspeed": airspeed, "angle": angle, "along": along, "cross": cross}
    arrays = {name: as_float_array(name, x) for name, x in given.items()}
    for name, x in arrays.items():
        check_array_finite(name, x)
    d, v, g, w_along, w_cross = arrays.values()
    va = v * np.cos(g)  # horizontal airspeed
    ground = np.sqrt(np.maximum(va**2 - w_cross**2, 0.0)) + w_along
    ok = ground > 0.1
    return np.where(ok, d * (-v * np.sin(g)) / np.where(ok, ground, 1.0), np.inf)


# Indices into Aircraft.packed(); kept next to the kernels that read them.
_AC_MASS, _AC_S, _AC_PIARE, _AC_CD0, _AC_CL0, _AC_ETA, _AC_MODEL = range(7)


@njit(cache=True, inline="always", fastmath=_FM, error_model=_EM)
def _thrust_coeffs(v: float, gamma: float, cos_phi: float, ac: np.ndarray) -> tuple[float, float, float, float]:
    """Constants of the steady-flight thrust as a function of the air density rho.

    "trim": ``T = a rho + b / rho + c``; "paper": ``T = sqrt((a rho + c)^2 + (b rho - d)^2)``.
    Split out so that the rollout evaluates them once per control segment, not per point.
    """
    half_v2s = 0.5 * v * v * ac[_AC_S]
    w = ac[_AC_MASS] * G
    if ac[_AC_MODEL] == 0.0:
        # "trim": dgamma/dt = 0 in the coordinated turn -> L = m g cos(gamma) / cos(phi);
        # D = q S C_D0 + L^2 / (q S pi AR e), T = D + m g sin(gamma).
        lift = w * math.cos(gamma) / cos_phi
        return half_v2s * ac[_AC_CD0], lift * lift / (half_v2s * ac[_AC_PIARE]), w * math.sin(gamma), 0.0
    # "paper": fixed C_L0, T_x = D + m g sin(gamma), T_z = L - m g cos(gamma) / cos(phi).
    cl = ac[_AC_CL0]
    return (
        half_v2s * (ac[_AC_CD0] + cl * cl / ac[_AC_PIARE]),
        half_v2s * cl,
        w * math.sin(gamma),
        w * math.cos(gamma) / cos_phi,
    )


@njit(cache=True, inline="always", fastmath=_FM, error_model=_EM)
def _thrust_at(rho: float, k: tuple[float, float, float, float], model: float) -> float:
    """Thrust [N] from :func:`_thrust_coeffs`, clipped at zero (no regeneration)."""
    if model == 0.0:
        t = k[0] * rho + k[1] / rho + k[2]
    else:
        tx = k[0] * rho + k[2]
        tz = k[1] * rho - k[3]
        t = math.sqrt(tx * tx + tz * tz)
    return t if t > 0.0 else 0.0


@njit(cache=True, fastmath=_FM, error_model=_EM)
def _thrust(v: float, gamma: float, cos_phi: float, h: float, ac: np.ndarray) -> float:
    """Steady-flight thrust [N], clipped at zero; see :meth:`Aircraft.thrust`."""
    return _thrust_at(_density(h), _thrust_coeffs(v, gamma, cos_phi, ac), ac[_AC_MODEL])


@njit(cache=True, fastmath=_FM, error_model=_EM)
def _glide_angles(v: np.ndarray, chi_dot: np.ndarray, h_max: float, ac: np.ndarray, out: np.ndarray) -> None:
    """Kernel of :meth:`Aircraft.glide_angle` (writes ``out``). Its thrust is the same expression as
    :meth:`Aircraft.thrust`'s, compiled in another context: the two agree to about 1e-16 N."""
    rho_lo = _density(0.0)
    rho_hi = _density(h_max)
    for i in range(v.shape[0]):
        cos_phi = math.cos(math.atan(v[i] * chi_dot[i] / G))
        lo = -0.25 * math.pi
        hi = 0.0
        k = _thrust_coeffs(v[i], lo, cos_phi, ac)
        if _thrust_at(rho_lo, k, ac[_AC_MODEL]) > 0.0 or _thrust_at(rho_hi, k, ac[_AC_MODEL]) > 0.0:
            out[i] = lo  # no glide within the envelope; the steepest angle is the closest
            continue
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            k = _thrust_coeffs(v[i], mid, cos_phi, ac)
            if _thrust_at(rho_lo, k, ac[_AC_MODEL]) > 0.0 or _thrust_at(rho_hi, k, ac[_AC_MODEL]) > 0.0:
                hi = mid
            else:
                lo = mid
        out[i] = lo
