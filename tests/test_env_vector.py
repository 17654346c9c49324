"""Vector envs: gymnasium sync / async, the native batched env, the SB3 adapter, subprocesses."""

from __future__ import annotations

import multiprocessing

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode
from hypothesis import given, settings
from hypothesis import strategies as st

import soaring_env  # noqa: F401  (registers the ids)
from soaring_env import ConfigError
from soaring_env._threads import MIN_ROWS_PER_THREAD, RowThreads
from soaring_env.env import CONTINUOUS_ENV_ID, ENV_ID, ENV_IDS
from soaring_env.env.vector import SoaringContinuousVectorEnv, SoaringVectorEnv
from soaring_env.primitives import N_PRIMITIVES

IDS = (ENV_ID, CONTINUOUS_ENV_ID)
INFO_KEYS = ("energy_spent", "edge_cost", "height", "updraft", "time", "outcome", "is_success", "scenario")


def _actions(space: gym.Space, rng: np.random.Generator, n: int) -> np.ndarray:
    if isinstance(space, gym.spaces.Discrete):
        return rng.integers(0, N_PRIMITIVES, n)
    return rng.uniform(-1, 1, (n, 3)).astype(np.float32)


def _assert_same_infos(a: dict, b: dict, keys=INFO_KEYS) -> None:
    for key in keys:
        assert (key in a) == (key in b), key
        if key in a:
            mask = a["_" + key]
            assert np.array_equal(mask, b["_" + key]), key
            assert np.array_equal(a[key][mask], b[key][mask]), (key, a[key], b[key])
    if "reward_terms" in a:
        for term, arr in a["reward_terms"].items():
            assert np.array_equal(arr, b["reward_terms"][term]), term


@pytest.mark.parametrize("env_id", IDS)
@pytest.mark.parametrize("scenario", ["paper", "random"])
def test_native_equals_sync_next_step(env_id: str, scenario: str) -> None:
    n = 5
    sync = gym.make_vec(env_id, num_envs=n, vectorization_mode="sync", scenario=scenario)
    native = gym.make_vec(env_id, num_envs=n, scenario=scenario)
    assert isinstance(native, (SoaringVectorEnv, SoaringContinuousVectorEnv))
    assert native.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    assert native.single_observation_space == sync.single_observation_space
    assert native.action_space == sync.action_space
    o1, i1 = sync.reset(seed=11)
    o2, i2 = native.reset(seed=11)
    assert np.array_equal(o1, o2)
    _assert_same_infos(i1, i2)
    rng = np.random.default_rng(0)
    ended = 0
    for _ in range(70):
        a = _actions(sync.single_action_space, rng, n)
        r1, r2 = sync.step(a), native.step(a)
        for x, y in zip(r1[:4], r2[:4], strict=True):
            assert np.array_equal(x, y)
        _assert_same_infos(r1[4], r2[4])
        ended += int((r1[2] | r1[3]).sum())
    assert ended > 0  # autoresets happened
    assert native.observation_space.contains(r2[0])
    sync.close()
    native.close()


@pytest.mark.parametrize("env_id", IDS)
def test_native_equals_sync_same_step(env_id: str) -> None:
    n = 4
    kw = {"num_envs": n, "scenario": "random"}
    sync = gym.make_vec(env_id, vectorization_mode="sync", vector_kwargs={"autoreset_mode": "SameStep"}, **kw)
    native = gym.make_vec(env_id, autoreset_mode=AutoresetMode.SAME_STEP, **kw)
    assert native.metadata["autoreset_mode"] == AutoresetMode.SAME_STEP
    assert np.array_equal(sync.reset(seed=2)[0], native.reset(seed=2)[0])
    rng = np.random.default_rng(1)
    finals = 0
    for _ in range(50):
        a = _actions(sync.single_action_space, rng, n)
        r1, r2 = sync.step(a), native.step(a)
        for x, y in zip(r1[:4], r2[:4], strict=True):
            assert np.array_equal(x, y)
        _assert_same_infos(r1[4], r2[4])
        if "final_obs" in r1[4]:
            done = r1[4]["_final_obs"]
            assert np.array_equal(done, r2[4]["_final_obs"])
            for i in np.flatnonzero(done):
                assert np.array_equal(r1[4]["final_obs"][i], r2[4]["final_obs"][i])
                assert r1[4]["final_info"]["energy_spent"][i] == r2[4]["final_info"]["energy_spent"][i]
                assert r1[4]["final_info"]["outcome"][i] == r2[4]["final_info"]["outcome"][i]
            finals += int(done.sum())
    assert finals > 0


def test_native_reset_mask_seed_list_and_options() -> None:
    env = SoaringVectorEnv(num_envs=3, scenario="random")
    obs, _ = env.reset(seed=[5, None, 7])
    single = gym.make(ENV_ID, scenario="random")
    assert np.array_equal(obs[0], single.reset(seed=5)[0])
    assert np.array_equal(obs[2], single.reset(seed=7)[0])
    before = obs.copy()
    mask = np.array([False, True, False])
    obs2, info = env.reset(options={"reset_mask": mask, "scenario": "paper"})
    assert np.array_equal(obs2[[0, 2]], before[[0, 2]])
    assert env.scenarios[1].name == "paper" and env.scenarios[0].name == "random"
    assert np.array_equal(info["_scenario"], mask)
    with pytest.raises(ConfigError, match="reset_mask"):
        env.reset(options={"reset_mask": np.zeros(3, dtype=bool)})


def test_native_action_masks_equal_single_env_masks() -> None:
    n = 4
    env = SoaringVectorEnv(num_envs=n, scenario="random")
    singles = [gym.make(ENV_ID, scenario="random") for _ in range(n)]
    env.reset(seed=3)
    for i, s in enumerate(singles):
        s.reset(seed=3 + i)
    rng = np.random.default_rng(0)
    for _ in range(3):
        masks = env.action_masks()
        assert masks.shape == (n, N_PRIMITIVES) and masks.dtype == np.bool_
        for i, s in enumerate(singles):
            assert np.array_equal(masks[i], s.unwrapped.action_masks())
        a = np.array([rng.choice(np.flatnonzero(m)) for m in masks])
        env.step(a)
        for i, s in enumerate(singles):
            s.step(int(a[i]))


@pytest.mark.parametrize(
    ("actions", "match"),
    [
        (np.array([0, 1, 174]), "0..173"),
        (np.array([0.0, 1.0, 2.0]), "integers"),
        (np.array([0, 1]), "shape"),
    ],
)
def test_native_bad_actions_are_explained(actions: np.ndarray, match: str) -> None:
    env = SoaringVectorEnv(num_envs=3)
    env.reset(seed=0)
    with pytest.raises(ConfigError, match=match):
        env.step(actions)
    cont = SoaringContinuousVectorEnv(num_envs=2)
    cont.reset(seed=0)
    with pytest.raises(ConfigError, match=r"\[-1, 1\]"):
        cont.step(np.array([[0.0, 0.0, 2.0], [0.0, 0.0, 0.0]]))
    with pytest.raises(ConfigError, match=r"\[-1, 1\]"):
        cont.step(np.array([[np.nan, 0.0, 0.0], [0.0, 0.0, 0.0]]))
    with pytest.raises(ConfigError, match="render"):
        SoaringVectorEnv(num_envs=2, render_mode="rgb_array")


@pytest.mark.parametrize("continuous", [False, True])
@pytest.mark.parametrize("scenario", ["paper", "random"])
def test_sb3_adapter_equals_dummy_vec_env(continuous: bool, scenario: str) -> None:
    from stable_baselines3.common.vec_env import DummyVecEnv

    from soaring_env.env.sb3 import SoaringSB3VecEnv

    env_id = CONTINUOUS_ENV_ID if continuous else ENV_ID
    n = 4
    dummy = DummyVecEnv([lambda: gym.make(env_id, scenario=scenario)] * n)
    ours = SoaringSB3VecEnv(n, continuous=continuous, scenario=scenario)
    dummy.seed(5)
    ours.seed(5)
    assert np.array_equal(dummy.reset(), ours.reset())
    rng = np.random.default_rng(1)
    dones = 0
    for _ in range(60):
        a = _actions(dummy.action_space, rng, n)
        r1, r2 = dummy.step(a), ours.step(a)
        for x, y in zip(r1[:3], r2[:3], strict=True):
            assert x.dtype == y.dtype and np.array_equal(x, y)
        for i1, i2 in zip(r1[3], r2[3], strict=True):
            for key in ("terminal_observation", "TimeLimit.truncated", "energy_spent", "is_success", "outcome"):
                assert (key in i1) == (key in i2), key
                if key in i1:
                    assert np.array_equal(i1[key], i2[key]), key
        dones += int(r1[2].sum())
    assert dones > 0
    assert ours.has_attr("action_masks") != continuous
    if not continuous:
        masks = ours.env_method("action_masks")
        assert len(masks) == n and masks[0].shape == (N_PRIMITIVES,)


def test_maskable_ppo_trains_on_the_sb3_adapter() -> None:
    from sb3_contrib import MaskablePPO

    from soaring_env.env.sb3 import SoaringSB3VecEnv

    venv = SoaringSB3VecEnv(4)
    model = MaskablePPO("MlpPolicy", venv, n_steps=16, batch_size=32, n_epochs=1, seed=0, device="cpu")
    model.learn(64)


def test_async_vector_env_with_spawn() -> None:
    env = gym.make_vec(
        "soaring_env:soaring/Soaring-v0",
        num_envs=2,
        vectorization_mode="async",
        vector_kwargs={"context": "spawn"},
    )
    try:
        obs, _ = env.reset(seed=0)
        assert obs.shape == (2, 26)
        for _ in range(3):
            obs, reward, *_ = env.step(np.array([7, 57]))
        assert np.all(np.isfinite(reward))
        masks = env.call("action_masks")
        assert len(masks) == 2 and masks[0].shape == (N_PRIMITIVES,)
    finally:
        env.close()


def test_sb3_subproc_vec_env_with_spawn() -> None:
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import SubprocVecEnv

    assert "spawn" in multiprocessing.get_all_start_methods()
    venv = make_vec_env(
        "soaring_env:soaring/SoaringContinuous-v0",
        n_envs=2,
        seed=0,
        vec_env_cls=SubprocVecEnv,
        vec_env_kwargs={"start_method": "spawn"},
    )
    try:
        venv.reset()
        for _ in range(3):
            obs, reward, _done, info = venv.step(np.zeros((2, 3), dtype=np.float32))
        assert obs.shape == (2, 26) and np.all(np.isfinite(reward))
        assert "energy_spent" in info[0]
    finally:
        venv.close()


def test_sb3_adapter_takes_every_registered_id() -> None:
    from soaring_env.env import ENV_IDS
    from soaring_env.env.sb3 import SoaringSB3VecEnv

    for env_id in ENV_IDS:
        venv = SoaringSB3VecEnv(2, env_id=env_id)
        assert venv.observation_space == gym.make(env_id).observation_space
        obs = venv.reset()
        assert obs.shape == (2, *venv.observation_space.shape)
    xc = SoaringSB3VecEnv(2, env_id="soaring/CrossCountry-v0")
    xc.reset()
    _, _, _, infos = xc.step(np.array([0, 0]))
    assert "battery_left" in infos[0]
    with pytest.raises(ConfigError, match="env_id"):
        SoaringSB3VecEnv(2, env_id="CartPole-v1")


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_threads_give_the_same_steps_bit_for_bit(env_id: str) -> None:
    """num_threads splits each step's rows over worker threads: same transitions as one thread."""
    n = 3 * MIN_ROWS_PER_THREAD + 5  # uneven blocks, enough rows for three threads
    kwargs = (
        {"scenario": "random"}
        if env_id in IDS
        else {"history_length": 3, "sensor_noise": 0.2, "history_positions": True}
    )
    envs = [gym.make_vec(env_id, num_envs=n, num_threads=k, **kwargs) for k in (1, 2, 3)]
    assert [e.num_threads for e in envs] == [1, 2, 3]
    first = [e.reset(seed=3) for e in envs]
    for o, i in first[1:]:
        assert np.array_equal(first[0][0], o)
        _assert_same_infos(first[0][1], i)
    rng = np.random.default_rng(1)
    for _ in range(12):
        a = _actions(envs[0].single_action_space, rng, n)
        steps = [e.step(a) for e in envs]
        for s in steps[1:]:
            for x, y in zip(steps[0][:4], s[:4], strict=True):
                assert np.array_equal(x, y)
            _assert_same_infos(steps[0][4], s[4])
    if isinstance(envs[0], SoaringVectorEnv):
        masks = [e.action_masks() for e in envs]
        assert all(np.array_equal(masks[0], m) for m in masks[1:])
    for e in envs:
        e.close()


@pytest.mark.parametrize("bad", [0, -2, 1.5, "2", True, None, 10**6])
def test_bad_thread_counts_are_explained(bad: object) -> None:
    with pytest.raises(ConfigError, match="num_threads"):
        SoaringVectorEnv(num_envs=2, num_threads=bad)


@settings(max_examples=60, deadline=None)
@given(n_rows=st.integers(0, 700), threads=st.integers(1, 6))
def test_row_threads_cover_every_row_once(n_rows: int, threads: int) -> None:
    seen = np.zeros(n_rows, dtype=np.int64)
    blocks: list[slice] = []
    pool = RowThreads(threads)

    def call(r: slice) -> None:
        blocks.append(r)
        seen[r] += 1

    pool.run(n_rows, call)
    pool.close()
    assert np.all(seen == 1)
    assert len(blocks) == max(1, min(threads, n_rows // MIN_ROWS_PER_THREAD))


def test_row_threads_raise_a_block_error_in_the_caller() -> None:
    pool = RowThreads(2)

    def call(r: slice) -> None:
        if r.start > 0:
            raise RuntimeError("worker block failed")

    with pytest.raises(RuntimeError, match="worker block failed"):
        pool.run(4 * MIN_ROWS_PER_THREAD, call)
    pool.close()
    pool.run(10, lambda r: None)  # closed: runs in the calling thread


@pytest.mark.parametrize("continuous", [False, True])
def test_step_rows_equals_rollout_then_post_step_and_skips_rows(continuous: bool) -> None:
    """The fused step kernel gives exactly the rollout kernel's edges followed by post_step on every
    row it flies; a skipped row gets zero terms, FLYING at the last point and its start as the new
    state, and its other outputs are left untouched."""
    from soaring_env.env._kernels import FLYING, post_step, step_rows

    cls = SoaringContinuousVectorEnv if continuous else SoaringVectorEnv
    env = cls(num_envs=40, scenario="random")
    env.reset(seed=5)
    rng = np.random.default_rng(2)
    for _ in range(3):  # states spread over the field, some episodes already restarted
        env.step(_actions(env.single_action_space, rng, env.num_envs))
    t = env.template
    b = env.num_envs
    ctrl = env._controls(_actions(env.single_action_space, rng, b))
    t_new = env.times + t._ts
    dur, n_pts, k_switch, max_substep, ac = t._prop.kernel_constants

    def outputs() -> list[np.ndarray]:
        return [
            np.full((b, n_pts, 4), -7.0), np.full((b, 6), -7.0), np.full(b, -7, np.int64), np.full(b, -7, np.int64),
            np.full((b, 4), -7.0), np.full(b, -7.0), np.full(b, -7.0), np.full(b, -7.0),
            np.full((b, env._n_obs), -7.0, np.float32),
        ]  # fmt: skip

    _, _, codes_a, ks_a, new_a, upd_a, lift_a, dist_a, obs_a = outputs()
    out_r, terms_r = t._prop.run_fields(
        env.states, env.times, env.airspeed_prev, ctrl, env._env_index, env._th, env._nth, env._fpar
    )
    post_step(
        out_r, env.states, ctrl, t._dt, t_new, env._prm, env._th, env._nth, t._scales, t._k_obs, t._low, t._high,
        t._goal_on, t._th_base, env._noise, codes_a, ks_a, new_a, upd_a, lift_a, dist_a, obs_a,
    )  # fmt: skip
    skip = rng.random(b) < 0.3
    skip[:2] = [False, True]
    out_b, terms_b, codes_b, ks_b, new_b, upd_b, lift_b, dist_b, obs_b = outputs()
    step_rows(
        skip, env.states, env.times, ctrl, env.airspeed_prev, env._env_index, dur, n_pts, k_switch, max_substep,
        env._th, env._nth, env._fpar, ac, out_b, terms_b, t._dt, t_new, env._prm, env._th, env._nth, t._scales,
        t._k_obs, t._low, t._high, t._goal_on, t._th_base, env._noise, codes_b, ks_b, new_b, upd_b, lift_b, dist_b,
        obs_b,
    )  # fmt: skip
    fly = ~skip
    for x, y in [(out_r, out_b), (terms_r, terms_b), (codes_a, codes_b), (ks_a, ks_b), (new_a, new_b),
                 (upd_a, upd_b), (lift_a, lift_b), (dist_a, dist_b), (obs_a, obs_b)]:  # fmt: skip
        assert np.array_equal(x[fly], y[fly])
    assert np.all(terms_b[skip] == 0.0)
    assert np.all(codes_b[skip] == FLYING) and np.all(ks_b[skip] == n_pts - 1)
    assert np.array_equal(new_b[skip], env.states[skip])
    assert np.all(upd_b[skip] == 0.0) and np.all(lift_b[skip] == 0.0)
    assert np.all(out_b[skip] == -7.0) and np.all(dist_b[skip] == -7.0) and np.all(obs_b[skip] == -7.0)
    env.close()
