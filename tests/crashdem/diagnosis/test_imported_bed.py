"""``crashdem diagnose`` on a scenario whose bed is imported (``soil.packing_file``): the
recording's bed is the model's, one realisation, so the search runs on it with no replicate
packings, one bed per level, no grain-radius numerics check and no floor-depth levels
(``cli._one_bed``, ``cli._search_setup``); a larger imported bed is searched on deposited
coarse beds. Measured on Yade's recordings on Yade's own beds: docs/diagnosis.md, "The
recording's own bed"."""
from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from crashdem import scenario as sc
from crashdem.diagnosis import generator_dem as gd

#: the imported bed: crashdem's small drop bed deposited at another packing seed and grain size
#: than the baseline's (what another code's bed is to the model: given, not re-deposited)
BED = {"scenario.seed": 7, "soil.radius": 0.105}
#: the recording's numerics on that bed: another time step than the diagnosis's baseline (0.3)
TRUTH_SAFETY = 0.2


def _bed_file(tmp_path: Path) -> Path:
    from crashdem.run import packing_cache, packing_spec
    from soil import packing as pk

    scen = sc.load(gd.scenario_path(), {**gd.BASE_OVERRIDES, **BED})
    bed = pk.cached(packing_spec(scen), packing_cache(None))
    path = tmp_path / "bed.npz"
    np.savez(path, x=bed.x, radius=bed.radius)
    return path


def _sets(bed: Path) -> list[str]:
    ov = {**gd.BASE_OVERRIDES, **gd.BASELINE_NUMERICS, "soil.radius": BED["soil.radius"],
          "soil.packing_file": str(bed), "scenario.name": "imported_bed"}
    return [f"{k}={str(v).lower() if isinstance(v, bool) else v}" for k, v in ov.items()]


def _recording(tmp_path: Path, bed: Path, effect: dict, seed: int) -> Path:
    from crashdem.recordings import write_recording

    truth = {**BED, "solver.safety": TRUTH_SAFETY, "soil.packing_file": str(bed),
             "instrumentation.sample_rate": gd.TRUTH_SAMPLE_RATE, **effect}
    rec, _, _ = gd._acquired_truth(truth, np.random.default_rng(seed), None)
    return write_recording(tmp_path / f"rec_{seed}.csv", rec)


def _diagnose(tmp_path: Path, bed: Path, rec: Path, name: str, *extra: str) -> dict:
    from crashdem import cli

    out = tmp_path / name
    argv = ["diagnose", "--scenario", str(gd.scenario_path()), "--recording", str(rec),
            "--out", str(out), "--workers", "0", *extra]
    for s in _sets(bed):
        argv += ["--set", s]
    assert cli.main(argv) == 0
    return json.loads((out / "report.json").read_text())


def test_a_layering_on_the_recordings_own_bed_is_named_and_a_null_is_not(tmp_path):
    """Oracle: recordings made by crashdem on the imported bed itself at another time step
    (safety 0.2 against 0.3), acquired like a lab's -- a stiffer lower layer (E x 6 below
    0.3 m of the bed's top; on an imported bed the layering changes the stiffness only, as
    Yade's layering does) and the bed as it is. The layering must be named at its depth to a
    grain radius (0.105 m: the levels are 0.05-0.1 m apart and an interface is defined to a
    grain), the null must name nothing; both with no replicate run, one bed per level, no
    floor level and no numerics check."""
    bed = _bed_file(tmp_path)
    layered = {"physics.soil_layering.enabled": True, "physics.soil_layering.depth": 0.3,
               "physics.soil_layering.lower_young_factor": 6.0}
    rep = _diagnose(tmp_path, bed, _recording(tmp_path, bed, layered, 5), "layering")
    null = _diagnose(tmp_path, bed, _recording(tmp_path, bed, {}, 6), "null")
    n_grains = len(np.load(bed)["radius"])
    for r in (rep, null):
        sims = r["simulations"]
        assert sims["imported_bed"]["grains"] == n_grains
        assert sims["imported_bed"]["replicates"] == 0 and sims["imported_bed"]["level_beds"] == 1
        assert "on the scenario itself (the imported bed" in sims["full_search"]
        assert "not searched: boundary_proximity" in sims["full_search"]
        rows = r["fit"]["confirmation"]
        assert not any(x["hypothesis"] in ("replicate", "boundary_proximity") for x in rows)
        assert not any(x.get("beds") and len(x["beds"]) > 1 for x in rows)
    assert null["missing_physics"] is None, null["decision"]
    assert rep["missing_physics"] == "soil_layering", rep["decision"]
    named = rep["fit"]["full_search"]["named"]
    assert named["interface_depth"] == pytest.approx(0.3, abs=BED["soil.radius"]), named
    assert rep["fit"]["after_full"]["overall"] > rep["fit"]["before"]["overall"] + 0.1
    md = (tmp_path / "layering" / "report.md").read_text()
    assert "Imported bed" in md and "no replicate packings" in md


def test_an_imported_bed_refuses_options_that_repeat_it(tmp_path):
    """Replicates, beds per level and a numerics check would each run the one imported bed
    again: asked for explicitly they are refused with the option and the field named."""
    from crashdem.diagnosis.cli import _one_bed

    bed = tmp_path / "bed.npz"
    np.savez(bed, x=np.array([[0.0, 0.0, 0.1], [0.3, 0.0, 0.1]]), radius=np.array([0.1, 0.1]))
    scen = sc.load(gd.scenario_path(), {**gd.BASE_OVERRIDES, "soil.packing_file": str(bed)})

    def args(**kw):
        return SimpleNamespace(**{"replicates": None, "level_beds": None,
                                  "numerics_check": None, "grain_check": None,
                                  "grain_fit": None, **kw})

    one = _one_bed(scen, None, args())
    assert one["grains"] == 2 and one["replicates"] == 0 and one["numerics_check"] == "off"
    assert _one_bed(scen, None, args(replicates=0, level_beds=1, numerics_check="off"))
    assert _one_bed(scen, object(), args(replicates=4)) is None  # a deposited search tier
    for kw, opt in (({"replicates": 4}, "--replicates"), ({"level_beds": 5}, "--level-beds"),
                    ({"numerics_check": "0.9,1.1"}, "--numerics-check"),
                    ({"grain_check": "1.1"}, "--grain-check"),
                    ({"grain_fit": "1.25"}, "--grain-fit")):
        with pytest.raises(ValueError, match=f"{opt}=.*soil.packing_file"):
            _one_bed(scen, None, args(**kw))
    deposited = sc.load(gd.scenario_path(), dict(gd.BASE_OVERRIDES))
    assert _one_bed(deposited, None, args(replicates=4)) is None


def test_the_command_refuses_them_before_any_run(tmp_path, capsys):
    """Through ``crashdem diagnose``: refused before the baseline runs (nothing written under
    OUT/baseline), the message naming the option and the field."""
    from crashdem import cli
    from crashdem.diagnosis.generator import acquire
    from crashdem.diagnosis.rom import RomParams
    from crashdem.recordings import write_recording

    bed = tmp_path / "bed.npz"
    np.savez(bed, x=np.array([[0.0, 0.0, 0.1], [0.3, 0.0, 0.1]]), radius=np.array([0.1, 0.1]))
    rec = write_recording(tmp_path / "rec.csv", acquire(RomParams(), np.random.default_rng(1)))
    argv = ["diagnose", "--scenario", str(gd.scenario_path()), "--recording", str(rec),
            "--out", str(tmp_path / "out"), "--workers", "0", "--replicates", "4"]
    for s in _sets(bed):
        argv += ["--set", s]
    assert cli.main(argv) != 0
    assert "--replicates=4" in capsys.readouterr().err
    assert not (tmp_path / "out" / "baseline").exists()


def test_search_setup_on_an_imported_bed(tmp_path):
    """A small imported bed is searched on itself without floor levels; one too large for the
    budget (its grains counted from the file) on the coarse tier, which deposits its own beds
    (``soil.packing_file`` cleared); a floor is not searched on either (its levels could not
    be confirmed on the imported bed)."""
    from crashdem.diagnosis.cli import (AUTO_FULL_LOAD, _search_setup, bed_grains, search_load,
                                        search_tier)

    def lattice(n_side, spacing, r, depth):
        g = np.arange(-n_side, n_side + 1) * spacing
        xs, ys, zs = np.meshgrid(g, g, np.arange(r, depth, spacing), indexing="ij")
        x = np.stack([xs.ravel(), ys.ravel(), zs.ravel()], axis=1)
        return x[np.hypot(x[:, 0], x[:, 1]) <= 1.0 - r]

    small, big = tmp_path / "small.npz", tmp_path / "big.npz"
    xs = lattice(4, 0.22, 0.1, 0.8)
    np.savez(small, x=xs, radius=np.full(len(xs), 0.1))
    xb = lattice(19, 0.052, 0.025, 1.0)
    np.savez(big, x=xb, radius=np.full(len(xb), 0.025))
    base = {**gd.BASE_OVERRIDES, **gd.BASELINE_NUMERICS}
    s_small = sc.load(gd.scenario_path(), {**base, "soil.packing_file": str(small)})
    s_big = sc.load(gd.scenario_path(), {**base, "soil.packing_file": str(big)})
    assert bed_grains(s_small) == len(xs) and bed_grains(s_big) == len(xb)
    assert search_load(s_small) <= AUTO_FULL_LOAD < search_load(s_big)
    cmap = {"accel_z": "accel_z"}
    searched, sim, how = _search_setup(s_small, False, "auto", cmap, tmp_path / "a")
    assert sim is None and "boundary_proximity" not in searched
    assert {"soil_layering", "cohesion", "contact_damping", "particle_rotation"} <= set(searched)
    assert "the imported bed" in how and "not searched: boundary_proximity" in how
    # an imported bed is not re-deposited: its layer is searched in the stiffness form alone,
    # a deposited bed's in both forms (catalogue.LAYER_FORMS)
    lay = searched["soil_layering"]
    assert lay.form == "stiffness" and not lay.forms and lay.n_levels == len(lay.values)
    assert lay.fixed["physics.soil_layering.compacted"] is False
    dep, _, _ = _search_setup(sc.load(gd.scenario_path(), base), False, "auto", cmap,
                              tmp_path / "c")
    assert [f for f, _ in dep["soil_layering"].forms] == ["stiffness", "compacted"]
    assert search_tier(s_big)["soil.packing_file"] == ""
    searched, sim, how = _search_setup(s_big, False, "auto", cmap, tmp_path / "b")
    assert sim is not None and "coarse resolution" in how and "deposited beds" in how
    assert "boundary_proximity" not in searched
    assert "soil.packing_file" not in search_tier(sc.load(gd.scenario_path(), base))
