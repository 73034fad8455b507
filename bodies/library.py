"""The two bodies of the reference tests: the drop-test sphere and the Rondine glider mock-up.

Every number that is not in the reference thesis (Varriale 2019, §2.1.1 and §2.2.1) is an
assumption; each is listed in ``docs/bodies.md`` and in ``RigidBodySpec.assumptions``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .mesh import icosphere, loft_fuselage, read_mesh, shell_mass_properties, triangle_areas
from .spec import MassComponent, RigidBodySpec, SensorMount, check_inertia, combine_components

G0 = 9.80665  # standard gravity [m/s^2], used only to express full scales given in g

# ---------------------------------------------------------------------------- drop sphere
DROP_SPHERE_MASS = 850.0  # [kg], thesis §2.1.1
DROP_SPHERE_DIAMETER = 0.90  # [m], thesis §2.1.1
DROP_SPHERE_CAVITY_DIAMETER = 0.20  # [m], thesis §2.1.1


def sphere_with_cavity_inertia(mass: float, radius: float, cavity_radius: float) -> float:
    """Moment of inertia of a homogeneous sphere with a concentric spherical cavity.

    Parameters
    ----------
    mass : float
        Mass of the hollowed sphere [kg].
    radius, cavity_radius : float
        Outer and cavity radii [m], ``0 <= cavity_radius < radius``.

    Returns
    -------
    float
        Moment of inertia about any axis through the centre [kg m^2].

    Notes
    -----
    Difference of two solid spheres of the same density:
    ``I = 2/5 m (R^5 - r^5) / (R^3 - r^3)`` (thick spherical shell).
    """
    if not 0.0 <= cavity_radius < radius:
        raise ValueError(
            f"cavity_radius={cavity_radius!r}: must be in [0, radius={radius}) [m]"
        )
    return 0.4 * mass * (radius**5 - cavity_radius**5) / (radius**3 - cavity_radius**3)


def drop_sphere(mass: float = DROP_SPHERE_MASS, diameter: float = DROP_SPHERE_DIAMETER,
                cavity_diameter: float = DROP_SPHERE_CAVITY_DIAMETER,
                mesh_subdivisions: int = 3) -> RigidBodySpec:
    """The reinforced-concrete drop mass of the reference drop tests.

    Parameters
    ----------
    mass : float
        [kg], default 850 (thesis §2.1.1).
    diameter : float
        [m], default 0.90 (thesis §2.1.1).
    cavity_diameter : float
        Instrument cavity diameter [m], default 0.20 (thesis §2.1.1).
    mesh_subdivisions : int
        Icosphere level of the visualisation mesh.

    Returns
    -------
    RigidBodySpec
        Contact shape: an exact sphere (``contact_radius = diameter/2``); sensors: the three
        accelerometers at the CG (x and z: 200 g full scale, y: 50 g). Body axes: z up at
        release, x and y horizontal.

    Notes
    -----
    Inertia from :func:`sphere_with_cavity_inertia` with the assumption that the cavity is
    spherical and concentric and the concrete homogeneous (rebar and the instrument plate
    neglected): ``I = 2/5 m (R^5 - r^5)/(R^3 - r^3)``.
    """
    radius = 0.5 * diameter
    if not mass > 0.0:
        raise ValueError(f"drop_sphere.mass={mass!r}: must be > 0 [kg]")
    if not diameter > 0.0:
        raise ValueError(f"drop_sphere.diameter={diameter!r}: must be > 0 [m]")
    i0 = sphere_with_cavity_inertia(mass, radius, 0.5 * cavity_diameter)
    v, t = icosphere(radius, mesh_subdivisions)
    origin = np.zeros(3)
    sensors = (
        SensorMount("accel_x", origin, (1.0, 0.0, 0.0), "accelerometer", 200.0 * G0),
        SensorMount("accel_y", origin, (0.0, 1.0, 0.0), "accelerometer", 50.0 * G0),
        SensorMount("accel_z", origin, (0.0, 0.0, 1.0), "accelerometer", 200.0 * G0),
    )
    density = mass / (4.0 / 3.0 * np.pi * (radius**3 - (0.5 * cavity_diameter) ** 3))
    return RigidBodySpec(
        name="drop_sphere",
        mass=mass,
        inertia=i0 * np.eye(3),
        vertices=v,
        triangles=t,
        contact_radius=radius,
        sensors=sensors,
        reference_dimensions={"diameter": diameter, "cavity_diameter": cavity_diameter},
        cg_in_construction_frame=np.zeros(3),
        assumptions=(
            "homogeneous concrete, rebar neglected; concentric spherical cavity; "
            f"implied density {density:.0f} kg/m^3",
            "accelerometer plate at the CG, its mass neglected",
        ),
    )


# ---------------------------------------------------------------------------- glider
@dataclass(frozen=True)
class GliderBuildUp:
    """Mass build-up of the V1/2 Rondine crash mock-up (thesis §2.2.1).

    Lengths are stations aft of the nose tip and heights above the fuselage axis (the floor is
    at ``-height/2``); y is to the left. Every default is an assumption documented in
    ``docs/bodies.md``.

    Parameters
    ----------
    total_mass : float
        Total assembled mass [kg]; thesis §2.2.1: 343.
    length, width, height, nose_length, aft_taper : float
        Fuselage shell geometry (see :func:`bodies.mesh.loft_fuselage`) [m], [-].
    nose_droop : float
        Side-view asymmetry of the nose, in [0, 1] (:func:`bodies.mesh.loft_fuselage`): 0 =
        symmetric elliptic nose (default), 1 = straight floor line up to the nose tip.
    fabric_areal_density : float
        Dry fabric per unit shell area [kg/m^2]; schedule of thesis §2.2.1:
        1 x 1717 (0.160) + 6 x 1102 (0.280) + 2 x 1035 (0.200) = 2.240.
    resin_mass_fraction : float
        Resin share of the cured laminate mass [-], in [0, 0.8).
    dummy_mass : float
        Anthropomorphic dummy [kg] (0 to leave it out); 50th percentile ~77.
    dummy_station, dummy_height, dummy_length : float
        Dummy CG station, height, and the length of the reclined body (uniform rod) [m].
    side_mass : float
        The extra mass at the fuselage sides near the seat [kg]; thesis: 32.
    side_station, side_height : float
        Its station and height [m]; split in two equal halves at y = +-(width/2 - 0.03).
    wingbeam_station, wingbeam_height, wingbeam_span, wingbeam_tube_side, wingbeam_wall : float
        Square steel tube at the wing attachments [m]; the wall is 4 mm (thesis).
    heb_mass_each, heb_length : float
        The two HEB beams welded at the tube ends [kg], [m] (HEB 100 is 20.4 kg/m).
    steel_density : float
        [kg/m^3]
    ballast_station, ballast_length, ballast_height, ballast_width, ballast_z : float
        Iron ballast behind the cockpit (four C-beams, two vertical plates) as a uniform
        box; it takes the remainder of ``total_mass`` [m].
    """

    total_mass: float = 343.0
    length: float = 2.3
    width: float = 0.6
    height: float = 0.8
    nose_length: float = 0.7
    aft_taper: float = 0.85
    nose_droop: float = 0.0
    fabric_areal_density: float = 0.160 + 6 * 0.280 + 2 * 0.200
    resin_mass_fraction: float = 0.45
    dummy_mass: float = 77.0
    dummy_station: float = 1.30
    dummy_height: float = -0.15
    dummy_length: float = 1.5
    side_mass: float = 32.0
    side_station: float = 1.60
    side_height: float = -0.20
    wingbeam_station: float = 2.20
    wingbeam_height: float = 0.10
    wingbeam_span: float = 2.0
    wingbeam_tube_side: float = 0.10
    wingbeam_wall: float = 0.004
    heb_mass_each: float = 6.1
    heb_length: float = 0.30
    steel_density: float = 7850.0
    ballast_station: float = 2.90
    ballast_length: float = 1.20
    ballast_height: float = 0.30
    ballast_width: float = 0.40
    ballast_z: float = 0.0

    def __post_init__(self):
        positive = ("total_mass", "length", "width", "height", "nose_length",
                    "fabric_areal_density", "dummy_length", "wingbeam_span",
                    "wingbeam_tube_side", "wingbeam_wall", "heb_length", "steel_density",
                    "ballast_length", "ballast_height", "ballast_width")
        for name in positive:
            val = getattr(self, name)
            if not (np.isfinite(val) and val > 0.0):
                raise ValueError(f"GliderBuildUp.{name}={val!r}: must be > 0")
        if not (np.isfinite(self.nose_droop) and 0.0 <= self.nose_droop <= 1.0):
            raise ValueError(f"GliderBuildUp.nose_droop={self.nose_droop!r}: must be in [0, 1]")
        for name in ("dummy_mass", "side_mass", "heb_mass_each"):
            val = getattr(self, name)
            if not (np.isfinite(val) and val >= 0.0):
                raise ValueError(f"GliderBuildUp.{name}={val!r}: must be >= 0 [kg]")
        if not 0.0 <= self.resin_mass_fraction < 0.8:
            raise ValueError(
                f"GliderBuildUp.resin_mass_fraction={self.resin_mass_fraction!r}: "
                "must be in [0, 0.8)"
            )
        if 2.0 * self.wingbeam_wall >= self.wingbeam_tube_side:
            raise ValueError(
                f"GliderBuildUp.wingbeam_wall={self.wingbeam_wall!r}: must be < "
                f"wingbeam_tube_side/2={self.wingbeam_tube_side / 2} [m]"
            )

    @property
    def laminate_areal_density(self) -> float:
        """Cured laminate areal density [kg/m^2]: fabric / (1 - resin mass fraction)."""
        return self.fabric_areal_density / (1.0 - self.resin_mass_fraction)


def _box_inertia(m, a, b, c):
    """Uniform box with edges a, b, c along x, y, z [kg m^2] (m (b^2 + c^2)/12, ...)."""
    return m / 12.0 * np.diag([b * b + c * c, a * a + c * c, a * a + b * b])


def _glider_components(bu: GliderBuildUp, vertices, triangles, is_cap):
    """Mass components in the construction frame (x forward from the nose tip, y left, z up)."""
    lateral = triangles[~is_cap]
    m_shell, cg_shell, j_shell = shell_mass_properties(vertices, lateral, bu.laminate_areal_density)
    comps = [
        MassComponent("shell", m_shell, cg_shell, j_shell,
                      f"laminate {bu.laminate_areal_density:.3f} kg/m^2 x lateral mesh area "
                      f"{triangle_areas(vertices, lateral).sum():.3f} m^2"),
    ]
    if bu.dummy_mass > 0.0:
        comps.append(MassComponent(
            "dummy", bu.dummy_mass, (-bu.dummy_station, 0.0, bu.dummy_height),
            _box_inertia(bu.dummy_mass, bu.dummy_length, 0.40, 0.25),
            "50th percentile dummy, reclined, uniform box 1.5 x 0.40 x 0.25 m"))
    if bu.side_mass > 0.0:
        y_side = 0.5 * bu.width - 0.03
        for sgn, tag in ((1.0, "left"), (-1.0, "right")):
            comps.append(MassComponent(
                f"side_mass_{tag}", 0.5 * bu.side_mass,
                (-bu.side_station, sgn * y_side, bu.side_height), np.zeros((3, 3)),
                "half of the 32 kg fixed at the fuselage sides near the seat, point mass"))
    a_out = bu.wingbeam_tube_side
    a_in = a_out - 2.0 * bu.wingbeam_wall
    m_tube = bu.steel_density * (a_out**2 - a_in**2) * bu.wingbeam_span
    comps.append(MassComponent(
        "wingbeam_tube", m_tube, (-bu.wingbeam_station, 0.0, bu.wingbeam_height),
        # tube along y: I_yy = m (a_o^2 + a_i^2)/6 (square tube about its axis),
        # I_xx = I_zz = m L^2/12 + m (a_o^2 + a_i^2)/12
        np.diag([m_tube * bu.wingbeam_span**2 / 12.0, 0.0, m_tube * bu.wingbeam_span**2 / 12.0])
        + m_tube * (a_out**2 + a_in**2) / 12.0 * np.diag([1.0, 2.0, 1.0]),
        f"square steel tube {a_out * 1e3:.0f} mm, wall {bu.wingbeam_wall * 1e3:.0f} mm, "
        f"span {bu.wingbeam_span} m"))
    if bu.heb_mass_each > 0.0:
        for sgn, tag in ((1.0, "left"), (-1.0, "right")):
            comps.append(MassComponent(
                f"wingbeam_heb_{tag}", bu.heb_mass_each,
                (-bu.wingbeam_station, sgn * 0.5 * bu.wingbeam_span, bu.wingbeam_height),
                _box_inertia(bu.heb_mass_each, bu.heb_length, 0.1, 0.1),
                "HEB beam welded at the tube end"))
    m_known = sum(c.mass for c in comps)
    m_ballast = bu.total_mass - m_known
    if m_ballast <= 0.0:
        raise ValueError(
            f"GliderBuildUp.total_mass={bu.total_mass}: must exceed the other components "
            f"({m_known:.1f} kg) so the ballast mass is > 0 [kg]"
        )
    comps.append(MassComponent(
        "ballast", m_ballast, (-bu.ballast_station, 0.0, bu.ballast_z),
        _box_inertia(m_ballast, bu.ballast_length, bu.ballast_width, bu.ballast_height),
        "iron ballast (4 C-beams, 2 vertical plates) as a uniform box; remainder of the total"))
    return comps


def glider_fuselage(
    build_up: GliderBuildUp | None = None,
    mass: float | None = None,
    cg: np.ndarray | None = None,
    inertia: np.ndarray | None = None,
    pitch_inertia: float | None = None,
    mesh_path=None,
    mesh_scale: float = 1.0,
    n_stations: int = 28,
    n_around: int = 32,
) -> RigidBodySpec:
    """The ballasted V1/2 Rondine fuselage of the 2009 La.S.T. crash test (thesis §2.2.1).

    Parameters
    ----------
    build_up : GliderBuildUp, optional
        Component build-up that defines the default mass properties.
    mass : float, optional
        Override of the total mass [kg].
    cg : array_like, shape (3,), optional
        Override of the CG in the construction frame (origin at the nose tip, x forward,
        y left, z up from the fuselage axis; so the station is ``-cg[0]``) [m].
    inertia : array_like, shape (3, 3), optional
        Override of the full inertia about the CG in body axes [kg m^2].
    pitch_inertia : float, optional
        Override of I_yy [kg m^2] (the quantity the test rig reproduced); I_zz is shifted by
        the same amount, as when mass is moved along the fuselage axis (keeps the tensor
        realisable).
    mesh_path : str or Path, optional
        A user surface (STL, OBJ, ...) in the construction frame replacing the parametric
        loft; the shell mass is then computed from its area.
    mesh_scale : float
        Factor from the file unit to metres (1e-3 for mm).
    n_stations, n_around : int
        Resolution of the parametric loft.

    Returns
    -------
    RigidBodySpec
        Body frame: origin at the CG, x forward (towards the nose), y left, z up. Sensors:
        ``front_accel_x``, ``front_accel_z``, ``rear_accel_x``, ``rear_accel_z`` (250 g) and
        ``pitch_rate`` (sensitive axis -y, so that nose-up is positive as in the SAE/aviation
        convention).

    Notes
    -----
    Shell: areal density x area (thin-shell integrals, :func:`bodies.mesh.shell_mass_properties`);
    assembly: parallel-axis theorem (:func:`bodies.spec.combine_components`).
    """
    bu = GliderBuildUp() if build_up is None else build_up
    if mesh_path is None:
        v, t, is_cap = loft_fuselage(bu.length, bu.width, bu.height, bu.nose_length,
                                     n_stations, n_around, bu.aft_taper, bu.nose_droop)
        mesh_note = (f"parametric loft: length {bu.length} m, width {bu.width} m, height "
                     f"{bu.height} m, elliptic nose {bu.nose_length} m, aft taper {bu.aft_taper}")
        if bu.nose_droop:
            mesh_note += f", nose droop {bu.nose_droop}"
    else:
        v, t = read_mesh(mesh_path, mesh_scale)
        is_cap = np.zeros(len(t), dtype=bool)
        mesh_note = f"user mesh {mesh_path} scaled by {mesh_scale}"
    comps = _glider_components(bu, v, t, is_cap)
    m_tot, cg_tot, j_tot = combine_components(comps)
    assumptions = [mesh_note,
                   f"laminate {bu.fabric_areal_density:.3f} kg/m^2 dry fabric, resin mass "
                   f"fraction {bu.resin_mass_fraction}"]
    assumptions += [f"{c.name}: {c.mass:.2f} kg at station {-c.cg[0]:.3f} m, z {c.cg[2]:+.3f} m; "
                    f"{c.note}" for c in comps]
    if mass is not None:
        if not mass > 0.0:
            raise ValueError(f"glider_fuselage.mass={mass!r}: must be > 0 [kg]")
        j_tot = j_tot * (mass / m_tot)
        m_tot = float(mass)
        assumptions.append(f"mass overridden: {mass} kg (inertia scaled with it)")
    if cg is not None:
        cg_arr = np.asarray(cg, dtype=float)
        if cg_arr.shape != (3,):
            raise ValueError(f"glider_fuselage.cg={cg!r}: must be a 3-vector [m]")
        cg_tot = cg_arr
        assumptions.append(f"CG overridden: {cg_arr.tolist()} m (construction frame)")
    if inertia is not None:
        j_tot = check_inertia(inertia, "glider_fuselage.inertia")
        assumptions.append("inertia overridden by the user")
    if pitch_inertia is not None:
        if not pitch_inertia > 0.0:
            raise ValueError(
                f"glider_fuselage.pitch_inertia={pitch_inertia!r}: must be > 0 [kg m^2]")
        j_tot = np.array(j_tot, dtype=float)
        delta = pitch_inertia - j_tot[1, 1]
        j_tot[1, 1] = pitch_inertia
        j_tot[2, 2] += delta  # mass moved along the fuselage axis changes I_zz alike
        j_tot = check_inertia(j_tot, "glider_fuselage.pitch_inertia")
        assumptions.append(f"pitch inertia overridden: {pitch_inertia} kg m^2 (I_zz shifted by "
                           f"the same {delta:+.1f} kg m^2: mass moved along the x axis)")
    floor_z = -0.5 * bu.height
    mounts = {
        # front: on the floor, 0.40 m behind the nose tip (in the nose cone); rear: on the
        # floor at the aft bulkhead, 2.20 m from the nose; gyro next to the rear pair.
        "front": np.array([-0.40, 0.0, floor_z + 0.05]),
        "rear": np.array([-2.20, 0.0, floor_z + 0.05]),
        "gyro": np.array([-2.10, 0.0, floor_z + 0.05]),
    }
    fs_acc = 250.0 * G0
    sensors = (
        SensorMount("front_accel_x", mounts["front"] - cg_tot, (1, 0, 0), "accelerometer", fs_acc),
        SensorMount("front_accel_z", mounts["front"] - cg_tot, (0, 0, 1), "accelerometer", fs_acc),
        SensorMount("rear_accel_x", mounts["rear"] - cg_tot, (1, 0, 0), "accelerometer", fs_acc),
        SensorMount("rear_accel_z", mounts["rear"] - cg_tot, (0, 0, 1), "accelerometer", fs_acc),
        SensorMount("pitch_rate", mounts["gyro"] - cg_tot, (0, -1, 0), "gyro",
                    np.deg2rad(1500.0)),
    )
    assumptions.append("sensor mounts: front at station 0.40 m, rear at 2.20 m, gyro at 2.10 m, "
                       "all 0.05 m above the floor; gyro full scale 1500 deg/s")
    return RigidBodySpec(
        name="glider_fuselage",
        mass=m_tot,
        inertia=j_tot,
        vertices=v - cg_tot,
        triangles=t,
        contact_radius=None,
        sensors=sensors,
        reference_dimensions={"length": bu.length, "width": bu.width, "height": bu.height},
        cg_in_construction_frame=cg_tot,
        components=tuple(comps),
        assumptions=tuple(assumptions),
    )


# ---------------------------------------------------------------------------- split nose
def _shift(m: float, d) -> np.ndarray:
    """Parallel-axis term ``m ((d.d) I - d d^T)`` [kg m^2]."""
    d = np.asarray(d, dtype=float)
    return m * (float(d @ d) * np.eye(3) - np.outer(d, d))


def split_nose(spec: RigidBodySpec, cut_station: float, areal_density: float,
               extra_mass: float = 0.0) -> tuple[RigidBodySpec, RigidBodySpec]:
    """Split a fuselage spec into a crushable nose (the shell ahead of ``cut_station``) and
    the rest of the aircraft (``physics.structural_crush``, docs/glider.md).

    Parameters
    ----------
    spec : RigidBodySpec
        The whole fuselage (body frame at its CG; the construction frame has x forward from
        the nose tip, so a station ``s`` aft of the tip is at ``x = -s``).
    cut_station : float
        Station of the cut aft of the nose tip [m], > 0 and inside the mesh; the nose takes
        the triangles whose three vertices lie at or ahead of it.
    areal_density : float
        Shell areal density [kg/m^2] (the laminate, ``GliderBuildUp.laminate_areal_density``).
    extra_mass : float
        Point mass added at the nose shell's CG (instruments) [kg], >= 0.

    Returns
    -------
    (rear, nose) : RigidBodySpec
        Each in its own CG body frame, axes parallel to ``spec``'s. ``rear`` keeps all the
        sensor mounts (offsets from its own CG) and ``spec.mass - nose.mass``; ``nose.
        cg_in_construction_frame`` / ``rear.cg_in_construction_frame`` locate the two CGs.

    Notes
    -----
    Thin-shell integrals (:func:`bodies.mesh.shell_mass_properties`) for the nose; the rear
    part by subtraction with the parallel-axis theorem:
    ``J_G = J_r + m_r S(d_r) + J_n + m_n S(d_n)``, ``S(d) = (d.d) I - d d^T``, ``d`` the part
    CG minus the whole CG; the total mass, CG and inertia are conserved exactly.
    """
    if not extra_mass >= 0.0:
        raise ValueError(f"split_nose.extra_mass={extra_mass!r}: must be >= 0 [kg]")
    v_c = np.asarray(spec.vertices) + np.asarray(spec.cg_in_construction_frame)
    station = -v_c[:, 0]
    if not (np.isfinite(cut_station) and station.min() < cut_station < station.max()):
        raise ValueError(f"split_nose.cut_station={cut_station!r}: must be in "
                         f"({station.min():.3f}, {station.max():.3f}) [m] (inside the mesh)")
    tri = np.asarray(spec.triangles)
    ahead = np.all(station[tri] <= cut_station + 1e-9, axis=1)
    if not ahead.any() or ahead.all():
        raise ValueError(f"split_nose.cut_station={cut_station!r}: leaves no triangle on one "
                         "side of the cut")
    m_n, cg_n, j_n = shell_mass_properties(spec.vertices, tri[ahead], areal_density)
    if extra_mass > 0.0:
        m_n += extra_mass  # point mass at the shell CG: no own inertia
    m_r = spec.mass - m_n
    if not m_r > 0.0:
        raise ValueError(f"split_nose: nose mass {m_n:.2f} kg must be < the body mass "
                         f"{spec.mass:.2f} kg")
    cg_r = -m_n * cg_n / m_r  # whole CG at the origin: m_r cg_r + m_n cg_n = 0
    j_r = np.asarray(spec.inertia) - j_n - _shift(m_n, cg_n) - _shift(m_r, cg_r)
    j_r = check_inertia(0.5 * (j_r + j_r.T), "split_nose rear inertia")

    def sub(mask, cg):
        used = np.unique(tri[mask])
        remap = -np.ones(len(spec.vertices), dtype=np.int64)
        remap[used] = np.arange(used.size)
        return np.asarray(spec.vertices)[used] - cg, remap[tri[mask]]

    v_n, t_n = sub(ahead, cg_n)
    v_r, t_r = sub(~ahead, cg_r)
    base_cg = np.asarray(spec.cg_in_construction_frame, dtype=float)
    sensors = tuple(SensorMount(s.name, np.asarray(s.position) - cg_r, s.axis, s.kind,
                                s.full_scale) for s in spec.sensors)
    note = (f"split at station {cut_station:.3f} m: nose shell {m_n:.2f} kg "
            f"(areal density {areal_density:.3f} kg/m^2 + {extra_mass:.2f} kg)")
    rear = RigidBodySpec(name=f"{spec.name}_rear", mass=m_r, inertia=j_r, vertices=v_r,
                         triangles=t_r, sensors=sensors,
                         reference_dimensions=dict(spec.reference_dimensions),
                         cg_in_construction_frame=base_cg + cg_r,
                         assumptions=tuple(spec.assumptions) + (note,))
    nose = RigidBodySpec(name=f"{spec.name}_nose", mass=m_n, inertia=j_n, vertices=v_n,
                         triangles=t_n, cg_in_construction_frame=base_cg + cg_n,
                         assumptions=(note,))
    return rear, nose
