"""Sphere--triangle-mesh contacts: de-duplication, creases, convergence, broad phase, threads."""

import time

import numba
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from soil import _mesh_kernels as mk
from soil.mesh import (MeshCollider, TriangleMesh, continue_contacts, spheres_touching_mesh,
                       world_contacts)

# float64 round-off on coordinates of order 1 after a rotation and a few dozen operations
ROUNDOFF = 1e-12


def _rotation(seed):
    q, _ = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    return q * np.sign(np.linalg.det(q))


def _contacts(mesh, x, r, rotation=None, translation=None, max_radius=None):
    x = np.atleast_2d(np.asarray(x, float))
    r = np.broadcast_to(np.asarray(r, float), (x.shape[0],)).copy()
    col = MeshCollider(mesh, max_radius or float(r.max()))
    return col.contacts(x, r, rotation, translation)


def _numpy_min_distance(points, mesh):
    """Independent oracle: distance to the nearest triangle by plane projection (if inside,
    signed sub-areas) or the best clamped edge, vectorised over all point-triangle pairs."""
    a, b, c = (v[None] for v in mesh.corners())
    p = points[:, None, :]
    n = np.cross(b - a, c - a)
    nn = np.einsum("...i,...i", n, n)
    q = p - (np.einsum("...i,...i", p - a, n) / nn)[..., None] * n
    lam = np.stack([np.einsum("...i,...i", np.cross(c - b, q - b), n),
                    np.einsum("...i,...i", np.cross(a - c, q - c), n),
                    np.einsum("...i,...i", np.cross(b - a, q - a), n)], axis=-1)
    inside = (lam >= 0).all(axis=-1)
    d = np.where(inside, np.linalg.norm(p - q, axis=-1), np.inf)
    for s, e in ((a, b), (b, c), (c, a)):
        t = np.clip(np.einsum("...i,...i", p - s, e - s) / np.einsum("...i,...i", e - s, e - s),
                    0, 1)
        d = np.minimum(d, np.linalg.norm(p - (s + t[..., None] * (e - s)), axis=-1))
    return d.min(axis=1)


# --------------------------------------------------------------------------------------------
# flat patches: exactly one contact, equal to the analytic plane's
# --------------------------------------------------------------------------------------------


def _assert_plane_contact(c, r, h, normal, foot):
    assert len(c) == 1, f"{len(c)} contacts (features {c.feature}, triangles {c.triangle})"
    assert abs(c.overlap[0] - (r - h)) < ROUNDOFF
    np.testing.assert_allclose(c.normal[0], normal, atol=1e-9)
    np.testing.assert_allclose(c.point[0], foot, atol=ROUNDOFF)


@settings(max_examples=150, deadline=None)
@given(
    nu=st.integers(1, 10), nv=st.integers(1, 10), seed=st.integers(0, 2**31),
    kind=st.sampled_from(["random", "vertex", "edge", "edge_mid"]),
    t=st.floats(0.0, 1.0), h_frac=st.floats(0.02, 0.98), rotated=st.booleans(),
    jitter=st.booleans(),
)
def test_flat_patch_single_contact_equals_plane(nu, nv, seed, kind, t, h_frac, rotated, jitter):
    """Oracle: analytic sphere-plane contact (overlap r - h, normal = plane normal, contact point
    = foot of the perpendicular). A patch of 2..200 triangles -- regular or with jittered interior
    vertices (irregular fans) -- must give exactly one contact anywhere, including exactly on
    shared edges (diagonals too) and vertices; the mesh is placed by a random rigid motion."""
    rng = np.random.default_rng(seed)
    mesh = TriangleMesh.plane_patch((1.0, 1.0), (nu, nv))
    if jitter and nu > 1 and nv > 1:
        v = mesh.vertices.copy()
        interior = (np.abs(v[:, 0]) < 0.5 - 1e-9) & (np.abs(v[:, 1]) < 0.5 - 1e-9)
        v[interior, :2] += rng.uniform(-0.3, 0.3, (interior.sum(), 2)) / np.array([nu, nv])
        mesh = TriangleMesh(v, mesh.triangles)
    r = 0.2 / max(nu, nv) + 0.05 * rng.random()
    h = h_frac * r
    if kind == "random":
        foot = np.r_[rng.uniform(-0.45, 0.45, 2), 0.0]
    else:
        tri = mesh.triangles[rng.integers(mesh.n_triangles)]
        k = rng.integers(3)
        a, b = mesh.vertices[tri[k]], mesh.vertices[tri[(k + 1) % 3]]
        foot = {"vertex": a, "edge": a + t * (b - a), "edge_mid": 0.5 * (a + b)}[kind]
    x_body = foot + np.array([0.0, 0.0, h])
    if rotated:
        rot, trans = _rotation(seed), rng.uniform(-5, 5, 3)
        c = _contacts(mesh, rot @ x_body + trans, r, rot, trans)
        _assert_plane_contact(c, r, h, rot[:, 2], rot @ foot + trans)
    else:
        c = _contacts(mesh, x_body, r)
        _assert_plane_contact(c, r, h, [0.0, 0.0, 1.0], foot)


@pytest.mark.parametrize("divisions", [(1, 1), (10, 10)])
def test_rolling_across_patch_is_continuous(divisions):
    """Oracle: analytic plane. A sphere swept in 2001 steps along a line crossing diagonals,
    shared edges and vertices of the patch (including exact hits) feels exactly one contact of
    constant overlap and normal at every position: no double force across an edge."""
    mesh = TriangleMesh.plane_patch((1.0, 1.0), divisions)
    r, h = 0.05, 0.03
    s = np.linspace(-0.45, 0.45, 2001)
    for direction in ([1.0, 0.0], [1.0, 1.0], [1.0, 0.37]):
        d = np.array(direction) / np.linalg.norm(direction)
        x = np.column_stack([s * d[0], s * d[1], np.full(s.size, h)])
        c = _contacts(mesh, x, np.full(s.size, r))
        np.testing.assert_array_equal(c.particle, np.arange(s.size))
        np.testing.assert_allclose(c.overlap, r - h, atol=ROUNDOFF)
        np.testing.assert_allclose(c.normal, np.tile([0, 0, 1.0], (s.size, 1)), atol=1e-9)


def test_particle_much_larger_than_triangles_single_contact():
    """Oracles: analytic plane and analytic sphere. A particle spanning ~10 triangles of a fine
    jittered flat patch (about 150 touching triangles) or of a fine icosphere still gets exactly
    one contact, with the plane's overlap and normal / the polyhedron's nearest distance."""
    rng = np.random.default_rng(15)
    mesh = TriangleMesh.plane_patch((1.0, 1.0), (40, 40))
    v = mesh.vertices.copy()
    interior = (np.abs(v[:, 0]) < 0.5 - 1e-9) & (np.abs(v[:, 1]) < 0.5 - 1e-9)
    v[interior, :2] += rng.uniform(-0.008, 0.008, (interior.sum(), 2))
    mesh = TriangleMesh(v, mesh.triangles)
    r = 0.12
    x = np.column_stack([rng.uniform(-0.3, 0.3, (300, 2)), rng.uniform(0.01, 0.1, 300)])
    c = _contacts(mesh, x, r)
    np.testing.assert_array_equal(c.particle, np.arange(300))
    np.testing.assert_allclose(c.overlap, r - x[:, 2], atol=ROUNDOFF)
    np.testing.assert_allclose(c.normal, np.tile([0, 0, 1.0], (300, 1)), atol=1e-9)
    sphere = TriangleMesh.icosphere(1.0, 4)
    d = rng.normal(size=(300, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    x = d * 1.1
    c = _contacts(sphere, x, 0.25)
    np.testing.assert_array_equal(c.particle, np.arange(300))
    np.testing.assert_allclose(c.overlap, 0.25 - _numpy_min_distance(x, sphere), atol=ROUNDOFF)


def test_continue_contacts_follows_a_sliding_sphere():
    """Oracle: a sphere sliding in 400 steps over a jittered 10 x 10 patch is one physical
    contact: every step's contact continues the previous one (index 0 of a one-contact list),
    although it changes triangle many times; a sphere lifted off and put back starts anew; in a
    concave corner both contacts continue themselves."""
    rng = np.random.default_rng(16)
    mesh = TriangleMesh.plane_patch((1.0, 1.0), (10, 10))
    v = mesh.vertices.copy()
    interior = (np.abs(v[:, 0]) < 0.5 - 1e-9) & (np.abs(v[:, 1]) < 0.5 - 1e-9)
    v[interior, :2] += rng.uniform(-0.03, 0.03, (interior.sum(), 2))
    mesh = TriangleMesh(v, mesh.triangles)
    col = MeshCollider(mesh, 0.03)
    s = np.linspace(-0.4, 0.4, 400)
    path = np.column_stack([s, 0.3 * np.sin(7 * s), np.full(s.size, 0.02)])
    prev = col.contacts(path[:1], [0.03])
    switches = 0
    for x in path[1:]:
        cur = col.contacts(x[None], [0.03])
        assert len(cur) == 1
        np.testing.assert_array_equal(continue_contacts(prev, cur, mesh), [0])
        switches += int(cur.triangle[0] != prev.triangle[0])
        prev = cur
    assert switches > 20
    far = col.contacts(path[-1:] + [0, 0, 1.0], [0.03])
    np.testing.assert_array_equal(continue_contacts(far, prev, mesh), [-1])
    corner = _corner_mesh((2, 2))
    cc = MeshCollider(corner, 0.1).contacts(np.array([[0.06, 0.1, 0.03]]), [0.1])
    np.testing.assert_array_equal(continue_contacts(cc, cc, corner), [0, 1])


def test_free_boundary_edge_and_vertex_keep_their_contact():
    """Oracle: distance to a segment / point. A sphere beyond the rim of an open patch touches
    the boundary edge (or corner) only: one contact with r - distance and a radial normal."""
    mesh = TriangleMesh.plane_patch((1.0, 1.0), (3, 3))
    r = 0.1
    x = np.array([[0.55, 0.1, 0.03], [0.54, 0.53, 0.02]])
    c = _contacts(mesh, x, r)
    np.testing.assert_array_equal(c.particle, [0, 1])
    feet = np.array([[0.5, 0.1, 0.0], [0.5, 0.5, 0.0]])
    dist = np.linalg.norm(x - feet, axis=1)
    np.testing.assert_allclose(c.overlap, r - dist, atol=ROUNDOFF)
    np.testing.assert_allclose(c.normal, (x - feet) / dist[:, None], atol=1e-12)
    assert c.feature[0] in (mk.FEATURE_EDGE0, mk.FEATURE_EDGE1, mk.FEATURE_EDGE2)
    assert c.feature[1] >= mk.FEATURE_VERTEX0


# --------------------------------------------------------------------------------------------
# creases
# --------------------------------------------------------------------------------------------


def _corner_mesh(divisions):
    """Floor z = 0 (x in [0, 1]) and wall x = 0 (z in [0, 1]) sharing the crease y-axis segment."""
    floor = TriangleMesh.plane_patch((1.0, 1.0), divisions, center=(0.5, 0.0, 0.0),
                                     u_axis=(1, 0, 0))
    wall = TriangleMesh.plane_patch((1.0, 1.0), divisions, center=(0.0, 0.0, 0.5),
                                    normal=(1, 0, 0), u_axis=(0, 0, 1))
    n = floor.n_vertices
    return TriangleMesh(np.vstack([floor.vertices, wall.vertices]),
                        np.vstack([floor.triangles, wall.triangles + n])).welded()


@pytest.mark.parametrize("divisions", [(1, 1), (4, 4)])
@pytest.mark.parametrize("y", [0.0, 0.1, 0.25, -0.3])
def test_concave_right_angle_corner_gives_two_face_contacts(divisions, y):
    """Oracle: analytic sphere in a 90 degree concave corner, two plane contacts with normals
    +z (floor, overlap r - z) and +x (wall, overlap r - x); the crease edges and vertices add
    nothing, whichever triangles meet there (y on vertices of the crease and between)."""
    mesh = _corner_mesh(divisions)
    assert mesh.n_vertices == 2 * (divisions[0] + 1) * (divisions[1] + 1) - (divisions[1] + 1)
    r, x0, z0 = 0.1, 0.06, 0.03
    c = _contacts(mesh, [x0, y, z0], r)
    assert len(c) == 2
    order = np.argsort(c.normal[:, 0])  # floor first
    np.testing.assert_allclose(c.normal[order], [[0, 0, 1.0], [1.0, 0, 0]], atol=1e-12)
    np.testing.assert_allclose(c.overlap[order], [r - z0, r - x0], atol=ROUNDOFF)
    np.testing.assert_allclose(c.point[order], [[x0, y, 0], [0, y, z0]], atol=ROUNDOFF)


def test_inward_box_corner_three_contacts_and_convex_box_edge_corner_one():
    """Oracles: analytic planes and analytic distance to a line / point. Inside a container box
    a sphere in a corner touches the three walls (3 contacts); outside a solid box, a sphere
    near an edge or a corner has one contact with r - |x - edge/corner| and the radial normal,
    and a sphere over a face next to the edge has only the face contact."""
    tank = TriangleMesh.box((0, 0, 0), (1, 1, 1), inward=True)
    r = 0.1
    c = _contacts(tank, [0.05, 0.07, 0.08], r)
    assert len(c) == 3
    np.testing.assert_allclose(np.sort(c.overlap), np.sort(r - np.array([0.05, 0.07, 0.08])),
                               atol=ROUNDOFF)
    solid = TriangleMesh.box((0, 0, 0), (1, 1, 1))
    x = np.array([[1.04, 0.5, 1.05], [1.03, 1.02, 1.05], [0.98, 0.5, 1.05], [0.5, 0.5, 1.0]])
    feet = np.array([[1.0, 0.5, 1.0], [1.0, 1.0, 1.0], [0.98, 0.5, 1.0], [0.5, 0.5, 1.0]])
    c = _contacts(solid, x, r)
    np.testing.assert_array_equal(c.particle, [0, 1, 2, 3])
    dist = np.linalg.norm(x - feet, axis=1)
    np.testing.assert_allclose(c.overlap, r - dist, atol=ROUNDOFF)
    # particle 3 sits exactly on the face diagonal: the plane normal, overlap r
    normals = np.vstack([(x - feet)[:3] / dist[:3, None], [[0, 0, 1.0]]])
    np.testing.assert_allclose(c.normal, normals, atol=1e-12)
    assert c.feature[2] == mk.FEATURE_FACE


def test_tank_interior_one_face_contact_per_touched_wall():
    """Oracle: analytic planes. Inside a unit container box (2 triangles per wall), a sphere
    touches each wall at distance w < r with overlap r - w and nothing else: the contact count
    and the summed overlap equal the analytic ones for 20000 random spheres (1000 of them centred
    exactly above a wall diagonal, x = y), in corners (3 walls), along edges (2) and at faces."""
    tank = TriangleMesh.box((0, 0, 0), (1, 1, 1), inward=True)
    rng = np.random.default_rng(14)
    x = rng.uniform(0.0, 1.0, (20_000, 3))
    r = rng.uniform(0.05, 0.3, 20_000)
    x[:1000, 0] = x[:1000, 1]
    c = _contacts(tank, x, r)
    walls = np.concatenate([x, 1 - x], axis=1)
    touching = walls < r[:, None]
    np.testing.assert_array_equal(np.bincount(c.particle, minlength=x.shape[0]),
                                  touching.sum(axis=1))
    assert (touching.sum(axis=1) == 3).sum() > 100  # corners are exercised
    overlap = np.zeros(x.shape[0])
    np.add.at(overlap, c.particle, c.overlap)
    np.testing.assert_allclose(overlap, np.where(touching, r[:, None] - walls, 0).sum(axis=1),
                               atol=ROUNDOFF)
    assert (c.feature == mk.FEATURE_FACE).sum() > 0.9 * len(c)


def test_no_particles_or_none_near():
    """Edge cases: an empty particle set and a cloud far from the mesh give zero contacts."""
    mesh = TriangleMesh.box((0, 0, 0), (1, 1, 1))
    col = MeshCollider(mesh, 0.1)
    assert len(col.contacts(np.empty((0, 3)), np.empty(0))) == 0
    assert len(col.contacts(np.full((10, 3), 5.0), np.full(10, 0.1))) == 0
    with pytest.raises(ValueError, match=r"radius min=0.0: must be > 0 \[m\]"):
        col.contacts(np.zeros((2, 3)), np.array([0.1, 0.0]))


# --------------------------------------------------------------------------------------------
# curved surface: convergence to the analytic sphere
# --------------------------------------------------------------------------------------------


def test_icosphere_overlap_converges_order_two():
    """Oracle: analytic sphere-sphere overlap r + R - |x - X| for a particle pressed onto a
    sphere of radius R; the inscribed icosphere must give one contact per particle and a mean
    overlap error decreasing with observed order ~2 in the edge length (facet sagitta)."""
    big_r, r, delta = 1.0, 0.1, 0.05
    rng = np.random.default_rng(5)
    d = rng.normal(size=(1500, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    x = d * (big_r + r - delta)
    errs, hs = [], []
    for s in range(2, 7):
        mesh = TriangleMesh.icosphere(big_r, s)
        c = _contacts(mesh, x, r)
        np.testing.assert_array_equal(c.particle, np.arange(x.shape[0]))
        # the polyhedron is inside the sphere: the overlap can only be smaller
        assert (c.overlap <= delta + ROUNDOFF).all()
        errs.append(np.mean(delta - c.overlap))
        v0, v1, _ = mesh.corners()
        hs.append(np.linalg.norm(v1 - v0, axis=1).mean())
    errs, hs = np.array(errs), np.array(hs)
    rates = np.log(errs[:-1] / errs[1:]) / np.log(hs[:-1] / hs[1:])
    print("icosphere overlap error", errs, "rates", rates)
    assert (rates > 1.8).all() and (rates < 2.2).all(), rates


# --------------------------------------------------------------------------------------------
# broad phase, determinism, threads, output growth
# --------------------------------------------------------------------------------------------


def _wavy_mesh():
    """A 510-triangle non-flat open surface with irregular triangles."""
    m = TriangleMesh.plane_patch((1.0, 1.2), (15, 17))
    v = m.vertices.copy()
    rng = np.random.default_rng(6)
    v[:, :2] += rng.uniform(-0.015, 0.015, (v.shape[0], 2))
    v[:, 2] = 0.08 * np.sin(6 * v[:, 0]) * np.cos(5 * v[:, 1])
    return TriangleMesh(v, m.triangles)


def _cloud(n, seed, lo, hi, r_lo, r_hi):
    rng = np.random.default_rng(seed)
    return rng.uniform(lo, hi, (n, 3)), rng.uniform(r_lo, r_hi, n)


def test_broad_phase_equals_brute_force_and_is_deterministic():
    """Oracles: (1) brute force -- the same search with one grid cell, i.e. every particle
    against every triangle -- must give bit-identical arrays; (2) an independent numpy
    point-triangle distance: a particle has contacts iff its nearest distance is below r, and
    its largest overlap is r minus that distance; (3) 1 and 2 threads give identical bits."""
    mesh = _wavy_mesh()
    assert mesh.n_triangles == 510
    x, r = _cloud(2000, 7, [-0.55, -0.65, -0.12], [0.55, 0.65, 0.12], 0.01, 0.04)
    col = MeshCollider(mesh, 0.02)  # cell 0.04 < largest diameter: multi-cell queries too
    assert np.prod(col.grid_shape) > 100
    fine = col.contacts(x, r)
    brute_col = MeshCollider(mesh, 100.0)
    assert np.prod(brute_col.grid_shape) == 1
    brute = brute_col.contacts(x, r)
    for name in ("particle", "triangle", "feature", "normal", "overlap", "point"):
        np.testing.assert_array_equal(getattr(fine, name), getattr(brute, name), err_msg=name)
    # not vacuous: about 2 r_mean / slab thickness = 0.2 of the 2000 particles touch the surface,
    # and edge/vertex features (the de-duplication paths) occur
    assert len(fine) > 200
    assert (fine.feature != mk.FEATURE_FACE).sum() > 10
    d = _numpy_min_distance(x, mesh)
    hit = np.unique(fine.particle)
    np.testing.assert_array_equal(hit, np.flatnonzero(d < r))
    max_overlap = np.full(x.shape[0], -np.inf)
    np.maximum.at(max_overlap, fine.particle, fine.overlap)
    np.testing.assert_allclose(max_overlap[hit], (r - d)[hit], atol=ROUNDOFF)
    key = fine.particle.astype(np.int64) * mesh.n_triangles + fine.triangle
    assert (np.diff(key) > 0).all()  # sorted by particle, then triangle; no duplicates
    np.testing.assert_allclose(np.linalg.norm(fine.normal, axis=1), 1.0, atol=ROUNDOFF)
    threads = numba.get_num_threads()
    try:
        results = []
        for n in (1, min(2, numba.config.NUMBA_NUM_THREADS)):
            numba.set_num_threads(n)
            results.append(MeshCollider(mesh, 0.02).contacts(x, r))
    finally:
        numba.set_num_threads(threads)
    for name in ("particle", "triangle", "feature", "normal", "overlap", "point"):
        np.testing.assert_array_equal(getattr(results[0], name), getattr(results[1], name))
        np.testing.assert_array_equal(getattr(results[0], name), getattr(fine, name))


def test_body_frame_pose_equals_world_mesh():
    """Oracle: placing the body-frame grid with (R, X) must give the contacts of the mesh
    transformed to the world (same particle/triangle/feature sets, geometry to round-off)."""
    mesh = _wavy_mesh()
    rot, trans = _rotation(8), np.array([3.0, -2.0, 0.7])
    x_body, r = _cloud(1500, 9, [-0.55, -0.65, -0.12], [0.55, 0.65, 0.12], 0.01, 0.04)
    x = x_body @ rot.T + trans
    posed = MeshCollider(mesh, 0.04).contacts(x, r, rot, trans)
    world = MeshCollider(TriangleMesh(mesh.transformed(rot, trans), mesh.triangles),
                         0.04).contacts(x, r)
    one_shot = world_contacts(mesh, x, r, rot, trans)
    np.testing.assert_array_equal(one_shot.overlap, posed.overlap)  # grid-independent result
    np.testing.assert_array_equal(posed.particle, world.particle)
    np.testing.assert_array_equal(posed.triangle, world.triangle)
    np.testing.assert_allclose(posed.overlap, world.overlap, atol=1e-10)
    np.testing.assert_allclose(posed.normal, world.normal, atol=1e-8)
    np.testing.assert_allclose(posed.point, world.point, atol=1e-10)


def test_kernel_reports_overflow_without_writing():
    """Contract: with too-small output arrays the kernel returns the true count and writes
    nothing; the wrapper grows its buffers and returns every contact."""
    mesh = TriangleMesh.plane_patch((1.0, 1.0), (2, 2))
    col = MeshCollider(mesh, 0.05)
    x = np.column_stack([np.linspace(-0.4, 0.4, 50), np.zeros(50), np.full(50, 0.01)])
    r = np.full(50, 0.05)
    outs = [np.full(10, -7, np.int32), np.full(10, -7, np.int32), np.full(10, -7, np.int8),
            np.full((10, 3), -7.0), np.full(10, -7.0), np.full((10, 3), -7.0)]
    n = mk.mesh_contacts(x, r, np.eye(3), np.zeros(3), col.tri_v0, col.tri_v1, col.tri_v2,
                         col.grid_lo, col.cell_size, col.grid_shape, col.cell_start,
                         col.cell_tris, *outs)
    assert n == 50
    for o in outs:
        assert (o == -7).all()
    c = col.contacts(x, r)
    assert len(c) == 50


def test_spheres_touching_mesh_for_carving():
    """Oracle: analytic sphere; particles overlapping an icosphere's surface or with their
    centre inside are flagged (|x| < R + r, up to the facet sagitta band which is excluded)."""
    mesh = TriangleMesh.icosphere(0.5, 4)
    x, r = _cloud(3000, 10, -0.8, 0.8, 0.01, 0.03)
    rot, trans = _rotation(11), np.array([1.0, 2.0, 3.0])
    flagged = spheres_touching_mesh(mesh, x @ rot.T + trans, r, rot, trans)
    sagitta = 0.5 * (1 - np.cos(np.arccos(np.abs(np.einsum(
        "ij,ij->i", mesh.face_normals, mesh.corners()[0])).min() / 0.5)))
    dist = np.linalg.norm(x, axis=1)
    sure_in = dist < 0.5 + r - sagitta - 1e-9
    sure_out = dist > 0.5 + r + 1e-9
    # ball volume fraction 4/3 pi 0.5^3 / 1.6^3 = 0.13: ~380 sure inside; most sure outside
    assert sure_in.sum() > 300 and sure_out.sum() > 2000
    assert flagged[sure_in].all() and not flagged[sure_out].any()


def test_timing_50k_particles_2k_triangles():
    """Benchmark (print, not a speed assertion) of one contact search: 50k particles in a soil
    slab (half of them within reach) against a 2k-triangle closed mesh; the result is checked
    against an independent numpy nearest-distance oracle on a 500-particle sample."""
    # fuselage-like closed tube: 40 segments x 24 rings + 2 caps = 2000 triangles
    mesh = TriangleMesh.cylinder(0.3, -1.0, 1.0, segments=40, axial_divisions=24)
    assert mesh.n_triangles == 2000
    rot = np.array([[0.0, 0, 1], [0, 1, 0], [-1, 0, 0]])  # lying along x, like a fuselage
    x, r = _cloud(50_000, 12, [-1.2, -0.5, -0.4], [1.2, 0.5, 0.4], 0.008, 0.012)
    col = MeshCollider(mesh, 0.012)
    col.contacts(x, r, rot, np.zeros(3))  # warm-up (compilation is cached, buffers grown)
    t0 = time.perf_counter()
    repeats = 5
    for _ in range(repeats):
        c = col.contacts(x, r, rot, np.zeros(3))
    dt = (time.perf_counter() - t0) / repeats
    print(f"\nmesh_contacts: {x.shape[0]} particles x {mesh.n_triangles} triangles, "
          f"{len(c)} contacts, {numba.get_num_threads()} threads: {dt * 1e3:.2f} ms per call "
          f"({dt / x.shape[0] * 1e9:.1f} ns per particle)")
    sample = np.random.default_rng(13).choice(x.shape[0], 500, replace=False)
    d = _numpy_min_distance((x[sample]) @ rot, mesh)
    hit = np.isin(sample, c.particle)
    np.testing.assert_array_equal(hit, d < r[sample])
