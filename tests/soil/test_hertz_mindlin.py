"""The Hertz-Mindlin contact law (``Material.contact_law="hertz_mindlin"``): Hertz's impact
(duration, largest overlap, their speed dependence), Tsuji's damping against an independent ODE
solution, the energy ledger with the Mindlin shear spring and Thornton's unloading rule, Yade's
coefficients, and the refusals."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

import soil
from soil.contact_laws import (
    hertz_coefficients,
    hertz_contact_duration,
    hertz_max_overlap,
    varying_spring_dissipation,
)

E = 2e7  # [Pa]
RHO = 2650.0  # [kg/m^3]
R = 0.05  # [m]
NU = 0.25  # [-]
#: steps per Hertz contact: the onset is quantised by dt, so a duration by +-2 dt
STEPS_PER_CONTACT = 400


def hertz(phi=0.0, **kw):
    return soil.Material(young=E, density=RHO, friction_angle=phi, contact_law="hertz_mindlin",
                         poisson=NU, **kw)


def sphere_mass(r=R):
    return 4.0 / 3.0 * math.pi * r**3 * RHO


def e_star(nu=NU):
    """E* of two bodies of this material [Pa]."""
    return 1.0 / (2.0 * (1.0 - nu * nu) / E)


def _impact(sim, i_obs, axis, n_max):
    """Run one impact; returns (duration, largest overlap seen, v before, v after)."""
    v_before = sim.synchronized_velocity()[0][i_obs, axis]
    t0 = t1 = None
    dmax = 0.0
    for _ in range(n_max):
        sim.step()
        c = sim.contacts()
        if len(c["i"]):
            dmax = max(dmax, float(np.max(c["overlap"])))
            if t0 is None:
                t0 = sim.time
        elif t0 is not None:
            t1 = sim.time
            break
    assert t0 is not None and t1 is not None, "impact did not complete"
    return t1 - t0, dmax, v_before, sim.synchronized_velocity()[0][i_obs, axis]


def _wall_impact(v0, mat, steps=STEPS_PER_CONTACT):
    """A sphere onto a plane at ``v0``; returns (simulation, Hertz duration, dt, measured
    duration, largest overlap, v before, v after)."""
    m = sphere_mass()
    tc = hertz_contact_duration(m, e_star(), R, v0)
    dt = tc / steps
    p = soil.Particles(x=[[0.0, 0.0, R + 1e-6]], radius=[R], v=[[0.0, 0.0, -v0]])
    sim = soil.Simulation(p, [mat], [soil.BoundaryBody(shapes=[soil.Plane()])],
                          gravity=(0, 0, 0), dt=dt)
    dur, dmax, vb, va = _impact(sim, 0, 2, 10 * steps)
    return sim, tc, dt, dur, dmax, vb, va


@pytest.mark.parametrize("v0", [1.0, 4.0])
def test_hertz_wall_impact_duration_overlap_and_rebound(v0):
    """Oracle: Hertz's impact of a sphere on a plane (Johnson 1985, section 11.4): the largest
    overlap (15 m v^2 / (16 E* sqrt(R)))^(2/5) (0.1 %) and the duration 2.9432 delta_max / v
    (+-2 dt); both scale with v^(-1/5) and v^(4/5), which a linear spring (duration independent
    of v) cannot; undamped, the rebound is the impact speed (1e-3)."""
    sim, tc, dt, dur, dmax, vb, va = _wall_impact(v0, hertz())
    m = sphere_mass()
    assert dmax == pytest.approx(hertz_max_overlap(m, e_star(), R, v0), rel=1e-3)
    assert abs(dur - tc) <= 2 * dt
    assert abs(-va / vb - 1.0) < 1e-3
    assert abs(sim.energy()["balance_error"]) < 1e-4 * 0.5 * m * v0**2


def test_hertz_duration_falls_with_speed_and_linear_does_not():
    """Oracle: t_c(4 v) / t_c(v) = 4^(-1/5) = 0.758 for Hertz (2 %), 1 for the linear law with
    the same grains (2 %)."""
    _, _, _, d1, _, _, _ = _wall_impact(1.0, hertz())
    _, _, _, d4, _, _, _ = _wall_impact(4.0, hertz())
    assert d4 / d1 == pytest.approx(4.0 ** -0.2, rel=2e-2)
    lin = soil.Material(young=E, density=RHO, friction_angle=0.0)
    _, _, _, l1, _, _, _ = _wall_impact(1.0, lin)
    _, _, _, l4, _, _, _ = _wall_impact(4.0, lin)
    assert l4 / l1 == pytest.approx(1.0, rel=2e-2)


def test_hertz_sphere_sphere_impact():
    """Oracle: two equal spheres head on, m* = m/2, R* = R/2, closing speed 2 v: duration and
    rebound as the Hertz solution (+-2 dt, 1e-3)."""
    m = sphere_mass()
    vrel = 2.0
    tc = hertz_contact_duration(0.5 * m, e_star(), 0.5 * R, vrel)
    dt = tc / STEPS_PER_CONTACT
    p = soil.Particles(x=[[0, 0, 0], [2 * R + 1e-6, 0, 0]], radius=R,
                       v=[[1.0, 0, 0], [-1.0, 0, 0]])
    sim = soil.Simulation(p, [hertz(0.3)], gravity=(0, 0, 0), dt=dt)
    dur, _, vb, va = _impact(sim, 1, 0, 10 * STEPS_PER_CONTACT)
    assert abs(dur - tc) <= 2 * dt
    assert abs(va / -vb - 1.0) < 1e-3


def _tsuji_oracle(m, kno, zeta, v0):
    """Independent implementation: scipy integration of m x'' = -(k_no x^1.5 + c(x) x'),
    c = 2 sqrt(5/6) zeta sqrt(m 1.5 k_no sqrt(x)), from x = 0, x' = v0 until the no-tension
    force reaches 0; returns |x'| / v0 there."""
    from scipy.integrate import solve_ivp

    def force(y):
        x = max(y[0], 0.0)
        c = 2.0 * math.sqrt(5.0 / 6.0) * zeta * math.sqrt(m * 1.5 * kno * math.sqrt(x))
        return kno * x ** 1.5 + c * y[1]

    def rhs(t, y):
        return [y[1], -force(y) / m]

    def release(t, y):
        return force(y) if t > 0 else 1.0

    release.terminal = True
    release.direction = -1
    sol = solve_ivp(rhs, [0, 1.0], [0.0, v0], events=release, rtol=1e-11, atol=1e-15,
                    first_step=1e-10, max_step=1e-5)
    return abs(sol.y_events[0][0][1]) / v0


@pytest.mark.parametrize("v0", [0.5, 4.0])
def test_tsuji_damping_rebound_and_ledger(v0):
    """Oracle: the ODE of the Hertz spring with Tsuji's dashpot (scipy) for the rebound (2e-3);
    the rebound is the same at both speeds (the dashpot grows as delta^(1/4)); the dashpot's
    work is booked in dissipated_viscous (0.5 %) and the ledger closes (0.5 %)."""
    mat = hertz(restitution=0.5)
    m = sphere_mass()
    kno, _ = hertz_coefficients(E, NU, E, NU, R)
    sim, tc, dt, dur, dmax, vb, va = _wall_impact(v0, mat)
    e_dem = -va / vb
    e_ode = _tsuji_oracle(m, kno, mat.damping_ratio, v0)
    assert abs(e_dem - e_ode) < 2e-3
    assert 0.4 < e_dem < 0.9  # a real loss, not the nominal 0.5 (the force is clamped)
    en = sim.energy()
    ke0 = 0.5 * m * v0**2
    assert en["dissipated_viscous"] == pytest.approx(ke0 * (1 - e_dem**2), rel=5e-3)
    assert abs(en["balance_error"]) < 5e-3 * ke0


def test_rebound_of_tsuji_damping_does_not_depend_on_speed():
    """Oracle: Tsuji's dashpot c ~ delta^(1/4) makes the restitution independent of the impact
    speed (Antypov & Elliott 2011): 0.5 and 4 m/s rebound alike (0.5 %)."""
    e = [(-va / vb) for *_, vb, va in (_wall_impact(v0, hertz(restitution=0.3))
                                        for v0 in (0.5, 4.0))]
    assert e[0] == pytest.approx(e[1], rel=5e-3)


def test_coefficients_are_yades_for_one_material():
    """Oracle: Yade's ``Ip2_FrictMat_FrictMat_MindlinPhys`` (kno = 4/3 E sqrt(R) with
    E = Ea Eb / ((1 - Va^2) Eb + (1 - Vb^2) Ea), kso = 2 sqrt(4 R) G / (2 - V)) for two grains
    of one material (1e-12); for two materials E* is Yade's and G* the series form."""
    r = 0.6 * R
    kno, kso = hertz_coefficients(E, NU, E, NU, r)
    ey = E * E / ((1 - NU**2) * E + (1 - NU**2) * E)
    g = E / (2 * (1 + NU))
    assert kno == pytest.approx(4.0 / 3.0 * ey * math.sqrt(r), rel=1e-12)
    assert kso == pytest.approx(2 * math.sqrt(4 * r) * g / (2 - NU), rel=1e-12)
    e2, nu2 = 3e10, 0.2
    kno2, kso2 = hertz_coefficients(E, NU, e2, nu2, r)
    ey2 = E * e2 / ((1 - NU**2) * e2 + (1 - nu2**2) * E)
    assert kno2 == pytest.approx(4.0 / 3.0 * ey2 * math.sqrt(r), rel=1e-12)
    g2 = e2 / (2 * (1 + nu2))
    assert kso2 == pytest.approx(8 * math.sqrt(r) / ((2 - NU) / g + (2 - nu2) / g2), rel=1e-12)


def test_varying_spring_dissipation_of_a_scaled_spring_is_the_shed_energy():
    """Oracle: a sticking spring (no displacement) whose stiffness falls from k0 to k1 and whose
    force is scaled by k1 / k0 (Thornton) sheds F0^2 / (2 k0) (1 - k1 / k0); one that stiffens
    at constant force stores less by F0^2 / 2 (1 / k0 - 1 / k1); neither creates energy, and
    an unscaled softening spring would (the check that the rule is needed)."""
    f0, k0, k1 = 3.0, 2.0e5, 1.5e5
    shed = varying_spring_dissipation(f0, 0, 0, f0 * k1 / k0, 0, 0, 0, 0, 0, k0, k1)
    assert shed == pytest.approx(f0**2 / (2 * k0) * (1 - k1 / k0), rel=1e-12)
    stiff = varying_spring_dissipation(f0, 0, 0, f0, 0, 0, 0, 0, 0, k1, k0)
    assert stiff == pytest.approx(f0**2 / 2 * (1 / k1 - 1 / k0), rel=1e-12)
    assert shed > 0 and stiff > 0
    assert varying_spring_dissipation(f0, 0, 0, f0, 0, 0, 0, 0, 0, k0, k1) < 0


@pytest.mark.parametrize("pair", ["sphere-wall", "sphere-sphere"])
def test_thornton_rule_never_makes_energy_in_a_sticking_oblique_impact(pair):
    """Oracle: passivity. An oblique impact at high friction (tan phi = 1.7) sticks through
    most of the contact; while the overlap shrinks the Mindlin spring softens, and its stored
    force must shed energy with it (Thornton's rule). The friction ledger may fall only by the
    scheme's second-order residue (< 1e-6 of the impact energy in a step; without the rule it
    falls by 8e-4), the rebound keeps less than the impact energy, and the ledger closes
    (1e-4)."""
    m = sphere_mass()
    v0 = 1.0
    if pair == "sphere-wall":
        tc = hertz_contact_duration(m, e_star(), R, v0)
        p = soil.Particles(x=[[0, 0, R + 1e-6]], radius=[R], v=[[0.5, 0, -v0]],
                           rotation_blocked=False)
        bodies = [soil.BoundaryBody(shapes=[soil.Plane()])]
    else:
        tc = hertz_contact_duration(0.5 * m, e_star(), 0.5 * R, v0)
        p = soil.Particles(x=[[0, 0, 0], [0, 0, 2 * R + 1e-6]], radius=R,
                           v=[[0, 0, 0], [0.5, 0, -v0]], rotation_blocked=False)
        bodies = []
    sim = soil.Simulation(p, [hertz(math.radians(60))], bodies, gravity=(0, 0, 0),
                          dt=tc / STEPS_PER_CONTACT)
    ke0 = sim.energy()["kinetic_translational"]
    fric = [0.0]
    for _ in range(3 * STEPS_PER_CONTACT):
        sim.step()
        e = sim.energy()
        fric.append(e["dissipated_friction"])
    assert fric[-1] > 1e-3 * ke0  # the contact slid at times and stuck at others
    assert np.min(np.diff(fric)) > -1e-6 * ke0
    assert e["kinetic_translational"] + e["kinetic_rotational"] < ke0
    assert abs(e["balance_error"]) < 1e-4 * ke0


def _oblique_bed(restitution=None, rolling=None, phi=math.radians(30)):
    rng = np.random.default_rng(3)
    h = 2 * R
    g = [(np.arange(k) + 0.5) * h for k in (4, 4, 2)]
    x = np.stack(np.meshgrid(*g, indexing="ij"), axis=-1).reshape(-1, 3)
    r = R * (1 - 0.05 * rng.uniform(0, 1, x.shape[0]))
    x = np.vstack([x, [[2 * R, 2 * R, 4.2 * R + 0.02]]])
    r = np.append(r, R)
    v = np.zeros_like(x)
    v[-1] = [2.0, 1.0, -4.0]
    m0 = hertz(phi, restitution=restitution, rolling=rolling)
    p = soil.Particles(x=x, radius=r, rotation_blocked=False, v=v)
    box = soil.BoundaryBody(shapes=[soil.Box((0, 0, 0), (8 * R, 8 * R, 1.0))])
    sim = soil.Simulation(p, [m0], [box], dt=1e-5)
    return sim, 0.5 * sim.particles.mass[-1] * (v[-1] ** 2).sum()


@pytest.mark.parametrize("case", ["friction", "friction+rolling+damping"])
def test_hertz_ledger_closes_on_an_oblique_impact_into_a_bed(case):
    """Oracle: conservation of energy with the Hertz-Mindlin law on grain pairs and walls
    (the Hertz energy 2/5 k_no delta^(5/2), the Mindlin spring over the stiffness it was made
    with): KE + elastic + dissipation - work of gravity = const within 0.5 % of the projectile's
    energy at every sampled instant; the friction ledger never runs backwards (Thornton's rule:
    a softening spring sheds energy, never makes it)."""
    kw = {} if case == "friction" else dict(restitution=0.5, rolling=soil.Rolling(0.05))
    sim, ke0 = _oblique_bed(**kw)
    worst = 0.0
    fric = [0.0]
    for _ in range(60):
        sim.step(50)
        e = sim.energy()
        worst = max(worst, abs(e["balance_error"]))
        fric.append(e["dissipated_friction"])
    assert e["dissipated_friction"] > 0.05 * ke0
    assert worst < 5e-3 * ke0, (worst / ke0, e)
    assert np.min(np.diff(fric)) > -1e-6 * ke0
    if case != "friction":
        assert e["dissipated_viscous"] > 0.01 * ke0


def test_material_refuses_bad_hertz_fields():
    """Oracle: parameter contract (field, value and allowed range in the message)."""
    with pytest.raises(ValueError, match=re.escape("Material.contact_law='hertz': must be one "
                                                   "of ('linear', 'hertz_mindlin')")):
        soil.Material(young=E, density=RHO, friction_angle=0.0, contact_law="hertz")
    with pytest.raises(ValueError, match=re.escape("Material.poisson=0.5: must be in [0, 0.5)")):
        soil.Material(young=E, density=RHO, friction_angle=0.0, poisson=0.5)


def test_a_bond_on_hertz_grains_is_the_cohesive_law_and_hertz_after_it_breaks():
    """Oracle: with cohesion a bond is the linear cohesive law's (Yade CohFrictPhys: tension up
    to a_n = sigma_n R^2, to one step increment k_n u dt, k_n = E R); pressed together after it
    broke, the two grains push back with Hertz's force k_no delta^(3/2) (1e-9), not k_n delta."""
    sn = 2e5
    m0 = hertz(0.5, cohesion=soil.Cohesion(normal_strength=sn, shear_strength=1e12))
    p = soil.Particles(x=[[0.0, 0.0, 0.0], [2 * R, 0, 0]], radius=R)
    sim = soil.Simulation(p, [m0], gravity=(0, 0, 0), dt=1e-5)
    sim.particles.inv_mass[:] = 0.0  # prescribed constant velocities
    sim.particles.v[:] = 0.0
    assert sim.bond_contacts() == 1
    u = 0.01
    sim.particles.v[1] = [u, 0, 0]
    fmin = 0.0
    for _ in range(5000):
        sim.step()
        c = sim.contacts()
        if len(c["fn"]) == 0 or not c["bonded"][0]:
            break
        fmin = min(fmin, c["fn"][0])
    else:
        pytest.fail("the bond did not break")
    assert abs(-fmin - sn * R**2) <= E * R * u * sim.dt * 1.0001
    sim.particles.v[1] = [-u, 0, 0]
    kno, _ = hertz_coefficients(E, NU, E, NU, 0.5 * R)
    pressed = 0
    for _ in range(10000):
        sim.step()
        c = sim.contacts()
        if len(c["fn"]) and c["overlap"][0] > 1e-4:
            assert not c["bonded"][0]
            assert c["fn"][0] == pytest.approx(kno * c["overlap"][0] ** 1.5, rel=1e-9)
            pressed += 1
    assert pressed > 100
