"""Yade side of validation/bench_dem.py: the impact phase of a drop on a deposited packing.

Run by bench_dem.py as ``yade -n -j<threads> -x impact_bench.py <config.json>``; not importable
from crashdem (it runs inside Yade's own Python).  It reads the same packing arrays (x, y, z, r)
that crashdem uses, builds the same scene (``utils.wall`` box, rotations blocked, FrictMat with
``poisson`` = ks/kn, Law2_ScGeom_FrictPhys_CundallStrack, no damping), times only the impact
steps and writes the drop-mass history and the timing to ``<out>.npz`` / ``<out>.json``.

Scene contract (identical in bench_dem.py):
  - soil spheres: material 0 (E, nu=ks/kn, phi, rho), blockedDOFs = rotations;
  - container walls: ``utils.wall`` at the box faces (floor + 4 sides), material 1;
  - drop mass: a sphere of radius R, material 2 with density m / (4/3 pi R^3), rotations blocked,
    initial velocity (0, 0, -v0), centre at ``z_start``;
  - gravity (0, 0, -g) on everything; NewtonIntegrator damping 0; fixed dt.
"""

import json
import resource
import sys
import time

import numpy as np

cfg = json.load(open(sys.argv[1]))
HERTZ = cfg.get("contact_law", "linear") == "hertz_mindlin"
data = np.load(cfg["packing_npz"])
x, r = data["x"], data["radius"]
mats = []
for m in cfg["materials"]:
    mats.append(
        O.materials.append(  # noqa: F821 (Yade builtins)
            FrictMat(  # noqa: F821
                young=m["young"],
                # Hertz-Mindlin: Poisson's ratio; the linear law: ks/kn
                poisson=m["poisson"] if HERTZ else m["stiffness_ratio"],
                frictionAngle=m["friction_angle"],
                density=m["density"],
            )
        )
    )
lo, hi = cfg["box_lo"], cfg["box_hi"]
walls = [
    utils.wall(lo[2], axis=2, sense=1, material=mats[1]),  # noqa: F821
    utils.wall(lo[0], axis=0, sense=1, material=mats[1]),  # noqa: F821
    utils.wall(hi[0], axis=0, sense=-1, material=mats[1]),  # noqa: F821
    utils.wall(lo[1], axis=1, sense=1, material=mats[1]),  # noqa: F821
    utils.wall(hi[1], axis=1, sense=-1, material=mats[1]),  # noqa: F821
]
O.bodies.append(walls)  # noqa: F821
spheres = [
    utils.sphere(tuple(x[i]), float(r[i]), material=mats[0])  # noqa: F821
    for i in range(len(r))
]
for b in spheres:
    b.state.blockedDOFs = "XYZ"
O.bodies.append(spheres)  # noqa: F821
drop = utils.sphere(tuple(cfg["drop_start"]), cfg["drop_radius"], material=mats[2])  # noqa: F821
drop.state.blockedDOFs = "XYZ"
drop.state.vel = Vector3(*cfg["drop_velocity"])  # noqa: F821
drop_id = O.bodies.append(drop)  # noqa: F821
mass_yade = O.bodies[drop_id].state.mass  # noqa: F821

O.engines = [  # noqa: F821
    ForceResetter(),  # noqa: F821
    InsertionSortCollider([Bo1_Sphere_Aabb(), Bo1_Wall_Aabb()]),  # noqa: F821
    InteractionLoop(  # noqa: F821
        [Ig2_Sphere_Sphere_ScGeom(), Ig2_Wall_Sphere_ScGeom()],  # noqa: F821
        [Ip2_FrictMat_FrictMat_MindlinPhys() if HERTZ  # noqa: F821
         else Ip2_FrictMat_FrictMat_FrictPhys()],  # noqa: F821
        [Law2_ScGeom_MindlinPhys_Mindlin() if HERTZ  # noqa: F821
         else Law2_ScGeom_FrictPhys_CundallStrack()],  # noqa: F821
    ),
    NewtonIntegrator(damping=0.0, gravity=(0.0, 0.0, -cfg["gravity"])),  # noqa: F821
]
O.dt = cfg["dt"]  # noqa: F821
n_steps = int(cfg["steps"])
# t, z, vz, Fz (contact force of the step), spare column
hist = np.zeros((n_steps + 1, 5))


STEP = {"k": 1}
contacts = []


def rec():
    """PyRunner, every step after the force evaluation and the integration of that step."""
    k = STEP["k"] = STEP["k"] + 1
    b = O.bodies[drop_id]  # noqa: F821
    hist[k, :4] = (k * O.dt, b.state.pos[2], b.state.vel[2], O.forces.f(drop_id)[2])  # noqa: F821
    if k % 25 == 0:
        contacts.append(O.interactions.countReal())  # noqa: F821


b0 = O.bodies[drop_id]  # noqa: F821
hist[0, :4] = (0.0, b0.state.pos[2], b0.state.vel[2], 0.0)
# first step untimed (collider initialisation), as in crashdem
O.run(1, True)  # noqa: F821
hist[1, :4] = (O.time, O.bodies[drop_id].state.pos[2], O.bodies[drop_id].state.vel[2],  # noqa: F821
               O.forces.f(drop_id)[2])  # noqa: F821
O.engines = O.engines + [PyRunner(command="rec()", iterPeriod=1)]  # noqa: F821
# one O.run for the timed steps: a per-step O.run(1) costs milliseconds of thread hand-off
t0 = time.perf_counter()
O.run(n_steps - 1, True)  # noqa: F821
elapsed = time.perf_counter() - t0
out = {
    "code": "yade",
    "threads": int(cfg["threads"]),
    "particles": int(len(r)),
    "steps_timed": n_steps - 1,
    "elapsed_s": elapsed,
    "particle_steps_per_s": len(r) * (n_steps - 1) / elapsed,
    "contacts_per_step": float(np.mean(contacts)) if contacts else 0.0,
    "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
    "drop_mass": mass_yade,
}
np.save(cfg["out"] + ".npy", hist)
json.dump(out, open(cfg["out"] + ".json", "w"))
print("BENCH_DONE", json.dumps(out))
sys.stdout.flush()
import os  # noqa: E402

os._exit(0)
