"""Validation helpers shared by every config: errors name the field, the value and what is allowed."""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

import numpy as np


class ConfigError(ValueError):
    """An invalid parameter; the message names the field, the value and the allowed range."""


def check_finite(name: str, value: float) -> float:
    """Return ``value`` as a Python float, or raise if it is NaN, infinite or not a number.

    Strings, bytes and bools are refused rather than converted: ``"3"`` in a numeric field is a
    typing mistake (a JSON or command-line value that was never parsed), and ``True`` is not a
    quantity. Callers store the returned float, so every config holds plain floats.
    """
    if isinstance(value, (str, bytes, bool, np.bool_)):
        raise ConfigError(
            f"{name}={value!r} has type {type(value).__name__}; a finite real number (int or float) is required"
        )
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


def check_int(name: str, value: int, low: int, high: int | None = None) -> int:
    """Return ``value`` as an int in ``[low, high]`` (no upper limit if ``high`` is None)."""
    allowed = f"an integer >= {low}" if high is None else f"an integer in [{low}, {high}]"
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ConfigError(f"{name}={value!r} must be {allowed}")
    if value < low or (high is not None and value > high):
        raise ConfigError(f"{name}={value!r} must be {allowed}")
    return int(value)


def check_bool(name: str, value: bool) -> bool:
    if not isinstance(value, (bool, np.bool_)):
        raise ConfigError(f"{name}={value!r} has type {type(value).__name__}; a bool is required")
    return bool(value)


def check_type(name: str, value: object, cls: type | tuple[type, ...], what: str | None = None) -> None:
    """Raise unless ``value`` is an instance of ``cls`` (``what`` describes it in the message)."""
    if not isinstance(value, cls):
        names = what or " or ".join(c.__name__ for c in (cls if isinstance(cls, tuple) else (cls,)))
        raise ConfigError(f"{name}={value!r} has type {type(value).__name__}; {names} is required")


def check_seed(name: str, value: int | None) -> int | None:
    """A random seed: None or an integer in [0, 2^63) (what ``np.random.default_rng`` accepts)."""
    if value is None:
        return None
    return check_int(name, value, 0, 2**63 - 1)


def check_pair(name: str, value: object, low: float, high: float, *, integer: bool = False) -> tuple[float, float]:
    """An ordered pair ``(a, b)`` with ``low <= a <= b <= high``, all finite (integers if asked)."""
    kind = "integers" if integer else "finite numbers"
    msg = f"{name}={value!r} must be a pair (low, high) of {kind} with {low:g} <= low <= high <= {high:g}"
    if isinstance(value, (str, bytes)) or not hasattr(value, "__len__") or len(value) != 2:  # type: ignore[arg-type]
        raise ConfigError(msg)
    a: Any = value[0]  # type: ignore[index]
    b: Any = value[1]  # type: ignore[index]
    pa: float
    pb: float
    try:
        if integer:
            pa, pb = check_int(f"{name}[0]", a, -(2**62)), check_int(f"{name}[1]", b, -(2**62))
        else:
            pa, pb = check_finite(f"{name}[0]", a), check_finite(f"{name}[1]", b)
    except ConfigError:
        raise ConfigError(msg) from None
    if not low <= pa <= pb <= high:
        raise ConfigError(msg)
    return pa, pb


def as_float_array(name: str, value: object) -> np.ndarray:
    """``value`` as a float64 array, or a ConfigError naming ``name``: real numbers only (no strings,
    bools, objects or ragged lists -- numpy would convert ``"3"`` silently or fail with its own message)."""
    if type(value) is np.ndarray and value.dtype == np.float64:  # the hot path: nothing to convert
        return value
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError):
        raise ConfigError(f"{name}={value!r} is not an array of numbers (ragged or mixed)") from None
    if arr.dtype.kind not in "fiu":
        raise ConfigError(f"{name}={value!r} has dtype {arr.dtype}; real numbers are required")
    return arr.astype(np.float64, copy=False)


def broadcast_flat(*values: object) -> tuple[tuple[int, ...], list[np.ndarray]]:
    """Broadcast ``values`` together: their common shape, and each as a flat C-contiguous float64
    array -- the caller's own memory where it already has that shape, else a fresh copy.

    Never a view from ``np.broadcast_arrays``: numba reads the ``writeable`` flag of every array
    argument, and numpy >= 2 answers that on such a view with a FutureWarning.
    """
    arrays = [np.asarray(v, dtype=np.float64) for v in values]
    shape = np.broadcast_shapes(*(a.shape for a in arrays))
    flat = [
        np.ascontiguousarray(a).reshape(-1) if a.shape == shape else np.broadcast_to(a, shape).flatten() for a in arrays
    ]
    return shape, flat


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
