"""Rigid-body specifications: validation, mass properties of the two reference bodies."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

import bodies
from bodies.mesh import enclosed_volume, icosphere, loft_fuselage, shell_mass_properties

#: round-off tolerance for sums of a few hundred float64 terms [-]
ROUNDOFF_RTOL = 1e-12
#: a level-5 icosphere (20480 faces) underestimates a sphere's area by the chord sag,
#: ~1e-3 relative; 3e-3 leaves margin without hiding an error in the integrals (O(1)).
ICOSPHERE_L5_RTOL = 3e-3


def test_inertia_checks_name_field_and_range():
    """Oracle: realisability of an inertia tensor (positive definite, triangle inequality)."""
    with pytest.raises(ValueError, match="symmetric"):
        bodies.check_inertia([[1, 0.5, 0], [0, 1, 0], [0, 0, 1]])
    with pytest.raises(ValueError, match="> 0"):
        bodies.check_inertia(np.diag([1.0, 1.0, -1.0]))
    with pytest.raises(ValueError, match="triangle inequality"):
        bodies.check_inertia(np.diag([1.0, 1.0, 2.5]))
    # a thin plate sits exactly on the bound and is accepted
    bodies.check_inertia(np.diag([1.0, 2.0, 3.0]))
    with pytest.raises(ValueError, match=r"RigidBodySpec.mass=-1"):
        bodies.RigidBodySpec("x", -1.0, np.eye(3), np.eye(3), [[0, 1, 2]])
    with pytest.raises(ValueError, match="full_scale"):
        bodies.SensorMount("a", (0, 0, 0), (1, 0, 0), "accelerometer", -1.0)


def test_drop_sphere_matches_thesis_and_cavity_formula():
    """Oracles: thesis §2.1.1 (850 kg, 0.90 m, 200 g / 50 g channels) and the thick-shell
    inertia 2/5 m (R^5 - r^5)/(R^3 - r^3), which tends to 2/5 m R^2 without the cavity."""
    s = bodies.drop_sphere()
    assert s.mass == 850.0
    assert s.contact_radius == pytest.approx(0.45, rel=ROUNDOFF_RTOL)
    i_expected = 0.4 * 850.0 * (0.45**5 - 0.1**5) / (0.45**3 - 0.1**3)
    np.testing.assert_allclose(s.inertia, i_expected * np.eye(3), rtol=ROUNDOFF_RTOL)
    assert bodies.sphere_with_cavity_inertia(1.0, 1.0, 0.0) == pytest.approx(0.4)
    fs = {m.name: m.full_scale / bodies.library.G0 for m in s.sensors}
    assert fs == pytest.approx({"accel_x": 200.0, "accel_y": 50.0, "accel_z": 200.0})
    for m in s.sensors:
        np.testing.assert_array_equal(m.position, 0.0)


def test_shell_integrals_on_a_sphere():
    """Oracle: thin spherical shell, area 4 pi R^2 and inertia 2/3 m R^2 about its centre."""
    v, t = icosphere(0.7, 5)
    m, cg, j = shell_mass_properties(v, t, 2.0)
    assert m == pytest.approx(2.0 * 4 * np.pi * 0.49, rel=ICOSPHERE_L5_RTOL)
    np.testing.assert_allclose(cg, 0.0, atol=1e-12)
    np.testing.assert_allclose(j, 2.0 / 3.0 * m * 0.49 * np.eye(3), rtol=ICOSPHERE_L5_RTOL,
                               atol=1e-12)
    assert enclosed_volume(v, t) == pytest.approx(4 / 3 * np.pi * 0.343, rel=ICOSPHERE_L5_RTOL)


def test_glider_build_up_closes_on_343_kg():
    """Oracle: thesis §2.2.1 total mass 343 kg; parallel-axis theorem recomputed by hand
    from the component list (independent summation)."""
    g = bodies.glider_fuselage()
    assert g.mass == pytest.approx(343.0, rel=ROUNDOFF_RTOL)
    comps = {c.name: c for c in g.components}
    assert comps["side_mass_left"].mass + comps["side_mass_right"].mass == pytest.approx(32.0)
    assert comps["dummy"].mass == 77.0
    # tube 100 mm, 4 mm wall, 2 m, steel: 7850 * (0.1^2 - 0.092^2) * 2
    assert comps["wingbeam_tube"].mass == pytest.approx(7850 * (0.01 - 0.092**2) * 2.0)
    m = sum(c.mass for c in g.components)
    cg = sum(c.mass * c.cg for c in g.components) / m
    iyy = sum(c.inertia[1, 1] + c.mass * ((c.cg[0] - cg[0]) ** 2 + (c.cg[2] - cg[2]) ** 2)
              for c in g.components)
    np.testing.assert_allclose(g.cg_in_construction_frame, cg, rtol=ROUNDOFF_RTOL)
    assert g.inertia[1, 1] == pytest.approx(iyy, rel=ROUNDOFF_RTOL)
    # the mesh is in the body frame: its vertices are the construction frame minus the CG
    assert g.vertices[:, 0].max() == pytest.approx(-cg[0], rel=1e-9)  # nose tip
    # laminate: (160 + 6*280 + 2*200) g/m^2 fabric at 45 % resin by mass
    assert bodies.GliderBuildUp().laminate_areal_density == pytest.approx(2.240 / 0.55)


def test_glider_overrides_and_sensor_convention():
    """Oracle: overrides are applied verbatim; mounts move with the CG."""
    g = bodies.glider_fuselage(mass=300.0, cg=(-2.0, 0.0, 0.0), pitch_inertia=400.0)
    ref = bodies.glider_fuselage(mass=300.0)
    assert g.mass == 300.0 and g.inertia[1, 1] == 400.0
    assert g.inertia[2, 2] - ref.inertia[2, 2] == pytest.approx(400.0 - ref.inertia[1, 1])
    np.testing.assert_allclose(g.sensor("front_accel_x").position, [-0.40 + 2.0, 0.0, -0.35])
    np.testing.assert_allclose(g.sensor("pitch_rate").axis, [0.0, -1.0, 0.0])
    with pytest.raises(ValueError, match="ballast"):
        bodies.glider_fuselage(bodies.GliderBuildUp(total_mass=100.0))


def test_fuselage_mesh_closed_and_outward():
    """Oracle: closed 2-manifold (every edge shared by exactly two triangles, in opposite
    directions) with positive enclosed volume, bounded by the ellipse-section cylinder."""
    v, t, is_cap = loft_fuselage()
    edges = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    directed = {tuple(e) for e in edges}
    assert len(directed) == len(edges)
    assert all((b, a) in directed for a, b in directed)
    vol = enclosed_volume(v, t)
    assert 0.0 < vol < np.pi * 0.3 * 0.4 * 2.3
    assert v[:, 0].min() == pytest.approx(-2.3) and v[:, 0].max() == 0.0
    assert np.ptp(v[:, 1]) == pytest.approx(0.6, rel=1e-2)
    assert np.ptp(v[:, 2]) == pytest.approx(0.8, rel=1e-2)
    assert is_cap.sum() == 32


def test_user_mesh_round_trip_in_millimetres(tmp_path):
    """Oracle: the same surface written in mm and read with scale 1e-3 gives the same
    mass properties as the parametric one (meshio round trip, unit scaling)."""
    v, t, _ = loft_fuselage()
    path = tmp_path / "fuselage_mm.stl"
    bodies.mesh.write_mesh(path, v * 1e3, t)
    vr, tr = bodies.mesh.read_mesh(path, scale=1e-3)
    assert len(vr) == len(v) and len(tr) == len(t)
    # the STL has no cap tag, so compare against the user-mesh path on the parametric arrays
    a = bodies.mesh.triangle_areas(v, t).sum()
    assert bodies.mesh.triangle_areas(vr, tr).sum() == pytest.approx(a, rel=1e-6)
    g = bodies.glider_fuselage(mesh_path=path, mesh_scale=1e-3)
    assert g.mass == pytest.approx(343.0)
    shell = [c for c in g.components if c.name == "shell"][0]
    assert shell.mass == pytest.approx(a * bodies.GliderBuildUp().laminate_areal_density, rel=1e-6)


@settings(max_examples=60, deadline=None)
@given(a=st.floats(0.01, 1e3), b=st.floats(0.01, 1e3), frac=st.floats(0.0, 1.0),
       quat=st.tuples(*[st.floats(-1.0, 1.0)] * 4).filter(lambda q: sum(x * x for x in q) > 0.1))
def test_check_inertia_accepts_exactly_the_realisable_tensors(a, b, frac, quat):
    """Oracle: a tensor R diag(I1, I2, I3) R^T is realisable iff every moment is > 0 and
    I3 <= I1 + I2 (Goldstein §5.3). I3 is drawn on both sides of the bound; the bound itself
    (a thin plate) is a pinned edge case in test_inertia_checks_name_field_and_range."""
    r = Rotation.from_quat(quat).as_matrix()
    i3_ok = frac * (a + b)  # inside the bound (or zero -> not positive)
    i3_bad = (a + b) * (1.0 + 1e-6 + frac)  # outside the bound
    if i3_ok > 1e-9 * (a + b) and i3_ok >= abs(a - b):
        j = r @ np.diag([a, b, i3_ok]) @ r.T
        np.testing.assert_allclose(bodies.check_inertia(j), 0.5 * (j + j.T))
    with pytest.raises(ValueError, match="triangle inequality|> 0"):
        bodies.check_inertia(r @ np.diag([a, b, i3_bad]) @ r.T)
