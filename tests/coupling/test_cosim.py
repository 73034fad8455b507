"""DEM <-> Exudyn co-simulation: trajectory equivalence, momentum, energy, sub-cycling.

Beds are generated in code: a jittered cubic lattice of 576 spheres (r ~ 0.06 m) in an
open box, hit by the 850 kg, 0.90 m drop sphere at 5 m/s.
"""

from dataclasses import replace

import numpy as np
import pytest

import bodies
import coupling
import soil

R_SPHERE = 0.45  # [m] drop mass radius (thesis §2.1.1)
M_SPHERE = 850.0  # [kg]
V0 = np.array([0.5, 0.0, -5.0])  # [m/s] oblique impact, so friction and spin matter
T_END = 0.08  # [s] whole impact: contact, penetration and rebound off the shallow bed

#: the task's bound on the coupled-vs-particle trajectory difference, relative to the
#: largest displacement during the impact [-]
MATCH_RTOL = 1e-4
#: with the leapfrog staggering the match is exact in real arithmetic; what remains is
#: round-off (~1e-16 per operation) over ~400-800 steps with the bounded amplification we
#: measured on this bed (a 1e-15 m perturbation stays below 1e-13 m): 1e-10 keeps four
#: decades of margin and is still six decades below an O(h) coupling error (~1e-4).
ROUNDOFF_RTOL = 1e-10
#: momentum sums of ~1e3 terms of ~1e4 N s magnitude: relative round-off ~1e-13
MOMENTUM_RTOL = 1e-11
#: energy closure required by the task [-]
LEDGER_RTOL = 0.01
#: at least first order is expected for a held (averaged) force over the exchange interval
#: (exudyn_coupling.md; ~2 is observed on this bed with the mid-window velocity
#: prediction); 0.2 of slack for the slip/stick and contact-onset events of a granular bed
#: that make the error curve irregular
SUBCYCLING_MIN_ORDER = 0.8


def _bed(nx=12, nz=4, r=0.06, seed=1):
    rng = np.random.default_rng(seed)
    s = 2.0 * r * 1.08
    g = np.arange(nx) * s - (nx - 1) * s / 2
    zz = r * 1.1 + np.arange(nz) * s
    gx, gy, gz = np.meshgrid(g, g, zz, indexing="ij")
    x = np.stack([gx.ravel(), gy.ravel(), gz.ravel()], 1)
    rad = r * (1 + 0.06 * (rng.random(len(x)) - 0.5))
    return x, rad, nx * s / 2


X_BED, R_BED, HALF = _bed()
X0 = np.array([0.03, -0.02, X_BED[:, 2].max() + R_BED.max() + R_SPHERE + 0.02])


def _materials(friction=0.5, restitution=0.5):
    rho_sphere = M_SPHERE / (4.0 / 3.0 * np.pi * R_SPHERE**3)
    return [soil.Material(young=2e7, density=2650.0, friction_angle=friction,
                          restitution=restitution, name="gravel"),
            soil.Material(young=2e7, density=rho_sphere, friction_angle=friction,
                          restitution=restitution, name="sphere")]


def _walls():
    return soil.BoundaryBody(shapes=[soil.Box((-HALF, -HALF, 0.0), (HALF, HALF, 3.0))],
                             material=0)


def _dt():
    p = soil.Particles(np.vstack([X_BED, X0]), np.append(R_BED, R_SPHERE),
                       np.append(np.zeros(len(X_BED), int), 1), rotation_blocked=False)
    return 0.3 * soil.Simulation(p, _materials(), [_walls()]).dt_critical


def run_particle(dt, mats, t_end=T_END):
    """The drop sphere as a DEM particle (free rotation, solid-sphere inertia)."""
    v = np.zeros((len(X_BED) + 1, 3))
    v[-1] = V0
    p = soil.Particles(np.vstack([X_BED, X0]), np.append(R_BED, R_SPHERE),
                       np.append(np.zeros(len(X_BED), int), 1), rotation_blocked=False, v=v)
    sim = soil.Simulation(p, mats, [_walls()], dt=dt)
    traj = []
    while sim.time < t_end - 0.5 * dt:
        sim.step(1)
        traj.append(sim.particles.x[-1].copy())
    return np.array(traj), sim


def sphere_spec():
    """Drop sphere with the solid-sphere inertia a DEM particle of the same mass has."""
    return bodies.drop_sphere().with_mass_properties(
        inertia=0.4 * M_SPHERE * R_SPHERE**2 * np.eye(3))


def run_coupled(dt, mats, m=1, t_end=T_END, gravity_in_exudyn=True, **run_options):
    p = soil.Particles(X_BED, R_BED, np.zeros(len(X_BED), int), rotation_blocked=False)
    spec = sphere_spec()
    body = coupling.boundary_for(spec, 1, position=X0, velocity=V0)
    sim = soil.Simulation(p, mats, [_walls(), body], dt=dt)
    sim.test_p0 = (sim.particles.mass[:, None] * sim.particles.v).sum(axis=0)  # v_{-1/2}
    model = bodies.ExudynRigidBody(spec, X0, np.eye(3), V0, (0, 0, 0), gravity=sim.gravity,
                                   gravity_in_exudyn=gravity_in_exudyn)
    cosim = coupling.CoSimulation(sim, 1, model, exchange_every=m)
    traj = []
    cosim.run(t_end, on_step=lambda t, s, mo: traj.append(np.array(s.boundaries[1].position)),
              **run_options)
    return np.array(traj), sim, cosim


@pytest.fixture(scope="module")
def dt():
    return _dt()


#: materials of the equivalence runs: frictional, no viscous damping. The engine's viscous
#: damping of a boundary contact uses the particle mass as m_eff (a wall of infinite mass);
#: a particle pair uses the reduced mass, so with damping a finite-mass body and a particle
#: differ by ~m_particle/M_body in the dashpot (measured 5e-4 relative on the trajectory).
EQUIV = dict(friction=0.5, restitution=None)


@pytest.fixture(scope="module")
def reference(dt):
    """Particle run and coupled run (m = 1) on a frictional bed."""
    mats = _materials(**EQUIV)
    return run_particle(dt, mats), run_coupled(dt, mats)


def _rel_diff(a, b):
    n = min(len(a), len(b))
    return np.abs(a[:n] - b[:n]).max() / np.abs(a[:n] - X0).max()


def test_coupled_sphere_follows_the_dem_particle(dt, reference):
    """Oracle: independent implementation -- the same sphere integrated by the DEM as a
    particle (leapfrog), same material and contact law. The staggered coupling reproduces
    leapfrog, so the difference is round-off at h and at h/2 (it cannot shrink further)."""
    (traj_p, sim_p), (traj_c, sim_c, cosim) = reference
    assert len(traj_p) == len(traj_c) > 300
    assert cosim.had_contact and np.abs(traj_p - X0).max() > 0.1  # a real impact happened
    err_h = _rel_diff(traj_p, traj_c)
    assert err_h < MATCH_RTOL
    assert err_h < ROUNDOFF_RTOL
    mats = _materials(**EQUIV)
    err_h2 = _rel_diff(run_particle(dt / 2, mats)[0], run_coupled(dt / 2, mats)[0])
    assert err_h2 < ROUNDOFF_RTOL
    # velocities too (Exudyn half-step velocity vs the particle's leapfrog velocity)
    np.testing.assert_allclose(cosim.model.velocity(), sim_p.particles.v[-1],
                               atol=ROUNDOFF_RTOL * np.linalg.norm(V0))


def test_weight_applied_once_either_way(dt, reference):
    """Oracle: the same run with the weight added by the coupling instead of Exudyn gives
    the same trajectory (gravity counted exactly once)."""
    _, (traj_c, _, _) = reference
    traj_g, _, _ = run_coupled(dt, _materials(**EQUIV), gravity_in_exudyn=False, t_end=0.02)
    assert _rel_diff(traj_c[:len(traj_g)], traj_g) < ROUNDOFF_RTOL


def test_momentum_balances_across_the_interface(reference):
    """Oracle: conservation of momentum. Body: Delta p = contact impulse (DEM accumulator) +
    weight impulse. Whole system: Delta p_body + Delta p_soil = gravity impulse - impulse
    taken by the fixed walls (no global damping)."""
    _, (_, sim, cosim) = reference
    bal = cosim.momentum_balance()
    scale = np.abs(bal["impulse"]).max()
    assert scale > 1e3  # an impact of ~10 kN s
    np.testing.assert_allclose(bal["error"], 0.0, atol=MOMENTUM_RTOL * scale)
    p = sim.particles
    # leapfrog half-step momenta (the DEM stores v_{-1/2} = v_0 - h F_0 / 2m at the start)
    dp_soil = (p.mass[:, None] * p.v).sum(axis=0) - sim.test_p0
    t = sim.time
    g = np.asarray(sim.gravity)
    walls = sim.boundaries[0]
    total = bal["delta_p"] + dp_soil
    expected = (M_SPHERE + p.mass.sum()) * g * t - walls.impulse
    np.testing.assert_allclose(total, expected, atol=MOMENTUM_RTOL * scale)
    # and the soil received minus what the body received from the soil
    np.testing.assert_allclose(dp_soil, -bal["impulse"] - walls.impulse + p.mass.sum() * g * t,
                               atol=MOMENTUM_RTOL * scale)


def test_energy_ledger_closes(dt, reference):
    """Oracles: (1) conservative bed (frictionless, undamped): the coupled ledger closes
    within 1 %; (2) dissipative bed: the coupled residual equals the energy balance error of
    the same impact computed with the sphere as a DEM particle (independent implementation),
    i.e. the coupling adds no energy error of its own."""
    mats0 = _materials(friction=0.0, restitution=None)
    _, _, cos0 = run_coupled(dt, mats0)
    led0 = cos0.ledger
    assert led0.scale > 1e4  # ~10 kJ impact
    assert led0.relative_residual < LEDGER_RTOL
    (_, sim_p), (_, _, cosim) = reference
    led = cosim.ledger
    e_p = sim_p.energy()
    assert led.residual == pytest.approx(e_p["balance_error"], rel=1e-6, abs=1e-6 * led.scale)
    # interface: work on the body and work of the body on the soil cancel to O(h)
    assert abs(led.interface_mismatch) < LEDGER_RTOL * led.scale


def test_subcycling_error_shrinks_at_first_order(dt, reference):
    """Oracle: observed convergence order. With the averaged wrench held over m DEM steps the
    coupling is first order in the exchange interval (exudyn_coupling.md); the error against
    the m = 1 run must fall at least at first order as m -> 1 (m halved each time); and
    momentum is still exchanged exactly (conservation)."""
    _, (traj_1, _, _) = reference
    mats = _materials(**EQUIV)
    ms = (2, 4, 8, 16)
    errs = []
    for m in ms:
        traj_m, _, cosim = run_coupled(dt, mats, m=m)
        idx = np.arange(m - 1, len(traj_1), m)[: len(traj_m)]
        errs.append(np.abs(traj_m[: len(idx)] - traj_1[idx]).max() / np.abs(traj_1 - X0).max())
        assert cosim.exchanges == len(traj_m)
        # the mean wrench over m steps carries exactly the DEM impulse (conservation)
        bal = cosim.momentum_balance()
        np.testing.assert_allclose(bal["error"], 0.0,
                                   atol=MOMENTUM_RTOL * np.abs(bal["impulse"]).max())
    errs = np.array(errs)
    rates = np.log(errs[1:] / errs[:-1]) / np.log(np.array(ms[1:]) / np.array(ms[:-1]))
    assert (rates > SUBCYCLING_MIN_ORDER).all(), (errs, rates)
    assert errs[0] < 10 * MATCH_RTOL


def test_eccentric_contact_pitch_rate():
    """Oracle: rigid-body impulse response. A body whose flat face strikes a free particle
    0.30 m off the CG (frictionless, elastic) gets d omega = I^-1 (r x J) with J the contact
    impulse, and J = 2 v_n / w, w = 1/M + 1/m_p + (r x n) . I^-1 (r x n) (elastic impact
    with a lever arm; Goldsmith, *Impact*, 1960, ch. 2)."""
    mat = soil.Material(young=2e7, density=2650.0, friction_angle=0.0, restitution=None)
    r_p = 0.05
    p = soil.Particles(np.array([[0.30, 0.0, -0.10 - r_p - 1e-4]]), r_p, [0],
                       rotation_blocked=False)
    spec = bodies.RigidBodySpec("paddle", 20.0, np.diag([10.0, 50.0, 50.0]),
                                *bodies.mesh.icosphere(0.1, 0))
    plate = soil.Plane((0.0, 0.0, -0.10), (0.0, 0.0, -1.0))  # body frame, faces down
    v_body = np.array([0.0, 0.0, -1.0])
    body = soil.BoundaryBody(shapes=[plate], material=0, motion="coupled", velocity=v_body)
    sim = soil.Simulation(p, [mat], [body], gravity=(0, 0, 0), dt=2e-5)
    model = bodies.ExudynRigidBody(spec, (0, 0, 0), np.eye(3), v_body, (0, 0, 0),
                                   gravity=(0, 0, 0))
    cosim = coupling.CoSimulation(sim, 0, model)
    l0 = model.momentum()[1]
    seen = []
    cosim.run(0.02, on_step=lambda t, s, mo: seen.append((t, s.time, mo.time)))
    assert cosim.had_contact and not cosim.in_contact and cosim.stop_reason == "time"
    t_cb = np.array(seen)
    np.testing.assert_allclose(t_cb[:, 0], t_cb[:, 1], rtol=0, atol=1e-15)
    np.testing.assert_allclose(t_cb[:, 0] - t_cb[:, 2], 0.5 * sim.dt, rtol=1e-6)  # staggering
    j = cosim.momentum_balance()["impulse"]
    r = np.array([0.30, 0.0, -0.10])  # lever arm of the contact point from the CG
    w_expected = np.linalg.solve(spec.inertia, np.cross(r, j))
    # the body turns by ~|omega| t_contact ~ 1e-4 rad during the contact: relative 1e-3
    np.testing.assert_allclose(model.angular_velocity(), w_expected,
                               atol=1e-3 * np.abs(w_expected).max())
    assert w_expected[1] < 0.0 and abs(w_expected[1]) > 1e-3  # nose-up pitch from a low hit
    # angular momentum about the CG changes by the DEM's angular impulse about the CG
    dl = model.momentum()[1] - l0
    np.testing.assert_allclose(dl, body.angular_impulse, atol=1e-9 * np.abs(dl).max())
    n = np.array([0.0, 0.0, -1.0])
    rn = np.cross(r, n)
    w_inv = 1 / 20.0 + 1 / sim.particles.mass[0] + rn @ np.linalg.solve(spec.inertia, rn)
    j_analytic = 2.0 * 1.0 / w_inv
    # leapfrog on a linear spring at omega_c dt ~ 0.02: rebound speed error ~1e-3
    assert j[2] == pytest.approx(j_analytic, rel=5e-3)


def test_stops_on_rebound(dt, reference):
    """Oracle: kinematics of the reference impact -- the sphere leaves the shallow bed
    moving up; the run stops at the first exchange out of contact, before t_end, at the
    same state as the uninterrupted run (no effect of the stop test on the physics)."""
    _, (traj_ref, _, _) = reference
    traj, sim, cosim = run_coupled(dt, _materials(**EQUIV), t_end=1.0, stop_on_rebound=True)
    assert cosim.stop_reason == "rebound" and sim.time < 1.0
    assert not cosim.in_contact and cosim.model.velocity()[2] > 0.0
    n = min(len(traj), len(traj_ref))
    np.testing.assert_array_equal(traj[:n], traj_ref[:n])


def test_set_up_errors(dt):
    """The coupling refuses set-ups that would double count or misplace loads."""
    mats = _materials()
    p = soil.Particles(X_BED, R_BED, np.zeros(len(X_BED), int))
    spec = sphere_spec()
    body = coupling.boundary_for(spec, 1, position=X0, velocity=V0)
    sim = soil.Simulation(p, mats, [_walls(), body], dt=dt)
    model = bodies.ExudynRigidBody(spec, X0, np.eye(3), V0, gravity=(0, 0, -9.0))
    with pytest.raises(ValueError, match="gravity"):
        coupling.CoSimulation(sim, 1, model)
    model = bodies.ExudynRigidBody(spec, X0, np.eye(3), V0, gravity=sim.gravity)
    with pytest.raises(ValueError, match="coupled"):
        coupling.CoSimulation(sim, 0, model)
    with pytest.raises(ValueError, match="exchange_every"):
        coupling.CoSimulation(sim, 1, model, exchange_every=0)


def test_glider_nose_impact_balances_momentum(dt):
    """Oracles: conservation of linear momentum (Delta p = contact impulse + weight impulse)
    and of angular momentum about the CG (Delta L_world = angular impulse of the contact
    torques) for the meshed glider fuselage striking the bed nose first at 45 deg."""
    spec = bodies.glider_fuselage(n_stations=12, n_around=12)
    pitch = np.deg2rad(45.0)  # nose down: positive rotation about +y (y left)
    rot = np.array([[np.cos(pitch), 0, np.sin(pitch)], [0, 1, 0], [-np.sin(pitch), 0,
                                                                   np.cos(pitch)]])
    nose = rot @ (spec.vertices[np.argmax(spec.vertices[:, 0])])
    top = X_BED[:, 2].max() + R_BED.max()
    x0 = np.array([0.0, 0.0, top + 0.01]) - nose
    v0 = 18.33 * np.array([np.cos(pitch), 0.0, -np.sin(pitch)]) * 0.3
    p = soil.Particles(X_BED, R_BED, np.zeros(len(X_BED), int), rotation_blocked=False)
    body = coupling.boundary_for(spec, 1, position=x0, rotation=rot, velocity=v0)
    sim = soil.Simulation(p, _materials(**EQUIV), [_walls(), body], dt=dt)
    model = bodies.ExudynRigidBody(spec, x0, rot, v0, gravity=sim.gravity)
    cosim = coupling.CoSimulation(sim, 1, model)
    l0 = model.momentum()[1]
    cosim.run(0.02)
    assert cosim.had_contact
    bal = cosim.momentum_balance()
    scale = np.abs(bal["impulse"]).max()
    np.testing.assert_allclose(bal["error"], 0.0, atol=MOMENTUM_RTOL * scale)
    dl = model.momentum()[1] - l0
    np.testing.assert_allclose(dl, body.angular_impulse, atol=1e-6 * np.abs(dl).max())
    # the soil pushes the nose up and back, ahead of the CG: a nose-up pitch rate, which the
    # pitch gyro (sensitive axis -y) reads positive (thesis §2.2.4 reports a nose-up rotation)
    gyro = spec.sensor("pitch_rate")
    assert model.angular_velocity() @ (model.rotation() @ gyro.axis) > 0.5


def test_restart_continues_the_run(dt, reference):
    """Oracle: the uninterrupted reference run. A coupling resumed from
    ``CoSimulation.state_dict`` (with the DEM from ``Simulation.state_dict``) continues it:
    the DEM restart is bit-exact and the rebuilt Exudyn body agrees to round-off."""
    _, (traj_ref, _, _) = reference
    mats = _materials(**EQUIV)
    traj_a, sim_a, cos_a = run_coupled(dt, mats, t_end=0.03)
    sim_b = soil.Simulation.from_state_dict(sim_a.state_dict())
    model_b = bodies.ExudynRigidBody(sphere_spec(), gravity=sim_b.gravity)
    cos_b = coupling.CoSimulation.from_state_dict(sim_b, 1, model_b, cos_a.state_dict())
    traj_b = []
    cos_b.run(T_END, on_step=lambda t, s, mo: traj_b.append(np.array(s.boundaries[1].position)))
    traj = np.vstack([traj_a, np.array(traj_b)])
    assert len(traj) == len(traj_ref)
    assert _rel_diff(traj_ref, traj) < ROUNDOFF_RTOL
    bal = cos_b.momentum_balance()
    scale = np.abs(bal["impulse"]).max()
    np.testing.assert_allclose(bal["error"], 0.0, atol=MOMENTUM_RTOL * scale)


def test_hertz_mindlin_coupled_sphere_follows_the_dem_particle(dt):
    """Oracle: independent implementation, as ``test_coupled_sphere_follows_the_dem_particle``,
    with the Hertz-Mindlin law (``soil.Material.contact_law``): the drop sphere as a DEM
    particle (pair contacts) and as the coupled Exudyn body (boundary contacts, R* of the two
    spheres) give the same trajectory to round-off, and the coupled ledger's residual is the
    particle run's balance error (the coupling adds none of its own)."""
    mats = [replace(m, contact_law="hertz_mindlin", poisson=0.25)
            for m in _materials(**EQUIV)]
    traj_p, sim_p = run_particle(dt, mats)
    traj_c, _, cosim = run_coupled(dt, mats)
    assert cosim.had_contact and np.abs(traj_p - X0).max() > 0.1
    assert _rel_diff(traj_p, traj_c) < ROUNDOFF_RTOL
    led = cosim.ledger
    assert led.residual == pytest.approx(sim_p.energy()["balance_error"], rel=1e-6,
                                         abs=1e-6 * led.scale)
    assert abs(led.interface_mismatch) < LEDGER_RTOL * led.scale
    # another law than the linear one: the trajectories part
    traj_lin, _ = run_particle(dt, _materials(**EQUIV))
    assert _rel_diff(traj_lin, traj_p) > 100 * ROUNDOFF_RTOL
