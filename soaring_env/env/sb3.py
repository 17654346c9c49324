"""Stable-Baselines3 ``VecEnv`` over the natively batched soaring env (needs stable-baselines3).

SB3 does not accept gymnasium's ``VectorEnv``; :class:`SoaringSB3VecEnv` adapts
:class:`~soaring_env.env.vector.SoaringVectorEnv` to SB3's conventions: same-step autoreset,
``info["terminal_observation"]`` (the last observation of a finished episode, before the reset),
``info["TimeLimit.truncated"]`` (every step: truncated and not terminated), float32 rewards, bool dones.
Transitions equal those of ``DummyVecEnv([lambda: gym.make(id)] * n)`` seeded alike, for every
registered id (``env_id``: goal reaching, thermal climb, cross-country).

Example::

    from sb3_contrib import MaskablePPO
    from soaring_env.env.sb3 import SoaringSB3VecEnv
    venv = SoaringSB3VecEnv(num_envs=16)  # soaring/Soaring-v0
    model = MaskablePPO("MlpPolicy", venv).learn(100_000)
    climb = SoaringSB3VecEnv(num_envs=16, env_id="soaring/ThermalClimbContinuous-v0")
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvIndices, VecEnvStepReturn

from soaring_env._validation import ConfigError
from soaring_env.env.config import SoaringEnvConfig
from soaring_env.env.vector import SoaringContinuousVectorEnv, SoaringVectorEnv

#: per-env info keys passed on to SB3 (kept short: building B dicts per step is the adapter's cost)
INFO_KEYS = ("energy_spent", "height", "outcome", "is_success")
#: the same, for tasks with a battery (cross-country)
BATTERY_INFO_KEYS = (*INFO_KEYS, "battery_left")


def vector_env_class(env_id: str) -> type[SoaringVectorEnv] | type[SoaringContinuousVectorEnv]:
    """The natively batched class registered as ``env_id``'s ``vector_entry_point``.

    :raises ConfigError: ``env_id`` is not a registered soaring id.
    """
    from gymnasium.envs.registration import load_env_creator

    import soaring_env  # noqa: F401  (registers the ids)

    if not isinstance(env_id, str):
        raise ConfigError(f"env_id={env_id!r} has type {type(env_id).__name__}; a registered soaring id is required")
    bare = env_id.split(":", 1)[-1]
    spec = gym.registry.get(bare)
    entry = None if spec is None else spec.vector_entry_point
    cls = load_env_creator(entry) if isinstance(entry, str) else entry
    if not (isinstance(cls, type) and issubclass(cls, (SoaringVectorEnv, SoaringContinuousVectorEnv))):
        from soaring_env.env import ENV_IDS

        raise ConfigError(f"env_id={env_id!r} is not a soaring env id; allowed: {', '.join(ENV_IDS)}")
    return cls


class SoaringSB3VecEnv(VecEnv):
    """``num_envs`` soaring envs as one SB3 ``VecEnv`` (numpy-batched, one rollout call per step).

    :param num_envs: number of envs.
    :param continuous: ``soaring/SoaringContinuous-v0`` dynamics (Box actions) instead of the
        174 primitives (ignored when ``env_id`` is given).
    :param max_episode_steps: step limit; ``"default"``: the id's (40 for goal reaching, none for
        the tasks, which truncate by their ``time_limit``).
    :param config: the id's config (or dict) shared by all envs.
    :param env_id: any registered soaring id (default: from ``continuous``).
    :param overrides: single config fields.
    """

    def __init__(
        self,
        num_envs: int = 1,
        continuous: bool = False,
        max_episode_steps: int | str | None = "default",
        config: SoaringEnvConfig | dict[str, Any] | None = None,
        env_id: str | None = None,
        **overrides: Any,
    ) -> None:
        if env_id is None:
            cls: Any = SoaringContinuousVectorEnv if continuous else SoaringVectorEnv
        else:
            cls = vector_env_class(env_id)
        self.venv: Any = cls(
            num_envs=num_envs,
            max_episode_steps=max_episode_steps,
            config=config,
            autoreset_mode=AutoresetMode.SAME_STEP,
            **overrides,
        )
        super().__init__(num_envs, self.venv.single_observation_space, self.venv.single_action_space)
        self._actions: np.ndarray | None = None
        self._info_keys = BATTERY_INFO_KEYS if self.venv.template.has_battery else INFO_KEYS

    # --- the VecEnv protocol -------------------------------------------------------------------------
    def reset(self) -> np.ndarray:
        """Reset all envs with the seeds / options set by ``seed()`` / ``set_options()`` (used once)."""
        seeds = self._seeds
        opts = self._options[0] if self._options and self._options[0] else None
        if any(o != self._options[0] for o in self._options):
            raise ConfigError("per-env reset options are not supported by SoaringSB3VecEnv; pass one dict")
        seed: Any = None if all(s is None for s in seeds) else seeds
        obs, _ = self.venv.reset(seed=seed, options=opts)
        self._reset_seeds()
        self._reset_options()
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self) -> VecEnvStepReturn:
        if self._actions is None:
            raise RuntimeError("step_wait() called without step_async()")
        obs, reward, terminated, truncated, info = self.venv.step(self._actions)
        self._actions = None
        dones = terminated | truncated
        n = self.num_envs
        info_keys = self._info_keys
        keys = (*info_keys, "TimeLimit.truncated")
        cols = [info[k].tolist() for k in info_keys]
        cols.append((truncated & ~terminated).tolist())
        infos: list[dict[str, Any]] = [dict(zip(keys, row, strict=True)) for row in zip(*cols, strict=True)]
        if dones.any():
            final_obs = info["final_obs"]
            final = info["final_info"]
            for i in np.flatnonzero(dones).tolist():
                d = infos[i]
                for k in info_keys:
                    d[k] = final[k][i].item() if isinstance(final[k][i], np.generic) else final[k][i]
                d["terminal_observation"] = final_obs[i]
        assert len(infos) == n
        return obs, reward.astype(np.float32), dones, infos

    def close(self) -> None:
        self.venv.close()

    def action_masks(self) -> np.ndarray:
        """(num_envs, 174) bool masks for sb3-contrib's MaskablePPO."""
        return self.venv.action_masks()

    def get_images(self) -> Sequence[np.ndarray | None]:
        return [None] * self.num_envs

    def _indices(self, indices: VecEnvIndices) -> list[int]:
        if indices is None:
            return list(range(self.num_envs))
        if isinstance(indices, int):
            return [indices]
        return list(indices if isinstance(indices, Iterable) else [indices])

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        """Per-env values of batched attributes (``states``, ``times``, ``scenarios``, ...)."""
        idx = self._indices(indices)
        if attr_name == "render_mode":
            return [None] * len(idx)
        value = getattr(self.venv, attr_name)
        if isinstance(value, (np.ndarray, list)) and len(value) == self.num_envs:
            return [value[i] for i in idx]
        return [value] * len(idx)

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        raise AttributeError(f"SoaringSB3VecEnv does not support setting {attr_name!r} per env")

    def env_method(self, method_name: str, *method_args: Any, indices: VecEnvIndices = None, **kw: Any) -> list[Any]:
        """Only ``action_masks`` is supported (what sb3-contrib's MaskablePPO calls)."""
        idx = self._indices(indices)
        if method_name == "action_masks":
            masks = self.venv.action_masks()
            return [masks[i] for i in idx]
        raise AttributeError(f"SoaringSB3VecEnv supports env_method('action_masks') only, not {method_name!r}")

    def has_attr(self, attr_name: str) -> bool:
        return hasattr(self.venv, attr_name)

    def env_is_wrapped(self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None) -> list[bool]:
        return [False] * len(self._indices(indices))
