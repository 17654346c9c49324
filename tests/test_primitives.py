"""The 174-primitive library and the rollout kernel: table contents and order, still-air geometry
against closed forms, integration accuracy through thermals, property-based checks (hypothesis) of
finiteness, batching and the horizontal closed form, and input validation."""

from __future__ import annotations

import hashlib
import math
from collections.abc import Callable

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from soaring_env import N_PRIMITIVES, Aircraft, ConfigError, PrimitiveLibrary, Thermal, WindField, rollout
from soaring_env.physics.atmosphere import G
from soaring_env.primitives import Propagator, pack_fields

FindPrimitive = Callable[[PrimitiveLibrary, str, float, float, float], int]

STRAIGHT, CURVE, SPIRAL, SPLINE = 0, 1, 2, 3
SPEEDS = (10.0, 20.0)
GAMMAS_DEG = (-45.0, -15.0, 0.0, 15.0, 45.0)

#: sha256 of the table rendered as "family,v_a,gamma_deg,turn1_deg,turn2_deg" lines (turn = rate * Ts),
#: rounded to 1e-6 deg so that the checksum pins the order and values, not the last bit.
TABLE_SHA256 = "ec685f25abff5ccbe0dfb5e063d36cf5d7595ca201ccae504b030ccea71fb931"


def table_lines(lib: PrimitiveLibrary) -> list[str]:
    def f(x: float) -> str:
        return f"{round(x, 6) + 0.0:+.6f}"

    ts = lib.duration
    return [
        f"{int(r[0])},{r[1]:g},{f(math.degrees(r[2]))},{f(math.degrees(r[3]) * ts)},{f(math.degrees(r[4]) * ts)}"
        for r in lib.table
    ]


def circle_path(start: np.ndarray, u: float, rate: float, t: np.ndarray, wind: tuple[float, float]) -> np.ndarray:
    """Independent closed form of the horizontal path, (len(t), 3): [Pn, Pe, unwrapped chi].

    Chord form ``p(t) = p0 + u t sinc(rate t / 2) (cos, sin)(chi0 + rate t / 2) + w t``: exact for
    constant controls and numerically stable for any turn rate, including 0 (the kernel uses the
    centre-offset form ``(u / rate)(sin(chi) - sin(chi0))`` instead).
    """
    n0, e0, chi0 = float(start[0]), float(start[1]), float(start[2])
    half = 0.5 * rate * t
    chord = u * t * np.sinc(half / math.pi)  # np.sinc(x) = sin(pi x) / (pi x)
    mid = chi0 + half
    return np.stack(
        [n0 + chord * np.cos(mid) + wind[0] * t, e0 + chord * np.sin(mid) + wind[1] * t, chi0 + 2 * half], 1
    )


def expected_horizontal(
    start: np.ndarray, v: float, gamma: float, rate1: float, rate2: float, dur: float, n: int, wind: tuple[float, float]
) -> np.ndarray:
    """Closed-form [Pn, Pe, chi] at the N output times, rate1 up to output point N // 2 then rate2."""
    u = v * math.cos(gamma)
    times = dur * np.arange(1, n + 1) / n
    k = n // 2
    t_switch = k * dur / n
    first = circle_path(start, u, rate1, np.minimum(times, t_switch), wind)
    mid = circle_path(start, u, rate1, np.array([t_switch]), wind)[0]
    second = circle_path(mid, u, rate2, np.maximum(times - t_switch, 0.0), wind)
    return np.where((times <= t_switch + 1e-12)[:, None], first, second)


def angle_error(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    d = np.asarray(a) - np.asarray(b)
    return np.abs((d + math.pi) % (2 * math.pi) - math.pi)


# --------------------------------------------------------------------------------------------
# The table
# --------------------------------------------------------------------------------------------
def test_family_counts(library: PrimitiveLibrary) -> None:
    fam = library.family
    assert len(library) == N_PRIMITIVES == 174 == library.table.shape[0]
    assert np.bincount(fam, minlength=4).tolist() == [10, 60, 80, 24]
    # families are contiguous blocks in the documented order
    assert fam.tolist() == [STRAIGHT] * 10 + [CURVE] * 60 + [SPIRAL] * 80 + [SPLINE] * 24


def test_family_contents_match_paper(library: PrimitiveLibrary) -> None:
    t = library.table
    ts = library.duration
    turn1 = np.round(np.degrees(t[:, 3]) * ts, 9)
    turn2 = np.round(np.degrees(t[:, 4]) * ts, 9)
    gam = np.round(np.degrees(t[:, 2]), 9)
    fam = library.family
    assert set(t[:, 1]) == set(SPEEDS)
    expected_turns = {
        STRAIGHT: {0.0},
        CURVE: {-90.0, -60.0, -30.0, 30.0, 60.0, 90.0},
        SPIRAL: {-1080.0, -720.0, -360.0, -180.0, 180.0, 360.0, 720.0, 1080.0},
        SPLINE: {-90.0, -60.0, 60.0, 90.0},
    }
    for f, turns in expected_turns.items():
        sel = fam == f
        assert set(turn1[sel]) == turns
        combos = {(v, a, b, g) for v, a, b, g in zip(t[sel, 1], turn1[sel], turn2[sel], gam[sel], strict=True)}
        assert len(combos) == sel.sum(), f"family {f} has duplicate rows"
        if f == SPLINE:
            assert set(gam[sel]) == {0.0}
            assert set(turn2[sel]) == turns
            assert len(combos) == 2 * 4 * 3  # ordered pairs of different rates
        else:
            assert set(gam[sel]) == set(GAMMAS_DEG)
            np.testing.assert_array_equal(turn1[sel], turn2[sel])
            assert len(combos) == 2 * len(turns) * 5


def test_spline_halves_differ(library: PrimitiveLibrary) -> None:
    spl = library.table[library.family == SPLINE]
    assert spl.shape[0] == 24
    assert np.all(spl[:, 3] != spl[:, 4])
    assert np.all(spl[:, 2] == 0.0)


def test_order_is_sorted_within_families(library: PrimitiveLibrary) -> None:
    """Documented order: family, then airspeed, then turn rate (splines: ordered pair), then gamma."""
    t = library.table
    key = np.stack([t[:, 0], t[:, 1], t[:, 3], t[:, 4], t[:, 2]], 1)
    order = np.lexsort(key.T[::-1])
    np.testing.assert_array_equal(order, np.arange(N_PRIMITIVES))


@pytest.mark.parametrize(
    ("index", "row"),
    [
        (0, "0,10,-45.000000,+0.000000,+0.000000"),  # first straight
        (7, "0,20,+0.000000,+0.000000,+0.000000"),  # level straight at 20 m/s
        (9, "0,20,+45.000000,+0.000000,+0.000000"),  # last straight
        (10, "1,10,-45.000000,-90.000000,-90.000000"),  # first curve
        (69, "1,20,+45.000000,+90.000000,+90.000000"),  # last curve
        (70, "2,10,-45.000000,-1080.000000,-1080.000000"),  # first spiral
        (147, "2,20,+0.000000,+1080.000000,+1080.000000"),  # tightest level spiral at 20 m/s
        (149, "2,20,+45.000000,+1080.000000,+1080.000000"),  # last spiral
        (150, "3,10,+0.000000,-90.000000,-60.000000"),  # first spline
        (173, "3,20,+0.000000,+90.000000,+60.000000"),  # last spline
    ],
)
def test_pinned_rows(library: PrimitiveLibrary, index: int, row: str) -> None:
    assert table_lines(library)[index] == row
    assert library.check_index(index) == index


def test_whole_table_checksum(library: PrimitiveLibrary) -> None:
    digest = hashlib.sha256("\n".join(table_lines(library)).encode()).hexdigest()
    assert digest == TABLE_SHA256, "the primitive table changed (order or values): the action index moved"


def test_table_is_read_only(library: PrimitiveLibrary) -> None:
    with pytest.raises(ValueError):
        library.table[0, 1] = 99.0


def test_describe(library: PrimitiveLibrary) -> None:
    assert library.describe(0) == "straight v_a=10 m/s gamma=-45 deg turn=+0 deg"
    assert library.describe(70).startswith("spiral v_a=10 m/s gamma=-45 deg turn=-1080 deg")
    assert library.describe(150).endswith("turn=-90 deg then -60 deg")


@pytest.mark.parametrize("bad", [-1, 174, 1000, 1.0, True, "3", None])
def test_check_index_rejects(library: PrimitiveLibrary, bad: object) -> None:
    with pytest.raises(ConfigError, match="primitive index"):
        library.check_index(bad)


def test_control_bounds(library: PrimitiveLibrary) -> None:
    lo, hi = library.control_bounds()
    np.testing.assert_allclose(lo, [10.0, -math.radians(1080) / 30.0, -math.radians(45)], rtol=1e-15)
    np.testing.assert_allclose(hi, [20.0, math.radians(1080) / 30.0, math.radians(45)], rtol=1e-15)
    t = library.table
    assert np.all((t[:, 1] >= lo[0]) & (t[:, 1] <= hi[0]))
    assert np.all(np.abs(t[:, 3:5]) <= hi[1] + 1e-15)
    assert np.all(np.abs(t[:, 2]) <= hi[2] + 1e-15)


def test_ts_and_n_are_parameters(library: PrimitiveLibrary, still_air: WindField, aircraft: Aircraft) -> None:
    lib = PrimitiveLibrary(20.0, 40)
    assert (lib.duration, lib.n_points) == (20.0, 40)
    # rates scale with 1 / Ts; speeds, path angles and order are unchanged
    np.testing.assert_allclose(lib.table[:, 3:5], library.table[:, 3:5] * 30.0 / 20.0, rtol=1e-14, atol=0)
    np.testing.assert_array_equal(lib.table[:, :3], library.table[:, :3])
    assert table_lines(lib) == table_lines(library)  # turns per primitive in degrees are the same
    lo, hi = lib.control_bounds()
    assert lo[1] == -hi[1]
    assert hi[1] == pytest.approx(math.radians(1080) / 20.0)
    r = rollout(np.array([0.0, 0.0, 0.0, 500.0]), still_air, aircraft, primitive=np.arange(174), library=lib)
    assert r.states.shape == (174, 40, 4)
    np.testing.assert_allclose(r.times, 20.0 * np.arange(1, 41) / 40, rtol=1e-15)
    np.testing.assert_array_equal(r.duration, np.full(174, 20.0))
    # a 360 deg spiral still closes in 20 s
    i = 70 + 5 * 2 + 2  # 10 m/s, -360 deg, level (order pinned above)
    assert np.hypot(*r.final[i, :2]) < 1e-6
    # and the default library gives 30 points
    assert rollout([0.0, 0.0, 0.0, 500.0], still_air, aircraft, primitive=0).states.shape == (1, 30, 4)


# --------------------------------------------------------------------------------------------
# Still-air geometry against closed forms
# --------------------------------------------------------------------------------------------
START = np.array([120.0, -340.0, 0.7, 800.0])


@pytest.mark.parametrize("turn", [-1080.0, -720.0, -360.0, 360.0, 720.0, 1080.0])
@pytest.mark.parametrize("v", SPEEDS)
@pytest.mark.parametrize("gamma", GAMMAS_DEG)
def test_full_circle_spirals_return_to_start(
    library: PrimitiveLibrary,
    still_air: WindField,
    aircraft: Aircraft,
    primitive_index: FindPrimitive,
    turn: float,
    v: float,
    gamma: float,
) -> None:
    i = primitive_index(library, "spiral", v, gamma, turn)
    r = rollout(START, still_air, aircraft, primitive=i, library=library)
    end = r.final[0]
    assert math.hypot(end[0] - START[0], end[1] - START[1]) < 1e-6
    assert angle_error(end[2], START[2]) < 1e-9
    assert end[3] == pytest.approx(START[3] + v * math.sin(math.radians(gamma)) * library.duration, abs=1e-9)


@pytest.mark.parametrize("index", range(10, 150))
def test_turn_radius_and_height(
    library: PrimitiveLibrary, still_air: WindField, aircraft: Aircraft, index: int
) -> None:
    """Every output point of a curve / spiral lies on the analytic circle of radius v cos(gamma) / chi_dot,
    and the height is h0 + v sin(gamma) t."""
    _, v, gam, rate, _ = library.table[index]
    r = rollout(START, still_air, aircraft, primitive=index, library=library)
    k = v * math.cos(gam) / rate  # signed radius: centre to the right for rate > 0
    centre = START[:2] + k * np.array([-math.sin(START[2]), math.cos(START[2])])
    dist = np.hypot(r.states[0, :, 0] - centre[0], r.states[0, :, 1] - centre[1])
    np.testing.assert_allclose(dist, abs(k), rtol=0, atol=1e-9)
    np.testing.assert_allclose(r.states[0, :, 3], START[3] + v * math.sin(gam) * r.times, rtol=0, atol=1e-9)
    expected_chi = START[2] + rate * r.times
    assert np.all(angle_error(r.states[0, :, 2], expected_chi) < 1e-9)
    assert np.all((r.states[0, :, 2] >= -math.pi) & (r.states[0, :, 2] <= math.pi))


def test_chi_wrap_excludes_pi(still_air: WindField, aircraft: Aircraft) -> None:
    r = rollout([0.0, 0.0, 0.0, 500.0], still_air, aircraft, primitive=120)  # 20 m/s, -1080 deg, -45 deg
    chi = r.states[0, :, 2]
    assert np.all((chi >= -math.pi) & (chi < math.pi)), chi[chi >= math.pi]


@pytest.mark.parametrize("index", range(10))
def test_straight_lines(library: PrimitiveLibrary, still_air: WindField, aircraft: Aircraft, index: int) -> None:
    _, v, gam, _, _ = library.table[index]
    r = rollout(START, still_air, aircraft, primitive=index, library=library)
    t = r.times
    u = v * math.cos(gam)
    np.testing.assert_allclose(r.states[0, :, 0], START[0] + u * t * math.cos(START[2]), rtol=0, atol=1e-9)
    np.testing.assert_allclose(r.states[0, :, 1], START[1] + u * t * math.sin(START[2]), rtol=0, atol=1e-9)
    np.testing.assert_allclose(r.states[0, :, 2], START[2], rtol=0, atol=1e-12)
    np.testing.assert_allclose(r.states[0, :, 3], START[3] + v * math.sin(gam) * t, rtol=0, atol=1e-9)


def test_half_turn_spiral_ends_opposite(
    library: PrimitiveLibrary, still_air: WindField, aircraft: Aircraft, primitive_index: FindPrimitive
) -> None:
    i = primitive_index(library, "spiral", 20.0, 0.0, 180.0)
    end = rollout([0.0, 0.0, 0.0, 500.0], still_air, aircraft, primitive=i, library=library).final[0]
    radius = 20.0 / (math.pi / 30.0)
    np.testing.assert_allclose(end[:2], [0.0, 2 * radius], atol=1e-9)
    assert angle_error(end[2], math.pi) < 1e-12


@pytest.mark.parametrize("index", [0, 7, 33, 72, 118, 147, 150, 166, 173])
def test_ambient_wind_shifts_path_by_w_t(
    library: PrimitiveLibrary, still_air: WindField, aircraft: Aircraft, index: int
) -> None:
    windy = WindField(wind_north=3.25, wind_east=-4.5)
    calm = rollout(START, still_air, aircraft, primitive=index, library=library)
    blown = rollout(START, windy, aircraft, primitive=index, library=library)
    shift = blown.states[0, :, :2] - calm.states[0, :, :2]
    np.testing.assert_allclose(shift[:, 0], 3.25 * calm.times, rtol=0, atol=1e-9)
    np.testing.assert_allclose(shift[:, 1], -4.5 * calm.times, rtol=0, atol=1e-9)
    np.testing.assert_allclose(shift[-1], np.array([3.25, -4.5]) * library.duration, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(blown.states[0, :, 2:], calm.states[0, :, 2:])
    assert blown.fuel[0] == calm.fuel[0]


@pytest.mark.parametrize("n_points", [2, 3, 7, 30, 31])
def test_spline_switches_at_output_point_n_half(still_air: WindField, aircraft: Aircraft, n_points: int) -> None:
    lib = PrimitiveLibrary(30.0, n_points)
    for i in range(150, 174):
        _, v, gam, r1, r2 = lib.table[i]
        r = rollout(START, still_air, aircraft, primitive=i, library=lib)
        exp = expected_horizontal(START, v, gam, r1, r2, lib.duration, n_points, (0.0, 0.0))
        np.testing.assert_allclose(r.states[0, :, :2], exp[:, :2], rtol=0, atol=1e-6)
        assert np.all(angle_error(r.states[0, :, 2], exp[:, 2]) < 1e-9)
        # final heading = chi0 + r1 * t_switch + r2 * (Ts - t_switch)
        t_sw = (n_points // 2) * lib.duration / n_points
        assert angle_error(r.final[0, 2], START[2] + r1 * t_sw + r2 * (lib.duration - t_sw)) < 1e-9


# --------------------------------------------------------------------------------------------
# Integration accuracy through thermals
# --------------------------------------------------------------------------------------------
THERMAL_CENTRE = (500.0, 200.0)


def _through_core_cases(lib: PrimitiveLibrary) -> tuple[np.ndarray, np.ndarray]:
    """Start states and primitives whose paths cross or circle the thermal core at (500, 200)."""
    cn, ce = THERMAL_CENTRE
    states, prims = [], []
    for v_idx, v in enumerate(SPEEDS):
        for g_idx in (1, 2, 3):  # -15, 0, +15 deg
            # straight through the centre from 150 m / 300 m south
            states.append([cn - 10.0 * v, ce, 0.0, 400.0])
            prims.append(v_idx * 5 + g_idx)
            # spirals of every turn centred on the core: start one radius west of it, heading north
            for s_idx, turn in enumerate((-1080.0, -720.0, -360.0, -180.0, 180.0, 360.0, 720.0, 1080.0)):
                rate = math.radians(turn) / lib.duration
                k = v * math.cos(math.radians(GAMMAS_DEG[g_idx])) / rate
                states.append([cn, ce - k, 0.0, 400.0])
                prims.append(70 + v_idx * 40 + s_idx * 5 + g_idx)
            # curves entering the core obliquely
            for c_idx in range(6):
                states.append([cn - 8.0 * v, ce - 40.0, 0.3, 400.0])
                prims.append(10 + v_idx * 30 + c_idx * 5 + g_idx)
        for s_idx in range(12):  # splines through the core
            states.append([cn - 10.0 * v, ce + 20.0, 0.0, 400.0])
            prims.append(150 + v_idx * 12 + s_idx)
    return np.array(states), np.array(prims)


@pytest.mark.parametrize(
    "field",
    [
        WindField(thermals=(Thermal(*THERMAL_CENTRE, strength=3.5),), model="allen", zi=1400.0),
        # heights 400-1000 m in zi = 1100 m reach the downdraft ring band (0.5 < z/zi <= 0.9)
        WindField(thermals=(Thermal(*THERMAL_CENTRE, strength=3.5),), model="allen", zi=1100.0, wind_east=1.5),
        WindField(thermals=(Thermal(*THERMAL_CENTRE, strength=4.0, radius=60.0),), model="gaussian"),
        WindField(thermals=(Thermal(*THERMAL_CENTRE, strength=4.0, radius=150.0),), model="gaussian", wind_north=-2.0),
    ],
    ids=["allen", "allen-ring-wind", "gaussian-narrow", "gaussian-wide-wind"],
)
def test_substep_refinement_changes_height_by_less_than_1cm(
    library: PrimitiveLibrary, aircraft: Aircraft, field: WindField
) -> None:
    states, prims = _through_core_cases(library)
    coarse = rollout(states, field, aircraft, primitive=prims, library=library)
    fine = rollout(states, field, aircraft, primitive=prims, library=library, max_substep=0.025)
    # the thermal really acts: compared with still air, the heights move by metres
    calm = rollout(states, WindField(wind_north=field.wind_north, wind_east=field.wind_east), aircraft, primitive=prims)
    lift = coarse.states[:, -1, 3] - calm.states[:, -1, 3]
    assert np.max(np.abs(lift)) > 20.0
    err = np.abs(coarse.states[..., 3] - fine.states[..., 3])
    assert err.max() < 0.01, f"max height change {err.max():.3e} m at primitive {prims[err.max(axis=1).argmax()]}"
    # the horizontal path is the closed form: independent of the substep
    np.testing.assert_allclose(coarse.states[..., :3], fine.states[..., :3], rtol=0, atol=1e-9)


@pytest.mark.parametrize("case", ["gaussian-climb-into-zi", "allen-nearest-thermal-switch"])
def test_substep_refinement_across_field_discontinuities(
    library: PrimitiveLibrary, aircraft: Aircraft, case: str
) -> None:
    if case == "gaussian-climb-into-zi":
        field = WindField(thermals=(Thermal(0.0, 0.0, 4.0, radius=80.0),), model="gaussian", zi=1000.0)
        prim = 102  # spiral 10 m/s, +720 deg, level (order pinned above)
        radius = 10.0 / library.table[prim, 3]
        start = np.array([0.0, -radius, 0.0, 960.0])  # circling the core 40 m below zi
    else:
        field = WindField(thermals=(Thermal(0.0, 0.0, 1.0), Thermal(60.0, 0.0, 3.5)), zi=1400.0)
        prim = 21  # curve 10 m/s, -30 deg, -15 deg path angle
        start = np.array([-200.0, 40.0, 0.0, 400.0])
    # Known limit (README, DEFAULT_MAX_SUBSTEP): fixed steps are first order across jumps of the field.
    # The error stays below jump x substep and shrinks at least linearly with the substep.
    ref = rollout(start, field, aircraft, primitive=prim, library=library, max_substep=0.0025).states[0, :, 3]
    err = {
        ms: np.abs(
            rollout(start, field, aircraft, primitive=prim, library=library, max_substep=ms).states[0, :, 3] - ref
        ).max()
        for ms in (0.5, 0.05)
    }
    jump = 4.0 if case == "gaussian-climb-into-zi" else 3.0
    assert err[0.5] < jump * 0.5 * 1.5
    assert err[0.05] < err[0.5] / 5.0


def test_substep_convergence_allen(library: PrimitiveLibrary, aircraft: Aircraft) -> None:
    """The integrator converges: 0.25 s vs 0.025 s substeps agree within 1 cm through an Allen core,
    and the error shrinks at least 2.8-fold when the step is halved (order > 1.5)."""
    field = WindField(thermals=(Thermal(*THERMAL_CENTRE, strength=3.5),), model="allen", zi=1400.0)
    states, prims = _through_core_cases(library)
    h = {
        ms: rollout(states, field, aircraft, primitive=prims, max_substep=ms).states[..., 3]
        for ms in (0.5, 0.25, 0.025, 0.0025)
    }
    assert np.abs(h[0.25] - h[0.025]).max() < 0.01
    err_05 = np.abs(h[0.5] - h[0.0025]).max()
    err_025 = np.abs(h[0.25] - h[0.0025]).max()
    # Allen's profile has kinks (the clip at ws = 0, the ring edges), so expect order > 1.5, not 4.
    assert err_025 < err_05 / 2.8


# --------------------------------------------------------------------------------------------
# Property-based checks
# --------------------------------------------------------------------------------------------
coord = st.floats(-1500.0, 1500.0, allow_nan=False)


@st.composite
def fields(draw: st.DrawFn) -> WindField:
    model = draw(st.sampled_from(["allen", "gaussian"]))
    thermals = draw(
        st.lists(
            st.builds(
                Thermal,
                north=coord,
                east=coord,
                strength=st.floats(0.3, 6.0),
                radius=st.floats(15.0, 300.0),
            ),
            min_size=0,
            max_size=5,
        )
    )
    return WindField(
        thermals=tuple(thermals),
        model=model,
        zi=draw(st.floats(400.0, 3000.0)),
        wind_north=draw(st.floats(-8.0, 8.0)),
        wind_east=draw(st.floats(-8.0, 8.0)),
        drift=draw(st.booleans()),
    )


states_st = st.tuples(coord, coord, st.floats(-10.0, 10.0), st.floats(5.0, 3000.0)).map(
    lambda s: np.array(s, dtype=np.float64)
)
primitive_st = st.integers(0, N_PRIMITIVES - 1)
t0_st = st.floats(0.0, 2000.0)


@settings(max_examples=50, deadline=None)
@given(field=fields(), state=states_st, prim=primitive_st, t0=t0_st, thrust=st.sampled_from(["trim", "paper"]))
def test_rollout_is_finite_and_consistent(
    field: WindField, state: np.ndarray, prim: int, t0: float, thrust: str
) -> None:
    ac = Aircraft(thrust_model=thrust)
    r = rollout(state, field, ac, primitive=prim, t0=t0)
    for name in ("states", "fuel", "potential", "kinetic", "cost", "max_bank", "min_height"):
        assert np.all(np.isfinite(getattr(r, name))), name
    assert r.fuel[0] >= 0.0
    assert r.kinetic[0] == 0.0
    assert r.cost[0] == r.fuel[0] + r.potential[0] + r.kinetic[0]
    assert r.potential[0] == pytest.approx(-G * (r.final[0, 3] - state[3]), rel=1e-12, abs=1e-9)
    assert r.min_height[0] == pytest.approx(min(state[3], r.states[0, :, 3].min()), abs=1e-12)
    _, v, _, r1, r2 = PrimitiveLibrary().table[prim]
    assert r.max_bank[0] == pytest.approx(math.atan(v * max(abs(r1), abs(r2)) / G), rel=1e-12)
    # documented range is [-pi, pi); pi itself can come out by rounding (see test_chi_wrap_excludes_pi)
    assert np.all((r.states[0, :, 2] >= -math.pi) & (r.states[0, :, 2] <= math.pi))


@settings(max_examples=30, deadline=None)
@given(
    field=fields(),
    states=st.lists(states_st, min_size=2, max_size=8),
    prims=st.lists(primitive_st, min_size=8, max_size=8),
    t0=t0_st,
    vprev=st.floats(5.0, 25.0),
)
def test_batched_equals_one_by_one(
    field: WindField, states: list[np.ndarray], prims: list[int], t0: float, vprev: float
) -> None:
    ac = Aircraft()
    x = np.stack(states)
    p = np.array(prims[: len(states)])
    batch = rollout(x, field, ac, primitive=p, t0=t0, airspeed_prev=vprev)
    for b in range(len(states)):
        one = rollout(x[b], field, ac, primitive=int(p[b]), t0=t0, airspeed_prev=vprev)
        for name in ("states", "fuel", "potential", "kinetic", "cost", "max_bank", "min_height"):
            assert np.array_equal(getattr(batch, name)[b], getattr(one, name)[0]), name
    # one primitive broadcast over many states, and one state over many primitives
    same_p = rollout(x, field, ac, primitive=int(p[0]), t0=t0)
    assert np.array_equal(same_p.states[0], batch.states[0])
    same_x = rollout(x[0], field, ac, primitive=p, t0=t0)
    assert np.array_equal(same_x.states[0], batch.states[0])


@settings(max_examples=50, deadline=None)
@given(field=fields(), state=states_st, prim=primitive_st, t0=t0_st)
def test_horizontal_path_matches_closed_form(field: WindField, state: np.ndarray, prim: int, t0: float) -> None:
    lib = PrimitiveLibrary()
    _, v, gam, r1, r2 = lib.table[prim]
    r = rollout(state, field, Aircraft(), primitive=prim, t0=t0)
    exp = expected_horizontal(state, v, gam, r1, r2, lib.duration, lib.n_points, (field.wind_north, field.wind_east))
    np.testing.assert_allclose(r.states[0, :, :2], exp[:, :2], rtol=0, atol=1e-6)
    assert np.all(angle_error(r.states[0, :, 2], exp[:, 2]) < 1e-9)
    if not field.thermals:  # no updraft anywhere: the height is linear in time too
        np.testing.assert_allclose(r.states[0, :, 3], state[3] + v * math.sin(gam) * r.times, rtol=0, atol=1e-9)


_LO, _HI = PrimitiveLibrary().control_bounds()
control_st = st.tuples(
    st.floats(_LO[0], _HI[0]), st.floats(_LO[1], _HI[1]), st.floats(_LO[2], _HI[2]), st.floats(1.0, 60.0)
)


@settings(max_examples=50, deadline=None)
@given(field=fields(), state=states_st, control=control_st, t0=t0_st)
def test_continuous_control_matches_closed_form(
    field: WindField, state: np.ndarray, control: tuple[float, float, float, float], t0: float
) -> None:
    v, rate, gam, dur = control
    r = rollout(state, field, Aircraft(), control=np.array([v, rate, gam]), duration=dur, t0=t0)
    assert np.all(np.isfinite(r.states)) and np.isfinite(r.cost[0]) and r.fuel[0] >= 0.0
    np.testing.assert_allclose(r.times, dur * np.arange(1, 31) / 30, rtol=1e-15)
    exp = expected_horizontal(state, v, gam, rate, rate, dur, 30, (field.wind_north, field.wind_east))
    np.testing.assert_allclose(r.states[0, :, :2], exp[:, :2], rtol=0, atol=1e-6)
    assert np.all(angle_error(r.states[0, :, 2], exp[:, 2]) < 1e-9)
    assert r.max_bank[0] == pytest.approx(math.atan(v * abs(rate) / G), rel=1e-12, abs=1e-15)
    if not field.thermals:
        np.testing.assert_allclose(r.states[0, :, 3], state[3] + v * math.sin(gam) * r.times, rtol=0, atol=1e-9)


def test_primitive_and_equivalent_control_agree(library: PrimitiveLibrary, aircraft: Aircraft) -> None:
    field = WindField(thermals=(Thermal(300.0, 0.0, 3.0), Thermal(-200.0, 400.0, 2.0)), wind_east=2.0)
    x = np.array([0.0, 0.0, 0.2, 450.0])
    for i in range(150):  # non-spline primitives are constant controls
        _, v, gam, rate, _ = library.table[i]
        a = rollout(x, field, aircraft, primitive=i)
        b = rollout(x, field, aircraft, control=[v, rate, gam])
        assert np.array_equal(a.states, b.states) and a.cost[0] == b.cost[0], i


# --------------------------------------------------------------------------------------------
# Bad input
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("kwargs", "pattern"),
    [
        ({"duration": 0.0}, r"duration=0\.0"),
        ({"duration": -30.0}, r"duration=-30\.0"),
        ({"duration": math.nan}, r"duration=nan"),
        ({"duration": math.inf}, r"duration=inf"),
        ({"n_points": 1}, r"n_points=1"),
        ({"n_points": 0}, r"n_points=0"),
        ({"n_points": 30.0}, r"n_points=30\.0"),
    ],
)
def test_library_validation(kwargs: dict[str, float], pattern: str) -> None:
    with pytest.raises(ConfigError, match=pattern):
        PrimitiveLibrary(**kwargs)  # type: ignore[arg-type]


GOOD = np.array([0.0, 0.0, 0.0, 300.0])


@pytest.mark.parametrize(
    ("kwargs", "pattern"),
    [
        ({"states": [0.0, math.nan, 0.0, 300.0], "primitive": 3}, r"states.*nan"),
        ({"states": [0.0, 0.0, math.inf, 300.0], "primitive": 3}, r"states.*inf"),
        ({"states": [[0.0, 0.0, 0.0, 300.0], [1.0, 2.0, 3.0, -math.inf]], "primitive": 3}, r"states.*inf"),
        ({"states": [0.0, 0.0, 300.0], "primitive": 3}, r"states has shape"),
        ({"states": GOOD, "control": [math.nan, 0.0, 0.0]}, r"control.*nan"),
        ({"states": GOOD, "control": [15.0, math.inf, 0.0]}, r"control.*inf"),
        ({"states": GOOD, "control": [15.0, 0.0, -math.inf]}, r"control.*inf"),
        ({"states": GOOD, "control": [0.0, 0.0, 0.0]}, r"control airspeed"),
        ({"states": GOOD, "control": [15.0, 0.0, 1.6]}, r"control gamma"),
        ({"states": GOOD, "control": [15.0, 0.0]}, r"control has shape"),
        ({"states": GOOD, "primitive": 174}, r"primitive=174"),
        ({"states": GOOD, "primitive": -1}, r"primitive=-1"),
        ({"states": GOOD, "primitive": 2.0}, r"primitive=2\.0"),
        ({"states": GOOD}, r"exactly one of primitive"),
        ({"states": GOOD, "primitive": 1, "control": [15.0, 0.0, 0.0]}, r"exactly one of primitive"),
        ({"states": GOOD, "primitive": 1, "duration": 0.0}, r"duration=0\.0"),
        ({"states": GOOD, "primitive": 1, "duration": math.nan}, r"duration=nan"),
        ({"states": GOOD, "primitive": 1, "max_substep": -1.0}, r"max_substep=-1\.0"),
        ({"states": GOOD, "primitive": 1, "t0": math.nan}, r"t0.*nan"),
        ({"states": np.zeros((3, 4)) + GOOD, "primitive": [1, 2]}, r"3 states and 2 primitive"),
    ],
)
def test_rollout_validation(still_air: WindField, aircraft: Aircraft, kwargs: dict[str, object], pattern: str) -> None:
    with pytest.raises(ConfigError, match=pattern):
        rollout(field=still_air, aircraft=aircraft, **kwargs)  # type: ignore[arg-type]


@pytest.mark.parametrize("vprev", [-30.0, math.inf])
def test_airspeed_prev_validated(still_air: WindField, aircraft: Aircraft, vprev: float) -> None:
    with pytest.raises(ConfigError, match="airspeed_prev"):
        rollout(GOOD, still_air, aircraft, control=[15.0, 0.0, 0.0], airspeed_prev=vprev)


def test_run_fields_rolls_each_row_out_in_its_own_field(
    library: PrimitiveLibrary, aircraft: Aircraft, rng: np.random.Generator
) -> None:
    """One multi-field kernel call gives, bit for bit, what one call per field gives (the batched
    env's random scenarios rely on it), for Allen and Gaussian fields, wind, drift and no thermals."""
    centres = rng.uniform(-300.0, 300.0, (6, 2))
    thermals = tuple(Thermal(float(n), float(e), 3.0, 60.0) for n, e in centres)
    fields = [
        WindField(thermals=thermals[:5], zi=1400.0),
        WindField(thermals=thermals, model="gaussian", zi=900.0, wind_north=3.0, wind_east=-2.0, drift=True),
        WindField(thermals=thermals[:2], zi=1200.0, wind_north=-4.0),
        WindField(),
    ]
    b = 400
    which = rng.integers(0, len(fields), b)
    x0 = np.stack(
        [rng.uniform(-400, 400, b), rng.uniform(-400, 400, b), rng.uniform(-np.pi, np.pi, b), rng.uniform(50, 1000, b)],
        axis=1,
    )
    t0 = rng.uniform(0.0, 200.0, b)
    vp = np.where(rng.random(b) < 0.5, np.nan, 15.0)
    ctrl = np.ascontiguousarray(library.kernel_rows[rng.integers(0, N_PRIMITIVES, b)])
    prop = Propagator(fields[0], aircraft, library)
    out, terms = prop.run_fields(x0, t0, vp, ctrl, which, *pack_fields(fields))
    for f, fld in enumerate(fields):
        rows = np.flatnonzero(which == f)
        o, t = Propagator(fld, aircraft, library).run(
            np.ascontiguousarray(x0[rows]), t0[rows], vp[rows], np.ascontiguousarray(ctrl[rows])
        )
        np.testing.assert_array_equal(out[rows], o)
        np.testing.assert_array_equal(terms[rows], t)
    # the fields really differ: the same edges in field 0 end elsewhere for the other fields' rows
    o0, _ = prop.run(x0, t0, vp, ctrl)
    assert not np.array_equal(o0[which != 0], out[which != 0])
    with pytest.raises(ConfigError, match="at least one"):
        pack_fields([])
