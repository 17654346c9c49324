"""The soaring tasks beyond goal reaching: thermal climb and energy-limited cross-country.

Each task is a config class (its defaults and extra fields), a pair of env classes (174 primitives
and continuous controls) and their natively batched vector envs; all share the goal-reaching envs'
model, kernels and API (:mod:`soaring_env.env.core`). Registered ids: see :mod:`soaring_env.env`.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar

from soaring_env._validation import check_finite, check_range
from soaring_env.env.config import ScenarioSpec, SoaringEnvConfig
from soaring_env.env.core import SoaringBaseEnv, SoaringContinuousEnv, SoaringEnv
from soaring_env.env.vector import SoaringContinuousVectorEnv, SoaringVectorEnv
from soaring_env.model import BATTERY_EMPTY, GOAL
from soaring_env.physics.aircraft import TEMPEST_CL_MAX, Aircraft
from soaring_env.scenario import Scenario, make_climb_scenario, make_cross_country_scenario

#: Control intervals [s] the continuous tasks accept: from a few seconds (an agent can centre a
#: thermal) to the paper's 30 s; shorter edges would need finer event points than the default.
CONTROL_INTERVAL = (1.0, 30.0)


def _tempest_with_stall_limit() -> Aircraft:
    return Aircraft(cl_max=TEMPEST_CL_MAX)


def _check_interval(cfg: SoaringEnvConfig) -> None:
    check_range("duration", cfg.duration, *CONTROL_INTERVAL)


@dataclass(frozen=True)
class ThermalClimbConfig(SoaringEnvConfig):
    """:class:`~soaring_env.env.config.SoaringEnvConfig` of the thermal-climb task (primitives).

    Differences from goal reaching: scenarios from :func:`~soaring_env.scenario.make_climb_scenario`
    (``"random"`` by default; ``random_scenario`` takes its keywords; named ``climb-<seed>``), a
    Tempest-like stall limit (``Aircraft(cl_max=TEMPEST_CL_MAX)``: the 10 m/s primitives are
    masked), ``time_limit`` 600 s, no progress shaping (there is no goal).
    """

    generator: ClassVar[Callable[..., Scenario]] = staticmethod(make_climb_scenario)
    scenario: ScenarioSpec = "random"
    aircraft: Aircraft = dataclasses.field(default_factory=_tempest_with_stall_limit)
    progress_weight: float = 0.0
    time_limit: float | None = 600.0
    max_steps: int | None = None  # truncated by time_limit


@dataclass(frozen=True)
class ThermalClimbContinuousConfig(ThermalClimbConfig):
    """The thermal-climb config of the continuous env: the physical envelope
    (:meth:`~soaring_env.primitives.ControlEnvelope.physical`) and a 5 s control interval
    (``duration`` in [1, 30] s), 10 event points per edge."""

    duration: float = 5.0
    n_points: int = 10
    envelope: str = "physical"

    def __post_init__(self) -> None:
        super().__post_init__()
        _check_interval(self)


@dataclass(frozen=True)
class CrossCountryConfig(SoaringEnvConfig):
    """:class:`~soaring_env.env.config.SoaringEnvConfig` of the energy-limited cross-country task.

    Scenarios from :func:`~soaring_env.scenario.make_cross_country_scenario` (named
    ``xc-<seed>``); the stall limit; ``time_limit`` 3600 s; positions scaled by 2 km (goals lie
    8-15 km away).

    :param battery_fraction: the battery [J/kg] as a fraction of the motor energy of the cheapest
        powered flight straight to the goal (level, best L/D, still air:
        :meth:`~soaring_env.physics.aircraft.Aircraft.cruise_energy`), in (0, 10]; the default 0.25
        leaves three quarters of the distance to be flown on thermals.
    :param battery_penalty: reward subtracted when the battery runs empty.
    """

    generator: ClassVar[Callable[..., Scenario]] = staticmethod(make_cross_country_scenario)
    scenario: ScenarioSpec = "random"
    aircraft: Aircraft = dataclasses.field(default_factory=_tempest_with_stall_limit)
    position_scale: float = 2000.0
    time_limit: float | None = 3600.0
    max_steps: int | None = None  # truncated by time_limit
    battery_fraction: float = 0.25
    battery_penalty: float = 25.0

    def __post_init__(self) -> None:
        super().__post_init__()
        frac = check_range("battery_fraction", self.battery_fraction, 0.0, 10.0, low_open=True)
        object.__setattr__(self, "battery_fraction", frac)
        object.__setattr__(self, "battery_penalty", check_finite("battery_penalty", self.battery_penalty))


@dataclass(frozen=True)
class CrossCountryContinuousConfig(CrossCountryConfig):
    """The cross-country config of the continuous env: the physical envelope and a 10 s control
    interval (``duration`` in [1, 30] s), 10 event points per edge."""

    duration: float = 10.0
    n_points: int = 10
    envelope: str = "physical"

    def __post_init__(self) -> None:
        super().__post_init__()
        _check_interval(self)


# --- the task hooks ----------------------------------------------------------------------------------
class _ThermalClimb(SoaringBaseEnv):
    has_goal: ClassVar[bool] = False

    def _terminal_terms(self) -> list[tuple[str, int, float]]:
        return [t for t in super()._terminal_terms() if t[1] != GOAL]  # no goal, no bonus


class _CrossCountry(SoaringBaseEnv):
    has_battery: ClassVar[bool] = True
    task_extras: ClassVar[tuple[str, ...]] = ("battery",)

    def _terminal_terms(self) -> list[tuple[str, int, float]]:
        cfg = self.config
        assert isinstance(cfg, CrossCountryConfig)
        return [*super()._terminal_terms(), ("battery_empty", BATTERY_EMPTY, -float(cfg.battery_penalty))]

    def _battery_budget_at(self, goal_north: float, goal_east: float, start_north: float, start_east: float) -> float:
        """``battery_fraction`` x the motor energy [J/kg] of level best-L/D flight straight to the goal."""
        cfg = self.config
        assert isinstance(cfg, CrossCountryConfig)
        distance = math.hypot(float(goal_north) - float(start_north), float(goal_east) - float(start_east))
        return cfg.battery_fraction * cfg.aircraft.cruise_energy(distance)


_CLIMB_DOC = """Thermal climb: gain as much specific energy as possible in a fixed time among thermals.

    ## Description

    The Tempest UAS starts low (100-300 m) at the centre of a 6 km square with several Allen
    thermals within about 1 km (:func:`~soaring_env.scenario.make_climb_scenario`) and flies for
    ``time_limit`` (600 s). There is no goal: the return is the net specific energy gained
    [kJ/kg], g x height gained minus motor energy -- circling in lift pays, motoring never does
    (the motor converts at eta = 0.8). The task of Notter et al.'s updraft exploitation and Flato et
    al.'s thermal-climb glider, on this project's model.

    ## Action Space

    ``soaring/ThermalClimb-v0``: ``Discrete(174)``, the paper's primitives (Ts = 30 s; see
    :class:`~soaring_env.env.core.SoaringEnv`). The aircraft has a stall limit (C_L,max = 1.27):
    :meth:`action_masks` masks the primitives that would stall (69 of the 87 at 10 m/s: all but the
    +-45 deg straights, curves and 180 deg spirals, whose path angle unloads the wing), hit the ground,
    leave the domain or exceed the bank limit. An agent that flies a primitive past the stall limit
    anyway ends the episode (``info["outcome"] == "stall"``).

    ``soaring/ThermalClimbContinuous-v0``: ``Box(-1, 1, (3,), float32)`` held for Ts = 5 s
    (``duration``, 1-30 s), mapped onto the physical envelope
    (:meth:`~soaring_env.primitives.ControlEnvelope.physical`): airspeed 12-25 m/s, bank angle
    +-phi_lim(v_a) (the 60 deg bank limit or the stall at the 1,500 m ceiling, whichever is
    smaller), path angle -30 to +20 deg.

    ## Observation Space

    The goal-reaching observation without the three goal entries, then ``time_left`` (flight time
    left / time limit), the history (``history_length`` edges of mean lift, climb rate and course
    change, newest first; 0 by default; ``history_positions=True`` adds where each edge's lift was
    sensed, relative to the aircraft) and the thermal slots (privileged tier; ``observe_thermals=False``
    gives the sensed tier). ``env.unwrapped.observation_names`` lists the entries; the README's
    "Observation tiers" table documents them.

    ## Rewards

    ``energy`` = -edge cost / 1000 (kJ/kg) per step; ``crash`` -25 on ground contact,
    ``out_of_bounds`` -25 on leaving the domain, ``stall`` -25 (``crash_penalty``; primitives only)
    on a primitive past the stall limit. The episode's energy return is
    ``-info["energy_spent"] / 1000``.

    ## Starting State

    ``scenario="random"`` (default): a new climb scenario at every reset from ``env.np_random``;
    ``climb-<seed>`` names one (held-out: ``climb-10000``, ...).

    ## Episode End

    Terminated on ground contact, on leaving the domain or on a stall (primitives: the edge is
    flown and charged, then the episode ends); truncated by the env itself when the flight time
    reaches ``time_limit`` (a ``step`` after that raises until ``reset``).

    ## Version History

    * v0: initial version. 2026-12-05: a primitive past the stall limit ends the episode
      (``"stall"``); before, the primitive env flew it as if the wing could (no published result
      flew one: every masked agent, planner and hand-written agent avoids them).
    """

_XC_DOC = """Energy-limited cross-country: reach a goal 8-15 km away on a battery too small to motor there.

    ## Description

    A goal region (radius 300 m, centred at 400 m) lies 8-15 km away (the start at 200-400 m),
    across a field of 1-2 thermals per km (:func:`~soaring_env.scenario.make_cross_country_scenario`).
    The motor runs on a battery of ``battery_fraction`` (0.25) x the energy of the cheapest powered
    flight straight to the goal (level, best L/D = 22.8, still air): success needs climbs in lift.
    The task of Notter et al.'s cross-country soaring, on this project's model.

    ## Action Space

    As the thermal climb (``soaring/CrossCountry-v0``: primitives with stall masks;
    ``soaring/CrossCountryContinuous-v0``: the physical envelope, Ts = 10 s).

    ## Observation Space

    The goal-reaching observation (positions scaled by 2 km), then ``battery`` (left / budget) and
    ``time_left``, the history and the thermal slots.

    ## Rewards

    As goal reaching (energy, progress shaping, ``goal`` +25, ``crash`` -25, ``out_of_bounds`` -25)
    plus ``battery_empty`` -25 (``battery_penalty``) and, on the primitives, ``stall`` -25 as in the
    thermal climb.

    ## Starting State

    ``scenario="random"`` (default) or ``xc-<seed>`` (held-out: ``xc-10000``, ...).

    ## Episode End

    Terminated at the goal (success), on ground contact, on leaving the domain, on a stall
    (primitives, as in the thermal climb), or when the battery
    is empty (``info["outcome"] == "battery_empty"``: the motor energy of the episode, fuel plus the
    speed changes' kinetic charge, reached the budget during the last edge, which is still flown to
    its end); truncated by the env at ``time_limit`` (3600 s). ``info["battery_left"]`` [J/kg].

    ## Version History

    * v0: initial version. 2026-12-05: the stall outcome, as in the thermal climb.
    """


class ThermalClimbEnv(_ThermalClimb, SoaringEnv):
    __doc__ = _CLIMB_DOC
    config_class: ClassVar[type[SoaringEnvConfig]] = ThermalClimbConfig


class ThermalClimbContinuousEnv(_ThermalClimb, SoaringContinuousEnv):
    __doc__ = _CLIMB_DOC
    config_class: ClassVar[type[SoaringEnvConfig]] = ThermalClimbContinuousConfig


class CrossCountryEnv(_CrossCountry, SoaringEnv):
    __doc__ = _XC_DOC
    config_class: ClassVar[type[SoaringEnvConfig]] = CrossCountryConfig


class CrossCountryContinuousEnv(_CrossCountry, SoaringContinuousEnv):
    __doc__ = _XC_DOC
    config_class: ClassVar[type[SoaringEnvConfig]] = CrossCountryContinuousConfig


class ThermalClimbVectorEnv(SoaringVectorEnv):
    """Natively batched :class:`ThermalClimbEnv` (see :class:`~soaring_env.env.vector.SoaringVectorEnv`)."""

    single_env_class: ClassVar[type[SoaringBaseEnv]] = ThermalClimbEnv


class ThermalClimbContinuousVectorEnv(SoaringContinuousVectorEnv):
    """Natively batched :class:`ThermalClimbContinuousEnv`."""

    single_env_class: ClassVar[type[SoaringBaseEnv]] = ThermalClimbContinuousEnv


class CrossCountryVectorEnv(SoaringVectorEnv):
    """Natively batched :class:`CrossCountryEnv`."""

    single_env_class: ClassVar[type[SoaringBaseEnv]] = CrossCountryEnv


class CrossCountryContinuousVectorEnv(SoaringContinuousVectorEnv):
    """Natively batched :class:`CrossCountryContinuousEnv`."""

    single_env_class: ClassVar[type[SoaringBaseEnv]] = CrossCountryContinuousEnv


#: Every task env class by registered id suffix: (single, vector).
TASK_ENVS: dict[str, tuple[type[SoaringBaseEnv], type[Any]]] = {
    "ThermalClimb-v0": (ThermalClimbEnv, ThermalClimbVectorEnv),
    "ThermalClimbContinuous-v0": (ThermalClimbContinuousEnv, ThermalClimbContinuousVectorEnv),
    "CrossCountry-v0": (CrossCountryEnv, CrossCountryVectorEnv),
    "CrossCountryContinuous-v0": (CrossCountryContinuousEnv, CrossCountryContinuousVectorEnv),
}
