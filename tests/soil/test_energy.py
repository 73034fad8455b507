"""Energy ledger of the soil DEM: closure with friction, drift without dissipation."""

from __future__ import annotations

import math

import numpy as np

import soil

E = 2e7  # [Pa]
RHO = 2650.0  # [kg/m^3]
R = 0.05  # [m]


def small_bed(phi, nx=4, ny=4, nz=2, seed=0, restitution=None):
    """A lattice bed of slightly polydisperse spheres resting-ish on a floor in a box."""
    rng = np.random.default_rng(seed)
    h = 2 * R
    g = [(np.arange(k) + 0.5) * h for k in (nx, ny, nz)]
    x = np.stack(np.meshgrid(*g, indexing="ij"), axis=-1).reshape(-1, 3)
    r = R * (1 - 0.05 * rng.uniform(0, 1, x.shape[0]))
    return x, r


ENERGY_CLOSURE_TOL = 5e-3  # task requirement: 0.5 % of the impact energy


def test_energy_balance_closes_oblique_impact_with_friction():
    """Oracle: conservation of energy, KE + elastic + friction/damping dissipation - work of
    gravity - work of the walls = const; an oblique projectile hits a frictional bed in a box
    (walls, friction, free rotations, rolling resistance). The balance error must stay below
    0.5 % of the projectile's kinetic energy at every sampled instant."""
    phi = math.radians(30)
    x, r = small_bed(phi)
    proj = np.array([[2 * R, 2 * R, 4.2 * R + 0.02]])
    x = np.vstack([x, proj])
    r = np.append(r, R)
    v = np.zeros_like(x)
    v[-1] = [2.0, 1.0, -4.0]
    m0 = soil.Material(young=E, density=RHO, friction_angle=phi, stiffness_ratio=0.3,
                       rolling=soil.Rolling(0.05))
    p = soil.Particles(x=x, radius=r, rotation_blocked=False, v=v)
    box = soil.BoundaryBody(shapes=[soil.Box((0, 0, 0), (8 * R, 8 * R, 1.0))])
    sim = soil.Simulation(p, [m0], [box], dt=2e-5)
    ke0 = 0.5 * sim.particles.mass[-1] * (v[-1] ** 2).sum()
    worst = 0.0
    for _ in range(60):
        sim.step(50)
        e = sim.energy()
        worst = max(worst, abs(e["balance_error"]))
    assert e["dissipated_friction"] > 0.05 * ke0  # friction really acted
    assert worst < ENERGY_CLOSURE_TOL * ke0, (worst / ke0, e)


DRIFT_TOL = 1e-4  # task requirement, relative to the total mechanical energy


def test_energy_drift_frictionless_undamped():
    """Oracle: a frictionless, undamped elastic system conserves KE + elastic - W_gravity;
    the leapfrog scheme (symplectic) keeps the drift bounded: < 1e-4 relative over 1e4 steps."""
    x, r = small_bed(0.0, 3, 3, 2)
    rng = np.random.default_rng(1)
    v = rng.normal(0, 0.5, x.shape)
    m0 = soil.Material(young=E, density=RHO, friction_angle=0.0, stiffness_ratio=0.3)
    p = soil.Particles(x=x, radius=r, v=v)
    box = soil.BoundaryBody(shapes=[soil.Box((0, 0, 0), (6 * R, 6 * R, 6 * R),
                                             open_top=False)])
    sim = soil.Simulation(p, [m0], [box], dt=1e-5)
    e0 = sim.energy()
    ref = e0["kinetic_translational"] + e0["elastic"]
    worst = 0.0
    for _ in range(20):
        sim.step(500)
        worst = max(worst, abs(sim.energy()["balance_error"]))
    assert sim.step_count == 10_000
    assert len(sim.contacts()["i"]) > 0
    assert worst < DRIFT_TOL * ref, worst / ref


def test_global_damping_dissipation_accounted():
    """Oracle: energy conservation with Cundall damping; the damping work lambda |F||v| is
    booked in dissipated_global so the balance still closes (0.5 %) while the bed settles."""
    x, r = small_bed(0.5, 3, 3, 3)
    x[:, 2] += 0.02
    m0 = soil.Material(young=E, density=RHO, friction_angle=0.5, stiffness_ratio=0.3)
    p = soil.Particles(x=x, radius=r)
    box = soil.BoundaryBody(shapes=[soil.Box((0, 0, 0), (6 * R, 6 * R, 1.0))])
    sim = soil.Simulation(p, [m0], [box], global_damping=0.3, dt=2e-5)
    sim.step(3000)
    e = sim.energy()
    assert e["dissipated_global"] > 0.0
    assert abs(e["balance_error"]) < ENERGY_CLOSURE_TOL * e["work_gravity"]
