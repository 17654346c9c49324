"""Shared fixtures and hypothesis settings for the soaring-env test suite.

Hypothesis runs without a per-example deadline everywhere: the first call of a numba kernel compiles
it (seconds), which would otherwise trip the default 200 ms deadline. Select a profile with the
``SOARING_HYPOTHESIS_PROFILE`` environment variable: ``dev`` (default, random) or ``ci``
(derandomized: the same examples on every run).
"""

from __future__ import annotations

import os
from collections.abc import Callable

import numpy as np
import pytest
from hypothesis import settings

from soaring_env import Aircraft, PrimitiveLibrary, WindField
from soaring_env.primitives import FAMILIES

settings.register_profile("dev", deadline=None, print_blob=True)
settings.register_profile("ci", deadline=None, print_blob=True, derandomize=True)
settings.load_profile(os.environ.get("SOARING_HYPOTHESIS_PROFILE", "dev"))


@pytest.fixture(scope="session")
def library() -> PrimitiveLibrary:
    """The default primitive library (Ts = 30 s, N = 30)."""
    return PrimitiveLibrary()


@pytest.fixture(scope="session")
def aircraft() -> Aircraft:
    """The default aircraft (Tempest UAS, ``"trim"`` thrust model)."""
    return Aircraft()


@pytest.fixture(scope="session")
def still_air() -> WindField:
    """No wind, no thermals."""
    return WindField()


@pytest.fixture
def rng() -> np.random.Generator:
    """A fixed-seed generator: tests that draw random points are reproducible."""
    return np.random.default_rng(20240607)


def _find_primitive(lib: PrimitiveLibrary, family: str, airspeed: float, gamma_deg: float, turn_deg: float) -> int:
    t = lib.table
    hit = np.flatnonzero(
        (t[:, 0] == FAMILIES.index(family))
        & (t[:, 1] == airspeed)
        & np.isclose(np.degrees(t[:, 2]), gamma_deg, rtol=0.0, atol=1e-9)
        & np.isclose(np.degrees(t[:, 3]) * lib.duration, turn_deg, rtol=0.0, atol=1e-9)
    )
    assert hit.size == 1, f"expected exactly one {family} primitive v={airspeed} gamma={gamma_deg} turn={turn_deg}"
    return int(hit[0])


@pytest.fixture(scope="session")
def primitive_index() -> Callable[[PrimitiveLibrary, str, float, float, float], int]:
    """``primitive_index(lib, family, airspeed, gamma_deg, turn_deg) -> index``: the first-half turn
    rate times Ts is matched in degrees; searched by value so tests do not depend on the order."""
    return _find_primitive
