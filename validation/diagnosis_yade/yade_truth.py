"""Yade side of the diagnosis's out-of-code validation (run inside Yade, not importable).

``yade -n -j1 -x yade_truth.py <config.json>`` makes one "recording" of the drop test with
Yade 2023.02a's own numerics, from its own deposition to its own contact laws:

1. deposition (skipped when ``packing_npz`` exists): a ``pack.SpherePack.makeCloud`` cloud of
   grains in a cylinder, settled under gravity with Yade's local non-viscous damping
   (``NewtonIntegrator.damping``) until the unbalanced force falls below ``deposit_unbalanced``,
   the grains above ``bed_depth`` removed, settled again; positions and radii saved;
2. impact on a fresh scene: a ``utils.wall`` floor, a facet cylinder, the grains (``FrictMat``,
   ``CohFrictMat`` bonded at the first step when ``cohesion`` is given, or ``FrictViscoMat``
   with a normal dashpot of ``betan`` x critical when ``restitution`` is given), the drop mass
   (a sphere of the impactor material); Cundall-Strack law
   (``Law2_ScGeom_FrictPhys_CundallStrack``, ``Law2_ScGeom6D_CohFrictPhys_CohesionMoment`` or
   ``Law2_ScGeom_FrictViscoPhys_CundallStrackVisco``: the same springs plus the dashpot, whose
   force may pull while a contact opens), no other damping, rotations blocked unless
   ``free_rotation``; the grains deeper than ``layer_depth`` get ``layer_young_factor`` x E;
   ``O.dt = dt_factor * PWaveTimeStep()``;
3. the history (t, z, vz, Fz) of the drop mass every step -> ``<out>.npy`` (+ ``.json`` facts).

``contact_law = "hertz_mindlin"`` makes the impact with Yade's Hertz-Mindlin law instead
(``Ip2_FrictMat_FrictMat_MindlinPhys`` + ``Law2_ScGeom_MindlinPhys_Mindlin``): the grains, the
tank and the drop mass are ``FrictMat`` with the Young's modulus ``hertz_young`` (the layer's
``layer_young_factor`` x it) and Poisson's ratio ``hertz_poisson``. The deposition stays linear
(the bed is the same as the linear law's for the same seed). No damping unless
``restitution`` is given; then the Ip2 functor's restitution ``en`` = ``es`` = ``restitution``
on every contact (grain-grain, grain-tank, grain-drop mass), as EDEM and LIGGGHTS damp their
Hertz-Mindlin law. Yade 2023.02a (measured on the binary, and its HertzMindlin.cpp): each
contact's damping ratio is Thornton et al. 2013's (B6)-(B7) for a Hertzian contact that ends
when its force reaches zero (``betan`` = 0.4536 for e = 0.3, against the linear law's 0.358),
the dashpots ``c = 2 beta sqrt(m* k)`` with the tangent stiffnesses ``kn = 1.5 kno
sqrt(delta)``, ``ks = kso sqrt(delta)``; the normal force is cut at zero (it never pulls: a
head-on pair rebounds at 0.2995 of its approach speed for e = 0.3, 0.0993 for e = 0.1); the
shear dashpot acts only while the contact sticks (sliding, the shear force is the Coulomb
limit of the elastic one). The restitution is given as ``MatchMaker(algo="val")`` (what a
float converts to; ``MatchMaker(matches=(), val=e)`` alone keeps ``algo="avg"`` and throws).
Not with ``cohesion``.

Everything else (the speed offset, the sensor, the acquisition) is applied by the driver.
"""

import json
import math
import os
import sys
from pathlib import Path

import numpy as np

# inside Yade __file__ is the launcher; the script is sys.argv[0] (validation/<dir>/<script>)
sys.path.insert(0, str(Path(sys.argv[0]).resolve().parents[2]))
from validation.yade_history import finish, record_history  # noqa: E402

cfg = json.load(open(sys.argv[1]))
R_tank = cfg["tank_radius"]
H = cfg["bed_depth"]
r_mean = cfg["radius"]
g = cfg["gravity"]


def frict(young, density, phi, coh=None, betan=None, poisson=None):
    if poisson is not None:
        # Hertz-Mindlin: poisson is the material's Poisson's ratio (MindlinPhys), not ks/kn
        return O.materials.append(FrictMat(  # noqa: F821
            young=young, poisson=poisson, frictionAngle=phi, density=density))
    if betan is not None:
        # Cundall-Strack springs (kn, ks as FrictPhys) + normal dashpot cn = betan * 2 sqrt(m* kn);
        # a pair takes the nonzero betan of its two materials
        return O.materials.append(FrictViscoMat(  # noqa: F821
            young=young, poisson=cfg["stiffness_ratio"], frictionAngle=phi, density=density,
            betan=betan))
    if coh is None:
        return O.materials.append(FrictMat(  # noqa: F821 (Yade builtins)
            young=young, poisson=cfg["stiffness_ratio"], frictionAngle=phi, density=density))
    return O.materials.append(CohFrictMat(  # noqa: F821
        young=young, poisson=cfg["stiffness_ratio"], frictionAngle=phi, density=density,
        isCohesive=True, normalCohesion=coh, shearCohesion=coh, momentRotationLaw=False))


def tank(mat):
    O.bodies.append(utils.wall(0.0, axis=2, sense=1, material=mat))  # noqa: F821
    O.bodies.append(geom.facetCylinder((0, 0, cfg["tank_height"] / 2), R_tank,  # noqa: F821
                                       cfg["tank_height"], segmentsNumber=64, wallMask=4,
                                       material=mat))


if not os.path.exists(cfg["packing_npz"]):
    m = frict(cfg["young"], cfg["density"], cfg["friction_angle"])
    tank(m)
    # grains for a bed of porosity ~0.40 plus 15 %, in a loose cloud three bed depths high
    n_target = int(1.15 * 0.60 * math.pi * R_tank ** 2 * H / (4.0 / 3.0 * math.pi * r_mean ** 3))
    sp = pack.SpherePack()  # noqa: F821
    half = R_tank - 1.05 * r_mean * (1 + cfg["radius_spread"])
    n_box = int(n_target * 4.0 / math.pi) + 1
    sp.makeCloud((-half, -half, r_mean), (half, half, r_mean + 3.5 * H), rMean=r_mean,
                 rRelFuzz=cfg["radius_spread"], num=n_box, seed=cfg["seed"])
    for c, rad in sp:
        if c[0] ** 2 + c[1] ** 2 <= half ** 2:
            b = utils.sphere(c, rad, material=m)  # noqa: F821
            b.state.blockedDOFs = "XYZ"
            O.bodies.append(b)  # noqa: F821
    O.engines = [  # noqa: F821
        ForceResetter(),  # noqa: F821
        InsertionSortCollider([Bo1_Sphere_Aabb(), Bo1_Wall_Aabb(), Bo1_Facet_Aabb()]),  # noqa: F821
        InteractionLoop(  # noqa: F821
            [Ig2_Sphere_Sphere_ScGeom(), Ig2_Wall_Sphere_ScGeom(), Ig2_Facet_Sphere_ScGeom()],  # noqa: F821
            [Ip2_FrictMat_FrictMat_FrictPhys()],  # noqa: F821
            [Law2_ScGeom_FrictPhys_CundallStrack()]),  # noqa: F821
        NewtonIntegrator(damping=0.4, gravity=(0.0, 0.0, -g)),  # noqa: F821
    ]
    O.dt = 0.5 * PWaveTimeStep()  # noqa: F821

    def settle(t_min, max_steps):
        O.run(int(t_min / O.dt), True)  # noqa: F821
        k = 0
        while unbalancedForce() > cfg["deposit_unbalanced"] and k < max_steps:  # noqa: F821
            O.run(200, True)  # noqa: F821
            k += 200

    settle(1.2, 40000)
    for b in list(O.bodies):  # noqa: F821
        if isinstance(b.shape, Sphere) and b.state.pos[2] + b.shape.radius > H:  # noqa: F821
            O.bodies.erase(b.id)  # noqa: F821
    settle(0.3, 20000)
    xs, rs = [], []
    for b in O.bodies:  # noqa: F821
        if isinstance(b.shape, Sphere):  # noqa: F821
            xs.append(tuple(b.state.pos))
            rs.append(b.shape.radius)
    # written whole under another name, then renamed: a killed deposition leaves no bed
    tmp = f"{cfg['packing_npz']}.tmp-{os.getpid()}.npz"
    np.savez(tmp, x=np.array(xs), radius=np.array(rs))
    os.replace(tmp, cfg["packing_npz"])
    O.reset()  # noqa: F821

data = np.load(cfg["packing_npz"])
x, rad = data["x"], data["radius"]
coh = cfg.get("cohesion")
e = cfg.get("restitution")
hertz = cfg.get("contact_law", "linear") == "hertz_mindlin"
if hertz and coh is not None:
    raise SystemExit("contact_law='hertz_mindlin' is not made with cohesion")
# linear law: damping ratio of a linear spring-dashpot with restitution e (exact for a contact
# that may pull); the Hertz-Mindlin law takes e itself (MindlinPhys's en, es below)
beta = None if e is None or hertz else -math.log(e) / math.sqrt(math.pi ** 2 + math.log(e) ** 2)
# with a dashpot every material is a FrictViscoMat (the wall and the drop mass undamped, betan 0):
# Yade's mixed FrictMat-FrictViscoMat functor takes the bodies in one order only
other = None if beta is None else 0.0
nu = cfg["hertz_poisson"] if hertz else None
young = cfg["hertz_young"] if hertz else cfg["young"]
m_up = frict(young, cfg["density"], cfg["friction_angle"], coh, beta, nu)
m_low = m_up
if cfg.get("layer_depth") is not None:
    m_low = frict(young * cfg["layer_young_factor"], cfg["density"], cfg["friction_angle"],
                  coh, beta, nu)
m_wall = frict(young, cfg["density"], cfg["friction_angle"], betan=other, poisson=nu)
R = cfg["drop_radius"]
rho_imp = cfg["drop_mass"] / (4.0 / 3.0 * math.pi * R ** 3)
m_imp = frict(cfg["impactor_young"], rho_imp, 0.0, betan=other, poisson=nu)
tank(m_wall)
surface = float(np.max(x[:, 2] + rad))
z_layer = surface - cfg["layer_depth"] if cfg.get("layer_depth") is not None else -1.0
for i in range(len(rad)):
    b = utils.sphere(tuple(x[i]), float(rad[i]),  # noqa: F821
                     material=m_low if x[i, 2] < z_layer else m_up)
    if not cfg.get("free_rotation", False):
        b.state.blockedDOFs = "XYZ"
    O.bodies.append(b)  # noqa: F821
# the drop mass just above the grains under its footprint
foot = np.hypot(x[:, 0], x[:, 1]) < R + rad
top = float(np.max(x[foot, 2] + rad[foot])) if foot.any() else surface
drop = utils.sphere((0.0, 0.0, top + R + cfg["gap"]), R, material=m_imp)  # noqa: F821
drop.state.blockedDOFs = "XYZ"
drop.state.vel = Vector3(0.0, 0.0, -cfg["impact_speed"])  # noqa: F821
did = O.bodies.append(drop)  # noqa: F821
# grain-grain geometry with the rotations the cohesion moments need; wall and facet contacts alike
ig2 = [Ig2_Sphere_Sphere_ScGeom() if coh is None else Ig2_Sphere_Sphere_ScGeom6D(),  # noqa: F821
       Ig2_Wall_Sphere_ScGeom(), Ig2_Facet_Sphere_ScGeom()]  # noqa: F821
if hertz and e is not None:
    # the same restitution in the normal and the shear direction, on every contact
    ip2 = [Ip2_FrictMat_FrictMat_MindlinPhys(  # noqa: F821
        en=MatchMaker(matches=(), algo="val", val=e),  # noqa: F821
        es=MatchMaker(matches=(), algo="val", val=e))]  # noqa: F821
    law = [Law2_ScGeom_MindlinPhys_Mindlin()]  # noqa: F821
elif hertz:
    ip2 = [Ip2_FrictMat_FrictMat_MindlinPhys()]  # noqa: F821
    law = [Law2_ScGeom_MindlinPhys_Mindlin()]  # noqa: F821
elif beta is not None:
    ip2 = [Ip2_FrictViscoMat_FrictViscoMat_FrictViscoPhys()]  # noqa: F821
    law = [Law2_ScGeom_FrictViscoPhys_CundallStrackVisco()]  # noqa: F821
elif coh is None:
    ip2 = [Ip2_FrictMat_FrictMat_FrictPhys()]  # noqa: F821
    law = [Law2_ScGeom_FrictPhys_CundallStrack()]  # noqa: F821
else:
    ip2 = [Ip2_CohFrictMat_CohFrictMat_CohFrictPhys(setCohesionNow=True,  # noqa: F821
                                                    setCohesionOnNewContacts=False),
           Ip2_FrictMat_FrictMat_FrictPhys()]  # noqa: F821
    law = [Law2_ScGeom6D_CohFrictPhys_CohesionMoment(), Law2_ScGeom_FrictPhys_CundallStrack()]  # noqa: F821
O.engines = [  # noqa: F821
    ForceResetter(),  # noqa: F821
    InsertionSortCollider([Bo1_Sphere_Aabb(), Bo1_Wall_Aabb(), Bo1_Facet_Aabb()]),  # noqa: F821
    InteractionLoop(ig2, ip2, law),  # noqa: F821
    NewtonIntegrator(damping=0.0, gravity=(0.0, 0.0, -g)),  # noqa: F821
]
O.dt = cfg["dt_factor"] * PWaveTimeStep()  # noqa: F821
record_history(O, did, cfg["t_end"], cfg["out"],  # noqa: F821
               {"dt": O.dt, "grains": int(len(rad)), "surface_z": surface,  # noqa: F821
                "drop_top_z": top})
finish()
