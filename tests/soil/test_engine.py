"""Engine-level physics checks of the soil DEM (impacts, friction threshold, convergence order,
action-reaction, cohesive bonds, time-step refusal)."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

import soil
from soil.contact_laws import contact_duration

E = 2e7  # [Pa]
RHO = 2650.0  # [kg/m^3]
R = 0.05  # [m]


def mat(phi=0.0, **kw):
    return soil.Material(young=E, density=RHO, friction_angle=phi, stiffness_ratio=0.25, **kw)


def sphere_mass(r=R, rho=RHO):
    return 4.0 / 3.0 * math.pi * r**3 * rho


# A linear-spring impact integrated by leapfrog with dt = t_c / STEPS_PER_CONTACT: the contact
# starts and ends between steps, so the measured duration is quantised by dt (+-2 dt), and the
# energy error of the symplectic scheme is O((omega dt)^2) ~ 2.5e-4 at 200 steps per contact.
STEPS_PER_CONTACT = 200
RESTITUTION_TOL = 1e-3  # task requirement


def _impact(sim, i_obs, n_max, in_contact):
    """Run until the contact has opened and closed; return (duration, v_before, v_after)."""
    v_before = sim.synchronized_velocity()[0][i_obs].copy()
    t_start = None
    t_end = None
    for _ in range(n_max):
        sim.step()
        c = in_contact(sim)
        if c and t_start is None:
            t_start = sim.time
        if t_start is not None and not c:
            t_end = sim.time
            break
    assert t_start is not None and t_end is not None, "impact did not complete"
    return t_end - t_start, v_before, sim.synchronized_velocity()[0][i_obs].copy()


def test_sphere_wall_impact_duration_and_restitution():
    """Oracle: undamped linear spring, t_c = pi sqrt(m/k_n), k_n = E r (wall side uses the
    sphere's own radius, Yade utils.wall); restitution 1 (energy conservation)."""
    m = sphere_mass()
    kn = E * R  # 2 E r E r / (E r + E r)
    t_c = contact_duration(m, kn)
    dt = t_c / STEPS_PER_CONTACT
    p = soil.Particles(x=[[0.0, 0.0, R + 1e-4]], radius=[R], v=[[0.0, 0.0, -1.0]])
    floor = soil.BoundaryBody(shapes=[soil.Plane()])
    sim = soil.Simulation(p, [mat()], [floor], gravity=(0, 0, 0), dt=dt)
    dur, vb, va = _impact(sim, 0, 10 * STEPS_PER_CONTACT, lambda s: len(s.contacts()["i"]) > 0)
    assert abs(dur - t_c) <= 2 * dt
    assert abs(-va[2] / vb[2] - 1.0) < RESTITUTION_TOL


def test_sphere_sphere_impact_duration_and_restitution():
    """Oracle: t_c = pi sqrt(m*/k_n), m* = m/2, k_n = E r for equal spheres; restitution 1."""
    m = sphere_mass()
    kn = E * R
    t_c = contact_duration(0.5 * m, kn)
    dt = t_c / STEPS_PER_CONTACT
    p = soil.Particles(x=[[0, 0, 0], [2 * R + 1e-4, 0, 0]], radius=R,
                       v=[[0.5, 0, 0], [-0.5, 0, 0]])
    sim = soil.Simulation(p, [mat(0.3)], gravity=(0, 0, 0), dt=dt)
    dur, vb, va = _impact(sim, 1, 10 * STEPS_PER_CONTACT, lambda s: len(s.contacts()["i"]) > 0)
    assert abs(dur - t_c) <= 2 * dt
    assert abs(va[0] / -vb[0] - 1.0) < RESTITUTION_TOL


@pytest.mark.parametrize("ratio, slides", [(0.9, False), (1.1, True)])
def test_block_on_incline_slides_iff_tan_theta_above_mu(ratio, slides):
    """Oracle: Coulomb friction; a rotation-blocked sphere on an incline (gravity tilted by
    theta) slides iff tan(theta) > mu. Cundall damping (0.5) removes the elastic tangential
    overshoot so the stuck case is static; displacement thresholds: stuck < 3 x the static spring
    deflection m g sin(theta) / k_s, sliding > 100 x that deflection after 0.3 s."""
    phi = math.radians(30.0)
    theta = math.atan(ratio * math.tan(phi))
    g = 9.81
    grav = (g * math.sin(theta), 0.0, -g * math.cos(theta))
    m = sphere_mass()
    kn = E * R
    ks = 0.25 * kn
    delta0 = m * g * math.cos(theta) / kn
    p = soil.Particles(x=[[0.0, 0.0, R - delta0]], radius=[R])
    floor = soil.BoundaryBody(shapes=[soil.Plane()])
    sim = soil.Simulation(p, [mat(phi)], [floor], gravity=grav, global_damping=0.5)
    x0 = sim.particles.x[0, 0]
    sim.step(int(0.3 / sim.dt))
    dx = abs(sim.particles.x[0, 0] - x0)
    deflection = m * g * math.sin(theta) / ks
    if slides:
        assert dx > 100 * deflection
    else:
        assert dx < 3 * deflection


CONVERGENCE_MIN_ORDER = 1.9  # task requirement; leapfrog is second order


def test_integrator_observed_order_two():
    """Oracle: analytic harmonic solution z(t) = z_eq - A cos(omega t), omega = sqrt(k_n/m), of a
    sphere pre-compressed on a plane under gravity (amplitude < static overlap, so the contact
    never opens); observed order from halving dt 4 times must be >= 1.9."""
    m = sphere_mass()
    kn = E * R
    g = 9.81
    d_eq = m * g / kn
    amp = 0.5 * d_eq
    omega = math.sqrt(kn / m)
    t_end = 2.0 * math.pi / omega * 3.3
    errs = []
    for level in range(5):
        n = 40 * 2**level * 3
        dt = t_end / n
        p = soil.Particles(x=[[0.0, 0.0, R - d_eq - amp]], radius=[R])
        floor = soil.BoundaryBody(shapes=[soil.Plane()])
        sim = soil.Simulation(p, [mat()], [floor], dt=dt)
        sim.step(n)
        z = R - d_eq - amp * math.cos(omega * sim.time)
        errs.append(abs(sim.particles.x[0, 2] - z))
    errs = np.array(errs)
    rates = np.log2(errs[:-1] / errs[1:])
    assert (rates >= CONVERGENCE_MIN_ORDER).all(), rates


ROUND_OFF = 1e-12  # relative to the sum of force magnitudes (double precision, ~1e2 terms)


@pytest.mark.parametrize("shear", [None, 0.3], ids=["normal-dashpot", "shear-dashpot-too"])
def test_internal_forces_sum_to_zero(shear):
    """Oracle: Newton's third law / conservation of momentum and angular momentum: without
    gravity and boundaries, sum F = 0 and sum (x x F + T) = 0 to round-off (free rotations,
    friction, rolling resistance and damping all on; with and without a shear dashpot)."""
    rng = np.random.default_rng(3)
    n = 60
    x = rng.uniform(0, 0.35, (n, 3))
    r = rng.uniform(0.04, 0.06, n)
    m0 = mat(0.5, restitution=0.5, rolling=soil.Rolling(0.1), shear_restitution=shear)
    p = soil.Particles(x=x, radius=r, rotation_blocked=False,
                       v=rng.normal(0, 0.5, (n, 3)), w=rng.normal(0, 5, (n, 3)))
    sim = soil.Simulation(p, [m0], gravity=(0, 0, 0))
    for _ in range(3):
        sim.step(20)
        f = sim.particles.f
        t = sim.particles.t
        scale = np.abs(f).sum()
        assert scale > 0
        assert np.abs(f.sum(axis=0)).max() < ROUND_OFF * scale
        ang = np.cross(sim.particles.x, f).sum(axis=0) + t.sum(axis=0)
        assert np.abs(ang).max() < ROUND_OFF * (np.abs(np.cross(sim.particles.x, f)).sum()
                                                + np.abs(t).sum())


def _kinematic_pair(material, x1, rotation_blocked=True):
    p = soil.Particles(x=[[0.0, 0.0, 0.0], x1], radius=R, rotation_blocked=rotation_blocked)
    sim = soil.Simulation(p, [material], gravity=(0, 0, 0), dt=1e-5)
    # test harness: infinite mass/inertia = prescribed constant velocities
    sim.particles.inv_mass[:] = 0.0
    sim.particles.inv_inertia[:] = 0.0
    sim.particles.v[:] = 0.0  # drop the half-step start kick computed with the real mass
    return sim


def test_cohesive_pair_tensile_strength_and_permanent_break():
    """Oracle: Yade CohFrictPhys: a_n = sigma_n min(R1,R2)^2; a fragile bond pulled apart carries
    a tension up to a_n (to one step increment k_n u dt), then breaks for good."""
    sn = 2e5
    m0 = mat(0.5, cohesion=soil.Cohesion(normal_strength=sn, shear_strength=1e12))
    sim = _kinematic_pair(m0, [2 * R, 0, 0])
    assert sim.bond_contacts() == 1
    u = 0.01
    sim.particles.v[1] = [u, 0, 0]
    an = sn * R**2
    fmin = 0.0
    broke_at = None
    for k in range(5000):
        sim.step()
        c = sim.contacts()
        fn = c["fn"][0] if len(c["fn"]) else 0.0
        fmin = min(fmin, fn)
        if broke_at is None and (len(c["fn"]) == 0 or not c["bonded"][0]):
            broke_at = sim.time
            break
    kn = E * R
    assert broke_at is not None
    assert abs(-fmin - an) <= kn * u * sim.dt * 1.0001
    # pushed back into contact and pulled again: no tension any more
    sim.particles.v[1] = [-u, 0, 0]
    sim.step(int(2 * broke_at / sim.dt))
    sim.particles.v[1] = [u, 0, 0]
    for _ in range(3000):
        sim.step()
        c = sim.contacts()
        if len(c["fn"]):
            assert c["fn"].min() >= 0.0
            assert not c["bonded"].any()


def test_cohesive_plastic_bond_holds_at_strength():
    """Oracle: Yade CohesionMoment with fragile=False: F_n = -a_n (normal plasticity) and the
    bond persists while stretched."""
    sn = 2e5
    m0 = mat(0.5, cohesion=soil.Cohesion(normal_strength=sn, shear_strength=1e12, plastic=True))
    sim = _kinematic_pair(m0, [2 * R, 0, 0])
    sim.bond_contacts()
    sim.particles.v[1] = [0.1, 0, 0]
    sim.step(2000)  # 2 mm of stretch, 4 x the elastic limit a_n/k_n = 0.5 mm
    c = sim.contacts()
    assert c["bonded"][0]
    assert c["fn"][0] == pytest.approx(-sn * R**2, rel=1e-12)


def test_cohesive_shear_strength():
    """Oracle: shear limit |F_s| <= a_t + F_n tan(phi) with a_t = sigma_s min(R)^2; F_n = 0 here
    (sliding at zero overlap), so the largest shear force equals a_t (to one step increment), and
    the bond then breaks."""
    ss = 1e5
    m0 = mat(0.3, cohesion=soil.Cohesion(normal_strength=1e12, shear_strength=ss))
    sim = _kinematic_pair(m0, [2 * R, 0, 0])
    sim.bond_contacts()
    u = 0.01
    sim.particles.v[1] = [0, u, 0]
    fs_max = 0.0
    limit = None
    for _ in range(20000):
        sim.step()
        c = sim.contacts()
        if len(c["fs"]) == 0 or not c["bonded"][0]:
            break
        fs = float(np.linalg.norm(c["fs"][0]))
        if fs > fs_max:
            fs_max = fs
            # F_n < 0 here: sliding at zero overlap stretches the pair slightly
            limit = ss * R**2 + c["fn"][0] * math.tan(0.3)
    ks = 0.25 * E * R
    assert len(c["fs"]) == 0 or not c["bonded"][0]
    assert limit is not None and limit > 0.99 * ss * R**2
    assert fs_max <= limit * (1 + 1e-12)
    assert fs_max >= limit - 1.01 * ks * u * sim.dt


def test_cohesive_bending_moment_cap():
    """Oracle: Yade CohesionMoment bending spring M_b = k_b theta_b, k_b = alphaKr k_s R1 R2, capped
    at etaRoll min(R) |F_n| (rolling-friction-like plateau)."""
    akr = 2.0
    eta = 0.3
    m0 = mat(0.5, cohesion=soil.Cohesion(normal_strength=1e12, shear_strength=1e12,
                                         bending_modulus_factor=akr, twisting_modulus_factor=1.0,
                                         bending_cap=eta))
    delta0 = 1e-4
    sim = _kinematic_pair(m0, [2 * R - delta0, 0, 0], rotation_blocked=False)
    sim.bond_contacts()
    omega = 0.5
    sim.particles.w[1] = [0, 0, omega]
    sim.particles.w[0] = [0, 0, -omega]  # pure relative rolling, contact point fixed
    kb = akr * 0.25 * E * R * R * R
    fn = E * R * delta0
    cap = eta * R * fn
    hist = []
    for _ in range(400):
        sim.step()
        hist.append(np.linalg.norm(sim.contacts()["moment"][0]))
    hist = np.array(hist)
    # elastic branch: |M| = k_b * 2 omega * t until the cap, then the plateau
    t1 = sim.dt * 3
    assert hist[2] == pytest.approx(kb * 2 * omega * t1, rel=1e-6)
    assert hist.max() == pytest.approx(cap, rel=1e-9)
    assert hist[-1] == pytest.approx(cap, rel=1e-9)


def test_time_step_above_limit_refused():
    """Oracle: stability bound; the message must name both numbers."""
    p = soil.Particles(x=[[0, 0, 0]], radius=[R])
    sim = soil.Simulation(p, [mat()])
    bad = 1.5 * sim.dt_critical
    with pytest.raises(ValueError) as ei:
        soil.Simulation(soil.Particles(x=[[0, 0, 0]], radius=[R]), [mat()], dt=bad)
    msg = str(ei.value)
    assert repr(bad) in msg and repr(sim.dt_critical) in msg
    # P-wave definition (Yade PWaveTimeStep)
    assert sim.dt_pwave == pytest.approx(R / math.sqrt(E / RHO), rel=1e-15)


@pytest.mark.parametrize(
    "field, value, text",
    [
        ("young", -3e7, "Material.young=-30000000.0: must be > 0 [Pa]"),
        ("density", 0.0, "Material.density=0.0: must be > 0 [kg/m^3]"),
        ("friction_angle", 2.0, "Material.friction_angle=2.0: must be in [0, pi/2) [rad]"),
        ("stiffness_ratio", 1.5, "Material.stiffness_ratio=1.5: must be in [0, 1] [-]"),
        ("restitution", 0.0, "Material.restitution=0.0: must be in (0, 1] or None [-]"),
    ],
)
def test_bad_material_field_named(field, value, text):
    """Oracle: parameter contract (field, value and allowed range in the message)."""
    kw = dict(young=E, density=RHO, friction_angle=0.5, stiffness_ratio=0.25)
    kw[field] = value
    with pytest.raises(ValueError, match=re.escape(text)):
        soil.Material(**kw)


def _damped_restitution_oracle(m, kn, zeta, v0):
    """Independent implementation: scipy integration of m x'' = -k x - c x' (x = overlap) from
    x = 0, x' = v0 until the no-tension force k x + c x' reaches 0; returns |x'|/v0 there."""
    from scipy.integrate import solve_ivp

    c = 2 * zeta * math.sqrt(m * kn)

    def rhs(t, y):
        return [y[1], -(kn * y[0] + c * y[1]) / m]

    def release(t, y):
        return kn * y[0] + c * y[1]

    release.terminal = True
    release.direction = -1
    sol = solve_ivp(rhs, [0, 1.0], [0.0, v0], events=release, rtol=1e-12, atol=1e-15,
                    first_step=1e-9)
    # the event at t=0 (force starts at +c v0 > 0) is not a downward crossing
    return abs(sol.y_events[0][0][1]) / v0


DAMPED_RESTITUTION_TOL = 2e-3  # leapfrog at 200 steps per contact (onset quantisation)


def test_viscous_damping_restitution_and_ledger():
    """Oracle: independent ODE solution of the clamped linear spring-dashpot (scipy, rtol 1e-12)
    for the rebound speed; energy conservation with the dashpot work booked in
    dissipated_viscous (0.5 %)."""
    e_target = 0.5
    m0 = mat(0.0, restitution=e_target)
    m = sphere_mass()
    kn = E * R
    t_c = contact_duration(m, kn)
    dt = t_c / STEPS_PER_CONTACT
    p = soil.Particles(x=[[0.0, 0.0, R + 1e-4]], radius=[R], v=[[0.0, 0.0, -1.0]])
    floor = soil.BoundaryBody(shapes=[soil.Plane()])
    sim = soil.Simulation(p, [m0], [floor], gravity=(0, 0, 0), dt=dt)
    dur, vb, va = _impact(sim, 0, 10 * STEPS_PER_CONTACT, lambda s: len(s.contacts()["i"]) > 0)
    e_dem = -va[2] / vb[2]
    e_ode = _damped_restitution_oracle(m, kn, m0.damping_ratio, 1.0)
    assert abs(e_dem - e_ode) < DAMPED_RESTITUTION_TOL
    # the rebound the material reports for itself (closed form, not the nominal e = 0.5)
    assert abs(e_dem - m0.rebound_restitution) < DAMPED_RESTITUTION_TOL
    assert m0.rebound_restitution > e_target + 0.04
    en = sim.energy()
    ke0 = 0.5 * m
    assert en["dissipated_viscous"] == pytest.approx(ke0 * (1 - e_dem**2), rel=5e-3)
    assert abs(en["balance_error"]) < 5e-3 * ke0


@pytest.mark.parametrize("e_target", [0.1, 0.3, 0.5])
@pytest.mark.parametrize("pair", ["sphere-wall", "sphere-sphere"])
def test_a_pulling_dashpot_rebounds_at_the_nominal_restitution(pair, e_target):
    """Oracle: closed form. A linear spring-dashpot whose force may pull until the overlap
    closes (``Material.dashpot_tension``, Yade ``CundallStrackVisco``) is the damped oscillator
    integrated from overlap 0 back to overlap 0: the rebound is exactly the nominal e of its
    damping ratio, below the clamped contact's (the same dashpot with the force held >= 0,
    ``rebound_restitution``); the dashpot's work is booked in dissipated_viscous (0.5 %). Both
    contact kernels: a grain on a wall (body contacts) and two grains (pair contacts). The
    pull ends with a jump (-c v to 0) where the overlap closes, between two steps: the rebound
    may differ by up to one step of that pull, (c / m*) dt e v0 = 2 zeta omega_n dt e v0, beyond
    the clamped contact's tolerance."""
    m0 = mat(0.0, restitution=e_target, dashpot_tension=True)
    clamped = mat(0.0, restitution=e_target)
    m = sphere_mass()
    kn = E * R
    m_eff = m if pair == "sphere-wall" else 0.5 * m
    dt = contact_duration(m_eff, kn) / STEPS_PER_CONTACT
    if pair == "sphere-wall":
        p = soil.Particles(x=[[0.0, 0.0, R + 1e-4]], radius=[R], v=[[0.0, 0.0, -1.0]])
        sim = soil.Simulation(p, [m0], [soil.BoundaryBody(shapes=[soil.Plane()])],
                              gravity=(0, 0, 0), dt=dt)
        i_obs, axis, ke0 = 0, 2, 0.5 * m
    else:
        p = soil.Particles(x=[[0, 0, 0], [2 * R + 1e-4, 0, 0]], radius=R,
                           v=[[0.5, 0, 0], [-0.5, 0, 0]])
        sim = soil.Simulation(p, [m0], gravity=(0, 0, 0), dt=dt)
        i_obs, axis, ke0 = 1, 0, 2 * 0.5 * m * 0.25
    dur, vb, va = _impact(sim, i_obs, 10 * STEPS_PER_CONTACT,
                          lambda s: len(s.contacts()["i"]) > 0)
    e_dem = -va[axis] / vb[axis]
    last_step = 2 * m0.damping_ratio * math.sqrt(kn / m_eff) * dt * e_target
    assert abs(e_dem - e_target) < DAMPED_RESTITUTION_TOL + last_step
    assert m0.rebound_restitution == e_target
    assert clamped.rebound_restitution > e_target + 0.04
    en = sim.energy()
    assert en["dissipated_viscous"] == pytest.approx(ke0 * (1 - e_dem**2), rel=5e-3)
    assert abs(en["balance_error"]) < 5e-3 * ke0


def test_dashpot_tension_must_be_a_bool():
    """Oracle: parameter contract (field, value and what is allowed in the message)."""
    with pytest.raises(ValueError, match=re.escape("Material.dashpot_tension=1: must be a bool")):
        mat(0.0, restitution=0.5, dashpot_tension=1)


def _bed_with_big_sphere(skin):
    rng = np.random.default_rng(8)
    h = 2 * R
    g = (np.arange(6) + 0.5) * h
    x = np.stack(np.meshgrid(g, g, g[:3], indexing="ij"), -1).reshape(-1, 3)
    x += rng.normal(0, 0.002, x.shape)
    r = R * (1 - 0.1 * rng.uniform(0, 1, x.shape[0]))
    big = 0.45
    x = np.vstack([x, [[3 * h, 3 * h, 3 * h + big + 0.01]]])
    r = np.append(r, big)
    v = np.zeros_like(x)
    v[-1] = [0.0, 0.0, -6.0]
    p = soil.Particles(x=x, radius=r, rotation_blocked=False, v=v)
    box = soil.BoundaryBody(shapes=[soil.Box((0, 0, 0), (6 * h, 6 * h, 3.0))])
    return soil.Simulation(p, [mat(0.5)], [box], dt=2e-5, skin=skin)


def test_history_survives_rebuilds_and_large_particle_pass():
    """Oracle: the physics must not depend on the Verlet list: a bed hit by a 0.45 m sphere
    particle (separate large-particle pass, radius 9 x median) gives the same trajectory with a
    tiny skin (rebuild nearly every step, tangential history carried across every rebuild) and a
    large skin (few rebuilds); and the contact set equals a brute-force O(N^2) overlap search."""
    a = _bed_with_big_sphere(skin=0.002)
    b = _bed_with_big_sphere(skin=0.04)
    assert a._large_idx.tolist() == [a.particles.n - 1]
    for _ in range(10):
        a.step(30)
        b.step(30)
    assert a.n_builds > 5 * b.n_builds
    # non-touching list entries add exact zeros and the gather order of touching pairs is the
    # same (rows sorted by j, transposed lists by pair index): bit-identical trajectories
    assert np.array_equal(a.particles.x, b.particles.x)
    assert np.array_equal(a.particles.v, b.particles.v)
    assert np.array_equal(a.particles.w, b.particles.w)
    x, r = a.particles.x, a.particles.radius
    d = np.linalg.norm(x[:, None] - x[None], axis=-1)
    ii, jj = np.nonzero(np.triu(d < r[:, None] + r[None], 1))
    c = a.contacts()
    pairs = c["j"] >= 0
    assert set(zip(ii.tolist(), jj.tolist())) == set(zip(c["i"][pairs].tolist(),
                                                         c["j"][pairs].tolist()))
    assert np.any(c["j"][pairs] == a.particles.n - 1)  # the big sphere is in contact


@pytest.mark.parametrize("ratio, rolls", [(0.8, False), (1.25, True)])
def test_sphere_on_incline_rolls_iff_tan_theta_above_mu_r(ratio, rolls):
    """Oracle: statics of a free sphere on an incline with type C rolling resistance (Ai et al.
    2011) on the wall, R* = r: friction F = m g sin(theta) must be balanced by the rolling moment
    F r <= mu_r r m g cos(theta), so the sphere rolls iff tan(theta) > mu_r (friction
    tan(phi) > tan(theta) keeps the contact sticking). Cundall damping removes the elastic
    overshoot; thresholds 5 x the static deflection (stuck) / 100 x (rolling) after 1 s
    (undamped rolling: a = g cos(theta) (tan(theta) - mu_r) / 1.4, 88 mm in 1 s)."""
    mu_r = 0.1
    theta = math.atan(ratio * mu_r)
    g = 9.81
    grav = (g * math.sin(theta), 0.0, -g * math.cos(theta))
    m = sphere_mass()
    kn = E * R
    delta0 = m * g * math.cos(theta) / kn
    m0 = mat(math.radians(30), rolling=soil.Rolling(mu_r))
    p = soil.Particles(x=[[0.0, 0.0, R - delta0]], radius=[R], rotation_blocked=False)
    floor = soil.BoundaryBody(shapes=[soil.Plane()])
    sim = soil.Simulation(p, [m0], [floor], gravity=grav, global_damping=0.5)
    x0 = sim.particles.x[0, 0]
    sim.step(int(1.0 / sim.dt))
    dx = abs(sim.particles.x[0, 0] - x0)
    kr = 2.25 * kn * mu_r**2 * R**2
    # static deflection: shear spring + rolling spring compliance at the contact point
    deflection = m * g * math.sin(theta) * (1 / (0.25 * kn) + R * R / kr)
    if rolls:
        assert dx > 100 * deflection
    else:
        assert dx < 5 * deflection
