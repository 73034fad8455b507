"""Search levels of a deposited effect on several beds (``screen_then_confirm(level_beds=...)``).

A floor or interface depth deposits a bed of its own at every level, so one run per level
carries that level's packing as well as the effect. The level's prediction is therefore pooled
over ``level_beds`` beds: the anchor plus the mean over the beds of the level run's change
against the baseline run of the same bed (bed 0: the baseline's packing, bed j: replicate j).
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from crashdem.diagnosis import diagnose, screen_then_confirm, write_report
from crashdem.diagnosis import confirm as cf
from crashdem.diagnosis.catalogue import DROP
from crashdem.diagnosis.generator import concealed_case
from crashdem.diagnosis.rom import RomParams, simulate
from crashdem.signal import Signal

REPS = [{"scenario.seed": s} for s in (2, 3, 4)]


@pytest.fixture(scope="module")
def case():
    return concealed_case(31, "soil_layering")


@pytest.fixture(scope="module")
def report(case):
    return diagnose(simulate(RomParams()), case.recording)


def _sig(rep, rng, scale):
    """Channels on the recording's time base: the baseline plus a random perturbation."""
    return {ch: Signal(ch, rep.baseline[ch].t, rep.baseline[ch].data
                       + scale * rng.standard_normal(rep.baseline[ch].t.size),
                       rep.baseline[ch].unit, rep.baseline[ch].cfc)
            for ch in rep.channels}


def _conf(rep, level_beds):
    return cf._Confirmation(rep, 2, True, None, REPS, level_beds)


def test_a_pooled_level_is_the_anchor_plus_the_mean_change_against_the_same_bed(report):
    """Each bed's level run is taken against the base run of its own bed; the changes are
    averaged and added to the anchor. A level of a non-deposited effect is left alone, a
    refinement of the same value is pooled apart from the level, and the order is kept."""
    rep, rng = report, np.random.default_rng(5)
    c = _conf(rep, 3)
    assert c.beds == [{}, REPS[0], REPS[1]]
    base0 = {"hypothesis": "baseline", "overrides": {}, "aligned": _sig(rep, rng, 1.0)}
    reps = [{"hypothesis": cf.REPLICATE, "overrides": dict(rv), "score": 0.5,
             "aligned": _sig(rep, rng, 1.0)} for rv in REPS]
    anchor = _sig(rep, rng, 0.5)
    floor = [{"hypothesis": "boundary_proximity", "overrides": {"scenario.seed": 1 + j},
              "search_value": 0.8, "score": 0.6, "aligned": _sig(rep, rng, 2.0)}
             for j in range(3)]
    refined = [{**r, "search_value": 0.8, "refined": True, "aligned": _sig(rep, rng, 2.0)}
               for r in floor]
    coh = {"hypothesis": "cohesion", "overrides": {}, "search_value": 1e5, "score": 0.7,
           "aligned": _sig(rep, rng, 1.0)}
    c.set_beds(base0, reps, anchor)
    assert c.bed_bases == [base0, reps[0], reps[1]]  # the third replicate is no bed
    out = c.pooled([floor[0], coh, floor[1], floor[2]] + refined + reps)
    assert [r["hypothesis"] for r in out] == (["boundary_proximity", "cohesion",
                                               "boundary_proximity"] + [cf.REPLICATE] * 3)
    assert out[1] is coh and out[3:] == reps
    lv, ref = out[0], out[2]
    assert not lv.get("refined") and ref["refined"]
    for row, runs in ((lv, floor), (ref, refined)):
        assert len(row["beds"]) == 3 and row["beds_pooled"] == 3
        assert [b["overrides"] for b in row["beds"]] == [r["overrides"] for r in runs]
        for ch in rep.channels:
            want = anchor[ch].data + np.mean([r["aligned"][ch].data - b["aligned"][ch].data
                                              for r, b in zip(runs, c.bed_bases)], axis=0)
            np.testing.assert_allclose(row["aligned"][ch].data, want, rtol=0, atol=1e-12)
        assert math.isclose(row["rss"], cf._full_rss(rep, row["aligned"]))
        assert row["score"] == c.rated(row["aligned"])["score"]
    # a run the model could not do leaves its bed out; no bed left: an error row
    broken = [floor[0], {**floor[1], "score": -math.inf, "error": "bed 1 failed"}, floor[2]]
    del broken[1]["aligned"]
    part = c.pooled(broken)[0]
    assert part["beds_pooled"] == 2 and part["beds"][1]["error"] == "bed 1 failed"
    for ch in rep.channels:
        want = anchor[ch].data + np.mean([floor[j]["aligned"][ch].data
                                          - c.bed_bases[j]["aligned"][ch].data
                                          for j in (0, 2)], axis=0)
        np.testing.assert_allclose(part["aligned"][ch].data, want, rtol=0, atol=1e-12)
    none = c.pooled(broken[1:2])[0]
    assert none["score"] == -math.inf and none["error"] == "bed 1 failed"
    assert "aligned" not in none and "rss" not in none


def test_pooling_removes_the_packing_of_each_level(report):
    """What pooling is for: a level run is its effect plus a packing realisation of its own (a
    deposited level shares no grains with the baseline). Averaged over more beds, the pooled
    level lies nearer the effect alone: the mean squared packing error falls about as 1/beds
    (measured here over 40 draws of independent realisations)."""
    rep = report
    rng = np.random.default_rng(11)
    effect = _sig(rep, rng, 3.0)  # the level's true response
    base = {ch: s for ch, s in rep.baseline.items()}
    err: dict[int, list[float]] = {1: [], 4: []}
    c = _conf(rep, 4)

    def mse(got):
        return np.mean([np.mean((got[ch].data - effect[ch].data) ** 2) for ch in rep.channels])

    for _ in range(40):
        def pack(sig):  # one packing realisation on top of a true response
            return {ch: Signal(ch, s.t, s.data + rng.standard_normal(s.t.size), s.unit, s.cfc)
                    for ch, s in sig.items()}
        bases = [pack(base) for _ in range(4)]
        runs = [pack(effect) for _ in range(4)]
        base0 = {"hypothesis": "baseline", "aligned": bases[0]}
        c.set_beds(base0, [{"hypothesis": cf.REPLICATE, "aligned": b} for b in bases[1:]], base)
        rows = [{"hypothesis": "soil_layering", "overrides": {}, "search_value": 0.3,
                 "score": 0.0, "aligned": r} for r in runs]
        # one bed: the level anchored on the baseline as a single run is (``anchored``)
        err[1].append(mse(c.anchored(rows[0], base0)["aligned"]))
        err[4].append(mse(c.pooled(rows)[0]["aligned"]))
    # one bed: run and base each carry one realisation (variance 2); four beds: 2 / 4
    assert np.mean(err[1]) == pytest.approx(2.0, rel=0.1)
    assert np.mean(err[4]) == pytest.approx(0.5, rel=0.1)


def test_deposited_levels_run_on_every_bed_and_are_counted(case, tmp_path):
    """Through ``screen_then_confirm`` (the ROM as the full model, no packing): every level
    of a deposited effect (floor, interface) runs once per bed with that bed's overrides, every
    other level once; the pooled rows report their beds and the simulation counts include them.
    With one bed per level nothing is run on another packing but the replicates."""
    from crashdem.diagnosis import catalogue as cat
    from tests.crashdem.diagnosis.test_report_confirm import _scenario_rom_simulator

    deposited = [n for n, fs in DROP.full_search.items() if fs.deposits]
    assert sorted(deposited) == ["boundary_proximity", "soil_layering"]
    n_dep = sum(DROP.full_search[n].n_levels for n in deposited)
    n_all = sum(fs.n_levels for fs in DROP.full_search.values())
    for beds in (1, 3):
        calls: list = []
        rep = screen_then_confirm(simulate(RomParams()), case.recording,
                                  _scenario_rom_simulator(calls), top_k=2, replicates=REPS,
                                  level_beds=beds, numerics=())
        seeded = [c for c in calls if "scenario.seed" in c]
        replicate_runs = [c for c in seeded if not any(k.startswith("physics.") for k in c)]
        assert replicate_runs == REPS
        levels = rep.fit["full_search"]["levels"]
        searched = [lv for lv in levels if not lv["refined"] and not lv["extension"]]
        assert len(searched) == n_all
        # an extension level (beyond the floor's shallowest) runs on the beds as a level does
        assert all(lv["hypothesis"] == "boundary_proximity" and lv.get("beds", 1) == beds
                   for lv in levels if lv["extension"])
        n_dep_ext = sum(lv["extension"] for lv in levels)
        for lv in searched:
            dep = lv["hypothesis"] in deposited
            assert lv.get("beds", 1) == (beds if dep else 1)
        # beds 2..: each deposited level (and a deposited refinement) once more with each
        # replicate's seed, its other overrides those of bed 0
        # the whole bed made stiffer (the realisation floor's recalibration runs) on every bed,
        # and the bed stiffer below its top grain row, the 0.15 m x2 / x5 stiffness layer (x5
        # is also the search's own 0.15 m level: the same overrides, run once for both)
        stiff_runs = [c for c in calls
                      if c.get("physics.soil_layering.depth") == cat.WHOLE_BED_DEPTH]
        assert len(stiff_runs) == len(cat.STIFFER_SOIL_FACTORS) * beds
        assert sorted(c.get("scenario.seed", 0) for c in stiff_runs) == sorted(
            [0, 2, 3][:beds] * len(cat.STIFFER_SOIL_FACTORS))
        top = [c for c in calls if c.get("physics.soil_layering.depth") == 0.15
               and c.get("physics.soil_layering.compacted") is False]
        x2 = [c for c in top if c["physics.soil_layering.lower_young_factor"] == 2.0]
        x5 = [c for c in top if c["physics.soil_layering.lower_young_factor"] == 5.0]
        assert len(x2) == len(x5) == beds
        assert sorted(c.get("scenario.seed", 0) for c in x2) == [0, 2, 3][:beds]
        assert len({json.dumps(c, sort_keys=True) for c in calls}) == len(calls)
        # the stiffer-soil runs taken away (the x5 one is the search level's too): what is
        # left is the replicates and the level runs on beds 2..
        rest = list(seeded)
        for c in stiff_runs + x2:
            if "scenario.seed" in c:
                rest.remove(c)
        bed_runs = [c for c in rest if c not in REPS]
        pooled = [lv for lv in levels if "beds" in lv]
        assert len(pooled) == (n_dep + n_dep_ext + sum(lv["refined"] for lv in pooled)
                               if beds > 1 else 0)
        assert len(bed_runs) == (beds - 1) * len(pooled)
        assert sorted(c["scenario.seed"] for c in bed_runs) == sorted(
            [2, 3][:beds - 1] * len(pooled))
        assert all({k: v for k, v in c.items() if k != "scenario.seed"} in calls
                   for c in bed_runs)
        assert rep.simulations["full_simulations"] == len(calls)
        assert rep.fit["full_search"]["level_beds"] == beds
    assert rep.missing_physics == "soil_layering", rep.decision
    text = Path(write_report(rep, tmp_path, plots=False)["md"]).read_text()
    assert ("Each level of boundary_proximity, soil_layering deposits its own bed, so it ran on "
            "3 beds") in text


@pytest.mark.parametrize("bad", [0, -1, 2.0, True, "3"])
def test_level_beds_is_checked(case, bad):
    with pytest.raises(ValueError, match=r"level_beds=.*must be an integer >= 1"):
        screen_then_confirm(simulate(RomParams()), case.recording, lambda ov: {},
                            level_beds=bad)


def test_command_line_level_beds():
    """``crashdem diagnose --level-beds N``: parsed; without it ``screen_then_confirm``'s
    default (None); outside [1, 33] an error naming the option and its range."""
    from crashdem.cli import build_parser
    from crashdem.diagnosis.cli import _level_beds

    base = ["diagnose", "--scenario", "s.toml", "--recording", "r.csv", "--out", "o"]
    assert build_parser().parse_args(base).level_beds is None
    assert build_parser().parse_args(base + ["--level-beds", "2"]).level_beds == 2
    assert _level_beds(None) is None and _level_beds(1) == 1
    for bad in (0, 34):
        with pytest.raises(ValueError, match=rf"--level-beds={bad}: must be in \[1, 33\]"):
            _level_beds(bad)


def test_default_beds_depend_on_where_the_search_runs(case):
    """By default a deposited level runs on ``LEVEL_BEDS`` beds (at most 1 + replicates) when
    the search runs on the full simulator, and on ``SEARCH_TIER_LEVEL_BEDS`` (one) on a
    separate search simulator; given explicitly, ``level_beds`` holds on either."""
    from tests.crashdem.diagnosis.test_report_confirm import _scenario_rom_simulator

    assert cf.SEARCH_TIER_LEVEL_BEDS == 1 < cf.LEVEL_BEDS
    reps = [{"scenario.seed": s} for s in range(2, 2 + cf.LEVEL_BEDS + 1)]

    def level_seeds(calls):
        return [c["scenario.seed"] for c in calls if "scenario.seed" in c
                and any(k.startswith("physics.") for k in c)]

    for search, beds, want in ((False, None, cf.LEVEL_BEDS), (True, None, 1), (True, 2, 2)):
        full_calls: list = []
        search_calls: list = []
        kw = {"search_simulator": _scenario_rom_simulator(search_calls)} if search else {}
        rep = screen_then_confirm(simulate(RomParams()), case.recording,
                                  _scenario_rom_simulator(full_calls), top_k=2, replicates=reps,
                                  level_beds=beds, numerics=(), **kw)
        assert rep.fit["full_search"]["level_beds"] == want
        seeds = set(level_seeds(search_calls if search else full_calls))
        assert seeds == {r["scenario.seed"] for r in reps[:want - 1]}
        assert not level_seeds(full_calls if search else search_calls)
