"""Scenarios: thermal layout, wind, start state, goal region and flight domain (frozen, JSON-able).

The named ``"paper"`` scenario reproduces the setting of the paper's figure 2: one thermal between
the start and the goal region. Its geometry is our choice (the paper gives none): start at the
origin heading north at 300 m, goal 3 km north at 300 m (radius 150 m), an Allen thermal of
w* = 2.56 m/s, zi = 1400 m (Allen's worked example) at 1.5 km north, 250 m east of the direct line.

Scenario names are one namespace, resolved by :func:`get_scenario` wherever a scenario is taken by
name (``gym.make(..., scenario=...)``, ``env.reset(options={"scenario": ...})``, the evaluation):
``"paper"``, ``"random-<seed>"`` (held-out test set: ``random-10000``, ...) and paths to ``.json``
files of :meth:`Scenario.save`; the envs add the mode ``"random"`` (a new scenario at every reset).
"""

from __future__ import annotations

import dataclasses
import inspect
import json
import math
import os
import re
import tempfile
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from soaring_env._validation import (
    ConfigError,
    check_bool,
    check_choice,
    check_finite,
    check_pair,
    check_positive,
    check_range,
    check_type,
)
from soaring_env.physics.atmosphere import MAX_HEIGHT
from soaring_env.physics.thermals import MIN_PERIOD, THERMAL_MODELS, Thermal, WindField

#: Most thermals a random scenario may draw (the kernels loop over all of them at every point).
MAX_RANDOM_THERMALS = 100


@dataclass(frozen=True)
class Bounds:
    """Flight domain [m]: leaving it ends an episode; the ground is at height 0.

    :param north_min: [m]; :param north_max: [m]; :param east_min: [m]; :param east_max: [m];
    :param height_max: ceiling [m], below ``MAX_HEIGHT`` (11 km: the energy model's ISA troposphere).
    """

    north_min: float = -1000.0
    north_max: float = 4000.0
    east_min: float = -2500.0
    east_max: float = 2500.0
    height_max: float = 1500.0

    def __post_init__(self) -> None:
        for name in ("north_min", "north_max", "east_min", "east_max"):
            object.__setattr__(self, name, check_finite(f"bounds.{name}", getattr(self, name)))
        hmax = check_range("bounds.height_max", self.height_max, 0.0, MAX_HEIGHT, low_open=True, high_open=True)
        object.__setattr__(self, "height_max", hmax)
        if self.north_max <= self.north_min:
            raise ConfigError(f"bounds.north_max={self.north_max!r} must be > north_min={self.north_min!r}")
        if self.east_max <= self.east_min:
            raise ConfigError(f"bounds.east_max={self.east_max!r} must be > east_min={self.east_min!r}")

    def contains(self, north, east, height) -> np.ndarray:
        """True where a point is inside the domain (above ground, below the ceiling)."""
        n, e, h = (np.asarray(a) for a in (north, east, height))
        return (
            (n >= self.north_min)
            & (n <= self.north_max)
            & (e >= self.east_min)
            & (e <= self.east_max)
            & (h > 0.0)
            & (h <= self.height_max)
        )

    @property
    def low(self) -> np.ndarray:
        return np.array([self.north_min, self.east_min, 0.0])

    @property
    def high(self) -> np.ndarray:
        return np.array([self.north_max, self.east_max, self.height_max])


@dataclass(frozen=True)
class GoalRegion:
    """Spherical goal region: reached when a flown point lies within ``radius`` of the centre.

    :param north: [m]; :param east: [m]; :param height: [m, > 0]; :param radius: [m, > 0].
    """

    north: float = 3000.0
    east: float = 0.0
    height: float = 300.0
    radius: float = 150.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "north", check_finite("goal.north", self.north))
        object.__setattr__(self, "east", check_finite("goal.east", self.east))
        h = check_finite("goal.height", self.height)
        if h <= 0.0:
            raise ConfigError(f"goal.height={self.height!r} is at or below the ground; it must be > 0 m")
        object.__setattr__(self, "height", h)
        object.__setattr__(self, "radius", check_positive("goal.radius", self.radius))

    @property
    def centre(self) -> np.ndarray:
        return np.array([self.north, self.east, self.height])

    def distance(self, north, east, height) -> np.ndarray:
        """Euclidean distance [m] from points to the goal centre."""
        return np.sqrt(
            (np.asarray(north) - self.north) ** 2
            + (np.asarray(east) - self.east) ** 2
            + (np.asarray(height) - self.height) ** 2
        )

    def contains(self, north, east, height) -> np.ndarray:
        return self.distance(north, east, height) <= self.radius


@dataclass(frozen=True)
class Scenario:
    """One planning problem: the air, where the aircraft starts and where it must go.

    :param field: ambient wind and thermals.
    :param start: start state ``(Pn [m], Pe [m], chi [rad], h [m])``.
    :param goal: goal region, or ``None`` for tasks without one (thermal climb).
    :param bounds: flight domain.
    :param name: label used in results and plots.
    """

    field: WindField = dataclasses.field(default_factory=WindField)
    start: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 300.0)
    goal: GoalRegion | None = dataclasses.field(default_factory=GoalRegion)
    bounds: Bounds = dataclasses.field(default_factory=Bounds)
    name: str = "custom"

    def __post_init__(self) -> None:
        check_type("field", self.field, WindField)
        if self.goal is not None:
            check_type("goal", self.goal, GoalRegion)
        check_type("bounds", self.bounds, Bounds)
        check_type("name", self.name, str)
        if isinstance(self.start, (str, bytes)) or not hasattr(self.start, "__len__") or len(self.start) != 4:
            raise ConfigError(f"start={self.start!r} must be 4 numbers (Pn [m], Pe [m], chi [rad], h [m])")
        start = tuple(check_finite(f"start[{i}]", v) for i, v in enumerate(self.start))
        object.__setattr__(self, "start", start)
        n, e, _, h = start
        if not bool(self.bounds.contains(n, e, h)):
            raise ConfigError(
                f"start position (north={n:g}, east={e:g}, height={h:g}) is outside the domain "
                f"north [{self.bounds.north_min:g}, {self.bounds.north_max:g}], "
                f"east [{self.bounds.east_min:g}, {self.bounds.east_max:g}], height (0, {self.bounds.height_max:g}]"
            )
        g = self.goal
        if g is None:
            return
        if not bool(self.bounds.contains(g.north, g.east, g.height)):
            raise ConfigError(
                f"goal centre (north={g.north:g}, east={g.east:g}, height={g.height:g}) is outside the domain "
                f"north [{self.bounds.north_min:g}, {self.bounds.north_max:g}], "
                f"east [{self.bounds.east_min:g}, {self.bounds.east_max:g}], height (0, {self.bounds.height_max:g}]"
            )
        if bool(g.contains(n, e, h)):
            raise ConfigError("start lies inside the goal region; the problem is already solved")

    def require_goal(self) -> GoalRegion:
        """The goal region; a :class:`ConfigError` for a scenario without one (for goal-directed
        planners and scores)."""
        if self.goal is None:
            raise ConfigError(f"scenario {self.name!r} has no goal region; this needs a goal-reaching scenario")
        return self.goal

    @property
    def start_state(self) -> np.ndarray:
        """Start state as a float64 array ``[Pn, Pe, chi, h]``."""
        return np.array(self.start, dtype=np.float64)

    def replace(self, **changes: Any) -> Scenario:
        return replace(self, **changes)

    # --- JSON -------------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        f = self.field
        return {
            "name": self.name,
            "start": list(self.start),
            "goal": None if self.goal is None else asdict(self.goal),
            "bounds": asdict(self.bounds),
            "field": {
                "model": f.model,
                "zi": f.zi,
                "wind_north": f.wind_north,
                "wind_east": f.wind_east,
                "drift": f.drift,
                "thermals": [_thermal_dict(t) for t in f.thermals],
            },
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any], *, source: str = "scenario") -> Scenario:
        """The inverse of :meth:`to_dict`. Missing and unknown keys and values of the wrong type raise
        a :class:`ConfigError` that names ``source`` (e.g. the file), the key and what is expected."""
        try:
            top = _keys(d, f"{source}", required=("start", "goal", "bounds", "field"), optional=("name",))
            fd = _keys(
                top["field"],
                f"{source}: field",
                required=(),
                optional=("model", "zi", "wind_north", "wind_east", "drift", "thermals"),
            )
            raw_thermals = fd.pop("thermals", [])
            if not isinstance(raw_thermals, (list, tuple)):
                raise ConfigError(f"{source}: field.thermals={raw_thermals!r} must be a list of thermal objects")
            thermals = tuple(
                Thermal(
                    **_keys(t, f"{source}: field.thermals[{i}]", required=("north", "east"), optional=_THERMAL_OPTIONAL)
                )
                for i, t in enumerate(raw_thermals)
            )
            start = top["start"]
            if not isinstance(start, (list, tuple)):
                raise ConfigError(f"{source}: start={start!r} must be a list of 4 numbers [Pn, Pe, chi, h]")
            goal = (
                None
                if top["goal"] is None
                else _keys(top["goal"], f"{source}: goal", required=(), optional=("north", "east", "height", "radius"))
            )
            bounds = _keys(
                top["bounds"],
                f"{source}: bounds",
                required=(),
                optional=("north_min", "north_max", "east_min", "east_max", "height_max"),
            )
            return cls(
                field=WindField(thermals=thermals, **fd),
                start=tuple(start),
                goal=None if goal is None else GoalRegion(**goal),
                bounds=Bounds(**bounds),
                name=top.get("name", "custom"),
            )
        except ConfigError as exc:
            msg = str(exc)
            raise ConfigError(msg if msg.startswith(source) else f"{source}: {msg}") from None

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=2)

    @classmethod
    def from_json(cls, text: str, *, source: str = "scenario JSON") -> Scenario:
        try:
            d = json.loads(text)
        except json.JSONDecodeError as exc:
            raise ConfigError(f"{source} is not valid JSON: {exc}") from None
        return cls.from_dict(d, source=source)

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the scenario as JSON, atomically (temporary file + rename)."""
        atomic_write_text(path, self.to_json())

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> Scenario:
        """Read a scenario written by :meth:`save`; errors name the file."""
        try:
            text = Path(path).read_text()
        except (OSError, UnicodeDecodeError) as exc:
            raise ConfigError(f"cannot read scenario file {str(path)!r}: {exc}") from None
        return cls.from_json(text, source=f"scenario file {str(path)!r}")


#: Optional keys of a thermal object in scenario JSON (all but north, east): the life cycle and
#: fluctuation keys are written only where they differ from their defaults (steady thermals keep
#: the JSON of before they existed), and files without them load as steady thermals.
_THERMAL_OPTIONAL = ("strength", "radius", "birth", "lifetime", "rise", "decay", "amplitude", "period", "phase")
_THERMAL_DEFAULTS = {f.name: f.default for f in dataclasses.fields(Thermal)}


def _thermal_dict(t: Thermal) -> dict[str, Any]:
    """A thermal as JSON: north, east, strength, radius, and the time-dependence keys that are set."""
    d = asdict(t)
    return {k: v for k, v in d.items() if k in ("north", "east", "strength", "radius") or v != _THERMAL_DEFAULTS[k]}


def _keys(d: Any, where: str, *, required: tuple[str, ...], optional: tuple[str, ...]) -> dict[str, Any]:
    """``d`` as a dict with string keys, all ``required`` present and nothing beyond ``optional``."""
    if not isinstance(d, dict):
        raise ConfigError(f"{where} must be an object (dict), got {type(d).__name__} {d!r}")
    missing = [k for k in required if k not in d]
    if missing:
        raise ConfigError(f"{where} lacks the key(s) {missing!r}; required: {', '.join(required)}")
    unknown = sorted(str(k) for k in d if k not in required + optional)
    if unknown:
        raise ConfigError(f"{where} has unknown key(s) {unknown!r}; allowed: {', '.join(required + optional)}")
    return dict(d)


def atomic_write_text(path: str | os.PathLike[str], text: str) -> None:
    """Write ``text`` to ``path`` so that readers see the old or the new file, never a torn one."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=p.parent, prefix=f".{p.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp creates 0600; give the file the usual permissions
        os.replace(tmp, p)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def paper_scenario() -> Scenario:
    """The paper's figure-2 setting: one Allen thermal between the start and the goal region."""
    return Scenario(
        field=WindField(thermals=(Thermal(north=1500.0, east=250.0, strength=2.56),), model="allen", zi=1400.0),
        start=(0.0, 0.0, 0.0, 300.0),
        goal=GoalRegion(north=3000.0, east=0.0, height=300.0, radius=150.0),
        bounds=Bounds(),
        name="paper",
    )


SCENARIOS = {"paper": paper_scenario}

#: The envs' scenario mode that draws a new random scenario at every reset (a mode, not one scenario).
RANDOM = "random"
#: First seed of the held-out test scenarios ``random-10000``, ``random-10001``, ... (training draws
#: from each env's own stream; PPO's validation scenarios use seeds 5000+).
HELDOUT_SEED0 = 10_000
#: First seed of the validation scenarios (``random-5000``, ``xc-5000``, ...): what a policy is
#: chosen on, disjoint from the held-out test seeds and the demonstrations' 20000+.
VALIDATION_SEED0 = 5_000
_RANDOM_SEED = re.compile(r"^(random|climb|xc)-([0-9]+)$")
_FORMS = (
    "random-<seed> (a random scenario drawn with that seed; held-out: random-10000, random-10001, ...), "
    "climb-<seed> and xc-<seed> (the thermal-climb and cross-country tasks' scenarios, same seeds), "
    "a path to a scenario file (*.json, written by Scenario.save), "
    f"and in the envs {RANDOM!r} (a new random scenario at every reset)"
)


def heldout_names(n: int, start: int = HELDOUT_SEED0, family: str = "random") -> list[str]:
    """Names of the first ``n`` held-out scenarios of a generator family (``random-10000``, ...;
    ``family`` is ``"random"`` (goal reaching), ``"climb"`` or ``"xc"``)."""
    check_choice("family", family, tuple(GENERATORS))
    return [f"{family}-{start + k}" for k in range(n)]


def _parse_name(name: str | os.PathLike[str]) -> tuple[str, Any]:
    """What a scenario name refers to: ``("named", factory)``, ``("random", (family, seed))`` or ``("file", path)``.

    One namespace for every place that takes a scenario by name: a name of :data:`SCENARIOS`,
    ``"random-<seed>"``, or a path (a ``PathLike``, or a string ending in ``.json``).
    """
    if isinstance(name, os.PathLike):
        return "file", Path(name)
    if not isinstance(name, str):
        raise ConfigError(f"scenario={name!r} has type {type(name).__name__}; a scenario name or path is required")
    if name in SCENARIOS:
        return "named", SCENARIOS[name]
    m = _RANDOM_SEED.match(name)
    if m:
        return "random", (m.group(1), int(m.group(2)))
    if name.lower().endswith(".json"):
        return "file", Path(name)
    if name == RANDOM:
        raise ConfigError(
            f"scenario {RANDOM!r} names no single scenario: it is the envs' mode that draws a new one at every "
            "reset (gym.make(..., scenario='random')); for one random scenario use 'random-<seed>', e.g. 'random-10000'"
        )
    raise ConfigError(f"scenario {name!r} is unknown; known: {', '.join(sorted(SCENARIOS))}, {_FORMS}")


def scenario_family(name: str | os.PathLike[str]) -> str | None:
    """The generator family of a ``<family>-<seed>`` name (``"random"``, ``"climb"``, ``"xc"``),
    else None (named scenarios, files)."""
    kind, value = _parse_name(name)
    return value[0] if kind == "random" else None


def check_scenario_name(name: str) -> str:
    """``name`` if it has the form of a scenario name (the file of a ``.json`` path is read only by
    :func:`get_scenario`), else a :class:`ConfigError` listing the known names and forms."""
    _parse_name(name)
    return name


def get_scenario(name: str | os.PathLike[str], random_scenario: Mapping[str, Any] | None = None) -> Scenario:
    """The scenario a name refers to; the one resolver behind ``gym.make(..., scenario=...)``,
    ``env.reset(options={"scenario": ...})`` and the evaluation's scenario names.

    :param name: a named scenario (``"paper"``); ``"random-<seed>"``: :func:`make_scenario` drawn
        from ``np.random.default_rng(seed)`` with ``random_scenario``, named ``name`` (the
        held-out test set is :func:`heldout_names`); ``"climb-<seed>"``, ``"xc-<seed>"``: the same
        with :func:`make_climb_scenario`, :func:`make_cross_country_scenario`; or a path to a
        JSON file of :meth:`Scenario.save`.
    :param random_scenario: :func:`make_scenario` keywords for ``"random-<seed>"`` (an env's
        ``random_scenario``, so that held-out scenarios follow its training distribution); ignored
        by the other forms.
    :raises ConfigError: for an unknown name (listing the known names and forms) or a bad file.
    """
    kind, value = _parse_name(name)
    if kind == "named":
        return value()
    if kind == "random":
        family, seed = value
        gen = GENERATORS[family]
        check_generator_keywords(gen, random_scenario or {})
        return gen(np.random.default_rng(seed), **{**dict(random_scenario or {}), "name": str(name)})
    return Scenario.load(value)


def check_generator_keywords(generator: Any, kwargs: Mapping[str, Any], field: str = "random_scenario") -> None:
    """A :class:`ConfigError` naming ``field`` if ``kwargs`` has keys ``generator`` does not take."""
    if not isinstance(kwargs, Mapping):
        raise ConfigError(f"{field}={kwargs!r} must be a dict of {generator.__name__} keywords")
    allowed = [p for p in inspect.signature(generator).parameters if p != "rng"]
    unknown = sorted(str(k) for k in kwargs if k not in allowed)
    if unknown:
        raise ConfigError(
            f"{field} has unknown key(s) {unknown!r} for {generator.__name__}; allowed: {', '.join(allowed)}"
        )


#: Goal radius of random scenarios [m].
_RANDOM_GOAL_RADIUS = 150.0
#: Largest time [s] a random scenario's life-cycle and fluctuation ranges may name (11.6 days).
MAX_RANDOM_TIME = 1e6
#: The thermal life-cycle and fluctuation keywords of the random-scenario generators.
TIME_OPTIONS = ("lifecycle", "rise_time", "birth_window", "strength_variation", "variation_period")
#: Least distance [m] of a random scenario's start and goal centre from the domain's horizontal edges.
RANDOM_MARGIN = 300.0
#: Draws a random scenario may try before its keywords are declared unsatisfiable.
RANDOM_TRIES = 1000
#: The error of keywords whose draws never fit the domain (after ``RANDOM_TRIES`` tries).
NO_FIT = "could not draw a scenario that fits the bounds; widen bounds or shorten goal_distance"


def check_int_pair(name: str, value: Any, low: int, high: int) -> tuple[int, int]:
    """An ordered pair of integers in [low, high]."""
    a, b = check_pair(name, value, low, high, integer=True)
    return int(a), int(b)


def default_random_bounds() -> Bounds:
    """The flight domain of random scenarios unless ``bounds`` is given: 6 km x 6 km, 1.5 km high."""
    return Bounds(-3000.0, 3000.0, -3000.0, 3000.0, 1500.0)


@dataclass(frozen=True)
class RandomScenarioSpec:
    """The validated keywords of :func:`make_scenario` (and of the envs' ``"random"`` mode draws),
    without the thermal life-cycle and fluctuation options (:data:`TIME_OPTIONS`).

    Every range is an ordered pair ``(low, high)`` of finite numbers: ``n_thermals`` integers in
    [0, ``MAX_RANDOM_THERMALS``], ``strength`` (w* or Gaussian peak) in (0, 20] m/s, ``wind_speed``
    in [0, 50] m/s, ``goal_distance`` [m] above the goal radius (150 m) and within the domain,
    ``height`` [m] inside (0, ``bounds.height_max``]; ``zi`` [m] > 0; ``lateral_spread`` in [0, 1]:
    thermals lie up to this fraction of the goal distance to either side of the start-goal line
    (0.3, the default; 0 puts them on it -- a curriculum in which flying straight meets the lift);
    ``thermal_along`` within [0, 1]: the thermals' positions along that line, as fractions of the
    goal distance from the start ((0.2, 0.8), the default; (0, 0.1) puts them at the start -- a
    curriculum that starts the aircraft in lift). A bad one raises a :class:`ConfigError` naming
    it. ``bounds=None`` is :func:`default_random_bounds`.
    """

    n_thermals: tuple[int, int] = (1, 5)
    strength: tuple[float, float] = (1.5, 3.5)
    wind_speed: tuple[float, float] = (0.0, 4.0)
    goal_distance: tuple[float, float] = (1500.0, 3500.0)
    height: tuple[float, float] = (200.0, 600.0)
    model: str = "allen"
    zi: float = 1400.0
    drift: bool = False
    bounds: Bounds | None = None
    name: str = "random"
    lateral_spread: float = 0.3
    thermal_along: tuple[float, float] = (0.2, 0.8)

    def __post_init__(self) -> None:
        object.__setattr__(self, "lateral_spread", check_range("lateral_spread", self.lateral_spread, 0.0, 1.0))
        object.__setattr__(self, "thermal_along", check_pair("thermal_along", self.thermal_along, 0.0, 1.0))
        bounds = default_random_bounds() if self.bounds is None else self.bounds
        check_type("bounds", bounds, Bounds)
        object.__setattr__(self, "bounds", bounds)
        n, strength, wind, zi, drift = _check_field_ranges(
            self.n_thermals, self.strength, self.wind_speed, self.model, self.zi, self.drift, self.name
        )
        for k, v in (("n_thermals", n), ("strength", strength), ("wind_speed", wind), ("zi", zi), ("drift", drift)):
            object.__setattr__(self, k, v)
        goal_distance = check_pair("goal_distance", self.goal_distance, _RANDOM_GOAL_RADIUS, math.inf)
        if goal_distance[0] <= _RANDOM_GOAL_RADIUS:
            raise ConfigError(
                f"goal_distance={goal_distance!r} must have low > {_RANDOM_GOAL_RADIUS:g} m (the goal radius)"
            )
        object.__setattr__(self, "goal_distance", goal_distance)
        height = check_pair("height", self.height, 0.0, bounds.height_max)
        if height[0] <= 0.0:
            raise ConfigError(f"height={height!r} must have low > 0 m (above the ground)")
        object.__setattr__(self, "height", height)
        if goal_distance[1] > 0.9 * math.hypot(self.span_north, self.span_east):
            raise ConfigError(f"goal_distance={goal_distance!r} does not fit in the domain {bounds!r}")

    @property
    def domain(self) -> Bounds:
        """``bounds`` (never None after validation)."""
        assert self.bounds is not None
        return self.bounds

    @property
    def span_north(self) -> float:
        """North extent of the domain [m]."""
        b = self.domain
        return b.north_max - b.north_min

    @property
    def span_east(self) -> float:
        """East extent of the domain [m]."""
        b = self.domain
        return b.east_max - b.east_min


def make_scenario(
    rng: np.random.Generator,
    *,
    n_thermals: tuple[int, int] = (1, 5),
    strength: tuple[float, float] = (1.5, 3.5),
    wind_speed: tuple[float, float] = (0.0, 4.0),
    goal_distance: tuple[float, float] = (1500.0, 3500.0),
    height: tuple[float, float] = (200.0, 600.0),
    model: str = "allen",
    zi: float = 1400.0,
    drift: bool = False,
    bounds: Bounds | None = None,
    name: str = "random",
    lateral_spread: float = 0.3,
    thermal_along: tuple[float, float] = (0.2, 0.8),
    lifecycle: tuple[float, float] | None = None,
    rise_time: float = 120.0,
    birth_window: tuple[float, float] = (0.0, 0.0),
    strength_variation: tuple[float, float] | None = None,
    variation_period: tuple[float, float] = (300.0, 900.0),
) -> Scenario:
    """A random scenario drawn only from ``rng`` (same generator state -> same scenario).

    Thermal count, positions (in the band between start and goal, so that using them is a real
    choice), strengths w* [m/s], wind speed [m/s] and direction, start heading and height, goal
    bearing, distance [m] and height are all drawn uniformly from the given ranges; draws whose
    start or goal lies within ``RANDOM_MARGIN`` of the domain's edges are drawn again.

    This is random-scenario distribution v1, one scenario at a time: the held-out and validation
    scenarios ``"random-<seed>"`` are drawn with it. The envs' ``"random"`` mode draws the same
    distribution in batches (:mod:`soaring_env.env.scenario_batch`, v2: another use of the stream)
    unless a thermal option below is on. The keywords and their ranges are those of
    :class:`RandomScenarioSpec` (a bad one raises a :class:`ConfigError` naming it).

    Thermal life cycle and strength fluctuation (see :mod:`soaring_env.physics.thermals`), both off
    by default; with both off no extra random number is drawn (a seed gives the scenario it gave
    before these options existed), and with either on their numbers are drawn after all others:

    :param lifecycle: range of the thermals' lifetimes [s] (birth to death), or None (default):
        steady thermals. Needs ``lifecycle[0] >= 2 rise_time``.
    :param rise_time: rise and decay time [s] of every thermal with a life cycle (>= 0).
    :param birth_window: range of the birth times [s] (default (0, 0): all born at t = 0);
        negative births are thermals already alive at the start, later ones appear during the flight.
    :param strength_variation: range of the relative fluctuation amplitude a, in [0, 1), or None
        (default): constant strengths. Each thermal's phase is uniform in [-pi, pi).
    :param variation_period: range of the fluctuation period [s] (>= ``MIN_PERIOD``, 10 s).

    ``rise_time``, ``birth_window`` and ``variation_period`` other than their defaults need their
    option on (a ConfigError otherwise, rather than being ignored).
    """
    check_type("rng", rng, np.random.Generator)
    s = _random_settings(
        n_thermals, strength, wind_speed, goal_distance, height, model, zi, drift, bounds, name, lateral_spread,
        thermal_along, lifecycle, rise_time, birth_window, strength_variation, variation_period,
    )  # fmt: skip
    spec, time_kw = s.spec, s.time
    assert spec is not None  # the goal-reaching settings always hold their spec
    bounds = spec.domain
    n_thermals, strength, wind_speed = spec.n_thermals, spec.strength, spec.wind_speed
    goal_distance, height = spec.goal_distance, spec.height
    span_n, span_e = spec.span_north, spec.span_east
    for _ in range(RANDOM_TRIES):
        dist = rng.uniform(*goal_distance)
        bearing = rng.uniform(-math.pi, math.pi)
        cn = 0.5 * (bounds.north_min + bounds.north_max)
        ce = 0.5 * (bounds.east_min + bounds.east_max)
        sn = cn - 0.5 * dist * math.cos(bearing) + rng.uniform(-0.1, 0.1) * span_n
        se = ce - 0.5 * dist * math.sin(bearing) + rng.uniform(-0.1, 0.1) * span_e
        gn = sn + dist * math.cos(bearing)
        ge = se + dist * math.sin(bearing)
        sh = rng.uniform(*height)
        gh = rng.uniform(*height)
        chi = bearing + rng.uniform(-math.pi / 2, math.pi / 2)
        chi = (chi + math.pi) % (2 * math.pi) - math.pi
        k = int(rng.integers(n_thermals[0], n_thermals[1] + 1))
        thermals = []
        for _j in range(k):
            along = rng.uniform(*spec.thermal_along)
            across = rng.uniform(-spec.lateral_spread, spec.lateral_spread) * dist
            tn = sn + along * (gn - sn) - across * math.sin(bearing)
            te = se + along * (ge - se) + across * math.cos(bearing)
            thermals.append(Thermal(north=tn, east=te, strength=rng.uniform(*strength)))
        wn, we = _draw_wind(rng, wind_speed)
        inside = bounds.contains(np.array([sn, gn]), np.array([se, ge]), np.array([sh, gh]))
        margin = RANDOM_MARGIN
        if (
            not inside.all()
            or min(
                sn - bounds.north_min,
                bounds.north_max - sn,
                se - bounds.east_min,
                bounds.east_max - se,
                gn - bounds.north_min,
                bounds.north_max - gn,
                ge - bounds.east_min,
                bounds.east_max - ge,
            )
            < margin
        ):
            continue
        if time_kw is not None:  # after every other draw of the accepted scenario: old seeds unchanged
            thermals = _draw_time_dependence(rng, thermals, *time_kw)
        return Scenario(
            field=WindField(
                thermals=tuple(thermals),
                model=spec.model,
                zi=spec.zi,
                wind_north=wn,
                wind_east=we,
                drift=spec.drift,
            ),
            start=(sn, se, chi, sh),
            goal=GoalRegion(north=gn, east=ge, height=gh, radius=_RANDOM_GOAL_RADIUS),
            bounds=bounds,
            name=spec.name,
        )
    raise ConfigError(NO_FIT)


def _random_settings(
    n_thermals: Any, strength: Any, wind_speed: Any, goal_distance: Any, height: Any, model: Any, zi: Any,
    drift: Any, bounds: Any, name: Any, lateral_spread: Any, thermal_along: Any, lifecycle: Any, rise_time: Any,
    birth_window: Any, strength_variation: Any, variation_period: Any,
) -> GeneratorSettings:  # fmt: skip
    """The validated keywords of :func:`make_scenario` (a bad one raises a ConfigError naming it)."""
    spec = RandomScenarioSpec(
        n_thermals=n_thermals,
        strength=strength,
        wind_speed=wind_speed,
        goal_distance=goal_distance,
        height=height,
        model=model,
        zi=zi,
        drift=drift,
        bounds=bounds,
        name=name,
        lateral_spread=lateral_spread,
        thermal_along=thermal_along,
    )
    time_kw = _check_time_options(lifecycle, rise_time, birth_window, strength_variation, variation_period)
    return GeneratorSettings(
        kind="random", height=spec.height, strength=spec.strength, wind_speed=spec.wind_speed, model=spec.model,
        zi=spec.zi, drift=spec.drift, time=time_kw, name=spec.name, bounds=spec.domain, n_thermals=spec.n_thermals,
        goal_distance=spec.goal_distance, spec=spec,
    )  # fmt: skip


_Range = tuple[float, float]
#: validated (lifecycle, rise_time, birth_window, strength_variation, variation_period)
_TimeOptions = tuple[_Range | None, float, _Range, _Range | None, _Range]


def _check_time_options(
    lifecycle: Any, rise_time: Any, birth_window: Any, strength_variation: Any, variation_period: Any
) -> _TimeOptions | None:
    """The validated life-cycle and fluctuation options of :func:`make_scenario`, or None if both are off."""
    life = None
    if lifecycle is not None:
        life = check_pair("lifecycle", lifecycle, 0.0, MAX_RANDOM_TIME)
        if life[0] <= 0.0:
            raise ConfigError(f"lifecycle={lifecycle!r} must have low > 0 s (a lifetime)")
    rise = check_range("rise_time", rise_time, 0.0, 0.5 * MAX_RANDOM_TIME)
    births = check_pair("birth_window", birth_window, -MAX_RANDOM_TIME, MAX_RANDOM_TIME)
    amp = None
    if strength_variation is not None:
        amp = check_pair("strength_variation", strength_variation, 0.0, 1.0)
        if amp[1] >= 1.0:
            raise ConfigError(f"strength_variation={strength_variation!r} must have high < 1 (an amplitude in [0, 1))")
    period = check_pair("variation_period", variation_period, MIN_PERIOD, MAX_RANDOM_TIME)
    if life is None:
        for name, value, default in (("rise_time", rise, 120.0), ("birth_window", births, (0.0, 0.0))):
            if value != default:
                raise ConfigError(f"{name}={value!r} needs lifecycle=(low, high) lifetimes [s]; lifecycle is None")
    elif life[0] < 2.0 * rise:
        raise ConfigError(
            f"lifecycle={lifecycle!r} allows lifetimes shorter than rise + decay = 2 rise_time = {2.0 * rise:g} s; "
            "allowed: lifecycle low >= 2 rise_time"
        )
    if amp is None and period != (300.0, 900.0):
        raise ConfigError(f"variation_period={period!r} needs strength_variation=(low, high); it is None")
    if life is None and amp is None:
        return None
    return life, rise, births, amp, period


def _draw_time_dependence(
    rng: np.random.Generator,
    thermals: list[Thermal],
    life: tuple[float, float] | None,
    rise: float,
    births: tuple[float, float],
    amp: tuple[float, float] | None,
    period: tuple[float, float],
) -> list[Thermal]:
    """``thermals`` with life cycles and fluctuations drawn from ``rng`` (lifetimes, births, then
    amplitudes, periods, phases, each as one vector over the thermals)."""
    k = len(thermals)
    kw: list[dict[str, Any]] = [{} for _ in range(k)]
    if life is not None:
        lifetimes = rng.uniform(*life, k)
        birth = rng.uniform(*births, k)
        for j in range(k):
            kw[j].update(lifetime=float(lifetimes[j]), birth=float(birth[j]), rise=rise, decay=rise)
    if amp is not None:
        a = rng.uniform(*amp, k)
        p = rng.uniform(*period, k)
        phi = rng.uniform(-math.pi, math.pi, k)
        for j in range(k):
            kw[j].update(amplitude=float(a[j]), period=float(p[j]), phase=float(phi[j]))
    return [replace(t, **kw[j]) for j, t in enumerate(thermals)]


def _draw_wind(rng: np.random.Generator, wind_speed: tuple[float, float]) -> tuple[float, float]:
    """(north, east) [m/s] of a wind of uniform speed in ``wind_speed`` and uniform direction."""
    ws = rng.uniform(*wind_speed)
    wd = rng.uniform(-math.pi, math.pi)
    return ws * math.cos(wd), ws * math.sin(wd)


def _check_field_ranges(
    n_thermals: Any, strength: Any, wind_speed: Any, model: Any, zi: Any, drift: Any, name: Any
) -> tuple[tuple[int, int], tuple[float, float], tuple[float, float], float, bool]:
    """The checks every random-scenario generator shares (see :func:`make_scenario`)."""
    n = check_int_pair("n_thermals", n_thermals, 0, MAX_RANDOM_THERMALS)
    st = check_pair("strength", strength, 0.0, 20.0)
    if st[0] <= 0.0:
        raise ConfigError(f"strength={strength!r} must have low > 0 m/s (a thermal's w* or peak is positive)")
    ws = check_pair("wind_speed", wind_speed, 0.0, 50.0)
    check_type("model", model, str)
    check_choice("model", model, THERMAL_MODELS)
    z = check_positive("zi", zi)
    d = check_bool("drift", drift)
    check_type("name", name, str)
    return n, st, ws, z, d


class GeneratorSettings(NamedTuple):
    """The validated keywords of a random-scenario generator, as its draws read them
    (:func:`generator_settings`).

    ``kind`` is ``"random"`` (:func:`make_scenario`, distribution v1: ``spec``, its
    :class:`RandomScenarioSpec`, with ``n_thermals``, ``goal_distance`` and the domain ``bounds``),
    ``"climb"`` (:func:`make_climb_scenario`: ``n_thermals``, ``thermal_radius`` [m] and the fixed
    ``bounds``) or ``"xc"`` (:func:`make_cross_country_scenario`: ``goal_distance``,
    ``thermals_per_km``, ``corridor``, ``margin``, ``goal_height``, ``height_max`` [m]); the fields
    of the other kinds keep their defaults. ``time`` holds the life-cycle and fluctuation options
    (lifetimes, rise time, birth window, amplitudes, periods), None when both are off.
    """

    kind: str
    height: tuple[float, float]
    strength: tuple[float, float]
    wind_speed: tuple[float, float]
    model: str
    zi: float
    drift: bool
    time: _TimeOptions | None
    name: str
    bounds: Bounds | None = None
    n_thermals: tuple[int, int] = (0, 0)
    thermal_radius: float = 0.0
    goal_distance: tuple[float, float] = (0.0, 0.0)
    thermals_per_km: tuple[float, float] = (0.0, 0.0)
    corridor: float = 0.0
    margin: float = 0.0
    goal_height: float = 0.0
    height_max: float = 0.0
    spec: RandomScenarioSpec | None = None


#: Goal radius of the cross-country task [m].
CROSS_COUNTRY_GOAL_RADIUS = 300.0


def make_climb_scenario(
    rng: np.random.Generator,
    *,
    n_thermals: tuple[int, int] = (3, 6),
    strength: tuple[float, float] = (1.5, 3.5),
    thermal_radius: float = 1000.0,
    wind_speed: tuple[float, float] = (0.0, 3.0),
    height: tuple[float, float] = (100.0, 300.0),
    model: str = "allen",
    zi: float = 1400.0,
    drift: bool = False,
    half_width: float = 3000.0,
    height_max: float = 1500.0,
    lifecycle: tuple[float, float] | None = None,
    rise_time: float = 120.0,
    birth_window: tuple[float, float] = (0.0, 0.0),
    strength_variation: tuple[float, float] | None = None,
    variation_period: tuple[float, float] = (300.0, 900.0),
    name: str = "climb",
) -> Scenario:
    """A thermal-climb scenario drawn only from ``rng``: the aircraft starts low among several
    thermals and has no goal (the task is to gain energy in a fixed time).

    Start at the domain centre (origin) with a uniform heading, at a height uniform in ``height``
    [m]; ``n_thermals`` thermals uniform over the disc of radius ``thermal_radius`` [m] around the
    start, strengths uniform in ``strength`` [m/s]; wind as :func:`make_scenario`. The domain is
    the square of ``half_width`` [m] around the origin, ceiling ``height_max`` [m]. The thermal
    realism options (``lifecycle``, ``rise_time``, ``birth_window``, ``strength_variation``,
    ``variation_period``) are those of :func:`make_scenario`.
    """
    check_type("rng", rng, np.random.Generator)
    s = _climb_settings(
        n_thermals, strength, thermal_radius, wind_speed, height, model, zi, drift, half_width, height_max,
        lifecycle, rise_time, birth_window, strength_variation, variation_period, name,
    )  # fmt: skip
    chi = rng.uniform(-math.pi, math.pi)
    h0 = rng.uniform(*s.height)
    k = int(rng.integers(s.n_thermals[0], s.n_thermals[1] + 1))
    thermals = []
    for _ in range(k):
        r = s.thermal_radius * math.sqrt(rng.uniform(0.0, 1.0))  # uniform over the disc
        a = rng.uniform(-math.pi, math.pi)
        thermals.append(Thermal(north=r * math.cos(a), east=r * math.sin(a), strength=rng.uniform(*s.strength)))
    wn, we = _draw_wind(rng, s.wind_speed)
    if s.time is not None:
        thermals = _draw_time_dependence(rng, thermals, *s.time)
    assert s.bounds is not None  # the climb's settings always hold its domain
    return Scenario(
        field=WindField(thermals=tuple(thermals), model=s.model, zi=s.zi, wind_north=wn, wind_east=we, drift=s.drift),
        start=(0.0, 0.0, chi, h0),
        goal=None,
        bounds=s.bounds,
        name=s.name,
    )


def _climb_settings(
    n_thermals: Any, strength: Any, thermal_radius: Any, wind_speed: Any, height: Any, model: Any, zi: Any,
    drift: Any, half_width: Any, height_max: Any, lifecycle: Any, rise_time: Any, birth_window: Any,
    strength_variation: Any, variation_period: Any, name: Any,
) -> GeneratorSettings:  # fmt: skip
    """The validated keywords of :func:`make_climb_scenario` (a bad one raises a ConfigError naming it)."""
    n_thermals, strength, wind_speed, zi, drift = _check_field_ranges(
        n_thermals, strength, wind_speed, model, zi, drift, name
    )
    time_kw = _check_time_options(lifecycle, rise_time, birth_window, strength_variation, variation_period)
    half = check_positive("half_width", half_width)
    r_max = check_range("thermal_radius", thermal_radius, 0.0, half)
    bounds = Bounds(-half, half, -half, half, check_range("height_max", height_max, 0.0, MAX_HEIGHT, low_open=True))
    height = check_pair("height", height, 0.0, bounds.height_max)
    if height[0] <= 0.0:
        raise ConfigError(f"height={height!r} must have low > 0 m (above the ground)")
    return GeneratorSettings(
        kind="climb", height=height, strength=strength, wind_speed=wind_speed, model=model, zi=zi, drift=drift,
        time=time_kw, name=name, bounds=bounds, n_thermals=n_thermals, thermal_radius=r_max,
    )  # fmt: skip


def make_cross_country_scenario(
    rng: np.random.Generator,
    *,
    goal_distance: tuple[float, float] = (8000.0, 15000.0),
    thermals_per_km: tuple[float, float] = (1.0, 2.0),
    corridor: float = 2000.0,
    strength: tuple[float, float] = (1.5, 3.5),
    wind_speed: tuple[float, float] = (0.0, 3.0),
    height: tuple[float, float] = (200.0, 400.0),
    goal_height: float = 400.0,
    model: str = "allen",
    zi: float = 1400.0,
    drift: bool = False,
    margin: float = 3000.0,
    height_max: float = 1500.0,
    lifecycle: tuple[float, float] | None = None,
    rise_time: float = 120.0,
    birth_window: tuple[float, float] = (0.0, 0.0),
    strength_variation: tuple[float, float] | None = None,
    variation_period: tuple[float, float] = (300.0, 900.0),
    name: str = "xc",
) -> Scenario:
    """A cross-country scenario drawn only from ``rng``: a goal ``goal_distance`` [m] away in a
    uniform direction across a field of many thermals.

    Start at the origin heading within +-90 deg of the goal bearing, at a height uniform in
    ``height`` [m]; goal region of radius ``CROSS_COUNTRY_GOAL_RADIUS`` (300 m) centred at
    ``goal_height`` [m] (the defaults leave at most 300 m to glide down: about 7 km at the best L/D,
    less than the shortest goal distance); ``round(rate * distance / 1 km)`` thermals (rate uniform in
    ``thermals_per_km``) uniform along the line from 5 % to 100 % of the distance and within
    ``corridor`` [m] of it. The domain is the bounding box of start and goal grown by ``margin``
    [m], ceiling ``height_max`` [m]. The task's battery (see the cross-country env) is what
    makes the thermals necessary. Thermal realism options as :func:`make_scenario`.
    """
    check_type("rng", rng, np.random.Generator)
    s = _cross_country_settings(
        goal_distance, thermals_per_km, corridor, strength, wind_speed, height, goal_height, model, zi, drift,
        margin, height_max, lifecycle, rise_time, birth_window, strength_variation, variation_period, name,
    )  # fmt: skip
    dist = rng.uniform(*s.goal_distance)
    bearing = rng.uniform(-math.pi, math.pi)
    gn, ge = dist * math.cos(bearing), dist * math.sin(bearing)
    chi = bearing + rng.uniform(-math.pi / 2, math.pi / 2)
    chi = (chi + math.pi) % (2 * math.pi) - math.pi
    h0 = rng.uniform(*s.height)
    k = min(int(round(rng.uniform(*s.thermals_per_km) * dist / 1000.0)), MAX_RANDOM_THERMALS)
    thermals = []
    for _ in range(k):
        along = rng.uniform(0.05, 1.0) * dist
        across = rng.uniform(-s.corridor, s.corridor)
        tn = along * math.cos(bearing) - across * math.sin(bearing)
        te = along * math.sin(bearing) + across * math.cos(bearing)
        thermals.append(Thermal(north=tn, east=te, strength=rng.uniform(*s.strength)))
    wn, we = _draw_wind(rng, s.wind_speed)
    if s.time is not None:
        thermals = _draw_time_dependence(rng, thermals, *s.time)
    pad, top = s.margin, s.height_max
    bounds = Bounds(min(0.0, gn) - pad, max(0.0, gn) + pad, min(0.0, ge) - pad, max(0.0, ge) + pad, top)
    return Scenario(
        field=WindField(thermals=tuple(thermals), model=s.model, zi=s.zi, wind_north=wn, wind_east=we, drift=s.drift),
        start=(0.0, 0.0, chi, h0),
        goal=GoalRegion(north=gn, east=ge, height=s.goal_height, radius=CROSS_COUNTRY_GOAL_RADIUS),
        bounds=bounds,
        name=s.name,
    )


def _cross_country_settings(
    goal_distance: Any, thermals_per_km: Any, corridor: Any, strength: Any, wind_speed: Any, height: Any,
    goal_height: Any, model: Any, zi: Any, drift: Any, margin: Any, height_max: Any, lifecycle: Any,
    rise_time: Any, birth_window: Any, strength_variation: Any, variation_period: Any, name: Any,
) -> GeneratorSettings:  # fmt: skip
    """The validated keywords of :func:`make_cross_country_scenario` (a bad one raises a ConfigError
    naming it)."""
    rate = check_pair("thermals_per_km", thermals_per_km, 0.0, 10.0)
    _, strength, wind_speed, zi, drift = _check_field_ranges((0, 0), strength, wind_speed, model, zi, drift, name)
    time_kw = _check_time_options(lifecycle, rise_time, birth_window, strength_variation, variation_period)
    dist_range = check_pair("goal_distance", goal_distance, CROSS_COUNTRY_GOAL_RADIUS, 100_000.0)
    if dist_range[0] <= CROSS_COUNTRY_GOAL_RADIUS:
        raise ConfigError(f"goal_distance={goal_distance!r} must have low > {CROSS_COUNTRY_GOAL_RADIUS:g} m")
    width = check_positive("corridor", corridor)
    pad = check_range("margin", margin, width, 100_000.0)
    top = check_range("height_max", height_max, 0.0, MAX_HEIGHT, low_open=True)
    height = check_pair("height", height, 0.0, top)
    if height[0] <= 0.0:
        raise ConfigError(f"height={height!r} must have low > 0 m (above the ground)")
    gh = check_range("goal_height", goal_height, 0.0, top, low_open=True)
    return GeneratorSettings(
        kind="xc", height=height, strength=strength, wind_speed=wind_speed, model=model, zi=zi, drift=drift,
        time=time_kw, name=name, goal_distance=dist_range, thermals_per_km=rate, corridor=width, margin=pad,
        goal_height=gh, height_max=top,
    )  # fmt: skip


def generator_settings(generator: Callable[..., Scenario], kwargs: Mapping[str, Any]) -> GeneratorSettings:
    """The validated settings of a random-scenario generator (:func:`make_scenario`,
    :func:`make_climb_scenario` or :func:`make_cross_country_scenario`) called with ``kwargs`` (its
    defaults for the others): what its draws read, for the batched draws of the envs. A bad keyword
    raises the generator's ConfigError."""
    if generator not in _GENERATOR_SETTINGS:
        allowed = sorted(g.__name__ for g in _GENERATOR_SETTINGS)
        raise ConfigError(f"generator={generator!r} has no batched draws; allowed: {allowed}")
    check_type("kwargs", kwargs, Mapping, "a mapping of keyword arguments")
    try:
        bound = inspect.signature(generator).bind(None, **dict(kwargs))
    except TypeError as err:
        raise ConfigError(f"{generator.__name__}: {err}") from None
    bound.apply_defaults()
    args = dict(bound.arguments)
    args.pop("rng")
    return _GENERATOR_SETTINGS[generator](**args)


_GENERATOR_SETTINGS: dict[Callable[..., Scenario], Callable[..., GeneratorSettings]] = {
    make_scenario: _random_settings,
    make_climb_scenario: _climb_settings,
    make_cross_country_scenario: _cross_country_settings,
}

#: The generators whose draws the envs can make in batches, exactly (:func:`generator_settings`).
BATCHED_GENERATORS = frozenset(_GENERATOR_SETTINGS)

#: The random-scenario generators by family: ``<family>-<seed>`` names and the envs' ``"random"``
#: mode draw from them (goal reaching ``random``, thermal climb ``climb``, cross-country ``xc``).
GENERATORS: dict[str, Callable[..., Scenario]] = {
    "random": make_scenario,
    "climb": make_climb_scenario,
    "xc": make_cross_country_scenario,
}
