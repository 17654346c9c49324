"""Layer 4: the Gymnasium environments (a thin shell over the model API).

Registered at ``import soaring_env``:

* ``soaring/Soaring-v0`` -- :class:`SoaringEnv`, ``Discrete(174)`` motion primitives;
* ``soaring/SoaringContinuous-v0`` -- :class:`SoaringContinuousEnv`, ``Box(-1, 1, (3,))`` controls;

both truncated by the env itself after ``max_steps=40`` steps (40 x 30 s = 20 min); and the tasks of
:mod:`soaring_env.env.tasks`, which truncate by their own ``time_limit``. No id registers
``max_episode_steps``: the env owns its limit, so a ``step()`` after truncation raises.

* ``soaring/ThermalClimb-v0``, ``soaring/ThermalClimbContinuous-v0`` -- gain energy in 600 s;
* ``soaring/CrossCountry-v0``, ``soaring/CrossCountryContinuous-v0`` -- a goal 8-15 km away on a
  small battery.

Every id has a natively batched ``vector_entry_point`` (:class:`~soaring_env.env.vector.SoaringVectorEnv`).
In subprocess workers (spawn / forkserver) use the module-qualified ids ``"soaring_env:soaring/Soaring-v0"``.
"""

from __future__ import annotations

import gymnasium as gym

from soaring_env.env.config import ENERGY_SCALE, MAX_EPISODE_STEPS, SoaringEnvConfig
from soaring_env.env.core import SoaringBaseEnv, SoaringContinuousEnv, SoaringEnv
from soaring_env.env.tasks import (
    TASK_ENVS,
    CrossCountryConfig,
    CrossCountryContinuousConfig,
    CrossCountryContinuousEnv,
    CrossCountryEnv,
    ThermalClimbConfig,
    ThermalClimbContinuousConfig,
    ThermalClimbContinuousEnv,
    ThermalClimbEnv,
)
from soaring_env.env.vector import SoaringContinuousVectorEnv, SoaringVectorEnv

ENV_ID = "soaring/Soaring-v0"
CONTINUOUS_ENV_ID = "soaring/SoaringContinuous-v0"


def register_envs() -> None:
    """Register both ids with gymnasium (idempotent: ids already registered are left alone)."""
    specs = (
        (ENV_ID, "soaring_env.env.core:SoaringEnv", "soaring_env.env.vector:SoaringVectorEnv"),
        (
            CONTINUOUS_ENV_ID,
            "soaring_env.env.core:SoaringContinuousEnv",
            "soaring_env.env.vector:SoaringContinuousVectorEnv",
        ),
    )
    for env_id, entry, vector_entry in specs:
        if env_id not in gym.registry:
            gym.register(
                id=env_id,
                entry_point=entry,
                vector_entry_point=vector_entry,
            )  # truncated by the env's own max_steps (MAX_EPISODE_STEPS)
    for suffix, (single, vector) in TASK_ENVS.items():
        env_id = f"soaring/{suffix}"
        if env_id not in gym.registry:
            gym.register(
                id=env_id,
                entry_point=f"{single.__module__}:{single.__name__}",
                vector_entry_point=f"{vector.__module__}:{vector.__name__}",
            )


#: Every registered id: goal reaching, thermal climb, cross-country (primitives and continuous).
ENV_IDS = (ENV_ID, CONTINUOUS_ENV_ID, *(f"soaring/{k}" for k in TASK_ENVS))

__all__ = [
    "CONTINUOUS_ENV_ID",
    "ENERGY_SCALE",
    "ENV_ID",
    "ENV_IDS",
    "MAX_EPISODE_STEPS",
    "TASK_ENVS",
    "CrossCountryConfig",
    "CrossCountryContinuousConfig",
    "CrossCountryContinuousEnv",
    "CrossCountryEnv",
    "SoaringBaseEnv",
    "SoaringContinuousEnv",
    "SoaringContinuousVectorEnv",
    "SoaringEnv",
    "SoaringEnvConfig",
    "SoaringVectorEnv",
    "ThermalClimbConfig",
    "ThermalClimbContinuousConfig",
    "ThermalClimbContinuousEnv",
    "ThermalClimbEnv",
    "register_envs",
]
