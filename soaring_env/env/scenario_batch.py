"""Random scenarios in batches: many draws at once, straight into the env kernels' packed arrays.

The envs' ``"random"`` mode draws a new scenario at every reset. Building a
:class:`~soaring_env.scenario.Scenario` (frozen, validated dataclasses) and a model per reset costs
~100 us; here a draw is a row of uniforms from numpy turned by one compiled kernel into the rows the
env kernels read -- a :func:`~soaring_env.env.observation.scenario_params` row, a thermal table of
:attr:`WindField.packed <soaring_env.physics.thermals.WindField.packed>` rows, the thermal count and
the start state -- for every drawn env at once. A :class:`Scenario` is built from those rows only when
someone asks for it (:func:`scenario_from_row`), and it packs back into the same rows bit for bit.

Distribution versions (:data:`RANDOM_SCENARIO_VERSION`):

* v1 -- :func:`~soaring_env.scenario.make_scenario`, one scenario at a time; still what
  ``"random-<seed>"`` names (the held-out set ``random-10000``, ..., PPO's validation seeds 5000+)
  draw, bit for bit.
* v2 -- this module, the ``"random"`` mode of every env since this version. The same keywords,
  ranges and validation (:class:`~soaring_env.scenario.RandomScenarioSpec`), the same uniform
  distributions and the same rejection of draws near the domain's edges, so the same distribution
  of scenarios; but the generator's stream is used differently (each draw reads a fixed block of
  :func:`draw_width` uniforms), so a seed gives other scenarios than under v1.

The other random modes -- the tasks (thermal climb, cross-country) and goal reaching with the thermal
life-cycle or fluctuation options (v1) -- are drawn in batches too (:class:`GeneratorSampler`), but
not as a new version: the kernel makes exactly the generator calls of
:func:`~soaring_env.scenario.make_scenario`, :func:`~soaring_env.scenario.make_climb_scenario` or
:func:`~soaring_env.scenario.make_cross_country_scenario` (numba's ``Generator`` methods are numpy's
algorithms), so a generator state gives the same scenario either way, bit for bit, and the held-out
``climb-<seed>`` and ``xc-<seed>`` sets need no versioning.

Streams: a draw reads its uniforms straight from a numpy generator inside the kernel (exactly the
numbers ``rng.random()`` would return, advancing that generator): each try reads
:func:`draw_width` uniforms, and a try whose start or goal lies near the domain's edges is followed
by another. :func:`draw_scenario_arrays` draws ``n`` scenarios one after the other from one
generator; the envs draw env ``i``'s scenario from env ``i``'s own generator (``env.np_random`` of a
single env, ``seed + i`` in a vector env), for all resetting envs in one call, so a vector env of B
envs gives exactly the scenarios of B single envs seeded alike, whichever envs reset together.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit
from numba.typed import List

from soaring_env import _jit  # noqa: F401  (the package-wide kernel cache key, before any kernel)
from soaring_env._jit import ERROR_MODEL as _EM
from soaring_env._validation import ConfigError, check_int, check_type
from soaring_env.env.observation import (
    N_PARAMS,
    P_DVX,
    P_DVY,
    P_EMAX,
    P_EMIN,
    P_GE,
    P_GH,
    P_GN,
    P_GR,
    P_NMAX,
    P_NMIN,
    P_WE,
    P_WN,
    scenario_params,
)
from soaring_env.physics.thermals import (
    COL_AMPLITUDE,
    COL_BIRTH,
    COL_DEATH,
    COL_DECAY,
    COL_DYNAMIC,
    COL_OMEGA,
    COL_PEAK,
    COL_PHASE,
    COL_RISE,
    COL_STRENGTH,
    PACKED_COLUMNS,
    Thermal,
    WindField,
)
from soaring_env.scenario import (
    MAX_RANDOM_THERMALS,
    NO_FIT,
    RANDOM_MARGIN,
    RANDOM_TRIES,
    TIME_OPTIONS,
    GeneratorSettings,
    GoalRegion,
    RandomScenarioSpec,
    Scenario,
    generator_settings,
    make_scenario,
)

#: The distribution of the envs' ``"random"`` mode: 2 = this module's batched draw (v1 =
#: :func:`~soaring_env.scenario.make_scenario` per scenario, kept for ``"random-<seed>"`` names).
RANDOM_SCENARIO_VERSION = 2

#: Uniforms of one draw before its thermals: goal distance, goal bearing, start offset north and
#: east, start height, goal height, start heading, thermal count, wind speed, wind direction.
_HEAD = 10
#: Uniforms per thermal slot: position along and across the start-goal line, strength.
_PER_THERMAL = 3

# Columns of the kernel's range row (see _range_row).
_R_GD, _R_H, _R_S, _R_WS, _R_NMIN, _R_NMAX, _R_EMIN, _R_EMAX, _R_HMAX, _R_MARGIN = 0, 2, 4, 6, 8, 9, 10, 11, 12, 13
_R_LAT = 14  # lateral_spread
_R_ALONG = 15  # thermal_along: low, width
_N_RANGE = 17


def batched_draws(generator: Any, kwargs: Mapping[str, Any]) -> bool:
    """Whether an env's ``"random"`` mode draws distribution v2 here: goal reaching
    (:func:`~soaring_env.scenario.make_scenario`) with steady thermals. A task's generator, or the
    thermal life-cycle and fluctuation options, draw their generator's own scenarios instead (the
    native env in batches too: :class:`GeneratorSampler`)."""
    return generator is make_scenario and not (set(kwargs) & set(TIME_OPTIONS))


def draw_width(spec: RandomScenarioSpec) -> int:
    """Uniforms one draw reads: 10 for start, goal and wind, 3 per possible thermal."""
    return _HEAD + _PER_THERMAL * spec.n_thermals[1]


def random_spec(kwargs: RandomScenarioSpec | Mapping[str, Any] | None = None) -> RandomScenarioSpec:
    """``kwargs`` (the keywords of :func:`~soaring_env.scenario.make_scenario`) as a validated spec."""
    if isinstance(kwargs, RandomScenarioSpec):
        return kwargs
    return RandomScenarioSpec(**dict(kwargs or {}))


@functools.lru_cache(maxsize=64)
def _templates(spec: RandomScenarioSpec) -> tuple[np.ndarray, np.ndarray]:
    """The columns every draw of ``spec`` shares: a full :func:`scenario_params` row (goal radius,
    domain, zi, model; the kernel overwrites goal centre and wind) and a full packed thermal row
    (radius-or-influence from the default ``Thermal.radius``; the kernel overwrites centre and
    strength). Taken from real objects, so the layouts stay those of ``scenario_params`` and
    ``WindField.packed``."""
    one = make_scenario(np.random.default_rng(0), **{**_as_kwargs(spec), "n_thermals": (0, 0)})
    prm = scenario_params(one)
    th = WindField(thermals=(Thermal(north=0.0, east=0.0),), model=spec.model, zi=spec.zi).packed[0].copy()
    prm.setflags(write=False)
    th.setflags(write=False)
    return prm, th


def _as_kwargs(spec: RandomScenarioSpec) -> dict[str, Any]:
    return {f: getattr(spec, f) for f in spec.__dataclass_fields__}


@functools.lru_cache(maxsize=64)
def _range_row(spec: RandomScenarioSpec) -> np.ndarray:
    b = spec.domain
    row = np.empty(_N_RANGE)
    row[_R_GD : _R_GD + 2] = spec.goal_distance
    row[_R_H : _R_H + 2] = spec.height
    row[_R_S : _R_S + 2] = spec.strength
    row[_R_WS : _R_WS + 2] = spec.wind_speed
    row[_R_NMIN], row[_R_NMAX], row[_R_EMIN], row[_R_EMAX] = b.north_min, b.north_max, b.east_min, b.east_max
    row[_R_HMAX] = b.height_max
    row[_R_MARGIN] = RANDOM_MARGIN
    row[_R_LAT] = spec.lateral_spread
    lo, hi = spec.thermal_along
    # the width to 15 digits: (0.2, 0.8) gives 0.6, not 0.6000000000000001, so the default's
    # draws stay those of the constants the kernel used before the knob existed
    row[_R_ALONG], row[_R_ALONG + 1] = lo, float(f"{hi - lo:.15g}")
    row.setflags(write=False)
    return row


@njit(cache=True, inline="always", error_model=_EM)
def _draw_row(
    g: Any,
    i: int,
    x: np.ndarray,
    r: np.ndarray,
    n_lo: int,
    n_hi: int,
    drift: bool,
    max_tries: int,
    prm_t: np.ndarray,
    th_t: np.ndarray,
    prm: np.ndarray,
    th: np.ndarray,
    nth: np.ndarray,
    start: np.ndarray,
) -> bool:
    """Draw one scenario from generator ``g`` into row ``i`` of ``prm``, ``th``, ``nth``, ``start``.

    Each try reads ``x.size`` uniforms of ``g``; the uniform ranges and the rejection rule (start and
    goal inside the domain and ``margin`` away from its horizontal edges) are those of
    ``make_scenario``. False if ``max_tries`` tries all failed.
    """
    nmin, nmax, emin, emax, hmax, margin = r[_R_NMIN], r[_R_NMAX], r[_R_EMIN], r[_R_EMAX], r[_R_HMAX], r[_R_MARGIN]
    lat = r[_R_LAT]
    a_lo, a_w = r[_R_ALONG], r[_R_ALONG + 1]
    cn = 0.5 * (nmin + nmax)
    ce = 0.5 * (emin + emax)
    span_n = nmax - nmin
    span_e = emax - emin
    pi = math.pi
    for _ in range(max_tries):
        for c in range(x.size):
            x[c] = g.random()
        dist = r[_R_GD] + (r[_R_GD + 1] - r[_R_GD]) * x[0]
        bearing = -pi + 2.0 * pi * x[1]
        cb = math.cos(bearing)
        sb = math.sin(bearing)
        sn = cn - 0.5 * dist * cb + (-0.1 + 0.2 * x[2]) * span_n
        se = ce - 0.5 * dist * sb + (-0.1 + 0.2 * x[3]) * span_e
        gn = sn + dist * cb
        ge = se + dist * sb
        sh = r[_R_H] + (r[_R_H + 1] - r[_R_H]) * x[4]
        gh = r[_R_H] + (r[_R_H + 1] - r[_R_H]) * x[5]
        inside = (sn >= nmin and sn <= nmax and se >= emin and se <= emax and sh > 0.0 and sh <= hmax) and (
            gn >= nmin and gn <= nmax and ge >= emin and ge <= emax and gh > 0.0 and gh <= hmax
        )
        edge = min(sn - nmin, nmax - sn, se - emin, emax - se, gn - nmin, nmax - gn, ge - emin, emax - ge)
        if not inside or edge < margin:
            continue
        chi = bearing + (-0.5 * pi + pi * x[6])
        chi = (chi + pi) % (2.0 * pi) - pi
        k = n_lo + min(int(x[7] * (n_hi - n_lo + 1)), n_hi - n_lo)
        ws = r[_R_WS] + (r[_R_WS + 1] - r[_R_WS]) * x[8]
        wd = -pi + 2.0 * pi * x[9]
        wn = ws * math.cos(wd)
        we = ws * math.sin(wd)
        for j in range(k):
            along = a_lo + a_w * x[_HEAD + _PER_THERMAL * j]  # default: 0.2 + 0.6 x
            across = (-lat + 2.0 * lat * x[_HEAD + _PER_THERMAL * j + 1]) * dist  # default: -0.3 + 0.6 x
            th[i, j, :] = th_t
            th[i, j, 0] = sn + along * (gn - sn) - across * sb
            th[i, j, 1] = se + along * (ge - se) + across * cb
            w = r[_R_S] + (r[_R_S + 1] - r[_R_S]) * x[_HEAD + _PER_THERMAL * j + 2]
            th[i, j, COL_STRENGTH] = w
            th[i, j, COL_PEAK] = w  # a steady thermal's peak strength is its strength
        nth[i] = k
        prm[i, :] = prm_t
        prm[i, P_GN] = gn
        prm[i, P_GE] = ge
        prm[i, P_GH] = gh
        prm[i, P_WN] = wn
        prm[i, P_WE] = we
        prm[i, P_DVX] = wn if drift else 0.0
        prm[i, P_DVY] = we if drift else 0.0
        start[i, 0] = sn
        start[i, 1] = se
        start[i, 2] = chi
        start[i, 3] = sh
        return True
    return False


@njit(cache=True, error_model=_EM)
def _draw_each(rows, gens, r, n_lo, n_hi, drift, max_tries, prm_t, th_t, prm, th, nth, start) -> int:
    """Row ``i`` of ``rows`` from generator ``gens[i]`` (a typed List); -1, or the row that failed."""
    x = np.empty(_HEAD + _PER_THERMAL * n_hi)
    for i in rows:
        if not _draw_row(gens[i], i, x, r, n_lo, n_hi, drift, max_tries, prm_t, th_t, prm, th, nth, start):
            return i
    return -1


@njit(cache=True, error_model=_EM)
def _draw_from(rows, g, r, n_lo, n_hi, drift, max_tries, prm_t, th_t, prm, th, nth, start) -> int:
    """Every row of ``rows``, in order, from the one generator ``g``; -1, or the row that failed."""
    x = np.empty(_HEAD + _PER_THERMAL * n_hi)
    for i in rows:
        if not _draw_row(g, i, x, r, n_lo, n_hi, drift, max_tries, prm_t, th_t, prm, th, nth, start):
            return i
    return -1


@njit(cache=True, error_model=_EM)
def _generator_list(g: Any, n: int) -> Any:
    out = List()
    for _ in range(n):
        out.append(g)
    return out


@njit(cache=True, error_model=_EM)
def _set_generator(gens: Any, i: int, g: Any) -> None:
    gens[i] = g


def generator_list(gens: Sequence[np.random.Generator]) -> Any:
    """``gens`` as the numba typed List :meth:`ScenarioSampler.draw_each` reads (built by compiled,
    disk-cached helpers: a typed List filled from Python compiles its methods in every process)."""
    out = _generator_list(gens[0], len(gens))
    for i in range(1, len(gens)):
        _set_generator(out, i, gens[i])
    return out


def set_generator(gens: Any, i: int, g: np.random.Generator) -> None:
    """Replace entry ``i`` of a :func:`generator_list` (the env's generator was reseeded)."""
    _set_generator(gens, i, g)


class _RowSampler:
    """What the envs' batched draws share: rows drawn into packed tables, one generator per row."""

    @property
    def max_thermals(self) -> int:
        """Most thermals a draw can have (the width a thermal table needs)."""
        raise NotImplementedError

    def _draw_rows(
        self,
        rows: np.ndarray,
        gens: Any,
        params: np.ndarray,
        thermals: np.ndarray,
        n_thermals: np.ndarray,
        start: np.ndarray,
    ) -> None:
        raise NotImplementedError

    def _check_slots(self, thermals: np.ndarray) -> None:
        if thermals.shape[1] < self.max_thermals:
            raise ConfigError(f"thermal table has {thermals.shape[1]} slots; draws need {self.max_thermals}")

    @staticmethod
    def _check_rows(rows: np.ndarray, n: int) -> None:
        """The kernels index without bounds checks: every row must name a row of every table."""
        if not (isinstance(rows, np.ndarray) and rows.dtype == np.int64 and rows.ndim == 1):
            raise ConfigError(f"rows must be a 1-D int64 array; got {type(rows).__name__} {getattr(rows, 'dtype', '')}")
        if rows.size and (rows.min() < 0 or rows.max() >= n):
            raise ConfigError(f"rows must lie in 0..{n - 1} (the tables' and generators' rows)")

    def draw_each(
        self,
        rows: np.ndarray,
        gens: Any,
        params: np.ndarray,
        thermals: np.ndarray,
        n_thermals: np.ndarray,
        start: np.ndarray,
    ) -> None:
        """Draw row ``i`` of ``rows`` (int64) from ``gens[i]`` (a :func:`generator_list`), all in one call."""
        self._check_slots(thermals)
        self._check_rows(rows, min(len(gens), params.shape[0], thermals.shape[0], n_thermals.shape[0], start.shape[0]))
        self._draw_rows(rows, gens, params, thermals, n_thermals, start)


class ScenarioSampler(_RowSampler):
    """v2 random scenarios of one set of keywords, drawn into packed rows.

    :param spec: the keywords (a :class:`~soaring_env.scenario.RandomScenarioSpec` or a dict of
        :func:`~soaring_env.scenario.make_scenario` keywords); validated like ``make_scenario``'s.

    The ``draw_*`` methods write, for each drawn row ``i``: ``params[i]`` (N_PARAMS,) a
    :func:`~soaring_env.env.observation.scenario_params` row, ``thermals[i, :k]`` its k
    ``WindField.packed`` rows (``thermals`` needs :attr:`max_thermals` slots; slots beyond k are
    left alone), ``n_thermals[i] = k`` and ``start[i]`` (Pn [m], Pe [m], chi [rad], h [m]).
    """

    def __init__(self, spec: RandomScenarioSpec | Mapping[str, Any] | None = None) -> None:
        self.spec = random_spec(spec)
        self._args = (
            _range_row(self.spec),
            self.spec.n_thermals[0],
            self.spec.n_thermals[1],
            self.spec.drift,
            RANDOM_TRIES,
            *_templates(self.spec),
        )

    @property
    def max_thermals(self) -> int:
        """Most thermals a draw can have (the width a thermal table needs)."""
        return self.spec.n_thermals[1]

    def _draw_rows(
        self,
        rows: np.ndarray,
        gens: Any,
        params: np.ndarray,
        thermals: np.ndarray,
        n_thermals: np.ndarray,
        start: np.ndarray,
    ) -> None:
        failed = _draw_each(rows, gens, *self._args, params, thermals, n_thermals, start)
        if failed >= 0:
            raise ConfigError(NO_FIT)

    def draw_from(
        self,
        rows: np.ndarray,
        rng: np.random.Generator,
        params: np.ndarray,
        thermals: np.ndarray,
        n_thermals: np.ndarray,
        start: np.ndarray,
    ) -> None:
        """Draw the rows ``rows`` (int64) in order, all from ``rng``."""
        check_type("rng", rng, np.random.Generator)
        self._check_slots(thermals)
        self._check_rows(rows, min(params.shape[0], thermals.shape[0], n_thermals.shape[0], start.shape[0]))
        failed = _draw_from(rows, rng, *self._args, params, thermals, n_thermals, start)
        if failed >= 0:
            raise ConfigError(NO_FIT)

    def draw(self, rng: np.random.Generator, n: int) -> ScenarioBatch:
        """``n`` scenarios drawn one after the other from ``rng``, as a :class:`ScenarioBatch`."""
        n = check_int("n", n, 1)
        params = np.empty((n, N_PARAMS))
        thermals = np.zeros((n, max(1, self.max_thermals), PACKED_COLUMNS))
        counts = np.zeros(n, dtype=np.int64)
        start = np.empty((n, 4))
        self.draw_from(np.arange(n, dtype=np.int64), rng, params, thermals, counts, start)
        return ScenarioBatch(spec=self.spec, params=params, thermals=thermals, n_thermals=counts, start=start)


# --- the Python generators' own streams, batched ------------------------------------------------
# Columns of a settings row (_settings_row): every kind, then climb, cross-country, goal reaching v1.
_T_H, _T_S, _T_WS, _T_LIFE, _T_RISE, _T_BIRTH, _T_AMP, _T_PERIOD = 0, 2, 4, 6, 8, 9, 11, 13
_T_NLO, _T_NHI, _T_RMAX = 15, 16, 17
_T_GD, _T_RATE, _T_WIDTH, _T_PAD, _T_MAXK = 18, 20, 22, 23, 24
_T_NMIN, _T_NMAX, _T_EMIN, _T_EMAX, _T_HMAX, _T_LAT, _T_ALONG, _T_TRIES, _T_MARGIN = 25, 26, 27, 28, 29, 30, 31, 33, 34
_N_SETTINGS = 35
_RANDOM_V1, _CLIMB, _XC = 0, 1, 2
_KINDS = {"random": _RANDOM_V1, "climb": _CLIMB, "xc": _XC}


def _settings_row(s: GeneratorSettings) -> np.ndarray:
    row = np.zeros(_N_SETTINGS)
    row[_T_H : _T_H + 2] = s.height
    row[_T_S : _T_S + 2] = s.strength
    row[_T_WS : _T_WS + 2] = s.wind_speed
    if s.time is not None:
        life, rise, births, amp, period = s.time
        if life is not None:
            row[_T_LIFE : _T_LIFE + 2] = life
        row[_T_RISE] = rise
        row[_T_BIRTH : _T_BIRTH + 2] = births
        if amp is not None:
            row[_T_AMP : _T_AMP + 2] = amp
        row[_T_PERIOD : _T_PERIOD + 2] = period
    row[_T_NLO], row[_T_NHI] = s.n_thermals
    row[_T_RMAX] = s.thermal_radius
    row[_T_GD : _T_GD + 2] = s.goal_distance
    row[_T_RATE : _T_RATE + 2] = s.thermals_per_km
    row[_T_WIDTH] = s.corridor
    row[_T_PAD] = s.margin
    row[_T_MAXK] = MAX_RANDOM_THERMALS
    if s.spec is not None:
        b = s.spec.domain
        row[_T_NMIN], row[_T_NMAX], row[_T_EMIN], row[_T_EMAX], row[_T_HMAX] = (
            b.north_min, b.north_max, b.east_min, b.east_max, b.height_max,
        )  # fmt: skip
        row[_T_LAT] = s.spec.lateral_spread
        row[_T_ALONG : _T_ALONG + 2] = s.spec.thermal_along
    row[_T_TRIES] = RANDOM_TRIES
    row[_T_MARGIN] = RANDOM_MARGIN
    row.setflags(write=False)
    return row


@njit(cache=True, error_model=_EM)
def _draw_generated_row(
    g: Any,
    i: int,
    kind: int,
    r: np.ndarray,
    has_life: bool,
    has_amp: bool,
    prm_t: np.ndarray,
    th_t: np.ndarray,
    prm: np.ndarray,
    th: np.ndarray,
    nth: np.ndarray,
    start: np.ndarray,
) -> bool:
    """One scenario from generator ``g`` into row ``i``: the calls of ``make_scenario`` (``kind`` 0,
    distribution v1), ``make_climb_scenario`` (1) or ``make_cross_country_scenario`` (2) on ``g``, in
    their order, with their arithmetic (no fast-math: every value is the one the generator's Python
    computes). False if goal reaching found no fit in its tries (``make_scenario`` raises then)."""
    pi = math.pi
    gn = ge = gh = sn = se = 0.0
    k = 0
    if kind == _RANDOM_V1:
        nmin, nmax, emin, emax, hmax = r[_T_NMIN], r[_T_NMAX], r[_T_EMIN], r[_T_EMAX], r[_T_HMAX]
        margin = r[_T_MARGIN]
        lat = r[_T_LAT]
        fit = False
        for _ in range(int(r[_T_TRIES])):
            dist = g.uniform(r[_T_GD], r[_T_GD + 1])
            bearing = g.uniform(-pi, pi)
            cn = 0.5 * (nmin + nmax)
            ce = 0.5 * (emin + emax)
            sn = cn - 0.5 * dist * math.cos(bearing) + g.uniform(-0.1, 0.1) * (nmax - nmin)
            se = ce - 0.5 * dist * math.sin(bearing) + g.uniform(-0.1, 0.1) * (emax - emin)
            gn = sn + dist * math.cos(bearing)
            ge = se + dist * math.sin(bearing)
            sh = g.uniform(r[_T_H], r[_T_H + 1])
            gh = g.uniform(r[_T_H], r[_T_H + 1])
            chi = bearing + g.uniform(-pi / 2, pi / 2)
            chi = (chi + pi) % (2 * pi) - pi
            k = g.integers(int(r[_T_NLO]), int(r[_T_NHI]) + 1)
            for j in range(k):
                along = g.uniform(r[_T_ALONG], r[_T_ALONG + 1])
                across = g.uniform(-lat, lat) * dist
                th[i, j, :] = th_t
                th[i, j, 0] = sn + along * (gn - sn) - across * math.sin(bearing)
                th[i, j, 1] = se + along * (ge - se) + across * math.cos(bearing)
                th[i, j, COL_STRENGTH] = g.uniform(r[_T_S], r[_T_S + 1])
            ws = g.uniform(r[_T_WS], r[_T_WS + 1])
            wd = g.uniform(-pi, pi)
            inside = (sn >= nmin and sn <= nmax and se >= emin and se <= emax and sh > 0.0 and sh <= hmax) and (
                gn >= nmin and gn <= nmax and ge >= emin and ge <= emax and gh > 0.0 and gh <= hmax
            )
            edge = min(sn - nmin, nmax - sn, se - emin, emax - se, gn - nmin, nmax - gn, ge - emin, emax - ge)
            if inside and not edge < margin:
                fit = True
                break
        if not fit:
            return False
        h0 = sh
    elif kind == _CLIMB:
        chi = g.uniform(-pi, pi)
        h0 = g.uniform(r[_T_H], r[_T_H + 1])
        k = g.integers(int(r[_T_NLO]), int(r[_T_NHI]) + 1)
        for j in range(k):
            rad = r[_T_RMAX] * math.sqrt(g.uniform(0.0, 1.0))
            a = g.uniform(-pi, pi)
            th[i, j, :] = th_t
            th[i, j, 0] = rad * math.cos(a)
            th[i, j, 1] = rad * math.sin(a)
            th[i, j, COL_STRENGTH] = g.uniform(r[_T_S], r[_T_S + 1])
        ws = g.uniform(r[_T_WS], r[_T_WS + 1])
        wd = g.uniform(-pi, pi)
    else:
        dist = g.uniform(r[_T_GD], r[_T_GD + 1])
        bearing = g.uniform(-pi, pi)
        gn = dist * math.cos(bearing)
        ge = dist * math.sin(bearing)
        chi = bearing + g.uniform(-pi / 2, pi / 2)
        chi = (chi + pi) % (2 * pi) - pi
        h0 = g.uniform(r[_T_H], r[_T_H + 1])
        k = min(int(round(g.uniform(r[_T_RATE], r[_T_RATE + 1]) * dist / 1000.0)), int(r[_T_MAXK]))
        width = r[_T_WIDTH]
        for j in range(k):
            along = g.uniform(0.05, 1.0) * dist
            across = g.uniform(-width, width)
            th[i, j, :] = th_t
            th[i, j, 0] = along * math.cos(bearing) - across * math.sin(bearing)
            th[i, j, 1] = along * math.sin(bearing) + across * math.cos(bearing)
            th[i, j, COL_STRENGTH] = g.uniform(r[_T_S], r[_T_S + 1])
        ws = g.uniform(r[_T_WS], r[_T_WS + 1])
        wd = g.uniform(-pi, pi)
    wn = ws * math.cos(wd)
    we = ws * math.sin(wd)
    # the life cycle and fluctuation draws of _draw_time_dependence: each quantity as one vector
    if has_life:
        for j in range(k):
            th[i, j, COL_DEATH] = g.uniform(r[_T_LIFE], r[_T_LIFE + 1])  # the lifetime, until the births
        for j in range(k):
            birth = g.uniform(r[_T_BIRTH], r[_T_BIRTH + 1])
            th[i, j, COL_BIRTH] = birth
            th[i, j, COL_DEATH] = birth + th[i, j, COL_DEATH]
            th[i, j, COL_RISE] = r[_T_RISE]
            th[i, j, COL_DECAY] = r[_T_RISE]
    if has_amp:
        for j in range(k):
            th[i, j, COL_AMPLITUDE] = g.uniform(r[_T_AMP], r[_T_AMP + 1])
        for j in range(k):
            th[i, j, COL_OMEGA] = 2.0 * pi / g.uniform(r[_T_PERIOD], r[_T_PERIOD + 1])
        for j in range(k):
            th[i, j, COL_PHASE] = g.uniform(-pi, pi)
    for j in range(k):  # as Thermal._row: dynamic unless steady, the peak w0 (1 + a)
        th[i, j, COL_DYNAMIC] = 1.0 if has_life or th[i, j, COL_AMPLITUDE] != 0.0 else 0.0
        th[i, j, COL_PEAK] = th[i, j, COL_STRENGTH] * (1.0 + th[i, j, COL_AMPLITUDE])
    nth[i] = k
    prm[i, :] = prm_t
    if kind != _CLIMB:
        prm[i, P_GN] = gn
        prm[i, P_GE] = ge
    if kind == _RANDOM_V1:
        prm[i, P_GH] = gh
    elif kind == _XC:
        pad = r[_T_PAD]
        prm[i, P_NMIN] = min(0.0, gn) - pad
        prm[i, P_NMAX] = max(0.0, gn) + pad
        prm[i, P_EMIN] = min(0.0, ge) - pad
        prm[i, P_EMAX] = max(0.0, ge) + pad
    prm[i, P_WN] = wn
    prm[i, P_WE] = we
    start[i, 0] = sn
    start[i, 1] = se
    start[i, 2] = chi
    start[i, 3] = h0
    return True


@njit(cache=True, error_model=_EM)
def _draw_generated_each(rows, gens, kind, r, has_life, has_amp, drift, prm_t, th_t, prm, th, nth, start) -> int:
    """Row ``i`` of ``rows`` from generator ``gens[i]`` (a typed List); -1, or the row that failed."""
    for i in rows:
        if not _draw_generated_row(gens[i], i, kind, r, has_life, has_amp, prm_t, th_t, prm, th, nth, start):
            return i
        prm[i, P_DVX] = prm[i, P_WN] if drift else 0.0
        prm[i, P_DVY] = prm[i, P_WE] if drift else 0.0
    return -1


class GeneratorSampler(_RowSampler):
    """Scenarios of a Python generator drawn into packed rows, many envs at once, bit for bit.

    :param generator: one of :data:`~soaring_env.scenario.BATCHED_GENERATORS`:
        :func:`~soaring_env.scenario.make_climb_scenario`,
        :func:`~soaring_env.scenario.make_cross_country_scenario`, or
        :func:`~soaring_env.scenario.make_scenario` (distribution v1; the envs use it where v2 does
        not apply: with the thermal life-cycle or fluctuation options).
    :param kwargs: its keywords (validated as the generator validates them).

    :meth:`draw_each` writes the rows :class:`ScenarioSampler` writes, but from exactly the
    generator calls the Python generator makes: ``generator(rng, **kwargs)`` from the same state
    gives the same :class:`Scenario`, whose ``scenario_params`` and ``field.packed`` are those rows,
    and leaves the generator in the same state.
    """

    def __init__(self, generator: Any, kwargs: Mapping[str, Any] | None = None) -> None:
        self.generator = generator
        self.settings = generator_settings(generator, {} if kwargs is None else kwargs)  # validates first
        self.kwargs = dict(kwargs or {})
        st = self.settings
        # templates from a real scenario: the columns no draw changes, in the layouts of
        # scenario_params and WindField.packed
        one = generator(np.random.default_rng(0), **self.kwargs)
        self._prm_t = scenario_params(one)
        self._th_t = WindField(thermals=(Thermal(north=0.0, east=0.0),), model=st.model, zi=st.zi).packed[0].copy()
        life = st.time is not None and st.time[0] is not None
        amp = st.time is not None and st.time[3] is not None
        self._args = (_KINDS[st.kind], _settings_row(st), life, amp, st.drift, self._prm_t, self._th_t)

    @property
    def max_thermals(self) -> int:
        """Most thermals a draw can have (the width a thermal table needs)."""
        st = self.settings
        if st.kind != "xc":
            return st.n_thermals[1]
        # round(rate * distance / 1 km) grows with both, so the highest of each bounds it
        return min(int(round(st.thermals_per_km[1] * st.goal_distance[1] / 1000.0)) + 1, MAX_RANDOM_THERMALS)

    def _draw_rows(
        self,
        rows: np.ndarray,
        gens: Any,
        params: np.ndarray,
        thermals: np.ndarray,
        n_thermals: np.ndarray,
        start: np.ndarray,
    ) -> None:
        if _draw_generated_each(rows, gens, *self._args, params, thermals, n_thermals, start) >= 0:
            raise ConfigError(NO_FIT)


def scenario_from_row(
    spec: RandomScenarioSpec, params: np.ndarray, thermals: np.ndarray, start: np.ndarray
) -> Scenario:
    """The :class:`Scenario` of one drawn row: ``params`` (N_PARAMS,), ``thermals`` (k, columns)
    its k packed thermal rows, ``start`` (4,). ``scenario_params`` and ``field.packed`` of the
    result give those rows back bit for bit."""
    field = WindField(
        thermals=tuple(Thermal(north=float(r[0]), east=float(r[1]), strength=float(r[2])) for r in thermals),
        model=spec.model,
        zi=spec.zi,
        wind_north=float(params[P_WN]),
        wind_east=float(params[P_WE]),
        drift=spec.drift,
    )
    goal = GoalRegion(
        north=float(params[P_GN]), east=float(params[P_GE]), height=float(params[P_GH]), radius=float(params[P_GR])
    )
    st = start.tolist()
    return Scenario(field=field, start=(st[0], st[1], st[2], st[3]), goal=goal, bounds=spec.domain, name=spec.name)


@dataclass(frozen=True)
class ScenarioBatch:
    """``n`` drawn scenarios as packed arrays (what the env kernels read).

    :param spec: the draw keywords.
    :param params: (n, N_PARAMS) float64 :func:`~soaring_env.env.observation.scenario_params` rows.
    :param thermals: (n, max(1, n_thermals high), PACKED_COLUMNS) float64 ``WindField.packed`` rows,
        zero beyond each row's count.
    :param n_thermals: (n,) int64 thermal counts.
    :param start: (n, 4) float64 start states (Pn [m], Pe [m], chi [rad], h [m]).
    """

    spec: RandomScenarioSpec
    params: np.ndarray
    thermals: np.ndarray
    n_thermals: np.ndarray
    start: np.ndarray

    def __len__(self) -> int:
        return int(self.params.shape[0])

    def scenario(self, i: int) -> Scenario:
        """Row ``i`` as a :class:`Scenario` (named ``spec.name``)."""
        return scenario_from_row(self.spec, self.params[i], self.thermals[i, : self.n_thermals[i]], self.start[i])


def draw_scenario_arrays(rng: np.random.Generator, n: int, **kwargs: Any) -> ScenarioBatch:
    """Draw ``n`` v2 random scenarios from ``rng`` at once (same generator state -> same batch).

    :param rng: the only source of randomness (advanced by the uniforms read).
    :param n: number of scenarios (>= 1).
    :param kwargs: the keywords of :func:`~soaring_env.scenario.make_scenario` (same ranges, same
        validation: a bad one raises a :class:`ConfigError` naming it).

    Scenario ``j`` reads the uniforms after those of scenario ``j - 1``: ``draw_width`` per try.
    A single env's reset draws ``draw_scenario_arrays(env.np_random, 1)``.
    """
    check_type("rng", rng, np.random.Generator)
    return ScenarioSampler(kwargs).draw(rng, n)
