"""Probe (docs/learning-to-soar.md, round nine): can primitives be planned from the privileged observation alone?

The cloned primitive policies fly straight on most held-out scenarios (median regret 1.00). This
probe asks whether the observation holds what a primitive agent needs, without any learning in
the loop where possible. At every decision it rebuilds the air from the observation -- the
observed thermal slots as Allen thermals at the observed offsets, with w* chosen so that Allen's
w_peak at the aircraft's height equals the observed peak, zi of the task's scenarios (1,400 m), the
observed wind: ``SuccessorFeatures.field`` of :mod:`baselines.scoring` -- and flies the 174
primitives through the model's own ``rollout`` in that field (a frame centred on the aircraft,
axes north and east, its true course):

* ``--mode beam``: a beam search over primitive sequences in the rebuilt field (width ``--width``,
  at most ``--depth`` edges; kept by cost so far + a straight-glide estimate of the cost still to
  go: ``g (h - h_goal) + g max(0, d / L - (h - h_goal)) / eta``, L = ``--glide-ratio``); the agent
  flies the first edge of the cheapest plan that reaches the goal and plans again (MPC);
* ``--mode rerank``: the saved c3 policy's ``--top`` most likely primitives, re-ranked by the
  rebuilt field's edge reward plus a cost-to-go fitted on the demonstrations' states (an MLP on
  the next state's goal and thermal offsets, by least squares on the plans' returns-to-go);
  ``--top 174`` ranks every allowed primitive (one-step lookahead on the fitted cost-to-go).

Every mode also reports how well the rebuilt field predicts the flown edge: the edge cost the
rollout gives there against the env's ``edge_cost`` of the same step. Episodes: ``paper`` and
``random-10000 ... random-10019`` (the 21 held-out scenarios of the goal-reaching tables), regret
against the yardstick in ``results/reference`` (primitive sampler). Nothing here is part of the
library: the domain's bounds are not in the observation and the probe ignores them, and thermals
beyond the observed slots do not exist for it.

Usage: ``python scripts/probe_lookahead.py --mode beam --width 32`` (80 s on one core of a slow host)
or ``--mode rerank --top 1 3 10 174`` (about a minute; needs ``results/ppo-score/c3``).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

G = 9.80665
NAMES = ["paper"] + [f"random-{10000 + i}" for i in range(20)]


class Lookahead:
    """Edges of the 174 primitives from many local states at once, in one rebuilt field."""

    def __init__(self, env: Any) -> None:
        from baselines.scoring import SuccessorFeatures, successor_kwargs

        u = env.unwrapped
        self.u = u
        # the successor policy's rebuild; with the raw observation's layout it is in the world frame
        self.rebuild = SuccessorFeatures(**successor_kwargs(u))
        self.names = list(u.observation_names)
        self.cfg = u.config
        self.allowed = u.model.allowed_primitives()
        self.n_prim = len(self.allowed)

    def start(self, obs: np.ndarray) -> dict[str, Any]:
        """The root of a search: local state, goal offset and height, the rebuilt field."""
        w = {n: i for i, n in enumerate(self.names)}
        cfg = self.cfg
        u = self.u
        h = float(u.state[3])
        return {
            "field": self.rebuild.field(np.asarray(obs, np.float64)),
            "goal": np.array(
                [
                    obs[w["goal_north"]] * cfg.position_scale,
                    obs[w["goal_east"]] * cfg.position_scale,
                    h + obs[w["goal_up"]] * cfg.height_scale,
                ]
            ),
            "x": np.array([[0.0, 0.0, float(u.state[2]), h]]),
            "vp": np.array([float(u.airspeed_prev)]),
        }

    def expand(self, root: dict[str, Any], x: np.ndarray, vp: np.ndarray) -> dict[str, np.ndarray]:
        """Every primitive from every state of ``x`` (B, 4): cost (B, 174), goal/crash flags, ends."""
        from soaring_env.primitives import rollout

        b = x.shape[0]
        prims = np.tile(np.arange(self.n_prim), b)
        r = rollout(
            np.repeat(x, self.n_prim, axis=0),
            root["field"],
            self.u.model.aircraft,
            primitive=prims,
            library=self.u.library,
            airspeed_prev=np.repeat(vp, self.n_prim),
            max_substep=self.u.model.max_substep,
        )
        s = r.states  # (B*174, N, 4)
        g = root["goal"]
        d = np.sqrt((s[..., 0] - g[0]) ** 2 + (s[..., 1] - g[1]) ** 2 + (s[..., 3] - g[2]) ** 2)
        shape = (b, self.n_prim)
        return {
            "cost": r.cost.reshape(shape),
            "goal": (d <= self.rebuild.goal_radius).any(axis=1).reshape(shape),
            "crash": (s[..., 3] <= 0.0).any(axis=1).reshape(shape),
            "end": s[:, -1, :].reshape(*shape, 4),
            "airspeed": self.u.library.table[prims, 1].reshape(shape),
        }


def to_go_estimate(end: np.ndarray, goal: np.ndarray, glide_ratio: float, eta: float) -> np.ndarray:
    """Straight-glide estimate of the cost still to go [J/kg] from states ``end`` (..., 4)."""
    d = np.hypot(end[..., 0] - goal[0], end[..., 1] - goal[1])
    excess = end[..., 3] - goal[2]
    return G * excess + G * np.maximum(0.0, d / glide_ratio - excess) / eta


def beam_action(look: Lookahead, obs: np.ndarray, width: int, depth: int, glide_ratio: float) -> tuple[int, float]:
    """First primitive of the cheapest goal plan of a beam search in the rebuilt field, and the
    cost the field predicts for it (NaN where no plan reached the goal: the best-ranked edge)."""
    root = look.start(obs)
    eta = look.u.model.aircraft.eta_ec * look.u.model.aircraft.eta_p
    x, vp = root["x"], root["vp"]
    acc = np.zeros(1)
    first = np.full(1, -1)
    best = (math.inf, -1)
    first_cost = None
    for k in range(depth):
        e = look.expand(root, x, vp)
        if k == 0:
            first_cost = e["cost"][0]
        tot = acc[:, None] + e["cost"]
        ok = look.allowed[None, :] & ~e["crash"]
        fa = np.broadcast_to(np.arange(look.n_prim)[None, :] if k == 0 else first[:, None], tot.shape)
        hit = ok & e["goal"]
        if hit.any():
            i = int(np.argmin(np.where(hit, tot, np.inf)))
            if tot.flat[i] < best[0]:
                best = (float(tot.flat[i]), int(fa.flat[i]))
        score = np.where(ok & ~e["goal"], tot + to_go_estimate(e["end"], root["goal"], glide_ratio, eta), np.inf)
        flat = score.ravel()
        keep = np.argsort(flat, kind="stable")[:width]
        keep = keep[np.isfinite(flat[keep])]
        if keep.size == 0:
            break
        x = e["end"].reshape(-1, 4)[keep]
        vp = e["airspeed"].ravel()[keep]
        acc = tot.ravel()[keep]
        first = fa.ravel()[keep]
    a = best[1] if best[1] >= 0 else int(first[0])
    assert first_cost is not None
    return a, float(first_cost[a])


def state_features(goal_ne: np.ndarray, goal_up: np.ndarray, h: np.ndarray, wind: np.ndarray, th: np.ndarray) -> Any:
    """Features of the fitted cost-to-go, in the aircraft's frame: goal offset [km], distance [km],
    height to go and height [km], wind / 10 m/s, and per observed thermal (nearest first) present,
    offset [km], distance [km], peak / 5 m/s and radius [km] (``th`` (B, K, 5) in that order)."""
    d = np.linalg.norm(th[..., 1:3], axis=-1) + (1.0 - th[..., 0]) * 1e6
    order = np.argsort(d, axis=1, kind="stable")
    th = np.take_along_axis(th, order[..., None], axis=1)
    d = np.take_along_axis(d, order, axis=1)
    on = th[..., 0]
    per = np.stack(
        [on, th[..., 1] / 1e3 * on, th[..., 2] / 1e3 * on, np.minimum(d, 1e4) / 1e3 * on, th[..., 3] / 5 * on,
         th[..., 4] / 1e3 * on],
        axis=-1,
    ).reshape(th.shape[0], -1)  # fmt: skip
    base = [
        goal_ne / 1e3,
        np.linalg.norm(goal_ne, axis=-1, keepdims=True) / 1e3,
        goal_up[:, None] / 1e3,
        h[:, None] / 1e3,
    ]
    return np.concatenate([*base, wind / 10.0, per], axis=1).astype(np.float32)


def body(v: np.ndarray, chi: np.ndarray) -> np.ndarray:
    """(north, east) vectors (..., 2) into (ahead, right) for courses ``chi`` [rad]."""
    c, s = np.cos(chi), np.sin(chi)
    return np.stack([v[..., 0] * c + v[..., 1] * s, -v[..., 0] * s + v[..., 1] * c], axis=-1)


def raw_features(obs: np.ndarray, names: list[str], cfg: Any) -> Any:
    """:func:`state_features` of raw env observations (B, D)."""
    w = {n: i for i, n in enumerate(names)}
    chi = np.arctan2(obs[:, w["sin_course"]], obs[:, w["cos_course"]])
    ps = cfg.position_scale
    k = 0
    slots = []
    while f"thermal_{k}_present" in w:
        rel = body(obs[:, [w[f"thermal_{k}_north"], w[f"thermal_{k}_east"]]] * ps, chi)
        slots.append(
            np.column_stack(
                [obs[:, w[f"thermal_{k}_present"]], rel, obs[:, w[f"thermal_{k}_peak"]] * cfg.updraft_scale,
                 obs[:, w[f"thermal_{k}_radius"]] * ps]
            )
        )  # fmt: skip
        k += 1
    return state_features(
        body(obs[:, [w["goal_north"], w["goal_east"]]] * ps, chi),
        obs[:, w["goal_up"]] * cfg.height_scale,
        obs[:, w["height"]] * cfg.height_scale,
        body(obs[:, [w["wind_north"], w["wind_east"]]] * cfg.wind_scale, chi),
        np.stack(slots, axis=1),
    )


#: The plans the cost-to-go is fitted on: round eight's 1,759 (``c4``'s and ``s1``'s).
DEMO_MATCH = r"random-20(\d\d\d)(-(r[12]|c[23])s\d+)?"


def fit_cost_to_go(
    names: list[str], cfg: Any, match: str = DEMO_MATCH, seed: int = 0, epochs: int = 120
) -> tuple[Any, dict[str, float]]:
    """An MLP fitted to the returns-to-go (gamma = 1) of the demonstrations' states (the plans of
    ``results/reference-train-prim-t1`` whose names match ``match``)."""
    import torch

    from baselines.imitation import demonstrations
    from baselines.ppo import make_eval_env

    demos = demonstrations(
        "results/reference-train-prim-t1",
        lambda sc: make_eval_env("soaring/Soaring-v0", [sc], {}, False),
        sampler="primitive",
        gamma=1.0,
        match=match,
    )
    x = torch.tensor(raw_features(demos.observations.astype(np.float64), names, cfg))
    y = torch.tensor(demos.returns.astype(np.float32))
    rng = np.random.default_rng(seed)
    eps = np.unique(demos.episode)
    rng.shuffle(eps)
    val = np.isin(demos.episode, eps[: len(eps) // 10])
    tr, va = np.flatnonzero(~val), np.flatnonzero(val)
    torch.manual_seed(seed)
    net = torch.nn.Sequential(
        torch.nn.Linear(x.shape[1], 256),
        torch.nn.Tanh(),
        torch.nn.Linear(256, 256),
        torch.nn.Tanh(),
        torch.nn.Linear(256, 1),
    )
    opt = torch.optim.Adam(net.parameters(), lr=1e-3)
    mu, sd = float(y[tr].mean()), float(y[tr].std())
    for _ in range(epochs):
        perm = rng.permutation(tr)
        for i in range(0, len(perm), 256):
            bi = perm[i : i + 256]
            loss = ((net(x[bi]).squeeze(-1) - (y[bi] - mu) / sd) ** 2).mean()
            opt.zero_grad()
            loss.backward()
            opt.step()
    with torch.no_grad():
        pred = net(x[va]).squeeze(-1) * sd + mu
        rmse = float(((pred - y[va]) ** 2).mean().sqrt())

    def value(feats: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            return (net(torch.tensor(feats)).squeeze(-1) * sd + mu).numpy()

    return value, {"rows": len(demos), "plans": len(demos.scenarios), "val_rmse": rmse, "val_sd": float(y[va].std())}


def rerank_action(look: Lookahead, obs: np.ndarray, logits: np.ndarray, top: int, value: Any) -> tuple[int, float]:
    """The best of the policy's ``top`` primitives by edge reward + fitted cost-to-go of its end."""
    cfg = look.cfg
    root = look.start(obs)
    e = look.expand(root, root["x"], root["vp"])
    end = e["end"][0]  # (174, 4) local frame
    chi = end[:, 2]
    g = root["goal"]
    w = {n: i for i, n in enumerate(look.names)}
    th_rows = []
    for t in root["field"].thermals:
        rel = body(np.column_stack([t.north - end[:, 0], t.east - end[:, 1]]), chi)
        prof = root["field"].allen_profile(float(np.clip(end[:, 3].mean(), 1.0, look.rebuild.zi - 1.0)), t.strength)
        th_rows.append(
            np.column_stack([np.ones(len(end)), rel, np.full(len(end), prof["w_peak"]), np.full(len(end), prof["r2"])])
        )
    k = 0
    while f"thermal_{k}_present" in w:
        k += 1
    while len(th_rows) < k:
        th_rows.append(np.zeros((len(end), 5)))
    feats = state_features(
        body(np.column_stack([g[0] - end[:, 0], g[1] - end[:, 1]]), chi),
        g[2] - end[:, 3],
        end[:, 3],
        body(np.tile(np.array([root["field"].wind_north, root["field"].wind_east]), (len(end), 1)), chi),
        np.stack(th_rows, axis=1),
    )
    d_now = float(np.linalg.norm(g - np.array([0.0, 0.0, root["x"][0, 3]])))
    d_new = np.sqrt((g[0] - end[:, 0]) ** 2 + (g[1] - end[:, 1]) ** 2 + (g[2] - end[:, 3]) ** 2)
    reward = (
        -e["cost"][0] / 1e3 + cfg.progress_weight * (d_now - d_new) / 1e3 + np.where(e["goal"][0], cfg.goal_bonus, 0.0)
    )
    q = reward + np.where(e["goal"][0], 0.0, value(feats))
    cand = np.argsort(-np.where(look.allowed, logits, -np.inf), kind="stable")[:top]
    a = int(cand[np.argmax(q[cand])])
    return a, float(e["cost"][0][a])


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--mode", choices=("beam", "rerank"), default="beam")
    p.add_argument("--width", type=int, default=32, help="beam width (beam)")
    p.add_argument("--depth", type=int, default=20, help="most edges of a plan (beam)")
    p.add_argument("--glide-ratio", type=float, default=15.0, help="L of the cost-to-go estimate (beam)")
    p.add_argument("--top", type=int, nargs="+", default=[1, 3, 10, 174], help="candidates re-ranked (rerank)")
    p.add_argument("--policy", default="results/ppo-score/c3/discrete/model.zip", help="the policy (rerank)")
    p.add_argument("--out", type=Path, default=None, help="write the episodes as JSON here")
    args = p.parse_args(argv)
    if args.width < 1 or args.depth < 1 or not args.glide_ratio > 0 or min(args.top) < 1:
        p.error("--width, --depth and --top must be >= 1 and --glide-ratio > 0")
    if args.mode == "rerank" and not (
        Path(args.policy).is_file() and (Path(args.policy).parent / "config.json").is_file()
    ):
        p.error(f"--policy {args.policy}: no such model.zip beside a config.json (a train_ppo.py run's output)")

    import gymnasium as gym
    import torch

    import soaring_env  # noqa: F401  (registers the ids)
    from baselines.reference import load_references

    torch.set_num_threads(1)
    refs = load_references("results/reference")
    probe_env: Any = gym.make("soaring/Soaring-v0").unwrapped
    names, cfg = list(probe_env.observation_names), probe_env.config
    runs: list[tuple[str, Any]] = []
    fit: dict[str, float] = {}
    if args.mode == "beam":
        runs.append((f"beam W={args.width} D={args.depth} L={args.glide_ratio:g}", None))
    else:
        from stable_baselines3 import PPO

        from baselines.ppo import observation_transform

        value, fit = fit_cost_to_go(names, cfg)
        print(f"cost-to-go fit: {fit}", flush=True)
        run_dir = Path(args.policy).parent
        transform = observation_transform(json.loads((run_dir / "config.json").read_text()))
        policy = PPO.load(args.policy, device="cpu").policy
        runs += [(f"rerank top {k}", k) for k in args.top]
    report: dict[str, Any] = {"args": {k: str(v) for k, v in vars(args).items()}, "fit": fit, "runs": {}}
    for label, top in runs:
        t0 = time.perf_counter()
        regrets, errs, rows = [], [], []
        for name in NAMES:
            ref = refs[name].samplers["primitive"]
            env = gym.make("soaring/Soaring-v0", scenario=refs[name].scenario)
            look = Lookahead(env)
            obs, info = env.reset(seed=0)
            done = False
            while not done:
                if top is None:
                    a, predicted = beam_action(look, obs, args.width, args.depth, args.glide_ratio)
                else:
                    with torch.no_grad():
                        o = torch.tensor(np.asarray(transform(obs) if transform else obs, np.float32)[None])
                        dist: Any = policy.get_distribution(o).distribution
                        logits = dist.logits[0].numpy()
                    a, predicted = rerank_action(look, obs, logits, top, value)
                obs, _, term, trunc, info = env.step(a)
                errs.append(predicted - float(info["edge_cost"]))
                done = bool(term or trunc)
            j = float(info["energy_spent"])
            reg = (j - ref.best_cost) / (ref.direct_cost - ref.best_cost) if info["outcome"] == "goal" else math.inf
            regrets.append(reg)
            rows.append({"scenario": name, "outcome": info["outcome"], "energy": j, "regret": reg})
            print(f"  {name:14s} {info['outcome']:8s} J {j:7.0f}  regret {reg:6.2f}", flush=True)
        r = np.array(regrets)
        e = np.abs(np.array(errs))
        summary = {
            "median_regret": float(np.median(r)),
            "below_0.6": int((r <= 0.6).sum()),
            "failures": int(np.isinf(r).sum()),
            "edge_error_median": float(np.median(e)),
            "edge_error_p90": float(np.percentile(e, 90)),
            "seconds": time.perf_counter() - t0,
        }
        report["runs"][label] = {"summary": summary, "episodes": rows}
        print(
            f"{label}: median regret {summary['median_regret']:.2f}, {summary['below_0.6']}/21 <= 0.6, "
            f"{summary['failures']} failures; |predicted - flown edge cost| median {summary['edge_error_median']:.1f}, "
            f"p90 {summary['edge_error_p90']:.1f} J/kg; {summary['seconds']:.0f} s",
            flush=True,
        )
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        tmp = args.out.with_suffix(".tmp")
        tmp.write_text(json.dumps(report, indent=1))
        tmp.replace(args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
