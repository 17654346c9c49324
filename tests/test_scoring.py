"""The primitive-scoring policy: its geometry in closed form, mirror symmetry, save and load."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

import soaring_env  # noqa: F401  (registers the envs)
from baselines.ppo import DISCRETE_ID, BodyFrameObservation, TrainConfig
from soaring_env.primitives import COL_AIRSPEED, COL_CHI_DOT_1, COL_FAMILY, COL_GAMMA, SPIRAL, STRAIGHT


@pytest.fixture(scope="module")
def env() -> gym.Env:
    return BodyFrameObservation(gym.make(DISCRETE_ID))


def test_still_air_paths_in_closed_form(env: gym.Env) -> None:
    """Straight primitives end v cos(gamma) Ts ahead and v sin(gamma) Ts up; a 1080-degree spiral
    closes on itself (three full circles), ending where it started but v sin(gamma) Ts lower."""
    from baselines.scoring import primitive_paths

    u = env.unwrapped
    kw = primitive_paths(u.model)
    paths, tab, ts = np.asarray(kw["paths"]), u.library.table, u.library.duration
    assert paths.shape == (174, 10, 3) and np.isclose(kw["times"][-1], ts)
    v, g = tab[:, COL_AIRSPEED], tab[:, COL_GAMMA]
    straight = tab[:, COL_FAMILY] == STRAIGHT
    end = paths[:, -1]
    assert np.allclose(end[straight, 0], (v * np.cos(g) * ts)[straight], atol=1e-6)
    assert np.allclose(end[straight, 1], 0.0, atol=1e-6)
    assert np.allclose(end[:, 2], v * np.sin(g) * ts, atol=1e-6)  # every family: gamma is constant
    spiral = (tab[:, COL_FAMILY] == SPIRAL) & np.isclose(np.abs(tab[:, COL_CHI_DOT_1]) * ts, math.radians(1080))
    assert spiral.sum() > 0 and np.allclose(end[spiral, :2], 0.0, atol=1e-6)
    # still-air cost: a level straight primitive spends fuel only, a -45 degree one gains g * 212 m
    cost = np.asarray(kw["cost"])
    assert np.all(cost[straight & (g == 0.0)] > 0.0)


def _features(env: gym.Env, obs: np.ndarray) -> np.ndarray:
    import torch

    from baselines.scoring import PrimitiveScorer, scorer_kwargs

    sc = PrimitiveScorer(len(obs), **scorer_kwargs(env))
    with torch.no_grad():
        return sc.features(torch.as_tensor(obs[None], dtype=torch.float32))[0].numpy()


def test_features_of_the_mirror_image_are_mirrored(env: gym.Env) -> None:
    """The mirror world (east -> -east) with the mirrored primitive gives the same features up to
    the sign of every 'right' component: the scorer sees the model's symmetry."""
    from baselines.ppo import policy_frame

    u = env.unwrapped
    signs = policy_frame(u).mirror_signs(u.observation_names)
    mirror = u.library.mirror_indices()
    rng = np.random.default_rng(0)
    for seed in range(3):
        obs, _ = env.reset(seed=seed)
        obs = obs + rng.normal(0, 0.05, obs.shape).astype(np.float32) * (obs != 0)
        f, fm = _features(env, obs), _features(env, obs * signs)
        # which feature columns flip: compare a primitive with its own mirror image
        flip = np.where(np.isclose(f[mirror], fm, atol=1e-5), 1.0, -1.0).min(axis=0)
        assert np.allclose(f[mirror] * flip, fm, atol=1e-5)
        assert np.any(flip < 0)  # the right components and turn features do flip


def test_lift_estimate_is_largest_on_the_thermal(env: gym.Env) -> None:
    """A thermal put 300 m ahead: the 10 m/s level straight primitive, which ends on its centre,
    has more estimated lift than any primitive that turns away from it."""
    obs, _ = env.reset(seed=0)
    u = env.unwrapped
    names = u.observation_names
    i = {n: k for k, n in enumerate(names)}
    obs = obs.copy()
    obs[[i["wind_north"], i["wind_east"]]] = 0.0
    for j in range(3):
        obs[[i[f"thermal_{j}_present"], i[f"thermal_{j}_north"], i[f"thermal_{j}_east"]]] = 0.0
    obs[i["thermal_0_present"]], obs[i["thermal_0_north"]] = 1.0, 0.3
    obs[i["thermal_0_peak"]], obs[i["thermal_0_radius"]] = 0.5, 0.08
    f = _features(env, obs)
    tab = u.library.table
    level = (tab[:, COL_FAMILY] == STRAIGHT) & (tab[:, COL_AIRSPEED] == 10.0) & (tab[:, COL_GAMMA] == 0.0)
    level10 = int(np.flatnonzero(level)[0])
    from baselines.scoring import PrimitiveScorer, scorer_kwargs

    n_fixed = PrimitiveScorer(len(obs), **scorer_kwargs(env)).fixed.shape[1]
    lift = f[:, n_fixed + 4]
    turning = tab[:, COL_FAMILY] != STRAIGHT
    assert lift[level10] > lift[turning].max()
    assert np.isclose(f[level10, n_fixed + 6 + 3], 0.0, atol=1e-3)  # ends on the centre: d / r = 0


def test_scoring_policy_saves_loads_and_predicts_alike(env: gym.Env, tmp_path: Path) -> None:
    import torch
    from stable_baselines3 import PPO

    from baselines.scoring import PrimitiveScoringPolicy, scorer_kwargs

    torch.manual_seed(0)
    model = PPO(
        PrimitiveScoringPolicy,
        env,
        seed=0,
        device="cpu",
        policy_kwargs={"net_arch": {"pi": [], "vf": [32]}, "scorer": {**scorer_kwargs(env), "hidden": [16]}},
    )
    probs = _check_saves_and_loads(model, env, tmp_path)
    assert probs.max() < 2.0 / 174  # the small last layer: a near-uniform first policy


def _check_saves_and_loads(model: object, env: gym.Env, tmp_path: Path) -> np.ndarray:
    """A distribution over the 174 primitives, and a saved and loaded copy that acts alike; returns
    the probabilities at one observation."""
    import torch
    from stable_baselines3 import PPO

    obs, _ = env.reset(seed=1)
    with torch.no_grad():
        probs = model.policy.get_distribution(torch.as_tensor(obs[None])).distribution.probs.numpy()[0]  # type: ignore[attr-defined]
    assert probs.shape == (174,) and np.isclose(probs.sum(), 1.0, atol=1e-5)
    model.save(tmp_path / "m.zip")  # type: ignore[attr-defined]
    loaded = PPO.load(tmp_path / "m.zip", device="cpu")
    for seed in range(3):
        o, _ = env.reset(seed=seed)
        assert model.predict(o, deterministic=True)[0] == loaded.predict(o, deterministic=True)[0]  # type: ignore[attr-defined]
    return probs


def test_bad_scoring_settings_are_refused() -> None:
    for kwargs in (
        {"algo": "continuous"},
        {"algo": "masked"},
        {"algo": "discrete", "task": "climb"},
        {"algo": "discrete", "body_frame": False},
    ):
        for policy in ("scoring", "successor"):
            with pytest.raises(ValueError, match=f"policy='{policy}'"):
                TrainConfig(policy=policy, **kwargs)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="policy="):
        TrainConfig(algo="discrete", policy="transformer")
    for bad in ((), "64", (0,), (16.5,), (True,)):
        with pytest.raises(ValueError, match="scorer_hidden"):
            TrainConfig(algo="discrete", policy="scoring", scorer_hidden=bad)  # type: ignore[arg-type]
    for bad_estimate in ("yes", 1, None):
        with pytest.raises(ValueError, match="scorer_estimate"):
            TrainConfig(algo="discrete", policy="successor", scorer_estimate=bad_estimate)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="scorer_estimate=True needs policy='successor'"):
        TrainConfig(algo="discrete", policy="scoring", scorer_estimate=True)
    with pytest.raises(ValueError, match="scorer_lift"):
        TrainConfig(algo="discrete", policy="successor", scorer_lift="yes")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="scorer_lift=True needs policy='successor'"):
        TrainConfig(algo="discrete", policy="scoring", scorer_lift=True)
    for bad_set in ("yes", 1, None):
        with pytest.raises(ValueError, match="demo_equivalents"):
            TrainConfig(algo="discrete", policy="successor", demos="d", demo_equivalents=bad_set)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="demo_equivalents=True needs policy='successor'"):
        TrainConfig(algo="discrete", policy="scoring", demos="d", demo_equivalents=True)
    with pytest.raises(ValueError, match="demo_equivalents=True needs demos"):
        TrainConfig(algo="discrete", policy="successor", demo_equivalents=True)


def test_scoring_needs_the_observed_thermals() -> None:
    from baselines.scoring import scorer_kwargs
    from soaring_env._validation import ConfigError

    with pytest.raises(ConfigError, match="thermal_0_present"):
        scorer_kwargs(gym.make(DISCRETE_ID, observe_thermals=False))


# --- the successor-scoring policy -------------------------------------------------------------------


def _successor(env: gym.Env, **kwargs: object) -> object:
    from baselines.scoring import SuccessorFeatures, successor_kwargs

    return SuccessorFeatures(**successor_kwargs(env), **kwargs)


@pytest.mark.parametrize("scenario", ["paper", "random"])
def test_successor_features_predict_every_flown_edge(scenario: str) -> None:
    """Where the observed slots hold every thermal (the paper's one; random draws of at most three),
    the field rebuilt from the observation gives each flown edge the cost the env charges, and the
    goal flag of the flown primitive says whether the step ends in the goal."""
    env = BodyFrameObservation(gym.make(DISCRETE_ID, scenario=scenario))
    feats = _successor(env)
    rng = np.random.default_rng(1)
    checked = goals = 0
    for seed in range(12):
        obs, _ = env.reset(seed=seed)
        if len(env.unwrapped.scenario.field.thermals) > 3:
            continue
        for _ in range(40):
            f = feats(obs[None])[0]  # type: ignore[operator]
            # towards the goal mostly (so that some episodes end there), else any primitive
            a = int(np.argmin(f[:, 2])) if rng.random() < 0.7 else int(rng.integers(174))
            obs, _, term, trunc, info = env.step(a)
            assert abs(f[a, 7] * 1000.0 - info["edge_cost"]) < 0.05  # [J/kg]; float32 features
            assert bool(f[a, 8]) == (info["outcome"] == "goal")
            checked += 1
            goals += info["outcome"] == "goal"
            if term or trunc:
                break
    assert checked > 20 and goals > 0


@pytest.mark.parametrize(("estimate", "lift"), [(False, False), (True, False), (False, True)])
def test_successor_features_of_the_mirror_image_are_mirrored(estimate: bool, lift: bool) -> None:
    """The mirror world with the mirrored primitive: the same successor up to the sign of every
    'right' component and of the turn rates; the cost-to-go estimates are the same."""
    from baselines.ppo import policy_frame

    env = BodyFrameObservation(gym.make(DISCRETE_ID, scenario="random"))
    u = env.unwrapped
    signs = policy_frame(u).mirror_signs(u.observation_names)
    mirror = u.library.mirror_indices()
    feats = _successor(env, estimate=estimate, lift=lift)
    for seed in range(3):
        obs, _ = env.reset(seed=seed)
        f, fm = feats(obs[None])[0], feats((obs * signs)[None])[0]  # type: ignore[operator]
        flip = np.where(np.isclose(f[mirror], fm, atol=1e-4), 1.0, -1.0).min(axis=0)
        assert np.allclose(f[mirror] * flip, fm, atol=1e-4)
        assert flip[1] < 0 and flip[0] > 0 and flip[7] > 0  # goal right flips; ahead and cost do not
        if estimate:
            assert np.all(flip[-5:] > 0)
        if lift:
            assert np.all(flip[-2:] > 0)


def test_successor_estimates_in_closed_form() -> None:
    """The search's cost-to-go estimate at each successor: without observed thermals, straight in at
    one cost per metre (the same for every successor below the goal's top), never below g times the
    height above that top; with them, the cheapest of straight in and the detours, still floored."""
    from baselines.scoring import N_SUCCESSOR_BASE, N_SUCCESSOR_SLOT, SuccessorFeatures, successor_kwargs
    from soaring_env.physics.atmosphere import G

    env = BodyFrameObservation(gym.make(DISCRETE_ID, scenario="random"))
    kw = successor_kwargs(env)
    feats = SuccessorFeatures(**kw, estimate=True)
    k = len(feats.layout.thermals)
    assert feats.n_features == N_SUCCESSOR_BASE + N_SUCCESSOR_SLOT * k + 2 + k
    detoured = 0
    for seed in range(4):
        obs, _ = env.reset(seed=seed)
        for calm in (True, False):
            x = obs.copy()
            if calm:
                for present, *_ in feats.layout.thermals:
                    x[present] = 0.0
            f = feats(x[None])[0].astype(np.float64)
            est, rank, det = f[:, -2 - k] * 1e3, f[:, -1 - k] * 1e3, f[:, -k:] * 1e3
            cost, h, below = f[:, 7] * 1e3, f[:, 4] * 1e3, f[:, 3] * 1e3  # edge cost, height, goal top - h ...
            d_goal = np.maximum(f[:, 2] * 1e3 - kw["goal_radius"], 0.0)
            floor = G * (h - (h + below + kw["goal_radius"]))  # g (h - goal top) < 0 below it
            assert np.allclose(rank, cost + est, atol=0.05)
            assert np.all(est >= floor - 0.05)
            assert np.all(est <= np.maximum(det.min(axis=1), floor) + 0.05)
            assert np.all(np.diff(det, axis=1) >= -1e-3)  # cheapest detour first
            if calm:
                lo = (d_goal > 50.0) & (est > floor + 1.0)
                per_metre = est[lo] / d_goal[lo]
                assert lo.sum() > 10 and np.ptp(per_metre) < 1e-3 * per_metre.mean()
                assert 0.1 < per_metre.mean() < 2.0  # J/(kg m): g / (L/D) of a straight glide or cruise
                assert np.allclose(det, det[:, :1], atol=0.05)  # no thermal: every "detour" is straight in
                assert np.allclose(est, np.maximum(det[:, 0], floor), atol=0.05)
            else:
                detoured += int(np.sum(det[:, 0] < est - 1.0) + np.sum(est < d_goal * per_metre.mean() - 1.0))
    assert detoured > 0  # some successor is nearer a thermal than straight in pays


@pytest.mark.parametrize(("estimate", "lift"), [(False, False), (True, False), (False, True)])
def test_successor_policy_saves_loads_and_predicts_alike(tmp_path: Path, estimate: bool, lift: bool) -> None:
    import torch
    from stable_baselines3 import PPO

    from baselines.scoring import SuccessorPolicy, successor_kwargs

    env = BodyFrameObservation(gym.make(DISCRETE_ID))
    torch.manual_seed(0)
    model = PPO(
        SuccessorPolicy,
        env,
        seed=0,
        device="cpu",
        n_steps=32,
        batch_size=16,
        n_epochs=1,
        policy_kwargs={
            "net_arch": {"pi": [], "vf": [32]},
            "scorer": {**successor_kwargs(env), "hidden": [16], "estimate": estimate, "lift": lift},
        },
    )
    model.learn(32)  # PPO trains it (the features are fixed functions of the observation)
    _check_saves_and_loads(model, env, tmp_path)


def test_successor_lift_features_in_closed_form() -> None:
    """The lift features: zero in calm air. With one thermal observed exactly where the straight
    primitive 0 ends, that successor's end-point feature is the rebuilt field's updraft in the
    core, above half the observed peak, and the ring's is the mean of the field at eight points
    20 m around it, lower than the core's (Allen's bell falls off from the centre)."""
    from baselines.scoring import LIFT_RING_M, N_SUCCESSOR_BASE, N_SUCCESSOR_SLOT

    env = BodyFrameObservation(gym.make(DISCRETE_ID, scenario="paper"))
    feats: Any = _successor(env, lift=True)
    lay = feats.layout
    assert feats.n_features == N_SUCCESSOR_BASE + N_SUCCESSOR_SLOT * len(lay.thermals) + 2
    obs, _ = env.reset(seed=0)
    calm = obs.copy()
    for present, *_ in lay.thermals:
        calm[present] = 0.0
    assert np.all(feats(calm[None])[0][:, -2:] == 0.0)
    end = feats.flown(calm.astype(np.float64)).states[0, -1, :]  # primitive 0 flies straight
    present, ia, ir, ipk, irad = lay.thermals[0]
    x = calm.copy()
    x[present], x[ia], x[ir], x[ipk], x[irad] = 1.0, end[0] / lay.position_scale, end[1] / lay.position_scale, 0.8, 0.08
    f = feats(x[None])[0].astype(np.float64) * lay.updraft_scale
    field = feats.field(x.astype(np.float64))
    end = feats.flown(x.astype(np.float64)).states[0, -1, :]  # the same point, higher in the lift
    ang = np.linspace(0.0, 2.0 * math.pi, 8, endpoint=False)
    ring = field.updraft(end[0] + LIFT_RING_M * np.cos(ang), end[1] + LIFT_RING_M * np.sin(ang), np.full(8, end[3]))
    assert np.isclose(f[0, -2], float(field.updraft(end[0], end[1], end[3])), atol=1e-5)
    assert f[0, -2] > 0.5 * 0.8 * lay.updraft_scale
    assert np.isclose(f[0, -1], ring.mean(), atol=1e-5) and f[0, -1] < f[0, -2]


def test_successor_needs_height_and_airspeed_entries() -> None:
    from baselines.scoring import SuccessorFeatures, successor_kwargs
    from soaring_env._validation import ConfigError

    kw = successor_kwargs(gym.make(DISCRETE_ID))
    layout = {k: v for k, v in kw["layout"].items() if k not in ("height", "airspeed")}  # a layout saved earlier
    with pytest.raises(ConfigError, match="height and airspeed"):
        SuccessorFeatures(**{**kw, "layout": layout})


def test_successor_features_refuse_non_finite_observations() -> None:
    from soaring_env._validation import ConfigError

    env = BodyFrameObservation(gym.make(DISCRETE_ID))
    obs, _ = env.reset(seed=0)
    feats = _successor(env)
    bad = obs.copy()
    bad[0] = np.nan
    with pytest.raises(ConfigError, match="finite"):
        feats(bad[None])  # type: ignore[operator]
    with pytest.raises(ConfigError, match="finite"):
        feats(obs)  # type: ignore[operator]  (one row, not a batch)


def test_near_equivalent_successors_in_closed_form() -> None:
    """Near-equivalence to a row's reference successor: end points within 50 m, heights within
    10 m and edge costs within 20 J/kg, each bound inclusive, the course ignored; the reference is
    always near itself. Two end points at the same distance from the goal on opposite sides of it
    are not near."""
    from baselines.scoring import near_equivalent
    from soaring_env._validation import ConfigError

    ends = np.zeros((1, 7, 4))
    ends[0, :, 0] = [1000.0, 1030.0, 1000.0, 1000.0, 1000.0, 1000.0, -1000.0]  # north [m]
    ends[0, :, 1] = [0.0, 40.0, 0.0, 0.0, 0.0, 0.0, 0.0]  # east: 50 m from the first
    ends[0, :, 2] = [0.0, 1.0, 2.0, 3.0, 0.0, 0.0, 0.0]  # courses differ
    ends[0, :, 3] = [500.0, 500.0, 510.0, 500.0, 500.0, 500.0, 500.0]
    costs = np.array([[100.0, 100.0, 100.0, 120.0, 121.0, 100.0, 100.0]])
    ends[0, 5, 1] = 51.0
    assert near_equivalent(ends, costs, np.array([0])).tolist() == [[True, True, True, True, False, False, False]]
    assert near_equivalent(ends, costs, np.array([6]))[0].tolist() == [False] * 6 + [True]
    with pytest.raises(ConfigError, match="near_equivalent"):
        near_equivalent(ends[0], costs, np.array([0]))
    with pytest.raises(ConfigError, match="near_equivalent"):
        near_equivalent(ends, costs[:, :3], np.array([0]))


def test_accepted_successors_are_the_near_equivalents_of_the_demonstrated_one() -> None:
    """On real observations: the accepted set holds the demonstrated primitive and exactly the
    primitives :func:`near_equivalent` finds among the edges flown from the observation; a
    straight primitive is not near a spiral."""
    from baselines.scoring import SuccessorFeatures, accepted_successors, near_equivalent, successor_kwargs
    from soaring_env._validation import ConfigError

    env = gym.make(DISCRETE_ID, scenario="random")
    frame = BodyFrameObservation(env)
    feats = SuccessorFeatures(**successor_kwargs(env))
    obs = np.stack([frame.reset(seed=s)[0] for s in range(3)])
    act = np.array([0, 17, 120])
    acc = accepted_successors(feats, obs, act)
    assert acc.shape == (3, 174) and acc[np.arange(3), act].all()
    for k in range(3):
        r = feats.flown(obs[k].astype(np.float64))
        assert np.array_equal(acc[k], near_equivalent(r.states[None, :, -1, :], r.cost[None], act[k : k + 1])[0])
    spiral = env.unwrapped.library.table[:, COL_FAMILY] == SPIRAL
    assert not acc[0, spiral].any()  # primitive 0 flies straight
    assert 1 < acc.sum() < 3 * 174
    # mismatched rows, float or out-of-range actions: a ConfigError, not numpy's or zip's ValueError
    for bad_obs, bad_act in ((obs, act[:2]), (obs, act + 0.5), (obs, np.array([0, 17, 174])), (obs[0], act[:1])):
        with pytest.raises(ConfigError, match="accepted_successors"):
            accepted_successors(feats, bad_obs, bad_act)
