"""Throughput of the soil DEM kernels: a loose lattice bed hit by a rigid sphere at 19 m/s.

Prints particle-steps per second for 1 and 2 Numba threads and the memory per particle.
Yade 2023.02a on this machine kind: ~3.8e5 (1 thread, 11.6k spheres) and 2.9e5 particle-steps/s
(100k) (anchors section 8); the target is >= 1.2e6 on 1 thread for 50k particles.

``--hertz`` also runs the same scene with the Hertz-Mindlin law (``Material.contact_law``) and
prints its rate over the linear law's, measured in the same run. ``--shear`` runs it with a
normal dashpot (restitution 0.3) and then with a shear dashpot too (``shear_restitution`` 0.3)
and prints the second's rate over the first's.

Usage: python validation/perf_soil_kernels.py [--n 50000] [--steps 200] [--small] [--hertz]
[--shear]
"""

from __future__ import annotations

import argparse
import time

import numba
import numpy as np

import soil

R_MEAN = 0.05  # [m] grain radius
R_SPREAD = 0.1  # relative radius spread (uniform +-)
SPHERE_R = 0.45  # [m] drop sphere radius
V_IMPACT = 19.0  # [m/s]


def build(n_target: int, threads: int, seed: int = 1, fcc: bool = False,
          law: str = "linear", damping: dict | None = None) -> soil.Simulation:
    """Cubic lattice (spacing 2 R_MEAN, radii R_MEAN (1 +- R_SPREAD)/(1 + R_SPREAD)) in an open
    box with the sphere just touching the bed surface, moving down at 19 m/s (coupled-body
    kinematics). ``fcc=True``: face-centred cubic lattice (12 neighbours at 2 R_MEAN, a much
    denser contact network: the harder benchmark). ``damping``: ``Material`` keywords of its
    dashpots (``restitution``, ``shear_restitution``)."""
    h = 2.0 * R_MEAN
    if fcc:
        a = h * np.sqrt(2.0)  # cubic cell edge for nearest-neighbour distance h
        side = int(round((n_target / 4.0) ** (1.0 / 3.0)))
        base = np.array([[0, 0, 0], [0.5, 0.5, 0], [0.5, 0, 0.5], [0, 0.5, 0.5]]) * a
        g = np.arange(side) * a
        cells = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 1, 3)
        x = (cells + base[None]).reshape(-1, 3) + 0.5 * R_MEAN
        side_len = side * a
    else:
        side = int(round(n_target ** (1.0 / 3.0)))
        g = (np.arange(side) + 0.5) * h
        x = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
        side_len = side * h
    rng = np.random.default_rng(seed)
    r = R_MEAN * (1.0 + R_SPREAD * rng.uniform(-1.0, 1.0, x.shape[0])) / (1.0 + R_SPREAD)
    mat = soil.Material(young=2e7, density=2650.0, friction_angle=np.radians(30.0),
                        stiffness_ratio=0.25, name="gravel", contact_law=law,
                        **(damping or {}))
    p = soil.Particles(x=x, radius=r, material=0, rotation_blocked=True)
    top = float(x[:, 2].max()) + R_MEAN
    box = soil.BoundaryBody(shapes=[soil.Box((0, 0, 0), (side_len, side_len, 4 * side_len))])
    c = np.array([0.5 * side_len, 0.5 * side_len, top + SPHERE_R])
    sphere = soil.BoundaryBody(shapes=[soil.SphereBoundary(SPHERE_R)], motion="coupled",
                               position=c, velocity=(0.0, 0.0, -V_IMPACT))
    return soil.Simulation(p, [mat], [box, sphere], threads=threads)


def measure(n: int, steps: int, threads: int, fcc: bool = False, law: str = "linear",
            damping: dict | None = None) -> dict:
    numba.set_num_threads(threads)
    sim = build(n, threads, fcc=fcc, law=law, damping=damping)
    sim.step(5)  # warm-up (compilation is cached on disk)
    b0 = sim.n_builds
    t0 = time.perf_counter()
    c0 = time.process_time()
    sim.step(steps)
    wall = time.perf_counter() - t0
    cpu = time.process_time() - c0
    mem = sim.memory_bytes()
    return {
        "threads": threads,
        "particles": sim.particles.n,
        "steps": steps,
        "dt": sim.dt,
        "wall_s": wall,
        "particle_steps_per_s": sim.particles.n * steps / wall,
        # CPU-time rate: robust on a shared machine (threads x wall when not contended)
        "particle_steps_per_cpu_s": sim.particles.n * steps / cpu,
        "rebuilds": sim.n_builds - b0,
        "bytes_per_particle": mem["per_particle"],
        "pairs_per_particle": mem["pairs_per_particle"],
        "sphere_force_N": float(np.linalg.norm(sim.boundaries[1].force)),
    }


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--n", type=int, default=50_000)
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--small", action="store_true", help="2k particles, 20 steps (for tests)")
    ap.add_argument("--fcc", action="store_true", help="dense FCC lattice instead of cubic")
    ap.add_argument("--hertz", action="store_true",
                    help="also the Hertz-Mindlin law, its rate over the linear law's")
    ap.add_argument("--shear", action="store_true",
                    help="also a normal dashpot, then normal and shear dashpots: the second's "
                         "rate over the first's")
    a = ap.parse_args(argv)
    n, steps = (2_000, 20) if a.small else (a.n, a.steps)
    out = []
    prev = numba.get_num_threads()
    for th in (1, 2):
        if th > numba.config.NUMBA_NUM_THREADS:
            continue
        res = measure(n, steps, th, a.fcc)
        out.append(res)
        print(
            f"threads={th} N={res['particles']} steps={steps} dt={res['dt']:.3e} s "
            f"wall={res['wall_s']:.2f} s -> {res['particle_steps_per_s']:.3e} particle-steps/s "
            f"({res['particle_steps_per_cpu_s']:.3e} per CPU-s); "
            f"rebuilds={res['rebuilds']}; memory {res['bytes_per_particle']:.0f} B/particle "
            f"({res['pairs_per_particle']:.2f} pairs/particle); "
            f"|F_sphere|={res['sphere_force_N']:.3e} N"
        )
        if a.hertz:
            hz = measure(n, steps, th, a.fcc, "hertz_mindlin")
            hz["law"] = "hertz_mindlin"
            out.append(hz)
            print(f"threads={th} Hertz-Mindlin: {hz['particle_steps_per_cpu_s']:.3e} per CPU-s, "
                  f"{hz['particle_steps_per_cpu_s'] / res['particle_steps_per_cpu_s']:.2f} x "
                  f"the linear law's; memory {hz['bytes_per_particle']:.0f} B/particle")
        if a.shear:
            rates = []
            for damping in ({"restitution": 0.3},
                            {"restitution": 0.3, "shear_restitution": 0.3}):
                d = measure(n, steps, th, a.fcc, damping=damping)
                d["damping"] = damping
                out.append(d)
                rates.append(d["particle_steps_per_cpu_s"])
                print(f"threads={th} dashpots {damping}: {rates[-1]:.3e} per CPU-s; memory "
                      f"{d['bytes_per_particle']:.0f} B/particle")
            normal = rates[0] / res["particle_steps_per_cpu_s"]
            print(f"threads={th} the shear dashpot: {rates[1] / rates[0]:.2f} x the rate of the "
                  f"normal dashpot alone (undamped: {normal:.2f} x for the normal one)")
    numba.set_num_threads(prev)
    return out


if __name__ == "__main__":
    main()
