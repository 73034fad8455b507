"""Triangle surface meshes of the bodies: generation, mass properties, file I/O (meshio)."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def icosphere(radius: float, subdivisions: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """Triangulated sphere by recursive subdivision of an icosahedron.

    Parameters
    ----------
    radius : float
        [m], > 0.
    subdivisions : int
        Number of 1-to-4 subdivisions (0 gives 20 triangles, each level x4).

    Returns
    -------
    vertices : numpy.ndarray, shape (V, 3)
        On the sphere, centred on the origin [m].
    triangles : numpy.ndarray, shape (T, 3)
        Counter-clockwise seen from outside (outward normals).
    """
    if not radius > 0.0:
        raise ValueError(f"icosphere.radius={radius!r}: must be > 0 [m]")
    if subdivisions < 0 or subdivisions > 6:
        raise ValueError(f"icosphere.subdivisions={subdivisions!r}: must be in [0, 6]")
    p = (1.0 + 5.0**0.5) / 2.0
    verts = [
        (-1, p, 0), (1, p, 0), (-1, -p, 0), (1, -p, 0),
        (0, -1, p), (0, 1, p), (0, -1, -p), (0, 1, -p),
        (p, 0, -1), (p, 0, 1), (-p, 0, -1), (-p, 0, 1),
    ]
    faces = [
        (0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11),
        (1, 5, 9), (5, 11, 4), (11, 10, 2), (10, 7, 6), (7, 1, 8),
        (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9),
        (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1),
    ]
    v = [np.array(x, dtype=float) / np.linalg.norm(x) for x in verts]
    for _ in range(subdivisions):
        cache: dict[tuple[int, int], int] = {}

        def mid(a, b):
            key = (a, b) if a < b else (b, a)
            if key not in cache:
                m = v[a] + v[b]
                v.append(m / np.linalg.norm(m))
                cache[key] = len(v) - 1
            return cache[key]

        new = []
        for a, b, c in faces:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            new += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = new
    return radius * np.array(v), np.array(faces, dtype=np.int32)


def triangle_areas(vertices, triangles) -> np.ndarray:
    """Area of each triangle [m^2]."""
    v = np.asarray(vertices, dtype=float)
    t = np.asarray(triangles)
    e1 = v[t[:, 1]] - v[t[:, 0]]
    e2 = v[t[:, 2]] - v[t[:, 0]]
    return 0.5 * np.linalg.norm(np.cross(e1, e2), axis=1)


def shell_mass_properties(vertices, triangles, areal_density: float):
    """Mass, CG and inertia about the CG of a thin shell of uniform areal density.

    Parameters
    ----------
    vertices : array_like, shape (V, 3)
        [m]
    triangles : array_like, shape (T, 3)
    areal_density : float
        [kg/m^2], > 0.

    Returns
    -------
    mass : float
        [kg]
    cg : numpy.ndarray, shape (3,)
        [m]
    inertia : numpy.ndarray, shape (3, 3)
        About the CG [kg m^2].

    Notes
    -----
    Exact integrals over a flat triangle of area A with vertices a, b, c:
    ``int x dA = A (a+b+c)/3`` and
    ``int x x^T dA = A/12 (a a^T + b b^T + c c^T + s s^T)`` with ``s = a+b+c``
    (second moment of a triangle, e.g. Eberly, *Polyhedral Mass Properties*, 2002,
    surface version); the inertia follows from ``J = tr(C) I - C``.
    """
    if not areal_density > 0.0:
        raise ValueError(f"areal_density={areal_density!r}: must be > 0 [kg/m^2]")
    v = np.asarray(vertices, dtype=float)
    t = np.asarray(triangles)
    a, b, c = v[t[:, 0]], v[t[:, 1]], v[t[:, 2]]
    area = triangle_areas(v, t)
    s = a + b + c
    mass = areal_density * area.sum()
    first = areal_density * (area[:, None] * s / 3.0).sum(axis=0)
    cg = first / mass
    second = np.zeros((3, 3))
    for p in (a, b, c, s):
        second += np.einsum("k,ki,kj->ij", area, p, p)
    second *= areal_density / 12.0
    second_cg = second - mass * np.outer(cg, cg)
    inertia = np.trace(second_cg) * np.eye(3) - second_cg
    return float(mass), cg, inertia


def enclosed_volume(vertices, triangles) -> float:
    """Volume enclosed by a closed, outward-oriented triangle mesh [m^3].

    Notes
    -----
    Divergence theorem: ``V = sum_T (a . (b x c)) / 6``.
    """
    v = np.asarray(vertices, dtype=float)
    t = np.asarray(triangles)
    return float(np.einsum("ij,ij->i", v[t[:, 0]], np.cross(v[t[:, 1]], v[t[:, 2]])).sum() / 6.0)


def loft_fuselage(
    length: float = 2.3,
    width: float = 0.6,
    height: float = 0.8,
    nose_length: float = 0.7,
    n_stations: int = 28,
    n_around: int = 32,
    aft_taper: float = 0.85,
    nose_droop: float = 0.0,
):
    """Parametric fuselage surface: a lofted body of elliptic sections with a blunt round nose.

    Construction frame: origin at the nose tip, x forward (the body lies at x in
    [-length, 0]), y to the left, z up; the section centres lie on the x axis.

    Parameters
    ----------
    length : float
        Nose-to-cut length [m].
    width, height : float
        Maximum full width and height of the sections [m].
    nose_length : float
        Length of the elliptic nose [m]; the semi-axes grow as ``sqrt(1 - (1 - s/L_n)^2)``
        (an ellipsoidal, blunt rounded nose).
    n_stations : int
        Number of stations along the body (>= 4).
    n_around : int
        Number of points around each section (>= 8).
    aft_taper : float
        Ratio of the section size at the cut to the maximum section (0 < r <= 1); the
        section shrinks linearly from the end of the nose to the cut.
    nose_droop : float
        Asymmetry of the nose in side view, in [0, 1]: the section centres of the nose lie
        ``nose_droop * height/2 * (1 - f)`` below the axis (``f`` the nose's section scale), so
        the nose tip is ``nose_droop * height/2`` below the axis. 0 = symmetric nose (tip on
        the axis); 1 = straight floor line up to the tip (the whole nose curvature on the
        upper, canopy side), as on a glider whose lower contour runs straight to the nose.

    Returns
    -------
    vertices : numpy.ndarray, shape (V, 3)
        [m]
    triangles : numpy.ndarray, shape (T, 3)
        Outward oriented; the shell is closed by a flat cap at the cut.
    is_cap : numpy.ndarray of bool, shape (T,)
        True for the triangles of the flat cap (the mold cut, not laminated).
    """
    for name, val in (("length", length), ("width", width), ("height", height),
                      ("nose_length", nose_length)):
        if not val > 0.0:
            raise ValueError(f"loft_fuselage.{name}={val!r}: must be > 0 [m]")
    if nose_length >= length:
        raise ValueError(f"loft_fuselage.nose_length={nose_length}: must be < length={length} [m]")
    if not 0.0 < aft_taper <= 1.0:
        raise ValueError(f"loft_fuselage.aft_taper={aft_taper!r}: must be in (0, 1]")
    if not (np.isfinite(nose_droop) and 0.0 <= nose_droop <= 1.0):
        raise ValueError(f"loft_fuselage.nose_droop={nose_droop!r}: must be in [0, 1] [-]")
    if n_stations < 4 or n_around < 8:
        raise ValueError(
            f"loft_fuselage: n_stations={n_stations} must be >= 4 and n_around={n_around} >= 8"
        )
    # stations: cosine-clustered on the nose (curvature), uniform behind it
    n_nose = max(3, n_stations // 2)
    u = 0.5 * (1.0 - np.cos(np.linspace(0.0, np.pi, n_nose + 1)))[1:]
    s_nose = nose_length * u
    s_aft = np.linspace(nose_length, length, n_stations - n_nose + 1)[1:]
    s = np.concatenate([s_nose, s_aft])
    scale = np.where(
        s <= nose_length,
        np.sqrt(np.clip(1.0 - (1.0 - s / nose_length) ** 2, 0.0, 1.0)),
        1.0 - (1.0 - aft_taper) * (s - nose_length) / (length - nose_length),
    )
    phi = np.linspace(0.0, 2.0 * np.pi, n_around, endpoint=False)
    # section centres below the axis on the nose (nose_droop), on the axis behind it
    zc = np.where(s <= nose_length, -nose_droop * 0.5 * height * (1.0 - scale), 0.0)
    verts = [np.array([0.0, 0.0, 0.0 - nose_droop * 0.5 * height])]  # nose tip
    for sk, fk, zk in zip(s, scale, zc):
        ring = np.stack(
            [np.full(n_around, -sk), 0.5 * width * fk * np.cos(phi),
             zk + 0.5 * height * fk * np.sin(phi)],
            axis=1,
        )
        verts.extend(ring)
    verts.append(np.array([-length, 0.0, 0.0]))  # cap centre
    v = np.array(verts)
    tris = []
    ring0 = 1
    for j in range(n_around):  # nose fan
        tris.append((0, ring0 + (j + 1) % n_around, ring0 + j))
    for k in range(len(s) - 1):
        a0 = 1 + k * n_around
        b0 = a0 + n_around
        for j in range(n_around):
            j1 = (j + 1) % n_around
            tris.append((a0 + j, a0 + j1, b0 + j1))
            tris.append((a0 + j, b0 + j1, b0 + j))
    n_lateral = len(tris)
    last = 1 + (len(s) - 1) * n_around
    centre = len(v) - 1
    for j in range(n_around):  # cap fan
        tris.append((centre, last + j, last + (j + 1) % n_around))
    t = np.array(tris, dtype=np.int32)
    is_cap = np.zeros(len(t), dtype=bool)
    is_cap[n_lateral:] = True
    # orient outward: the enclosed volume must be positive
    if enclosed_volume(v, t) < 0.0:
        t = t[:, ::-1].copy()
    return v, t, is_cap


def write_mesh(path, vertices, triangles) -> None:
    """Write a triangle mesh with meshio (format from the extension: .stl, .obj, .vtk, ...).

    STL files are written binary (float32 coordinates: ~1e-7 relative precision).
    """
    import meshio

    mesh = meshio.Mesh(np.asarray(vertices, float), [("triangle", np.asarray(triangles))])
    if str(path).lower().endswith(".stl"):
        meshio.write(str(path), mesh, binary=True)
    else:
        meshio.write(str(path), mesh)


def read_mesh(path, scale: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Read a triangle surface mesh with meshio and scale it to metres.

    Parameters
    ----------
    path : str or Path
        STL, OBJ, or any format meshio reads.
    scale : float
        Factor from the file's length unit to metres (1e-3 for a file in mm).

    Returns
    -------
    vertices : numpy.ndarray, shape (V, 3)
        [m]
    triangles : numpy.ndarray, shape (T, 3)

    Raises
    ------
    ValueError
        If the file holds no triangles or ``scale`` is not > 0.
    """
    import meshio

    if not scale > 0.0:
        raise ValueError(f"read_mesh.scale={scale!r}: must be > 0 [m per file unit]")
    path = Path(path)
    # meshio's STL sniffing multiplies a uint32 header count and overflows harmlessly on
    # ASCII files (numpy >= 2 warns); the overflow only selects the ASCII branch.
    with np.errstate(over="ignore"):
        m = meshio.read(str(path))
    tri = [c.data for c in m.cells if c.type == "triangle"]
    if not tri:
        raise ValueError(f"{path}: no triangle cells (found {[c.type for c in m.cells]})")
    t = np.concatenate(tri).astype(np.int32)
    v = np.asarray(m.points, dtype=float)[:, :3] * scale
    # STL repeats vertices per facet: merge exact duplicates so edges are shared
    v_unique, inverse = np.unique(v, axis=0, return_inverse=True)
    return v_unique, inverse.reshape(-1)[t].astype(np.int32)
