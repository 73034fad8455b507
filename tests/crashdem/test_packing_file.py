"""A bed imported from a file (``soil.packing_file``, ``crashdem.beds``): the same bed gives the
same run as the deposited one, bit for bit; text and .npz read alike; layering by depth; bad
files and conflicting keys are refused with the field named."""
from pathlib import Path

import h5py
import numpy as np
import pytest

from crashdem import scenario as sc
from crashdem.beds import WALL_OVERLAP, imported_packing, read_bed
from crashdem.results import open_result
from crashdem.run import _container_top, packing_spec, run_scenario
from crashdem.scenario import ScenarioError
from soil import packing as pk

from test_run import TINY as RUN_TINY

ROOT = Path(__file__).resolve().parents[2]
SCEN = ROOT / "validation/scenarios/drop_s2_h5p00.toml"
#: test_run's tiny drop (a few hundred grains, 0.03 s), without snapshots
TINY = {**RUN_TINY, "output.snapshots": 0}
CHANNELS = ("drop_mass_accel_z", "drop_mass_velocity_z", "drop_mass_contact_force_z")


def _channels(path):
    with open_result(path) as res:
        return {c: np.asarray(res.channel(c, filtered=False).data) for c in CHANNELS}


def _scen(**kw):
    return sc.load(SCEN, {**TINY, **kw})


def test_imported_bed_reproduces_the_deposited_run(tmp_path):
    """The deposited bed written out and imported again is the same bed: the impact on it must
    match the deposited run to the last bit (any change of the grains' order, material, radius
    or position, or a bed re-settled on import, would show)."""
    scen = _scen()
    deposited = run_scenario(scen, out_dir=tmp_path / "dep", progress=False)
    bed = pk.cached(packing_spec(scen), tmp_path / "dep" / "packings")
    f = tmp_path / "bed.npz"
    np.savez(f, x=bed.x, radius=bed.radius)
    imported = run_scenario(_scen(**{"soil.packing_file": str(f)}), out_dir=tmp_path / "imp",
                            progress=False)
    a, b = _channels(deposited), _channels(imported)
    assert np.max(np.abs(a["drop_mass_contact_force_z"])) > 850 * 5 * 9.81  # a real impact
    for c in CHANNELS:
        assert np.array_equal(a[c], b[c]), c
    with h5py.File(imported) as h:
        info = dict(h["run"].attrs)
    assert info["packing_file"] == str(f)
    assert len(info["packing_file_sha256"]) == 64
    assert info["particles"] == len(bed.radius)


def test_text_rows_read_as_the_npz(tmp_path):
    """Yade's ``export.text`` layout (a '#format x_y_z_r' header, blank-separated) and a CSV
    give the arrays the .npz gives."""
    rng = np.random.default_rng(3)
    x = rng.uniform(-0.5, 0.5, (40, 3)) + [0.0, 0.0, 1.0]
    r = rng.uniform(0.05, 0.08, 40)
    np.savez(tmp_path / "b.npz", x=x, radius=r)
    rows = np.column_stack([x, r])
    np.savetxt(tmp_path / "b.txt", rows, fmt="%.17g", header="format x_y_z_r")
    np.savetxt(tmp_path / "b.csv", rows, fmt="%.17g", delimiter=",")
    for name in ("b.npz", "b.txt", "b.csv"):
        xi, ri = read_bed(tmp_path / name)
        assert np.array_equal(xi, x) and np.array_equal(ri, r), name


def test_layering_gives_the_lower_material_below_its_depth(tmp_path):
    z = np.linspace(0.1, 0.9, 9)
    x = np.column_stack([np.zeros(9), np.zeros(9), z])
    r = np.full(9, 0.05)
    np.savez(tmp_path / "b.npz", x=x, radius=r)
    scen = _scen(**{"soil.packing_file": str(tmp_path / "b.npz"),
                    "physics.soil_layering.enabled": True,
                    "physics.soil_layering.depth": 0.3})
    p = imported_packing(scen, packing_spec(scen), _container_top(scen))
    top = 0.95
    assert p.material.tolist() == [1 if zi < top - 0.3 else 0 for zi in z]
    assert p.materials[1].young == pytest.approx(
        p.materials[0].young * scen["physics.soil_layering.lower_young_factor"])


def _refused(tmp_path, x, r, match, **kw):
    f = tmp_path / "b.npz"
    np.savez(f, x=np.asarray(x, float), radius=np.asarray(r, float))
    scen = _scen(**{"soil.packing_file": str(f), **kw})
    with pytest.raises(ScenarioError, match=match) as e:
        imported_packing(scen, packing_spec(scen), _container_top(scen))
    assert "soil.packing_file" in str(e.value) or "floor_depth" in str(e.value)
    return str(e.value)


def test_grains_outside_the_container_are_refused(tmp_path):
    R = 0.65  # container.diameter / 2
    ok = [[0.0, 0.0, 0.1]]
    # a grain pressing the wall by less than WALL_OVERLAP of its radius is a settled bed's
    f = tmp_path / "edge.npz"
    np.savez(f, x=np.array([[R - 0.1 + 0.5 * WALL_OVERLAP * 0.1, 0.0, 0.1]]), radius=[0.1])
    scen = _scen(**{"soil.packing_file": str(f)})
    assert imported_packing(scen, packing_spec(scen), _container_top(scen)).x.shape == (1, 3)
    msg = _refused(tmp_path, ok + [[R, 0.0, 0.5]], [0.05, 0.05], "outside the tank wall")
    assert "grain 1 of 2" in msg and "container.diameter/2 = 0.65" in msg
    _refused(tmp_path, ok + [[0.0, 0.0, 0.01]], [0.05, 0.05], "below the floor")
    _refused(tmp_path, ok + [[0.0, 0.0, 10.0]], [0.05, 0.05], "above the container's top")
    _refused(tmp_path, ok + [[0.0, 1.0, 0.3]], [0.05, 0.05], "outside the box",
             **{"container.shape": "box", "container.length": 1.0, "container.width": 1.0})


def test_bad_files_and_keys_are_refused(tmp_path):
    _refused(tmp_path, [[0.0, 0.0, 0.1]], [0.0], "radii > 0")
    _refused(tmp_path, [[0.0, 0.0, np.nan]], [0.05], "must be finite")
    _refused(tmp_path, [[0.0, 0.0, 0.1]], [0.05], "floor_depth.*allowed: null",
             **{"physics.boundary_proximity.enabled": True,
                "physics.boundary_proximity.floor_depth": 0.3})
    with pytest.raises(ScenarioError, match="soil.packing_file.*no such file"):
        read_bed(tmp_path / "none.npz")
    (tmp_path / "three.txt").write_text("# x y z\n0 0 0.1\n")
    with pytest.raises(ScenarioError, match="3 columns; each row must be 'x y z r'"):
        read_bed(tmp_path / "three.txt")
    np.savez(tmp_path / "nox.npz", centres=np.zeros((1, 3)), radius=[0.1])
    with pytest.raises(ScenarioError, match="no array 'x'"):
        read_bed(tmp_path / "nox.npz")
    np.savez(tmp_path / "shape.npz", x=np.zeros((2, 2)), radius=[0.1, 0.1])
    with pytest.raises(ScenarioError, match=r"x must be \(N, 3\)"):
        read_bed(tmp_path / "shape.npz")


def test_the_glider_refuses_an_imported_bed(tmp_path):
    from crashdem.run import build_model

    scen = sc.load(ROOT / "validation/scenarios/glider_real.toml",
                   {"soil.packing_file": str(tmp_path / "b.npz")})
    with pytest.raises(ScenarioError, match="soil.packing_file.*drop_test' only"):
        build_model(scen, tmp_path)
