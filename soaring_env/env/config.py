"""Typed, frozen configuration of the soaring environments and scenario resolution.

:class:`SoaringEnvConfig` is what ``gym.make("soaring/Soaring-v0", config=...)`` accepts; plain
keyword arguments to ``gym.make`` override single fields (``gym.make(id, goal_bonus=10.0)``).
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from soaring_env._validation import (
    ConfigError,
    check_bool,
    check_choice,
    check_finite,
    check_int,
    check_pair,
    check_positive,
    check_range,
    check_type,
)
from soaring_env.physics.aircraft import Aircraft
from soaring_env.primitives import DEFAULT_MAX_SUBSTEP, ENVELOPES, MAX_POINTS, check_duration, check_substep
from soaring_env.scenario import (
    GENERATORS,
    RANDOM,
    Scenario,
    check_generator_keywords,
    get_scenario,
    make_scenario,
    scenario_family,
)

#: Reward scale: one reward unit is one kJ/kg of specific energy.
ENERGY_SCALE = 1000.0

#: A scenario as the envs take it: a name or path of :func:`~soaring_env.scenario.get_scenario`,
#: ``"random"`` (a new scenario drawn from ``env.np_random`` at every reset), a Scenario or its dict.
ScenarioSpec = str | os.PathLike[str] | Scenario | Mapping[str, Any]
#: Longest observation history [edges].
MAX_HISTORY = 64
#: the goal-reaching step limit: 40 steps of Ts = 30 s, 20 minutes of flight
MAX_EPISODE_STEPS = 40
#: the largest ``max_steps``
MAX_STEPS = 10_000_000


@dataclass(frozen=True)
class SoaringEnvConfig:
    """Everything that defines a soaring environment (all fields validated on construction).

    :param scenario: ``"paper"`` (default: the paper's figure-2 setting, one thermal between start
        and goal), any other name of :func:`soaring_env.scenario.get_scenario` (``"random-<seed>"``,
        a path to a scenario ``.json`` file), ``"random"`` (a new scenario drawn from
        ``env.np_random`` at every reset: distribution v2 of :mod:`soaring_env.env.scenario_batch`,
        the ranges of :func:`soaring_env.scenario.make_scenario`), a
        :class:`~soaring_env.scenario.Scenario`, or its dict form. A path is stored as a string.
    :param random_scenario: keyword arguments of :func:`~soaring_env.scenario.make_scenario` for
        ``"random"`` mode (v2 draws) and for ``"random-<seed>"`` names (v1 draws): thermal count,
        strength and wind ranges, bounds, ...
    :param duration: primitive duration Ts [s]: one env step flies Ts seconds.
    :param n_points: output points per primitive N (events are detected on these points).
    :param aircraft: aircraft and thrust model (default: Tempest UAS, ``"trim"`` thrust).
    :param max_substep: largest RK4 substep of the updraft integration near thermals [s].
    :param max_bank_deg: bank-angle limit [deg] of :meth:`SoaringEnv.action_masks`.
    :param observe_thermals: include the nearest thermals in the observation; ``False`` leaves only
        locally sensed lift (a harder, partially observed task).
    :param n_obs_thermals: number of nearest-thermal slots in the observation.
    :param position_scale: horizontal distances are divided by this [m] (default 1 km).
    :param height_scale: heights are divided by this [m] (default 1 km).
    :param updraft_scale: vertical winds are divided by this [m/s].
    :param speed_scale: airspeeds are divided by this [m/s].
    :param wind_scale: horizontal winds are divided by this [m/s].
    :param goal_bonus: reward added when the goal region is reached [kJ/kg-equivalent]. The energy
        rewards of an episode sum to ``-(fuel + kinetic) + g (h_end - h_start)``, so height kept at
        the end pays; the bonus must beat ending high instead of at the goal (g x 1.3 km = 12.7).
    :param energy_weight: weight of the energy term (``-energy_weight x cost / 1 kJ/kg``; default 1).
        Among the policies that reach the goal the least energy still scores best at any weight;
        a larger weight makes the energy a thermal saves a larger part of the return (a training
        aid: ``info["energy_spent"]`` and every score stay in J/kg).
    :param crash_penalty: reward subtracted on ground contact (the height lost on the way down is
        already charged as potential energy; the penalty makes a crash worse than any flight).
    :param out_of_bounds_penalty: reward subtracted on leaving the flight domain.
    :param progress_weight: potential-based shaping [reward per km]: each step adds
        ``progress_weight * (d_before - d_after) / 1 km`` with ``d`` the 3-D distance to the goal
        centre; it telescopes, so it changes no optimal policy (gamma = 1). 0 switches it off.
    :param settle_height: a training aid for soaring toward a goal (default False: off). On
        truncation (an episode that ends by its limit, not at the goal, the ground or the edge) add
        ``energy_weight x g (h_top - h_end) / 1 kJ/kg``, h_top the goal region's top [m]: the
        episode's energy rewards then sum to ``-(fuel + kinetic) + g (h_top - h_start)``, as for a
        flight that ends at the goal top, so height climbed in a thermal and kept to the end earns
        nothing by itself -- only the fuel it saves on the way to the goal pays. Without it a policy
        can bank a thermal's climb by circling until the limit. Needs a task with a goal.
    :param render_size: (width, height) of ``rgb_array`` frames [px].
    :param envelope: continuous envs: ``"paper"`` (default: the primitives' envelope, turn rates
        +-1080 deg / Ts) or ``"physical"`` (airspeed, bank-angle and stall limits, independent of
        Ts: :meth:`~soaring_env.primitives.ControlEnvelope.physical`); an aircraft with a stall
        limit (``cl_max``) needs ``"physical"``.
    :param airspeed_range: ``"physical"`` envelope: (low, high) airspeed [m/s].
    :param gamma_range_deg: ``"physical"`` envelope: (low, high) flight-path angle [deg].
    :param history_length: number H of past edges in the observation (each: mean lift, climb rate,
        course change); 0 (default) adds none.
    :param history_positions: each history edge also gives where its lift was sensed: the edge's
        time midpoint relative to the aircraft now, north and east / ``position_scale`` [m] (what
        a glider's logger pairs with its variometer; entries ``history_<j>_north`` / ``_east``,
        zero for edges not yet flown). Needs ``history_length`` > 0. Default False.
    :param observe_start: add where the episode started relative to the aircraft, north and east /
        ``position_scale`` [m] (entries ``start_north``, ``start_east``: what a glider's GPS gives;
        lets a policy on the sensed tier search around, and stay near, its start). Default False.
    :param sensor_noise: standard deviation [m/s] of Gaussian noise on the sensed lift entries
        (``updraft``, ``edge_lift``, the history's lift), drawn from the episode's seed; 0: exact.
    :param time_limit: flight time [s] after which an episode is truncated, or ``None`` (default:
        no time limit; ``max_steps`` still applies); at least one step (Ts). Adds ``time_left`` to
        the observation.
    :param max_steps: the env truncates after this many steps (default 40: 20 min of 30 s steps;
        ``None``: never), as gymnasium's ``TimeLimit`` would, and a ``step()`` after that raises
        until ``reset()``. The env owns its limit so that it knows an episode was truncated:
        change it with ``gym.make(id, max_steps=N)`` (``gym.make``'s own ``max_episode_steps``
        adds a ``TimeLimit`` outside the env, which can only shorten episodes).
    """

    #: the random-scenario generator of ``"random"`` mode and ``random_scenario`` (a task's own)
    generator: ClassVar[Callable[..., Scenario]] = staticmethod(make_scenario)

    scenario: ScenarioSpec = "paper"
    random_scenario: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    duration: float = 30.0
    n_points: int = 30
    aircraft: Aircraft = dataclasses.field(default_factory=Aircraft)
    max_substep: float = DEFAULT_MAX_SUBSTEP
    max_bank_deg: float = 60.0
    observe_thermals: bool = True
    n_obs_thermals: int = 3
    position_scale: float = 1000.0
    height_scale: float = 1000.0
    updraft_scale: float = 5.0
    speed_scale: float = 20.0
    wind_scale: float = 10.0
    goal_bonus: float = 25.0
    energy_weight: float = 1.0
    crash_penalty: float = 25.0
    out_of_bounds_penalty: float = 25.0
    progress_weight: float = 1.0
    settle_height: bool = False
    render_size: tuple[int, int] = (960, 640)
    envelope: str = "paper"
    airspeed_range: tuple[float, float] = (12.0, 25.0)
    gamma_range_deg: tuple[float, float] = (-30.0, 20.0)
    history_length: int = 0
    history_positions: bool = False
    observe_start: bool = False
    sensor_noise: float = 0.0
    time_limit: float | None = None
    max_steps: int | None = MAX_EPISODE_STEPS

    def __post_init__(self) -> None:
        if isinstance(self.scenario, os.PathLike):
            object.__setattr__(self, "scenario", os.fspath(self.scenario))  # configs are saved as JSON
        if not isinstance(self.scenario, (str, Scenario, Mapping)):
            raise ConfigError(
                f"scenario={self.scenario!r} has type {type(self.scenario).__name__}; "
                "allowed: a scenario name or path, 'random', a Scenario or a dict"
            )
        check_generator_keywords(self.generator, self.random_scenario)
        if self.scenario == RANDOM or self.random_scenario:
            self.generator(np.random.default_rng(0), **dict(self.random_scenario))  # fail early on bad ranges
        object.__setattr__(self, "duration", check_duration("duration", self.duration))
        check_int("n_points", self.n_points, 2, MAX_POINTS)
        if not isinstance(self.aircraft, Aircraft):
            raise ConfigError(f"aircraft={self.aircraft!r} must be an Aircraft")
        object.__setattr__(self, "max_substep", check_substep("max_substep", self.max_substep))
        bank = check_range("max_bank_deg", self.max_bank_deg, 0.0, 90.0, low_open=True, high_open=True)
        object.__setattr__(self, "max_bank_deg", bank)
        check_bool("observe_thermals", self.observe_thermals)
        check_bool("settle_height", self.settle_height)
        check_int("n_obs_thermals", self.n_obs_thermals, 0, 64)
        for name in ("position_scale", "height_scale", "updraft_scale", "speed_scale", "wind_scale"):
            object.__setattr__(self, name, check_positive(name, getattr(self, name)))
        object.__setattr__(self, "energy_weight", check_range("energy_weight", self.energy_weight, 0.0, 1000.0))
        for name in ("goal_bonus", "crash_penalty", "out_of_bounds_penalty", "progress_weight"):
            object.__setattr__(self, name, check_finite(name, getattr(self, name)))
        if isinstance(self.render_size, (str, bytes)) or not hasattr(self.render_size, "__iter__"):
            raise ConfigError(f"render_size={self.render_size!r} must be (width, height) in pixels, each >= 64")
        size = tuple(self.render_size)
        if len(size) != 2 or any(isinstance(s, bool) or not isinstance(s, int) or s < 64 for s in size):
            raise ConfigError(f"render_size={self.render_size!r} must be (width, height) in pixels, each >= 64")
        object.__setattr__(self, "render_size", size)
        check_type("envelope", self.envelope, str)
        check_choice("envelope", self.envelope, ENVELOPES)
        for name in ("airspeed_range", "gamma_range_deg"):
            object.__setattr__(self, name, check_pair(name, getattr(self, name), -100.0, 100.0))
        check_int("history_length", self.history_length, 0, MAX_HISTORY)
        check_bool("history_positions", self.history_positions)
        check_bool("observe_start", self.observe_start)
        if self.history_positions and not self.history_length:
            raise ConfigError("history_positions=True needs history_length > 0 (allowed with history_length=0: False)")
        object.__setattr__(self, "sensor_noise", check_range("sensor_noise", self.sensor_noise, 0.0, 10.0))
        if self.time_limit is not None:
            tl = check_range("time_limit", self.time_limit, self.duration, 1e7)
            object.__setattr__(self, "time_limit", tl)
        if self.max_steps is not None:
            object.__setattr__(self, "max_steps", check_int("max_steps", self.max_steps, 1, MAX_STEPS))
        # Fail early on an unknown name, a bad file or pinned scenario, or bad random-scenario keywords.
        resolve_scenario(self.scenario, self.random_scenario, self.generator)

    @classmethod
    def field_names(cls) -> tuple[str, ...]:
        return tuple(f.name for f in dataclasses.fields(cls))

    def replace(self, **changes: Any) -> SoaringEnvConfig:
        """A copy with some fields changed; unknown names raise with the list of fields."""
        unknown = sorted(set(changes) - set(self.field_names()))
        if unknown:
            raise ConfigError(
                f"unknown config field(s) {', '.join(map(repr, unknown))}; allowed: {', '.join(self.field_names())}"
            )
        return dataclasses.replace(self, **changes)


def make_config(
    config: SoaringEnvConfig | Mapping[str, Any] | None,
    overrides: Mapping[str, Any],
    cls: type[SoaringEnvConfig] = SoaringEnvConfig,
) -> SoaringEnvConfig:
    """Combine a config of class ``cls`` (or a dict of its fields, or None for its defaults) with
    keyword overrides."""
    if config is None:
        base = cls()
    elif isinstance(config, SoaringEnvConfig):
        if type(config) is not cls:
            raise ConfigError(f"config has type {type(config).__name__}; this env takes a {cls.__name__}")
        base = config
    elif isinstance(config, Mapping):
        base = cls().replace(**dict(config))
    else:
        raise ConfigError(f"config={config!r} must be a {cls.__name__}, a dict of its fields or None")
    return base.replace(**dict(overrides)) if overrides else base


def resolve_scenario(
    spec: ScenarioSpec,
    random_kwargs: Mapping[str, Any] | None = None,
    generator: Callable[..., Scenario] = make_scenario,
) -> Scenario | None:
    """A :class:`Scenario` from a Scenario, a dict, or a name or path of
    :func:`~soaring_env.scenario.get_scenario`; ``None`` for ``"random"``. ``random_kwargs`` (the
    keywords of ``generator``, an env's ``random_scenario``) apply to ``<family>-<seed>`` names of
    that generator's family only."""
    if isinstance(spec, Scenario):
        return spec
    if isinstance(spec, (str, os.PathLike)):
        if spec == RANDOM:
            return None
        family = scenario_family(spec)
        own = family is not None and GENERATORS[family] is generator
        return get_scenario(spec, random_kwargs if own else None)
    if isinstance(spec, Mapping):
        return Scenario.from_dict(dict(spec))
    raise ConfigError(f"scenario={spec!r} is invalid; allowed: a scenario name or path, 'random', a Scenario or a dict")


def choose_scenario(
    options: Mapping[str, Any] | None,
    fixed: Scenario | None,
    random_kwargs: Mapping[str, Any],
    generator: Callable[..., Scenario] = make_scenario,
    more_keys: tuple[str, ...] = (),
) -> Scenario | None:
    """The scenario of a new episode, or ``None`` for a new random one.

    ``options["scenario"]`` (anything :class:`SoaringEnvConfig` takes as ``scenario``) wins; else
    the configured ``fixed`` scenario; else (``"random"`` mode, or ``options={"scenario": "random"}``)
    ``None``: the env draws from its own generator (``generator`` with ``random_kwargs``; goal
    reaching: distribution v2 of :mod:`soaring_env.env.scenario_batch`). ``random_kwargs`` are also
    the keywords of that generator's ``<family>-<seed>`` names. ``more_keys``: further reset
    options the caller reads itself (allowed here, not interpreted).
    """
    spec: Any = None
    allowed = ("scenario", *more_keys)
    if options:
        if not isinstance(options, Mapping):
            raise ConfigError(f"options={options!r} must be a dict; allowed keys: {', '.join(map(repr, allowed))}")
        unknown = sorted(set(options) - set(allowed))
        if unknown:
            raise ConfigError(f"unknown reset option(s) {unknown!r}; allowed: {', '.join(map(repr, allowed))}")
        spec = options.get("scenario")
    if spec is not None:
        return resolve_scenario(spec, random_kwargs, generator)  # None for "random"
    return fixed
