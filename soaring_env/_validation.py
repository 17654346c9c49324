"""Validation helpers shared by every config: errors name the field, the value and what is allowed."""

from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np


class ConfigError(ValueError):
    """An invalid parameter; the message names the field, the value and the allowed range."""


def check_finite(name: str, value: float) -> float:
    """Return ``value`` as a float, or raise if it is NaN, infinite or not a number."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ConfigError(f"{name}={value!r} is not a number; a finite real number is required") from None
    if not math.isfinite(v):
        raise ConfigError(f"{name}={value!r} is not finite; a finite real number is required")
    return v


def check_positive(name: str, value: float) -> float:
    v = check_finite(name, value)
    if v <= 0.0:
        raise ConfigError(f"{name}={value!r} must be > 0")
    return v


def check_range(
    name: str, value: float, low: float, high: float, *, low_open: bool = False, high_open: bool = False
) -> float:
    """Check ``low <= value <= high`` (open ends where asked)."""
    v = check_finite(name, value)
    bad_low = v <= low if low_open else v < low
    bad_high = v >= high if high_open else v > high
    if bad_low or bad_high:
        lb = "(" if low_open else "["
        hb = ")" if high_open else "]"
        raise ConfigError(f"{name}={value!r} is outside the allowed range {lb}{low:g}, {high:g}{hb}")
    return v


def check_int(name: str, value: int, low: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ConfigError(f"{name}={value!r} must be an integer >= {low}")
    if value < low:
        raise ConfigError(f"{name}={value!r} must be an integer >= {low}")
    return int(value)


def check_choice(name: str, value: str, choices: Iterable[str]) -> str:
    options = tuple(choices)
    if value not in options:
        raise ConfigError(f"{name}={value!r} is unknown; allowed: {', '.join(map(repr, options))}")
    return value


def check_array_finite(name: str, arr: np.ndarray) -> None:
    if not np.all(np.isfinite(arr)):
        bad = np.argwhere(~np.isfinite(arr))[0]
        raise ConfigError(
            f"{name} contains a non-finite value {arr[tuple(bad)]!r} at index {tuple(int(i) for i in bad)}; "
            "all entries must be finite"
        )
