"""The model API shared by the environments and the planners.

:class:`SoaringModel` bundles a scenario, the aircraft, the primitive library and the integration
settings, and rolls out any primitive or control from any batch of states without touching an
environment's state. ``env.step`` calls exactly these methods, so a plan made with the model
replays through the env bit for bit.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from soaring_env._validation import ConfigError, check_array_finite, check_positive, check_range
from soaring_env.physics.aircraft import Aircraft
from soaring_env.primitives import DEFAULT_MAX_SUBSTEP, N_PRIMITIVES, PrimitiveLibrary, Rollout, rollout
from soaring_env.scenario import Scenario, paper_scenario

#: Edge outcome codes returned by :meth:`SoaringModel.classify`.
FLYING, GOAL, CRASH, OUT_OF_BOUNDS = 0, 1, 2, 3
OUTCOMES = ("flying", "goal", "crash", "out_of_bounds")


@dataclass(frozen=True)
class SoaringModel:
    """Scenario + aircraft + primitive library: everything needed to propagate and score edges.

    :param scenario: thermal field, wind, start, goal and domain.
    :param aircraft: aircraft and thrust model.
    :param library: the 174 primitives (Ts, N).
    :param max_substep: largest integration substep near thermals [s].
    :param max_bank_deg: bank-angle limit [deg] used by action masks and planners (the tightest
        spiral needs 52 deg at Ts = 30 s).
    """

    scenario: Scenario = dataclasses.field(default_factory=paper_scenario)
    aircraft: Aircraft = dataclasses.field(default_factory=Aircraft)
    library: PrimitiveLibrary = dataclasses.field(default_factory=PrimitiveLibrary)
    max_substep: float = DEFAULT_MAX_SUBSTEP
    max_bank_deg: float = 60.0

    def __post_init__(self) -> None:
        check_positive("max_substep", self.max_substep)
        check_range("max_bank_deg", self.max_bank_deg, 0.0, 90.0, low_open=True, high_open=True)

    # --- propagation -----------------------------------------------------------------------
    def rollout_primitive(self, states, primitive, *, t0=0.0, airspeed_prev=None) -> Rollout:
        """Fly primitive(s) ``primitive`` (int or (B,)) for Ts from ``states`` ((4,) or (B, 4))."""
        return rollout(
            states,
            self.scenario.field,
            self.aircraft,
            primitive=primitive,
            library=self.library,
            t0=t0,
            airspeed_prev=airspeed_prev,
            max_substep=self.max_substep,
        )

    def rollout_control(self, states, control, *, duration=None, t0=0.0, airspeed_prev=None) -> Rollout:
        """Hold physical control(s) ``(v_a [m/s], chi_dot [rad/s], gamma [rad])`` for ``duration``
        (default Ts) from ``states``."""
        return rollout(
            states,
            self.scenario.field,
            self.aircraft,
            control=control,
            library=self.library,
            duration=duration,
            t0=t0,
            airspeed_prev=airspeed_prev,
            max_substep=self.max_substep,
        )

    # --- the continuous action envelope --------------------------------------------------------
    @property
    def control_low(self) -> np.ndarray:
        """Lower corner of the continuous envelope (v_a [m/s], chi_dot [rad/s], gamma [rad])."""
        return self.library.control_bounds()[0]

    @property
    def control_high(self) -> np.ndarray:
        return self.library.control_bounds()[1]

    def action_to_control(self, action) -> np.ndarray:
        """Map normalized actions in [-1, 1]^3 affinely onto the physical envelope."""
        a = np.asarray(action, dtype=np.float64)
        if a.shape[-1:] != (3,):
            raise ConfigError(f"action has shape {a.shape}; expected (..., 3) in [-1, 1]")
        check_array_finite("action", a)
        if np.any(np.abs(a) > 1.0):
            raise ConfigError(f"action {a.tolist()!r} is outside [-1, 1]^3")
        lo, hi = self.library.control_bounds()
        return lo + 0.5 * (a + 1.0) * (hi - lo)

    def control_to_action(self, control) -> np.ndarray:
        """Inverse of :meth:`action_to_control`."""
        lo, hi = self.library.control_bounds()
        return 2.0 * (np.asarray(control, dtype=np.float64) - lo) / (hi - lo) - 1.0

    # --- outcomes ------------------------------------------------------------------------------
    def classify(self, result: Rollout) -> tuple[np.ndarray, np.ndarray]:
        """First event along each edge: (outcome code (B,), index of the output point (B,)).

        An edge reaches the goal if one of its N points lies in the goal region before any point
        hits the ground or leaves the domain; ``FLYING`` edges have index N - 1.
        """
        s = result.states
        sc = self.scenario
        in_goal = sc.goal.contains(s[..., 0], s[..., 1], s[..., 3])
        crash = s[..., 3] <= 0.0
        out = ~sc.bounds.contains(s[..., 0], s[..., 1], s[..., 3]) & ~crash
        n = s.shape[1]
        big = n + 1

        def first(mask: np.ndarray) -> np.ndarray:
            return np.where(mask.any(axis=1), mask.argmax(axis=1), big)

        kg, kc, ko = first(in_goal), first(crash), first(out)
        k = np.minimum(np.minimum(kg, kc), ko)
        code = np.full(s.shape[0], FLYING)
        code[k == ko] = OUT_OF_BOUNDS
        code[k == kc] = CRASH
        code[k == kg] = GOAL  # goal wins ties: the point is inside the region
        code[k == big] = FLYING
        return code, np.where(k == big, n - 1, k)

    def bank_ok(self) -> np.ndarray:
        """(174,) bool: primitives whose coordinated-turn bank stays within ``max_bank_deg``."""
        t = self.library.table
        bank = np.arctan(t[:, 1:2] * np.abs(t[:, 3:5]) / 9.80665).max(axis=1)
        return bank <= math.radians(self.max_bank_deg) + 1e-12

    @property
    def n_primitives(self) -> int:
        return N_PRIMITIVES
