"""International Standard Atmosphere (troposphere) and physical constants."""

from __future__ import annotations

import numpy as np
from numba import njit

from soaring_env._jit import ERROR_MODEL as _EM
from soaring_env._jit import FASTMATH as _FM

#: Standard gravity [m/s^2] (ISO 80000-3).
G = 9.80665
#: ISA sea-level density [kg/m^3], temperature [K] and lapse rate [K/m] (ISO 2533:1975).
RHO0 = 1.225
T0 = 288.15
LAPSE = 0.0065
#: ISA troposphere density exponent g / (R L) - 1 with R = 287.053 J/(kg K).
ISA_EXPONENT = 4.2559
#: Top of the ISA troposphere [m]: the density formula (and so the whole energy model) holds below it.
MAX_HEIGHT = 11000.0


@njit(cache=True, inline="always", fastmath=_FM, error_model=_EM)
def _density(h: float) -> float:
    return RHO0 * (1.0 - LAPSE * h / T0) ** ISA_EXPONENT


def _binomial_coefficients(n: float, degree: int) -> np.ndarray:
    c = [1.0]
    for i in range(1, degree + 1):
        c.append(c[-1] * (n - i + 1) / i)
    return np.array(c)


#: Taylor coefficients of (1 + x)^ISA_EXPONENT up to x^7 (see :func:`_density_near`).
_DENSITY_SERIES = _binomial_coefficients(ISA_EXPONENT, 7)
#: Largest |x| = |L (h - h_ref) / (T0 theta_ref)| (about 2 km of height) :func:`density_series` serves.
DENSITY_SERIES_MAX_X = 0.05


@njit(cache=True, inline="always", fastmath=_FM, error_model=_EM)
def density_offset(h: float, h_ref: float, theta_ref: float) -> float:
    """``x = -L (h - h_ref) / (T0 theta_ref)``: the relative temperature change from ``h_ref`` to ``h``
    [m], with ``theta_ref = 1 - L h_ref / T0``; ``rho(h) = rho(h_ref) (1 + x)^4.2559``."""
    return -LAPSE * (h - h_ref) / (T0 * theta_ref)


@njit(cache=True, inline="always", fastmath=_FM, error_model=_EM)
def density_series(x: float, rho_ref: float) -> float:
    """``rho_ref (1 + x)^4.2559`` [kg/m^3] as its degree-7 binomial series, for
    ``|x| <= DENSITY_SERIES_MAX_X``: relative error below 4e-14, at a third of the cost of the
    power function, and a loop over many heights vectorizes (one over ``pow`` does not)."""
    c = _DENSITY_SERIES
    return rho_ref * (c[0] + x * (c[1] + x * (c[2] + x * (c[3] + x * (c[4] + x * (c[5] + x * (c[6] + x * c[7])))))))


@njit(cache=True, inline="always", fastmath=_FM, error_model=_EM)
def _density_near(h: float, h_ref: float, rho_ref: float, theta_ref: float) -> float:
    """ISA density at ``h`` from its value ``rho_ref`` at a nearby height ``h_ref``:
    :func:`density_series` where it holds (|h - h_ref| up to ~2 km), else the power function."""
    x = density_offset(h, h_ref, theta_ref)
    if abs(x) > DENSITY_SERIES_MAX_X:
        return _density(h)
    return density_series(x, rho_ref)


@njit(cache=True, fastmath=_FM, error_model=_EM)
def _density_many(h: np.ndarray, out: np.ndarray) -> None:
    for i in range(h.size):
        out.flat[i] = _density(h.flat[i])


def air_density(height: np.ndarray | float) -> np.ndarray:
    """ISA troposphere air density ``rho(h) = 1.225 (1 - 0.0065 h / 288.15)^4.2559`` [kg/m^3].

    :param height: geometric height above mean sea level [m], valid below 11 km.
    """
    h = np.asarray(height, dtype=np.float64)
    if np.any(h >= MAX_HEIGHT) or not np.all(np.isfinite(h)):
        raise ValueError(f"height={height!r} must be finite and below {MAX_HEIGHT:g} m (ISA troposphere)")
    out = np.empty_like(h)
    _density_many(h, out)
    return out
