"""The soaring tasks: a thermal climb on the sensed observation tier, and what the reference gains.

    python examples/06_tasks.py

``soaring/ThermalClimbContinuous-v0`` starts low among thermals and scores the specific energy
gained in 600 s (5 s control interval, the physical envelope, a stall limit). Here a fixed
"circle at 30 deg bank, zero thrust" policy flies it with the sensed observation (the lift where the
aircraft is and was, noisy), and the thermal-climb reference search
(:func:`baselines.reference.horizon.energy_search`) shows what the scenario offers.
"""

from __future__ import annotations

import math
import os

import gymnasium as gym
import numpy as np

import soaring_env  # noqa: F401  (importing it registers the env ids)
from baselines.reference.horizon import HorizonConfig, energy_search

QUICK = os.environ.get("SOARING_EXAMPLES_QUICK") == "1"  # the tests run a smaller search

env = gym.make(
    "soaring/ThermalClimbContinuous-v0",
    scenario="climb-10000",  # a held-out climb scenario (climb-<seed>)
    observe_thermals=False,  # the sensed tier: no thermal positions ...
    history_length=4,  # ... but the last 4 edges' lift, climb rate and turn
    sensor_noise=0.2,  # m/s on every lift reading
)
obs, info = env.reset(seed=0)
base = env.unwrapped
print("observation:", ", ".join(base.observation_names))

# circle at 30 deg bank, 13 m/s, at the zero-thrust glide angle of that turn
v = 13.0
chi_dot = 9.80665 * math.tan(math.radians(30.0)) / v
gamma = float(base.model.aircraft.glide_angle(v, chi_dot, base.scenario.bounds.height_max))
action = np.clip(base.model.control_to_action(np.array([v, chi_dot, gamma])), -1, 1).astype(np.float32)
done = False
while not done:
    obs, reward, terminated, truncated, info = env.step(action)
    done = terminated or truncated
print(
    f"circling where it started: {-info['energy_spent'] / 1000:+.2f} kJ/kg in {info['time']:.0f} s ({info['outcome']})"
)

env.reset(seed=0)
ref = energy_search(base.model, "continuous", 600.0, HorizonConfig(beam_width=50 if QUICK else 500))
print(f"reference search: {ref.energy / 1000:+.2f} kJ/kg ({len(ref.actions)} actions, {ref.seconds:.1f} s)")
