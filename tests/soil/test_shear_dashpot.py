"""The viscous shear dashpot (``Material.shear_restitution``): a sticking contact's tangential
motion is the damped oscillator of its shear spring and dashpot, a sliding contact is not
damped by it, a body's reaction includes it, and its work is booked in
``dissipated_viscous``."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

import soil
from soil.contact_laws import damping_ratio, hertz_coefficients

E = 2e7  # [Pa]
RHO = 2650.0  # [kg/m^3]
R = 0.05  # [m]
G = 9.81  # [m/s^2]
M = 4.0 / 3.0 * math.pi * R**3 * RHO
#: friction angle of the sticking tests: the Coulomb limit (tan 1.4 = 5.8 x the weight) stays
#: above the oscillation's largest spring force (about 0.4 x the weight at V0)
PHI_STICK = 1.4
V0 = 0.02  # [m/s]
#: leapfrog steps per undamped shear period
STEPS = 400


def mat(phi, **kw):
    return soil.Material(young=E, density=RHO, friction_angle=phi, stiffness_ratio=0.25, **kw)


def _oscillator(m, ks, cs, v0, t):
    """Independent closed form: m x'' + cs x' + ks x = 0 from x = 0, x' = v0 (underdamped);
    returns (x, x') at times ``t``."""
    w0 = math.sqrt(ks / m)
    z = cs / (2.0 * math.sqrt(m * ks))
    wd = w0 * math.sqrt(1.0 - z * z)
    a = z * w0
    x = v0 / wd * np.exp(-a * t) * np.sin(wd * t)
    v = v0 * np.exp(-a * t) * (np.cos(wd * t) - a / wd * np.sin(wd * t))
    return x, v


def _resting_sphere(material, pair, overlap, dt, v0):
    """A grain resting on a plane (``pair`` False) or on a fixed grain (True) at its static
    ``overlap`` under gravity, moving at ``v0`` along x at t = 0, stepped by ``dt``; returns
    (sim, index of the moving grain)."""
    if pair:
        p = soil.Particles(x=[[0.0, 0.0, 0.0], [0.0, 0.0, 2 * R - overlap]], radius=R,
                           v=[[0.0, 0.0, 0.0], [v0, 0.0, 0.0]])
        bodies = []
        i = 1
    else:
        p = soil.Particles(x=[[0.0, 0.0, R - overlap]], radius=[R], v=[[v0, 0.0, 0.0]])
        bodies = [soil.BoundaryBody(shapes=[soil.Plane()])]
        i = 0
    sim = soil.Simulation(p, [material], bodies, gravity=(0, 0, -G), dt=dt)
    if pair:
        # the lower grain held fixed (infinite mass and inertia), without the start's half kick
        sim.particles.inv_mass[0] = 0.0
        sim.particles.inv_inertia[0] = 0.0
        sim.particles.v[0] = 0.0
    return sim, i


def _run(sim, i, n):
    x0 = sim.particles.x[i, 0]
    v, _w = sim.synchronized_velocity()
    t = [0.0]
    xs = [0.0]
    vs = [v[i, 0]]
    for _ in range(n):
        sim.step()
        v, _w = sim.synchronized_velocity()
        t.append(sim.time)
        xs.append(sim.particles.x[i, 0] - x0)
        vs.append(v[i, 0])
    return np.array(t), np.array(xs), np.array(vs)


@pytest.mark.parametrize("law", ["linear", "hertz_mindlin"])
@pytest.mark.parametrize("pair", [False, True], ids=["grain-plane", "grain-grain"])
@pytest.mark.parametrize("e_s", [0.3, 0.7])
def test_sticking_shear_is_the_damped_oscillator(law, pair, e_s):
    """Oracle: closed form of the damped oscillator m x'' + c_s x' + k_s x = 0 of the grain's
    tangential motion under a constant normal load (rotations blocked, no sliding), with
    c_s = 2 zeta(e_s) sqrt(m* k_s) for the linear law and 2 sqrt(5/6) zeta sqrt(m* k_s,t) for
    Hertz-Mindlin, m* the contact's reduced mass (m on a plane, m / 2 between two equal grains,
    one held fixed). On a plane with the linear law the velocity half a damped period later is
    exactly -e_s V0 (the shear restitution); 1 % of the amplitude over three periods and 0.005 in
    that ratio are leapfrog's error at 400 steps per period. The dashpot's work is booked in
    dissipated_viscous (1 %), and energy balances."""
    material = mat(PHI_STICK, contact_law=law, shear_restitution=e_s)
    m_eff = 0.5 * M if pair else M
    r_eff = 0.5 * R if pair else R
    if law == "linear":
        ks = 0.25 * E * R
        overlap = M * G / (E * R)
        cs = 2.0 * damping_ratio(e_s) * math.sqrt(m_eff * ks)
    else:
        kno, kso = hertz_coefficients(E, 0.25, E, 0.25, r_eff)
        overlap = (M * G / kno) ** (2.0 / 3.0)
        ks = kso * math.sqrt(overlap)
        cs = 2.0 * math.sqrt(5.0 / 6.0) * damping_ratio(e_s) * math.sqrt(m_eff * ks)
    period = 2.0 * math.pi * math.sqrt(M / ks)
    sim, i = _resting_sphere(material, pair, overlap, period / STEPS, V0)
    t, x, v = _run(sim, i, 3 * STEPS)
    x_ref, v_ref = _oscillator(M, ks, cs, V0, t)
    amp = V0 * math.sqrt(M / ks)
    assert np.max(np.abs(x - x_ref)) < 0.01 * amp
    assert np.max(np.abs(v - v_ref)) < 0.01 * V0
    # the contact stuck throughout: the spring force stayed below the Coulomb limit
    assert ks * np.max(np.abs(x)) < 0.5 * math.tan(PHI_STICK) * M * G
    if law == "linear" and not pair:
        zeta = damping_ratio(e_s)
        t_half = math.pi / (math.sqrt(ks / M) * math.sqrt(1.0 - zeta * zeta))
        assert np.interp(t_half, t, v) / V0 == pytest.approx(-e_s, abs=5e-3)
    en = sim.energy()
    ke0 = 0.5 * M * V0**2
    assert en["dissipated_viscous"] == pytest.approx(ke0 - 0.5 * M * v[-1] ** 2
                                                     - 0.5 * ks * x[-1] ** 2, rel=1e-2)
    assert en["dissipated_viscous"] > 0.5 * ke0
    assert abs(en["balance_error"]) < 1e-2 * ke0


@pytest.mark.parametrize("law", ["linear", "hertz_mindlin"])
def test_a_sliding_contact_is_not_damped_by_the_shear_dashpot(law):
    """Oracle: Coulomb sliding, identical trajectories. A grain sliding on a plane decelerates
    at mu g whether or not its material has a shear dashpot (the dashpot acts while the contact
    sticks, as Yade's ViscElPhys and MindlinPhys): the two runs are the same bit for bit while
    it slides, and the dashpot has done no work."""
    phi = 0.1
    u0 = 1.0
    dt = 5e-5
    runs = []
    for e_s in (None, 0.2):
        material = mat(phi, contact_law=law, shear_restitution=e_s)
        if law == "linear":
            overlap = M * G / (E * R)
        else:
            kno, _kso = hertz_coefficients(E, 0.25, E, 0.25, R)
            overlap = (M * G / kno) ** (2.0 / 3.0)
        sim, i = _resting_sphere(material, False, overlap, dt, u0)
        stop = u0 / (math.tan(phi) * G)
        n = int(0.8 * stop / dt)
        xs = []
        for _ in range(n):
            sim.step()
            xs.append(sim.particles.x[i].copy())
        runs.append((np.array(xs), sim.energy()))
    (x0, _e0), (x1, e1) = runs
    np.testing.assert_array_equal(x0, x1)
    assert e1["dissipated_viscous"] == 0.0
    # it did slide: its speed fell as mu g t
    t = dt * len(x0)
    v_end = (x0[-1, 0] - x0[-2, 0]) / dt
    assert v_end == pytest.approx(u0 - math.tan(phi) * G * t, abs=2e-3)


def test_shear_dashpot_balances_energy():
    """Oracle: conservation of energy in a free cloud with free rotations, friction, rolling
    resistance and both dashpots (1 % of the initial energy), with the shear dashpot's work in
    dissipated_viscous, which exceeds the normal dashpot's alone on the same cloud (Newton's
    third law with it: ``test_engine.py::test_internal_forces_sum_to_zero``)."""
    rng = np.random.default_rng(5)
    n = 60
    x = rng.uniform(0, 0.35, (n, 3))
    r = rng.uniform(0.04, 0.06, n)
    v = rng.normal(0, 0.5, (n, 3))
    w = rng.normal(0, 5, (n, 3))
    visc = []
    for e_s in (None, 0.3):
        m0 = mat(0.5, restitution=0.5, rolling=soil.Rolling(0.1), shear_restitution=e_s)
        p = soil.Particles(x=x, radius=r, rotation_blocked=False, v=v, w=w)
        sim = soil.Simulation(p, [m0], gravity=(0, 0, 0))
        e_start = sim.energy()
        total0 = (e_start["kinetic_translational"] + e_start["kinetic_rotational"]
                  + e_start["elastic"])
        sim.step(60)
        en = sim.energy()
        assert abs(en["balance_error"]) < 1e-2 * total0
        visc.append(en["dissipated_viscous"])
    assert visc[1] > 1.05 * visc[0]


def test_shear_dashpot_on_a_rigid_body_and_its_reaction():
    """Oracle: action and reaction between grains and a boundary body: the force the grains put
    on the plane (``BoundaryBody.force``) is minus the sum of the body contacts' forces on the
    grains, with the shear dashpot's (``contacts()["fs"]``: spring plus dashpot), which is
    not zero while the grains stick and slow down."""
    rng = np.random.default_rng(2)
    n = 12
    # each grain at its static overlap under its weight (linear springs: k_n = E R)
    x = np.column_stack([(np.arange(n) + 0.5) * 3 * R, rng.uniform(0, 1, n),
                         np.full(n, R - M * G / (E * R))])
    v = np.column_stack([rng.normal(0, 0.02, (n, 2)), np.zeros(n)])
    plane = soil.BoundaryBody(shapes=[soil.Plane()])
    p = soil.Particles(x=x, radius=R, v=v)
    sim = soil.Simulation(p, [mat(PHI_STICK, shear_restitution=0.2)], [plane],
                          gravity=(0, 0, -G))
    sim.step(30)
    c = sim.contacts()
    body = c["j"] == -1
    assert body.sum() == n
    on_grains = (c["fn"][body, None] * c["normal"][body] + c["fs"][body]).sum(axis=0)
    np.testing.assert_allclose(plane.force, -on_grains, rtol=1e-12, atol=1e-9)
    shear = np.linalg.norm(c["fs"][body], axis=1)
    assert np.all(shear > 0)
    # the dashpot's part: the same run without it has other shear forces
    p2 = soil.Particles(x=x, radius=R, v=v)
    plane2 = soil.BoundaryBody(shapes=[soil.Plane()])
    sim2 = soil.Simulation(p2, [mat(PHI_STICK)], [plane2], gravity=(0, 0, -G))
    sim2.step(30)
    assert not np.allclose(sim2.contacts()["fs"], c["fs"], rtol=1e-3, atol=0)


def test_shear_restitution_one_is_no_dashpot_bit_for_bit():
    """Oracle: identity. ``shear_restitution=1`` (zero damping ratio) runs the same as None."""
    rng = np.random.default_rng(9)
    n = 40
    x = rng.uniform(0, 0.3, (n, 3))
    r = rng.uniform(0.04, 0.06, n)
    v = rng.normal(0, 0.3, (n, 3))
    out = []
    for e_s in (None, 1.0):
        p = soil.Particles(x=x, radius=r, rotation_blocked=False, v=v)
        sim = soil.Simulation(p, [mat(0.5, restitution=0.4, shear_restitution=e_s)],
                              [soil.BoundaryBody(shapes=[soil.Plane()])], gravity=(0, 0, -G))
        sim.step(200)
        out.append(sim.particles.x.copy())
    np.testing.assert_array_equal(out[0], out[1])


@pytest.mark.parametrize("value", [0.0, -0.2, 1.5, float("nan")])
def test_bad_shear_restitution_named(value):
    """Oracle: parameter contract (field, value and allowed range in the message)."""
    with pytest.raises(ValueError, match=re.escape("Material.shear_restitution=")) as ei:
        mat(0.5, shear_restitution=value)
    assert "(0, 1] or None" in str(ei.value) or "finite" in str(ei.value)
