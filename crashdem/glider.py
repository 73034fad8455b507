"""The reference glider crash (Varriale 2019 §2.2, §2.4): a 343 kg rigid fuselage in Exudyn,
released from a sled at 18.33 m/s, flying freely into a 45° soil slope inside a container of
30 mm poplar-plywood panels, coupled to the DEM soil.

API
---
``build_glider_model(scen, cache_dir, progress=None) -> crashdem.run.Model`` (``run.build_model``
dispatches ``scenario.kind = "glider_crash"`` here; ``run.run_scenario`` then runs it);
``PlywoodPanel`` (plate-theory panel -> one-degree-of-freedom support), ``CompliantWall`` (a
rigid panel boundary body on that support, integrated every DEM step), ``BodyWallContact`` (the
fuselage against the container walls: the nose's secondary impact on the rear wall);
``release_state(...)`` (ballistic free flight from the sled to the DEM start);
``crash_features(signals, t_contact)`` (the reference features: two deceleration peaks, pitch
extremes, event duration); ``kinematic_identity(signals, mount)`` (oracle of the accelerometer
channels).

Geometry (world frame, z up, gravity -z): the container's inner box is
``[-L/2, L/2] x [-W/2, W/2] x [0, H]``; the slope is the plane through the front bottom edge
``(x = -L/2, z = 0)`` rising towards +x at ``container.slope_deg`` (``soil.packing.SlopeSpec``);
the fuselage flies along +x; the rear wall is at ``x = +L/2``.

Walls (``CompliantWall``): the rear and the two side walls are plywood panels, each a rigid
plane (``soil.Plane``) carried by a coupled ``soil.BoundaryBody`` translating along its outward
normal on a spring-mass-damper whose mass and stiffness are those of the fundamental mode of a
simply supported plate, expressed in the panel's *mean* normal displacement (see
``PlywoodPanel``). The floor (laboratory slab) and the low front edge are rigid.

Notes
-----
Kirchhoff plate, simply supported on four edges (Navier): fundamental mode
``w = q sin(pi x/a) sin(pi y/b)``, ``omega_11 = pi^2 (1/a^2 + 1/b^2) sqrt(D / (rho t))``,
``D = E t^3 / (12 (1 - nu^2))`` (Timoshenko & Woinowsky-Krieger, *Theory of Plates and
Shells*, §28; Leissa, *Vibration of Plates*, NASA SP-160, Tab. 4.1). Mean displacement
``u = (2/pi)^2 q``; kinetic energy ``rho t a b q'^2/8`` gives the mass
``M_u = rho t a b pi^4/64``; ``K_u = M_u omega_11^2``. Free flight: torque-free rigid
body, ``omega`` constant when it is about a principal axis (Euler's equations).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from crashdem.scenario import Scenario, ScenarioError
from crashdem.sensors import _Sensor

__all__ = [
    "BodyWallContact",
    "CompliantWall",
    "CrushChannel",
    "NOSE_CUT_STATION",
    "PlywoodPanel",
    "POPLAR_PLYWOOD_DENSITY",
    "WALL_DAMPING_RATIO",
    "build_glider_model",
    "coupled_specs",
    "crash_features",
    "glider_spec",
    "kinematic_identity",
    "release_state",
]

G0 = 9.80665  # [m/s^2] standard gravity (g units of the reported accelerations)
#: Poplar plywood density [kg/m^3] (typical 400-500 for poplar plywood; an assumption)
POPLAR_PLYWOOD_DENSITY = 450.0
#: Poisson ratio of the equivalent isotropic plywood plate [-] (assumption)
PLYWOOD_POISSON = 0.3
#: Modal damping ratio of a screwed plywood panel [-] (wood 1-3 % plus joint friction; assumption)
WALL_DAMPING_RATIO = 0.05
#: Local bearing stiffness between the fuselage and a wall [N/m]: through-thickness plywood
#: modulus ~0.4 GPa over a ~0.075 m^2 nose footprint and a 30 mm panel, E A / t = 1e9 N/m,
#: capped to 2e8 N/m so the penalty contact stays far inside the DEM step's stability limit
#: (omega h < 0.3 for h = 1e-4 s); either way the panel's global compliance (1e6-1e7 N/m)
#: governs the secondary impact force.
WALL_CONTACT_STIFFNESS = 2.0e8
#: Damping ratio of the fuselage-wall penalty contact (composite skin crushing; assumption)
WALL_CONTACT_DAMPING = 0.2
#: Default friction angle of the fuselage skin on the grains [deg] (``glider.skin_friction_deg``):
#: glass/carbon-epoxy laminate on dry gravel, mu ~ 0.5-0.6 (assumption); the pair uses
#: min(phi_skin, phi_soil) (Yade). The drop sphere's null impactor friction (thesis §3.1) is not
#: carried over to the glider, whose nose slides up the slope during the primary impact.
FUSELAGE_FRICTION_DEG = 30.0
#: Time between the DEM start and the nominal first contact [s] (records the free flight)
PRE_CONTACT_TIME = 0.02
#: Threshold of the event duration, as a fraction of the reference peak 20 g [-]
DURATION_THRESHOLD_G = 2.0
#: Station of the crushable nose's aft end [m] (``physics.structural_crush``): the nose cone
#: ahead of the cockpit (the loft's elliptic nose is 0.70 m long; the front accelerometers at
#: 0.40 m, which broke in the test, sit in it); an assumption, longer than the default stroke
#: 0.2 m. The nose takes the mesh triangles at or ahead of it.
NOSE_CUT_STATION = 0.5


# ---------------------------------------------------------------------------------------------
# plate theory -> panel support
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class PlywoodPanel:
    """A rectangular plywood wall panel reduced to one degree of freedom (its mean normal
    displacement), from the fundamental mode of a simply supported Kirchhoff plate.

    Parameters
    ----------
    width : float
        Panel edge along its first in-plane axis [m], > 0.
    height : float
        Panel edge along its second in-plane axis [m], > 0.
    thickness : float
        [m], > 0 (thesis: 30 mm).
    young : float
        Equivalent isotropic bending modulus [Pa], > 0 (poplar plywood ~7 GPa along the face
        grain, ``crashdem.run.PLYWOOD_YOUNG``).
    density : float
        [kg/m^3], > 0.
    poisson : float
        [-], in [0, 0.5).
    bays : int
        Number of identical bays the panel is divided into by line supports along ``height``
        (e.g. 2 for a steel stiffener at mid-height), >= 1; each bay is simply supported on
        its four edges and all bays move together.
    damping_ratio : float
        Modal damping ratio [-], in [0, 1).

    Notes
    -----
    ``D = E t^3/(12(1-nu^2))``; ``omega = pi^2 (1/a^2 + 1/b^2) sqrt(D/(rho t))`` with the bay
    edges ``a = width``, ``b = height/bays`` (Navier solution, Timoshenko & Woinowsky-Krieger
    §28; Leissa NASA SP-160 Tab. 4.1). Mean displacement of the mode ``(2/pi)^2 q`` gives the
    generalised mass ``M = rho t A pi^4/64`` (A the whole panel area) and ``K = M omega^2``;
    under a uniform pressure the static mean deflection ``F/K`` is the first term of the Navier
    series (99.0 % of the whole series for a square plate).
    """

    width: float
    height: float
    thickness: float = 0.03
    young: float = 7.0e9
    density: float = POPLAR_PLYWOOD_DENSITY
    poisson: float = PLYWOOD_POISSON
    bays: int = 1
    damping_ratio: float = WALL_DAMPING_RATIO

    def __post_init__(self) -> None:
        for name, unit in (("width", "m"), ("height", "m"), ("thickness", "m"), ("young", "Pa"),
                           ("density", "kg/m^3")):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"PlywoodPanel.{name}={v!r}: must be > 0 [{unit}]")
        if not 0.0 <= self.poisson < 0.5:
            raise ValueError(f"PlywoodPanel.poisson={self.poisson!r}: must be in [0, 0.5) [-]")
        if int(self.bays) != self.bays or self.bays < 1:
            raise ValueError(f"PlywoodPanel.bays={self.bays!r}: must be an integer >= 1")
        if not 0.0 <= self.damping_ratio < 1.0:
            raise ValueError(
                f"PlywoodPanel.damping_ratio={self.damping_ratio!r}: must be in [0, 1) [-]")

    @property
    def flexural_rigidity(self) -> float:
        """``D = E t^3 / (12 (1 - nu^2))`` [N m]."""
        return self.young * self.thickness**3 / (12.0 * (1.0 - self.poisson**2))

    @property
    def mass(self) -> float:
        """Physical panel mass [kg]."""
        return self.density * self.thickness * self.width * self.height

    @property
    def omega(self) -> float:
        """Fundamental angular frequency of a bay [rad/s]."""
        a, b = self.width, self.height / self.bays
        return math.pi**2 * (1.0 / a**2 + 1.0 / b**2) * math.sqrt(
            self.flexural_rigidity / (self.density * self.thickness))

    @property
    def frequency(self) -> float:
        """Fundamental frequency [Hz]."""
        return self.omega / (2.0 * math.pi)

    @property
    def modal_mass(self) -> float:
        """Generalised mass of the mean-displacement coordinate, ``rho t A pi^4/64`` [kg]."""
        return self.mass * math.pi**4 / 64.0

    @property
    def stiffness(self) -> float:
        """Support stiffness of the mean displacement, ``M omega^2`` [N/m]."""
        return self.modal_mass * self.omega**2

    @property
    def damping(self) -> float:
        """Viscous support coefficient ``2 zeta sqrt(K M)`` [N s/m]."""
        return 2.0 * self.damping_ratio * math.sqrt(self.stiffness * self.modal_mass)

    def describe(self) -> dict[str, float]:
        """The numbers that define the support (for the run report)."""
        return {"width_m": self.width, "height_m": self.height, "bays": int(self.bays),
                "thickness_m": self.thickness, "young_Pa": self.young,
                "density_kg_m3": self.density, "poisson": self.poisson,
                "D_Nm": self.flexural_rigidity, "f1_Hz": self.frequency,
                "mass_kg": self.mass, "modal_mass_kg": self.modal_mass,
                "stiffness_N_m": self.stiffness, "damping_ratio": self.damping_ratio}


class CompliantWall:
    """A container wall: rigid plane on a ``PlywoodPanel`` support, leapfrog-integrated.

    Parameters
    ----------
    name : str
    panel : PlywoodPanel
    body : soil.BoundaryBody
        ``motion="coupled"`` body carrying the wall plane (origin at the world origin).
    outward : (3,) unit vector
        Direction the soil pushes the wall (opposite to the plane's particle-side normal).

    Notes
    -----
    ``M u'' = F_soil . e - F_0 - K u - C u' + F_extra``: ``F_0`` is the at-rest soil force at
    the start (the panel is pre-deflected under it, so the deposited geometry is the loaded
    one). Leapfrog, as the DEM: the wall force at ``t_n`` (computed by the engine on the state
    at ``t_n``) updates ``u'_{n-1/2} -> u'_{n+1/2}``; the engine then moves the plane at that
    velocity over the next step(s).
    """

    def __init__(self, name: str, panel: PlywoodPanel, body: Any, outward) -> None:
        self.name = name
        self.panel = panel
        self.body = body
        e = np.asarray(outward, dtype=float)
        self.e = e / np.linalg.norm(e)
        self.x0 = np.array(body.position, dtype=float)
        self.preload: float | None = None
        self.u = 0.0  # mean normal displacement [m] (outward positive)
        self.v = 0.0  # leapfrog half-step velocity [m/s]
        self.t_last: float | None = None
        self.force = 0.0  # last total normal load on the panel (soil + bodies) [N]
        self.extra = 0.0  # load from the fuselage contact at the last update [N]
        self.max_u = 0.0

    def update(self, t: float, extra: float = 0.0) -> None:
        """Advance the support to ``t`` (called once per exchange, after the DEM step).

        Parameters
        ----------
        t : DEM time [s]
        extra : normal load from other bodies (the fuselage), outward positive [N]
        """
        f_soil = float(np.asarray(self.body.force) @ self.e)
        if self.preload is None:
            self.preload = f_soil
        self.u = float((np.asarray(self.body.position) - self.x0) @ self.e)
        self.force = f_soil + extra
        self.extra = extra
        p = self.panel
        if self.t_last is not None:
            h = t - self.t_last
            # damper on the synchronised velocity v_n = v_{n-1/2} + (h/2) a_n (implicit in a_n,
            # keeps the scheme second order): a_n (M + C h/2) = F - K u - C v_{n-1/2}
            a = (f_soil - self.preload + extra - p.stiffness * self.u - p.damping * self.v) \
                / (p.modal_mass + 0.5 * h * p.damping)
            self.v += h * a
        self.t_last = t
        self.max_u = max(self.max_u, abs(self.u))
        self.body.set_kinematics(self.x0 + self.u * self.e, np.eye(3), self.v * self.e,
                                 np.zeros(3))

    def energy(self) -> float:
        """Strain + kinetic energy of the support relative to the preloaded state [J]."""
        p = self.panel
        return 0.5 * p.stiffness * self.u**2 + 0.5 * p.modal_mass * self.v**2

    # restart (``crashdem.checkpoint`` component protocol)
    _STATE = ("u", "v", "t_last", "force", "extra", "max_u", "preload")

    def state_dict(self) -> dict[str, Any]:
        """Restart state of the support (SI; copies): displacement, half-step velocity, clock,
        loads, preload and the rest geometry."""
        d: dict[str, Any] = {k: getattr(self, k) for k in self._STATE}
        d["x0"] = self.x0.copy()
        d["e"] = self.e.copy()
        return d

    def load_state_dict(self, d: dict[str, Any]) -> None:
        """Restore :meth:`state_dict` in place (bit-exact)."""
        for k in self._STATE:
            setattr(self, k, d[k])
        self.x0 = np.array(d["x0"], dtype=float)
        self.e = np.array(d["e"], dtype=float)

    def rebind(self, old_sim: Any, new_sim: Any) -> None:
        """Carry the panel body over to a DEM rebuilt from its state dict (same index)."""
        for i, b in enumerate(old_sim.boundaries):
            if b is self.body:
                self.body = new_sim.boundaries[i]
                return
        raise ValueError(f"CompliantWall {self.name!r}: its body is not a boundary of the "
                         "simulation being replaced")


class BodyWallContact:
    """Penalty contact of the fuselage surface against the container planes.

    DEM boundaries do not touch each other, so the nose's secondary impact on the rear wall
    (thesis §2.2.4, §2.4) is modelled here: every mesh vertex behind a wall plane penetrates it
    by ``d_i``; the contact force is ``k d_max + c d'_max`` (compression only) along the wall's
    particle-side normal, applied at the ``d``-weighted centroid of the penetrating vertices,
    optionally capped at a crush force (``physics.structural_crush``).

    Parameters
    ----------
    vertices : (V, 3) body-frame vertices [m]
    mass : body mass [kg]
    walls : list of (name, point (3,), normal (3,), CompliantWall or None)
        Plane through ``point`` (at zero wall displacement) with particle-side unit ``normal``.
    stiffness : [N/m]; damping_ratio : [-]; crush_force : [N] or None

    Notes
    -----
    Penalty (Kelvin-Voigt) contact; critical damping ``2 sqrt(k m_red)`` with the reduced mass
    of the body and the panel's generalised mass.
    """

    def __init__(self, vertices, mass: float, walls, stiffness: float = WALL_CONTACT_STIFFNESS,
                 damping_ratio: float = WALL_CONTACT_DAMPING, crush_force: float | None = None):
        self.v_body = np.asarray(vertices, dtype=float)
        self.mass = float(mass)
        self.walls = list(walls)
        self.k = float(stiffness)
        self.zeta = float(damping_ratio)
        self.crush_force = crush_force
        self.forces = {name: 0.0 for name, *_ in self.walls}
        self.max_force = {name: 0.0 for name, *_ in self.walls}
        self._d_prev: dict[str, float] = {}
        self._t_prev: float | None = None

    def evaluate(self, t: float, position, rotation, velocity, omega):
        """Force and torque (about the CG) on the body, and the normal load on each wall.

        Returns
        -------
        force (3,) [N], torque (3,) [N m], loads {wall name: outward normal load [N]}
        """
        pts = np.asarray(position) + self.v_body @ np.asarray(rotation).T
        f_tot = np.zeros(3)
        t_tot = np.zeros(3)
        loads = {}
        h = None if self._t_prev is None else t - self._t_prev
        for name, point, normal, wall in self.walls:
            n = np.asarray(normal, dtype=float)
            p0 = np.asarray(point, dtype=float)
            # wall moved outward (along -n) by u: plane through p0 - u n, so a vertex's
            # penetration behind it is -(x - p0).n - u
            off = 0.0 if wall is None else wall.u
            d = -((pts - p0) @ n) - off  # penetration behind the plane [m]
            inside = d > 0.0
            if not inside.any():
                loads[name] = 0.0
                self.forces[name] = 0.0
                self._d_prev[name] = 0.0
                continue
            dd = d[inside]
            d_max = float(dd.max())
            c = (dd[:, None] * pts[inside]).sum(0) / dd.sum()
            m_red = self.mass if wall is None else 1.0 / (1.0 / self.mass
                                                          + 1.0 / wall.panel.modal_mass)
            rate = 0.0 if (h is None or h <= 0) else (d_max - self._d_prev.get(name, 0.0)) / h
            fn = self.k * d_max + 2.0 * self.zeta * math.sqrt(self.k * m_red) * rate
            fn = max(fn, 0.0)
            if self.crush_force is not None:
                fn = min(fn, float(self.crush_force))
            f = fn * n
            f_tot += f
            t_tot += np.cross(c - np.asarray(position), f)
            loads[name] = fn  # the wall is pushed outward (along -n) by fn
            self.forces[name] = fn
            self.max_force[name] = max(self.max_force[name], fn)
            self._d_prev[name] = d_max
        self._t_prev = t
        return f_tot, t_tot, loads

    # restart (``crashdem.checkpoint`` component protocol); the walls are components of their
    # own (restored in place), referenced here, not copied
    def state_dict(self) -> dict[str, Any]:
        """Restart state: last forces, their maxima, previous penetrations and clock."""
        return {"forces": dict(self.forces), "max_force": dict(self.max_force),
                "d_prev": dict(self._d_prev), "t_prev": self._t_prev}

    def load_state_dict(self, d: dict[str, Any]) -> None:
        """Restore :meth:`state_dict` in place (bit-exact)."""
        self.forces = dict(d["forces"])
        self.max_force = dict(d["max_force"])
        self._d_prev = dict(d["d_prev"])
        self._t_prev = d["t_prev"]


# ---------------------------------------------------------------------------------------------
# channels of the walls (read from the objects above; no engine query)
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True, kw_only=True)
class WallChannel(_Sensor):
    """A wall quantity as a sensor channel: ``quantity`` = "force" (total normal load on the
    panel, soil + fuselage) [N], "deflection" (mean outward displacement) [m] or
    "contact_force" (fuselage on the wall) [N]."""

    wall: Any = field(default=None, compare=False)
    contact: Any = field(default=None, compare=False)
    quantity: str = "force"
    kind = "wall"

    @property
    def unit(self) -> str:  # type: ignore[override]
        return "m" if self.quantity == "deflection" else "N"

    def __post_init__(self) -> None:
        self._check_common()
        if self.quantity not in ("force", "deflection", "contact_force"):
            raise ValueError(f"WallChannel.quantity={self.quantity!r}: must be 'force', "
                             "'deflection' or 'contact_force'")

    def info(self) -> dict[str, Any]:
        out = super().info()
        out.update(wall=self.wall.name if self.wall is not None else None,
                   quantity=self.quantity)
        return out

    def _measure(self, bodies, contacts, gravity, up):
        if self.quantity == "deflection":
            return float(self.wall.u)
        if self.quantity == "contact_force":
            cs = self.contact if isinstance(self.contact, (tuple, list)) else (self.contact,)
            return float(sum(c.forces.get(self.wall.name, 0.0) for c in cs))
        return float(self.wall.force - (self.wall.preload or 0.0))


@dataclass(frozen=True, kw_only=True)
class CrushChannel(_Sensor):
    """The crush element of the nose (``physics.structural_crush``) as a channel: ``quantity``
    = "load" (compressive axial load, N) or "stroke" (nose displacement aft relative to the
    fuselage, m), read from the ``bodies.ExudynCrushableBody`` after each step."""

    model: Any = field(default=None, compare=False)
    quantity: str = "load"
    kind = "crush"

    @property
    def unit(self) -> str:  # type: ignore[override]
        return "m" if self.quantity == "stroke" else "N"

    def __post_init__(self) -> None:
        self._check_common()
        if self.quantity not in ("load", "stroke"):
            raise ValueError(f"CrushChannel.quantity={self.quantity!r}: must be 'load' or "
                             "'stroke'")

    def info(self) -> dict[str, Any]:
        out = super().info()
        out.update(quantity=self.quantity)
        return out

    def _measure(self, bodies, contacts, gravity, up):
        if self.quantity == "stroke":
            return float(getattr(self.model, "compression", 0.0))
        return float(self.model.load)


@dataclass(frozen=True, kw_only=True)
class ValueChannel(_Sensor):
    """A scalar of the glider model as a channel: ``source`` maps the shared record ``store``
    (a dict filled once per exchange by the model's ``pre_record``) to the value in ``unit``."""

    store: Any = field(default=None, compare=False)
    key: str = ""
    component: int = 0
    channel_unit: str = "N"
    kind = "model"

    @property
    def unit(self) -> str:  # type: ignore[override]
        return self.channel_unit

    def __post_init__(self) -> None:
        self._check_common()

    def info(self) -> dict[str, Any]:
        out = super().info()
        out.update(key=self.key, component=int(self.component))
        return out

    def _measure(self, bodies, contacts, gravity, up):
        v = self.store.get(self.key)
        return 0.0 if v is None else float(np.asarray(v)[self.component])


# ---------------------------------------------------------------------------------------------
# free flight
# ---------------------------------------------------------------------------------------------
def pitch_rotation(pitch: float) -> np.ndarray:
    """Body -> world rotation of a nose-up pitch ``pitch`` [rad] (rotation about world -y)."""
    c, s = math.cos(pitch), math.sin(pitch)
    return np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]])


def release_state(x_release, v_release, t: float, gravity=(0.0, 0.0, -9.81)):
    """Ballistic CG state a time ``t`` after release (torque-free flight).

    Returns
    -------
    position (3,) [m], velocity (3,) [m/s]

    Notes
    -----
    ``x = x_0 + v_0 t + g t^2/2``, ``v = v_0 + g t`` (gravity acts at the CG: no moment, so
    the attitude and the angular velocity are those of the release).
    """
    g = np.asarray(gravity, dtype=float)
    x0 = np.asarray(x_release, dtype=float)
    v0 = np.asarray(v_release, dtype=float)
    return x0 + v0 * t + 0.5 * g * t * t, v0 + g * t


def _support_vertex(vertices: np.ndarray, rotation: np.ndarray, direction) -> np.ndarray:
    """World-frame offset (from the CG) of the vertex furthest along ``direction``."""
    w = np.asarray(vertices) @ rotation.T
    return w[int(np.argmax(w @ np.asarray(direction, dtype=float)))]


# ---------------------------------------------------------------------------------------------
# the model
# ---------------------------------------------------------------------------------------------
def glider_spec(scen: Scenario):
    """The ``bodies.glider_fuselage`` spec of a scenario's ``[glider]`` / ``[impactor]``
    overrides (mesh, mass, CG, pitch inertia)."""
    import bodies

    g = scen["glider"]
    kw: dict[str, Any] = {}
    if g["mesh"]:
        kw.update(mesh_path=g["mesh"], mesh_scale=g["mesh_scale"])
    elif g["nose_droop"]:
        kw["build_up"] = bodies.GliderBuildUp(nose_droop=g["nose_droop"])
    if scen["impactor.mass"] is not None:
        kw["mass"] = scen["impactor.mass"]
    if g["pitch_inertia"] is not None:
        kw["pitch_inertia"] = g["pitch_inertia"]
    if g["cg_from_nose"] is not None or g["cg_height"] is not None:
        base = bodies.glider_fuselage(**{k: v for k, v in kw.items()
                                         if k.startswith("mesh") or k == "build_up"})
        cg = np.array(base.cg_in_construction_frame, dtype=float)
        if g["cg_from_nose"] is not None:
            cg[0] = -g["cg_from_nose"]
        if g["cg_height"] is not None:
            floor = -0.5 * base.reference_dimensions["height"]
            cg[2] = floor + g["cg_height"]
        kw["cg"] = cg
    return bodies.glider_fuselage(**kw)


def coupled_specs(scen: Scenario):
    """The Exudyn bodies of a scenario: ``(whole, rear, nose)``. Without
    ``physics.structural_crush`` ``rear`` is the whole fuselage and ``nose`` is None; with it
    the shell ahead of ``NOSE_CUT_STATION`` is the nose (``bodies.split_nose``, laminate areal
    density of the build-up) and ``rear`` the rest (its sensors, mass and inertia)."""
    import bodies

    spec = glider_spec(scen)
    if not scen["physics.structural_crush.enabled"]:
        return spec, spec, None
    rear, nose = bodies.split_nose(spec, NOSE_CUT_STATION,
                                   bodies.GliderBuildUp().laminate_areal_density)
    return spec, rear, nose


def wall_panels(scen: Scenario) -> dict[str, PlywoodPanel]:
    """The plate-theory panels of the rear and side walls of a scenario's container.

    Rear wall: width x height, one bay. Side walls: length x height, two bays (the steel
    C-beams welded on the side walls, thesis §2.2.2, assumed at mid-height as line supports).
    ``container.wall_young`` null = poplar plywood (``crashdem.run.PLYWOOD_YOUNG``).
    """
    from crashdem.run import PLYWOOD_YOUNG

    c = scen["container"]
    e = c["wall_young"] if c["wall_young"] is not None else PLYWOOD_YOUNG
    t = c["wall_thickness"]
    return {
        "rear_wall": PlywoodPanel(c["width"], c["height"], t, e),
        "left_wall": PlywoodPanel(c["length"], c["height"], t, e, bays=2),
        "right_wall": PlywoodPanel(c["length"], c["height"], t, e, bays=2),
    }


def _check_scenario(scen: Scenario) -> None:
    c = scen["container"]
    if c["shape"] != "box":
        raise ScenarioError(f"container.shape={c['shape']!r}: the glider crash needs 'box'")
    if not c["slope_deg"] > 0.0:
        raise ScenarioError(f"container.slope_deg={c['slope_deg']!r}: the glider crash needs "
                            "an inclined soil surface, in (0, 60] [deg]")
    if scen["impactor.body"] != "glider":
        raise ScenarioError(f"impactor.body={scen['impactor.body']!r}: must be 'glider' for "
                            "scenario.kind='glider_crash'")
    if scen["glider.impact_height"] >= c["soil_depth"]:
        raise ScenarioError(f"glider.impact_height={scen['glider.impact_height']!r}: must be "
                            f"below the soil top container.soil_depth={c['soil_depth']!r} [m]")
    if scen["glider.mesh"] and scen["glider.nose_droop"]:
        raise ScenarioError(f"glider.nose_droop={scen['glider.nose_droop']!r}: must be 0 with "
                            "glider.mesh (the mesh file defines the nose), allowed [0, 1] with "
                            "the parametric loft")
    if c["soil_depth"] > c["height"]:
        raise ScenarioError(f"container.soil_depth={c['soil_depth']!r}: must be <= "
                            f"container.height={c['height']!r} [m]")


def _crush_exchange(sim, b, nb, model, nose_contact, t, f, tq, loads, h, store):
    """Once per exchange (after the DEM step, at ``t_{n+1}``) with the crushable nose.

    1. the nose's wall contacts are evaluated and their loads added to the panels';
    2. the nose's external load (soil + walls) is handed to Exudyn for the next step;
    3. the connector wrench on the fuselage (rear body), evaluated on the DEM poses at
       ``t_{n+1}`` with the Exudyn half-step velocities, is added to the fuselage's wrench
       (so the coupling's velocity prediction, the accelerometers and the ``contact_force``
       channels see every load on the rear body) and declared to the model, which removes
       it again from the Exudyn load (its own connector produces it);
    4. the window velocity of the fuselage's DEM body is corrected for the loads added
       after the coupling's kick (walls, connector), and the nose's DEM body is placed at
       ``x_e + (h/2) v_e`` with the window velocity ``v_e + h a_{n+1}`` (leapfrog, as
       ``coupling.CoSimulation`` does for the fuselage).

    Returns the extra force and torque on the fuselage (walls + connector).
    """
    from coupling import rotation_increment

    fn, tqn, loads_n = nose_contact.evaluate(t, nb.position, nb.rotation, nb.velocity,
                                             nb.angular_velocity)
    for k, v in loads_n.items():
        loads[k] = loads.get(k, 0.0) + v
    f_nose = np.asarray(nb.force, dtype=float) + fn
    t_nose = np.asarray(nb.torque, dtype=float) + tqn
    # external contact load on the aircraft (soil + walls on the fuselage and the nose)
    store["contact_force"] = np.asarray(b.force, dtype=float) + f + f_nose
    model.apply_nose(f_nose, t_nose)
    fr, tr, fcn, tcn, _ = model.connector_wrench(
        b.position, b.rotation, model.velocity(), model.angular_velocity(),
        nb.position, nb.rotation, model.nose_velocity(), model.nose_angular_velocity())
    model.add_connector_load(fr, tr)
    f = f + fr
    tq = tq + tr
    g = np.asarray(sim.gravity, dtype=float)
    # fuselage: the coupling kicked with the DEM wrench only
    r = np.asarray(b.rotation)
    jw = r @ model.spec.inertia @ r.T
    b.set_kinematics(np.array(b.position), r, np.asarray(b.velocity) + h * f / model.spec.mass,
                     np.asarray(b.angular_velocity) + h * np.linalg.solve(jw, tq))
    # nose
    ns = model.nose_spec
    xe, re_, ve, we = (model.nose_position(), model.nose_rotation(), model.nose_velocity(),
                       model.nose_angular_velocity())
    a = (f_nose + fcn) / ns.mass + g
    jn = re_ @ ns.inertia @ re_.T
    alpha = np.linalg.solve(jn, t_nose + tcn - np.cross(we, jn @ we))
    nb.set_kinematics(xe + 0.5 * h * ve, rotation_increment(we, 0.5 * h) @ re_, ve + h * a,
                      we + h * alpha)
    store["nose_velocity"] = ve + 0.5 * h * a  # synchronised with the DEM time t_{n+1}
    store["crush_force_on_fuselage"] = fr
    return f, tq


def build_glider_model(scen: Scenario, cache_dir, progress=None):
    """Deposit (or load) the slope packing and assemble the coupled glider crash.

    Parameters
    ----------
    scen : Scenario
        ``scenario.kind = "glider_crash"``, ``container.shape = "box"``, ``impactor.body =
        "glider"``.
    cache_dir : path
        Packing cache.
    progress : callable or None
        Passed to the packing build.

    Returns
    -------
    crashdem.run.Model
        ``body_name="glider"``; ``extra`` holds the walls, the fuselage-wall contact, the
        release state and the geometry; ``pre_record`` integrates the walls and applies the
        fuselage-wall contact once per exchange.

    Notes
    -----
    The DEM starts ``PRE_CONTACT_TIME`` before the nominal first contact; the free flight
    before it is exact (ballistic CG, constant attitude and rate). The first contact point is
    the fuselage's support point along the slope's inward normal, placed on the envelope of the
    grains at ``glider.impact_height`` above the floor.
    """
    import bodies
    import coupling
    import soil
    from crashdem import run as rn
    from crashdem import sensors as sn
    from soil import packing as pk

    _check_scenario(scen)
    g = rn.GRAVITY
    spec_p = rn.packing_spec(scen)
    packing = pk.cached(spec_p, cache_dir, progress=progress)
    if scen["physics.soil_layering.enabled"] and not scen["physics.soil_layering.compacted"]:
        rn.stiffness_layer(scen, packing)  # refuses the glider, naming the field
    mats = rn.impact_materials(scen, packing)
    wall_mat, imp_mat = len(packing.materials), len(packing.materials) + 1
    mats[imp_mat] = replace(mats[imp_mat],
                            friction_angle=math.radians(scen["glider.skin_friction_deg"]),
                            name="fuselage")
    particles = soil.Particles(x=packing.x, radius=packing.radius, material=packing.material,
                               rotation_blocked=rn._rotations_blocked(scen))
    c = scen["container"]
    lx, ly = c["length"], c["width"]
    x_lo, x_hi, y_hi = -0.5 * lx, 0.5 * lx, 0.5 * ly

    # rigid floor + low front edge; compliant rear and side panels
    fixed = soil.BoundaryBody(shapes=[soil.Plane((0.0, 0.0, 0.0), (0.0, 0.0, 1.0)),
                                      soil.Plane((x_lo, 0.0, 0.0), (1.0, 0.0, 0.0))],
                              material=wall_mat, motion="fixed")
    panels = wall_panels(scen)
    geo = {"rear_wall": ((x_hi, 0.0, 0.0), (-1.0, 0.0, 0.0)),
           "left_wall": ((0.0, y_hi, 0.0), (0.0, -1.0, 0.0)),
           "right_wall": ((0.0, -y_hi, 0.0), (0.0, 1.0, 0.0))}
    wall_bodies = {name: soil.BoundaryBody(shapes=[soil.Plane(p, n)], material=wall_mat,
                                           motion="coupled")
                   for name, (p, n) in geo.items()}

    # fuselage and its release
    spec, rear, nose = coupled_specs(scen)
    gl = scen["glider"]
    speed = gl["release_speed"]
    path = scen["impactor.angle_deg"]
    pitch = scen["impactor.pitch_deg"]
    if scen["physics.initial_conditions.enabled"]:
        speed += scen["physics.initial_conditions.velocity_offset"]
        path += scen["physics.initial_conditions.angle_offset_deg"]
        pitch += scen["physics.initial_conditions.pitch_offset_deg"]
    if speed <= 0:
        raise ScenarioError(f"glider.release_speed after offsets = {speed!r}: must be > 0 [m/s]")
    # pitch rate at release (nose-up positive): torque-free flight about the principal pitch
    # axis keeps it constant, so the attitude grows linearly; impactor.pitch_deg is the
    # attitude at release
    q0 = math.radians(gl["release_pitch_rate_deg_s"])
    omega0 = np.array([0.0, -q0, 0.0])  # world; nose-up = rotation about -y
    t_ff = gl["free_flight_time"]
    rot_contact = pitch_rotation(math.radians(pitch) + q0 * t_ff)
    a = math.radians(path)
    v_rel = speed * np.array([math.cos(a), 0.0, -math.sin(a)])
    alpha = math.radians(c["slope_deg"])
    n_out = np.array([-math.sin(alpha), 0.0, math.cos(alpha)])
    p0 = np.array([x_lo, 0.0, 0.0])
    # envelope of the grains above the slope plane near the expected contact point
    zc = gl["impact_height"]
    xc_plane = x_lo + zc / math.tan(alpha)
    near = (np.abs(packing.x[:, 0] - xc_plane) < 0.5) & (np.abs(packing.x[:, 1]) < 0.5 *
                                                           spec.reference_dimensions["width"])
    near &= np.abs(packing.x[:, 2] - zc) < 0.5
    sd = (packing.x - p0) @ n_out + packing.radius
    delta = float(np.max(sd[near])) if near.any() else float(np.max(packing.radius))
    # contact point: on the envelope plane, at height zc; fuselage support point there
    x_contact_pt = x_lo + (math.cos(alpha) * zc - delta) / math.sin(alpha)
    r_sup = _support_vertex(spec.vertices, rot_contact, -n_out)
    # CG at contact, back to release (ballistic), forward to the DEM start
    # (velocity at contact = v_rel + g t_ff; the contact point lies on the plane at zc)
    x_cg_contact = np.array([x_contact_pt, 0.0, zc]) - r_sup
    x_rel = x_cg_contact - v_rel * t_ff - 0.5 * g * t_ff * t_ff
    t_start = max(t_ff - PRE_CONTACT_TIME, 0.0)
    x0, v0 = release_state(x_rel, v_rel, t_start, g)
    t_contact = t_ff - t_start
    rot = pitch_rotation(math.radians(pitch) + q0 * t_start)  # attitude at the DEM start

    # with the crushable nose the fuselage (rear) and nose CGs are offset from the whole CG
    cg_whole = np.asarray(spec.cg_in_construction_frame, dtype=float)
    d_r = rot @ (np.asarray(rear.cg_in_construction_frame) - cg_whole)
    x0_r, v0_r = x0 + d_r, v0 + np.cross(omega0, d_r)
    body = coupling.boundary_for(rear, imp_mat, position=x0_r, rotation=rot, velocity=v0_r,
                                 angular_velocity=omega0)
    boundaries = [fixed, body] + list(wall_bodies.values())
    nose_index = None
    if nose is not None:
        d_n = rot @ (np.asarray(nose.cg_in_construction_frame) - cg_whole)
        boundaries.append(coupling.boundary_for(nose, imp_mat, position=x0 + d_n, rotation=rot,
                                                velocity=v0 + np.cross(omega0, d_n),
                                                angular_velocity=omega0))
        nose_index = len(boundaries) - 1
        if scen["solver.exchange_every"] != 1:
            raise ScenarioError(f"solver.exchange_every={scen['solver.exchange_every']!r}: "
                                "must be 1 with physics.structural_crush (the nose is "
                                "exchanged every DEM step)")
    threads = scen["scenario.threads"] or None
    sim = soil.Simulation(particles, mats, boundaries, gravity=tuple(g), dt=scen["solver.dt"],
                          safety=scen["solver.safety"], threads=threads)
    if scen["physics.cohesion.enabled"]:
        sim.bond_contacts()
    if nose is None:
        model = bodies.ExudynRigidBody(spec, position=x0, rotation=rot, velocity=v0,
                                       angular_velocity=omega0, gravity=tuple(g))
    else:
        from bodies.crush import ExudynCrushableBody

        model = ExudynCrushableBody(rear, nose, scen["physics.structural_crush.crush_force"],
                                    scen["physics.structural_crush.stroke"], sim.dt,
                                    position=x0_r, rotation=rot, velocity=v0_r,
                                    angular_velocity=omega0, gravity=tuple(g))
    cosim = coupling.CoSimulation(sim, 1, model, exchange_every=scen["solver.exchange_every"])

    walls = {name: CompliantWall(name, panels[name], wall_bodies[name], -np.asarray(n))
             for name, (_, n) in geo.items()}
    wall_list = ([("floor", (0.0, 0.0, 0.0), (0.0, 0.0, 1.0), None)]
                 + [(name, p, n, walls[name]) for name, (p, n) in geo.items()])
    # the crushable nose (when on) limits the nose load itself: no cap on the wall contacts
    contact = BodyWallContact(rear.vertices, rear.mass, wall_list)
    nose_contact = None if nose is None else BodyWallContact(nose.vertices, nose.mass,
                                                             wall_list)
    h_dem = sim.dt
    store: dict[str, Any] = {}

    def pre_record(t, sim_, model_):
        b = sim_.boundaries[1]
        f, tq, loads = contact.evaluate(t, b.position, b.rotation, b.velocity,
                                        b.angular_velocity)
        if nose_index is not None:
            f, tq = _crush_exchange(sim_, b, sim_.boundaries[nose_index], model_,
                                    nose_contact, t, f, tq, loads, h_dem, store)
        if np.any(f):
            b.force[:] = np.asarray(b.force) + f
            b.torque[:] = np.asarray(b.torque) + tq
        for name, w in walls.items():
            w.update(t, loads.get(name, 0.0))

    # sensors: accelerometers (250 g, failure factor), gyro, pitch, CG kinematics, walls
    fs_g = scen["instrumentation.accel_full_scale_g"] * G0
    cfc, dyn = rn.sensor_dynamics(scen)
    out = sn.sensors_for_body(rear.sensors, "glider", cfc=cfc, accel_full_scale=fs_g,
                              failure_factor=scen["instrumentation.accel_failure_factor"],
                              dynamics=dyn)
    out.append(sn.PitchAngle(name="pitch_angle_lab", body="glider", method="integrated",
                             initial="zero", cfc=cfc))
    if nose is None:
        out += [sn.BodyForce(name="contact_force_x", body="glider", quantity="force",
                             axis=(1.0, 0.0, 0.0), cfc=cfc),
                sn.BodyForce(name="contact_force_z", body="glider", quantity="force",
                             axis=(0.0, 0.0, 1.0), cfc=cfc)]
    else:
        # contact_force_*: soil + walls on the aircraft (fuselage and nose); fuselage_force_*:
        # every load on the fuselage (rear body) incl. the crush element; nose velocity for
        # the momentum balance of the two bodies
        out += [ValueChannel(name=f"contact_force_{ax}", store=store, key="contact_force",
                             component=i, channel_unit="N", cfc=cfc) for ax, i in (("x", 0),
                                                                                   ("z", 2))]
        out += [sn.BodyForce(name=f"fuselage_force_{ax}", body="glider", quantity="force",
                             axis=e, cfc=cfc) for ax, e in (("x", (1.0, 0.0, 0.0)),
                                                           ("z", (0.0, 0.0, 1.0)))]
        out += [ValueChannel(name=f"nose_velocity_{ax}", store=store, key="nose_velocity",
                             component=i, channel_unit="m/s", cfc=cfc) for ax, i in (("x", 0),
                                                                                    ("z", 2))]
    for name, w in walls.items():
        out.append(WallChannel(name=f"{name}_force", wall=w, contact=contact, quantity="force",
                               cfc=cfc))
        out.append(WallChannel(name=f"{name}_deflection", wall=w, contact=contact,
                               quantity="deflection", cfc=cfc))
    both = contact if nose_contact is None else (contact, nose_contact)
    out.append(WallChannel(name="nose_rear_wall_force", wall=walls["rear_wall"], contact=both,
                           quantity="contact_force", cfc=cfc))
    if nose is not None:
        out.append(CrushChannel(name="nose_crush_load", model=model, quantity="load", cfc=cfc))
        out.append(CrushChannel(name="nose_crush_stroke", model=model, quantity="stroke",
                                cfc=cfc))
    sensors = sn.SensorSet(out, fs=scen["instrumentation.sample_rate"], t0=0.0,
                           gravity=tuple(g))

    surface_z = zc
    extra = {"walls": walls, "contact": contact, "panels": panels, "release_position": x_rel,
             "release_velocity": v_rel, "release_time": -t_start, "t_start_after_release": t_start,
             "grain_envelope": delta, "contact_point_body": r_sup @ rot_contact,
             "pitch0": math.radians(pitch), "release_pitch_rate": q0,
             "pitch_contact": math.radians(pitch) + q0 * t_ff, "slope_normal": n_out,
             "nose_contact": nose_contact, "nose_index": nose_index, "whole_spec": spec}
    # stateful parts outside the DEM, the coupling and the sensors (restart checkpoints,
    # crashdem.checkpoint): every such object goes here, named
    components: dict[str, Any] = {f"wall.{name}": w for name, w in walls.items()}
    components["wall_contact"] = contact
    if nose_contact is not None:
        components["nose_wall_contact"] = nose_contact
        components["crush_store"] = store  # read by the ValueChannel sensors
    return rn.Model(scen, sim, 1, rear, model, cosim, sensors, packing, surface_z, t_contact,
                    t_contact + scen["solver.t_end"], {}, "glider", extra, pre_record,
                    components=components)


# ---------------------------------------------------------------------------------------------
# features and oracles
# ---------------------------------------------------------------------------------------------
def _peaks(t: np.ndarray, y: np.ndarray, min_separation: float, min_prominence: float):
    """Local maxima of ``y`` (indices), at least ``min_separation`` s apart, by prominence."""
    from scipy.signal import find_peaks

    dt = float(np.median(np.diff(t))) if t.size > 1 else 1.0
    idx, prop = find_peaks(np.nan_to_num(y), distance=max(1, int(min_separation / dt)),
                           prominence=min_prominence)
    order = np.argsort(prop["prominences"])[::-1]
    return idx[order], prop["prominences"][order]


def crash_features(signals: dict, t_contact: float, accel: str = "rear_accel_x",
                   gyro: str = "pitch_rate", cfc: float = 60.0) -> dict[str, Any]:
    """The reference features of the glider crash from the recorded channels.

    Parameters
    ----------
    signals : name -> crashdem.signal.Signal (raw, SI; e.g. ``SensorSet.signals()`` or
        ``Result.signals(filtered=False)``)
    t_contact : nominal first contact [s] (run time)
    accel, gyro : channel names
    cfc : filter class applied here (SAE J211, thesis §2.3: CFC 60)

    Returns
    -------
    dict
        ``peak_ax_g`` (largest longitudinal deceleration, g), ``second_peak_ax_g`` (the second
        most prominent deceleration peak, at least 20 ms from the first), ``t_peaks_s``
        (their times after the first contact, in time order), ``pitch_min_deg`` /
        ``pitch_max_deg`` (extremes of the pitch angle integrated from the filtered gyro from
        the start of the record, the laboratory procedure), ``duration_s`` (first contact to
        the last instant the deceleration exceeds ``DURATION_THRESHOLD_G``), ``t_first_contact_s``
        (first non-zero contact force, run time), ``free_flight_rate_max`` (max |gyro| before
        it) [rad/s].

    Notes
    -----
    SAE J211-1 Appendix C filter (``crashdem.filters.cfc_filter``); gyro integration by the
    trapezoidal rule (``crashdem.sensors.integrate_signal``).
    """
    from crashdem.filters import cfc_filter
    from crashdem.sensors import integrate_signal

    ax = signals[accel]
    t = ax.t
    fx = signals.get("contact_force_x")
    fz = signals.get("contact_force_z")
    t_first = t_contact
    if fx is not None and fz is not None:
        on = np.flatnonzero((np.abs(fx.data) + np.abs(fz.data)) > 0.0)
        if on.size:
            t_first = float(t[on[0]])
    finite = np.isfinite(ax.data)
    n_ok = ax.data.size if finite.all() else int(np.argmin(finite))
    axf = cfc_filter(ax.data[:n_ok], fs=1.0 / float(np.median(np.diff(t))), cfc=cfc)
    decel = -np.asarray(axf) / G0
    td = t[:n_ok]
    idx, _ = _peaks(td, decel, 0.02, 0.5)
    idx = [i for i in idx if td[i] >= t_first - 0.005]
    if idx:
        i1 = int(idx[0])
        i2 = int(idx[1]) if len(idx) > 1 else i1
    else:
        i1 = i2 = int(np.nanargmax(decel))
    first, second = sorted((i1, i2))
    peak = float(decel[i1])
    sec = float(decel[i2]) if i2 != i1 else float("nan")
    g = signals[gyro]
    gf = cfc_filter(g.data, fs=1.0 / float(np.median(np.diff(g.t))), cfc=cfc)
    from crashdem.signal import Signal

    pitch = integrate_signal(Signal("q", g.t, np.asarray(gf), "rad/s"), 0.0).data
    above = np.flatnonzero(decel > DURATION_THRESHOLD_G)
    t_end = float(td[above[-1]]) if above.size else t_first
    pre = g.t < t_first
    return {
        "peak_ax_g": peak,
        "second_peak_ax_g": sec,
        "t_peaks_s": [float(td[first] - t_first), float(td[second] - t_first)],
        "pitch_min_deg": float(np.degrees(pitch.min())),
        "pitch_max_deg": float(np.degrees(pitch.max())),
        "duration_s": t_end - t_first,
        "t_first_contact_s": t_first,
        "free_flight_rate_max": float(np.max(np.abs(g.data[pre]))) if pre.any() else 0.0,
    }


def kinematic_identity(signals: dict, mount_position, accel: str = "rear_accel_x") -> dict:
    """Oracle for a body-x accelerometer in planar (x-z) motion.

    With ``e_x = (cos th, 0, sin th)``, ``e_z = (-sin th, 0, cos th)`` (``th`` nose-up pitch),
    ``q = th'`` and ``v_P = v + omega x r_P`` (``omega = -q e_y``): ``d/dt (v_P . e_x) =
    a_P . e_x + q v_P . e_z``, so the specific force ``f_x = (a_P - g) . e_x`` integrates to
    ``int f_x dt = Delta(v_P . e_x) - int q (v_P . e_z) dt - int g . e_x dt``.

    Parameters
    ----------
    signals : raw channels (needs ``accel``, ``pitch_rate``, ``pitch_angle``, ``cg_velocity_x``,
        ``cg_velocity_z``)
    mount_position : body-frame mount offset from the CG [m]

    Returns
    -------
    dict with ``lhs`` (int f_x dt) and ``rhs`` [m/s], over the record up to the first NaN.

    Notes
    -----
    Rigid-body kinematics (e.g. Shabana, *Dynamics of Multibody Systems*, ch. 2); trapezoidal
    integration of the 12.5 kHz samples.
    """
    f = signals[accel].data
    n = f.size if np.isfinite(f).all() else int(np.argmin(np.isfinite(f)))
    t = signals[accel].t[:n]
    f = f[:n]
    q = signals["pitch_rate"].data[:n]
    th = signals["pitch_angle"].data[:n]
    vx = signals["cg_velocity_x"].data[:n]
    vz = signals["cg_velocity_z"].data[:n]
    r = np.asarray(mount_position, dtype=float)
    ex = np.stack([np.cos(th), np.zeros_like(th), np.sin(th)], 1)
    ez = np.stack([-np.sin(th), np.zeros_like(th), np.cos(th)], 1)
    r_w = r[0] * ex + r[2] * ez  # planar: y offset of the mount is zero
    omega = np.stack([np.zeros_like(q), -q, np.zeros_like(q)], 1)
    v_p = np.stack([vx, np.zeros_like(vx), vz], 1) + np.cross(omega, r_w)
    grav = np.array([0.0, 0.0, -9.81])

    def trap(y):
        return float(np.sum(0.5 * np.diff(t) * (y[1:] + y[:-1])))

    lhs = trap(f)
    vpx = np.einsum("ij,ij->i", v_p, ex)
    rhs = (vpx[-1] - vpx[0]) - trap(q * np.einsum("ij,ij->i", v_p, ez)) - trap(ex @ grav)
    return {"lhs": lhs, "rhs": float(rhs), "n": int(n)}
