"""Control samplers for SST's Monte-Carlo propagation (generic: they know nothing about aircraft).

* :class:`IndexSampler` -- uniform over a finite set of control indices (the motion primitives),
  optionally only over an allowed subset (e.g. the primitives within the bank limit).
* :class:`BoxSampler` -- uniform over the normalized box [-1, 1]^d (the continuous action space),
  rounded to float32 so that the sampled values are exactly what a ``Box(float32)`` action space
  holds: a plan replays bit for bit through an env that stores actions as float32.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from baselines.sst.core import SSTError


@dataclass(frozen=True)
class IndexSampler:
    """Uniform over ``0..n-1`` (or over the indices where ``allowed`` is True).

    :param n: number of discrete controls.
    :param allowed: optional (n,) bool mask of the indices that may be drawn.
    """

    n: int
    allowed: np.ndarray | None = None
    choices: np.ndarray = field(init=False, repr=False, compare=False)
    control_dim: int = field(default=1, init=False)

    def __post_init__(self) -> None:
        if isinstance(self.n, bool) or not isinstance(self.n, (int, np.integer)) or self.n < 1:
            raise SSTError(f"n={self.n!r} must be an integer >= 1")
        if self.allowed is None:
            choices = np.arange(self.n)
        else:
            mask = np.asarray(self.allowed, dtype=bool)
            if mask.shape != (self.n,):
                raise SSTError(f"allowed has shape {mask.shape}; expected ({self.n},)")
            choices = np.flatnonzero(mask)
            if len(choices) == 0:
                raise SSTError("allowed masks out every control; at least one must be allowed")
        object.__setattr__(self, "choices", choices)

    def sample(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """(n, 1) float array of control indices."""
        return self.choices[rng.integers(0, len(self.choices), size=n)].astype(np.float64)[:, None]


@dataclass(frozen=True)
class BoxSampler:
    """Uniform over [-1, 1]^dim, rounded to float32 values.

    :param dim: number of control components.
    """

    dim: int

    def __post_init__(self) -> None:
        if isinstance(self.dim, bool) or not isinstance(self.dim, (int, np.integer)) or self.dim < 1:
            raise SSTError(f"dim={self.dim!r} must be an integer >= 1")

    @property
    def control_dim(self) -> int:
        return self.dim

    def sample(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """(n, dim) float64 array of float32-representable values in [-1, 1]."""
        return rng.uniform(-1.0, 1.0, size=(n, self.dim)).astype(np.float32).astype(np.float64)
