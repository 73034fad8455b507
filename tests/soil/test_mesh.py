"""TriangleMesh: closest point on a triangle, validation, I/O, orientation, mass properties."""

import meshio
import numpy as np
import pytest
from hypothesis import HealthCheck, assume, example, given, settings
from hypothesis import strategies as st
from scipy.optimize import minimize

from soil import _mesh_kernels as mk
from soil.mesh import MassProperties, TriangleMesh

# float64 round-off on coordinates of order 1 amplified by a few dozen operations
ROUNDOFF = 1e-12
# SLSQP on a smooth convex 2-variable problem, started at the centroid, stops at ftol 1e-14 on
# the squared distance: the distance it reports is within ~1e-7 of the optimum
SLSQP_DIST_TOL = 1e-6
# STL stores float32 coordinates: relative resolution 2^-24 ~ 6e-8
FLOAT32_REL = 1e-7


# --------------------------------------------------------------------------------------------
# closest point on a triangle
# --------------------------------------------------------------------------------------------


def _numpy_closest(p, a, b, c):
    """Independent oracle: plane projection if inside, else the best of the 3 clamped edges."""
    n = np.cross(b - a, c - a)
    q = p - np.dot(p - a, n) / np.dot(n, n) * n
    # barycentric coordinates of q by signed sub-areas
    lam = np.array([np.dot(np.cross(c - b, q - b), n), np.dot(np.cross(a - c, q - c), n),
                    np.dot(np.cross(b - a, q - a), n)]) / np.dot(n, n)
    if np.all(lam >= 0):
        return q
    best, best_d = None, np.inf
    for s, e in ((a, b), (b, c), (c, a)):
        t = np.clip(np.dot(p - s, e - s) / np.dot(e - s, e - s), 0.0, 1.0)
        cand = s + t * (e - s)
        d = np.linalg.norm(p - cand)
        if d < best_d:
            best, best_d = cand, d
    return best


def _slsqp_distance(p, a, b, c):
    """Oracle 2: numerical minimisation of |p - (a + u (b - a) + v (c - a))| over the simplex."""
    ab, ac = b - a, c - a

    def f(uv):
        r = a + uv[0] * ab + uv[1] * ac - p
        return r @ r

    res = minimize(f, x0=[1 / 3, 1 / 3], method="SLSQP", bounds=[(0, 1), (0, 1)],
                   constraints=[{"type": "ineq", "fun": lambda uv: 1.0 - uv[0] - uv[1]}],
                   options={"ftol": 1e-14, "maxiter": 200})
    return np.sqrt(res.fun)


def _kernel_closest(p, a, b, c):
    q, f = mk.closest_points(p[None], a[None], b[None], c[None])
    return q[0], int(f[0])


def _barycentric(q, a, b, c):
    n = np.cross(b - a, c - a)
    return np.array([np.dot(np.cross(c - b, q - b), n), np.dot(np.cross(a - c, q - c), n),
                     np.dot(np.cross(b - a, q - a), n)]) / np.dot(n, n)


coord = st.floats(-1.0, 1.0, allow_nan=False, allow_infinity=False)
vec = st.tuples(coord, coord, coord).map(np.array)

# pinned points in each Voronoi region of the triangle (0,0,0), (1,0,0), (0,1,0) (z = 0.3 above)
A0, B0, C0 = np.array([0.0, 0, 0]), np.array([1.0, 0, 0]), np.array([0.0, 1, 0])
VORONOI_CASES = [
    ((0.2, 0.2, 0.3), mk.FEATURE_FACE),
    ((0.5, -0.4, 0.3), mk.FEATURE_EDGE0),  # below edge (0, 1)
    ((0.8, 0.8, 0.3), mk.FEATURE_EDGE1),  # beyond hypotenuse (1, 2)
    ((-0.4, 0.5, 0.3), mk.FEATURE_EDGE2),  # left of edge (2, 0)
    ((-0.3, -0.2, 0.3), mk.FEATURE_VERTEX0),
    ((1.5, -0.2, -0.3), mk.FEATURE_VERTEX1),
    ((-0.1, 1.6, 0.0), mk.FEATURE_VERTEX2),
]


@pytest.mark.parametrize("p, feature", VORONOI_CASES)
def test_closest_point_pinned_voronoi_regions(p, feature):
    """Oracle: closed-form closest point of each Voronoi region of a right triangle."""
    p = np.array(p)
    q, f = _kernel_closest(p, A0, B0, C0)
    assert f == feature
    np.testing.assert_allclose(q, _numpy_closest(p, A0, B0, C0), atol=ROUNDOFF)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.filter_too_much])
@given(p=vec, a=vec, b=vec, c=vec)
@example(p=np.array([0.5, 0.5, 0.0]), a=A0, b=B0, c=C0)  # exactly on the hypotenuse
@example(p=np.array([1.0, 0.0, 0.0]), a=A0, b=B0, c=C0)  # exactly on a vertex
@example(p=np.array([0.25, 0.25, 0.0]), a=A0, b=B0, c=C0)  # in the face plane, inside
def test_closest_point_matches_independent_oracles(p, a, b, c):
    """Oracles: an independent projection/clamped-edge implementation, and SLSQP minimisation of
    the distance over the triangle (no point of the triangle may be closer than ours); the
    returned feature is consistent with the barycentric coordinates of the point."""
    n = np.cross(b - a, c - a)
    area = 0.5 * np.linalg.norm(n)
    longest = max(np.linalg.norm(b - a), np.linalg.norm(c - b), np.linalg.norm(a - c))
    assume(area > 1e-3 and area > 1e-2 * longest**2)  # well-conditioned triangles only
    q, f = _kernel_closest(p, a, b, c)
    d = np.linalg.norm(p - q)
    np.testing.assert_allclose(q, _numpy_closest(p, a, b, c), atol=1e-9)
    assert d <= _slsqp_distance(p, a, b, c) + SLSQP_DIST_TOL
    lam = _barycentric(q, a, b, c)
    assert lam.min() >= -1e-9  # q is on the triangle
    if f == mk.FEATURE_FACE:
        assert lam.min() >= -1e-9
    elif f <= mk.FEATURE_EDGE2:
        opposite = (f - mk.FEATURE_EDGE0 + 2) % 3  # edge k joins corners k, k+1
        assert abs(lam[opposite]) <= 1e-9
    else:
        np.testing.assert_array_equal(q, (a, b, c)[f - mk.FEATURE_VERTEX0])


# --------------------------------------------------------------------------------------------
# construction and validation
# --------------------------------------------------------------------------------------------


def test_validation_errors_name_field_value_and_index():
    """Each invalid input is rejected with the field, the offending value/index and the rule."""
    v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 0, 0]])
    with pytest.raises(ValueError, match=r"triangles\[1\]=\[0, 1, 3\]: degenerate, area 0"):
        TriangleMesh(v, [[0, 1, 2], [0, 1, 3]])
    with pytest.raises(ValueError,
                       match=r"triangles\[0\]=\[0, 1, 7\]: indices must be in \[0, 3\]"):
        TriangleMesh(v, [[0, 1, 7]])
    bad = v.copy()
    bad[2, 1] = np.nan
    with pytest.raises(ValueError, match=r"vertices\[2\].*must be finite"):
        TriangleMesh(bad, [[0, 1, 2]])
    with pytest.raises(ValueError, match=r"vertices: shape \(4, 2\)"):
        TriangleMesh(v[:, :2], [[0, 1, 2]])
    with pytest.raises(ValueError, match=r"icosphere radius=-1.0: must be > 0 \[m\]"):
        TriangleMesh.icosphere(-1.0)
    with pytest.raises(ValueError, match=r"box: lo=.*must satisfy lo < hi"):
        TriangleMesh.box((0, 0, 0), (1, 0, 1))
    m = TriangleMesh(v, [[0, 1, 2]])
    assert not m.vertices.flags.writeable and m.triangles.dtype == np.int32
    with pytest.raises(ValueError, match="not closed"):
        m.mass_properties(density=1.0)


def test_transformed_is_rigid_motion():
    """Oracle: a rigid motion preserves every pairwise vertex distance; the origin maps to x."""
    m = TriangleMesh.box((-1, -2, -3), (1, 2, 3))
    rng = np.random.default_rng(0)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.linalg.det(q))
    w = m.transformed(q, (1.0, 2.0, 3.0))
    d0 = np.linalg.norm(m.vertices[:, None] - m.vertices[None], axis=2)
    d1 = np.linalg.norm(w[:, None] - w[None], axis=2)
    np.testing.assert_allclose(d1, d0, atol=ROUNDOFF)
    np.testing.assert_allclose(w.mean(axis=0), [1.0, 2.0, 3.0], atol=ROUNDOFF)
    with pytest.raises(ValueError, match="proper rotation"):
        m.transformed(np.diag([1.0, 1.0, -1.0]), (0, 0, 0))


# --------------------------------------------------------------------------------------------
# topology and orientation
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("builder", [
    lambda: TriangleMesh.box((0, 0, 0), (1, 2, 3)),
    lambda: TriangleMesh.icosphere(0.7, 2, center=(1, 1, 1)),
    lambda: TriangleMesh.cylinder(0.5, -1.0, 1.0, segments=12),
    lambda: TriangleMesh.cylinder(0.5, -1.0, 1.0, segments=9, axial_divisions=4),
])
def test_builders_closed_and_outward(builder):
    """Oracle: Euler characteristic V - E + F = 2 of a sphere-like closed surface, and outward
    normals (positive divergence-theorem volume)."""
    m = builder()
    n_edges = np.unique(np.sort(m._edges(), axis=1), axis=0).shape[0]
    assert m.n_vertices - n_edges + m.n_triangles == 2
    assert m.is_closed and m.is_consistently_oriented and m.is_outward


def test_plane_patch_geometry():
    """Oracle: the patch lies in the requested plane, faces point along the normal, total area
    Lu Lv, 2 nu nv triangles, and it is open (boundary edges used once)."""
    n = np.array([1.0, 2.0, 2.0]) / 3.0
    m = TriangleMesh.plane_patch((2.0, 3.0), (4, 5), center=(1, 1, 1), normal=n)
    assert m.n_triangles == 40
    np.testing.assert_allclose(m.face_normals, np.tile(n, (40, 1)), atol=ROUNDOFF)
    np.testing.assert_allclose((m.vertices - 1.0) @ n, 0.0, atol=ROUNDOFF)
    assert abs(m.area - 6.0) < ROUNDOFF
    assert not m.is_closed and m.is_consistently_oriented


def test_fix_orientation_restores_outward_normals_and_cavities():
    """Oracle: the builder's outward box; after randomly flipping triangles, fix_orientation
    must give the same normals back; a box nested inside another becomes a cavity (inward),
    so the enclosed volume is V_outer - V_inner."""
    rng = np.random.default_rng(1)
    ref = TriangleMesh.icosphere(1.0, 1)
    tri = ref.triangles.copy()
    flip = rng.random(tri.shape[0]) < 0.5
    tri[flip] = tri[flip][:, ::-1]
    scrambled = TriangleMesh(ref.vertices, tri)
    assert not scrambled.is_consistently_oriented
    fixed = scrambled.fix_orientation()
    np.testing.assert_allclose(fixed.face_normals, ref.face_normals, atol=ROUNDOFF)
    inverted = ref.flipped().fix_orientation()
    assert inverted.is_outward
    outer = TriangleMesh.box((0, 0, 0), (4, 4, 4))
    inner = TriangleMesh.box((1, 1, 1), (2, 3, 2))  # outward too: wrong for a cavity
    both = TriangleMesh(np.vstack([outer.vertices, inner.vertices]),
                        np.vstack([outer.triangles, inner.triangles + 8]))
    fixed = both.fix_orientation()
    assert abs(fixed.signed_volume() - (64.0 - 2.0)) < ROUNDOFF
    assert abs(fixed.mass_properties(density=1.0).mass - 62.0) < ROUNDOFF


def test_triangle_adjacency_of_regular_patch():
    """Oracle: brute-force pairwise check of shared vertices on a plane patch split by
    alternating diagonals (vertices with 4 and with 8 incident triangles)."""
    m = TriangleMesh.plane_patch((1.0, 1.0), (4, 3))
    start, nb = m.triangle_adjacency()
    tri = m.triangles
    for t in range(m.n_triangles):
        expect = [u for u in range(m.n_triangles)
                  if u != t and np.intersect1d(tri[t], tri[u]).size > 0]
        np.testing.assert_array_equal(nb[start[t]:start[t + 1]], expect)


def test_welded_restores_topology_of_triangle_soup():
    """Oracle: a box whose triangles have private corners (as in STL) is open before welding and
    closed with 8 vertices after."""
    ref = TriangleMesh.box((0, 0, 0), (1, 1, 1))
    soup = TriangleMesh(ref.vertices[ref.triangles.ravel()], np.arange(36).reshape(12, 3))
    assert not soup.is_closed
    w = soup.welded()
    assert w.n_vertices == 8 and w.is_outward


# --------------------------------------------------------------------------------------------
# mass properties
# --------------------------------------------------------------------------------------------


def test_box_mass_properties_rotated_and_translated():
    """Oracle: solid cuboid, I = m/12 diag(b^2 + c^2, ...), centroid at the centre; after a
    rotation R the tensor is R I R^T (rigid-body tensor transformation)."""
    lo, hi = np.array([1.0, -2.0, 0.5]), np.array([1.5, 1.0, 2.5])
    m = TriangleMesh.box(lo, hi)
    a, b, c = hi - lo
    mass = 7.0
    mp = m.mass_properties(mass=mass)
    assert isinstance(mp, MassProperties)
    assert abs(mp.measure - a * b * c) < ROUNDOFF
    assert abs(mp.mass - mass) < ROUNDOFF
    np.testing.assert_allclose(mp.centroid, (lo + hi) / 2, atol=ROUNDOFF)
    i_ref = mass / 12 * np.diag([b * b + c * c, a * a + c * c, a * a + b * b])
    np.testing.assert_allclose(mp.inertia, i_ref, atol=ROUNDOFF * mass * 10)
    rng = np.random.default_rng(2)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.linalg.det(q))
    moved = TriangleMesh(m.transformed(q, (10.0, -5.0, 3.0)), m.triangles)
    mp2 = moved.mass_properties(density=mass / (a * b * c))
    np.testing.assert_allclose(mp2.inertia, q @ i_ref @ q.T, atol=1e-10)
    np.testing.assert_allclose(mp2.centroid, q @ ((lo + hi) / 2) + (10.0, -5.0, 3.0), atol=1e-10)
    # orientation independent
    mp3 = m.flipped().mass_properties(mass=mass)
    np.testing.assert_allclose(mp3.inertia, i_ref, atol=ROUNDOFF * mass * 10)


def test_polygonal_prism_mass_properties_exact():
    """Oracle: a regular n-gon prism (cylinder builder) has volume n/2 R^2 sin(2 pi/n) H and axial
    moment m R^2 (2 + cos(2 pi/n)) / 6 (regular polygon lamina), centroid on the axis."""
    n, r, z0, z1 = 7, 0.4, -0.3, 0.9
    m = TriangleMesh.cylinder(r, z0, z1, segments=n, center=(0.2, -0.1))
    mp = m.mass_properties(density=1000.0)
    vol = n / 2 * r * r * np.sin(2 * np.pi / n) * (z1 - z0)
    assert abs(mp.measure - vol) < ROUNDOFF
    np.testing.assert_allclose(mp.centroid, [0.2, -0.1, 0.3], atol=ROUNDOFF)
    i_zz = mp.mass * r * r * (2 + np.cos(2 * np.pi / n)) / 6
    assert abs(mp.inertia[2, 2] - i_zz) < 1e-10 * i_zz


def test_icosphere_mass_properties_converge_order_two():
    """Oracle: solid sphere V = 4/3 pi R^3, I = 2/5 M R^2 (with M = rho V_exact); the inscribed
    polyhedron's errors must fall with observed order ~2 in the edge length (chord sagitta
    h^2 / 8R); the centroid is the centre (symmetry) to round-off."""
    r, rho = 0.45, 800.0
    center = np.array([0.3, -0.2, 1.0])
    errs_v, errs_i, hs = [], [], []
    for s in range(1, 6):
        m = TriangleMesh.icosphere(r, s, center=center)
        mp = m.mass_properties(density=rho)
        np.testing.assert_allclose(mp.centroid, center, atol=1e-12)
        errs_v.append(abs(mp.measure - 4 / 3 * np.pi * r**3))
        i_exact = 2 / 5 * rho * 4 / 3 * np.pi * r**5
        errs_i.append(np.abs(mp.inertia - i_exact * np.eye(3)).max())
        v0, v1, _ = m.corners()
        hs.append(np.linalg.norm(v1 - v0, axis=1).mean())
    hs = np.array(hs)
    for errs in (np.array(errs_v), np.array(errs_i)):
        rates = np.log(errs[:-1] / errs[1:]) / np.log(hs[:-1] / hs[1:])
        assert (rates > 1.8).all() and (rates < 2.2).all(), rates


def test_shell_mass_properties():
    """Oracles: thin spherical shell I = 2/3 M R^2 (order-2 convergence on the icosphere); the
    open box surface is a sum of rectangular plates (parallel-axis theorem), exact."""
    errs, hs = [], []
    for s in range(2, 6):
        m = TriangleMesh.icosphere(1.0, s)
        mp = m.shell_mass_properties(mass=3.0)
        errs.append(abs(mp.inertia[0, 0] - 2 / 3 * 3.0))
        v0, v1, _ = m.corners()
        hs.append(np.linalg.norm(v1 - v0, axis=1).mean())
    errs, hs = np.array(errs), np.array(hs)
    rates = np.log(errs[:-1] / errs[1:]) / np.log(hs[:-1] / hs[1:])
    assert (rates > 1.8).all(), rates
    # unit cube surface, areal density 1: each face is a 1x1 plate of mass 1
    mp = TriangleMesh.box((0, 0, 0), (1, 1, 1)).shell_mass_properties(areal_density=1.0)
    # Ixx: 2 plates normal to x (I = 1/12 (1 + 1) each) + 4 plates containing x at 1/2 distance
    # (2 with I = 1/12 + 1/4 and 2 with I = 1/12 + 1/4) -> 2/6 + 4 (1/12 + 1/4) = 5/3
    np.testing.assert_allclose(mp.inertia, 5 / 3 * np.eye(3), atol=ROUNDOFF)
    assert abs(mp.measure - 6.0) < ROUNDOFF
    with pytest.raises(ValueError, match="exactly one of density and mass"):
        TriangleMesh.box((0, 0, 0), (1, 1, 1)).shell_mass_properties()


# --------------------------------------------------------------------------------------------
# inside test and signed distance
# --------------------------------------------------------------------------------------------


def test_contains_and_signed_distance_box():
    """Oracle: analytic signed distance of an axis-aligned box (Quilez), random points inside,
    outside and near faces, edges and corners."""
    lo, hi = np.array([-1.0, -0.5, 0.0]), np.array([1.0, 0.5, 2.0])
    m = TriangleMesh.box(lo, hi)
    rng = np.random.default_rng(3)
    p = rng.uniform(-2.0, 3.0, size=(500, 3))
    c, h = (lo + hi) / 2, (hi - lo) / 2
    q = np.abs(p - c) - h
    sd = np.linalg.norm(np.maximum(q, 0), axis=1) + np.minimum(q.max(axis=1), 0)
    np.testing.assert_allclose(m.signed_distance(p), sd, atol=ROUNDOFF)
    np.testing.assert_array_equal(m.contains(p), sd < 0)


def test_point_in_closed_mesh_world_frame():
    """Oracle: an icosphere of radius R placed at X contains points with |p - X| < R cos(theta)
    (inscribed sphere of the polyhedron, lower bound) and excludes |p - X| > R."""
    from soil.mesh import point_in_closed_mesh

    m = TriangleMesh.icosphere(1.0, 3)
    r_in = np.abs(np.einsum("ij,ij->i", m.face_normals, m.corners()[0])).min()
    rng = np.random.default_rng(4)
    d = rng.normal(size=(400, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    rad = rng.uniform(0, 2, 400)
    rad = rad[(rad < r_in - 1e-9) | (rad > 1 + 1e-9)]
    x = np.array([5.0, 0.0, -1.0])
    rot = np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])
    inside = point_in_closed_mesh(m, x + d[: rad.size] * rad[:, None], rot, x)
    np.testing.assert_array_equal(inside, rad < r_in)


# --------------------------------------------------------------------------------------------
# meshio round trip
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name, kwargs, tol", [
    ("m.stl", {}, FLOAT32_REL),
    ("m_bin.stl", {"binary": True}, FLOAT32_REL),
    ("m.obj", {}, 1e-9),
    ("m.vtu", {}, 0.0),
    ("m.ply", {}, 0.0),
])
def test_meshio_round_trip(tmp_path, name, kwargs, tol):
    """Oracle: the written mesh (generated here) read back has the same triangle set (compared
    as sorted corner coordinates), the same area and volume, and stays outward."""
    m = TriangleMesh.icosphere(0.3, 2, center=(0.1, 0.2, 0.3))
    path = tmp_path / name
    m.write(path, **kwargs)
    back = TriangleMesh.read(path)
    assert back.n_triangles == m.n_triangles and back.n_vertices == m.n_vertices

    def key(mesh):
        c = np.sort(np.stack(mesh.corners(), axis=1).reshape(-1, 9), axis=0)
        return c

    np.testing.assert_allclose(key(back), key(m), atol=tol * 1.0 + 1e-15)
    assert abs(back.volume - m.volume) <= 10 * tol * m.volume + 1e-15
    assert back.is_outward


def test_read_scale_and_quads_split(tmp_path):
    """Oracle: a unit cube of 6 quads written in mm (VTU) reads as 12 triangles of a
    1e-3-scaled cube: area 6e-6 m^2, volume 1e-9 m^3, closed and outward."""
    v = np.array([[i & 1, (i >> 1) & 1, (i >> 2) & 1] for i in range(8)], float)
    quads = np.array([[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4],
                      [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]])
    path = tmp_path / "cube_mm.vtu"
    meshio.write_points_cells(path, v, [("quad", quads)])
    m = TriangleMesh.read(path, scale=1e-3)
    assert m.n_triangles == 12
    assert abs(m.area - 6e-6) < 1e-18 and abs(m.volume - 1e-9) < 1e-21
    assert m.is_outward


def test_read_polygon_cells_fan_split(tmp_path):
    """Oracle: a regular hexagon prism written with two hexagon cells and six quads reads as a
    closed mesh of 2 * 4 + 6 * 2 = 20 triangles with the exact prism volume 3 sqrt(3)/2 a^2 H."""
    a, h = 0.2, 0.5
    ang = np.pi / 3 * np.arange(6)
    ring = np.column_stack([a * np.cos(ang), a * np.sin(ang)])
    pts = np.vstack([np.column_stack([ring, np.zeros(6)]), np.column_stack([ring, np.full(6, h)])])
    i = np.arange(6)
    j = (i + 1) % 6
    cells = [("polygon", np.array([i[::-1], i + 6])), ("quad", np.stack([i, j, j + 6, i + 6], 1))]
    path = tmp_path / "hex.vtu"
    meshio.write_points_cells(path, pts, cells)
    m = TriangleMesh.read(path)
    assert m.n_triangles == 20 and m.is_outward
    assert abs(m.volume - 1.5 * np.sqrt(3) * a * a * h) < ROUNDOFF


def test_read_degenerate_triangle_named_or_dropped(tmp_path):
    """A file with a zero-area sliver (collinear corners) is rejected with the file, the
    triangle index and its area; with drop_degenerate=True the sliver is removed and the
    remaining box is closed with the exact volume."""
    box = TriangleMesh.box((0, 0, 0), (1, 2, 3))
    pts = np.vstack([box.vertices, [[0.5, 0.0, 0.0]]])  # on the edge (0,0,0)-(1,0,0)
    tris = np.vstack([box.triangles, [[0, 1, 8]]])
    path = tmp_path / "sliver.vtu"
    meshio.write_points_cells(path, pts, [("triangle", tris)])
    with pytest.raises(ValueError, match=r"sliver.vtu'.*triangles\[12\]=\[0, 1, 8\]: "
                                         r"degenerate, area 0"):
        TriangleMesh.read(path)
    m = TriangleMesh.read(path, drop_degenerate=True)
    assert m.n_triangles == 12 and m.is_outward and abs(m.volume - 6.0) < ROUNDOFF


def test_read_errors_name_the_file(tmp_path):
    """Unreadable files, files without triangle cells and missing files raise ValueError naming
    the file (and the cell types found)."""
    junk = tmp_path / "junk.stl"
    junk.write_bytes(b"\x00\x01 not a mesh at all " * 3)
    with pytest.raises(ValueError, match="junk.stl"):
        TriangleMesh.read(junk)
    lines = tmp_path / "lines.vtu"
    meshio.write_points_cells(lines, np.eye(3), [("line", np.array([[0, 1], [1, 2]]))])
    with pytest.raises(ValueError,
                       match=r"lines.vtu' has no triangle, quad or polygon cells \(found: line\)"):
        TriangleMesh.read(lines)
    with pytest.raises(ValueError, match="no such file.*missing.obj"):
        TriangleMesh.read(tmp_path / "missing.obj")
    with pytest.raises(ValueError, match=r"scale=-1.0: must be > 0"):
        TriangleMesh.read(lines, scale=-1.0)
