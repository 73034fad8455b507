"""ParaView export: VTU + PVD and XDMF round trips read back with meshio, PVD XML validity,
impactor surface from stored poses, and clear errors.

Results are generated in code with ``ResultWriter`` (random radii, a rigid translation of the
bed over time, velocities, an octahedron "impactor" rotating about z).
"""
from __future__ import annotations

import xml.etree.ElementTree as ET

import h5py
import meshio
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from crashdem import export as ex
from crashdem import scenario as sc
from crashdem.results import ResultWriter, open_result

N = 57  # particles
TIMES = np.array([0.0, 0.0125, 0.025, 0.0375])  # [s] snapshot times
OCTA_V = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]],
                  dtype=float) * 0.45  # [m]
OCTA_T = np.array([[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4],
                   [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]])
#: float64 arithmetic of x_w = R x_b + p done in two orders (matrix product vs scipy apply):
#: agree to a few ulps of the 1 m coordinates
POSE_ATOL = 1e-14  # [m]


def _pose(k: int) -> tuple[np.ndarray, np.ndarray]:
    angle = 0.3 * k  # [rad] about z
    R = Rotation.from_euler("z", angle).as_matrix()
    p = np.array([0.1 * k, 0.0, 2.5 - 0.2 * k])
    return p, R


def _make_result(path, *, snapshots=True, velocities=True, body=True, layering=False,
                 with_scenario=True):
    rng = np.random.default_rng(7)
    x0 = rng.uniform(-1.0, 1.0, (N, 3))
    radius = rng.uniform(0.04, 0.06, N)
    v = np.tile([0.5, 0.0, -1.0], (N, 1)) + rng.normal(0, 0.01, (N, 3))
    kw = {}
    if with_scenario:
        kw["scenario"] = sc.loads("[physics.soil_layering]\nenabled = %s\n"
                                  % ("true" if layering else "false"))
    with ResultWriter(path, default_cfc=None, **kw) as w:
        if snapshots:
            w.declare_snapshots(radius, velocities=velocities)
            if body:
                ex.declare_body_surface(w, "drop_mass", OCTA_V, OCTA_T)
            for k, t in enumerate(TIMES):
                w.write_snapshot(t, x0 + t * v, v if velocities else None)
                if body:
                    ex.write_body_pose(w, "drop_mass", *_pose(k))
    return path


def test_vtu_round_trip_and_pvd(tmp_path):
    """Oracle: the result's own snapshots (``Result.snapshot``) and the analytic pose
    x_w = R x_b + p of the octahedron (scipy Rotation, independent of the exporter)."""
    res_path = _make_result(tmp_path / "run.h5")
    paths = ex.export_result(res_path, "vtu", tmp_path / "pv")
    pvd = paths[0]
    assert pvd.suffix == ".pvd" and all(p.exists() for p in paths)
    root = ET.parse(pvd).getroot()
    assert root.tag == "VTKFile" and root.get("type") == "Collection"
    sets = root.find("Collection").findall("DataSet")
    parts = {int(d.get("part")) for d in sets}
    assert parts == {0, 1}
    with open_result(res_path) as res:
        times = res.snapshot_times()
        p_sets = [d for d in sets if d.get("part") == "0"]
        assert [float(d.get("timestep")) for d in p_sets] == times.tolist()
        x_first = res.snapshot(0)["x"]
        for k, d in enumerate(p_sets):
            m = meshio.read(pvd.parent / d.get("file"))
            snap = res.snapshot(k)
            assert m.points.shape == (N, 3)
            assert m.cells[0].type == "vertex" and len(m.cells[0].data) == N
            np.testing.assert_array_equal(m.point_data["radius"], snap["radius"])
            np.testing.assert_array_equal(m.point_data["diameter"], 2 * snap["radius"])
            np.testing.assert_array_equal(m.points, snap["x"])
            np.testing.assert_array_equal(m.point_data["velocity"], snap["v"])
            np.testing.assert_array_equal(m.point_data["displacement"], snap["x"] - x_first)
            np.testing.assert_array_equal(m.point_data["material"], np.zeros(N))  # one material
        b_sets = [d for d in sets if d.get("part") == "1"]
        assert [float(d.get("timestep")) for d in b_sets] == times.tolist()
        for k, d in enumerate(b_sets):
            m = meshio.read(pvd.parent / d.get("file"))
            p, R = _pose(k)
            expected = Rotation.from_matrix(R).apply(OCTA_V) + p
            np.testing.assert_allclose(m.points, expected, rtol=0, atol=POSE_ATOL)
            np.testing.assert_array_equal(m.cells_dict["triangle"], OCTA_T)


def test_xdmf_round_trip(tmp_path):
    """Oracle: the result's snapshots. meshio's XDMF time-series reader returns the first
    geometry and each step's point data, so positions are checked as x0 + displacement, and
    each step's own geometry is read independently from the heavy-data file."""
    res_path = _make_result(tmp_path / "run.h5")
    paths = ex.export_result(res_path, "xdmf", tmp_path / "xd")
    xdmf = paths[0]
    assert xdmf.suffix == ".xdmf"
    assert (tmp_path / "xd" / "run_drop_mass.xdmf") in paths
    with open_result(res_path) as res, meshio.xdmf.TimeSeriesReader(xdmf) as reader:
        points, cells = reader.read_points_cells()
        assert points.shape == (N, 3) and cells[0].type == "vertex"
        assert reader.num_steps == TIMES.size
        x0 = res.snapshot(0)["x"]
        np.testing.assert_array_equal(points, x0)
        for k in range(reader.num_steps):
            t, pd, _ = reader.read_data(k)
            snap = res.snapshot(k)
            assert t == res.snapshot_times()[k]
            np.testing.assert_array_equal(pd["radius"], snap["radius"])
            np.testing.assert_array_equal(pd["velocity"], snap["v"])
            np.testing.assert_array_equal(x0 + pd["displacement"], snap["x"])
        grids = ET.parse(xdmf).getroot().find("Domain/Grid").findall("Grid")
        with h5py.File(paths[1], "r") as h:
            for k, g in enumerate(grids):
                fname, dset = g.find("Geometry/DataItem").text.split(":")
                assert fname == paths[1].name
                np.testing.assert_array_equal(h[dset][()], res.snapshot(k)["x"])
    with meshio.xdmf.TimeSeriesReader(paths[2]) as body:
        pts, cells = body.read_points_cells()
        np.testing.assert_allclose(pts, OCTA_V + _pose(0)[0], rtol=0, atol=POSE_ATOL)
        np.testing.assert_array_equal(cells[0].data, OCTA_T)


def test_every_and_missing_optional_data(tmp_path):
    """every=2 exports snapshots 0 and 2; without velocities, body poses or a single-material
    scenario, those arrays/parts are simply absent."""
    res_path = _make_result(tmp_path / "bare.h5", velocities=False, body=False, layering=True)
    paths = ex.export_result(res_path, "vtu", tmp_path / "pv", every=2)
    sets = ET.parse(paths[0]).getroot().find("Collection").findall("DataSet")
    assert [float(d.get("timestep")) for d in sets] == [TIMES[0], TIMES[2]]
    m = meshio.read(paths[0].parent / sets[1].get("file"))
    assert set(m.point_data) == {"radius", "diameter", "displacement"}


def test_stored_material_ids_are_exported(tmp_path):
    """``/snapshots/material`` when present is exported as is (oracle: the stored array)."""
    res_path = _make_result(tmp_path / "mat.h5", body=False, layering=True)
    mat = (np.arange(N) % 2).astype(np.int32)
    with h5py.File(res_path, "a") as f:
        f["snapshots"].create_dataset("material", data=mat)
    paths = ex.export_result(res_path, "vtu", tmp_path / "pv")
    m = meshio.read(paths[1])
    np.testing.assert_array_equal(m.point_data["material"], mat)


def test_result_without_snapshots_is_a_clear_error(tmp_path):
    res_path = _make_result(tmp_path / "nosnap.h5", snapshots=False)
    with pytest.raises(ValueError, match=r"no particle snapshots stored .*output\.snapshots"):
        ex.export_result(res_path, "vtu", tmp_path / "pv")
    assert not (tmp_path / "pv").exists()
    with pytest.raises(ValueError, match=r"export_result\.fmt='vtk'"):
        ex.export_result(res_path, "vtk")
    with pytest.raises(ValueError, match=r"export_result\.every=0"):
        ex.export_result(res_path, "vtu", every=0)


def test_cli_export(tmp_path, capsys):
    """``crashdem export RESULT.h5 --format xdmf --out DIR`` prints the written paths."""
    from crashdem.cli import main

    res_path = _make_result(tmp_path / "cli.h5", body=False)
    assert main(["export", str(res_path), "--format", "xdmf", "--out", str(tmp_path / "o")]) == 0
    out = capsys.readouterr().out.split()
    assert out[0].endswith("cli.xdmf")
    res_none = _make_result(tmp_path / "none.h5", snapshots=False)
    assert main(["export", str(res_none)]) == 2
    assert "no particle snapshots" in capsys.readouterr().err


def test_body_declaration_checks(tmp_path):
    with ResultWriter(tmp_path / "b.h5") as w:
        with pytest.raises(RuntimeError, match="declare_snapshots"):
            ex.declare_body_surface(w, "b", OCTA_V, OCTA_T)
        w.declare_snapshots(np.ones(3))
        with pytest.raises(ValueError, match=r"indices in \[0, 5\]"):
            ex.declare_body_surface(w, "b", OCTA_V, OCTA_T + 1)
        with pytest.raises(ValueError, match="body name 'a/b'"):
            ex.declare_body_surface(w, "a/b", OCTA_V, OCTA_T)
