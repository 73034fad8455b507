"""Yade side of the drop-campaign comparison (run inside Yade, not importable from crashdem).

``yade -n -j1 -x yade_drop.py <config.json>`` builds the same scene as crashdem.run for a drop
test in a cylindrical tank: the packing's x, r and material ids (two FrictMat layers), a
``utils.wall`` floor, a facet cylinder for the tank wall, the drop mass as a sphere of the
impactor material with density m / (4/3 pi R^3), rotations blocked, Cundall-Strack law, no
damping, fixed dt, gravity; it writes the history (t, z, vz, Fz) to ``<out>.npy``.

Differences from crashdem, by construction: the tank wall is made of facets (Yade uses 2r on
the facet side, crashdem's Cylinder uses the grain's own radius), and the drop mass is
integrated by Yade's leapfrog instead of Exudyn.
"""

import json
import sys
from pathlib import Path

import numpy as np

# inside Yade __file__ is the launcher; the script is sys.argv[0] (validation/<dir>/<script>)
sys.path.insert(0, str(Path(sys.argv[0]).resolve().parents[2]))
from validation.yade_history import finish, record_history  # noqa: E402

cfg = json.load(open(sys.argv[1]))
data = np.load(cfg["packing_npz"])
x, r, mat = data["x"], data["radius"], data["material"]
mids = []
for m in cfg["materials"]:
    mids.append(O.materials.append(FrictMat(  # noqa: F821 (Yade builtins)
        young=m["young"], poisson=m["stiffness_ratio"], frictionAngle=m["friction_angle"],
        density=m["density"])))
wall_mat, imp_mat = mids[cfg["wall_material"]], mids[cfg["impactor_material"]]
O.bodies.append(utils.wall(0.0, axis=2, sense=1, material=wall_mat))  # noqa: F821
R_tank = cfg["tank_radius"]
O.bodies.append(geom.facetCylinder((0, 0, cfg["tank_height"] / 2), R_tank,  # noqa: F821
                                   cfg["tank_height"], segmentsNumber=64, wallMask=4,
                                   material=wall_mat))
for i in range(len(r)):
    b = utils.sphere(tuple(x[i]), float(r[i]), material=mids[int(mat[i])])  # noqa: F821
    b.state.blockedDOFs = "XYZ"
    O.bodies.append(b)  # noqa: F821
R = cfg["drop_radius"]
drop = utils.sphere(tuple(cfg["drop_start"]), R, material=imp_mat)  # noqa: F821
drop.state.blockedDOFs = "XYZ"
drop.state.vel = Vector3(*cfg["drop_velocity"])  # noqa: F821
did = O.bodies.append(drop)  # noqa: F821
O.engines = [  # noqa: F821
    ForceResetter(),  # noqa: F821
    InsertionSortCollider([Bo1_Sphere_Aabb(), Bo1_Wall_Aabb(), Bo1_Facet_Aabb()]),  # noqa: F821
    InteractionLoop(  # noqa: F821
        [Ig2_Sphere_Sphere_ScGeom(), Ig2_Wall_Sphere_ScGeom(),  # noqa: F821
         Ig2_Facet_Sphere_ScGeom()],  # noqa: F821
        [Ip2_FrictMat_FrictMat_FrictPhys()],  # noqa: F821
        [Law2_ScGeom_FrictPhys_CundallStrack()],  # noqa: F821
    ),
    NewtonIntegrator(damping=0.0, gravity=(0.0, 0.0, -cfg["gravity"])),  # noqa: F821
]
O.dt = cfg["dt"]  # noqa: F821
record_history(O, did, cfg["t_end"], cfg["out"])  # noqa: F821
finish()
