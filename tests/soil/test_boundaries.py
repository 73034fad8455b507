"""Boundary bodies: wrench, impulse and stiffness conventions."""

from __future__ import annotations

import math

import numpy as np
import pytest

import soil

E = 2e7  # [Pa]
RHO = 2650.0  # [kg/m^3]
R = 0.05  # [m]
G = 9.81  # [m/s^2]


def mat(phi=0.5):
    return soil.Material(young=E, density=RHO, friction_angle=phi, stiffness_ratio=0.25)


STATIC_TOL = 1e-3  # settled with Cundall damping: residual dynamic force << 0.1 % of the weight


def test_resting_bed_weight_equals_floor_force():
    """Oracle: static equilibrium; a settled bed inside frictionless side walls loads the floor
    body with its full weight (sum m g)."""
    h = 2 * R
    g = (np.arange(4) + 0.5) * h
    x = np.stack(np.meshgrid(g, g, (np.arange(3) + 0.5) * h, indexing="ij"), -1).reshape(-1, 3)
    rng = np.random.default_rng(5)
    r = R * (1 - 0.08 * rng.uniform(0, 1, x.shape[0]))
    p = soil.Particles(x=x, radius=r, material=0)
    floor = soil.BoundaryBody(shapes=[soil.Plane()], material=0)
    sides = soil.BoundaryBody(shapes=[soil.Box((0, 0, -1), (4 * h, 4 * h, 1.0))], material=1)
    # the box floor at z = -1 is never touched; its side planes are frictionless
    sim = soil.Simulation(p, [mat(0.5), mat(0.0)], [floor, sides], global_damping=0.7)
    sim.step(int(0.6 / sim.dt))
    weight = sim.particles.mass.sum() * G
    assert floor.force[2] == pytest.approx(-weight, rel=STATIC_TOL)
    assert abs(sides.force[2]) < STATIC_TOL * weight
    assert sim.unbalanced_force() < 1e-2


def test_eccentric_contact_torque():
    """Oracle: torque of a point load about a reference point, T = (c - P) x F; a sphere resting
    at (a, b) on a floor with reference P gives T = (c - P) x (0, 0, -m g)."""
    a, b = 0.3, -0.2
    m = 4 / 3 * math.pi * R**3 * RHO
    delta = m * G / (E * R)
    p = soil.Particles(x=[[a, b, R - delta]], radius=[R])
    ref = np.array([0.1, 0.05, -0.2])
    floor = soil.BoundaryBody(shapes=[soil.Plane()], reference_point=ref)
    sim = soil.Simulation(p, [mat()], [floor])
    sim.step(10)
    c = sim.contacts()["point"][0]
    f = np.array([0.0, 0.0, -m * G])
    expect = np.cross(c - ref, f)
    assert floor.force == pytest.approx(f, rel=1e-9, abs=1e-9 * m * G)
    assert floor.torque == pytest.approx(expect, rel=1e-9, abs=1e-9 * m * G)
    assert c[:2] == pytest.approx([a, b], abs=1e-12)


def test_sphere_boundary_matches_particle_sphere():
    """Oracle: independent implementation; a SphereBoundary of radius Rs gives the same contact
    force as a particle sphere of radius Rs held in place (same material, Yade sphere-sphere
    stiffness 2 E1 R1 E2 R2 / (E1 R1 + E2 R2))."""
    rs = 0.45
    x0 = np.array([[0.0, 0.0, rs + R - 1e-3]])
    v0 = np.array([[0.3, 0.0, -1.0]])
    pa = soil.Particles(x=x0, radius=[R], v=v0)
    body = soil.BoundaryBody(shapes=[soil.SphereBoundary(rs)])
    sa = soil.Simulation(pa, [mat()], [body], gravity=(0, 0, 0), dt=1e-5)
    pb = soil.Particles(x=np.vstack([x0, [[0, 0, 0]]]), radius=[R, rs],
                        v=np.vstack([v0, [[0, 0, 0]]]))
    sb = soil.Simulation(pb, [mat()], gravity=(0, 0, 0), dt=1e-5)
    sb.particles.inv_mass[1] = 0.0
    sb.particles.v[1] = 0.0
    for _ in range(30):
        sa.step(3)
        sb.step(3)
        assert sa.particles.f[0] == pytest.approx(sb.particles.f[0], rel=1e-12, abs=1e-9)
        assert -body.force == pytest.approx(sa.particles.f[0], rel=1e-12, abs=1e-9)


def test_moving_body_impulse_equals_momentum_transfer():
    """Oracle: conservation of momentum; a coupled sphere body moving at constant velocity
    through a few particles (no gravity): the body's accumulated impulse equals minus the
    momentum gained by the particles (to round-off), and its constant-velocity pose update is
    x = x0 + v t."""
    rs = 0.2
    x = np.array([[0.0, 0.0, 0.0], [0.12, 0.0, 0.02], [-0.1, 0.05, -0.03]])
    p = soil.Particles(x=x, radius=R)
    x0 = np.array([0.0, 0.0, 0.3])
    vb = np.array([0.0, 0.0, -5.0])
    body = soil.BoundaryBody(shapes=[soil.SphereBoundary(rs)], motion="coupled", position=x0,
                             velocity=vb, angular_velocity=(0.0, 3.0, 0.0))
    sim = soil.Simulation(p, [mat()], [body], gravity=(0, 0, 0), dt=2e-5)
    mv0 = (sim.particles.mass[:, None] * sim.synchronized_velocity()[0]).sum(0)
    sim.step(1500)
    # momentum of the particles at the half step after the last kick = sum of kicks
    mv = (sim.particles.mass[:, None] * sim.particles.v).sum(0)
    scale = np.abs(sim.particles.mass[:, None] * sim.particles.v).sum()
    assert scale > 0.1
    # the initial half kick (velocity-Verlet start) used F_0 = 0 here (no initial contact)
    assert mv - mv0 == pytest.approx(-body.impulse, abs=1e-12 * scale)
    assert body.position == pytest.approx(x0 + vb * sim.time, abs=1e-12)
    assert np.allclose(body.rotation @ body.rotation.T, np.eye(3), atol=1e-12)


def test_prescribed_motion_and_work():
    """Oracle: work-energy; a prescribed floor rising at constant speed lifts a resting sphere:
    work of the body on the particle = gain of KE + potential energy + stored elastic energy
    (frictionless, undamped) to the ledger's second-order accuracy (0.5 %)."""
    m = 4 / 3 * math.pi * R**3 * RHO
    delta = m * G / (E * R)
    p = soil.Particles(x=[[0.0, 0.0, R - delta]], radius=[R])
    u = 0.2

    def motion(t):
        return (0.0, 0.0, u * t), np.eye(3), (0.0, 0.0, u), (0.0, 0.0, 0.0)

    floor = soil.BoundaryBody(shapes=[soil.Plane()], motion="prescribed", prescribed=motion)
    sim = soil.Simulation(p, [mat(0.0)], [floor], dt=1e-5)
    sim.step(20000)
    e = sim.energy()
    assert floor.position[2] == pytest.approx(u * sim.time, rel=1e-12)
    assert e["work_boundaries"] > 0.1 * m * G * u * sim.time
    assert abs(e["balance_error"]) < 5e-3 * e["work_boundaries"]


def test_bad_shapes_named():
    """Oracle: parameter contract (field, value, range)."""
    with pytest.raises(ValueError, match=r"Cylinder.radius=-1.0: must be > 0 \[m\]"):
        soil.Cylinder(radius=-1.0)
    with pytest.raises(ValueError, match=r"SphereBoundary.radius=0.0: must be > 0 \[m\]"):
        soil.SphereBoundary(0.0)
    with pytest.raises(ValueError, match=r"BoundaryBody.motion='moving'"):
        soil.BoundaryBody(motion="moving")


def test_cylinder_tank_contains_particles():
    """Oracle: geometry; a particle thrown at the inside of a vertical cylinder wall bounces
    back and never leaves the tank: max radial position = R_tank - r + v sqrt(m/k_n)."""
    p = soil.Particles(x=[[0.0, 0.0, 0.5]], radius=[R], v=[[3.0, 1.0, 0.0]])
    tank = soil.BoundaryBody(shapes=[soil.Cylinder((0.0, 0.0), 0.5, 0.0, 1.0), soil.Plane()])
    sim = soil.Simulation(p, [mat(0.0)], [tank], gravity=(0, 0, 0), dt=2e-5)
    rmax = 0.0
    for _ in range(200):
        sim.step(60)  # 0.24 s at 3.2 m/s: reaches the wall and comes back
        rmax = max(rmax, float(np.hypot(*sim.particles.x[0, :2])))
    m = 4 / 3 * math.pi * R**3 * RHO
    delta_max = math.hypot(3.0, 1.0) * math.sqrt(m / (E * R))  # undamped linear spring
    assert rmax < 0.5 - R + 1.01 * delta_max
    assert rmax > 0.5 - R + 0.9 * delta_max
