"""Coupling overhead and sub-cycling error of the DEM <-> Exudyn co-simulation.

Usage::

    python validation/bench_coupling.py            # 50,000 particles, + sub-cycling table
    python validation/bench_coupling.py --small    # ~2,000 particles (what the tests run)

1. Overhead: the 850 kg drop sphere (``bodies.drop_sphere``) strikes a lattice bed of N
   spheres. The same run is timed twice: (a) with a prescribed constant-velocity body
   (pure DEM, no coupling) and (b) coupled to Exudyn (``coupling.CoSimulation``, m = 1). The
   printed ratio is the coupling's wall time per step (kick + Exudyn step + pose update)
   over the DEM wall time per step of the same coupled run; the target is <= 5 % at 50,000
   particles.
2. Sub-cycling: on a small frictional bed, the trajectory error of m = 2, 5, 10, 20 against
   m = 1 (relative to the largest displacement).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import bodies
import coupling
import soil

#: target of the task: coupling overhead at most 5 % of the DEM step at 50,000 particles
OVERHEAD_TARGET = 0.05


def lattice_bed(n_target: int, r: float = 0.05, gap: float = 0.04, seed: int = 3):
    """Jittered cubic lattice of about ``n_target`` spheres, as wide as it is 4x deep."""
    rng = np.random.default_rng(seed)
    nz = max(2, int(round((n_target / 16.0) ** (1.0 / 3.0))))
    nx = max(2, int(round(np.sqrt(n_target / nz))))
    s = 2.0 * r * (1.0 + gap)
    g = np.arange(nx) * s - (nx - 1) * s / 2.0
    zz = r * (1.0 + gap) + np.arange(nz) * s
    gx, gy, gz = np.meshgrid(g, g, zz, indexing="ij")
    x = np.stack([gx.ravel(), gy.ravel(), gz.ravel()], axis=1)
    rad = r * (1.0 + 0.06 * (rng.random(len(x)) - 0.5))
    return x, rad, nx * s / 2.0


def _setup(n_target: int, motion: str):
    x, rad, half = lattice_bed(n_target)
    spec = bodies.drop_sphere()
    r_s = spec.contact_radius
    x0 = np.array([0.0, 0.0, x[:, 2].max() + rad.max() + r_s - 0.01])  # already in contact
    v0 = np.array([0.0, 0.0, -10.0])
    mats = [soil.Material(young=2e7, density=2650.0, friction_angle=0.5, restitution=0.5),
            soil.Material(young=2e7, density=2400.0, friction_angle=0.5, restitution=0.5)]
    walls = soil.BoundaryBody(shapes=[soil.Box((-half, -half, 0.0), (half, half, 5.0))],
                              material=0)
    if motion == "coupled":
        body = coupling.boundary_for(spec, 1, position=x0, velocity=v0)
    else:
        body = soil.BoundaryBody(
            shapes=[soil.SphereBoundary(r_s)], material=1, motion="prescribed",
            prescribed=lambda t: (x0 + v0 * t, np.eye(3), v0, np.zeros(3)))
    p = soil.Particles(x, rad, np.zeros(len(x), int), rotation_blocked=False)
    sim = soil.Simulation(p, mats, [walls, body])
    return sim, spec, x0, v0


def overhead(n_target: int, n_steps: int) -> dict:
    """Wall time per DEM step with and without the coupling [s] and their ratio."""
    sim_d, _, _, _ = _setup(n_target, "prescribed")
    sim_d.step(2)  # warm-up (compilation, first neighbour build)
    dem_only = []
    for _ in range(n_steps):
        tic = time.perf_counter()
        sim_d.step(1)
        dem_only.append(time.perf_counter() - tic)

    sim, spec, x0, v0 = _setup(n_target, "coupled")
    model = bodies.ExudynRigidBody(spec, x0, np.eye(3), v0, gravity=sim.gravity)
    cosim = coupling.CoSimulation(sim, 1, model, exchange_every=1)
    cosim.exchange()
    cosim.exchange()  # warm-up
    dem, exch = [], []
    for _ in range(n_steps):
        d0, e0 = cosim.wall_time["dem"], cosim.wall_time["exchange"]
        cosim.exchange()
        dem.append(cosim.wall_time["dem"] - d0)
        exch.append(cosim.wall_time["exchange"] - e0)
    # medians: the VM is shared, a mean is dominated by the steps another job preempted
    t_dem_only, t_dem, t_exch = (float(np.median(a)) for a in (dem_only, dem, exch))
    return {"n_particles": sim.particles.n, "dt": sim.dt, "dem_only_step": t_dem_only,
            "coupled_dem_step": t_dem, "coupling_per_step": t_exch,
            "ratio": t_exch / t_dem,
            "ratio_vs_dem_only": (t_dem + t_exch - t_dem_only) / t_dem_only,
            "contact_force": float(np.linalg.norm(cosim.last_force))}


def subcycling(ms=(1, 2, 5, 10, 20), n_target: int = 600, t_end: float = 0.06) -> dict:
    """Relative trajectory error of sub-cycled coupling against m = 1."""
    x, rad, half = lattice_bed(n_target, r=0.06)
    spec = bodies.drop_sphere()
    x0 = np.array([0.03, -0.02, x[:, 2].max() + rad.max() + spec.contact_radius + 0.02])
    v0 = np.array([0.5, 0.0, -5.0])
    mats = [soil.Material(young=2e7, density=2650.0, friction_angle=0.5, restitution=0.5),
            soil.Material(young=2e7, density=2400.0, friction_angle=0.5, restitution=0.5)]
    dt = None
    out = {}
    ref = None
    for m in ms:
        walls = soil.BoundaryBody(shapes=[soil.Box((-half, -half, 0.0), (half, half, 3.0))],
                                  material=0)
        body = coupling.boundary_for(spec, 1, position=x0, velocity=v0)
        p = soil.Particles(x, rad, np.zeros(len(x), int), rotation_blocked=False)
        sim = soil.Simulation(p, mats, [walls, body], dt=dt)
        dt = sim.dt
        model = bodies.ExudynRigidBody(spec, x0, np.eye(3), v0, gravity=sim.gravity)
        cosim = coupling.CoSimulation(sim, 1, model, exchange_every=m)
        traj = []
        cosim.run(t_end, on_step=lambda t, s, mo: traj.append(np.array(s.boundaries[1].position)))
        traj = np.array(traj)
        if ref is None:
            ref = traj
            out[m] = 0.0
            continue
        idx = np.arange(m - 1, len(ref), m)[: len(traj)]
        out[m] = float(np.abs(traj[: len(idx)] - ref[idx]).max() / np.abs(ref - x0).max())
    return out


def main(small: bool = False) -> dict:
    n_target, n_steps = (2000, 30) if small else (50_000, 40)
    res = overhead(n_target, n_steps)
    print(f"particles               {res['n_particles']}")
    print(f"dt                      {res['dt']:.3e} s")
    print("(medians over the timed steps)")
    print(f"DEM step, no coupling   {res['dem_only_step'] * 1e3:.3f} ms")
    print(f"DEM step, coupled run   {res['coupled_dem_step'] * 1e3:.3f} ms")
    print(f"coupling per step       {res['coupling_per_step'] * 1e6:.1f} us")
    print(f"overhead ratio          {res['ratio'] * 100:.3f} %  (target <= {OVERHEAD_TARGET:.0%})")
    print(f"total vs DEM-only       {res['ratio_vs_dem_only'] * 100:+.2f} %")
    if not small:
        sub = subcycling()
        print("sub-cycling error (relative to max displacement) vs m = 1:")
        for m, e in sub.items():
            print(f"  m = {m:3d}: {e:.3e}")
        res["subcycling"] = sub
    return res


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--small", action="store_true", help="~2,000 particles (test mode)")
    main(small=ap.parse_args().small)
