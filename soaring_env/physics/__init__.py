"""Layer 1: atmosphere, aircraft and energy model, wind and thermal field (numpy + numba only)."""

from soaring_env.physics.aircraft import Aircraft, bank_angle, glide_height_loss
from soaring_env.physics.atmosphere import G, air_density
from soaring_env.physics.thermals import THERMAL_MODELS, Thermal, WindField

__all__ = ["THERMAL_MODELS", "Aircraft", "G", "Thermal", "WindField", "air_density", "bank_angle", "glide_height_loss"]
