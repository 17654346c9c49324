"""Physics layer: ISA atmosphere, Allen and Gaussian thermals (against an independent numpy
re-implementation of ``shared/design/physics.md``), the thrust / energy model through ``rollout``
(closed forms), and validation of every physics parameter."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from soaring_env import (
    Aircraft,
    ConfigError,
    G,
    PrimitiveLibrary,
    Thermal,
    WindField,
    air_density,
    bank_angle,
    rollout,
)
from soaring_env.physics.thermals import ALLEN_SHAPE, _pow, allen_reach, within_allen_reach

FindPrimitive = Callable[[PrimitiveLibrary, str, float, float, float], int]

# ----------------------------------------------------------------------------------------------
# Independent reference implementations (written from physics.md, not from the package code)
# ----------------------------------------------------------------------------------------------
#: physics.md table: r1/r2, k1, k2, k3, k4.
ALLEN_TABLE = np.array(
    [
        [0.14, 1.5352, 2.5826, -0.0113, -0.1950],
        [0.25, 1.5265, 3.6054, -0.0176, -0.1265],
        [0.36, 1.4866, 4.8356, -0.0320, -0.0818],
        [0.47, 1.2042, 7.7904, 0.0848, -0.0445],
        [0.58, 0.8816, 13.9720, 0.3404, -0.0216],
        [0.69, 0.7067, 23.9940, 0.5689, -0.0099],
        [0.80, 0.6189, 42.7965, 0.7157, -0.0033],
    ]
)


def isa_density(h: np.ndarray | float) -> np.ndarray:
    return 1.225 * (1.0 - 0.0065 * np.asarray(h, dtype=float) / 288.15) ** 4.2559


def allen_scales(z: np.ndarray, zi: float, wstar: np.ndarray | float) -> dict[str, np.ndarray]:
    """r2, r1, wbar, w_peak and the shape-table row at heights z (physics.md formulas)."""
    zz = np.asarray(z, dtype=float) / zi
    cb = np.cbrt(zz)
    wbar = wstar * cb * (1.0 - 1.1 * zz)
    r2 = np.maximum(10.0, 0.102 * cb * (1.0 - 0.25 * zz) * zi)
    ratio = np.where(r2 < 600.0, 0.0011 * r2 + 0.14, 0.8)
    r1 = ratio * r2
    w_peak = 3.0 * wbar * (r2**3 - r2**2 * r1) / (r2**3 - r1**3)
    row = np.argmin(np.abs(ratio[..., None] - ALLEN_TABLE[:, 0]), axis=-1)
    return {"zz": zz, "r2": r2, "r1": r1, "wbar": wbar, "w_peak": w_peak, "row": row}


def allen_reference(
    north: np.ndarray, east: np.ndarray, z: np.ndarray, thermals: Sequence[Thermal], zi: float
) -> np.ndarray:
    """Allen (2006) updraft at points, nearest-thermal rule, no environmental sink, w = 0 at z >= zi."""
    north, east, z = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in (north, east, z)))
    cn = np.array([t.north for t in thermals])
    ce = np.array([t.east for t in thermals])
    ws_ = np.array([t.strength for t in thermals])
    d = np.hypot(north[..., None] - cn, east[..., None] - ce)
    j = np.argmin(d, axis=-1)
    r = np.take_along_axis(d, j[..., None], axis=-1)[..., 0]
    zc = np.clip(z, 1e-9, zi)  # keep the cube root real; heights outside (0, zi) are zeroed below
    sc = allen_scales(zc, zi, ws_[j])
    k1, k2, k3, k4 = (ALLEN_TABLE[sc["row"], c] for c in (1, 2, 3, 4))
    x = r / sc["r2"]
    ws = np.maximum(0.0, 1.0 / (1.0 + (k1 * np.abs(x + k3)) ** k2) + k4 * x)
    wl = np.where((r > sc["r1"]) & (r < 2.0 * sc["r2"]), np.pi / 6.0 * np.sin(np.pi * x), 0.0)
    swd = np.where((sc["zz"] > 0.5) & (sc["zz"] <= 0.9), 2.5 * (sc["zz"] - 0.5), 0.0)
    w_d = np.minimum(swd * wl, 0.0)
    w = ws * sc["w_peak"] + w_d * sc["wbar"]
    return np.where((z <= 0.0) | (z >= zi), 0.0, w)


def gaussian_reference(north: np.ndarray, east: np.ndarray, thermals: Sequence[Thermal]) -> np.ndarray:
    w = np.zeros(np.broadcast(north, east).shape)
    for t in thermals:
        w = w + t.strength * np.exp(-((north - t.north) ** 2 + (east - t.east) ** 2) / t.radius**2)
    return w


def trim_drag(ac: Aircraft, v: float, gamma: float, phi: float, h: float) -> float:
    """Drag [N] with lift m g cos(gamma) / cos(phi) and the parabolic polar (physics.md "trim")."""
    qs = 0.5 * float(isa_density(h)) * v * v * ac.wing_area
    cl = ac.mass * G * math.cos(gamma) / (math.cos(phi) * qs)
    return qs * (ac.cd0 + cl * cl / (math.pi * ac.aspect_ratio * ac.oswald))


# ----------------------------------------------------------------------------------------------
# Atmosphere
# ----------------------------------------------------------------------------------------------
def test_isa_density_values() -> None:
    assert float(air_density(0.0)) == pytest.approx(1.225, rel=1e-12)
    assert float(air_density(1000.0)) == pytest.approx(1.112, rel=1e-3)  # ISA table: 1.1117
    assert float(air_density(2000.0)) == pytest.approx(1.0066, rel=1e-3)  # ISA table
    h = np.linspace(-200.0, 10000.0, 57)
    np.testing.assert_allclose(air_density(h), isa_density(h), rtol=1e-12)
    assert np.all(np.diff(air_density(h)) < 0.0)


@pytest.mark.parametrize("bad", [11000.0, math.nan, math.inf])
def test_isa_density_rejects_outside_troposphere(bad: float) -> None:
    with pytest.raises(ValueError, match="height"):
        air_density(bad)


# ----------------------------------------------------------------------------------------------
# Allen thermal
# ----------------------------------------------------------------------------------------------
def test_allen_worked_example() -> None:
    """physics.md: zi = 1400 m, w* = 2.56 m/s, z = 300 m -> r2 80.9, r1 18.5, wbar 1.17, w_peak 2.74."""
    f = WindField(thermals=(Thermal(0.0, 0.0, strength=2.56),), zi=1400.0)
    p = f.allen_profile(300.0, 2.56)
    assert p["r2"] == pytest.approx(80.9, rel=0.01)
    assert p["r1"] == pytest.approx(18.5, rel=0.01)
    assert p["wbar"] == pytest.approx(1.17, rel=0.01)
    assert p["w_peak"] == pytest.approx(2.74, rel=0.01)
    ref = allen_scales(np.array(300.0), 1400.0, 2.56)
    for key in ("r2", "r1", "wbar", "w_peak"):
        assert p[key] == pytest.approx(float(ref[key]), rel=1e-12), key
    # strength scales wbar and w_peak linearly, the radii not at all
    p1 = f.allen_profile(300.0)
    assert p1["w_peak"] * 2.56 == pytest.approx(p["w_peak"], rel=1e-12)
    assert p1["r2"] == p["r2"]


def test_allen_centre_equals_peak() -> None:
    f = WindField(thermals=(Thermal(0.0, 0.0, strength=2.56),), zi=1400.0)
    w0 = float(f.updraft(0.0, 0.0, 300.0))
    w_peak = f.allen_profile(300.0, 2.56)["w_peak"]
    # ws(0) = 1 / (1 + (k1 |k3|)^k2) is not exactly 1: compare with what the formula gives
    sc = allen_scales(np.array(300.0), 1400.0, 2.56)
    k1, k2, k3 = (ALLEN_TABLE[int(sc["row"]), c] for c in (1, 2, 3))
    ws0 = 1.0 / (1.0 + (k1 * abs(k3)) ** k2)
    assert w0 == pytest.approx(ws0 * w_peak, rel=1e-12)
    assert w0 == pytest.approx(w_peak, rel=1e-4)
    assert w0 == pytest.approx(2.74, rel=0.01)


@pytest.mark.parametrize(
    ("zi", "thermals", "half_width"),
    [
        (1400.0, (Thermal(0.0, 0.0, 2.56),), 250.0),
        (1213.0, (Thermal(0.0, 0.0, 1.97), Thermal(150.0, -40.0, 3.2), Thermal(-90.0, 220.0, 0.8)), 450.0),
        (
            1975.0,
            tuple(Thermal(n, e, s) for n, e, s in [(0, 0, 2.69), (300, 0, 1.5), (0, 310, 3.0), (-250, -250, 2.0)]),
            500.0,
        ),
        (300.0, (Thermal(10.0, -5.0, 4.0), Thermal(-25.0, 30.0, 2.0)), 80.0),  # r2 <= 23 m, floor 10 m near ground
    ],
)
def test_allen_matches_reference(
    rng: np.random.Generator, zi: float, thermals: tuple[Thermal, ...], half_width: float
) -> None:
    f = WindField(thermals=thermals, model="allen", zi=zi)
    m = 20000
    n = rng.uniform(-half_width, half_width, m)
    e = rng.uniform(-half_width, half_width, m)
    z = rng.uniform(-50.0, 1.2 * zi, m)
    got = f.updraft(n, e, z)
    exp = allen_reference(n, e, z, thermals, zi)
    np.testing.assert_allclose(got, exp, rtol=1e-9, atol=1e-12)
    assert np.count_nonzero(exp > 0.1) > 100 and np.count_nonzero(exp < -0.01) > 10  # non-trivial sample


def test_allen_zero_at_and_above_zi_and_at_ground() -> None:
    f = WindField(thermals=(Thermal(0.0, 0.0, 3.0),), zi=1400.0)
    r = np.array([0.0, 10.0, 50.0, 90.0, 150.0])
    for z in (1400.0, 1400.0 + 1e-9, 1500.0, 5000.0, 0.0, -10.0):
        np.testing.assert_array_equal(f.updraft(r, 0.0, z), np.zeros_like(r))
    assert float(f.updraft(0.0, 0.0, 1399.0)) != 0.0  # just below zi the formula is active


def test_allen_symmetric_in_azimuth() -> None:
    f = WindField(thermals=(Thermal(120.0, -80.0, 2.8),), zi=1400.0)
    ang = np.linspace(0.0, 2 * np.pi, 37)[:-1]
    for z in (150.0, 600.0, 1000.0):
        for rad in (0.0, 5.0, 40.0, 95.0, 130.0, 200.0):
            w = f.updraft(120.0 + rad * np.cos(ang), -80.0 + rad * np.sin(ang), z)
            np.testing.assert_allclose(w, w[0], rtol=1e-10, atol=1e-12)


def test_allen_downdraft_ring() -> None:
    """Negative only for r2 < r < 2 r2 and 0.5 < z/zi <= 0.9; exactly zero beyond 2 r2 at every height."""
    zi = 1400.0
    f = WindField(thermals=(Thermal(0.0, 0.0, 2.56),), zi=zi)
    z = np.linspace(5.0, 0.9 * zi, 120)
    r = np.linspace(0.0, 260.0, 521)
    rr, zz = np.meshgrid(r, z)
    w = f.updraft(rr, 0.0, zz)
    r2 = allen_scales(zz, zi, 2.56)["r2"]
    neg = w < 0.0
    assert neg.any()
    assert np.all((rr[neg] > r2[neg]) & (rr[neg] < 2.0 * r2[neg]))
    assert np.all((zz[neg] / zi > 0.5) & (zz[neg] / zi <= 0.9))
    # inside the core it lifts, and below half of zi there is no sink at all
    assert np.all(w[rr < 0.5 * r2] > 0.0)
    assert np.all(w[zz / zi <= 0.5] >= 0.0)
    # beyond 2 r2: exactly zero at every height below zi (and the top of the band has the ring)
    z_all = np.linspace(1.0, zi - 1.0, 300)
    r2_all = allen_scales(z_all, zi, 2.56)["r2"]
    for fac in (2.000001, 2.01, 2.5, 4.0, 20.0):  # at exactly 2 r2 sin(pi x) may round to -1e-16
        np.testing.assert_array_equal(f.updraft(fac * r2_all, 0.0, z_all), 0.0)


def test_allen_near_zi_mean_updraft_turns_negative() -> None:
    """Allen's wbar = w* zz^(1/3) (1 - 1.1 zz) is negative for 1/1.1 < z/zi < 1 (entrainment layer):
    the formula, as specified, sinks at the core there."""
    f = WindField(thermals=(Thermal(0.0, 0.0, 2.0),), zi=1000.0)
    assert float(f.updraft(0.0, 0.0, 950.0)) < 0.0
    assert float(f.updraft(0.0, 0.0, 900.0)) > 0.0


def test_nearest_thermal_rule() -> None:
    zi = 1400.0
    a, b, c = Thermal(0.0, 0.0, 2.0), Thermal(100.0, 0.0, 3.5), Thermal(0.0, 120.0, 1.0)
    f = WindField(thermals=(a, b, c), zi=zi)
    z = 300.0
    for pn, pe in [(40.0, 0.0), (49.0, 5.0), (60.0, 0.0), (80.0, 30.0), (10.0, 70.0), (-30.0, -20.0)]:
        d = [math.hypot(pn - t.north, pe - t.east) for t in (a, b, c)]
        nearest = (a, b, c)[int(np.argmin(d))]
        alone = WindField(thermals=(nearest,), zi=zi)
        assert float(f.updraft(pn, pe, z)) == pytest.approx(float(alone.updraft(pn, pe, z)), rel=1e-12, abs=1e-15)
    # the strong thermal B dominates only on its side of the bisector: not a superposition
    left = float(f.updraft(49.0, 0.0, z))
    right = float(f.updraft(51.0, 0.0, z))
    assert left == pytest.approx(float(WindField(thermals=(a,), zi=zi).updraft(49.0, 0.0, z)), rel=1e-12)
    assert right > left
    assert float(f.updraft(40.0, 0.0, z)) != pytest.approx(
        sum(float(WindField(thermals=(t,), zi=zi).updraft(40.0, 0.0, z)) for t in (a, b, c)), rel=1e-3
    )


@pytest.mark.parametrize("model", ["allen", "gaussian"])
def test_drift_moves_field_with_wind(model: str) -> None:
    th = (Thermal(100.0, -50.0, 3.0, radius=70.0), Thermal(-200.0, 150.0, 2.0, radius=90.0))
    wn, we = 3.0, -2.0
    drifting = WindField(thermals=th, model=model, wind_north=wn, wind_east=we, drift=True)
    fixed = WindField(thermals=th, model=model, wind_north=wn, wind_east=we, drift=False)
    n = np.linspace(-300.0, 300.0, 61)
    e = np.linspace(-250.0, 250.0, 51)
    nn, ee = np.meshgrid(n, e)
    for t in (0.0, 10.0, 45.0):
        moved = drifting.updraft(nn + wn * t, ee + we * t, 400.0, t)
        np.testing.assert_allclose(moved, fixed.updraft(nn, ee, 400.0), rtol=1e-12, atol=1e-13)
        np.testing.assert_allclose(fixed.updraft(nn, ee, 400.0, t), fixed.updraft(nn, ee, 400.0), rtol=0, atol=0)
        np.testing.assert_allclose(drifting.centres(t), fixed.centres() + np.array([wn, we]) * t, rtol=1e-15)
    assert not np.allclose(drifting.updraft(nn, ee, 400.0, 45.0), fixed.updraft(nn, ee, 400.0))


def test_updraft_rejects_non_finite_points() -> None:
    f = WindField(thermals=(Thermal(0.0, 0.0),))
    with pytest.raises(ConfigError, match="height"):
        f.updraft(0.0, 0.0, math.nan)
    with pytest.raises(ConfigError, match="north"):
        f.updraft(math.inf, 0.0, 100.0)


@pytest.mark.filterwarnings("error")  # numpy's FutureWarning on broadcast views passed to numba
@pytest.mark.parametrize(
    "shapes", [((), (), ()), ((1,), (), ()), ((1, 1), (2,), ()), ((3, 1), (1, 2), (1,)), ((2,), (2,), (2,))]
)
def test_updraft_and_glide_broadcast_without_warnings(shapes: tuple[tuple[int, ...], ...]) -> None:
    """Scalars and any broadcastable shapes: no warning, numpy's broadcast shape, the same values
    as point by point."""
    f = WindField(thermals=(Thermal(0.0, 0.0),))
    north, east, height = (np.full(s, v) if s else v for s, v in zip(shapes, (20.0, -30.0, 300.0), strict=True))
    want = np.broadcast_shapes(*shapes)
    w = f.updraft(north, east, height)
    assert w.shape == want and w.dtype == np.float64
    np.testing.assert_array_equal(w, np.full(want, float(f.updraft(20.0, -30.0, 300.0))))
    ac = Aircraft()
    g = ac.glide_angle(np.full(shapes[0], 15.0), np.full(shapes[1], 0.05), 1500.0)
    assert g.shape == np.broadcast_shapes(shapes[0], shapes[1])
    np.testing.assert_array_equal(g, np.full(g.shape, float(ac.glide_angle(15.0, 0.05, 1500.0))))


# ----------------------------------------------------------------------------------------------
# Gaussian thermal
# ----------------------------------------------------------------------------------------------
def test_gaussian_peak_and_radius() -> None:
    f = WindField(thermals=(Thermal(200.0, -100.0, strength=3.0, radius=75.0),), model="gaussian")
    assert float(f.updraft(200.0, -100.0, 400.0)) == pytest.approx(3.0, rel=1e-14)
    ang = np.linspace(0.0, 2 * np.pi, 9)
    at_r = f.updraft(200.0 + 75.0 * np.cos(ang), -100.0 + 75.0 * np.sin(ang), 400.0)
    np.testing.assert_allclose(at_r, 3.0 / math.e, rtol=1e-12)
    assert float(f.updraft(200.0 + 2000.0, -100.0, 400.0)) == 0.0


def test_gaussian_sums_thermals(rng: np.random.Generator) -> None:
    th = (Thermal(0.0, 0.0, 3.0, 80.0), Thermal(90.0, 30.0, 2.0, 50.0), Thermal(-60.0, 140.0, 4.5, 120.0))
    f = WindField(thermals=th, model="gaussian", zi=1400.0)
    n = rng.uniform(-500.0, 500.0, 5000)
    e = rng.uniform(-500.0, 500.0, 5000)
    np.testing.assert_allclose(f.updraft(n, e, 700.0), gaussian_reference(n, e, th), rtol=1e-12, atol=1e-12)
    # where two thermals overlap the field is their sum, unlike Allen's nearest-thermal rule
    one = WindField(thermals=th[:1], model="gaussian").updraft(45.0, 15.0, 700.0)
    two = WindField(thermals=th[1:2], model="gaussian").updraft(45.0, 15.0, 700.0)
    assert float(WindField(thermals=th[:2], model="gaussian").updraft(45.0, 15.0, 700.0)) == pytest.approx(
        float(one + two), rel=1e-14
    )
    np.testing.assert_array_equal(f.updraft(0.0, 0.0, [0.0, 1400.0, 2000.0]), 0.0)


def test_no_thermals_no_updraft() -> None:
    for model in ("allen", "gaussian"):
        np.testing.assert_array_equal(WindField(model=model).updraft([0.0, 100.0], [0.0, 5.0], 500.0), 0.0)


# ----------------------------------------------------------------------------------------------
# Energy and cost through rollout
# ----------------------------------------------------------------------------------------------
@pytest.mark.parametrize("v", [10.0, 20.0])
@pytest.mark.parametrize("h", [100.0, 1000.0, 2500.0])
def test_level_straight_fuel_closed_form(
    library: PrimitiveLibrary, primitive_index: FindPrimitive, v: float, h: float
) -> None:
    ac = Aircraft()
    i = primitive_index(library, "straight", v, 0.0, 0.0)
    r = rollout([0.0, 0.0, 1.0, h], WindField(), ac, primitive=i)
    drag = trim_drag(ac, v, 0.0, 0.0, h)
    expected = drag * v * library.duration / (ac.mass * ac.eta_ec * ac.eta_p)
    assert r.fuel[0] == pytest.approx(expected, rel=1e-10)
    assert r.cost[0] == pytest.approx(expected, rel=1e-10)
    assert r.potential[0] == 0.0 and r.kinetic[0] == 0.0
    assert ac.weight / 25.0 < drag < ac.weight / 10.0  # a glider's L/D: between 10 and 25 at these speeds


@pytest.mark.parametrize("turn", [-1080.0, -360.0, 180.0, 720.0, 1080.0])
def test_level_turn_fuel_closed_form(library: PrimitiveLibrary, primitive_index: FindPrimitive, turn: float) -> None:
    ac = Aircraft()
    i = primitive_index(library, "spiral", 20.0, 0.0, turn)
    r = rollout([0.0, 0.0, 0.0, 500.0], WindField(), ac, primitive=i)
    phi = math.atan(20.0 * abs(math.radians(turn) / library.duration) / G)
    expected = trim_drag(ac, 20.0, 0.0, phi, 500.0) * 20.0 * library.duration / (ac.mass * 0.8)
    assert r.fuel[0] == pytest.approx(expected, rel=1e-10)
    assert r.max_bank[0] == pytest.approx(phi, rel=1e-12)


def test_climb_fuel_matches_quadrature() -> None:
    """A straight 15 deg climb: the fuel is the time integral of T v / (m eta) with density varying
    with height (checked against a fine trapezoid of the closed-form thrust)."""
    ac = Aircraft(eta_ec=0.7, eta_p=0.9)
    lib = PrimitiveLibrary()
    for i in (3, 4, 8, 9):  # +15 and +45 deg at 10 and 20 m/s (order pinned in test_primitives)
        _, v, gam, _, _ = lib.table[i]
        r = rollout([0.0, 0.0, 0.0, 200.0], WindField(), ac, primitive=i)
        t = np.linspace(0.0, lib.duration, 200001)
        h = 200.0 + v * math.sin(gam) * t
        qs = 0.5 * isa_density(h) * v * v * ac.wing_area
        cl = ac.weight * math.cos(gam) / qs
        thrust = qs * (ac.cd0 + cl**2 / (math.pi * ac.aspect_ratio * ac.oswald)) + ac.weight * math.sin(gam)
        y = thrust * v / (ac.mass * ac.eta_ec * ac.eta_p)
        expected = float(np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(t)))
        assert r.fuel[0] == pytest.approx(expected, rel=1e-5)
        assert r.potential[0] == pytest.approx(-G * v * math.sin(gam) * lib.duration, rel=1e-12)


@pytest.mark.parametrize("thrust_model", ["trim", "paper"])
@pytest.mark.parametrize(("duration", "n_points"), [(30.0, 30), (300.0, 7), (600.0, 2)])
def test_fuel_is_the_trapezoid_over_the_points(thrust_model: str, duration: float, n_points: int) -> None:
    """The propulsive energy is the trapezoid rule over the edge's own points, each control segment
    with its own bank: checked against ``Aircraft.thrust`` (the exact ISA density) at the heights the
    rollout returns. Climbs of 300 s and 600 s span more than 2 km, past the density series."""
    ac = Aircraft(thrust_model=thrust_model)
    lib = PrimitiveLibrary(duration=duration, n_points=n_points)
    field = WindField(thermals=(Thermal(150.0, 0.0, strength=3.0),), zi=1400.0)
    h0 = 200.0
    span = 0.0
    for i in (4, 9, 150, 160, 172, 40):  # 45 deg climbs, splines (two banks), a spiral
        _, v, gam, rate1, rate2 = lib.table[i]
        r = rollout([0.0, 0.0, 0.3, h0], field, ac, primitive=i, library=lib)
        h = np.concatenate([[h0], r.states[0, :, 3]])
        k_switch = n_points // 2
        bank = np.where(np.arange(n_points) < k_switch, math.atan(v * abs(rate1) / G), math.atan(v * abs(rate2) / G))
        per = v / (ac.mass * ac.eta_ec * ac.eta_p)
        mean = 0.5 * (ac.thrust(v, gam, bank, h[:-1]) + ac.thrust(v, gam, bank, h[1:])) * per
        assert r.fuel[0] == pytest.approx(float(np.sum(mean)) * duration / n_points, rel=1e-12, abs=1e-12)
        span = max(span, float(np.ptp(h)))
    assert span > 2000.0 or duration == 30.0  # the long climbs leave the density series' range


@pytest.mark.parametrize("index", [0, 1, 5, 6, 10, 11, 41, 70, 71, 146, 145])
def test_glide_costs_exactly_potential(library: PrimitiveLibrary, index: int) -> None:
    """Descending at -15 / -45 deg the required thrust D + m g sin(gamma) is negative and clipped to
    zero: no fuel, and the cost is exactly g times the height lost."""
    ac = Aircraft()
    _, v, gam, rate, _ = library.table[index]
    assert gam < 0.0
    phi = math.atan(v * abs(rate) / G)
    assert float(ac.thrust(v, gam, phi, 600.0)) == 0.0
    assert trim_drag(ac, v, gam, phi, 600.0) + ac.weight * math.sin(gam) < 0.0
    r = rollout([0.0, 0.0, 0.0, 600.0], WindField(), ac, primitive=index)
    h1 = r.final[0, 3]
    assert r.fuel[0] == 0.0
    assert r.cost[0] == r.potential[0]
    assert r.cost[0] == pytest.approx(G * (600.0 - h1), rel=1e-12)
    assert h1 < 600.0 and r.cost[0] > 0.0  # losing height spends potential energy


def test_climbing_in_thermal_core_costs_less_than_zero(
    library: PrimitiveLibrary, primitive_index: FindPrimitive
) -> None:
    ac = Aircraft()
    i = primitive_index(library, "spiral", 10.0, 0.0, 1080.0)
    rate = math.radians(1080.0) / library.duration
    radius = 10.0 / rate  # ~15.9 m, well inside the core
    field = WindField(thermals=(Thermal(800.0, -300.0, strength=3.5),), zi=1400.0)
    start = [800.0, -300.0 - radius, 0.0, 300.0]  # heading north, turning right: centre due east
    r = rollout(start, field, ac, primitive=i)
    dist = np.hypot(r.states[0, :, 0] - 800.0, r.states[0, :, 1] + 300.0)
    np.testing.assert_allclose(dist, radius, atol=1e-6)
    gain = r.final[0, 3] - 300.0
    assert gain > 60.0  # ~3.7 m/s for 30 s
    assert r.fuel[0] > 0.0
    assert r.cost[0] < 0.0
    assert r.cost[0] == pytest.approx(r.fuel[0] - G * gain, rel=1e-12)
    # the same spiral in still air costs fuel only
    calm = rollout(start, WindField(), ac, primitive=i)
    assert calm.cost[0] == pytest.approx(calm.fuel[0], rel=1e-12) and calm.cost[0] > 0.0


def test_kinetic_term() -> None:
    fast, slow = 7, 2  # level straight at 20 and 10 m/s
    for ac in (Aircraft(), Aircraft(eta_ec=0.5, eta_p=0.9)):
        eta = ac.eta_ec * ac.eta_p
        x = [0.0, 0.0, 0.0, 400.0]
        up = rollout(x, WindField(), ac, primitive=fast, airspeed_prev=10.0)
        assert up.kinetic[0] == pytest.approx(0.5 * (20.0**2 - 10.0**2) / eta, rel=1e-14)
        assert up.cost[0] == pytest.approx(up.fuel[0] + up.potential[0] + up.kinetic[0], rel=1e-14)
        assert rollout(x, WindField(), ac, primitive=slow, airspeed_prev=20.0).kinetic[0] == 0.0
        assert rollout(x, WindField(), ac, primitive=fast, airspeed_prev=20.0).kinetic[0] == 0.0
        assert rollout(x, WindField(), ac, primitive=fast).kinetic[0] == 0.0
        assert rollout(x, WindField(), ac, primitive=fast, airspeed_prev=math.nan).kinetic[0] == 0.0
        ctl = rollout(x, WindField(), ac, control=[17.5, 0.0, 0.0], airspeed_prev=12.0)
        assert ctl.kinetic[0] == pytest.approx(0.5 * (17.5**2 - 12.0**2) / eta, rel=1e-14)
        batch = rollout([x, x, x], WindField(), ac, primitive=[fast, slow, fast], airspeed_prev=[10.0, 20.0, np.nan])
        np.testing.assert_allclose(batch.kinetic, [0.5 * 300.0 / eta, 0.0, 0.0], rtol=1e-14)


def test_bank_angle_of_tightest_spiral(library: PrimitiveLibrary, primitive_index: FindPrimitive) -> None:
    rate = math.radians(1080.0) / 30.0
    assert math.degrees(float(bank_angle(20.0, rate))) == pytest.approx(52.0, abs=0.1)
    assert math.degrees(float(bank_angle(20.0, -rate))) == pytest.approx(-52.0, abs=0.1)
    for turn in (1080.0, -1080.0):
        i = primitive_index(library, "spiral", 20.0, 0.0, turn)
        r = rollout([0.0, 0.0, 0.0, 500.0], WindField(), Aircraft(), primitive=i)
        assert math.degrees(r.max_bank[0]) == pytest.approx(52.0, abs=0.1)
    # at Ts = 20 s it would need ~62 deg (physics.md)
    assert math.degrees(float(bank_angle(20.0, math.radians(1080.0) / 20.0))) == pytest.approx(62.5, abs=0.5)
    assert float(bank_angle(20.0, 0.0)) == 0.0


def test_aircraft_thrust_closed_forms() -> None:
    ac = Aircraft()
    assert ac.weight == pytest.approx(6.40 * G)
    assert ac.span == pytest.approx(3.32, abs=0.01)
    for v, gam, phi, h in [(10.0, 0.0, 0.0, 0.0), (20.0, 0.2, 0.5, 800.0), (15.0, -0.05, 0.9, 300.0)]:
        t = trim_drag(ac, v, gam, phi, h) + ac.weight * math.sin(gam)
        assert float(ac.thrust(v, gam, phi, h)) == pytest.approx(max(t, 0.0), rel=1e-12)
        assert float(ac.fuel_power(v, gam, phi, h)) == pytest.approx(max(t, 0.0) * v / (ac.mass * 0.8), rel=1e-12)
    # "paper" model: fixed C_L0, thrust magnitude sqrt(T_x^2 + T_z^2)
    pa = Aircraft(thrust_model="paper", cl0=0.5)
    for v, gam, phi, h in [(10.0, 0.0, 0.0, 0.0), (20.0, 0.2, 0.5, 800.0), (20.0, -0.7, 0.9, 300.0)]:
        qs = 0.5 * float(isa_density(h)) * v * v * pa.wing_area
        drag = qs * (pa.cd0 + 0.25 / (math.pi * pa.aspect_ratio * pa.oswald))
        tx = drag + pa.weight * math.sin(gam)
        tz = qs * 0.5 - pa.weight * math.cos(gam) / math.cos(phi)
        assert float(pa.thrust(v, gam, phi, h)) == pytest.approx(math.hypot(tx, tz), rel=1e-12)
    # broadcasting
    assert ac.thrust([10.0, 20.0], 0.0, 0.0, [0.0, 100.0]).shape == (2,)


def test_paper_thrust_model_differs_and_is_finite(library: PrimitiveLibrary) -> None:
    field = WindField(thermals=(Thermal(300.0, 0.0, 2.5),))
    x = np.array([0.0, 0.0, 0.0, 400.0])
    trim = rollout(x, field, Aircraft(), primitive=np.arange(174))
    paper = rollout(x, field, Aircraft(thrust_model="paper"), primitive=np.arange(174))
    assert np.all(np.isfinite(paper.fuel)) and np.all(np.isfinite(paper.cost))
    assert np.all(paper.fuel >= 0.0)
    assert np.count_nonzero(paper.fuel != trim.fuel) > 150
    np.testing.assert_array_equal(paper.states, trim.states)  # the thrust model does not move the aircraft
    np.testing.assert_array_equal(paper.potential, trim.potential)


# ----------------------------------------------------------------------------------------------
# Validation
# ----------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("kwargs", "pattern"),
    [
        ({"mass": 0.0}, r"mass=0\.0"),
        ({"mass": -6.4}, r"mass=-6\.4"),
        ({"mass": math.nan}, r"mass=nan"),
        ({"mass": math.inf}, r"mass=inf"),
        ({"wing_area": 0.0}, r"wing_area=0\.0"),
        ({"wing_area": -1.0}, r"wing_area=-1\.0"),
        ({"wing_area": math.nan}, r"wing_area=nan"),
        ({"aspect_ratio": 0.0}, r"aspect_ratio=0\.0"),
        ({"aspect_ratio": math.inf}, r"aspect_ratio=inf"),
        ({"oswald": 0.0}, r"oswald=0\.0"),
        ({"oswald": 1.5}, r"oswald=1\.5"),
        ({"oswald": math.nan}, r"oswald=nan"),
        ({"cd0": -0.01}, r"cd0=-0\.01"),
        ({"cd0": math.nan}, r"cd0=nan"),
        ({"cl0": 0.0}, r"cl0=0\.0"),
        ({"cl0": math.inf}, r"cl0=inf"),
        ({"eta_ec": 0.0}, r"eta_ec=0\.0"),
        ({"eta_ec": 1.2}, r"eta_ec=1\.2"),
        ({"eta_ec": math.nan}, r"eta_ec=nan"),
        ({"eta_p": -0.5}, r"eta_p=-0\.5"),
        ({"eta_p": math.inf}, r"eta_p=inf"),
        ({"stall_speed": 0.0}, r"stall_speed=0\.0"),
        ({"thrust_model": "jet"}, r"thrust_model='jet'"),
        ({"thrust_model": "Trim"}, r"thrust_model='Trim'"),
    ],
)
def test_aircraft_validation(kwargs: dict[str, object], pattern: str) -> None:
    with pytest.raises(ConfigError, match=pattern):
        Aircraft(**kwargs)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("kwargs", "pattern"),
    [
        ({"north": math.nan, "east": 0.0}, r"thermal\.north=nan"),
        ({"north": 0.0, "east": math.inf}, r"thermal\.east=inf"),
        ({"north": 0.0, "east": 0.0, "strength": 0.0}, r"thermal\.strength=0\.0"),
        ({"north": 0.0, "east": 0.0, "strength": -2.0}, r"thermal\.strength=-2\.0"),
        ({"north": 0.0, "east": 0.0, "strength": math.nan}, r"thermal\.strength=nan"),
        ({"north": 0.0, "east": 0.0, "radius": 0.0}, r"thermal\.radius=0\.0"),
        ({"north": 0.0, "east": 0.0, "radius": -5.0}, r"thermal\.radius=-5\.0"),
        ({"north": 0.0, "east": 0.0, "radius": math.inf}, r"thermal\.radius=inf"),
    ],
)
def test_thermal_validation(kwargs: dict[str, float], pattern: str) -> None:
    with pytest.raises(ConfigError, match=pattern):
        Thermal(**kwargs)


@pytest.mark.parametrize(
    ("kwargs", "pattern"),
    [
        ({"zi": 0.0}, r"zi=0\.0"),
        ({"zi": -100.0}, r"zi=-100\.0"),
        ({"zi": math.nan}, r"zi=nan"),
        ({"zi": math.inf}, r"zi=inf"),
        ({"model": "gauss"}, r"model='gauss'"),
        ({"model": "Allen"}, r"model='Allen'"),
        ({"wind_north": math.nan}, r"wind_north=nan"),
        ({"wind_east": -math.inf}, r"wind_east=-inf"),
        ({"drift": "yes"}, r"drift='yes'"),
        ({"thermals": ((0.0, 0.0, 2.0),)}, r"thermals\[0\]"),
    ],
)
def test_wind_field_validation(kwargs: dict[str, object], pattern: str) -> None:
    with pytest.raises(ConfigError, match=pattern):
        WindField(**kwargs)  # type: ignore[arg-type]


def test_config_error_is_value_error() -> None:
    assert issubclass(ConfigError, ValueError)
    with pytest.raises(ValueError):
        Aircraft(mass=-1.0)


@settings(deadline=None)
@given(
    d=st.floats(0.0, 400.0),
    z=st.floats(-100.0, 3000.0),
    zi=st.floats(200.0, 2500.0),
)
def test_within_allen_reach_is_the_cube_root_free_reach_test(d: float, z: float, zi: float) -> None:
    """The rollout's cube-root-free test decides ``d < 2 r2(z)`` exactly as the closed form does
    (away from a rounding-width band at the boundary), and 2 r2 bounds the updraft's support."""
    reach = allen_reach(z, zi)
    assume(abs(d - reach) > 1e-9 * reach)
    assert within_allen_reach(d, z, zi) == (d < reach)
    if d > reach * (1.0 + 1e-9) and z < zi:
        assert float(WindField(thermals=(Thermal(0.0, 0.0, 3.0),), zi=zi).updraft(d, 0.0, z)) == 0.0


@given(x=st.floats(1e-12, 1e3), y=st.sampled_from([1.0 / 3.0, *ALLEN_SHAPE[:, 2]]))
def test_fast_pow_matches_pow(x: float, y: float) -> None:
    """exp(y log x) stands in for libm's pow in the updraft: relative error ~ |y ln x| 2^-53."""
    exact = x**y
    assume(1e-300 < exact < 1e300)
    assert _pow(x, y) == pytest.approx(exact, rel=4.0 * max(1.0, abs(y * math.log(x))) * 2.0**-53)
    assert _pow(0.0, y) == 0.0


@settings(max_examples=50, deadline=None)
@given(
    v=st.floats(8.0, 25.0),
    deg=st.floats(1.0, 20.0),
    along=st.floats(-6.0, 6.0),
    cross=st.floats(-6.0, 6.0),
    dist=st.floats(1.0, 1e4),
)
def test_glide_height_loss_closed_form(v: float, deg: float, along: float, cross: float, dist: float) -> None:
    """Sink rate over ground speed: in still air ``d tan|gamma|``; crabbing into a crosswind the
    ground speed along the track is ``sqrt(va^2 - c^2) + w``; no headway: inf."""
    from soaring_env.physics import glide_height_loss

    g = -math.radians(deg)
    still = float(glide_height_loss(dist, v, g, 0.0, 0.0))
    assert still == pytest.approx(dist * math.tan(-g), rel=1e-12)
    va = v * math.cos(g)
    ground = math.sqrt(max(va * va - cross * cross, 0.0)) + along
    got = float(glide_height_loss(dist, v, g, along, cross))
    if ground > 0.1:
        assert got == pytest.approx(dist * v * math.sin(-g) / ground, rel=1e-12)
        if abs(ground - va) > 1e-6:  # a headwind or a crosswind costs height, a tailwind saves it
            assert (got > still) == (ground < va)
    else:
        assert got == math.inf
    # broadcast over airspeeds: one row per track
    many = glide_height_loss(dist, np.array([v, v + 1.0]), np.array([g, g]), along, cross)
    assert many.shape == (2,) and float(many[0]) == got


def test_glide_height_loss_refuses_bad_input() -> None:
    """Strings and non-finite values are refused with a ConfigError naming the argument."""
    from soaring_env import ConfigError
    from soaring_env.physics import glide_height_loss

    with pytest.raises(ConfigError, match="distance"):
        glide_height_loss("far", 15.0, -0.05, 0.0, 0.0)
    with pytest.raises(ConfigError, match="along"):
        glide_height_loss(1.0, 15.0, -0.05, math.nan, 0.0)
    with pytest.raises(ConfigError, match="airspeed"):
        glide_height_loss(1.0, [15.0, math.inf], -0.05, 0.0, 0.0)
