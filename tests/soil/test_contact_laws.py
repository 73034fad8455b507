"""Scalar contact laws, each checked alone against its formula or an analytic property."""

from __future__ import annotations

import math
import sys

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from soil import contact_laws as cl

moduli = st.floats(1e5, 1e11)
radii = st.floats(1e-3, 1.0)
ratios = st.one_of(st.just(0.0), st.floats(1e-6, 1.0))  # 0 pinned; tiny ratios underflow a*b
REL = 1e-12  # pure floating-point re-association of a few products
# first call loads the Numba cache from disk: no per-example deadline
HYP = settings(deadline=None, max_examples=50)


@HYP
@given(moduli, radii)
def test_equal_spheres_kn_is_E_r(e, r):
    """Oracle: thesis eq. 3.6 / anchors section 8 (Yade live contacts): equal spheres give
    k_n = E r; a wall with the sphere radius on its side gives the same, a facet (2r) 4/3 E r."""
    assert cl.normal_stiffness(e, r, e, r) == pytest.approx(e * r, rel=REL)
    assert cl.normal_stiffness(e, 2 * r, e, r) == pytest.approx(4.0 / 3.0 * e * r, rel=REL)


@HYP
@given(moduli, radii, moduli, radii)
def test_kn_series_springs(e1, r1, e2, r2):
    """Oracle: two springs k1 = 2 E1 R1, k2 = 2 E2 R2 in series: 1/k = 1/k1 + 1/k2."""
    k = cl.normal_stiffness(e1, r1, e2, r2)
    assert k == pytest.approx(1.0 / (1.0 / (2 * e1 * r1) + 1.0 / (2 * e2 * r2)), rel=1e-10)
    assert k == cl.normal_stiffness(e2, r2, e1, r1)


@HYP
@given(moduli, radii, moduli, radii, ratios)
def test_ks_equal_ratio(e1, r1, e2, r2, nu):
    """Oracle: Yade series form with equal ks/kn ratio nu gives k_s = nu k_n."""
    ks = cl.shear_stiffness(e1, r1, nu, e2, r2, nu)
    assert ks == pytest.approx(nu * cl.normal_stiffness(e1, r1, e2, r2), rel=1e-10, abs=0.0)


@HYP
@given(st.floats(0.01, 0.999))
def test_damping_ratio_reproduces_restitution(e):
    """Oracle: analytic damped linear oscillator: e = exp(-zeta pi / sqrt(1 - zeta^2))."""
    z = cl.damping_ratio(e)
    assert math.exp(-z * math.pi / math.sqrt(1 - z * z)) == pytest.approx(e, rel=1e-12)
    assert cl.damping_ratio(1.0) == 0.0


def _no_tension_rebound_ode(zeta):
    """Independent oracle: scipy integration of x'' = -x - 2 zeta x' from x = 0, x' = 1 until
    the force x + 2 zeta x' first crosses 0 downwards; |x'| there."""
    from scipy.integrate import solve_ivp

    def release(t, y):
        return y[0] + 2.0 * zeta * y[1]

    release.terminal = True
    release.direction = -1
    sol = solve_ivp(lambda t, y: [y[1], -y[0] - 2.0 * zeta * y[1]], [0.0, 200.0], [0.0, 1.0],
                    events=release, rtol=1e-12, atol=1e-14, first_step=1e-9)
    return abs(sol.y_events[0][0][1])


@settings(deadline=None, max_examples=30)
@given(st.floats(1e-3, 8.0))
@example(1.0)
@example(1.0 - 1e-9)
@example(1.0 + 1e-9)
def test_no_tension_restitution_matches_the_ode(zeta):
    """Oracle: ODE of the linear spring-dashpot released when its force would pull, in the
    under-, critically and over-damped branches (the three closed forms join at zeta = 1)."""
    assert cl.no_tension_restitution(zeta) == pytest.approx(_no_tension_rebound_ode(zeta),
                                                            rel=1e-7, abs=1e-12)


def test_no_tension_restitution_exceeds_the_nominal_one():
    """Oracle: the force-free release comes before the overlap closes, so the rebound is
    faster than the nominal restitution (full oscillator) and tends to it as zeta -> 0;
    monotonic in the damping; refused outside [0, inf)."""
    es = np.linspace(0.02, 0.99, 60)
    reb = [cl.no_tension_restitution(cl.damping_ratio(e)) for e in es]
    assert all(r > e for r, e in zip(reb, es))
    assert np.all(np.diff(reb) > 0)
    assert cl.no_tension_restitution(cl.damping_ratio(0.999)) == pytest.approx(0.999, abs=1e-4)
    assert cl.no_tension_restitution(0.0) == 1.0
    for bad in (-0.1, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="zeta"):
            cl.no_tension_restitution(bad)
    assert cl.rebound_restitution(0.2) == cl.no_tension_restitution(cl.damping_ratio(0.2))
    assert cl.rebound_restitution(1.0) == 1.0
    for bad in (0.0, -0.5, 1.5, float("nan")):
        with pytest.raises(ValueError, match=r"restitution=.*\(0, 1\]"):
            cl.rebound_restitution(bad)


def test_damping_coefficient_and_duration():
    """Oracle: c = 2 zeta sqrt(m k); t_c = pi sqrt(m/k) (harmonic half period)."""
    assert cl.damping_coefficient(0.5, 2.0, 8.0) == pytest.approx(4.0, rel=REL)
    assert cl.contact_duration(1.0, math.pi**2) == pytest.approx(1.0, rel=REL)


# forces whose square underflows (|F| < 1e-154 N) are physically meaningless and excluded
force = st.floats(-1e3, 1e3).filter(lambda v: v == 0.0 or abs(v) > 1e-100)
# so are Coulomb limits of that size: a subnormal limit (5e-324 N, found by Hypothesis in a
# fresh CI database) caps |F| = 2 N to 0 (lim / |F| underflows), 5e-324 N off the limit
limit = st.floats(0.0, 1e3).filter(lambda v: v == 0.0 or v > 1e-100)


@HYP
@given(force, force, limit, st.floats(1.0, 1e6))
@example(416.7050794048648, 0.0625, 416.705078125, 1.0)  # |F| - limit = 1.5e-8 |F|
def test_coulomb_cap(fx, fy, lim, ks):
    """Oracle: Coulomb |F_s| <= limit, direction kept; Yade plastic dissipation
    ((trial - capped)/ks) . capped >= 0, equal to (|F| - limit) limit / ks to 1e-9 relative or
    the rounding of the difference trial - capped, a few ulp of |F| times limit / ks (found by
    Hypothesis: |F| - limit = 1.5e-8 |F| left 4.3e-12 J of 2.5e-3 J, 0.1 eps |F| limit / ks)."""
    gx, gy, gz, d, slipped = cl.coulomb_cap(fx, fy, 0.0, lim, ks)
    f = math.hypot(fx, fy)
    if f <= lim:
        assert (gx, gy, d, slipped) == (fx, fy, 0.0, False)
    else:
        assert math.hypot(gx, gy) == pytest.approx(lim, rel=1e-12, abs=1e-300)
        assert gx * fy - gy * fx == pytest.approx(0.0, abs=1e-9 * f * f)
        rounding = 4.0 * sys.float_info.epsilon * f * lim / ks
        assert d == pytest.approx((f - lim) * lim / ks, rel=1e-9, abs=rounding)
        assert slipped


def test_rotate_shear_follows_the_contact_frame():
    """Oracle: rigid rotation; rotating the contact normal by small steps about an axis (total
    angle a) carries a tangential spring along: the result stays tangent and matches the exactly
    rotated vector with an error that halves with the step (first-order update, Yade ScGeom)."""
    errs = []
    for nsteps in (100, 200, 400):
        a = 0.3
        f = np.array([1.0, 0.0, 0.0])
        n_prev = np.array([0.0, 0.0, 1.0])
        for k in range(1, nsteps + 1):
            th = a * k / nsteps
            n = np.array([0.0, -math.sin(th), math.cos(th)])  # rotation about x... and twist
            f = np.array(cl.rotate_shear(*f, *n_prev, *n, 0.0))
            n_prev = n
        assert abs(f @ n_prev) < 1e-14
        errs.append(abs(np.linalg.norm(f) - 1.0))
    # rotation about x keeps f = (1, 0, 0) exactly: magnitude drift must be round-off
    assert max(errs) < 1e-12
    # a rotation in the plane of f: f must turn with the normal
    f = np.array([1.0, 0.0, 0.0])
    n_prev = np.array([0.0, 0.0, 1.0])
    nsteps = 1000
    a = 0.2
    for k in range(1, nsteps + 1):
        th = a * k / nsteps
        n = np.array([math.sin(th), 0.0, math.cos(th)])
        f = np.array(cl.rotate_shear(*f, *n_prev, *n, 0.0))
        n_prev = n
    exact = np.array([math.cos(a), 0.0, -math.sin(a)])
    assert np.linalg.norm(f - exact) < 1e-3


def test_twist_rotates_about_normal():
    """Oracle: a twist angle t about n rotates a tangential vector by t (first order)."""
    t = 1e-4
    f = np.array(cl.rotate_shear(1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0, t))
    assert f == pytest.approx([1.0, t, 0.0], abs=1e-15)


def test_cohesive_normal_force_branches():
    """Oracle: Yade CohesionMoment normal law: F = kn (u - u_p) above -a_n; fragile break below
    (then no tension); plastic: F = -a_n and u_p = u + a_n/kn."""
    kn, an = 1e6, 100.0
    assert cl.cohesive_normal_force(kn, -5e-5, 0.0, an, False)[:3] == (-50.0, 0.0, False)
    fn, unp, broken, _w = cl.cohesive_normal_force(kn, -2e-4, 0.0, an, False)
    assert (fn, broken) == (0.0, True)
    fn, unp, broken, w = cl.cohesive_normal_force(kn, -2e-4, 0.0, an, True)
    assert fn == -an and not broken
    assert unp == pytest.approx(-2e-4 + an / kn, rel=REL)
    assert w == pytest.approx(an * abs(unp), rel=REL)


def test_cohesive_shear_cap_breaks_bond():
    """Oracle: |F_s| <= a_t + F_n tan(phi); exceeding it breaks a bonded contact and the limit
    falls to F_n tan(phi)."""
    gx, gy, gz, d, broken = cl.cohesive_shear_cap(90.0, 0.0, 0.0, 10.0, 0.5, 100.0, True, 1e5)
    assert (gx, broken) == (90.0, False)
    gx, gy, gz, d, broken = cl.cohesive_shear_cap(120.0, 0.0, 0.0, 10.0, 0.5, 100.0, True, 1e5)
    assert broken and gx == pytest.approx(5.0, rel=REL)


def test_rolling_stiffness_and_cap():
    """Oracle: Ai et al. (2011) type C: k_r = 2.25 k_n mu_r^2 R*^2; |M_r| <= mu_r R* |F_n|."""
    assert cl.rolling_stiffness(1e6, 0.1, 0.025) == pytest.approx(2.25 * 1e6 * 0.01 * 0.025**2)
    mx, my, mz, d = cl.moment_cap(3.0, 4.0, 0.0, 2.5, 10.0)
    assert math.hypot(mx, my) == pytest.approx(2.5, rel=REL)
    assert cl.moment_cap(3.0, 4.0, 0.0, -1.0, 10.0) == (3.0, 4.0, 0.0, 0.0)


@HYP
@given(st.floats(-10, 10), st.floats(-10, 10), st.floats(-1e-4, 1e-4), st.floats(-1e-4, 1e-4),
       st.floats(1e3, 1e7))
def test_spring_dissipation_zero_while_sticking(ox, oy, dux, duy, k):
    """Oracle: an elastic (uncapped) step stores exactly the trapezoidal work: D = 0."""
    fx, fy = ox - k * dux, oy - k * duy
    d = cl.spring_dissipation(ox, oy, 0.0, fx, fy, 0.0, dux, duy, 0.0, k)
    scale = (abs(ox) + abs(oy) + k * (abs(dux) + abs(duy))) ** 2 / k + 1e-300
    assert abs(d) <= 1e-12 * scale


def test_spring_dissipation_equals_yade_in_steady_sliding():
    """Oracle: steady sliding at the cap L: Yade's ((trial - capped)/k) . capped = L |du|."""
    k, lim, du = 1e5, 20.0, 1e-5
    trial = lim + k * du
    gx, _, _, d_yade, _ = cl.coulomb_cap(trial, 0.0, 0.0, lim, k)
    d = cl.spring_dissipation(lim, 0.0, 0.0, gx, 0.0, 0.0, -du, 0.0, 0.0, k)
    assert d == pytest.approx(lim * du, rel=1e-9)
    assert d_yade == pytest.approx(lim * du, rel=1e-9)
