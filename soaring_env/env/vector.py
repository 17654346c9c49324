"""A natively batched vector env: numpy over all envs at once, one rollout call per step.

``gym.make_vec("soaring/Soaring-v0", num_envs=1024)`` (``vectorization_mode`` left out or
``"vector_entry_point"``) builds :class:`SoaringVectorEnv`; ``"sync"`` / ``"async"`` build
gymnasium's generic vector envs over :class:`~soaring_env.env.core.SoaringEnv`. All give the same
transitions for the same seeds: every env ``i`` behaves like a single env reset with ``seed + i``
(each has its own ``np.random.Generator``, used only by ``"random"`` scenarios).

``"random"`` scenarios (distribution v2, :mod:`soaring_env.env.scenario_batch`) are drawn for all
envs that reset at once, by one compiled call that writes the kernels' rows directly; env ``i`` still
reads only its own generator's stream, so it draws what a single env seeded ``seed + i`` draws.
The :class:`~soaring_env.scenario.Scenario` objects (``scenarios``) and models (``models``) of
drawn rows are built only when asked for; ``info["scenario"]`` holds the names.

Autoreset: ``AutoresetMode.NEXT_STEP`` by default, as gymnasium's ``SyncVectorEnv`` (the step
after an episode ends resets that env, ignores its action and returns reward 0,
terminated = truncated = False and the reset info); ``autoreset_mode=AutoresetMode.SAME_STEP``
resets in the same step and puts the last observation and info into ``info["final_obs"]`` and
``info["final_info"]``. Truncation: after ``max_episode_steps`` steps (default: the config's
``max_steps``, 40 for goal reaching), as the single env does, and at the config's ``time_limit``.

One kernel call rolls out every env's edge, each in its own scenario's thermal field (the kernel
reads a per-env table of fields), so ``"random"`` scenarios cost no more than a shared one.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, ClassVar

import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from soaring_env._threads import RowThreads
from soaring_env._validation import ConfigError
from soaring_env.env._kernels import (
    CRASH,
    FLYING,
    GOAL,
    OUT_OF_BOUNDS,
    classify_batch,
    step_rows,
)
from soaring_env.env.config import SoaringEnvConfig, choose_scenario
from soaring_env.env.core import SoaringBaseEnv, SoaringContinuousEnv, SoaringEnv
from soaring_env.env.observation import N_PARAMS, P_GE, P_GN, P_WN, observe_batch, scenario_params, sensor_noise
from soaring_env.env.scenario_batch import (
    GeneratorSampler,
    ScenarioSampler,
    batched_draws,
    generator_list,
    scenario_from_row,
    set_generator,
)
from soaring_env.model import BATTERY_EMPTY, OUTCOMES, STALL, SoaringModel
from soaring_env.physics.thermals import PACKED_COLUMNS
from soaring_env.primitives import N_PRIMITIVES
from soaring_env.scenario import BATCHED_GENERATORS, Scenario

_OUTCOMES_OBJ = np.array(OUTCOMES, dtype=object)
#: info keys of a step that a reset info does not have
_STEP_ONLY = ("edge_cost", "fuel", "potential", "kinetic", "airspeed", "bank_angle", "battery_left", "reward_terms")
#: dtypes of the reset info's arrays (as SyncVectorEnv batches them)
_RESET_DTYPES: dict[str, Any] = {
    "energy_spent": np.float64,
    "height": np.float64,
    "updraft": np.float64,
    "time": np.float64,
    "outcome": object,
    "is_success": np.bool_,
    "scenario": object,
}


class _SoaringVectorBase(VectorEnv):
    """``num_envs`` copies of a soaring env stepped as numpy arrays.

    Same observations, rewards, terminations, truncations and info values as ``num_envs`` single
    envs (``gym.make_vec(..., vectorization_mode="sync")``) for the same seeds and actions; infos
    are gymnasium's batched dicts (``info[key]`` arrays with ``info["_" + key]`` masks).

    :param num_envs: number of envs B.
    :param max_episode_steps: truncate after this many steps (None: never; ``"default"``: the
        config's ``max_steps``).
    :param render_mode: must be None (render single envs instead).
    :param config: a :class:`~soaring_env.env.config.SoaringEnvConfig` (or dict), shared by all envs.
    :param autoreset_mode: ``NEXT_STEP`` (default) or ``SAME_STEP``.
    :param num_threads: threads that share the compiled per-row work of a step (the rollout and
        the bookkeeping after it) in contiguous blocks of envs; default 1. The results are the same
        bit for bit for any count; more threads than cores only add hand-offs.
    :param overrides: single config fields, as for ``gym.make``.

    Attributes: ``states`` (B, 4), ``times`` (B,) [s], ``airspeed_prev`` (B,) [m/s],
    ``energy_spent`` (B,) [J/kg], ``scenarios`` and ``models`` (lists of B, built on access).
    """

    metadata: dict[str, Any] = {"render_modes": [], "autoreset_mode": AutoresetMode.NEXT_STEP}  # noqa: RUF012
    single_env_class: ClassVar[type[SoaringBaseEnv]] = SoaringEnv

    def __init__(
        self,
        num_envs: int = 1,
        max_episode_steps: int | str | None = "default",
        render_mode: str | None = None,
        config: SoaringEnvConfig | dict[str, Any] | None = None,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        num_threads: int = 1,
        **overrides: Any,
    ) -> None:
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) or num_envs < 1:
            raise ConfigError(f"num_envs={num_envs!r} must be an integer >= 1")
        if render_mode is not None:
            raise ConfigError(
                f"render_mode={render_mode!r}: the native vector env does not render; allowed: None "
                "(use vectorization_mode='sync' or a single env to render)"
            )
        #: a single env that holds the shared configuration, spaces and library
        self.template = tmpl = self.single_env_class(config, **overrides)
        if max_episode_steps == "default":
            max_episode_steps = tmpl.config.max_steps
        if max_episode_steps is not None and (
            isinstance(max_episode_steps, (bool, str))
            or not isinstance(max_episode_steps, (int, np.integer))
            or max_episode_steps < 1
        ):
            raise ConfigError(f"max_episode_steps={max_episode_steps!r} must be an integer >= 1 or None")
        try:
            mode = AutoresetMode(autoreset_mode)
        except ValueError:
            raise ConfigError(
                f"autoreset_mode={autoreset_mode!r} is not supported; allowed: NEXT_STEP, SAME_STEP"
            ) from None
        if mode not in (AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP):
            raise ConfigError(f"autoreset_mode={mode!r} is not supported; allowed: NEXT_STEP, SAME_STEP")
        self.autoreset_mode = mode
        self.metadata = {**type(self).metadata, "autoreset_mode": mode}
        self.config = tmpl.config
        self.num_envs = int(num_envs)
        self._threads = RowThreads(num_threads)
        self.num_threads = self._threads.num_threads
        self.max_episode_steps = max_episode_steps
        self.render_mode = None
        self.single_observation_space = tmpl.observation_space
        self.single_action_space = tmpl.action_space
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.observation_names = tmpl.observation_names
        self.continuous = tmpl.continuous
        b = self.num_envs
        self._n_obs = tmpl._n_obs
        self._n_pts = tmpl.library.n_points
        self.states = np.empty((b, 4))
        self.times = np.zeros(b)
        self.airspeed_prev = np.full(b, np.nan)
        self.energy_spent = np.zeros(b)
        self.steps = np.zeros(b, dtype=np.int64)
        self._d_goal = np.zeros(b)
        self._lift = np.zeros(b)
        self._upd = np.zeros(b)
        self._dist = np.zeros(b)
        self._prev_done = np.zeros(b, dtype=np.bool_)
        self._no_skip = np.zeros(b, dtype=np.bool_)
        #: the edges of the last step (B, N, 4), rewritten by every step
        self._out = np.zeros((b, tmpl.library.n_points, 4))
        self._prm = np.zeros((b, N_PARAMS))
        self._th = np.zeros((b, 1, PACKED_COLUMNS))
        self._nth = np.zeros(b, dtype=np.int64)
        #: per-env field scalars for the kernel (rows of field_params); env i's field is row i. A view
        #: of the field_params tail of the scenario_params rows: no copy to keep in step at resets.
        self._fpar = self._prm[:, P_WN:]
        assert self._fpar.shape == (b, N_PARAMS - P_WN)
        self._env_index = np.arange(b, dtype=np.int64)
        self._seeds: list[int | None] = [None] * b
        self._rngs: list[np.random.Generator | None] = [None] * b
        self._start = np.empty((b, 4))
        #: per env: its Scenario -- stale where ``_lazy``: a drawn row whose Scenario is not built yet
        self._sc = np.full(b, None, dtype=object)
        self._sc[:] = [tmpl.scenario] * b
        self._lazy = np.zeros(b, dtype=np.bool_)
        self._names = np.full(b, tmpl.scenario.name, dtype=object)
        #: model per scenario in use, by id(scenario); the model keeps the scenario alive
        self._models: dict[int, SoaringModel] = {id(tmpl.scenario): tmpl.model}
        self._sampler: ScenarioSampler | None = None
        #: env i's generator at entry i (a numba typed List, built at the first random draw)
        self._gens: Any = None
        fixed = tmpl._fixed_scenario
        #: the configured scenario's packed rows, computed once
        self._fixed_prm = scenario_params(fixed) if fixed is not None else None
        #: "random" draws of distribution v2 (goal reaching with steady thermals); else _gen_sampler
        self._batched = batched_draws(tmpl.config.generator, tmpl.config.random_scenario)
        #: the other "random" draws (tasks; goal reaching with thermal life cycles or fluctuations),
        #: batched: the same scenarios as the generator, bit for bit
        self._gen_sampler: GeneratorSampler | None = None
        if fixed is None and not self._batched and tmpl.config.generator in BATCHED_GENERATORS:
            self._gen_sampler = GeneratorSampler(tmpl.config.generator, tmpl.config.random_scenario)
        #: per env: its generator's state before its last such draw (to build that Scenario on demand)
        self._draw_state: list[Mapping[str, Any] | None] = [None] * b
        if fixed is None and self._batched:
            self._ensure_slots(self._random_sampler().max_thermals)
        self._allowed = tmpl.model.allowed_primitives()
        #: the primitives past the stall limit (None: none, or a continuous env): as the single env's
        self._stalls: np.ndarray | None = None if self.continuous or not tmpl._stalls.any() else tmpl._stalls
        self._envelope = tmpl.model.control_envelope
        self._needs_reset = True
        self._obs_last = np.zeros((b, self._n_obs), dtype=np.float32)
        self.battery = np.full(b, np.inf)
        self.battery_left = np.full(b, np.inf)
        self._noise = np.zeros((b, 2))
        self._noise_key = np.zeros(b, dtype=np.uint64)
        self._history = np.zeros((b, tmpl._hist_len, tmpl._hist_width))

    # --- scenario bookkeeping ------------------------------------------------------------------------
    def _rng(self, i: int) -> np.random.Generator:
        rng = self._rngs[i]
        if rng is None:
            rng, _ = seeding.np_random(self._seeds[i])
            self._rngs[i] = rng
        return rng

    def _random_sampler(self) -> ScenarioSampler:
        if self._sampler is None:
            self._sampler = ScenarioSampler(self.config.random_scenario)
        return self._sampler

    def _ensure_slots(self, n: int) -> None:
        """Grow the per-env thermal table to at least ``n`` slots."""
        if n > self._th.shape[1]:
            th = np.zeros((self.num_envs, n, PACKED_COLUMNS))
            th[:, : self._th.shape[1]] = self._th
            self._th = th

    def _model(self, sc: Scenario) -> SoaringModel:
        model = self._models.get(id(sc))
        if model is None or model.scenario is not sc:
            t = self.template
            model = SoaringModel(
                scenario=sc,
                aircraft=t.config.aircraft,
                library=t.library,
                max_substep=t.config.max_substep,
                max_bank_deg=t.config.max_bank_deg,
                envelope=t.envelope,
            )
            self._models[id(sc)] = model
        return model

    @property
    def scenarios(self) -> list[Scenario]:
        """The current :class:`Scenario` of every env; drawn ones are built here, on first access
        after their reset (equal to what a single env would hold, and packing back bit for bit)."""
        lazy = np.flatnonzero(self._lazy)
        if lazy.size:
            ts = self._gen_sampler
            spec = self._random_sampler().spec if ts is None else None  # lazy rows come from one sampler
            for i in lazy.tolist():
                if spec is not None:
                    self._sc[i] = scenario_from_row(spec, self._prm[i], self._th[i, : self._nth[i]], self._start[i])
                    continue
                assert ts is not None
                rng = np.random.Generator(type(self._rng(i).bit_generator)())  # the generator again, from
                state = self._draw_state[i]  # its state before the draw (set by every generated draw)
                assert state is not None
                rng.bit_generator.state = state
                self._sc[i] = ts.generator(rng, **ts.kwargs)
            self._lazy[lazy] = False
        return self._sc.tolist()

    @property
    def models(self) -> list[SoaringModel]:
        """The :class:`SoaringModel` of every env's current scenario (built on access)."""
        scs = self.scenarios
        if len(self._models) > 4 * self.num_envs:  # forget models of scenarios no env uses
            live = {id(sc) for sc in scs}
            self._models = {k: v for k, v in self._models.items() if k in live}
        return [self._model(sc) for sc in scs]

    def _put(self, rows: np.ndarray, sc: Scenario, prm: np.ndarray | None = None) -> None:
        """Give envs ``rows`` the scenario ``sc`` (``prm``: its scenario_params row, if known)."""
        n = len(sc.field.thermals)
        self._ensure_slots(n)
        self._prm[rows] = scenario_params(sc) if prm is None else prm
        self._th[rows, :n] = sc.field.packed
        self._nth[rows] = n
        self._start[rows] = sc.start
        self._sc[rows] = sc
        self._lazy[rows] = False
        self._names[rows] = sc.name

    def _draw(self, rows: np.ndarray) -> None:
        """Draw new random scenarios for envs ``rows``, each from its own generator, in one call."""
        sampler = self._random_sampler()
        self._ensure_slots(sampler.max_thermals)
        if self._gens is None:
            self._gens = generator_list([self._rng(i) for i in range(self.num_envs)])
        sampler.draw_each(rows, self._gens, self._prm, self._th, self._nth, self._start)
        self._lazy[rows] = True  # their Scenario objects (in _sc) are stale until ``scenarios`` rebuilds them
        self._names[rows] = sampler.spec.name

    def _draw_generated(self, rows: np.ndarray) -> None:
        """Draw new scenarios for envs ``rows`` with the generator's own calls, each from its own
        generator, in one call."""
        sampler = self._gen_sampler
        assert sampler is not None
        self._ensure_slots(sampler.max_thermals)
        if self._gens is None:
            self._gens = generator_list([self._rng(i) for i in range(self.num_envs)])
        for i in rows.tolist():
            self._draw_state[i] = self._rng(i).bit_generator.state
        sampler.draw_each(rows, self._gens, self._prm, self._th, self._nth, self._start)
        self._lazy[rows] = True
        self._names[rows] = sampler.settings.name

    def _reset_rows(self, rows: np.ndarray, options: dict[str, Any] | None, obs: np.ndarray) -> None:
        """Start new episodes in envs ``rows`` and write their observations into ``obs``."""
        t = self.template
        fixed = t._fixed_scenario
        if options is None and fixed is not None:
            self._put(rows, fixed, self._fixed_prm)
        else:
            cfg = t.config
            sc = choose_scenario(options, fixed, cfg.random_scenario, cfg.generator)  # the same for every row
            if sc is None and self._batched:
                self._draw(rows)
            elif sc is None and self._gen_sampler is not None:
                self._draw_generated(rows)
            elif sc is None:  # another generator: one Scenario per row, from the row's generator
                for i in rows.tolist():
                    self._put(np.array([i]), cfg.generator(self._rng(i), **dict(cfg.random_scenario)))
            else:
                self._put(rows, sc)
        if t.has_battery:
            self.battery[rows] = [
                t._battery_budget_at(self._prm[i, P_GN], self._prm[i, P_GE], self._start[i, 0], self._start[i, 1])
                for i in rows.tolist()
            ]
        self.battery_left[rows] = self.battery[rows]
        self._history[rows] = 0.0
        if t._noise_sigma:  # after the scenario draws, as the single env draws its key
            for i in rows.tolist():
                self._noise_key[i] = self._rng(i).integers(0, 2**63, dtype=np.uint64)
            self._noise[rows] = sensor_noise(
                self._noise_key[rows], np.zeros(len(rows), dtype=np.uint64), t._noise_sigma
            )
        self.states[rows] = self._start[rows]
        self.times[rows] = 0.0
        self.airspeed_prev[rows] = np.nan
        self.energy_spent[rows] = 0.0
        self.steps[rows] = 0
        self._lift[rows] = 0.0
        observe_batch(
            self.states,
            self.times,
            self.airspeed_prev,
            self._lift,
            self._prm,
            self._th,
            self._nth,
            t._scales,
            t._k_obs,
            t._low,
            t._high,
            t._goal_on,
            t._th_base,
            self._noise,
            rows,
            self._upd,
            self._dist,
            obs,
        )
        if t._extras or t._hist_len:
            t._fill_task_entries(
                obs,
                rows,
                self.times,
                self.battery_left,
                self.battery,
                self._history,
                self.states[:, :2],
                self._start[:, :2],
                self.steps,
            )
        self._d_goal[rows] = self._dist[rows]

    def _reset_info(self, rows: np.ndarray, infos: dict[str, Any]) -> None:
        """Write the reset info of envs ``rows`` into batched ``infos`` (masks like SyncVectorEnv).

        ``infos`` is empty (``reset``) or a step's infos, whose keys all have all-True masks.
        """
        b = self.num_envs
        vals = (
            ("energy_spent", 0.0),
            ("height", self.states[rows, 3]),
            ("updraft", self._upd[rows]),
            ("time", 0.0),
            ("outcome", "flying"),
            ("is_success", False),
            ("scenario", self._names[rows]),
        )
        for key, v in vals:
            arr = infos.get(key)
            if arr is None:
                dtype = _RESET_DTYPES[key]
                arr = np.empty(b, dtype=object) if dtype is object else np.zeros(b, dtype=dtype)  # None / 0
                infos[key] = arr
                infos["_" + key] = mask = np.zeros(b, dtype=np.bool_)
                mask[rows] = True
            arr[rows] = v  # a key step() already filled has its mask all True
        for key in _STEP_ONLY:
            if key in infos:
                infos["_" + key][rows] = False
                if key == "reward_terms":
                    for sub, arr in infos[key].items():
                        if not sub.startswith("_"):
                            arr[rows] = 0.0
                            infos[key]["_" + sub][rows] = False
                else:
                    infos[key][rows] = 0

    # --- gymnasium API -------------------------------------------------------------------------------
    def reset(
        self, *, seed: int | Sequence[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset all envs (or those in ``options["reset_mask"]``); env i is seeded with ``seed + i``."""
        b = self.num_envs
        seeds: list[int | None]
        if seed is None:
            seeds = [None] * b
        elif isinstance(seed, (int, np.integer)) and not isinstance(seed, bool):
            super().reset(seed=int(seed))
            seeds = [int(seed) + i for i in range(b)]
        elif isinstance(seed, Sequence) and len(seed) == b:
            seeds = [None if s is None else int(s) for s in seed]
        else:
            raise ConfigError(f"seed={seed!r} is invalid; allowed: None, an int, or a list of {b} ints/None")
        opts = dict(options) if options else {}
        mask = opts.pop("reset_mask", None)
        if mask is None:
            rows = np.arange(b)
        else:
            mask = np.asarray(mask)
            if mask.shape != (b,) or mask.dtype != np.bool_ or not mask.any():
                raise ConfigError(f"options['reset_mask'] must be a bool array of shape ({b},) with a True entry")
            rows = np.flatnonzero(mask)
        reseeded = [i for i in rows.tolist() if seeds[i] is not None]
        for i in reseeded:
            self._seeds[i] = seeds[i]
            self._rngs[i] = None
        if self._gens is not None:
            for i in reseeded:  # the random draws read the new generators
                set_generator(self._gens, i, self._rng(i))
        obs = np.empty((b, self._n_obs), dtype=np.float32)
        if mask is not None:
            obs[:] = self._obs_last
        self._reset_rows(rows, opts or None, obs)
        self._prev_done[rows] = False
        self._needs_reset = False
        self._obs_last = obs
        infos: dict[str, Any] = {}
        self._reset_info(rows, infos)
        return obs.copy(), infos

    def _controls(self, actions: Any) -> np.ndarray:
        b = self.num_envs
        a = np.asarray(actions)
        if self.continuous:
            if a.shape != (b, 3) or a.dtype.kind not in "fiu":
                raise ConfigError(
                    f"actions have shape {a.shape} and dtype {a.dtype}; allowed: a real array of shape ({b}, 3) "
                    "in [-1, 1]"
                )
            a64 = a.astype(np.float64)
            if not (np.all(a64 >= -1.0) and np.all(a64 <= 1.0)):
                raise ConfigError("actions contain values outside [-1, 1] or non-finite values; allowed: [-1, 1]")
            u = self._envelope.to_control(a64)
            return np.ascontiguousarray(u[:, [0, 2, 1, 1]])
        if a.shape != (b,) or a.dtype.kind not in "iu":
            raise ConfigError(
                f"actions={a!r} have shape {a.shape} and dtype {a.dtype}; allowed: integers of shape ({b},) "
                f"in 0..{N_PRIMITIVES - 1}"
            )
        if a.size and (a.min() < 0 or a.max() >= N_PRIMITIVES):
            raise ConfigError(f"actions contain indices outside 0..{N_PRIMITIVES - 1}")
        return np.take(self.template._prop.ctrl_table, a, axis=0)

    def _rollout(
        self, x0: np.ndarray, t0: np.ndarray, vp: np.ndarray, ctrl: np.ndarray, env: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Roll out edge b from ``x0[b]`` in the field of env ``env[b]``, for every b: one kernel call."""
        prop = self.template._prop  # same aircraft, library and substep for every env
        return prop.run_fields(x0, t0, vp, ctrl, env, self._th, self._nth, self._fpar, self._threads)

    def step(self, actions: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Step all envs; see the module docstring for the autoreset modes."""
        if self._needs_reset:
            raise RuntimeError("step() called before reset(); call reset() first")
        ctrl = self._controls(actions)
        t = self.template
        b = self.num_envs
        autoreset = self._prev_done.copy() if self.autoreset_mode == AutoresetMode.NEXT_STEP else None
        # Envs that autoreset in this step (next-step mode) throw their edge away: not flown.
        skip = autoreset if autoreset is not None else self._no_skip
        t_new = self.times + t._ts
        obs = np.empty((b, self._n_obs), dtype=np.float32)
        new_states = np.empty((b, 4))
        codes = np.empty(b, dtype=np.int64)
        ks = np.empty(b, dtype=np.int64)
        terms = np.empty((b, 6))
        out = self._out
        dur, n_pts, k_switch, max_substep, ac = t._prop.kernel_constants  # same for every env
        if t._noise_sigma:
            self._noise[:] = sensor_noise(self._noise_key, (self.steps + 1).astype(np.uint64), t._noise_sigma)

        def block(r: slice) -> None:
            step_rows(
                skip[r], self.states[r], self.times[r], ctrl[r], self.airspeed_prev[r], self._env_index[r], dur,
                n_pts, k_switch, max_substep, self._th, self._nth, self._fpar, ac, out[r], terms[r], t._dt, t_new[r],
                self._prm[r], self._th[r], self._nth[r], t._scales, t._k_obs, t._low, t._high, t._goal_on,
                t._th_base, self._noise[r], codes[r], ks[r], new_states[r], self._upd[r], self._lift[r],
                self._dist[r], obs[r],
            )  # fmt: skip

        self._threads.run(b, block)
        tt = terms.T.copy()  # (6, B): one copy gives every per-term info array below
        if t.has_battery:
            self.battery_left = self.battery_left - (tt[0] + tt[2])
            codes[(codes == FLYING) & (self.battery_left <= 0.0)] = BATTERY_EMPTY
        if self._stalls is not None:  # a flown primitive past the stall limit ends the episode
            codes[self._stalls[np.asarray(actions)] & ~skip] = STALL
        if t._extras or t._hist_len:
            flown = (ks + 1) * t._dt
            lift = self._lift + self._noise[:, 1]
            t._push_history(
                self._history,
                lift,
                new_states[:, 3] - self.states[:, 3],
                new_states[:, 2] - self.states[:, 2],
                flown,
                out,
                ks,
            )
            t._fill_task_entries(
                obs,
                self._env_index,
                t_new,
                self.battery_left,
                self.battery,
                self._history,
                new_states[:, :2],
                self._start[:, :2],
                self.steps + 1,
            )
        cost = tt[3]
        airspeed = ctrl[:, 0].copy()
        d_new = self._dist.copy()
        reward_terms = t.reward_terms(cost, self._d_goal, d_new, codes)
        terminated = codes != FLYING
        self.states = new_states
        self.times = t_new
        self.airspeed_prev = airspeed.copy()
        self.energy_spent = self.energy_spent + cost
        self._d_goal = d_new
        self.steps += 1
        if self.max_episode_steps is None:
            truncated = np.zeros(b, dtype=np.bool_)
        else:
            truncated = self.steps >= self.max_episode_steps
        if t._time_limit != np.inf:
            truncated |= ~terminated & (t_new >= t._time_limit - 1e-9)
        t.settle_terms(reward_terms, truncated & ~terminated, new_states[:, 3], self._prm)  # resets come below
        reward = sum(reward_terms.values())
        infos: dict[str, Any] = {
            "energy_spent": self.energy_spent.copy(),
            "edge_cost": cost,
            "fuel": tt[0],
            "potential": tt[1],
            "kinetic": tt[2],
            "height": new_states[:, 3].copy(),
            "airspeed": airspeed,
            "bank_angle": tt[4],
            "updraft": self._upd.copy(),
            "time": t_new.copy(),
            "outcome": _OUTCOMES_OBJ[codes],
            "is_success": codes == GOAL,
            "reward_terms": reward_terms,
        }
        if t.has_battery:
            infos["battery_left"] = self.battery_left.copy()
        keys, sub = list(infos), list(reward_terms)
        masks = np.ones((len(keys) + len(sub), b), dtype=np.bool_)  # a row per mask, one allocation
        for j, key in enumerate(keys):
            infos["_" + key] = masks[j]
        for j, key in enumerate(sub, len(keys)):
            reward_terms["_" + key] = masks[j]
        if autoreset is not None:
            if autoreset.any():
                rows = np.flatnonzero(autoreset)
                self._reset_rows(rows, None, obs)
                reward[rows] = 0.0
                terminated[rows] = False
                truncated[rows] = False
                self._reset_info(rows, infos)
            self._prev_done = terminated | truncated
        else:
            done = terminated | truncated
            if done.any():
                rows = np.flatnonzero(done)
                final_obs = np.full(b, None, dtype=object)
                for i in rows.tolist():
                    final_obs[i] = obs[i].copy()
                final_info = {k: v for k, v in infos.items() if not k.startswith("_")}
                final_info["reward_terms"] = dict(infos["reward_terms"])
                for key in [k for k in final_info if not k.startswith("_")]:
                    final_info["_" + key] = done.copy()
                self._reset_rows(rows, None, obs)
                infos = {k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in infos.items()}
                infos["reward_terms"] = {k: v.copy() for k, v in infos["reward_terms"].items()}
                self._reset_info(rows, infos)
                infos["final_obs"], infos["_final_obs"] = final_obs, done.copy()
                infos["final_info"], infos["_final_info"] = final_info, done.copy()
        self._obs_last = obs
        return obs, reward, terminated, truncated, infos

    def close_extras(self, **kwargs: Any) -> None:
        self._threads.close()
        self.template.close()


class SoaringVectorEnv(_SoaringVectorBase):
    """``num_envs`` copies of :class:`~soaring_env.env.core.SoaringEnv` (``Discrete(174)``), stepped
    as numpy arrays; see :class:`_SoaringVectorBase` for the arguments."""

    single_env_class: ClassVar[type[SoaringBaseEnv]] = SoaringEnv

    # --- action masking ------------------------------------------------------------------------------
    def action_masks(self) -> np.ndarray:
        """(B, 174) bool: :meth:`SoaringEnv.action_masks` of every env (one batched rollout)."""
        b, p = self.num_envs, N_PRIMITIVES
        x0 = np.repeat(self.states, p, axis=0)
        t0 = np.repeat(self.times, p)
        vp = np.repeat(self.airspeed_prev, p)
        ctrl = np.tile(self.template._prop.ctrl_table, (b, 1))
        out, _ = self._rollout(x0, t0, vp, ctrl, np.repeat(self._env_index, p))
        codes = np.empty(b * p, dtype=np.int64)
        ks = np.empty(b * p, dtype=np.int64)
        classify_batch(out, np.repeat(self._prm, p, axis=0), codes, ks)
        code2 = codes.reshape(b, p)
        k2 = ks.reshape(b, p)
        valid = (code2 != CRASH) & (code2 != OUT_OF_BOUNDS) & self._allowed
        for i in np.flatnonzero(~valid.any(axis=1)).tolist():
            kk = np.where(self._allowed, k2[i], -1)
            valid[i] = kk == kk.max()
        return valid


class SoaringContinuousVectorEnv(_SoaringVectorBase):
    """``num_envs`` copies of :class:`~soaring_env.env.core.SoaringContinuousEnv` (``Box(-1, 1, (3,))``);
    see :class:`_SoaringVectorBase` for the arguments."""

    single_env_class: ClassVar[type[SoaringBaseEnv]] = SoaringContinuousEnv
