"""soaring-env: energy-aware path planning for thermal-soaring fixed-wing aircraft."""

from soaring_env._validation import ConfigError
from soaring_env.physics import Aircraft, G, Thermal, WindField, air_density, bank_angle
from soaring_env.primitives import N_PRIMITIVES, PrimitiveLibrary, Rollout, rollout

__all__ = [
    "N_PRIMITIVES",
    "Aircraft",
    "ConfigError",
    "G",
    "PrimitiveLibrary",
    "Rollout",
    "Thermal",
    "WindField",
    "air_density",
    "bank_angle",
    "rollout",
]
__version__ = "0.1.0"
