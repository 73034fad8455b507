"""Build and run a scenario: packing -> DEM soil + boundaries -> Exudyn impactor -> coupling ->
virtual sensors -> HDF5 results (+ plots).

API
---
``run_scenario(scenario, out_dir=None, progress=True, resume=False, plots=None) -> Path``
``build_model(scenario, cache_dir) -> Model`` (everything but the run, for tests and the diagnosis)
``packing_spec(scenario) -> soil.packing.PackingSpec`` (what decides the deposited bed)
``impact_materials(scenario, packing) -> list[soil.Material]`` (what the impact phase uses)

The deposited packing depends only on the geometry, the grain size and the deposition-relevant
material data (E, density, friction, porosity targets, layering); impact-phase physics
(cohesion, rolling, contact damping, wall compliance...) is applied on top of a cached packing,
so re-runs that switch such physics on or off cost no new deposition.

Notes
-----
Impact speed: the body starts ``impactor.gap`` above the highest grain under it with the speed
``sqrt(v^2 - 2 g gap)``, so it touches the soil at the scenario's impact speed ``v``.
"""
from __future__ import annotations

import contextlib
import logging
import math
import os
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from crashdem.scenario import Scenario, ScenarioError

log = logging.getLogger("crashdem.run")

GRAVITY = np.array([0.0, 0.0, -9.81])  # [m/s^2]
#: Poplar plywood, 30 mm panels (glider container walls, thesis §2.2.2): E along the face grain
#: ~ 7 GPa (typical handbook value for poplar plywood; an assumption, stated in docs)
PLYWOOD_YOUNG = 7.0e9


@dataclass
class Model:
    """A built scenario, ready to run."""

    scenario: Scenario
    sim: Any  # soil.Simulation
    body_index: int
    spec: Any  # bodies.RigidBodySpec
    model: Any  # bodies.ExudynRigidBody
    cosim: Any  # coupling.CoSimulation
    sensors: Any  # crashdem.sensors.SensorSet
    packing: Any  # soil.packing.Packing
    surface_z: float  # free-surface height under the impactor [m]
    t_contact: float  # expected time of first contact [s]
    t_end: float  # end of the run [s]
    boundary_names: dict[str, int] = field(default_factory=dict)  # load-cell boundaries
    body_name: str = "drop_mass"  # sensor name of the coupled body
    extra: dict[str, Any] = field(default_factory=dict)  # scenario-specific objects
    #: called once per DEM step before the sensors record (e.g. compliant walls), or None
    pre_record: Any = None
    #: stateful objects outside the DEM, the coupling and the sensors (compliant walls, contact
    #: laws, crush elements...), by name; each has ``state_dict()`` / ``load_state_dict(d)``
    #: (and optionally ``rebind(old_sim, new_sim)``) so that checkpoints capture and restore
    #: them (``crashdem.checkpoint``)
    components: dict[str, Any] = field(default_factory=dict)


def _deg(x: float) -> float:
    return math.radians(x)


def _law(scen: Scenario) -> dict[str, Any]:
    """The impact phase's contact law as ``soil.Material`` fields ({} for the linear law, so
    that a linear scenario's materials stay as they were)."""
    if scen["soil.contact_law"] == "linear":
        return {}
    return {"contact_law": scen["soil.contact_law"], "poisson": scen["soil.poisson"]}


def soil_material(scen: Scenario, lower: bool = False):
    """The soil material of the upper (re-worked) or lower (compacted) layer."""
    import soil

    m = scen["soil.material"]
    young = m["young"]
    if lower:
        young *= scen["physics.soil_layering.lower_young_factor"]
    return soil.Material(young=young, density=m["density"],
                         friction_angle=_deg(m["friction_angle_deg"]),
                         stiffness_ratio=m["stiffness_ratio"],
                         name="soil_lower" if lower else "soil_upper")


def lower_grains(scen: Scenario, x: np.ndarray, top: float) -> np.ndarray:
    """The grains of the lower layer of a bed deposited whole (stiffness-only layering, an
    imported bed): those whose centre lies deeper than ``physics.soil_layering.depth`` below the
    bed's top ``top`` [m]."""
    return x[:, 2] < float(top) - float(scen["physics.soil_layering.depth"])


def stiffness_layer(scen: Scenario, packing):
    """``packing`` (deposited whole, as without the layering) with its lower grains given the
    lower layer's material: ``physics.soil_layering.compacted = false``, a stiffness
    discontinuity with no change of packing. The bed is the unlayered scenario's own, so its
    cache entry is shared with it. The interface lies ``depth`` below the bed's nominal top
    (``soil_depth``, where deposition cuts the grain centres: the level a compacted lower layer
    is deposited up to), so a depth means the same in both forms and on every packing seed
    (the highest grain's top, a single grain, scatters by a radius between packings)."""
    if scen["scenario.kind"] != "drop_test":
        raise ScenarioError("physics.soil_layering.compacted=false: a stiffness-only layer is "
                            "supported for scenario.kind='drop_test' only (the glider's container "
                            "deposits its compacted part); allowed: true")
    material = np.array(packing.material, dtype=np.int32, copy=True)
    material[lower_grains(scen, packing.x, soil_depth(scen))] = 1
    info = dict(packing.info or {})
    info["stiffness_layer_grains"] = int(np.count_nonzero(material == 1))
    return replace(packing, material=material,
                   materials=(packing.materials[0], soil_material(scen, lower=True)), info=info)


def soil_depth(scen: Scenario) -> float:
    d = scen["container.soil_depth"]
    if scen["physics.boundary_proximity.enabled"] and scen["physics.boundary_proximity.floor_depth"] is not None:
        d = scen["physics.boundary_proximity.floor_depth"]
    return d


def packing_spec(scen: Scenario):
    """The deposition spec of a scenario (its hash keys the packing cache)."""
    from soil import packing as pk

    depth = soil_depth(scen)
    r = scen["soil.radius"]
    dist = pk.RadiusDistribution(r, scen["soil.radius_spread"])
    materials = [soil_material(scen)]
    dep_phi = scen["soil.deposition_friction_deg"]
    dep_phi = None if dep_phi is None else _deg(dep_phi)
    upper_por = scen["soil.porosity_target"]
    if scen["physics.soil_layering.enabled"]:
        z_d = scen["physics.soil_layering.depth"]
        if not 0.0 < z_d < depth:
            raise ScenarioError(
                f"physics.soil_layering.depth={z_d!r}: must be in (0, {depth:g}) [m], inside the "
                "soil layer")
    if scen["physics.soil_layering.enabled"] and scen["physics.soil_layering.compacted"]:
        materials.append(soil_material(scen, lower=True))
        layers = (
            pk.LayerSpec(depth - z_d, material=1,
                         deposition_friction=_deg(scen["physics.soil_layering.lower_deposition_friction_deg"]),
                         target_porosity=scen["physics.soil_layering.lower_porosity"]),
            pk.LayerSpec(z_d, material=0, deposition_friction=dep_phi, target_porosity=upper_por),
        )
    else:
        layers = (pk.LayerSpec(depth, material=0, deposition_friction=dep_phi,
                               target_porosity=upper_por),)
    headroom = 1.0 * depth + 10 * r
    slope = None
    if scen["container.shape"] == "cylinder":
        container = pk.CylinderRegion((0.0, 0.0), 0.5 * scen["container.diameter"], 0.0,
                                      depth + headroom)
    else:
        lx, ly = scen["container.length"], scen["container.width"]
        container = pk.BoxRegion((-0.5 * lx, -0.5 * ly, 0.0), (0.5 * lx, 0.5 * ly, depth + headroom))
        if scen["container.slope_deg"] > 0:
            slope = pk.SlopeSpec(_deg(scen["container.slope_deg"]),
                                 "horizontal" if scen["container.compaction"] == "horizontal" else "normal")
    dep = pk.DepositionSettings(threshold=scen["solver.deposit_unbalanced"],
                                threads=scen["scenario.threads"] or None)
    return pk.PackingSpec(container=container, materials=tuple(materials), layers=layers,
                          radius=dist, seed=scen["scenario.seed"], deposition=dep, slope=slope,
                          gravity=float(-GRAVITY[2]))


def impact_materials(scen: Scenario, packing) -> list:
    """Materials of the impact phase: the packing's soil materials with the switched-on physics
    and ``soil.impact_young_factor`` x their modulus, then the container wall (of that scaled
    soil modulus unless ``container.wall_young`` or the floor's ``wall_young`` says otherwise)
    and the impactor (their indices: ``len(soil)`` and ``len(soil)+1``)."""
    import soil

    mats = []
    scale = float(scen["soil.impact_young_factor"])
    for m in packing.materials:
        kw: dict[str, Any] = {}
        if scen["physics.cohesion.enabled"]:
            c = scen["physics.cohesion"]
            kw["cohesion"] = soil.Cohesion(normal_strength=c["normal_strength"],
                                           shear_strength=c["shear_strength"],
                                           moments=c["moments"])
        if scen["soil.rotation"] == "free" or scen["physics.particle_rotation.enabled"]:
            mu_r = (scen["physics.particle_rotation.rolling_coefficient"]
                    if scen["physics.particle_rotation.enabled"] else scen["soil.rolling_coefficient"])
            kw["rolling"] = soil.Rolling(coefficient=mu_r)
        e = scen["soil.restitution"]
        e_s = scen["soil.shear_restitution"]
        if scen["physics.contact_damping.enabled"]:
            e = scen["physics.contact_damping.restitution"]
            kw["dashpot_tension"] = bool(scen["physics.contact_damping.tension"])
            if scen["physics.contact_damping.shear"]:
                e_s = e
        if e is not None:
            kw["restitution"] = e
        if e_s is not None:
            kw["shear_restitution"] = e_s
        kw.update(_law(scen))
        if scale != 1.0:
            kw["young"] = m.young * scale
        mats.append(replace(m, **kw) if kw else m)
    wall_e = scen["container.wall_young"]
    if scen["physics.boundary_proximity.enabled"] and scen["physics.boundary_proximity.wall_young"] is not None:
        wall_e = scen["physics.boundary_proximity.wall_young"]
    base = packing.materials[0]
    mats.append(replace(base, young=wall_e or base.young * scale, name="wall", **_law(scen)))
    mats.append(replace(base, young=scen["impactor.material_young"], friction_angle=0.0,
                        name="impactor", **_law(scen)))  # thesis §3.1: impactor friction null
    return mats


def _rotations_blocked(scen: Scenario) -> bool:
    return not (scen["soil.rotation"] == "free" or scen["physics.particle_rotation.enabled"])


def _container_top(scen: Scenario) -> float:
    """Height of the drop tank's walls [m]: the soil depth plus at least 2 m of freeboard."""
    depth = soil_depth(scen)
    return depth + max(2.0, depth)


def _container_boundary(scen: Scenario, packing, wall_material: int):
    import soil

    top = _container_top(scen)
    if scen["container.shape"] == "cylinder":
        shapes = [soil.Plane((0.0, 0.0, 0.0), (0.0, 0.0, 1.0)),
                  soil.Cylinder((0.0, 0.0), 0.5 * scen["container.diameter"], 0.0, top)]
    else:
        lx, ly = scen["container.length"], scen["container.width"]
        shapes = [soil.Box((-0.5 * lx, -0.5 * ly, 0.0), (0.5 * lx, 0.5 * ly, top), open_top=True)]
    return soil.BoundaryBody(shapes=shapes, material=wall_material, motion="fixed")


def _impactor_spec(scen: Scenario):
    import bodies

    if scen["impactor.body"] == "drop_sphere":
        spec = bodies.drop_sphere() if scen["impactor.mass"] is None else bodies.drop_sphere(
            mass=scen["impactor.mass"])
        return spec
    raise ScenarioError(
        f"impactor.body={scen['impactor.body']!r}: the glider crash scenario is not available in "
        "this version; allowed now: 'drop_sphere'")


def sensor_dynamics(scen: Scenario):
    """``(cfc, dynamics)`` of the accelerometer channels (``sensors.dynamics_from_scenario``):
    the instrumentation CFC and no mount model, unless ``physics.sensor_dynamics`` is on."""
    from crashdem import sensors as sn

    return sn.dynamics_from_scenario(scen)


def _sensor_set(scen: Scenario, spec, floor_name: str, body_name: str):
    from crashdem import sensors as sn

    fs = scen["instrumentation.sample_rate"]
    cfc, dyn = sensor_dynamics(scen)
    fs_g = scen["instrumentation.accel_full_scale_g"] * 9.80665
    out = []
    for m in spec.sensors:
        name = f"{body_name}_{m.name}"
        if m.kind == "accelerometer":
            full = min(float(m.full_scale), fs_g) if "accel_y" not in m.name else float(m.full_scale)
            out.append(sn.Accelerometer(name=name, body=body_name, position=tuple(m.position),
                                        axis=tuple(m.axis), full_scale=full, dynamics=dyn, cfc=cfc))
        else:
            out.append(sn.Gyroscope(name=name, body=body_name, axis=tuple(m.axis),
                                    full_scale=float(m.full_scale), cfc=cfc))
    r = spec.contact_radius or 0.0
    out += [
        sn.PointKinematics(name=f"{body_name}_velocity_z", body=body_name, quantity="velocity",
                           axis=(0.0, 0.0, 1.0), cfc=cfc),
        sn.PointKinematics(name=f"{body_name}_bottom_z", body=body_name, quantity="position",
                           point=(0.0, 0.0, -r), axis=(0.0, 0.0, 1.0), frame="world"),
        sn.BodyForce(name=f"{body_name}_contact_force_z", body=body_name, quantity="force",
                     axis=(0.0, 0.0, 1.0), cfc=cfc),
    ]
    # Eight floor load cells along a diameter (thesis §2.1.1: eight strain-gauge cells on the
    # tank bottom, aligned on a diameter, 2000 kg full scale). Footprint: 0.30 m discs, an
    # assumption (the cell size is not given); centres spread evenly over 80 % of the radius.
    if scen["container.shape"] == "cylinder":
        half = 0.4 * scen["container.diameter"]
    else:
        half = 0.4 * scen["container.length"]
    for k, xc in enumerate(np.linspace(-half, half, 8)):
        out.append(sn.LoadCell(name=f"floor_load_cell_{k + 1}", boundary=floor_name,
                               center=(float(xc), 0.0, 0.0), normal=(0.0, 0.0, 1.0), radius=0.15,
                               full_scale=2000.0 * 9.80665, cfc=cfc))
    return sn.SensorSet(out, fs=fs, t0=0.0, gravity=tuple(GRAVITY))


def build_model(scen: Scenario, cache_dir: str | os.PathLike, progress=None) -> Model:
    """Deposit (or load) the packing and assemble soil, impactor, coupling and sensors."""
    import bodies
    import coupling
    import soil
    from soil import packing as pk

    if scen["scenario.kind"] == "glider_crash":
        if scen["soil.packing_file"]:
            raise ScenarioError(f"soil.packing_file={scen['soil.packing_file']!r}: an imported "
                                "bed is supported for scenario.kind='drop_test' only (the "
                                "glider's container deposits its sloped bed)")
        try:
            from crashdem.glider import build_glider_model
        except ImportError:  # pragma: no cover - the glider module ships with the package
            raise ScenarioError("scenario.kind='glider_crash': crashdem.glider is missing") from None
        return build_glider_model(scen, cache_dir, progress=progress)
    if scen["physics.structural_crush.enabled"]:
        raise ScenarioError("physics.structural_crush.enabled=true: needs a crushable-nose body "
                            "(glider); the drop sphere is rigid by definition")
    spec_p = packing_spec(scen)
    if scen["soil.packing_file"]:
        from crashdem.beds import imported_packing

        packing = imported_packing(scen, spec_p, _container_top(scen))
    else:
        packing = pk.cached(spec_p, cache_dir)
        if scen["physics.soil_layering.enabled"] and not scen["physics.soil_layering.compacted"]:
            packing = stiffness_layer(scen, packing)
    mats = impact_materials(scen, packing)
    wall_mat, imp_mat = len(packing.materials), len(packing.materials) + 1
    particles = soil.Particles(x=packing.x, radius=packing.radius, material=packing.material,
                               rotation_blocked=_rotations_blocked(scen))
    container = _container_boundary(scen, packing, wall_mat)

    spec = _impactor_spec(scen)
    R = float(spec.contact_radius)
    v = scen.impact_velocity
    gap = scen["impactor.gap"]
    under = np.hypot(packing.x[:, 0], packing.x[:, 1]) <= R + packing.radius
    surface = float(np.max(packing.x[under, 2] + packing.radius[under])) if under.any() else float(
        np.max(packing.x[:, 2] + packing.radius))
    angle = scen["impactor.angle_deg"]
    if scen["physics.initial_conditions.enabled"]:
        angle += scen["physics.initial_conditions.angle_offset_deg"]
    v0 = math.sqrt(max(v * v - 2.0 * 9.81 * gap, 0.0))
    a = _deg(angle)
    vel = np.array([v0 * math.sin(a), 0.0, -v0 * math.cos(a)])
    pos = np.array([0.0, 0.0, surface + R + gap])
    body = coupling.boundary_for(spec, imp_mat, position=pos, velocity=vel)
    threads = scen["scenario.threads"] or None
    sim = soil.Simulation(particles, mats, [container, body], gravity=tuple(GRAVITY),
                          dt=scen["solver.dt"], safety=scen["solver.safety"], threads=threads)
    if scen["physics.cohesion.enabled"]:
        sim.bond_contacts()
    model = bodies.ExudynRigidBody(spec, position=pos, velocity=vel, gravity=tuple(GRAVITY))
    cosim = coupling.CoSimulation(sim, 1, model, exchange_every=scen["solver.exchange_every"])
    t_contact = gap / max(v, 1e-9)
    sensors = _sensor_set(scen, spec, "tank", "drop_mass")
    return Model(scen, sim, 1, spec, model, cosim, sensors, packing, surface, t_contact,
                 t_contact + scen["solver.t_end"], {"tank": 0}, "drop_mass")


def _boundary_contacts(contacts: dict, body: int):
    from crashdem.sensors import BoundaryContacts

    return BoundaryContacts.from_contacts(contacts, body)


def _body_state(cosim):
    """Sensor state of the coupled body at the DEM time ``t_{n+1}``.

    The pose is the one the DEM used at ``t_{n+1}``; the accelerations come from the wrench the
    DEM evaluated on that pose (``F_{n+1}``, Newton–Euler); the velocities are the leapfrog
    half-step values advanced by half a step, ``v_{n+1} = v_{n+1/2} + (h/2) a_{n+1}``. Taking
    the accelerations from the wrench that drove the *previous* step would make the
    accelerometer lag the contact force by one DEM step.
    """
    from crashdem.sensors import BodyState

    st = cosim.body_state()
    b = cosim.sim.boundaries[cosim.body_index]
    spec = cosim.model.spec
    h = cosim.sim.dt
    force = np.array(b.force, dtype=float)
    torque = np.array(b.torque, dtype=float)
    acc = force / spec.mass + np.asarray(cosim.sim.gravity, dtype=float)
    R = np.asarray(st.rotation)
    inertia_w = R @ np.asarray(spec.inertia) @ R.T
    w_half = np.asarray(st.angular_velocity)
    alpha = np.linalg.solve(inertia_w, torque - np.cross(w_half, inertia_w @ w_half))
    return BodyState(position=st.position, rotation=R,
                     velocity=np.asarray(st.velocity) + 0.5 * h * acc,
                     angular_velocity=w_half + 0.5 * h * alpha, acceleration=acc,
                     angular_acceleration=alpha, force=force, torque=torque)


def default_output(scen: Scenario, out_dir: str | os.PathLike | None) -> Path:
    d = Path(out_dir if out_dir is not None else scen["output.directory"])
    return d / f"{scen['scenario.name']}.h5"


#: the coupling refreshes its energy ledger every this many exchanges (``CoSimulation.run``)
LEDGER_EVERY = 10


def packing_cache(root: str | os.PathLike | None = None) -> Path:
    """A packing cache shared by runs of several commands (``crashdem diagnose
    --packing-cache``): ``<root>/<engine fingerprint>``, root defaulting to
    ``$CRASHDEM_CACHE/packings`` or ``~/.cache/crashdem/packings``. The fingerprint
    (``soil.packing.code_fingerprint``) changes with the soil engine's code and the numpy and
    numba versions, so a bed is only reused by the engine that deposited it; within one, the
    file name is the spec's hash. Nothing is created here."""
    from soil.packing import code_fingerprint

    if root is None:
        root = Path(os.environ.get("CRASHDEM_CACHE") or "~/.cache/crashdem") / "packings"
    return Path(root).expanduser().absolute() / code_fingerprint()


def share_packings(run_dir: str | os.PathLike, cache: str | os.PathLike) -> None:
    """Let the runs written to ``run_dir`` reuse (and add to) the deposited beds in ``cache``:
    ``run_scenario`` caches its packings in ``<out_dir>/packings``, which becomes a link to
    ``cache`` (both directories are created) unless it exists already. A link to another
    directory (say the engine-keyed cache of an earlier soil engine, ``packing_cache``, left in
    a reused output directory) is pointed at ``cache`` again; a real directory is kept. On a
    file system without symbolic links nothing is linked and the runs deposit their own beds."""
    run_dir, cache = Path(run_dir), Path(cache)
    link = run_dir / "packings"
    try:
        if link.is_symlink():
            cache.mkdir(parents=True, exist_ok=True)
            if link.resolve() == cache.resolve():
                return
            link.unlink()
        elif link.exists():
            return
        run_dir.mkdir(parents=True, exist_ok=True)
        cache.mkdir(parents=True, exist_ok=True)
        link.symlink_to(cache.resolve(), target_is_directory=True)
    except OSError:
        pass


@contextlib.contextmanager
def output_lock(path: Path, what: str = "another run is writing this file now"):
    """Hold ``<path>.lock`` (an exclusive ``flock``) while a run writes ``path``: a second run
    writing the same file -- two commands given the same output directory -- is refused with
    a ``ScenarioError`` instead of both writing it (HDF5 then reports "addr overflow" in one
    and the other's file is garbage). The lock goes with the process, so a killed run leaves
    none behind; the lock file is removed when the run ends. Without ``fcntl`` (Windows) there
    is no lock."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not on Linux/macOS
        yield
        return
    lock = Path(f"{path}.lock")
    fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise ScenarioError(
                f"{path}: {what} (lock {lock} held); give this one another output directory "
                "or scenario.name, or wait for it") from None
        try:
            yield
        finally:
            try:
                lock.unlink()
            except OSError:
                pass
    finally:
        os.close(fd)


def run_scenario(scen: Scenario, out_dir: str | os.PathLike | None = None, progress: bool = True,
                 resume: bool = False, plots: bool | None = None) -> Path:
    """Run a scenario end to end and return the HDF5 result path.

    Parameters
    ----------
    scen : Scenario
    out_dir : output directory (default: ``output.directory``)
    progress : show the progress line
    resume : continue a killed run from its last checkpoint (``<name>.ckpt.h5`` next to the
        result); the results are bit-identical to an uninterrupted run (same thread count)
    plots : write PNG plots (default: ``output.plots``)

    Notes
    -----
    With ``output.checkpoint_every_s`` set, a checkpoint (``crashdem.checkpoint``) is written
    at the first exchange at or after every multiple of that simulated-time interval that
    follows an energy-ledger refresh (so that the resumed ledger cadence is the same), and a
    final one (``complete=True``) at the end; see ``docs/restart.md``. The result file is
    locked for the run (``output_lock``): a second run of the same file is refused.
    """
    path = default_output(scen, out_dir)
    path.parent.mkdir(parents=True, exist_ok=True)
    with output_lock(path):
        return _run_scenario(scen, path, progress, resume, plots)


def _run_scenario(scen: Scenario, path: Path, progress: bool, resume: bool,
                  plots: bool | None) -> Path:
    """``run_scenario`` writing the result file ``path`` (its directory exists, its lock is
    held)."""
    from crashdem import checkpoint as ck
    from crashdem.progress import Progress
    from crashdem.results import ResultWriter

    ckpt_path = ck.checkpoint_path(path)
    every = scen["output.checkpoint_every_s"]
    saved = None
    if resume:
        saved = ck.read_checkpoint(ckpt_path)
        saved.check_scenario(scen, ckpt_path)
        if saved.complete and path.exists():
            from crashdem.results import open_result

            with open_result(path) as res:
                if res.complete:
                    raise ScenarioError(f"--resume: {path} is already complete (its checkpoint "
                                        f"{ckpt_path} holds the final state); nothing to resume")
    cache = path.parent / "packings"
    wall0 = time.perf_counter()
    log.info("building %s (packing cache: %s)", scen["scenario.name"], cache)
    m = build_model(scen, cache)
    if saved is not None or every is not None:
        ck.check_restartable(m, f"output.checkpoint_every_s={every!r}"
                             + (" / --resume" if resume else ""))
    if saved is not None:
        saved.restore(m)
        log.info("resuming %s from its checkpoint at t = %.6g s (%s)", scen["scenario.name"],
                 saved.t, ckpt_path)
    log.info("%d particles, dt = %.3g s (critical %.3g s), impact at %.2f m/s",
             m.sim.particles.n, m.sim.dt, m.sim.dt_critical, scen.impact_velocity)
    n_snap = scen["output.snapshots"]
    snap_times = list(np.linspace(0.0, m.t_end, n_snap)) if n_snap > 0 else []
    if saved is None:
        state = {"steps": 0, "snap": 0, "next_checkpoint": every if every is not None else 0.0}
        bar = Progress(m.t_end, label=scen["scenario.name"], enabled=progress)
        w = ResultWriter(path, scenario=scen, seed=scen["scenario.seed"],
                         threads=scen["scenario.threads"] or None,
                         title=scen["scenario.description"],
                         default_cfc=scen["instrumentation.cfc"])
    else:
        state = {k: saved.loop[k] for k in ("steps", "snap", "next_checkpoint")}
        if (state["steps"] - 1) % LEDGER_EVERY:
            raise ck.CheckpointError(
                f"{ckpt_path}: loop steps={state['steps']}: a checkpoint is taken right after "
                f"a ledger refresh (steps = 1 mod {LEDGER_EVERY})")
        bar = Progress(m.t_end, label=scen["scenario.name"], enabled=progress, t0=saved.t)
        poses = ck.read_body_poses(path, saved.t) if path.exists() else {}
        w = ResultWriter.resume(path, saved.t, sensor_set=m.sensors,
                                default_cfc=scen["instrumentation.cfc"])
    with w:
        if saved is None:
            w.declare_sensors(m.sensors)
        if snap_times:
            from crashdem.export import declare_body_surface, write_body_pose

            if saved is None:
                w.declare_snapshots(m.sim.particles.radius)
            elif "snapshots" not in w._f:
                raise ck.CheckpointError(f"{path}: the interrupted result has no snapshots "
                                         "group; cannot resume it")
            declare_body_surface(w, m.body_name, m.spec.vertices, m.spec.triangles)
            if saved is not None and m.body_name in poses:
                for pos, rot in zip(poses[m.body_name]["position"],
                                    poses[m.body_name]["rotation"]):
                    write_body_pose(w, m.body_name, pos, rot)
        if saved is None:
            m.cosim.update_ledger()
            w.declare_energy(list(_ledger_dict(m.cosim.ledger)))
        scen_hash = ck.scenario_hash(scen)
        steps0 = state["steps"]  # the progress bar's rate counts this session's steps only

        def checkpoint(t, complete=False):
            # everything drained so far is on disk before the checkpoint names it as kept
            w.append_sensors(m.sensors)
            w.flush()
            ck.write_checkpoint(ckpt_path, ck.Checkpoint.capture(
                m, t, loop=dict(state), scenario_hash=scen_hash, complete=complete))

        def record(t, sim, model):
            if m.pre_record is not None:
                m.pre_record(t, sim, model)
            contacts = sim.contacts() if m.boundary_names else None
            m.sensors.record(t, {m.body_name: _body_state(m.cosim)},
                             {name: _boundary_contacts(contacts, idx)
                              for name, idx in m.boundary_names.items()})
            state["steps"] += 1
            if state["steps"] % 10 == 0:
                w.append_sensors(m.sensors)
                e = m.cosim.ledger
                w.append_energy(t, _ledger_dict(e))
            while state["snap"] < len(snap_times) and t >= snap_times[state["snap"]] - 0.5 * sim.dt:
                w.write_snapshot(t, sim.particles.x)
                b = sim.boundaries[m.body_index]
                write_body_pose(w, m.body_name, b.position, b.rotation)
                state["snap"] += 1
            # CoSimulation.run refreshes the ledger at exchanges k = LEDGER_EVERY j counted
            # from its start (here steps = k + 1); a resumed run restarts k at 0, so the
            # checkpoint is taken right after a refresh to keep the same cadence
            if (every is not None and t >= state["next_checkpoint"]
                    and (state["steps"] - 1) % LEDGER_EVERY == 0):
                state["next_checkpoint"] = (math.floor(t / every) + 1) * every
                checkpoint(t)
            bar.update(t, state["steps"] - steps0)

        if saved is None:
            record(m.sim.time, m.sim, m.model)
        m.cosim.run(m.t_end, on_step=record, ledger_every=LEDGER_EVERY)
        w.append_sensors(m.sensors)
        w.append_energy(m.sim.time, _ledger_dict(m.cosim.ledger))
        if every is not None:
            checkpoint(m.sim.time, complete=True)
        bar.close(m.sim.time)
    info = {"particles": int(m.sim.particles.n), "dt": float(m.sim.dt),
            "dt_critical": float(m.sim.dt_critical), "surface_z": float(m.surface_z),
            "impact_velocity": float(scen.impact_velocity), "t_contact": float(m.t_contact),
            "stop_reason": str(m.cosim.stop_reason), "dem_steps": int(m.sim.step_count),
            "wall_s": time.perf_counter() - wall0}
    if saved is not None:
        info["resumed_from_t"] = float(saved.t)
    if "stiffness_layer_grains" in m.packing.info:
        info["stiffness_layer_grains"] = int(m.packing.info["stiffness_layer_grains"])
    if m.packing.info.get("source") == "imported":
        info.update(packing_file=m.packing.info["packing_file"],
                    packing_file_sha256=m.packing.info["packing_file_sha256"])
    _write_run_info(path, info)
    if plots if plots is not None else scen["output.plots"]:
        from crashdem.plotting import plot_result

        plot_result(path, path.with_suffix(""))
    log.info("wrote %s in %.1f s", path, time.perf_counter() - wall0)
    return path


def _ledger_dict(e) -> dict[str, float]:
    out = {f"soil_{k}": float(v) for k, v in e.soil.items() if np.isscalar(v)}
    out.update(body_kinetic=float(e.body_kinetic), body_potential=float(e.body_potential),
               body_interface_work=float(e.body_interface_work),
               soil_interface_work=float(e.soil_interface_work))
    return out


def _write_run_info(path: Path, info: dict[str, Any]) -> None:
    """Run facts (particle count, time step, surface height...) as attributes of ``/run``."""
    import h5py

    with h5py.File(path, "a") as f:
        g = f.require_group("run")
        for k, v in info.items():
            g.attrs[k] = v
