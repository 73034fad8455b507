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
    """On an imported bed the depth counts from the bed's free surface (``beds.free_surface``),
    not from its highest grain: a grain standing on top of a regular bed of four tiers moves
    the highest top by a diameter and the interface not at all; a bed too small to show a
    surface is refused, naming the field."""
    from crashdem.beds import free_surface

    r0 = 0.05
    g = np.arange(-0.4, 0.4 + 1e-9, 2 * r0)
    xx, yy, zz = np.meshgrid(g, g, r0 + 2 * r0 * np.arange(4), indexing="ij")
    x = np.column_stack([xx.ravel(), yy.ravel(), zz.ravel()])  # tiers' top at 0.4 m
    x = np.vstack([x, [[0.0, 0.0, 0.4 + r0]]])  # one grain standing on the top tier
    r = np.full(len(x), r0)
    np.savez(tmp_path / "b.npz", x=x, radius=r)
    scen = _scen(**{"soil.packing_file": str(tmp_path / "b.npz"),
                    "physics.soil_layering.enabled": True,
                    "physics.soil_layering.depth": 0.15})
    surface = free_surface(scen, x, r)
    assert surface == pytest.approx(0.4, abs=0.5 * r0)
    p = imported_packing(scen, packing_spec(scen), _container_top(scen))
    assert p.material.tolist() == [1 if zi < surface - 0.15 else 0 for zi in x[:, 2]]
    assert 0 < int(np.sum(p.material)) < len(x)
    # the two lowest tiers (centres 0.05, 0.15 m) are below 0.4 - 0.15 = 0.25 m; the highest
    # top (0.5 m) would also have put the third tier (0.25 m) below its 0.35 m
    assert set(np.round(x[p.material == 1, 2], 6)) == {0.05, 0.15}
    assert p.info["free_surface_z"] == surface
    assert p.materials[1].young == pytest.approx(
        p.materials[0].young * scen["physics.soil_layering.lower_young_factor"])
    np.savez(tmp_path / "few.npz", x=x[:9], radius=r[:9])
    few = _scen(**{"soil.packing_file": str(tmp_path / "few.npz"),
                   "physics.soil_layering.enabled": True, "physics.soil_layering.depth": 0.15})
    with pytest.raises(ScenarioError, match="physics.soil_layering.depth=0.15.*needs at least 10"):
        imported_packing(few, packing_spec(few), _container_top(few))


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


def test_stiffness_only_layer_is_the_unlayered_bed_with_stiffer_lower_grains(tmp_path):
    """``physics.soil_layering.compacted = false``: the bed is the unlayered scenario's own (one
    packing file in the cache, the same grains), the grains deeper than the depth below its
    nominal top (container.soil_depth) take lower_young_factor x E, and the run equals the run
    on that bed imported with the same layering at the depth the imported convention (below
    the bed's free surface) puts at the same level, bit for bit; a stiffer lower layer
    shallower than the sphere's penetration stops it sooner than the unlayered bed."""
    import h5py as _h5

    layered = {"physics.soil_layering.enabled": True, "physics.soil_layering.depth": 0.12,
               "physics.soil_layering.lower_young_factor": 20.0,
               "physics.soil_layering.compacted": False}
    plain = run_scenario(_scen(), out_dir=tmp_path / "runs", progress=False)
    stiff = run_scenario(_scen(**layered, **{"scenario.name": "tiny_stiff_layer"}),
                         out_dir=tmp_path / "runs", progress=False)
    cache = plain.parent / "packings"
    assert stiff.parent / "packings" == cache
    assert len(list(cache.glob("packing-*.h5"))) == 1
    bed = pk.cached(packing_spec(_scen()), cache)
    assert packing_spec(_scen(**layered)) == packing_spec(_scen())
    f = tmp_path / "bed.npz"
    np.savez(f, x=bed.x, radius=bed.radius)
    from crashdem.beds import free_surface

    top = float(np.max(bed.x[:, 2] + bed.radius))
    nominal = _scen()["container.soil_depth"]
    surface = free_surface(_scen(**{"soil.packing_file": str(f)}), bed.x, bed.radius)
    same_level = {**layered, "physics.soil_layering.depth": surface - (nominal - 0.12)}
    imported = run_scenario(_scen(**same_level, **{"soil.packing_file": str(f),
                                                   "scenario.name": "tiny_stiff_layer"}),
                            out_dir=tmp_path / "imp", progress=False)
    a, b, c = _channels(plain), _channels(stiff), _channels(imported)
    for k in CHANNELS:
        assert np.array_equal(b[k], c[k]), k
    with _h5.File(stiff) as h:
        n_lower = int(h["run"].attrs["stiffness_layer_grains"])
    assert n_lower == int(np.count_nonzero(bed.x[:, 2] < nominal - 0.12)) > 0
    assert n_lower < int(np.count_nonzero(bed.x[:, 2] < top - 0.12))  # not the top's level
    # deeper penetration is a more negative velocity integral; the stiff layer holds the sphere
    va, vb = a["drop_mass_velocity_z"], b["drop_mass_velocity_z"]
    assert np.sum(vb) > np.sum(va)
    assert np.max(b["drop_mass_contact_force_z"]) > 1.05 * np.max(a["drop_mass_contact_force_z"])


def test_stiffness_only_layer_is_refused_for_the_glider():
    from crashdem.run import stiffness_layer

    scen = sc.load(ROOT / "validation/scenarios/glider_real.toml",
                   {"physics.soil_layering.compacted": False})
    with pytest.raises(ScenarioError, match="physics.soil_layering.compacted=false.*allowed: true"):
        stiffness_layer(scen, None)
