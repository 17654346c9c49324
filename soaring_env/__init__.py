"""soaring-env: energy-aware path planning for thermal-soaring fixed-wing aircraft."""

from soaring_env._validation import ConfigError
from soaring_env.env import (
    CONTINUOUS_ENV_ID,
    ENV_ID,
    SoaringContinuousEnv,
    SoaringEnv,
    SoaringEnvConfig,
    register_envs,
)
from soaring_env.physics import Aircraft, G, Thermal, WindField, air_density, bank_angle
from soaring_env.primitives import N_PRIMITIVES, PrimitiveLibrary, Rollout, rollout
from soaring_env.scenario import Scenario, get_scenario, make_scenario

# The Gymnasium envs register at import: gymnasium 1.x loads no entry-point plugins.
register_envs()

__all__ = [
    "CONTINUOUS_ENV_ID",
    "ENV_ID",
    "N_PRIMITIVES",
    "Aircraft",
    "ConfigError",
    "G",
    "PrimitiveLibrary",
    "Rollout",
    "Scenario",
    "SoaringContinuousEnv",
    "SoaringEnv",
    "SoaringEnvConfig",
    "Thermal",
    "WindField",
    "air_density",
    "bank_angle",
    "get_scenario",
    "make_scenario",
    "rollout",
]
__version__ = "0.1.0"
