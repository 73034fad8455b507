"""ParaView export of a result's particle snapshots (and impactor surface, when stored).

API
---
``export_result(path, fmt="vtu"|"xdmf", out=None, every=1) -> list[Path]``
    ``vtu``: one VTU file per snapshot (point cloud, ``vertex`` cells) plus a ``.pvd``
    collection listing them with their times (the first path returned);
    ``xdmf``: one XDMF 3 temporal collection (the first path returned) whose heavy data is in
    a companion HDF5 file; the impactor, if stored, gets its own ``<stem>_<body>.xdmf``.
``declare_body_surface(writer, name, vertices, triangles)`` and
``write_body_pose(writer, name, position, rotation)``: store an impactor surface and its pose
    with each particle snapshot of a ``crashdem.results.ResultWriter`` (call ``write_body_pose``
    right after each ``write_snapshot``), so that the export can show the body.

Point data of the particles (per snapshot):

============== ======= =======================================================================
name           unit    content
============== ======= =======================================================================
radius         m       particle radius (``/snapshots/radius``)
diameter       m       2 radius: the Glyph scale array for ParaView's default sphere (radius 0.5)
material       1       material index: ``/snapshots/material`` when stored; all 0 when the
                       scenario has a single soil material (layering off); absent otherwise
velocity       m/s     when the snapshots store velocities (``declare_snapshots(velocities=True)``)
speed          m/s     |velocity|
displacement   m       x - x(first exported snapshot): crater and bulging at a glance
============== ======= =======================================================================

Layout of the optional body data in the result (written by the two helpers above)::

    /snapshots/bodies/<name>/vertices   (V, 3) float64  body frame (origin at the CG) [m]
    /snapshots/bodies/<name>/triangles  (T, 3) int32
    /snapshots/bodies/<name>/position   (S, 3) float64  CG, world frame, one row per snapshot [m]
    /snapshots/bodies/<name>/rotation   (S, 3, 3)       body-to-world rotation matrix, per snapshot

World vertices: ``x_w = R x_b + p`` (body-to-world rotation, as ``soil.BoundaryBody.rotation``).

Notes
-----
VTK file formats: Kitware, "VTK File Formats" (XML VTU/PVD, ``Collection`` with ``timestep`` and
``part`` attributes). XDMF 3: xdmf.org "XDMF Model and Format" (Temporal collection, Polyvertex
topology, HDF heavy data). Files written with meshio (VTU) and ElementTree + h5py (PVD, XDMF).
"""
from __future__ import annotations

import logging
import os
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import h5py
import numpy as np

__all__ = ["FORMATS", "declare_body_surface", "export_result", "write_body_pose"]

log = logging.getLogger("crashdem.export")

FORMATS = ("vtu", "xdmf")


# --------------------------------------------------------------------------------------------
# writing the body pose with the snapshots (used by the run loop)
# --------------------------------------------------------------------------------------------
def _body_group_name(name: str) -> str:
    if not name or "/" in name:
        raise ValueError(f"body name {name!r}: must be non-empty without '/'")
    return name


def declare_body_surface(writer: Any, name: str, vertices: np.ndarray,
                         triangles: np.ndarray) -> None:
    """Store a body's surface mesh (body frame) in a result, for the ParaView export.

    Parameters
    ----------
    writer : ``crashdem.results.ResultWriter`` with snapshots declared
    name : body name (e.g. ``"drop_mass"``)
    vertices : (V, 3) vertices in the body frame, origin at the CG [m]
        (``bodies.RigidBodySpec.vertices``)
    triangles : (T, 3) vertex indices (``bodies.RigidBodySpec.triangles``)
    """
    name = _body_group_name(name)
    f = writer._f
    if "snapshots" not in f:
        raise RuntimeError("declare_body_surface: call writer.declare_snapshots(radius) first")
    v = np.asarray(vertices, dtype=float)
    tri = np.asarray(triangles)
    if v.ndim != 2 or v.shape[1] != 3 or v.shape[0] < 3 or not np.isfinite(v).all():
        raise ValueError(f"declare_body_surface({name!r}): vertices shape {v.shape}, must be "
                         "(V>=3, 3), finite [m]")
    if tri.ndim != 2 or tri.shape[1] != 3 or tri.size == 0 or tri.min() < 0 \
            or tri.max() >= v.shape[0]:
        raise ValueError(f"declare_body_surface({name!r}): triangles shape {tri.shape} must be "
                         f"(T>=1, 3) with indices in [0, {v.shape[0] - 1}]")
    g = f["snapshots"].require_group("bodies").create_group(name)
    d = g.create_dataset("vertices", data=v)
    d.attrs["unit"] = "m"
    d.attrs["frame"] = "body"
    d = g.create_dataset("triangles", data=tri.astype(np.int32))
    d.attrs["unit"] = "1"
    d = g.create_dataset("position", shape=(0, 3), maxshape=(None, 3), chunks=(64, 3),
                         dtype="f8")
    d.attrs["unit"] = "m"
    d = g.create_dataset("rotation", shape=(0, 3, 3), maxshape=(None, 3, 3), chunks=(64, 3, 3),
                         dtype="f8")
    d.attrs["unit"] = "1"
    f.flush()


def write_body_pose(writer: Any, name: str, position: np.ndarray, rotation: np.ndarray) -> None:
    """Append the body pose of the snapshot just written (``writer.write_snapshot``).

    Parameters
    ----------
    position : (3,) CG position in the world frame [m]
    rotation : (3, 3) body-to-world rotation matrix
    """
    g = writer._f["snapshots"]["bodies"][_body_group_name(name)]
    p = np.asarray(position, dtype=float).reshape(3)
    r = np.asarray(rotation, dtype=float).reshape(3, 3)
    k = g["position"].shape[0]
    g["rotation"].resize((k + 1, 3, 3))
    g["rotation"][k] = r
    g["position"].resize((k + 1, 3))
    g["position"][k] = p
    writer._f.flush()


# --------------------------------------------------------------------------------------------
# reading what the result holds
# --------------------------------------------------------------------------------------------
def _material(res: Any, n: int) -> np.ndarray | None:
    g = res._f["snapshots"]
    if "material" in g:
        return np.asarray(g["material"][:], dtype=np.int32)
    try:
        params = res.parameters
        layering = params.get("physics", {}).get("soil_layering", {}).get("enabled", None)
    except (KeyError, AttributeError):
        layering = None
    if layering is False:  # one soil material: every particle is material 0
        return np.zeros(n, dtype=np.int32)
    log.info("%s: no /snapshots/material and the scenario has several soil materials: the "
             "material id is not exported", res.path)
    return None


def _bodies(res: Any, n_snap: int) -> dict[str, dict[str, np.ndarray]]:
    g = res._f["snapshots"]
    out: dict[str, dict[str, np.ndarray]] = {}
    if "bodies" not in g:
        log.info("%s: no /snapshots/bodies: the impactor surface is not exported (the result "
                 "stores no body pose per snapshot)", res.path)
        return out
    for name, b in g["bodies"].items():
        k = min(b["position"].shape[0], b["rotation"].shape[0], n_snap)
        out[name] = {"vertices": b["vertices"][:], "triangles": b["triangles"][:].astype(np.int64),
                     "position": b["position"][:k], "rotation": b["rotation"][:k]}
    return out


def _frames(res: Any, every: int) -> tuple[np.ndarray, list[int]]:
    times = res.snapshot_times()
    if times.size == 0:
        raise ValueError(f"{res.path}: no particle snapshots stored (/snapshots missing or "
                         "empty); run the scenario with output.snapshots = N > 0 to export it")
    idx = list(range(0, times.size, every))
    return times, idx


def _point_data(snap: dict[str, Any], x_ref: np.ndarray, material: np.ndarray | None
                ) -> dict[str, np.ndarray]:
    r = np.asarray(snap["radius"], dtype=float)
    pd = {"radius": r, "diameter": 2.0 * r}
    if material is not None:
        pd["material"] = material
    if snap["v"] is not None:
        pd["velocity"] = snap["v"]
        pd["speed"] = np.linalg.norm(snap["v"], axis=1)
    pd["displacement"] = snap["x"] - x_ref
    return pd


def _world_vertices(body: dict[str, np.ndarray], k: int) -> np.ndarray:
    return body["vertices"] @ body["rotation"][k].T + body["position"][k]


# --------------------------------------------------------------------------------------------
# export
# --------------------------------------------------------------------------------------------
def export_result(path: str | os.PathLike, fmt: str = "vtu", out: str | os.PathLike | None = None,
                  every: int = 1) -> list[Path]:
    """Export a result's particle snapshots for ParaView.

    Parameters
    ----------
    path : crashdem HDF5 result with ``/snapshots`` (``output.snapshots > 0``)
    fmt : "vtu" (VTU files + ``.pvd`` collection) or "xdmf" (XDMF 3 + HDF5 heavy data)
    out : output directory (default: ``<result without .h5>_paraview/``)
    every : export every ``every``-th snapshot (>= 1)

    Returns
    -------
    paths written; the first is the file to open in ParaView (``.pvd`` or ``.xdmf``)

    Raises
    ------
    ValueError : unknown format, ``every < 1``, or a result without snapshots
    """
    from crashdem.results import open_result

    if fmt not in FORMATS:
        raise ValueError(f"export_result.fmt={fmt!r}: must be one of {FORMATS}")
    if not (isinstance(every, int) and every >= 1):
        raise ValueError(f"export_result.every={every!r}: must be an int >= 1")
    path = Path(path)
    out_dir = Path(out) if out is not None else path.with_name(path.stem + "_paraview")
    with open_result(path) as res:
        times, idx = _frames(res, every)
        out_dir.mkdir(parents=True, exist_ok=True)
        if fmt == "vtu":
            return _export_vtu(res, path.stem, out_dir, times, idx)
        return _export_xdmf(res, path.stem, out_dir, times, idx)


def _export_vtu(res: Any, stem: str, out_dir: Path, times: np.ndarray, idx: list[int]
                ) -> list[Path]:
    import meshio

    written: list[Path] = []
    snap0 = res.snapshot(idx[0])
    n = snap0["x"].shape[0]
    material = _material(res, n)
    bodies = _bodies(res, times.size)
    vertex_cells = [("vertex", np.arange(n, dtype=np.int64)[:, None])]
    collection: list[tuple[float, int, str]] = []
    width = max(4, len(str(times.size - 1)))
    for k in idx:
        snap = snap0 if k == idx[0] else res.snapshot(k)
        fname = f"{stem}_particles_{k:0{width}d}.vtu"
        mesh = meshio.Mesh(snap["x"], vertex_cells,
                           point_data=_point_data(snap, snap0["x"], material))
        meshio.write(out_dir / fname, mesh, file_format="vtu")
        written.append(out_dir / fname)
        collection.append((float(times[k]), 0, fname))
        for part, (name, body) in enumerate(bodies.items(), start=1):
            if k >= body["position"].shape[0]:
                continue
            bname = f"{stem}_{name}_{k:0{width}d}.vtu"
            meshio.write(out_dir / bname,
                         meshio.Mesh(_world_vertices(body, k), [("triangle", body["triangles"])]),
                         file_format="vtu")
            written.append(out_dir / bname)
            collection.append((float(times[k]), part, bname))
    pvd = out_dir / f"{stem}.pvd"
    _write_pvd(pvd, collection, ["particles", *bodies])
    return [pvd, *written]


def _write_pvd(path: Path, collection: list[tuple[float, int, str]], parts: list[str]) -> None:
    root = ET.Element("VTKFile", type="Collection", version="0.1", byte_order="LittleEndian")
    root.append(ET.Comment(" crashdem particle snapshots; parts: "
                           + ", ".join(f"{i} = {p}" for i, p in enumerate(parts)) + " "))
    col = ET.SubElement(root, "Collection")
    for t, part, fname in collection:
        # repr(float) round-trips the float64 time exactly
        ET.SubElement(col, "DataSet", timestep=repr(t), group="", part=str(part), file=fname)
    ET.indent(root)
    ET.ElementTree(root).write(path, encoding="utf-8", xml_declaration=True)


def _data_item(parent: ET.Element, h5name: str, dset: str, shape: tuple[int, ...],
               dtype: np.dtype) -> ET.Element:
    kind = "Int" if np.issubdtype(dtype, np.integer) else "Float"
    item = ET.SubElement(parent, "DataItem", DataType=kind,
                         Dimensions=" ".join(str(s) for s in shape), Format="HDF",
                         Precision=str(np.dtype(dtype).itemsize))
    item.text = f"{h5name}:{dset}"
    return item


_ATTR_TYPE = {1: "Scalar", 3: "Vector"}


def _export_xdmf(res: Any, stem: str, out_dir: Path, times: np.ndarray, idx: list[int]
                 ) -> list[Path]:
    heavy = out_dir / f"{stem}_xdmf.h5"
    xdmf = out_dir / f"{stem}.xdmf"
    snap0 = res.snapshot(idx[0])
    n = snap0["x"].shape[0]
    material = _material(res, n)
    bodies = _bodies(res, times.size)
    written = [xdmf, heavy]

    def document(name: str) -> tuple[ET.Element, ET.Element]:
        root = ET.Element("Xdmf", Version="3.0")
        dom = ET.SubElement(root, "Domain")
        col = ET.SubElement(dom, "Grid", Name=name, GridType="Collection",
                            CollectionType="Temporal")
        return root, col

    root, col = document("particles")
    with h5py.File(heavy, "w") as h:
        h.attrs["source"] = str(res.path)
        conn = h.create_dataset("particles/connectivity",
                                data=np.arange(n, dtype=np.int64)[:, None])
        static: dict[str, np.ndarray] = {}
        for k in idx:
            snap = snap0 if k == idx[0] else res.snapshot(k)
            pd = _point_data(snap, snap0["x"], material)
            grid = ET.SubElement(col, "Grid", Name=f"particles_{k}", GridType="Uniform")
            ET.SubElement(grid, "Time", Value=repr(float(times[k])))
            topo = ET.SubElement(grid, "Topology", TopologyType="Polyvertex",
                                 NumberOfElements=str(n), NodesPerElement="1")
            _data_item(topo, heavy.name, "/particles/connectivity", (n, 1), conn.dtype)
            geo = ET.SubElement(grid, "Geometry", GeometryType="XYZ")
            d = h.create_dataset(f"particles/x/{k}", data=snap["x"])
            d.attrs["unit"] = "m"
            _data_item(geo, heavy.name, d.name, (n, 3), d.dtype)
            for name, arr in pd.items():
                if name in ("radius", "diameter", "material"):  # constant: stored once
                    if name not in static:
                        static[name] = arr
                        h.create_dataset(f"particles/{name}", data=arr)
                    dname = f"/particles/{name}"
                else:
                    h.create_dataset(f"particles/{name}/{k}", data=arr)
                    dname = f"/particles/{name}/{k}"
                a = ET.SubElement(grid, "Attribute", Name=name,
                                  AttributeType=_ATTR_TYPE[1 if arr.ndim == 1 else 3],
                                  Center="Node")
                _data_item(a, heavy.name, dname, arr.shape, arr.dtype)
        body_docs = []
        for name, body in bodies.items():
            broot, bcol = document(name)
            tri = h.create_dataset(f"bodies/{name}/triangles", data=body["triangles"])
            nv, nt = body["vertices"].shape[0], body["triangles"].shape[0]
            for k in idx:
                if k >= body["position"].shape[0]:
                    continue
                grid = ET.SubElement(bcol, "Grid", Name=f"{name}_{k}", GridType="Uniform")
                ET.SubElement(grid, "Time", Value=repr(float(times[k])))
                topo = ET.SubElement(grid, "Topology", TopologyType="Triangle",
                                     NumberOfElements=str(nt))
                _data_item(topo, heavy.name, tri.name, (nt, 3), tri.dtype)
                geo = ET.SubElement(grid, "Geometry", GeometryType="XYZ")
                d = h.create_dataset(f"bodies/{name}/x/{k}", data=_world_vertices(body, k))
                _data_item(geo, heavy.name, d.name, (nv, 3), d.dtype)
            body_docs.append((out_dir / f"{stem}_{name}.xdmf", broot))
    for p, r in [(xdmf, root), *body_docs]:
        ET.indent(r)
        ET.ElementTree(r).write(p, encoding="utf-8", xml_declaration=True)
    written += [p for p, _ in body_docs]
    return written
