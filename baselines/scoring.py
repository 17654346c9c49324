"""A policy that scores each motion primitive by where it would take the aircraft.

A plain MLP over the 174 primitives must learn, from the observation alone, which of 174 fixed
30 s manoeuvres ends in a thermal's core, passes the goal or spirals in lift: a product of the
thermal offsets, the wind and each primitive's geometry, learnt anew for every output. Cloned from
the reference plans such policies fly safely but straight (docs/learning-to-soar.md, rounds four and five: held-out
median regret 1.00-1.06). :class:`PrimitiveScoringPolicy` gives PPO that geometry as an inductive
bias instead: the logit of primitive ``a`` is one small MLP shared by all primitives,

    logit_a = f_theta(obs, phi(obs, a)),

where ``phi`` holds what the primitive does from the observed state: its still-air path (flown once
through the model's own rollout, :func:`primitive_paths`) shifted by the observed wind, the goal
offset it would leave, its offset to each observed thermal and a crude lift estimate along it (a
Gaussian bell of the observed peak and radius; the network learns how far to trust it). ``phi`` is a
fixed function of the observation, so this is an ordinary stochastic policy over ``Discrete(174)``
trained by ordinary PPO; only its parametrisation differs (action features shared across actions,
as in Q-networks over action embeddings). The critic is the usual MLP.

:class:`SuccessorPolicy` (round nine) goes one step further: it flies each primitive through the
air the observation shows (the observed thermal slots rebuilt into an Allen field, the model's own
``rollout``) and scores the *successor state* -- its goal and thermal offsets in its own frame, its
height, the edge's exact cost -- with one MLP shared by all primitives, no per-primitive vectors.

Both read the body-frame observation (:class:`baselines.ppo.BodyFrame`, the thermal slots of the
privileged tier); its layout is resolved by name when the policy is built.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import torch
from stable_baselines3.common.policies import ActorCriticPolicy
from stable_baselines3.common.torch_layers import MlpExtractor
from torch import nn

from soaring_env._validation import ConfigError
from soaring_env.physics.thermals import WindField
from soaring_env.primitives import COL_AIRSPEED, COL_CHI_DOT_1, COL_CHI_DOT_2, COL_FAMILY, COL_GAMMA, Rollout, rollout
from soaring_env.scenario import Bounds, GoalRegion, Scenario

#: Samples of each primitive's path the lift estimate is averaged over (every 3 s of a 30 s edge).
N_PATH_SAMPLES = 10


def primitive_paths(model: Any, n_samples: int = N_PATH_SAMPLES) -> dict[str, list[Any]]:
    """Each primitive of ``model.library`` flown once in still air without thermals, from the
    origin heading north at the scenario's start height, through the model's rollout.

    :returns: ``paths`` (174, n_samples, 3): (ahead, right, up) offsets [m] at ``times`` [s]
        (n_samples evenly spaced output points, the last the edge's end); ``static`` (174, 8):
        airspeed / 20 m/s, path angle [rad], the two halves' turns / 1080 deg, the four family
        flags; ``cost`` (174,): the still-air specific energy spent [kJ/kg] (fuel + potential).
        Plain lists, so that a saved model's constructor arguments stay JSON-friendly.
    """
    lib = model.library
    sc = model.scenario
    still = WindField(thermals=(), model=sc.field.model, zi=sc.field.zi)
    n = len(lib)
    h0 = float(sc.start[3])
    x0 = np.tile(np.array([0.0, 0.0, 0.0, h0]), (n, 1))
    r = rollout(x0, still, model.aircraft, primitive=np.arange(n), library=lib)
    pts = r.states.shape[1]
    pick = np.linspace(pts / n_samples - 1, pts - 1, n_samples).round().astype(np.int64)
    st = r.states[:, pick, :]
    paths = np.stack([st[..., 0], st[..., 1], st[..., 3] - h0], axis=-1)
    tab = lib.table
    full = math.radians(1080.0) / lib.duration
    fam = np.eye(4)[tab[:, COL_FAMILY].astype(np.int64)]
    static = np.column_stack(
        [
            tab[:, COL_AIRSPEED] / 20.0,
            tab[:, COL_GAMMA],
            tab[:, COL_CHI_DOT_1] / full,
            tab[:, COL_CHI_DOT_2] / full,
            fam,
        ]
    )
    cost = (r.fuel + r.potential) / 1000.0
    return {
        "paths": paths.tolist(),
        "times": r.times[pick].tolist(),
        "static": static.tolist(),
        "cost": cost.tolist(),
    }


@dataclasses.dataclass(frozen=True)
class ObservationLayout:
    """Where :class:`PrimitiveScorer` finds its inputs in the body-frame observation, and the env's
    scales (observation = SI value / scale)."""

    goal: tuple[int, int, int]  # ahead, right, up
    wind: tuple[int, int]  # ahead, right
    thermals: tuple[tuple[int, int, int, int, int], ...]  # present, ahead, right, peak, radius
    position_scale: float
    height_scale: float
    updraft_scale: float
    wind_scale: float
    # read by SuccessorScorer only; -1 in layouts saved before it existed
    height: int = -1
    airspeed: int = -1
    speed_scale: float = 20.0

    @classmethod
    def of(cls, names: Sequence[str], config: Any) -> ObservationLayout:
        """The layout of a body-frame observation whose first entries are the env's ``names``
        (the rotated pairs keep the names' positions: ``*_north`` holds ahead, ``*_east`` right).

        :raises ConfigError: a layout without a goal or without thermal slots (the sensed tiers).
        """
        where = {n: i for i, n in enumerate(names)}
        need = ("goal_north", "goal_east", "goal_up", "wind_north", "wind_east", "thermal_0_present")
        missing = [n for n in need if n not in where]
        if missing:
            raise ConfigError(
                f"policy='scoring' needs the goal and the observed thermal slots (privileged tier); "
                f"the observation lacks {', '.join(missing)}"
            )
        slots = []
        j = 0
        while f"thermal_{j}_present" in where:
            slots.append(tuple(where[f"thermal_{j}_{k}"] for k in ("present", "north", "east", "peak", "radius")))
            j += 1
        return cls(
            goal=(where["goal_north"], where["goal_east"], where["goal_up"]),
            wind=(where["wind_north"], where["wind_east"]),
            thermals=tuple(slots),  # type: ignore[arg-type]
            position_scale=float(config.position_scale),
            height_scale=float(config.height_scale),
            updraft_scale=float(config.updraft_scale),
            wind_scale=float(config.wind_scale),
            height=where.get("height", -1),
            airspeed=where.get("airspeed", -1),
            speed_scale=float(config.speed_scale),
        )

    def to_dict(self) -> dict[str, Any]:
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in dataclasses.asdict(self).items()}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> ObservationLayout:
        """The inverse of :meth:`to_dict` (a saved model's constructor arguments)."""
        return cls(
            goal=tuple(d["goal"]),  # type: ignore[arg-type]
            wind=tuple(d["wind"]),  # type: ignore[arg-type]
            thermals=tuple(tuple(t) for t in d["thermals"]),  # type: ignore[arg-type]
            **{k: float(d[k]) for k in ("position_scale", "height_scale", "updraft_scale", "wind_scale")},
            height=int(d.get("height", -1)),
            airspeed=int(d.get("airspeed", -1)),
            speed_scale=float(d.get("speed_scale", 20.0)),
        )


def scorer_kwargs(env: Any) -> dict[str, Any]:
    """The constructor arguments of :class:`PrimitiveScorer` for ``env`` (a raw single env of a
    primitive task): the primitives' still-air paths and the observation layout."""
    u = env.unwrapped if hasattr(env, "unwrapped") else env
    return {**primitive_paths(u.model), "layout": ObservationLayout.of(u.observation_names, u.config).to_dict()}


class PrimitiveScorer(nn.Module):
    """Body-frame observations (B, D) -> logits (B, 174) (module docstring).

    :param paths: (A, K, 3) still-air offsets [m]; :param times: (K,) their times [s];
    :param static: (A, S) fixed features; :param cost: (A,) still-air cost [kJ/kg];
    :param layout: :meth:`ObservationLayout.to_dict`; :param hidden: the shared MLP's widths.
    """

    paths: torch.Tensor
    times: torch.Tensor
    fixed: torch.Tensor

    def __init__(
        self,
        obs_dim: int,
        paths: Sequence[Any],
        times: Sequence[float],
        static: Sequence[Any],
        cost: Sequence[float],
        layout: dict[str, Any],
        hidden: Sequence[int] = (64, 64),
    ) -> None:
        super().__init__()
        f32 = torch.float32
        self.register_buffer("paths", torch.tensor(np.asarray(paths), dtype=f32))
        self.register_buffer("times", torch.tensor(np.asarray(times), dtype=f32))
        fixed = np.column_stack([np.asarray(static), np.asarray(cost)[:, None], np.asarray(paths)[:, -1, :] / 1000.0])
        self.register_buffer("fixed", torch.tensor(fixed, dtype=f32))
        lay = ObservationLayout.from_dict(layout)
        self.layout = lay
        n_dyn = 6 + 4 * len(lay.thermals)
        self.n_features = fixed.shape[1] + n_dyn
        sizes = [int(h) for h in hidden]
        self.state_in = nn.Linear(obs_dim, sizes[0])
        self.action_in = nn.Linear(self.n_features, sizes[0], bias=False)
        # a learnt vector per primitive beside its features: what the features miss (the plain
        # MLP's per-action output weights); without it the cloning fits far worse
        # (docs/learning-to-soar.md, round seven)
        self.action_embedding = nn.Parameter(torch.zeros(len(fixed), sizes[0]))
        layers: list[Any] = []
        for a, b in itertools.pairwise(sizes):
            layers += [nn.Tanh(), nn.Linear(a, b)]
        layers += [nn.Tanh(), nn.Linear(sizes[-1], 1)]
        self.head = nn.Sequential(*layers)

    def features(self, obs: Any) -> Any:
        """(B, A, F) per-primitive features of body-frame observations (B, D)."""
        lay = self.layout
        b = obs.shape[0]
        km = 1000.0
        wind = obs[:, list(lay.wind)] * lay.wind_scale  # (B, 2) ahead, right [m/s]
        # ground-relative path: still-air offsets + wind drift (thermals do not drift by default)
        xy = self.paths[None, :, :, :2] + wind[:, None, None, :] * self.times[None, None, :, None]  # (B,A,K,2)
        end = xy[:, :, -1, :]
        goal = obs[:, list(lay.goal[:2])] * lay.position_scale
        to_goal = goal[:, None, :] - end  # (B, A, 2) [m]
        d_goal = torch.linalg.vector_norm(to_goal, dim=-1)
        up_left = obs[:, lay.goal[2]][:, None] * lay.height_scale - self.paths[None, :, -1, 2]
        d_now = torch.linalg.vector_norm(goal, dim=-1)[:, None]
        lift = torch.zeros(b, xy.shape[1], xy.shape[2], dtype=obs.dtype)
        per_slot = []
        for present, ia, ir, ipk, irad in lay.thermals:
            c = torch.stack([obs[:, ia], obs[:, ir]], dim=-1) * lay.position_scale  # (B, 2)
            on = obs[:, present][:, None]
            peak = obs[:, ipk][:, None] * lay.updraft_scale
            rad = torch.clamp(obs[:, irad] * lay.position_scale, min=10.0)[:, None]
            d = torch.linalg.vector_norm(c[:, None, None, :] - xy, dim=-1)  # (B, A, K)
            w = on[:, :, None] * peak[:, :, None] * torch.exp(-((d / rad[:, :, None]) ** 2))
            lift = lift + w
            rel = (c[:, None, :] - end) * on[:, :, None]  # empty slots: zeros
            per_slot += [
                on.expand(-1, xy.shape[1]),
                rel[..., 0] / km,
                rel[..., 1] / km,
                on * torch.clamp(d[:, :, -1] / rad, max=10.0),
            ]
        dt = float(self.times[-1])
        mean_lift = lift.mean(dim=-1)
        dyn = torch.stack(
            [
                to_goal[..., 0] / km,
                to_goal[..., 1] / km,
                (d_goal - d_now) / km,
                up_left / km,
                mean_lift / lay.updraft_scale,
                mean_lift * dt / km,  # height the lift would give [km]
                *per_slot,
            ],
            dim=-1,
        )
        return torch.cat([self.fixed[None].expand(b, -1, -1), dyn], dim=-1)

    def forward(self, obs: Any) -> Any:
        h = self.state_in(obs)[:, None, :] + self.action_in(self.features(obs)) + self.action_embedding[None]
        return self.head(h).squeeze(-1)


class ScoringExtractor(MlpExtractor):
    """SB3's extractor with the actor replaced by :class:`PrimitiveScorer` (latent = logits)."""

    def __init__(self, feature_dim: int, vf_arch: Sequence[int], scorer: dict[str, Any]) -> None:
        super().__init__(feature_dim, net_arch={"pi": [], "vf": list(vf_arch)}, activation_fn=nn.Tanh)
        self.policy_net = PrimitiveScorer(feature_dim, **scorer)  # type: ignore[assignment]
        self.latent_dim_pi = len(scorer["paths"])


class PrimitiveScoringPolicy(ActorCriticPolicy):
    """ActorCriticPolicy over ``Discrete(174)`` whose logits come from :class:`PrimitiveScorer`.

    :param scorer: :func:`scorer_kwargs` of the env (plus optionally ``hidden``).
    """

    def __init__(self, *args: Any, scorer: dict[str, Any], **kwargs: Any) -> None:
        self.scorer = dict(scorer)
        super().__init__(*args, **kwargs)

    #: the extractor whose actor is the scorer (:class:`SuccessorPolicy` swaps it)
    extractor_class: Any = None

    def _build_mlp_extractor(self) -> None:
        arch = self.net_arch
        vf = arch.get("vf", [64, 64]) if isinstance(arch, dict) else list(arch)
        self.mlp_extractor = (self.extractor_class or ScoringExtractor)(self.features_dim, vf, self.scorer)

    def _build(self, lr_schedule: Any) -> None:
        super()._build(lr_schedule)
        # the scorer's output already is the logits; its last layer starts small, as SB3's
        # action_net does (a near-uniform first policy)
        self.action_net = nn.Identity()
        scorer = self.mlp_extractor.policy_net
        assert isinstance(scorer, (PrimitiveScorer, SuccessorScorer))
        last = scorer.head[-1]
        assert isinstance(last, nn.Linear)
        nn.init.orthogonal_(last.weight, gain=0.01)
        nn.init.zeros_(last.bias)
        optimizer_class: Any = self.optimizer_class
        self.optimizer = optimizer_class(self.parameters(), lr=lr_schedule(1), **self.optimizer_kwargs)

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()
        data["scorer"] = self.scorer
        return data


# --- successor scoring: each primitive flown through the air the observation shows ------------------

#: Entries of one primitive's successor features (:class:`SuccessorFeatures`): goal ahead/right,
#: goal distance, height to the goal, height, wind ahead/right, edge cost, goal reached, ground hit,
#: the primitive's airspeed, path angle and two turn rates, then per observed thermal (nearest to the
#: successor first) present, ahead/right, distance, peak, radius.
N_SUCCESSOR_BASE = 14
N_SUCCESSOR_SLOT = 6
#: Radius [m] of the ring :meth:`SuccessorFeatures.lift_at` averages the updraft over: about the
#: turn radius of the primitives' tightest circles (1080 degrees in 30 s at 10-15 m/s: 16-24 m).
LIFT_RING_M = 20.0
#: Near-equivalent successors: end points within this [m] of each other, heights within this [m]
#: and edge costs within this [J/kg] -- e.g. a 360 against a 720 degree circle (docs/learning-to-soar.md, round twelve).
NEAR_POSITION_M = 50.0
NEAR_HEIGHT_M = 10.0
NEAR_COST = 20.0


def near_equivalent(ends: np.ndarray, costs: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """(B, A) bool: which of each row's A successors are near-equivalent to its successor ``reference``.

    :param ends: (B, A, 4) the successors' states ``[Pn, Pe, chi, h]`` [m, m, rad, m] in one frame
        per row (e.g. :meth:`SuccessorFeatures.flown`'s end points); the course plays no part.
    :param costs: (B, A) the edges' costs [J/kg].
    :param reference: (B,) a primitive per row (e.g. the demonstrated one; always near itself).
    """
    e, c, k = np.asarray(ends, np.float64), np.asarray(costs, np.float64), np.asarray(reference, np.int64)
    if e.ndim != 3 or e.shape[2] < 4 or c.shape != e.shape[:2] or k.shape != e.shape[:1]:
        raise ConfigError(
            f"near_equivalent: ends {e.shape}, costs {c.shape} and reference {k.shape} must be (B, A, 4), (B, A), (B,)"
        )
    i = np.arange(len(e))
    ref, ref_cost = e[i, k][:, None, :], c[i, k][:, None]
    return (
        (np.hypot(e[..., 0] - ref[..., 0], e[..., 1] - ref[..., 1]) <= NEAR_POSITION_M)
        & (np.abs(e[..., 3] - ref[..., 3]) <= NEAR_HEIGHT_M)
        & (np.abs(c - ref_cost) <= NEAR_COST)
    )


class SuccessorFeatures:
    """Body-frame observations (B, D) -> (B, 174, F) features of the state each primitive leads to.

    The observation's thermal slots are rebuilt into an Allen field in the aircraft's frame (each at
    its observed offset, w* chosen so that Allen's w_peak at the aircraft's height is the observed
    peak; ``zi`` of the task's scenarios), with the observed wind; the 174 primitives are flown from
    the aircraft (course 0 in that frame, the observed height and last airspeed) through the
    model's ``rollout``. Where the observed slots hold every thermal near the aircraft (random goal
    scenarios: 1-5 thermals, 3 slots) the edge costs are those the env will charge (docs/learning-to-soar.md, round
    nine: the probe's rebuilt field matched every flown edge). The features of a primitive are
    its successor's goal offset, height, wind and thermal offsets in the successor's own frame, the
    edge cost [kJ/kg], whether the edge reaches the goal region (``goal_radius``, fixed by the task
    and not in the observation) or the ground, and the primitive's own settings. The domain's
    bounds are not in the observation and play no part.

    ``estimate`` appends the reference search's cost-to-go estimates (:meth:`estimates`), ``lift``
    the updraft at and around each successor's end point (:meth:`lift_at`).

    A cache (``cache_rows`` observations, least recently used out) keeps the features of rows seen
    again: behaviour cloning and PPO's epochs score the same observations many times.
    """

    def __init__(
        self,
        layout: dict[str, Any],
        aircraft: dict[str, Any],
        duration: float,
        n_points: int,
        max_substep: float,
        zi: float,
        goal_radius: float,
        cache_rows: int = 65_536,
        estimate: bool = False,
        height_max: float = 1500.0,
        lift: bool = False,
    ) -> None:
        from collections import OrderedDict

        from soaring_env.physics.aircraft import Aircraft
        from soaring_env.primitives import PrimitiveLibrary

        self.layout = ObservationLayout.from_dict(layout)
        if self.layout.height < 0 or self.layout.airspeed < 0:
            raise ConfigError("policy='successor' needs the observation's height and airspeed entries")
        self.aircraft = Aircraft(**aircraft)
        self.library = PrimitiveLibrary(duration=duration, n_points=n_points)
        self.max_substep = float(max_substep)
        self.zi = float(zi)
        self.goal_radius = float(goal_radius)
        self.cache_rows = int(cache_rows)
        self._cache: OrderedDict[bytes, np.ndarray] = OrderedDict()
        tab = self.library.table
        full = math.radians(1080.0) / self.library.duration
        rates = tab[:, [COL_CHI_DOT_1, COL_CHI_DOT_2]] / full
        self._static = np.column_stack([tab[:, COL_AIRSPEED] / 20.0, tab[:, COL_GAMMA] * 5.0, rates])
        self._unit = WindField(zi=self.zi)
        self.estimate = bool(estimate)
        self._per_metre: dict[int, float] = {}
        self.height_max = float(height_max)
        self.n_features = N_SUCCESSOR_BASE + N_SUCCESSOR_SLOT * len(self.layout.thermals)
        if self.estimate:
            self.n_features += 2 + len(self.layout.thermals)
        self.lift = bool(lift)
        if self.lift:
            self.n_features += 2

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        x = np.ascontiguousarray(obs, dtype=np.float32)
        if x.ndim != 2 or not np.all(np.isfinite(x)):
            raise ConfigError(f"observations of shape {x.shape} must be a finite (B, D) array of body-frame rows")
        out = np.empty((x.shape[0], len(self.library), self.n_features), np.float32)
        for i, row in enumerate(x):
            key = row.tobytes()
            f = self._cache.get(key)
            if f is None:
                f = self.one(row.astype(np.float64))
                self._cache[key] = f
                if len(self._cache) > self.cache_rows:
                    self._cache.popitem(last=False)
            else:
                self._cache.move_to_end(key)
            out[i] = f
        return out

    def field(self, obs: np.ndarray) -> WindField:
        """The Allen field of the observed thermal slots, in the aircraft's frame (ahead = north)."""
        from soaring_env.physics.thermals import Thermal

        lay = self.layout
        h = float(obs[lay.height]) * lay.height_scale
        unit = self._unit.allen_profile(min(max(h, 1.0), self.zi * (1.0 - 1e-9)))["w_peak"]
        ths = []
        for present, ia, ir, ipk, _ in lay.thermals:
            peak = float(obs[ipk]) * lay.updraft_scale
            if obs[present] > 0.5 and peak > 0.0 and unit > 0.0:
                ths.append(
                    Thermal(
                        north=float(obs[ia]) * lay.position_scale,
                        east=float(obs[ir]) * lay.position_scale,
                        strength=peak / unit,
                    )
                )
        wa, wr = (float(obs[i]) * lay.wind_scale for i in lay.wind)
        return WindField(thermals=tuple(ths), zi=self.zi, wind_north=wa, wind_east=wr)

    def scenario(self, obs: np.ndarray) -> Scenario:
        """The goal-reaching scenario one body-frame observation (float64) shows, in the aircraft's
        frame (ahead = north, course 0; positions [m]): the start at the observed height, the goal
        at its observed offset (``goal_radius``), the observed thermal slots and wind
        (:meth:`field`). The domain's bounds are not in the observation: 100 km either way, the
        ceiling ``height_max``."""
        lay = self.layout
        h = float(obs[lay.height]) * lay.height_scale
        ga, gr = (float(obs[i]) * lay.position_scale for i in lay.goal[:2])
        gu = float(obs[lay.goal[2]]) * lay.height_scale
        far = 1e5
        return Scenario(
            field=self.field(obs),
            start=(0.0, 0.0, 0.0, min(max(h, 1.0), self.height_max)),
            goal=GoalRegion(north=ga, east=gr, height=max(h + gu, 1.0), radius=self.goal_radius),
            bounds=Bounds(north_min=-far, north_max=far, east_min=-far, east_max=far, height_max=self.height_max),
        )

    def flown(self, obs: np.ndarray) -> Rollout:
        """The 174 primitives flown from one body-frame observation (float64) through the field it
        shows: states ``[Pn, Pe, chi, h]`` in the aircraft's frame (ahead = north, course 0) [m, m,
        rad, m] and edge costs [J/kg]."""
        lay = self.layout
        n = len(self.library)
        h = float(obs[lay.height]) * lay.height_scale
        vp = float(obs[lay.airspeed]) * lay.speed_scale
        return rollout(
            np.tile(np.array([0.0, 0.0, 0.0, h]), (n, 1)),
            self.field(obs),
            self.aircraft,
            primitive=np.arange(n),
            library=self.library,
            airspeed_prev=np.full(n, vp if vp > 0.0 else math.nan),  # 0: no previous edge
            max_substep=self.max_substep,
        )

    def one(self, obs: np.ndarray) -> np.ndarray:
        """(174, F) features of one body-frame observation (float64)."""
        lay = self.layout
        n = len(self.library)
        h = float(obs[lay.height]) * lay.height_scale
        scale = np.array([lay.position_scale, lay.position_scale, lay.height_scale])
        goal = np.array([obs[i] for i in lay.goal]) * scale
        r = self.flown(obs)
        s = r.states
        d3 = np.sqrt((s[..., 0] - goal[0]) ** 2 + (s[..., 1] - goal[1]) ** 2 + (s[..., 3] - h - goal[2]) ** 2)
        end = s[:, -1, :]
        c, sn = np.cos(end[:, 2]), np.sin(end[:, 2])

        def frame(dn: np.ndarray, de: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            # an offset (north, east) of the aircraft's frame into the successor's (ahead, right)
            return dn * c + de * sn, -dn * sn + de * c

        ga, gr = frame(goal[0] - end[:, 0], goal[1] - end[:, 1])
        wind = [float(obs[i]) * lay.wind_scale for i in lay.wind]
        wa, wr = frame(np.full(n, wind[0]), np.full(n, wind[1]))
        km = 1000.0
        base = [
            ga / km, gr / km, np.hypot(ga, gr) / km, (h + goal[2] - end[:, 3]) / km, end[:, 3] / km, wa / 10.0,
            wr / 10.0, r.cost / km, (d3 <= self.goal_radius).any(axis=1), (s[..., 3] <= 0.0).any(axis=1),
        ]  # fmt: skip
        slots = []
        for present, ia, ir, ipk, irad in lay.thermals:
            on = float(obs[present] > 0.5)
            ta, tr = frame(obs[ia] * lay.position_scale - end[:, 0], obs[ir] * lay.position_scale - end[:, 1])
            dist = np.hypot(ta, tr)
            peak = obs[ipk] * lay.updraft_scale / 5.0 * on
            radius = obs[irad] * lay.position_scale / km * on
            far = np.where(on > 0, dist, 1e4) / km
            slots.append(
                np.column_stack([np.full(n, on), ta / km * on, tr / km * on, far, np.full(n, peak), np.full(n, radius)])
            )
        f = np.column_stack([*base, self._static])
        if slots:
            st = np.stack(slots, axis=1)  # (174, K, 6): nearest to the successor first, empty slots last
            order = np.argsort(st[:, :, 3], axis=1, kind="stable")
            st = np.take_along_axis(st, order[..., None], axis=1)
            st[:, :, 3] = np.minimum(st[:, :, 3], 10.0) * st[:, :, 0]
            f = np.column_stack([f, st.reshape(n, -1)])
        if self.estimate:
            f = np.column_stack([f, self.estimates(obs, end, r.cost) / km])
        if self.lift:
            f = np.column_stack([f, self.lift_at(obs, end) / lay.updraft_scale])
        return f.astype(np.float32)

    def lift_at(self, obs: np.ndarray, end: np.ndarray) -> np.ndarray:
        """(174, 2) the updraft [m/s] the field the observation shows has at each successor ``end``
        (rows ``[Pn, Pe, chi, h]`` in the aircraft's frame): at the end point, and the mean over a
        ring of ``LIFT_RING_M`` around it at the same height (what a tight circle there would
        meet). Where the next edge can climb, before the scorer has to infer it from the
        thermal's offset, peak and radius (``scorer_lift``)."""
        field = self.field(obs)
        ang = np.linspace(0.0, 2.0 * math.pi, 8, endpoint=False)
        n = end[:, 0:1] + LIFT_RING_M * np.cos(ang)[None, :]
        e = end[:, 1:2] + LIFT_RING_M * np.sin(ang)[None, :]
        h = np.maximum(end[:, 3:4], 0.0)
        centre = field.updraft(end[:, 0], end[:, 1], np.maximum(end[:, 3], 0.0))
        ring = field.updraft(n, e, np.broadcast_to(h, n.shape)).mean(axis=1)
        return np.column_stack([centre, ring])

    def estimates(self, obs: np.ndarray, end: np.ndarray, cost: np.ndarray) -> np.ndarray:
        """(174, 2 + K) cost-to-go estimates [J/kg] of the successors ``end`` (rows ``[Pn, Pe, chi,
        h]`` in the aircraft's frame) of edges costing ``cost``: the reference search's ranking
        heuristic (:func:`baselines.reference.beam.cost_to_go_estimate`: straight in, or a detour
        through a thermal climbed to the goal's top, in the field the observation shows), edge cost
        plus it (the search's rank of the child), and each observed thermal's detour estimate,
        cheapest first (the straight estimate where there are fewer climbable thermals). A thermal's
        climb value is taken from its centre on one course (the search: 0 and 20 m off, four
        courses), about 10 ms an observation instead of 60.

        The beam search that made the demonstrations keeps the children of best rank, so its first
        decisions follow this heuristic; a scorer given it need not learn the min over thermals of
        distances and climb values from a few thousand plans."""
        from baselines.reference.beam import cost_to_go_estimate, still_air_cost_per_metre, thermal_values
        from soaring_env.model import SoaringModel

        h = float(obs[self.layout.height]) * self.layout.height_scale
        scen = self.scenario(obs)
        model = SoaringModel(scenario=scen, aircraft=self.aircraft, library=self.library, max_substep=self.max_substep)
        ctrls = np.arange(len(self.library), dtype=np.float64)[:, None]
        hb = round(h / 10.0)  # the still-air cost per metre barely changes with height: one per 10 m band
        per_metre = self._per_metre.get(hb)
        if per_metre is None:
            band = (0.0, 0.0, 0.0, min(max(10.0 * hb, 1.0), self.height_max))
            at = dataclasses.replace(model, scenario=scen.replace(start=band))
            per_metre = self._per_metre[hb] = still_air_cost_per_metre(at, ctrls)
        lift = thermal_values(model, ctrls, offsets=(0.0,), n_courses=1)  # the search's 8 starts: 8x the time
        g = scen.require_goal()
        g_top = g.height + g.radius
        d_goal = np.maximum(np.hypot(end[:, 0] - g.north, end[:, 1] - g.east) - g.radius, 0.0)
        est = cost_to_go_estimate(end, d_goal, per_metre, g_top, lift, (g.north, g.east))
        straight = per_metre * d_goal
        k = len(self.layout.thermals)
        detours = np.tile(straight[:, None], (1, max(k, len(lift))))
        for j, row in enumerate(lift):
            detours[:, j] = cost_to_go_estimate(end, d_goal, per_metre, g_top, row[None, :], (g.north, g.east))
        detours = np.sort(detours, axis=1)[:, :k]
        return np.column_stack([est, cost + est, detours])


def successor_kwargs(env: Any) -> dict[str, Any]:
    """The constructor arguments of :class:`SuccessorScorer` for ``env`` (a raw single env of the
    goal-reaching primitive task): observation layout, aircraft, primitives, integration, the
    scenario family's ``zi`` and goal radius."""
    u = env.unwrapped if hasattr(env, "unwrapped") else env
    sc = u.scenario
    lib = u.library
    return {
        "layout": ObservationLayout.of(u.observation_names, u.config).to_dict(),
        "aircraft": dataclasses.asdict(u.model.aircraft),
        "duration": float(lib.duration),
        "n_points": int(lib.n_points),
        "max_substep": float(u.model.max_substep),
        "zi": float(sc.field.zi),
        "goal_radius": float(sc.require_goal().radius),
        "height_max": float(sc.bounds.height_max),
    }


def accepted_successors(
    features: SuccessorFeatures, observations: np.ndarray, actions: np.ndarray, progress: bool = False
) -> np.ndarray:
    """(N, 174) bool: the primitives whose successor is near-equivalent (:func:`near_equivalent`)
    to that of each row's primitive ``actions``, the 174 edges flown from each body-frame
    observation through the field it shows (:meth:`SuccessorFeatures.flown`; about 4 ms a row) --
    the labels of a cloning that does not ask the policy to tell a 360 from a 720 degree circle
    (``demo_equivalents``), and the ``near-equivalent`` share of ``scripts/diagnose_clone.py fit``.
    """
    from baselines._runs import progress_bar

    obs = np.asarray(observations, np.float64)
    acts = np.asarray(actions)
    n_prim = len(features.library)
    if obs.ndim != 2 or acts.shape != (len(obs),) or not np.issubdtype(acts.dtype, np.integer):
        raise ConfigError(
            f"accepted_successors: observations {obs.shape} and actions {acts.shape} ({acts.dtype}) must be "
            "(N, D) rows and N integer primitive indices"
        )
    if acts.size and (acts.min() < 0 or acts.max() >= n_prim):
        raise ConfigError(
            f"accepted_successors: actions must lie in 0 ... {n_prim - 1}; got {acts.min()} ... {acts.max()}"
        )
    out = np.empty((len(obs), n_prim), bool)
    bar = progress_bar(len(obs), 0, progress, "near-equivalent successors", "row")
    for k, (row, a) in enumerate(zip(obs, acts.astype(np.int64), strict=True)):
        r = features.flown(row)
        out[k] = near_equivalent(r.states[None, :, -1, :], r.cost[None], np.array([a]))[0]
        if bar is not None:
            bar.update(1)
    if bar is not None:
        bar.close()
    return out


class SuccessorScorer(nn.Module):
    """Body-frame observations (B, D) -> logits (B, 174): one MLP over each primitive's successor
    features (:class:`SuccessorFeatures`), shared by all primitives.

    A policy over what each primitive *leads to* rather than over the observation: the cloning
    loss then compares the demonstrated successor with the 173 others the same observation
    offers, so states the plans never visit are scored too (docs/learning-to-soar.md, round nine).
    """

    def __init__(
        self, obs_dim: int, hidden: Sequence[int] = (128, 128), skip: bool = False, members: int = 1, **features: Any
    ) -> None:
        super().__init__()
        if isinstance(members, bool) or not isinstance(members, int) or members < 1:
            raise ConfigError(f"members={members!r} must be an integer >= 1 (the scorers whose logits are averaged)")
        self.features = SuccessorFeatures(**features)
        sizes = [self.features.n_features, *(int(h) for h in hidden)]

        def mlp() -> nn.Sequential:
            layers: list[Any] = []
            for a, b in itertools.pairwise(sizes):
                layers += [nn.Linear(a, b), nn.Tanh()]
            layers.append(nn.Linear(sizes[-1], 1))
            return nn.Sequential(*layers)

        self.head = mlp()
        # a linear path beside the MLP (``scorer_skip``): the parts of a successor's worth that are
        # linear in its features (edge cost, height) exactly, where the tanh MLP is only near them.
        # Zeroed where a policy without it is loaded into it (``init_from``).
        self.skip: nn.Linear | None = nn.Linear(sizes[0], 1) if skip else None
        # further members of an ensemble (``ensemble_of``): the same scorer trained apart; the policy's
        # logits are the mean of all members' (one feature computation serves them all)
        self.more = nn.ModuleList(mlp() for _ in range(members - 1))
        self.more_skip = nn.ModuleList(nn.Linear(sizes[0], 1) for _ in range(members - 1) if skip)

    @property
    def members(self) -> int:
        """How many scorers' logits are averaged (1: a single scorer)."""
        return 1 + len(self.more)

    def forward(self, obs: Any) -> Any:
        f = torch.as_tensor(self.features(obs.detach().cpu().numpy()), dtype=obs.dtype)
        out = self.head(f)
        if self.skip is not None:
            out = out + self.skip(f)
        for k, head in enumerate(self.more):
            out = out + head(f)
            if self.skip is not None:
                out = out + self.more_skip[k](f)
        return (out / self.members).squeeze(-1)


class SuccessorExtractor(MlpExtractor):
    """SB3's extractor with the actor replaced by :class:`SuccessorScorer` (latent = logits)."""

    def __init__(self, feature_dim: int, vf_arch: Sequence[int], scorer: dict[str, Any]) -> None:
        super().__init__(feature_dim, net_arch={"pi": [], "vf": list(vf_arch)}, activation_fn=nn.Tanh)
        net = SuccessorScorer(feature_dim, **scorer)
        self.policy_net = net  # type: ignore[assignment]
        self.latent_dim_pi = len(net.features.library)


class SuccessorPolicy(PrimitiveScoringPolicy):
    """ActorCriticPolicy over ``Discrete(174)`` whose logits come from :class:`SuccessorScorer`.

    :param scorer: :func:`successor_kwargs` of the env (plus optionally ``hidden``).
    """

    extractor_class = SuccessorExtractor
