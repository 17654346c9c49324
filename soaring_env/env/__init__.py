"""Layer 4: the Gymnasium environments (a thin shell over the model API).

Registered at ``import soaring_env``:

* ``soaring/Soaring-v0`` -- :class:`SoaringEnv`, ``Discrete(174)`` motion primitives;
* ``soaring/SoaringContinuous-v0`` -- :class:`SoaringContinuousEnv`, ``Box(-1, 1, (3,))`` controls.

Both with ``max_episode_steps=40`` (40 x 30 s = 20 min) and a natively batched
``vector_entry_point`` (:class:`~soaring_env.env.vector.SoaringVectorEnv`). In subprocess workers
(spawn / forkserver) use the module-qualified ids ``"soaring_env:soaring/Soaring-v0"``.
"""

from __future__ import annotations

import gymnasium as gym

from soaring_env.env.config import ENERGY_SCALE, SoaringEnvConfig
from soaring_env.env.core import SoaringBaseEnv, SoaringContinuousEnv, SoaringEnv
from soaring_env.env.vector import SoaringContinuousVectorEnv, SoaringVectorEnv

ENV_ID = "soaring/Soaring-v0"
CONTINUOUS_ENV_ID = "soaring/SoaringContinuous-v0"
#: 40 steps of Ts = 30 s: 20 minutes of flight.
MAX_EPISODE_STEPS = 40


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
                max_episode_steps=MAX_EPISODE_STEPS,
            )


__all__ = [
    "CONTINUOUS_ENV_ID",
    "ENERGY_SCALE",
    "ENV_ID",
    "MAX_EPISODE_STEPS",
    "SoaringBaseEnv",
    "SoaringContinuousEnv",
    "SoaringContinuousVectorEnv",
    "SoaringEnv",
    "SoaringEnvConfig",
    "SoaringVectorEnv",
    "register_envs",
]
