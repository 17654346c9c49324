"""The Gymnasium environments: discrete motion primitives and continuous controls.

Both are thin shells over the model API (:class:`soaring_env.model.SoaringModel`): ``step`` rolls
out one edge of duration Ts from the current state with the project's rollout kernel, classifies
it (goal / crash / out of bounds / flying) and charges the full edge cost.
"""

from __future__ import annotations

import math
from collections import deque
from typing import TYPE_CHECKING, Any, ClassVar, SupportsFloat

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from soaring_env._validation import ConfigError, check_positive
from soaring_env.env._kernels import CRASH, FLYING, GOAL, OUT_OF_BOUNDS, step_rows
from soaring_env.env.config import ENERGY_SCALE, SoaringEnvConfig, choose_scenario, make_config, resolve_scenario
from soaring_env.env.observation import (
    HISTORY_FEATURES,
    HISTORY_POSITION_FEATURES,
    N_BASE,
    N_GOAL,
    N_PARAMS,
    P_GH,
    P_GR,
    observation_layout,
    observe_batch,
    scenario_params,
    sensor_noise,
)
from soaring_env.env.scenario_batch import ScenarioSampler, batched_draws, scenario_from_row
from soaring_env.model import BATTERY_EMPTY, OUTCOMES, STALL, SoaringModel
from soaring_env.physics.atmosphere import G
from soaring_env.physics.thermals import PACKED_COLUMNS, WindField
from soaring_env.primitives import N_PRIMITIVES, ControlEnvelope, PrimitiveLibrary
from soaring_env.scenario import Scenario, get_scenario, make_scenario

if TYPE_CHECKING:  # pragma: no cover - matplotlib is imported only when an env renders
    from soaring_env.env.rendering import Renderer

#: Progress shaping is counted per km of distance to the goal centre.
PROGRESS_SCALE = 1000.0
#: The raw env keeps the flown points and traces (``path``, ``history``) of the last this many
#: edges only, so that an episode without a time limit cannot grow memory without bound.
MAX_PATH_EDGES = 10_000
_ZERO_ROW = np.zeros(1, dtype=np.int64)
#: step_rows arguments of a single env: no row skipped, its own field (index table empty)
_NO_SKIP = np.zeros(1, dtype=np.bool_)
_NO_FIELD = np.empty(0, dtype=np.int64)


class SoaringBaseEnv(gym.Env[np.ndarray, Any]):
    """Energy-aware flight of a small powered glider to a goal region through thermal updrafts.

    ## Description

    A fixed-wing UAS (the Tempest: 6.4 kg, 3.3 m span, electric motor) must fly from a start state
    to a spherical goal region while spending as little specific energy [J/kg] as possible. It can
    harvest thermal updrafts (Allen 2006 or Gaussian thermals): circling in lift gains height for
    less motor energy than climbing does. This is the setting of Ryu et al., "energy-aware path
    planning ... with motion primitives": each step flies one of the paper's 174 motion
    primitives (straight, curve, spiral, spline) for Ts = 30 s -- or, in
    ``soaring/SoaringContinuous-v0``, holds a continuous control for Ts.

    The model behind the env is reachable as ``env.unwrapped.model`` (a
    :class:`~soaring_env.model.SoaringModel`): it rolls out any primitive or control from any
    state without touching the env, and ``step`` uses exactly its numbers, so a plan made with the
    model (e.g. by the SST planner) replays through ``step`` bit for bit. ``env.unwrapped.scenario``
    is the current :class:`~soaring_env.scenario.Scenario`, ``env.unwrapped.field`` its thermal
    field, ``env.unwrapped.state`` the state ``[Pn, Pe, chi, h]`` (float64, [m, m, rad, m]),
    ``env.unwrapped.time`` the flight time [s] and ``env.unwrapped.airspeed_prev`` the airspeed of
    the last edge [m/s] (NaN after reset: the first edge pays no speed-change term).

    ## Action Space

    ``soaring/Soaring-v0``: ``Discrete(174)``, the index of a motion primitive (order documented
    in :class:`~soaring_env.primitives.PrimitiveLibrary`; ``env.unwrapped.model.library.describe(i)``):

    | index   | family   | airspeed [m/s] | path angle [deg]     | turn over Ts [deg]                        |
    |---------|----------|----------------|----------------------|-------------------------------------------|
    | 0-9     | straight | 10, 20         | -45, -15, 0, 15, 45  | 0                                         |
    | 10-69   | curve    | 10, 20         | -45, -15, 0, 15, 45  | +-30, +-60, +-90                          |
    | 70-149  | spiral   | 10, 20         | -45, -15, 0, 15, 45  | +-180, +-360, +-720, +-1080               |
    | 150-173 | spline   | 10, 20         | 0                    | two of +-60, +-90 (first / second half)   |

    :meth:`action_masks` (for sb3-contrib's ``MaskablePPO``) masks primitives that would hit the
    ground, leave the domain or exceed the bank-angle limit.

    ``soaring/SoaringContinuous-v0``: ``Box(-1, 1, (3,), float32)``, mapped affinely onto the
    envelope of the primitives and held for Ts:

    | idx | control                  | -1           | +1          | unit  |
    |-----|--------------------------|--------------|-------------|-------|
    | 0   | airspeed v_a             | 10           | 20          | m/s   |
    | 1   | course rate chi_dot      | -1080 / Ts   | 1080 / Ts   | deg/s |
    | 2   | flight-path angle gamma  | -45          | 45          | deg   |

    ## Observation Space

    ``Box(float32)`` with finite bounds; every entry is clipped into them. Default scales: 1 km
    (distances, heights), 5 m/s (vertical winds), 20 m/s (airspeed), 10 m/s (horizontal wind).
    ``env.unwrapped.observation_names`` lists the entries.

    | idx     | observation                                             | unit (before scaling) | bounds    |
    |---------|---------------------------------------------------------|-----------------------|-----------|
    | 0, 1    | goal centre minus position, north / east                | m                     | +-10      |
    | 2       | goal height minus height                                | m                     | +-3       |
    | 3, 4    | sin, cos of the course chi                              | -                     | +-1       |
    | 5       | height h                                                | m                     | [-1, 3]   |
    | 6       | updraft w_up at the aircraft                            | m/s                   | +-4       |
    | 7       | mean updraft along the last edge (0 after reset)        | m/s                   | +-4       |
    | 8       | airspeed of the last edge (0 after reset)               | m/s                   | [0, 2]    |
    | 9, 10   | ambient wind, north / east                              | m/s                   | +-4       |
    | 11+5j   | slot j holds a thermal (1) or is empty (0, all zeros)   | -                     | [0, 1]    |
    | 12+5j,  | thermal centre minus position, north / east             | m                     | +-10      |
    | 13+5j   |                                                         |                       |           |
    | 14+5j   | peak updraft of the thermal at the aircraft's height    | m/s                   | [0, 4]    |
    | 15+5j   | updraft radius at that height (Allen r2, Gaussian R)    | m                     | [0, 4]    |

    Slots j = 0 .. K-1 (``n_obs_thermals``, default 3) hold the nearest living thermals, nearest
    first, with their current strength (thermals with a life cycle are absent before their birth and
    after their death; see :mod:`soaring_env.env.observation`).
    With ``observe_thermals=False`` the observation is only entries 0-10: the agent senses lift
    locally (entries 6-7) and must find thermals itself -- a partially observed task.

    ## Rewards

    Reward units are kJ/kg of specific energy. Each step gives the sum of these terms, each also
    reported in ``info["reward_terms"]``:

    - ``energy``: ``-energy_weight * edge_cost / 1000`` (weight 1 by default), the negative net
      specific energy spent on the edge (motor energy + potential energy lost + kinetic energy
      added). Positive in strong lift.
    - ``progress``: ``progress_weight * (d_before - d_after) / 1 km`` with d the 3-D distance to
      the goal centre (potential-based shaping; default weight 1; 0 turns it off).
    - ``goal``: ``+goal_bonus`` (default 25) on reaching the goal region.
    - ``crash``: ``-crash_penalty`` (default 25) on ground contact.
    - ``out_of_bounds``: ``-out_of_bounds_penalty`` (default 25) on leaving the flight domain.

    The full edge cost is charged even when the edge ends early at an event.

    ## Starting State

    The scenario's start state: in the default ``"paper"`` scenario ``[0, 0, 0, 300]`` (origin,
    heading north, 300 m), goal 3 km north at 300 m (radius 150 m), one Allen thermal
    (w* = 2.56 m/s, zi = 1400 m) 1.5 km north, 250 m east. With ``scenario="random"`` every reset
    draws thermal count, positions, strengths, wind, start and goal from ``env.np_random``.
    ``reset(options={"scenario": s})`` pins a scenario for that episode: a Scenario, its dict,
    ``"random"``, or a name of :func:`~soaring_env.scenario.get_scenario` (``"paper"``,
    ``"random-<seed>"``, a path to a scenario ``.json`` file) -- the same forms as ``scenario=``;
    ``options["airspeed_prev"]`` [m/s] (single envs) starts it as if an edge at that airspeed had
    just been flown (a start mid-flight: the first edge pays the speed change).
    Random scenarios follow distribution v2 (:mod:`soaring_env.env.scenario_batch`: the ranges of
    :func:`~soaring_env.scenario.make_scenario`, drawn as the batched vector env draws them, so
    ``gym.make_vec(..., num_envs=n)`` equals n single envs); ``"random-<seed>"`` names stay v1.

    ## Episode End

    Each step flies Ts = 30 s and checks N = 30 points along the edge; at the first point that is

    1. inside the goal region -- terminated, success (``info["is_success"]`` True);
    2. at or below the ground (h <= 0) -- terminated (crash);
    3. outside the flight domain (horizontal bounds or the ceiling) -- terminated.

    The new state is that event point (else the edge's end). The env truncates the episode itself
    after ``max_steps`` steps (default 40 = 20 min of flight; ``gym.make(id, max_steps=N)``), or
    at ``time_limit`` if one is set; a ``step()`` after that raises until ``reset()``.

    ## Information

    ``info`` (Python floats, SI units): ``energy_spent`` (cumulative, J/kg), ``edge_cost``,
    ``fuel``, ``potential``, ``kinetic`` (the edge's terms, J/kg; ``edge_cost`` is their sum),
    ``height`` [m], ``airspeed`` [m/s], ``bank_angle`` (largest along the edge, rad), ``updraft``
    (at the new position, m/s), ``time`` [s], ``outcome`` (``"flying"``, ``"goal"``, ``"crash"``,
    ``"out_of_bounds"``), ``is_success`` (bool), ``reward_terms`` (dict). ``reset`` returns
    ``energy_spent``, ``height``, ``updraft``, ``time``, ``outcome``, ``is_success``, ``scenario``.

    ## Arguments

    ```python
    import gymnasium as gym
    import soaring_env
    env = gym.make("soaring/Soaring-v0", render_mode="rgb_array")          # defaults
    env = gym.make("soaring/Soaring-v0", scenario="random", observe_thermals=False)
    env = gym.make("soaring/Soaring-v0", config=soaring_env.SoaringEnvConfig(goal_bonus=50.0))
    ```

    ``config`` is a :class:`~soaring_env.env.config.SoaringEnvConfig` (or a dict of its fields);
    keyword arguments override single fields. ``render_mode`` is ``None``, ``"rgb_array"``
    (uint8 H x W x 3 frames, headless) or ``"human"`` (a matplotlib window).

    ## Version History

    * v0: initial version.
    """

    metadata: dict[str, Any] = {"render_modes": ["human", "rgb_array"], "render_fps": 4}  # noqa: RUF012
    continuous: ClassVar[bool] = False
    #: the task's config class (its defaults and extra fields)
    config_class: ClassVar[type[SoaringEnvConfig]] = SoaringEnvConfig
    #: whether the task has a goal region (goal entries, progress shaping, the goal bonus)
    has_goal: ClassVar[bool] = True
    #: whether the task's motor runs on a battery (:meth:`battery_budget`; outcome "battery_empty")
    has_battery: ClassVar[bool] = False
    #: the task's extra observation entries (keys of observation.TASK_FEATURES)
    task_extras: ClassVar[tuple[str, ...]] = ()

    def __init__(
        self,
        config: SoaringEnvConfig | dict[str, Any] | None = None,
        render_mode: str | None = None,
        **overrides: Any,
    ) -> None:
        cfg = make_config(config, overrides, self.config_class)
        self.config = cfg
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ConfigError(
                f"render_mode={render_mode!r} is not supported; allowed: None, "
                + ", ".join(repr(m) for m in self.metadata["render_modes"])
            )
        self.render_mode = render_mode
        self.library = PrimitiveLibrary(duration=cfg.duration, n_points=cfg.n_points)
        self._fixed_scenario = resolve_scenario(cfg.scenario, cfg.random_scenario, cfg.generator)
        first = self._fixed_scenario or self._placeholder_scenario()
        if self.continuous and cfg.aircraft.cl_max is not None and cfg.envelope == "paper":
            raise ConfigError(
                f"aircraft.cl_max={cfg.aircraft.cl_max!r} with envelope='paper': the paper's envelope flies 10 m/s "
                "spirals far past any stall limit; allowed: envelope='physical' (or cl_max=None)"
            )
        #: the continuous envelope (None: the paper's), evaluated at the first scenario's ceiling
        self.envelope: ControlEnvelope | None = (
            None
            if cfg.envelope == "paper"
            else ControlEnvelope.physical(
                cfg.aircraft,
                max_bank_deg=cfg.max_bank_deg,
                height_max=first.bounds.height_max,
                airspeed=cfg.airspeed_range,
                gamma_deg=cfg.gamma_range_deg,
            )
        )
        self._extras = (
            self.task_extras
            + (("time_left",) if cfg.time_limit is not None else ())
            + (("start_north", "start_east") if cfg.observe_start else ())
        )
        self._hist_len = cfg.history_length
        self._hist_pos = cfg.history_positions
        names, low, high = observation_layout(
            cfg.observe_thermals,
            cfg.n_obs_thermals,
            goal=self.has_goal,
            extras=self._extras,
            history=self._hist_len,
            history_positions=self._hist_pos,
        )
        #: where the task's entries, the history and the thermal slots start in the observation
        self._extra_base = N_BASE if self.has_goal else N_BASE - N_GOAL
        self._hist_base = self._extra_base + len(self._extras)
        #: entries per history edge (lift, climb, turn; with positions also north, east)
        self._hist_width = len(HISTORY_FEATURES) + (len(HISTORY_POSITION_FEATURES) if self._hist_pos else 0)
        self._th_base = self._hist_base + self._hist_width * self._hist_len
        self._goal_on = int(self.has_goal)
        self._noise_sigma = float(cfg.sensor_noise)
        self._time_limit = math.inf if cfg.time_limit is None else float(cfg.time_limit)
        self._max_steps = math.inf if cfg.max_steps is None else int(cfg.max_steps)
        self.observation_names: list[str] = names
        self.observation_space = spaces.Box(low, high, dtype=np.float32)
        self._n_obs = len(names)
        self.action_space = self._make_action_space()
        self._low, self._high = low, high
        self._scales = np.array(
            [cfg.position_scale, cfg.height_scale, cfg.updraft_scale, cfg.speed_scale, cfg.wind_scale]
        )
        self._k_obs = cfg.n_obs_thermals if cfg.observe_thermals else 0
        self._ts = float(self.library.duration)
        self._dt = self.library.duration / self.library.n_points
        self._w_progress = float(cfg.progress_weight)
        self._w_energy = float(cfg.energy_weight)
        self._settle = bool(cfg.settle_height)
        if self._settle and not self.has_goal:
            raise ConfigError(f"settle_height=True needs a goal; {type(self).__name__} has none (allowed: False)")
        # Terminal reward terms indexed by the outcome code (model.OUTCOMES).
        self._terminal = {
            name: np.array([value if code == c else 0.0 for c in range(len(OUTCOMES))])
            for name, code, value in self._terminal_terms()
        }
        # scratch buffers of the hot path (copied into Python floats before step returns)
        self._t0 = np.zeros(1)
        self._vp = np.full(1, np.nan)
        self._tn = np.zeros(1)
        self._codes = np.zeros(1, dtype=np.int64)
        self._ks = np.zeros(1, dtype=np.int64)
        self._upd = np.zeros(1)
        self._lift = np.zeros(1)
        self._dist = np.zeros(1)
        self._ctrl = np.zeros((1, 4))
        self._x0 = np.zeros((1, 4))
        # "random" draws (distribution v2) from env.np_random; set up at the first draw
        self._sampler: ScenarioSampler | None = None
        self._noise = np.zeros((1, 2))
        self._noise_key = np.zeros(1, dtype=np.uint64)
        self._history = np.zeros((1, self._hist_len, self._hist_width))
        self.scenario: Scenario = first
        self._install(self.scenario)
        self._start_episode()
        self._needs_reset = True
        self._renderer: Renderer | None = None

    # --- public attributes of the contract -------------------------------------------------------
    @property
    def field(self) -> WindField:
        """The current thermal field and ambient wind (``scenario.field``)."""
        return self.scenario.field

    @property
    def path(self) -> np.ndarray:
        """Every flown point of the episode so far, (M, 4) ``[Pn, Pe, chi, h]``, start included (of
        the last ``MAX_PATH_EDGES`` edges only, on longer episodes)."""
        return np.concatenate(self._path, axis=0)

    @property
    def episode_steps(self) -> int | None:
        """The most steps an episode has: ``max_steps`` or ``time_limit`` over Ts [s], whichever
        ends it first (None: neither is set). Planners plan within ``episode_steps - steps``."""
        limits = [] if self.config.max_steps is None else [int(self.config.max_steps)]
        if self.config.time_limit is not None:
            limits.append(int(round(self.config.time_limit / self.library.duration)))
        return min(limits) if limits else None

    def _make_action_space(self) -> spaces.Space:
        raise NotImplementedError

    # --- task hooks (overridden by the tasks of soaring_env.env.tasks) ---------------------------
    def _placeholder_scenario(self) -> Scenario:
        """The scenario before the first reset in ``"random"`` mode: ``"paper"`` for goal reaching,
        a task's draw of seed 0 (``<family>-0``) for the others."""
        cfg = self.config
        if cfg.generator is make_scenario:
            return get_scenario("paper")
        return cfg.generator(np.random.default_rng(0), **dict(cfg.random_scenario))

    def _terminal_terms(self) -> list[tuple[str, int, float]]:
        """(reward-term name, outcome code, value) of the terminal rewards; ``stall`` (the crash
        penalty) only on the primitive envs with a stall limit."""
        cfg = self.config
        terms = [
            ("goal", GOAL, float(cfg.goal_bonus)),
            ("crash", CRASH, -float(cfg.crash_penalty)),
            ("out_of_bounds", OUT_OF_BOUNDS, -float(cfg.out_of_bounds_penalty)),
        ]
        if not self.continuous and cfg.aircraft.cl_max is not None:
            terms.append(("stall", STALL, -float(cfg.crash_penalty)))
        return terms

    def battery_budget(self, scenario: Scenario) -> float:
        """The motor energy [J/kg] an episode in ``scenario`` may spend (inf: no battery limit)."""
        if not self.has_battery:
            return math.inf
        g = scenario.require_goal()
        return self._battery_budget_at(g.north, g.east, scenario.start[0], scenario.start[1])

    def _battery_budget_at(self, goal_north: float, goal_east: float, start_north: float, start_east: float) -> float:
        """:meth:`battery_budget` of a scenario with its goal centre and start at these positions [m]
        (what the budget depends on; the batched env reads them from its packed rows)."""
        return math.inf

    def _fill_task_entries(
        self,
        obs: np.ndarray,
        rows: np.ndarray,
        times: np.ndarray,
        battery_left: np.ndarray,
        budget: np.ndarray,
        history: np.ndarray,
        positions: np.ndarray,
        starts: np.ndarray,
        n_flown: np.ndarray,
    ) -> None:
        """Write the task's extra entries and the ``history`` (B, H, W) of envs ``rows`` into ``obs``
        (batched: the single env passes one row, the vector env all of its own). ``positions``,
        ``starts`` (B, 2): the aircraft's north and east now and at the episode's start [m];
        ``n_flown`` (B,): edges flown so far (the history's positions are relative to
        ``positions``, zero where no edge was flown yet)."""
        i = self._extra_base
        for key in self._extras:
            if key == "battery":
                v = battery_left[rows] / budget[rows]
            elif key == "time_left":
                v = np.maximum(self._time_limit - times[rows], 0.0) / self._time_limit
            else:  # start_north, start_east
                c = 0 if key == "start_north" else 1
                v = (starts[rows, c] - positions[rows, c]) / self.config.position_scale
            obs[rows, i] = np.clip(v, self._low[i], self._high[i])
            i += 1
        if self._hist_len:
            lo = self._low[self._hist_base : self._th_base]
            hi = self._high[self._hist_base : self._th_base]
            h = history[rows]
            if self._hist_pos:
                p = len(HISTORY_FEATURES)
                rel = (h[:, :, p:] - positions[rows, None, :]) / self.config.position_scale
                flown = np.arange(self._hist_len)[None, :] < n_flown[rows, None]
                h[:, :, p:] = np.where(flown[:, :, None], rel, 0.0)
            obs[rows, self._hist_base : self._th_base] = np.clip(h.reshape(len(rows), -1), lo, hi)

    def _push_history(
        self,
        history: np.ndarray,
        lift: np.ndarray,
        dh: np.ndarray,
        dchi: np.ndarray,
        flown: np.ndarray,
        out: np.ndarray,
        ks: np.ndarray,
    ) -> None:
        """Shift ``history`` (B, H, W) and put the last edge first: mean (sensed) lift and climb rate
        over the flown time ``flown`` [s] (scaled like the updraft), course change / pi; with
        positions, the north and east [m] of the edge's time midpoint (point ``ks // 2`` of its
        flown points ``out``, B x N x 4; ``ks`` the last flown point's index)."""
        if not self._hist_len:
            return
        h = history
        rows = slice(None)
        h[rows, 1:] = h[rows, :-1]
        us = self.config.updraft_scale
        h[rows, 0, 0] = lift / us
        h[rows, 0, 1] = dh / flown / us
        h[rows, 0, 2] = (dchi + math.pi) % (2.0 * math.pi) / math.pi - 1.0
        if self._hist_pos:
            p = len(HISTORY_FEATURES)
            h[rows, 0, p:] = out[np.arange(out.shape[0]), ks // 2, :2]

    def reward_terms(self, cost, d_prev, d_new, code) -> dict[str, Any]:
        """The reward terms of an edge -- floats for one edge, arrays for a batch (the vector env).

        ``energy = -energy_weight cost / 1000`` (cost in J/kg), ``progress = w (d_prev - d_new) / 1000`` (goal
        distances in m), and the terminal terms of the outcome ``code``; the reward is their sum.
        """
        terms = {"energy": -self._w_energy * cost / ENERGY_SCALE}
        if self.has_goal:
            terms["progress"] = self._w_progress * (d_prev - d_new) / PROGRESS_SCALE
        for key, by_code in self._terminal.items():
            terms[key] = by_code[code]
        return terms

    def settle_terms(self, terms: dict[str, Any], truncated, h_end, prm: np.ndarray) -> None:
        """Add the ``settlement`` term of ``config.settle_height`` to ``terms`` in place (nothing when
        off): ``energy_weight g (h_top - h_end) / 1 kJ/kg`` where ``truncated``, else 0, h_top [m] the
        goal top of the :func:`scenario_params` row(s) ``prm`` -- a float for one edge, arrays for a
        batch. ``truncated`` must be False on terminating steps."""
        if self._settle:
            h_top = prm[..., P_GH] + prm[..., P_GR]
            terms["settlement"] = np.where(truncated, self._w_energy * G * (h_top - h_end) / ENERGY_SCALE, 0.0)

    # --- scenario handling -----------------------------------------------------------------------
    def _install(self, sc: Scenario) -> None:
        """Make ``sc`` the current scenario: model, propagator and packed kernel arguments."""
        cfg = self.config
        self.scenario = sc
        self.model = SoaringModel(
            scenario=sc,
            aircraft=cfg.aircraft,
            library=self.library,
            max_substep=cfg.max_substep,
            max_bank_deg=cfg.max_bank_deg,
            envelope=self.envelope,
        )
        self._prop = self.model.propagator
        self._prm = scenario_params(sc)[None, :]
        self._th = np.ascontiguousarray(sc.field.packed[None, :, :])
        self._nth = np.array([len(sc.field.thermals)], dtype=np.int64)
        self._allowed = self.model.allowed_primitives()
        #: (174,) bool: the primitives past the stall limit (flying one ends the episode: "stall")
        self._stalls = ~self.model.stall_ok()

    def _draw_random(self) -> Scenario:
        """A new random scenario from ``self.np_random``: ``draw_scenario_arrays(np_random, 1)``, the
        draw env ``i`` of a vector env makes from its generator (goal reaching, distribution v2); the
        task's generator where the batched draw does not apply (:func:`batched_draws`)."""
        cfg = self.config
        if not batched_draws(cfg.generator, cfg.random_scenario):
            return cfg.generator(self.np_random, **dict(cfg.random_scenario))
        sampler = self._sampler
        if sampler is None:
            sampler = self._sampler = ScenarioSampler(self.config.random_scenario)
            self._drawn = (
                np.empty((1, N_PARAMS)),
                np.zeros((1, max(1, sampler.max_thermals), PACKED_COLUMNS)),
                np.zeros(1, dtype=np.int64),
                np.empty((1, 4)),
            )
        prm, th, nth, start = self._drawn
        sampler.draw_from(_ZERO_ROW, self.np_random, prm, th, nth, start)
        return scenario_from_row(sampler.spec, prm[0], th[0, : nth[0]], start[0])

    def _start_episode(self, airspeed_prev: float = math.nan) -> tuple[np.ndarray, dict[str, Any]]:
        sc = self.scenario
        self.state = sc.start_state
        self.time = 0.0
        self.airspeed_prev = airspeed_prev
        self.energy_spent = 0.0
        self.steps = 0
        self.outcome = "flying"
        self._lift[0] = 0.0
        self.battery = self.battery_budget(sc)
        self.battery_left = self.battery
        self._history[:] = 0.0
        if self._noise_sigma:
            self._noise_key[0] = self.np_random.integers(0, 2**63, dtype=np.uint64)
            self._noise[:] = sensor_noise(self._noise_key, np.zeros(1, dtype=np.uint64), self._noise_sigma)
        obs = np.empty((1, self._n_obs), dtype=np.float32)
        observe_batch(
            self.state[None, :],
            np.zeros(1),
            np.full(1, airspeed_prev),
            self._lift,
            self._prm,
            self._th,
            self._nth,
            self._scales,
            self._k_obs,
            self._low,
            self._high,
            self._goal_on,
            self._th_base,
            self._noise,
            _ZERO_ROW,
            self._upd,
            self._dist,
            obs,
        )
        self._fill_task_entries(
            obs,
            _ZERO_ROW,
            np.zeros(1),
            np.array([self.battery_left]),
            np.array([self.battery]),
            self._history,
            self.state[None, :2],
            self.state[None, :2],
            np.zeros(1, dtype=np.int64),
        )
        self._d_goal = float(self._dist[0])
        self.updraft = float(self._upd[0])
        self._path: deque[np.ndarray] = deque([self.state[None, :].copy()], maxlen=MAX_PATH_EDGES + 1)
        self.history: dict[str, deque[float]] = {
            key: deque([v], maxlen=MAX_PATH_EDGES + 1)
            for key, v in (
                ("time", 0.0),
                ("height", float(self.state[3])),
                ("energy_spent", 0.0),
                ("updraft", self.updraft),
            )
        }
        info = {
            "energy_spent": 0.0,
            "height": float(self.state[3]),
            "updraft": self.updraft,
            "time": 0.0,
            "outcome": "flying",
            "is_success": False,
            "scenario": sc.name,
        }
        return obs[0], info

    # --- gymnasium API -------------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        """Start an episode; ``options={"scenario": Scenario | name | dict | "random"}`` pins a scenario.

        ``options["airspeed_prev"]`` [m/s] starts the episode as if an edge at that airspeed had just
        been flown (the first edge then pays the speed change, and the observation shows it): a start
        mid-flight, as in a model rebuilt from an observation (:class:`baselines.agents.RolloutAgent`).
        Without it the first edge pays no speed change."""
        super().reset(seed=seed)
        cfg = self.config
        sc = choose_scenario(options, self._fixed_scenario, cfg.random_scenario, cfg.generator, ("airspeed_prev",))
        v_prev = (options or {}).get("airspeed_prev")
        if v_prev is not None:
            v_prev = check_positive("options['airspeed_prev']", v_prev)
        if sc is None:
            sc = self._draw_random()
        if sc is not self.scenario:
            self._install(sc)
        obs, info = self._start_episode(math.nan if v_prev is None else v_prev)
        self._needs_reset = False
        if self.render_mode == "human":
            self.render()
        return obs, info

    def _advance(self, ctrl: np.ndarray, primitive: int | None) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        if self._needs_reset:
            raise RuntimeError(
                "step() called before reset() or after the episode ended (terminated or truncated); call reset() first"
            )
        x0 = self._x0  # a writable buffer: see primitives.Propagator
        x0[0, :] = self.state
        self._t0[0] = self.time
        self._vp[0] = self.airspeed_prev
        t_new = self.time + self._ts
        self._tn[0] = t_new
        obs = np.empty((1, self._n_obs), dtype=np.float32)
        new_state = np.empty((1, 4))
        out = np.empty((1, self.library.n_points, 4))  # kept: the path of the flown part
        terms = np.empty((1, 6))
        if self._noise_sigma:
            self._noise[:] = sensor_noise(
                self._noise_key, np.array([self.steps + 1], dtype=np.uint64), self._noise_sigma
            )
        prop = self._prop
        dur, n_pts, k_switch, max_substep, ac = prop.kernel_constants
        step_rows(
            _NO_SKIP, x0, self._t0, ctrl, self._vp, _NO_FIELD, dur, n_pts, k_switch, max_substep, *prop.field_tables,
            ac, out, terms, self._dt, self._tn, self._prm, self._th, self._nth, self._scales, self._k_obs, self._low,
            self._high, self._goal_on, self._th_base, self._noise, self._codes, self._ks, new_state, self._upd,
            self._lift, self._dist, obs,
        )  # fmt: skip
        code = int(self._codes[0])
        k = int(self._ks[0])
        fuel, potential, kinetic, cost, bank, _ = terms[0].tolist()
        if self.has_battery:  # the motor's energy: fuel and the speed change's kinetic charge
            self.battery_left -= fuel + kinetic
            if code == FLYING and self.battery_left <= 0.0:
                code = BATTERY_EMPTY
        if primitive is not None and self._stalls[primitive]:  # the wing cannot fly it: whatever the edge did
            code = STALL
        if self._extras or self._hist_len:
            self._push_history(
                self._history,
                self._lift + self._noise[:, 1],
                new_state[:, 3] - x0[:, 3],
                new_state[:, 2] - x0[:, 2],
                np.array([(k + 1) * self._dt]),
                out,
                self._ks,
            )
            self._fill_task_entries(
                obs,
                _ZERO_ROW,
                self._tn,
                np.array([self.battery_left]),
                np.array([self.battery]),
                self._history,
                new_state[:, :2],
                self.scenario.start_state[None, :2],
                np.array([self.steps + 1]),
            )
        airspeed = float(ctrl[0, 0])
        d_new = float(self._dist[0])
        updraft = float(self._upd[0])
        self.state = new_state[0]
        self.time = t_new
        self.airspeed_prev = airspeed
        self.energy_spent += cost
        self.steps += 1
        self.updraft = updraft
        outcome = OUTCOMES[code]
        self.outcome = outcome
        terminated = code != FLYING
        # the step limit truncates as gymnasium's TimeLimit does (also on the terminating step)
        truncated = self.steps >= self._max_steps or (not terminated and t_new >= self._time_limit - 1e-9)
        self._needs_reset = terminated or truncated
        h = float(new_state[0, 3])
        by_term = self.reward_terms(cost, self._d_goal, d_new, code)
        self.settle_terms(by_term, truncated and not terminated, h, self._prm[0])
        reward_terms = {key: float(v) for key, v in by_term.items()}
        reward = sum(reward_terms.values())
        self._d_goal = d_new
        self._path.append(out[0, : k + 1])
        hist = self.history
        hist["time"].append(t_new)
        hist["height"].append(h)
        hist["energy_spent"].append(self.energy_spent)
        hist["updraft"].append(updraft)
        info = {
            "energy_spent": self.energy_spent,
            "edge_cost": cost,
            "fuel": fuel,
            "potential": potential,
            "kinetic": kinetic,
            "height": h,
            "airspeed": airspeed,
            "bank_angle": bank,
            "updraft": updraft,
            "time": t_new,
            "outcome": outcome,
            "is_success": code == GOAL,
            "reward_terms": reward_terms,
        }
        if self.has_battery:
            info["battery_left"] = self.battery_left
        if self.render_mode == "human":
            self.render()
        return obs[0], reward, terminated, truncated, info

    # --- rendering -----------------------------------------------------------------------------------
    def render(self) -> np.ndarray | None:
        """``rgb_array``: a uint8 (H, W, 3) frame; ``human``: draw into a window, return None."""
        if self.render_mode is None:
            gym.logger.warn(
                "render() called without a render mode; pass render_mode='rgb_array' or 'human' to gym.make"
            )
            return None
        if self._renderer is None:
            from soaring_env.env.rendering import Renderer

            self._renderer = Renderer(self.config.render_size, human=self.render_mode == "human")
        frame = self._renderer.draw(self)
        return frame if self.render_mode == "rgb_array" else None

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    # --- helpers -------------------------------------------------------------------------------------
    def decode_observation(self, obs: np.ndarray) -> dict[str, float]:
        """The observation as ``{name: value}`` (scaled values, see the class docstring)."""
        return {n: float(v) for n, v in zip(self.observation_names, np.asarray(obs).ravel(), strict=True)}


class SoaringEnv(SoaringBaseEnv):
    __doc__ = SoaringBaseEnv.__doc__
    continuous: ClassVar[bool] = False

    def _make_action_space(self) -> spaces.Space:
        return spaces.Discrete(N_PRIMITIVES)

    def step(self, action: Any) -> tuple[np.ndarray, SupportsFloat, bool, bool, dict[str, Any]]:
        """Fly primitive ``action`` for Ts; see the class docstring for rewards and episode end."""
        idx = self._action_index(action)
        return self._advance(self._prop.ctrl_rows[idx], idx)

    def _action_index(self, action: Any) -> int:
        if type(action) is int:
            idx = action
        elif isinstance(action, np.integer):
            idx = int(action)
        elif isinstance(action, np.ndarray) and action.shape == () and action.dtype.kind in "iu":
            idx = int(action)
        else:
            raise ConfigError(
                f"action={action!r} (type {type(action).__name__}) is invalid; "
                f"allowed: an integer primitive index in 0..{N_PRIMITIVES - 1} (Discrete({N_PRIMITIVES}))"
            )
        if not 0 <= idx < N_PRIMITIVES:
            raise ConfigError(
                f"action={idx} is out of range; allowed: 0..{N_PRIMITIVES - 1} (Discrete({N_PRIMITIVES}))"
            )
        return idx

    # --- action masking ------------------------------------------------------------------------------
    def action_masks(self) -> np.ndarray:
        """(174,) bool: True for primitives that neither hit the ground, nor leave the domain, nor
        exceed ``max_bank_deg``, rolled out from the current state in one batched model call.

        Never all False: if every primitive is invalid, the bank-feasible primitives whose first
        event comes latest along the edge (they stay airborne and inside longest) are unmasked.
        """
        m = self.model
        r = m.rollout_primitive(self.state, np.arange(N_PRIMITIVES), t0=self.time, airspeed_prev=self.airspeed_prev)
        code, k = m.classify(r)
        valid = (code != CRASH) & (code != OUT_OF_BOUNDS) & self._allowed
        if not valid.any():
            kk = np.where(self._allowed, k, -1)
            valid = kk == kk.max()
        return valid


class SoaringContinuousEnv(SoaringBaseEnv):
    __doc__ = SoaringBaseEnv.__doc__
    continuous: ClassVar[bool] = True

    def _make_action_space(self) -> spaces.Space:
        return spaces.Box(-1.0, 1.0, shape=(3,), dtype=np.float32)

    def _install(self, sc: Scenario) -> None:
        super()._install(sc)
        env = self.model.control_envelope
        lo, hi = env.bounds()
        self._c_lo = lo.tolist()
        self._c_span = (hi - lo).tolist()
        self._affine = env.kind == "paper"  # the paper's box: the scalar fast path below

    def action_to_control(self, action: Any) -> tuple[float, float, float]:
        """Validate a normalized action and map it like ``model.action_to_control`` (same floats):
        returns ``(v_a [m/s], chi_dot [rad/s], gamma [rad])``."""
        a = action if isinstance(action, np.ndarray) else np.asarray(action)
        if a.shape != (3,) or a.dtype.kind not in "fiu":
            raise ConfigError(
                f"action={action!r} has shape {a.shape} and dtype {a.dtype}; allowed: a real array of shape (3,) "
                "in [-1, 1] (v_a, chi_dot, gamma), Box(-1, 1, (3,), float32)"
            )
        a0, a1, a2 = a.tolist()
        if not (-1.0 <= a0 <= 1.0 and -1.0 <= a1 <= 1.0 and -1.0 <= a2 <= 1.0):
            raise ConfigError(
                f"action={a.tolist()!r} is outside the action space; allowed: finite values in [-1, 1] "
                "for (v_a, chi_dot, gamma)"
            )
        if not self._affine:
            v, chi_dot, gamma = self.model.control_envelope.to_control(a).tolist()
            return v, chi_dot, gamma
        lo, sp = self._c_lo, self._c_span
        return (
            lo[0] + 0.5 * (a0 + 1.0) * sp[0],
            lo[1] + 0.5 * (a1 + 1.0) * sp[1],
            lo[2] + 0.5 * (a2 + 1.0) * sp[2],
        )

    def step(self, action: Any) -> tuple[np.ndarray, SupportsFloat, bool, bool, dict[str, Any]]:
        """Hold the control ``action`` (normalized v_a, chi_dot, gamma) for Ts."""
        v, chi_dot, gamma = self.action_to_control(action)
        c = self._ctrl
        c[0, 0] = v
        c[0, 1] = gamma
        c[0, 2] = chi_dot
        c[0, 3] = chi_dot
        return self._advance(c, None)
