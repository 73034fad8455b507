"""Report files, screening-then-confirmation with an expensive simulator, and the CLI."""
from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from crashdem.diagnosis import diagnose, screen_then_confirm, write_report
from crashdem.diagnosis.catalogue import STIFFER_SOIL_FACTORS, WHOLE_BED_DEPTH
from crashdem.diagnosis.generator import TRUTH_DT, acquire, concealed_case
from crashdem.diagnosis.rom import SCALE_KEYS, RomParams, simulate

SCENARIO_TOML = """
[scenario]
name = "s7_diagnosis_test_no_result"
kind = "drop_test"
[impactor]
impact_velocity = 16.4
"""


def _run(name, db, score, value=None):
    """A scored confirmation row (the shape ``_Confirmation`` rules read): hypothesis, Delta BIC
    against the reference, score and, for a search level, its value."""
    r = {"hypothesis": name, "overrides": {}, "rss": 1.0, "score": score,
         "delta_bic_vs_reference": db}
    if value is not None:
        r["search_value"] = value
    return r


@pytest.fixture(scope="module")
def layering_case():
    return concealed_case(31, "soil_layering")


def test_write_report_files(layering_case, tmp_path):
    """report.json (parsable, with the issue-7 keys), report.md and one PNG per channel."""
    rep = diagnose(simulate(RomParams()), layering_case.recording)
    paths = write_report(rep, tmp_path)
    d = json.loads((tmp_path / "report.json").read_text())
    assert d["missing_physics"] == "soil_layering"
    assert {"mismatch", "hypotheses", "missing_physics", "fit"} <= set(d)
    md = (tmp_path / "report.md").read_text()
    assert "soil_layering" in md and "Mismatch windows" in md
    assert len(paths["plots"]) == len(rep.channels)
    for p in paths["plots"]:
        with open(p, "rb") as fh:
            assert fh.read(8) == b"\x89PNG\r\n\x1a\n"
    # beside the rating at the least-squares alignment, the rating at the best one within
    # SCORE_SHIFT_S: of the baseline and of the refitted curve the plots show
    from crashdem.diagnosis.fit import SCORE_SHIFT_S, rating_at_best_alignment

    best = d["fit"]["rating_best_alignment"]
    assert best["tolerance_s"] == SCORE_SHIFT_S
    win = tuple(d["fit"]["score_window_s"])
    for k, sims in (("before", rep.baseline), ("after", rep.refitted)):
        again = rating_at_best_alignment(rep.recording, sims, rep.channels, win)
        assert best[k]["overall"] == pytest.approx(again["overall"])
        assert best[k]["overall"] >= d["fit"][k]["overall"] - 1e-12
        assert abs(best[k]["shift_s"]) <= SCORE_SHIFT_S
    assert best["after"]["overall"] > best["before"]["overall"]
    assert "At the best common alignment within 2 ms of it: before " in md


def test_screen_then_confirm_counts_full_simulations(layering_case):
    """The expensive simulator (here: the truth numerics driven through *scenario keys*, so the
    catalogue's scenario mapping and ``rom_from_scenario`` are exercised) is called once for the
    recalibration and once per confirmed candidate; the concealed effect is confirmed."""
    calls: list = []
    full = _scenario_rom_simulator(calls)
    top_k = 2
    rep = screen_then_confirm(simulate(RomParams()), layering_case.recording, full, top_k=top_k,
                              full_search=False)
    assert rep.simulations["full_simulations"] == len(calls) == 1 + top_k
    assert rep.missing_physics == "soil_layering"
    conf = {r["hypothesis"]: r["score"] for r in rep.fit["confirmation"]}
    assert conf["soil_layering"] > conf["recalibration"]
    assert TRUTH_DT < 2e-5  # the confirming numerics differ from the screening ROM


def _cli_rom_diagnose(tmp_path, rec_path, *extra: str) -> tuple[int, dict | None]:
    """``crashdem diagnose --baseline rom`` of ``rec_path`` against ``SCENARIO_TOML``: the exit
    code and ``report.json`` (None when nothing was written)."""
    from crashdem import cli

    scen = tmp_path / "s.toml"
    scen.write_text(SCENARIO_TOML)
    out = tmp_path / "out"
    rc = cli.main(["diagnose", "--scenario", str(scen), "--recording", str(rec_path),
                   "--out", str(out), "--baseline", "rom", *extra])
    rep = out / "report.json"
    return rc, (json.loads(rep.read_text()) if rc == 0 and rep.exists() else None)


def _scenario_rom_simulator(calls: list, recording=None, same_as_recording=(),
                            grain_interface=False):
    """A stand-in for the full model: the ROM driven through *scenario keys*
    (``rom_from_scenario``, truth numerics, no noise); the overrides of every call are
    appended to ``calls``. With ``recording``, runs switching on an effect named in
    ``same_as_recording`` return the recording itself (two effects that fit equally), and so
    does a replicate (``scenario.seed`` set) when ``"replicate"`` is among them. The ROM has no
    grains: a grain-radius factor (the numerics check) changes nothing, unless
    ``grain_interface``: then the layer interface acts at its depth divided by the factor (as
    if the interface were felt through a grain-size-dependent number of grain layers)."""
    scenario = pytest.importorskip("crashdem.scenario")
    from crashdem.diagnosis.cli import rom_from_scenario
    from crashdem.diagnosis.distributed import RADIUS_SCALE_KEY

    base_scen = scenario.loads(SCENARIO_TOML)

    def full(overrides):
        calls.append(dict(overrides))
        overrides = dict(overrides)
        f = float(overrides.pop(RADIUS_SCALE_KEY, 1.0))
        if grain_interface and "physics.soil_layering.depth" in overrides:
            overrides["physics.soil_layering.depth"] = overrides["physics.soil_layering.depth"] / f
        if any(overrides.get(f"physics.{e}.enabled") for e in same_as_recording) or (
                "replicate" in same_as_recording and "scenario.seed" in overrides):
            return dict(recording)
        scales = {k.split(".", 1)[1]: v for k, v in overrides.items() if k.startswith("calibration.")}
        assert set(scales) <= set(SCALE_KEYS)
        keys = {k: v for k, v in overrides.items() if not k.startswith("calibration.")}
        p = rom_from_scenario(base_scen.with_overrides(keys)).with_values(scales)
        return acquire(p, np.random.default_rng(0), noise={"accel_z": 0.0, "velocity_z": 0.0})

    return full


def test_full_search_runs_every_level_of_every_effect(layering_case, tmp_path):
    """With the full-model search, the full model also runs each searched effect at each of its
    levels (``catalogue.DROP_FULL_SEARCH``: 24, 34 runs with the layering and the contact
    damping in both their forms) and at most one refinement; every level is
    reported with its score and Delta BIC (report.json) and each effect's best level in
    report.md, each effect is judged by its best run, and the concealed layering is named (its
    interface 0.15-0.5 m levels bracket the truth)."""
    from crashdem.diagnosis.catalogue import DROP
    from crashdem.diagnosis.confirm import _full_residuals, _full_rss

    calls: list = []
    full = _scenario_rom_simulator(calls)
    top_k = 2
    rep = screen_then_confirm(simulate(RomParams()), layering_case.recording, full, top_k=top_k)
    n_levels = sum(fs.n_levels for fs in DROP.full_search.values())
    assert n_levels == 34
    # the numerics check runs the named effect's levels twice when a search level stands for it
    n_num = rep.simulations.get("numerics_simulations", 0)
    assert n_num == (2 * len(DROP.full_search["soil_layering"].values)
                     if rep.fit["full_search"].get("named") else 0)
    levels = rep.fit["full_search"]["levels"]
    # extension levels run only while an effect's strong end fits best (at most its extension)
    n_ext = sum(lv.get("beds", 1) for lv in levels if lv["extension"])
    assert n_ext <= sum(len(fs.extension) for fs in DROP.full_search.values())
    assert 1 + top_k + n_levels + n_ext <= len(calls) - n_num \
        == rep.simulations["full_simulations"] <= 1 + top_k + n_levels + n_ext + 1
    assert len(levels) >= n_levels
    assert {lv["hypothesis"] for lv in levels} == set(DROP.full_search)
    assert all(lv["delta_bic_vs_reference"] is not None for lv in levels)
    assert rep.missing_physics == "soil_layering", rep.decision
    md = (tmp_path / "report.md")
    write_report(rep, tmp_path, plots=False)
    text = md.read_text()
    assert "## Full-simulation confirmation" in text and "Full-model search" in text
    for name in DROP.full_search:
        assert f"| {name} |" in text
    # the named effect's evidence is its full run's, the screening's kept beside it: the
    # layering adds the recording's second peak the baseline lacks
    h = rep.hypotheses[0]
    assert h["name"] == "soil_layering"
    if "full_model" in h:  # a search level named: its value
        what = f"interface_depth = {h['full_model']['parameters']['interface_depth']:.4g} m"
    else:  # the screening's claim run: its scenario values
        depth = h["scenario_overrides"]["physics.soil_layering.depth"]
        what = f"physics.soil_layering.depth = {depth:.4g}"
    assert h["evidence"].startswith(f"in the full simulation with {what}")
    assert ": adds the missing peak of " in h["evidence"]
    assert h["evidence"].endswith(f"score {rep.fit['before']['overall']:.3f} -> "
                                  f"{rep.fit['after_full']['overall']:.3f}.")
    assert h["screening_evidence"].startswith("adds the missing peak")
    assert "residual" in h["screening_evidence"]
    assert all("screening_evidence" not in x for x in rep.hypotheses[1:])
    # the fit "after" is the named effect's full run (the plots' refitted curve), the screening
    # refit's scores kept beside it
    full = rep.fit["after_full"]
    assert rep.fit["after_source"] == "full simulation"
    assert rep.fit["after"] == {"per_channel": full["per_channel"], "overall": full["overall"]}
    assert h["score_after"] == full["overall"]
    scr = rep.fit["after_screening_refit"]
    assert scr["hypothesis"] == "soil_layering"
    assert scr["overall"] == h["screening_score_after"] == rep.fits["soil_layering"].scores[
        "overall"]
    assert scr["overall"] != full["overall"]
    rms = math.sqrt(_full_rss(rep, rep.refitted) / sum(
        r.size for r in _full_residuals(rep, rep.refitted)))
    assert rep.fit["residual_rms_sigma_after"] == pytest.approx(rms, rel=1e-12)
    assert (f"After: the full simulation with soil_layering (the refitted curve of the plots). "
            f"The screening refit (soil_layering with the recalibration") in text
    # a screening alone keeps its refit as the fit "after"
    alone = diagnose(simulate(RomParams()), layering_case.recording)
    assert alone.fit["after_source"] == "screening refit"
    assert "after_screening_refit" not in alone.fit
    assert alone.fit["after"] == alone.fits[alone.best].scores
    # report.md heads with the named value and the evidence for it
    head = text.split("**Decision:**")[0]
    assert f"**Why:** {h['evidence']}  " in head
    k, v = next(iter(h["parameters"].items()))
    assert f"**Value:** {k} = " in head and " m;" in head.split("**Value:**")[1].split("\n")[0]


def test_a_confirmed_sensor_keeps_its_model_free_evidence():
    """A resonant mount found by the model-free accelerometer check and confirmed by its full
    run: the evidence is the full run's, with the check's sentence kept at its end
    (``model_free_evidence``), and the screening's sentence in ``screening_evidence``."""
    from crashdem.diagnosis.generator import acquire

    rec = acquire(RomParams(mount_frequency=70.0, mount_damping=0.15, mount_form=1.0),
                  np.random.default_rng(3), trigger_offset=0.0012)
    rep = screen_then_confirm(simulate(RomParams()), rec, _scenario_rom_simulator([]), top_k=2,
                              full_search=False)
    assert rep.missing_physics == "sensor_dynamics", rep.decision
    h = rep.hypotheses[0]
    mf = h["model_free_evidence"]
    assert mf.startswith("The accelerometer disagrees") and mf.endswith("(model-free check).")
    assert h["evidence"].startswith("in the full simulation with physics.sensor_dynamics.")
    assert h["evidence"].endswith(" " + mf)
    assert h["screening_evidence"].endswith(" " + mf)
    assert "residual" in h["screening_evidence"] and "residual" not in h["evidence"]


def test_numerics_check_widens_a_named_value_by_its_grain_size_shift(tmp_path):
    """The numerics check reruns the named effect's levels with the grain radius x0.9 and x1.1.
    The recording: the search's own layering form (interface 0.33 m) in the stand-in model;
    only the search runs (top_k = 0), so a search level stands for the named effect.
    Where the located value moves with the grains (here the interface acts at its depth over
    the factor, so the profile's optimum moves by about the factor), the values it reports are
    ordered with the factor, the shift is about a tenth of the depth, the reported uncertainty
    is at least the shift and report.md says so. Where nothing moves (the stand-in has no
    grains), every value equals the one at the own grains and the uncertainty is the one
    without the check."""
    from crashdem import scenario
    from crashdem.diagnosis.catalogue import DROP
    from crashdem.diagnosis.cli import rom_from_scenario

    fs = {"soil_layering": DROP.full_search["soil_layering"]}
    truth = rom_from_scenario(scenario.loads(SCENARIO_TOML).with_overrides(
        fs["soil_layering"].overrides(0.33)))
    recording = acquire(truth, np.random.default_rng(5))

    def run(grain_interface, numerics=(0.9, 1.1)):
        return screen_then_confirm(simulate(RomParams()), recording,
                                   _scenario_rom_simulator([], grain_interface=grain_interface),
                                   top_k=0, full_search=fs, numerics=numerics)

    moved = run(True)
    assert moved.missing_physics == "soil_layering", moved.decision
    named = moved.fit["full_search"]["named"]
    num = named["numerics"]
    own = num["own_value"]
    assert abs(own - 0.33) < 0.03, num
    v09, v11 = (p["value"] for p in num["values"])
    assert v09 < own < v11, num
    # the optimum moves by about 0.1 x 0.33 m each way; the profile locates it from levels
    # 0.05-0.1 m apart (a parabola through three of them), so to within that spacing
    assert 0.02 < num["uncertainty"] <= 0.1, num
    assert named["uncertainty"] >= num["uncertainty"]
    h = next(h for h in moved.hypotheses if h["name"] == "soil_layering")
    assert h["full_model"]["uncertainty"]["interface_depth"] == named["uncertainty"]
    assert moved.simulations["numerics_simulations"] == 2 * len(fs["soil_layering"].values)
    write_report(moved, tmp_path, plots=False)
    n_num = 2 * len(fs["soil_layering"].values)
    assert f"Numerics check ({n_num} runs)" in (tmp_path / "report.md").read_text()

    still, off = run(False), run(False, numerics=())
    num = still.fit["full_search"]["named"]["numerics"]
    # the same runs; Delta BIC against another constant, so equal to rounding
    assert [p["value"] for p in num["values"]] == pytest.approx([num["own_value"]] * 2, rel=1e-12)
    assert num["uncertainty"] < 1e-12
    assert still.fit["full_search"]["named"]["uncertainty"] \
        == off.fit["full_search"]["named"]["uncertainty"]
    assert "numerics" not in off.fit["full_search"]["named"]
    assert "numerics_simulations" not in off.simulations


def test_grain_scaled_simulator_counts_each_run_once():
    """The grain check's simulator scales every run's grain radius and counts the runs made. A
    batch in which one run fails raises; ``_run_full`` then runs the batch one by one, and the
    count is those runs, not the failed batch as well (each request counted once)."""
    from crashdem.diagnosis.confirm import RADIUS_SCALE_KEY, _GrainScaled, _run_full

    seen = []

    class Sim:
        def __call__(self, ov):
            seen.append(ov[RADIUS_SCALE_KEY])
            if ov.get("fail"):
                raise ValueError("the full model cannot run this")
            return ov[RADIUS_SCALE_KEY]

        def map(self, batch):
            return [self(ov) for ov in batch]

    g = _GrainScaled(Sim(), 1.1)
    assert g.map([{}, {RADIUS_SCALE_KEY: 0.9}]) == pytest.approx([1.1, 0.99])
    assert g.n == 2
    outs = _run_full(g, [("a", {}), ("b", {"fail": True}), ("c", {})])
    assert outs[0] == pytest.approx(1.1) and outs[2] == pytest.approx(1.1)
    assert isinstance(outs[1], ValueError)
    assert g.n == 2 + 3
    assert g({}) == pytest.approx(1.1) and g.n == 6


def test_grain_check_names_only_what_every_grain_size_names(tmp_path):
    """The grain check makes the whole confirmation again with every run's grain radius times
    a factor (its own baseline run, screening, search and numerics check). The recording: the
    search's layering form (interface 0.33 m) in the stand-in model, which has no grains, so
    at 1.3 x the confirmation names the layering too and the name stands, the check's answer
    and runs recorded. Control: a stand-in in which the layering shows nothing from 1.25 x
    the grain radius on (its runs there are the baseline's); the confirmation at 1.3 x then
    names nothing, and the layering named at the model's grains is withdrawn, with why.
    Without the check (the default) neither is recorded."""
    from crashdem import scenario
    from crashdem.diagnosis.catalogue import DROP
    from crashdem.diagnosis.cli import rom_from_scenario
    from crashdem.diagnosis.confirm import GRAIN_CHECK_SCALES
    from crashdem.diagnosis.distributed import RADIUS_SCALE_KEY

    fs = {"soil_layering": DROP.full_search["soil_layering"]}
    truth = rom_from_scenario(scenario.loads(SCENARIO_TOML).with_overrides(
        fs["soil_layering"].overrides(0.33)))
    recording = acquire(truth, np.random.default_rng(5))
    calls: list = []
    rom = _scenario_rom_simulator(calls)

    def fading(overrides):
        """The layering shows nothing on grains 1.25 x or more the model's."""
        if float(overrides.get(RADIUS_SCALE_KEY, 1.0)) >= 1.25:
            overrides = {k: v for k, v in overrides.items()
                         if not k.startswith("physics.soil_layering.")}
        return rom(overrides)

    def run(sim, grain_check=(1.3,), agree="all"):
        calls.clear()
        return screen_then_confirm(simulate(RomParams()), recording, sim, top_k=0,
                                   full_search=fs, grain_check=grain_check, grain_agree=agree)

    kept = run(rom)
    assert kept.missing_physics == "soil_layering", kept.decision
    assert kept.fit["grain_check"]["agree"] == "all"
    (g,) = kept.fit["grain_check"]["factors"]
    assert g["radius_scale"] == 1.3 and g["named"] == "soil_layering"
    # the check's runs: at 1.3 x, and its numerics check's at 1.3 x 0.9 and 1.3 x 1.1
    scaled = [c for c in calls if round(c.get(RADIUS_SCALE_KEY, 1.0), 9) not in (0.9, 1.0, 1.1)]
    assert g["runs"] == kept.simulations["grain_check_simulations"] == len(scaled) > 0
    assert "withdrawn" not in kept.decision

    gone = run(fading)
    assert gone.fit["grain_check"]["factors"][0]["named"] is None
    assert gone.missing_physics is None, gone.decision
    assert ("soil_layering withdrawn: the confirmation made again with the grain radius scaled "
            "does not name it at every grain size (1.3x grains: nothing)") in gone.decision
    write_report(gone, tmp_path, plots=False)
    assert "named, then withdrawn: the confirmation made again" in (
        tmp_path / "report.md").read_text()

    # two factors, one on each side of where the layering fades: "all" withdraws it at the
    # first that does not name it, "any" keeps it at the first that does; neither runs the
    # other factor
    both = run(fading, (1.3, 1.2))
    assert both.missing_physics is None
    assert [g["radius_scale"] for g in both.fit["grain_check"]["factors"]] == [1.3]
    one = run(fading, (1.2, 1.3), agree="any")
    assert one.missing_physics == "soil_layering", one.decision
    assert [(g["radius_scale"], g["named"]) for g in one.fit["grain_check"]["factors"]] == [
        (1.2, "soil_layering")]
    none = run(fading, (1.3,), agree="any")
    assert none.missing_physics is None
    assert "does not name it at any other grain size (1.3x grains: nothing)" in none.decision
    with pytest.raises(ValueError, match="grain_agree='most': must be 'all' or 'any'"):
        run(rom, agree="most")

    assert GRAIN_CHECK_SCALES == ()
    off = run(fading, GRAIN_CHECK_SCALES)
    assert off.missing_physics == "soil_layering"
    assert "grain_check" not in off.fit and "grain_check_simulations" not in off.simulations
    assert all(round(c.get(RADIUS_SCALE_KEY, 1.0), 9) in (0.9, 1.0, 1.1) for c in calls)


def test_grain_fit_confirms_at_the_grain_size_that_fits_the_recording():
    """The grain fit rates the baseline at other grain sizes and, when one fits the recording
    decisively better, makes the confirmation there. The stand-in: grains 1.2 x the model's
    or more respond as a layer at 0.33 m does at the model's grains (another code's coarser
    soil). A null recording from 1.25 x grains is then claimed a layering at the model's
    grains; with the grain fit (1.25 x) that grain size fits it far better (the recording is
    its run plus noise), the confirmation there names nothing, and the report keeps the
    answer at the model's grains, the scenario's own baseline score as ``before`` and the
    runs. Control: a floor recorded at the model's grains, which 1.25 x fits worse: the grain
    size stays the model's, one more run, the floor still named."""
    from crashdem import scenario
    from crashdem.diagnosis.catalogue import DROP
    from crashdem.diagnosis.cli import rom_from_scenario
    from crashdem.diagnosis.confirm import GRAIN_FIT_MARGIN, GRAIN_FIT_SCALES
    from crashdem.diagnosis.distributed import RADIUS_SCALE_KEY
    from crashdem.diagnosis.report import to_markdown

    fs = {k: DROP.full_search[k] for k in ("soil_layering", "boundary_proximity")}
    layer = fs["soil_layering"].overrides(0.33)
    calls: list = []
    rom = _scenario_rom_simulator(calls)

    def coarse_reads_as_layer(overrides):
        ov = dict(overrides)
        if (float(ov.get(RADIUS_SCALE_KEY, 1.0)) >= 1.2
                and not any(k.startswith("physics.soil_layering.") for k in ov)):
            ov.update(layer)
        return rom(ov)

    def recording(ov):
        p = rom_from_scenario(scenario.loads(SCENARIO_TOML).with_overrides(ov))
        return acquire(p, np.random.default_rng(5))

    def run(rec, grain_fit):
        calls.clear()
        return screen_then_confirm(simulate(RomParams()), rec, coarse_reads_as_layer, top_k=0,
                                   full_search=fs, grain_fit=grain_fit)

    null = recording(layer)
    claimed = run(null, GRAIN_FIT_SCALES)
    assert GRAIN_FIT_SCALES == ()
    assert claimed.missing_physics == "soil_layering", claimed.decision
    assert "grain_fit" not in claimed.fit and "grain_fit_simulations" not in claimed.simulations

    fitted = run(null, (1.25,))
    g = fitted.fit["grain_fit"]
    sizes = {s["radius_scale"]: s["bic_mean"] for s in g["sizes"]}
    assert set(sizes) == {1.0, 1.25} and sizes[1.0] - sizes[1.25] > GRAIN_FIT_MARGIN
    assert g["chosen"] == 1.25
    assert fitted.missing_physics is None, fitted.decision
    assert g["at_model_grains"]["named"] == "soil_layering"
    assert fitted.fit["before"] == claimed.fit["before"]
    assert fitted.fit["before_at_grain_fit"]["overall"] > fitted.fit["before"]["overall"]
    assert fitted.fit["residual_rms_sigma_before"] == claimed.fit["residual_rms_sigma_before"]
    assert fitted.fit["residual_rms_sigma_before_at_grain_fit"] < \
        fitted.fit["residual_rms_sigma_before"]
    # its runs: at 1.25 x (the numerics check at the model's grains runs at 0.9 and 1.1 x)
    scaled = [c for c in calls if round(c.get(RADIUS_SCALE_KEY, 1.0), 9) not in (0.9, 1.0, 1.1)]
    assert fitted.simulations["grain_fit_simulations"] == g["runs"] == len(scaled) > 1
    assert "Taken: x1.25" in to_markdown(fitted)
    (recal,) = [h for h in fitted.hypotheses if h["name"] == "recalibration"]
    assert recal["grain_radius_scale"] == 1.25

    floor_rec = recording(fs["boundary_proximity"].overrides(0.9))
    floor = run(floor_rec, (1.25,))
    g = floor.fit["grain_fit"]
    assert g["chosen"] == 1.0 and g["runs"] == 1 and "at_model_grains" not in g
    sizes = {s["radius_scale"]: s["bic_mean"] for s in g["sizes"]}
    assert sizes[1.25] > sizes[1.0]
    assert floor.missing_physics == "boundary_proximity", floor.decision
    assert "before_at_grain_fit" not in floor.fit
    assert "The model's grains stand." in to_markdown(floor)


def test_law_fit_confirms_in_the_contact_law_that_fits_the_recording(tmp_path):
    """The law fit rates the baseline's realisations in the other contact law at several moduli
    and, when one fits the recording decisively better than the scenario's law, makes the
    confirmation in it. The stand-in: a run in the Hertz-Mindlin law at 4 x the modulus
    responds as a layer at 0.33 m does in the scenario's law, at 2 x as a layer at 0.45 m (the
    ROM has no contact law). A null recording of the Hertz-Mindlin bed at 4 x is then claimed
    a layering in the scenario's law; with the law fit (2, 4) the 4 x law fits it best and far
    better, the confirmation in it names nothing, and every run of that confirmation is in the
    law at 4 x. The report keeps the answer in the scenario's law, its baseline score as
    ``before``, the runs, and the law in the recalibration. Control: a floor recorded in the
    scenario's law, which the other law fits worse: the law stands, the floor named. The law
    fit also rates the scenario's law at the same moduli (here: unchanged by the modulus, so
    not taken); when the scenario's law at 4 x reads as the same layer, the law stands and its
    4 x modulus is taken instead (a stiffness, not a law)."""
    from crashdem import scenario
    from crashdem.diagnosis.catalogue import DROP
    from crashdem.diagnosis.cli import rom_from_scenario
    from crashdem.diagnosis.confirm import (
        GRAIN_FIT_MARGIN,
        IMPACT_YOUNG_KEY,
        LAW_FIT_FACTORS,
        LAW_KEY,
        OWN_LAW,
    )
    from crashdem.diagnosis.report import to_markdown

    fs = {k: DROP.full_search[k] for k in ("soil_layering", "boundary_proximity")}
    as_layer = {4.0: fs["soil_layering"].overrides(0.33), 2.0: fs["soil_layering"].overrides(0.45)}
    calls: list = []
    rom = _scenario_rom_simulator(calls)

    stiffness_reads_as_layer = False

    def other_law_reads_as_layer(overrides):
        ov = dict(overrides)
        law, k = ov.pop(LAW_KEY, "linear"), float(ov.pop(IMPACT_YOUNG_KEY, 1.0))
        if ((law == "hertz_mindlin" or stiffness_reads_as_layer and k == 4.0)
                and not any(x.startswith("physics.soil_layering.") for x in ov)):
            ov.update(as_layer[k])
        out = rom(ov)
        calls[-1] = dict(overrides)
        return out

    def recording(ov):
        p = rom_from_scenario(scenario.loads(SCENARIO_TOML).with_overrides(ov))
        return acquire(p, np.random.default_rng(5))

    def run(rec, law_fit, **kw):
        calls.clear()
        return screen_then_confirm(simulate(RomParams()), rec, other_law_reads_as_layer,
                                   top_k=0, full_search=fs, law_fit=law_fit, **kw)

    null = recording(as_layer[4.0])
    claimed = run(null, LAW_FIT_FACTORS)
    assert LAW_FIT_FACTORS == ()
    assert claimed.missing_physics == "soil_layering", claimed.decision
    assert "law_fit" not in claimed.fit and "law_fit_simulations" not in claimed.simulations
    assert not any(LAW_KEY in c for c in calls)

    fitted = run(null, (2.0, 4.0))
    g = fitted.fit["law_fit"]
    laws = {(s["contact_law"], s["impact_young_factor"]): s for s in g["laws"]}
    assert set(laws) == {(OWN_LAW, None), (OWN_LAW, 2.0), (OWN_LAW, 4.0),
                         ("hertz_mindlin", 2.0), ("hertz_mindlin", 4.0)}
    assert g["law"] == "hertz_mindlin"
    hz4, hz2 = laws["hertz_mindlin", 4.0], laws["hertz_mindlin", 2.0]
    assert hz4["delta_bic_vs_model"] > GRAIN_FIT_MARGIN
    assert hz4["delta_bic_vs_own_law"] > GRAIN_FIT_MARGIN  # the scenario's law at no modulus
    assert hz4["bic_mean"] < hz2["bic_mean"] - GRAIN_FIT_MARGIN
    assert g["chosen"] == {"contact_law": "hertz_mindlin", "impact_young_factor": 4.0}
    assert fitted.missing_physics is None, fitted.decision
    assert g["at_model_law"]["named"] == "soil_layering"
    assert fitted.fit["before"] == claimed.fit["before"]
    assert fitted.fit["before_at_law_fit"]["overall"] > fitted.fit["before"]["overall"]
    # the confirmation in the scenario's law, the law fit's four runs (the scenario's law at
    # 2 and 4 x, then the other law), then every run of the confirmation in the law at 4 x
    i = next(i for i, c in enumerate(calls) if IMPACT_YOUNG_KEY in c)
    assert i > 0 and [c.get(IMPACT_YOUNG_KEY) for c in calls[i:i + 4]] == [2.0, 4.0, 2.0, 4.0]
    assert [c.get(LAW_KEY) for c in calls[i:i + 4]] == [None, None] + ["hertz_mindlin"] * 2
    assert all(c[LAW_KEY] == "hertz_mindlin" and c[IMPACT_YOUNG_KEY] == 4.0
               for c in calls[i + 4:])
    assert fitted.simulations["law_fit_simulations"] == g["runs"] == len(calls) - i > 4
    (recal,) = [h for h in fitted.hypotheses if h["name"] == "recalibration"]
    assert recal["contact_law"] == "hertz_mindlin" and recal["impact_young_factor"] == 4.0
    assert "Taken: hertz_mindlin at x4 the modulus" in to_markdown(fitted)
    assert "In the scenario's law it named soil_layering." in to_markdown(fitted)

    # without the scenario's law at other moduli (law_fit_stiffness=()): the other law alone
    alone = run(null, (2.0, 4.0), law_fit_stiffness=())
    assert {s["contact_law"] for s in alone.fit["law_fit"]["laws"][1:]} == {"hertz_mindlin"}
    assert alone.fit["law_fit"]["chosen"] == g["chosen"]
    assert "delta_bic_vs_own_law" not in alone.fit["law_fit"]["laws"][1]

    # a stiffness: the scenario's law at 4 x reads as the same layer as the other law at 4 x
    stiffness_reads_as_layer = True
    stiff = run(null, (2.0, 4.0))
    g = stiff.fit["law_fit"]
    assert g["chosen"] == {"contact_law": OWN_LAW, "impact_young_factor": 4.0}
    assert stiff.missing_physics is None, stiff.decision
    assert g["at_model_law"]["named"] == "soil_layering"
    i = next(i for i, c in enumerate(calls) if IMPACT_YOUNG_KEY in c)
    assert all(LAW_KEY not in c and c[IMPACT_YOUNG_KEY] == 4.0 for c in calls[i + 4:])
    (recal,) = [h for h in stiff.hypotheses if h["name"] == "recalibration"]
    assert recal["impact_young_factor"] == 4.0 and "contact_law" not in recal
    assert "Taken: the scenario's law at x4 the modulus, a recalibration of the soil's " \
        "stiffness" in to_markdown(stiff)
    # the other law at 4 x is the same stand-in run as the scenario's at 4 x: no better, so
    # nothing undecided to report; nor where the other law was taken
    assert g["law_undecided"] is None and fitted.fit["law_fit"]["law_undecided"] is None
    assert "does not tell the two contact laws apart" not in to_markdown(stiff)
    stiffness_reads_as_layer = False

    floor = run(recording(fs["boundary_proximity"].overrides(0.9)), (4.0,))
    g = floor.fit["law_fit"]
    assert g["chosen"] is None and g["runs"] == 2 and "at_model_law" not in g
    laws = {s["contact_law"]: s["bic_mean"] for s in g["laws"] if s["impact_young_factor"]}
    own = g["laws"][0]["bic_mean"]
    # the stand-in's modulus changes nothing: the run, not the baseline signals, within 0.5
    assert laws["hertz_mindlin"] > own and abs(laws[OWN_LAW] - own) < 0.5
    assert floor.missing_physics == "boundary_proximity", floor.decision
    assert "before_at_law_fit" not in floor.fit
    assert "The scenario's law stands at its modulus." in to_markdown(floor)
    with pytest.raises(ValueError, match="law_fit_law='hooke': must be one of linear"):
        screen_then_confirm(simulate(RomParams()), null, rom, law_fit=(4.0,), law_fit_law="hooke")
    with pytest.raises(ValueError, match=r"law_fit=\(0.0,\): factor 0.0 is outside \[0.01, 100\]"):
        screen_then_confirm(simulate(RomParams()), null, rom, law_fit=(0.0,))
    with pytest.raises(ValueError, match=r"law_fit_stiffness=\(200.0,\): factor 200.0 is outs"):
        screen_then_confirm(simulate(RomParams()), null, rom, law_fit=(4.0,),
                            law_fit_stiffness=(200.0,))


def test_law_fit_choice_floor_run_and_cli_factors():
    """``law_choice`` takes another law only when decisive, and of the decisive moduli the best
    rated within the BIC margin. In a confirmation made in the law the law fit took, the
    realisation floor's run of the other law (``FullSearch.hertz_floor``) is left out (it
    would be the chosen law again, at another modulus); ``--law-fit`` names the other law of
    the scenario's and gives absolute
    ``soil.impact_young_factor`` values (times the scenario's own), refusing a factor out of
    range with the option, the value and the range."""
    from crashdem import scenario
    from crashdem.diagnosis.catalogue import DROP
    from crashdem.diagnosis.cli import _law_fit_factors
    from crashdem.diagnosis.confirm import _law_undecided, _without_hertz_floor, law_choice
    from crashdem.diagnosis.report import _undecided_sentence

    lay = replace(DROP.full_search["soil_layering"], hertz_floor=4.0)
    out = _without_hertz_floor({"soil_layering": lay, "x": DROP.full_search["boundary_proximity"]})
    assert out["soil_layering"].hertz_floor is None
    assert out["x"] is DROP.full_search["boundary_proximity"]
    assert _without_hertz_floor(True) is True

    # law_choice: decisive against the scenario's law (margin and 2 standard errors), then
    # of those within the margin of the best BIC the best rated (a Yade Hertz-Mindlin null's
    # table, 13.7 m seed 30: 4 x, the truth's modulus, over 8 x)
    def law(k, mean, sd, score):
        return {"contact_law": "scenario" if k is None else "hertz_mindlin",
                "impact_young_factor": k, "bic_mean": mean, "bic_sd": sd,
                "score_mean": score, "realisations": 5}

    seed30 = [law(None, 70.5, 5.7, 0.784), law(2.0, 79.4, 3.5, 0.740),
              law(4.0, 57.7, 5.4, 0.755), law(8.0, 52.1, 5.2, 0.701)]
    assert law_choice(seed30) == {"contact_law": "hertz_mindlin", "impact_young_factor": 4.0}
    assert seed30[2]["delta_bic_vs_model"] == pytest.approx(12.8)
    seed30[2]["bic_mean"] = 58.2  # 6.1 above the best: beyond the margin, 8 x taken
    assert law_choice(seed30)["impact_young_factor"] == 8.0
    # decisive in BIC but not beyond two standard errors of the packings' scatter
    assert law_choice([law(None, 70.5, 12.0, 0.78), law(4.0, 62.0, 12.0, 0.80)]) is None
    assert law_choice([law(4.0, 62.0, 1.0, 0.80)]) is None  # the scenario's law not rated

    # with the scenario's law at 4 x too: the other law must also beat its best modulus
    def own(k, mean, sd, score):
        return {**law(None, mean, sd, score), "impact_young_factor": k}

    seed30[2]["bic_mean"] = 57.7
    table = [*seed30, own(4.0, 55.0, 5.0, 0.76)]  # within the margin of the best: a stiffness
    assert law_choice(table) == {"contact_law": "scenario", "impact_young_factor": 4.0}
    assert table[3]["delta_bic_vs_own_law"] == pytest.approx(2.9)
    # 4 x of the scenario's law not decisive (6.5 < 2 SE); 8 x of the other law beats it
    # by 11.9 > 2 SE (6.5), 4 x by 6.3 < 2 SE (6.6): the law at 8 x, not the better-rated 4 x
    table = [*seed30, own(4.0, 64.0, 5.0, 0.76)]
    assert law_choice(table) == {"contact_law": "hertz_mindlin", "impact_young_factor": 8.0}
    assert table[2]["delta_bic_vs_own_law"] == pytest.approx(6.3)
    # the other law beats the scenario's modulus but not its 4 x, which is not decisive itself
    table = [law(None, 70.5, 5.7, 0.78), own(4.0, 64.0, 5.0, 0.79), law(4.0, 60.0, 5.4, 0.80)]
    assert law_choice(table) is None
    assert table[2]["delta_bic_vs_model"] == pytest.approx(10.5)
    # ... but when the 4 x is decisive (8.5 > 2 SE, 6.8), it is taken, though 7 in BIC from
    # the other law's best: that law does not beat it beyond 2 SE (8.4)
    table = [law(None, 70.5, 5.7, 0.78), own(4.0, 62.0, 5.0, 0.79), law(4.0, 55.0, 8.0, 0.80)]
    assert law_choice(table) == {"contact_law": "scenario", "impact_young_factor": 4.0}
    # ... and reported: the other law fits better, not decisively (Yade Hertz-Mindlin
    # layering 11 at 13.7 m: the linear x4 taken, Hertz-Mindlin x8 7.4 better at 4.7 SE)
    lay11 = [law(None, 82.5, 2.4, 0.632), own(4.0, 66.6, 3.8, 0.736),
             own(8.0, 66.1, 9.2, 0.688), law(8.0, 58.7, 5.1, 0.762)]
    chosen = law_choice(lay11)
    assert chosen == {"contact_law": "scenario", "impact_young_factor": 4.0}
    u = _law_undecided(lay11, chosen)
    assert u["impact_young_factor"] == 8.0 and u["delta_bic_vs_own_law"] == pytest.approx(7.4)
    assert "fits the recording better than the scenario's law at its best modulus by 7.4 in " \
        "BIC (4.7 standard error), not decisively" in _undecided_sentence(u)
    assert _law_undecided(seed30, law_choice(seed30)) is None  # the other law taken
    assert _law_undecided(table[:2], None) is None and _undecided_sentence(None) == ""

    lin = scenario.loads(SCENARIO_TOML)
    assert _law_fit_factors(lin, None) == ((), "hertz_mindlin", ())
    assert _law_fit_factors(lin, "2,4,8") == ((2.0, 4.0, 8.0), "hertz_mindlin", (2.0, 4.0, 8.0))
    assert _law_fit_factors(lin, "off") == ((), "hertz_mindlin", ())
    hz = lin.with_overrides({"soil.contact_law": "hertz_mindlin",
                             "soil.impact_young_factor": 4.0})
    assert _law_fit_factors(hz, "0.25,0.5,1") == ((1.0, 2.0, 4.0), "linear", (1.0, 2.0))
    with pytest.raises(ValueError, match=r"--law-fit='2,40': factor 40 is outside \[0.0025, 25\]"):
        _law_fit_factors(hz, "2,40")
    with pytest.raises(ValueError, match="--law-fit='x': must be comma-separated"):
        _law_fit_factors(lin, "x")
    # --law-fit-stiffness: on by default, off leaves the scenario's law at its own modulus
    from crashdem.cli import build_parser

    base = ["diagnose", "--scenario", "s.toml", "--recording", "r.csv", "--out", "o"]
    assert build_parser().parse_args(base).law_fit_stiffness == "on"
    assert build_parser().parse_args([*base, "--law-fit-stiffness", "off"]).law_fit_stiffness \
        == "off"
    with pytest.raises(SystemExit):
        build_parser().parse_args([*base, "--law-fit-stiffness", "maybe"])


def test_grain_fit_on_its_own_tier_is_anchored_through_that_tier():
    """With ``grain_fit_simulator`` the grain fit runs every realisation at every size, the
    model's grains too, on that simulator and anchors each through the tier's own baseline
    run. Stand-ins: the full model (and search) has no grain-size response, the tier has one
    (grains 1.2 x or more respond as a layer at 0.33 m does); a null recording from such
    grains. On the search's simulator the grain fit cannot move; on the tier it takes 1.25 x.
    The tier's own misfit cancels: the same tier off by a constant in every run rates every
    size the same.
    A tier whose baseline run fails is an error naming it, not a silent unanchored fit."""
    from crashdem import scenario
    from crashdem.diagnosis.catalogue import DROP
    from crashdem.diagnosis.cli import rom_from_scenario
    from crashdem.diagnosis.distributed import RADIUS_SCALE_KEY
    from crashdem.signal import Signal

    fs = {"soil_layering": DROP.full_search["soil_layering"]}
    layer = fs["soil_layering"].overrides(0.33)
    reps = [{"scenario.seed": s} for s in (2, 3)]
    calls: list = []
    rom = _scenario_rom_simulator(calls)
    tier_calls: list = []

    def tier(overrides):
        tier_calls.append(dict(overrides))
        ov = dict(overrides)
        if float(ov.get(RADIUS_SCALE_KEY, 1.0)) >= 1.2:
            ov.update(layer)
        return rom(ov)

    def offset_tier(overrides):
        """The tier off by a constant in every run (each run is aligned on the recording by its
        own onset, which a constant does not move)."""
        off = {"accel_z": 5.0, "velocity_z": 0.2}
        return {ch: Signal(v.name, v.t, v.data + off[ch], v.unit, v.cfc, dict(v.meta))
                for ch, v in tier(overrides).items()}

    truth = rom_from_scenario(scenario.loads(SCENARIO_TOML).with_overrides(layer))
    null = acquire(truth, np.random.default_rng(5))

    def run(sim):
        tier_calls.clear()
        return screen_then_confirm(simulate(RomParams()), null, rom, top_k=0, full_search=fs,
                                   replicates=reps, numerics=(), grain_fit=(1.25,),
                                   grain_fit_simulator=sim)

    on_search = run(None).fit["grain_fit"]
    assert on_search["simulator"] == "full" and on_search["chosen"] == 1.0
    assert not tier_calls

    g = run(tier).fit["grain_fit"]
    assert g["simulator"] == "grain-fit tier (anchored)" and g["chosen"] == 1.25
    assert [s["realisations"] for s in g["sizes"]] == [1 + len(reps)] * 2
    # every realisation at both sizes on the tier, its baseline run first
    assert [{k: v for k, v in c.items() if k != RADIUS_SCALE_KEY} for c in tier_calls] == \
        [{}, *reps] * 2
    assert [c.get(RADIUS_SCALE_KEY, 1.0) for c in tier_calls] == [1.0] * 3 + [1.25] * 3

    moved = run(offset_tier).fit["grain_fit"]
    assert moved["chosen"] == 1.25
    for a, b in zip(moved["sizes"], g["sizes"]):
        assert a["bic_mean"] == pytest.approx(b["bic_mean"], rel=1e-9, abs=1e-9)

    def broken(overrides):
        if not overrides:
            raise RuntimeError("bed did not settle")
        return tier(overrides)

    with pytest.raises(RuntimeError, match="the grain fit's tier: its baseline run at the "
                                           "model's grains failed .*bed did not settle"):
        run(broken)


@pytest.mark.parametrize("tiered", [False, True])
def test_grain_fit_takes_the_model_grains_runs_from_the_confirmation(layering_case, monkeypatch,
                                                                     tiered):
    """At the model's grains the grain fit rates the realisations the confirmation has run
    already (the replicates, and the search simulator's baseline run when the search runs on
    a separate tier) instead of running them again: the same sizes, BICs and choice as when
    it runs them itself, and exactly that many runs fewer (oracle: the grain fit with the
    reuse switched off, and the simulators' call counts)."""
    from crashdem.diagnosis import confirm

    reps = [{"scenario.seed": s} for s in (2, 3, 4)]

    def run(reuse):
        if not reuse:
            monkeypatch.setattr(confirm, "_reused_realisations", lambda c, n: None)
        calls: list = []
        kw = {"search_simulator": _scenario_rom_simulator(calls)} if tiered else {}
        rep = screen_then_confirm(simulate(RomParams()), layering_case.recording,
                                  _scenario_rom_simulator(calls), top_k=1, replicates=reps,
                                  grain_fit=(1.25,), **kw)
        monkeypatch.undo()
        return rep, len(calls)

    (kept, n_kept), (rerun, n_rerun) = run(True), run(False)
    g, g0 = kept.fit["grain_fit"], rerun.fit["grain_fit"]
    assert g["sizes"] == g0["sizes"] and g["chosen"] == g0["chosen"]
    assert [s["realisations"] for s in g["sizes"]] == [1 + len(reps)] * 2
    saved = len(reps) + (1 if tiered else 0)
    assert g0["runs"] - g["runs"] == saved == n_rerun - n_kept
    assert kept.simulations["grain_fit_simulations"] == g["runs"]
    assert kept.missing_physics == rerun.missing_physics == "soil_layering", kept.decision


def test_full_search_on_a_search_simulator_keeps_1_plus_top_k_full_runs(layering_case):
    """With a separate (cheaper) search simulator the levels run there (plus its baseline run
    and at most one refinement) and only the leading effects' best levels reach the full
    model, in the place of screened candidates: the full runs stay 1 + top_k."""
    full_calls: list = []
    search_calls: list = []
    top_k = 2
    rep = screen_then_confirm(simulate(RomParams()), layering_case.recording,
                              _scenario_rom_simulator(full_calls), top_k=top_k,
                              search_simulator=_scenario_rom_simulator(search_calls))
    assert len(full_calls) == rep.simulations["full_simulations"] <= 1 + top_k
    # a numerics check (when a search level stands for the named effect) runs where the search
    # ran, each factor with its own baseline run
    from crashdem.diagnosis.catalogue import DROP

    n_layering = len(DROP.full_search["soil_layering"].values)
    n_levels = sum(fs.n_levels for fs in DROP.full_search.values())
    assert n_levels == 34
    n_num = rep.simulations.get("numerics_simulations", 0)
    assert n_num == (2 * (1 + n_layering) if rep.fit["full_search"].get("named") else 0)
    n_ext = sum(lv.get("beds", 1) for lv in rep.fit["full_search"]["levels"] if lv["extension"])
    # the search simulator's baseline, the levels, the extension levels, at most one refinement
    assert 1 + n_levels + n_ext <= len(search_calls) - n_num \
        == rep.simulations["search_simulations"] <= 1 + n_levels + n_ext + 1
    assert search_calls[0] == {}  # the search simulator's own baseline run comes first
    assert rep.fit["full_search"]["tier"] == "search simulator"
    assert rep.missing_physics == "soil_layering", rep.decision


def test_two_effects_that_fit_equally_are_not_told_apart(layering_case):
    """Two searched effects whose full runs fit the recording equally well (here: both return
    the recording itself) are both decisive but within ``AMBIGUITY_MARGIN`` of each other:
    neither is named and the report lists them (``fit.confirmation_ambiguous``)."""
    calls: list = []
    full = _scenario_rom_simulator(calls, layering_case.recording,
                                   same_as_recording=("cohesion", "contact_damping"))
    rep = screen_then_confirm(simulate(RomParams()), layering_case.recording, full, top_k=2,
                              hypotheses=["cohesion", "contact_damping", "initial_conditions"])
    amb = rep.fit["confirmation_ambiguous"]
    assert set(amb) == {"cohesion", "contact_damping"}
    assert rep.missing_physics is None, rep.decision
    assert "neither named" in rep.decision
    for name in amb:
        assert "not told apart" in rep.fit["confirmation_verdicts"][name]
    # report.md heads with the pair, each with its located level and evidence
    from crashdem.diagnosis.report import to_markdown

    head = next(ln for ln in to_markdown(rep).splitlines() if ln.startswith("**Not told apart:**"))
    ev = {h["name"]: h["full_model_evidence"] for h in rep.hypotheses if h["name"] in amb}
    for name, c in amb.items():
        fs = rep.catalogue.full_search[name]
        # a search level stands for the effect: its value; a screened candidate's run: none
        where = f"{fs.parameter} = {ev[name]['value']:.3g} {fs.unit}; " if "value" in ev[name] else ""
        assert f"{name} ({where}Delta BIC {c['delta_bic_vs_reference']:.1f} over the reference" \
            in head, head
        # each run is the recording itself: it adds the layering's peak the baseline lacks,
        # and the headline says so for both
        assert ev[name]["changes"].startswith("adds the missing peak of ")
        assert f"; {ev[name]['changes']})" in head
    assert any("value" in e for e in ev.values())


def test_a_replicate_that_fits_as_well_names_nothing(layering_case, tmp_path):
    """The realisation floor: when another packing of the baseline itself (a replicate, here:
    it returns the recording) fits the recording as well as an effect does, the effect is not
    named -- its fit is no better than a realisation's. Without the replicates the same effect
    is named (the control), so the replicates are what decides."""
    kw = dict(top_k=2, hypotheses=["cohesion", "contact_damping", "initial_conditions"])
    rec = layering_case.recording
    named = screen_then_confirm(simulate(RomParams()), rec, _scenario_rom_simulator(
        [], rec, same_as_recording=("cohesion",)), **kw)
    assert named.missing_physics == "cohesion", named.decision
    assert "realisation" not in named.fit
    assert named.fit["confirmation_verdicts"]["cohesion"] == "named"
    calls: list = []
    reps = [{"scenario.seed": 2}, {"scenario.seed": 3}]
    rep = screen_then_confirm(simulate(RomParams()), rec, _scenario_rom_simulator(
        calls, rec, same_as_recording=("cohesion", "replicate")), replicates=reps, **kw)
    assert rep.missing_physics is None, rep.decision
    # the answer heads the report: the recalibration, else the named effect
    assert rep.best == "recalibration" and rep.hypotheses[0]["name"] == "recalibration"
    assert named.best == "cohesion" and named.hypotheses[0]["name"] == "cohesion"
    rf = rep.fit["realisation"]
    assert rf["tier"] == "full simulator" and len(rf["runs"]) == 2
    assert [r["overrides"] for r in rf["runs"]] == reps
    cohesion = max(r["delta_bic_vs_reference"] for r in rep.fit["confirmation"]
                   if r["hypothesis"] == "cohesion")
    # the replicate fits exactly as well with one parameter fewer
    assert rf["floor_delta_bic"] > cohesion > 10.0
    assert sum("scenario.seed" in c for c in calls) == 2
    assert "realisation floor of 2 replicate packings" in rep.decision
    # and the report says why, per effect
    why = rep.fit["confirmation_verdicts"]
    assert why["cohesion"].startswith("fits no better than a replicate packing"), why
    assert "named" not in why.values()
    md = write_report(rep, tmp_path, plots=False)["md"]
    text = Path(md).read_text()
    assert "Realisation floor (2 replicate packings" in text
    assert f"scatters by {rf['scatter_delta_bic']:.1f} (sample standard deviation)" in text
    assert "| scenario.seed=3 |" in text
    assert f"| cohesion | {why['cohesion']} |" in text


def test_verdict_of_a_screening_claim_that_another_effect_replaces(layering_case):
    """The screening claims the layering; its full run (here: 80 % of its change on the baseline,
    so better than the reference but not exact) stands, but a searched cohesion level
    reproduces the recording and replaces it. The layering's verdict says so -- not that its
    run was decisively worse."""
    from crashdem.signal import Signal

    inner = _scenario_rom_simulator([], layering_case.recording, same_as_recording=("cohesion",))

    def full(ov):
        out = inner(ov)
        if not ov.get("physics.soil_layering.enabled"):
            return out
        off = inner({k: v for k, v in ov.items() if not k.startswith("physics.soil_layering.")})
        return {ch: Signal(ch, s.t, 0.8 * s.data + 0.2 * off[ch].data, s.unit, s.cfc)
                for ch, s in out.items()}

    rep = screen_then_confirm(simulate(RomParams()), layering_case.recording, full, top_k=2,
                              hypotheses=["soil_layering", "cohesion", "initial_conditions"])
    by = {h["name"]: h for h in rep.hypotheses}
    assert by["soil_layering"]["screening_rank"] == 1  # the screening's claim
    assert rep.missing_physics == "cohesion", rep.decision
    assert rep.hypotheses[0]["name"] == "cohesion"  # the answer ranks first
    why = rep.fit["confirmation_verdicts"]
    assert why["cohesion"] == "named"
    assert why["soil_layering"].startswith("the screening's claim stood"), why
    assert "cohesion's full run beats it" in why["soil_layering"]


def _layer_share_simulator(case, claim: float, rival: float, replicate: float | None = None):
    """A full simulator on the screening model whose layering runs carry the share ``claim`` of
    ``case``'s concealed layer's change on the baseline, its cohesion runs the share ``rival``
    and its replicate packings (``scenario.seed``) the share ``replicate`` (None: the
    baseline); every other run is the scenario's."""
    from crashdem.signal import Signal

    inner = _scenario_rom_simulator([], case.recording)
    v = case.values
    truth = {"physics.soil_layering.enabled": True,
             "physics.soil_layering.depth": v["interface_depth"],
             "physics.soil_layering.lower_young_factor": v["strength_ratio"]}

    def full(ov):
        share = (claim if ov.get("physics.soil_layering.enabled") else
                 rival if ov.get("physics.cohesion.enabled") else
                 replicate if "scenario.seed" in ov else None)
        base = {k: x for k, x in ov.items() if k != "scenario.seed"
                and not k.startswith(("physics.soil_layering.", "physics.cohesion."))}
        off = inner(base)
        if share is None:
            return off
        on = inner({**base, **truth})
        return {ch: Signal(ch, s.t, share * s.data + (1.0 - share) * off[ch].data, s.unit,
                           s.cfc) for ch, s in on.items()}
    return full


def test_a_claim_outranked_in_likelihood_by_a_decisive_rival_is_not_named(layering_case):
    """The screening claims the layering and its full runs stand (80 % of the concealed layer's
    change on the baseline); a searched cohesion level fits the recording with a higher
    likelihood (its runs carry 85 % of it), decisively, but does not score ``CONFIRM_MIN_GAIN``
    higher. The claim used to be named by its score alone; now the two are not told apart
    and neither is named. Measured on Yade's floor recording 12 at 18.45 m through the command
    line: the screening claimed a layer, its full run Delta BIC 27.7 (score 0.809) against the
    floor's 0.5 m level 30.8 (0.751), and the layer was named, wrongly. Control: a rival of
    lower likelihood (75 %) leaves the claim named."""
    from crashdem.diagnosis.confirm import CONFIRM_MIN_GAIN

    def mixed(share_claim, share_rival):
        return _layer_share_simulator(layering_case, share_claim, share_rival)

    kw = dict(top_k=2, hypotheses=["soil_layering", "cohesion", "initial_conditions"])
    base = simulate(RomParams())
    rep = screen_then_confirm(base, layering_case.recording, mixed(0.8, 0.85), **kw)
    by = {h["name"]: h for h in rep.hypotheses}
    assert by["soil_layering"]["screening_rank"] == 1  # the screening's claim
    amb = rep.fit["confirmation_ambiguous"]
    assert set(amb) == {"soil_layering", "cohesion"}, rep.decision
    # the premise: the rival is decisive, fits better in likelihood, and not by the score margin
    rival, claim = amb["cohesion"], amb["soil_layering"]
    assert rival["delta_bic_vs_reference"] > claim["delta_bic_vs_reference"]
    assert rival["score"] - claim["score"] < CONFIRM_MIN_GAIN
    assert rep.missing_physics is None, rep.decision
    assert "neither named" in rep.decision and "higher likelihood" in rep.decision
    why = rep.fit["confirmation_verdicts"]
    assert why["soil_layering"].startswith("the screening's claim") and \
        "not told apart" in why["soil_layering"], why
    assert "not told apart" in why["cohesion"] and "higher likelihood" in why["cohesion"], why
    # control: a rival of lower likelihood leaves the claim named
    kept = screen_then_confirm(base, layering_case.recording, mixed(0.8, 0.75), **kw)
    assert kept.missing_physics == "soil_layering", kept.decision
    assert "confirmation_ambiguous" not in kept.fit


def test_a_standing_claim_with_a_rival_better_on_both_counts_is_not_named(layering_case):
    """A screening claim stands when its full run is not decisively worse than the realisation
    floor; a rival is named only with ``CONFIRM_MIN_GAIN`` in score over that floor. A rival
    that beats the claim *and* the floor in likelihood and score, but is under that margin,
    used to leave the claim named: the rival was held to a margin the claim was not. Now the
    two are not told apart. Stand-in: the layering claim's runs carry 80 % of the concealed
    layer's change, the replicate packings 78 % (the floor), the cohesion rival's 85 %.
    Measured through the command line on the Yade 5 m floor recording 11: the claimed layer
    (Delta BIC 15.4, score 0.842; floor 10.5, 0.837) was named beside the floor's 0.9 m level
    (20.5, 0.847). Control: a rival of 75 % (worse than the floor) leaves the claim named."""
    from crashdem.diagnosis.confirm import CONFIRM_MIN_GAIN

    def mixed(share_rival):
        return _layer_share_simulator(layering_case, 0.8, share_rival, replicate=0.78)

    kw = dict(top_k=2, hypotheses=["soil_layering", "cohesion", "initial_conditions"],
              replicates=[{"scenario.seed": 2}, {"scenario.seed": 3}])
    base = simulate(RomParams())
    rep = screen_then_confirm(base, layering_case.recording, mixed(0.85), **kw)
    by = {h["name"]: h for h in rep.hypotheses}
    assert by["soil_layering"]["screening_rank"] == 1  # the screening's claim
    rf = rep.fit["realisation"]
    floor = {"delta_bic": rf["floor_delta_bic"], "score": rf["floor_score"]}
    amb = rep.fit["confirmation_ambiguous"]
    assert set(amb) == {"soil_layering", "cohesion"}, rep.decision
    rival, claim = amb["cohesion"], amb["soil_layering"]
    # the premise: the claim stands by the lenient rule and is not decisive itself; the rival
    # beats it and the floor on both counts, short of the score margin over the floor
    assert floor["delta_bic"] < claim["delta_bic_vs_reference"] < rival["delta_bic_vs_reference"]
    assert floor["score"] < claim["score"] < rival["score"]
    assert rival["score"] - floor["score"] < CONFIRM_MIN_GAIN
    assert rep.missing_physics is None, rep.decision
    assert "higher likelihood and a higher score than soil_layering" in rep.decision
    assert "neither named" in rep.decision
    why = rep.fit["confirmation_verdicts"]
    assert why["soil_layering"].startswith("the screening's claim") and \
        "not told apart" in why["soil_layering"], why
    assert why["cohesion"].startswith("fits with a higher likelihood and score than the "
                                      "screening's claim soil_layering"), why
    # control: a rival that fits worse than the floor leaves the claim named
    kept = screen_then_confirm(base, layering_case.recording, mixed(0.75), **kw)
    assert kept.missing_physics == "soil_layering", kept.decision
    assert "confirmation_ambiguous" not in kept.fit


def test_replicates_run_on_the_search_simulator(layering_case):
    """With a search simulator the replicates run there, next to its baseline run, and set the
    floor of the promotion, with the bed made stiffer; the concealed layering (far above a
    replicate, which here is the baseline again: the ROM has no packing) is still named, and
    the full runs stay 1 + top_k. Fails when the screening's claim is held to the stiffer-soil
    runs on the search tier."""
    full_calls: list = []
    search_calls: list = []
    reps = [{"scenario.seed": s} for s in (2, 3, 4)]
    rep = screen_then_confirm(simulate(RomParams()), layering_case.recording,
                              _scenario_rom_simulator(full_calls), top_k=2,
                              search_simulator=_scenario_rom_simulator(search_calls),
                              replicates=reps)
    assert len(full_calls) == rep.simulations["full_simulations"] <= 3
    # the replicates (on a search simulator a deposited level runs on one bed by default:
    # test_level_beds.py)
    assert [c for c in search_calls if "scenario.seed" in c
            and not any(k.startswith("physics.") for k in c)] == reps
    assert not any("scenario.seed" in c for c in full_calls)
    n_num = rep.simulations.get("numerics_simulations", 0)
    assert rep.simulations["search_simulations"] == len(search_calls) - n_num
    rf = rep.fit["realisation"]
    assert rf["tier"] == "search simulator" and len(rf["runs"]) == 3
    # the replicate is the search baseline itself
    assert all(abs(r["delta_bic_vs_reference"]) < 1e-9 for r in rf["runs"])
    # the floor there also holds the bed made stiffer (one bed each here); the screening's
    # claim is held to the replicates' part of it (``_search_support``): the bed x2 stiffer
    # below 0.15 m out-fits every x5 level of this x1.9 layer, and the claim stands
    stiff = rf["stiffer_soil"]
    assert [(s["form"], s["young_factor"], s["runs"]) for s in stiff] == [
        ("whole bed", 2.0, 1), ("whole bed", 5.0, 1), ("below 0.15 m", 2.0, 1),
        ("below 0.15 m", 5.0, 1)]
    assert rf["floor_delta_bic"] == pytest.approx(
        max(0.0, *(s["delta_bic_vs_reference"] for s in stiff)))
    assert rf["floor_delta_bic"] > 50.0
    assert rep.missing_physics == "soil_layering", rep.decision
    verdicts = rep.fit["full_search"]["verdicts"]  # the search tier says what it promoted
    assert set(verdicts) <= set(rep.fit["full_search"]["best"])
    assert all(v == "promoted to a full run" or v.startswith("not promoted: ")
               for v in verdicts.values())


def test_a_floor_above_the_layer_interface_ends_the_column(tmp_path):
    """The reference drop scenarios have a compacted layer below 1 m. A hypothesis's rigid floor
    at or above that interface ends the soil column there, so its run has no lower layer
    (``distributed.scenario_overrides``); a deeper floor keeps it, and so do overrides that set
    the layering themselves. The full-model search of such a scenario therefore runs every floor
    level (before, the 0.6-0.9 m levels failed the scenario check and were dropped)."""
    scenario = pytest.importorskip("crashdem.scenario")
    from crashdem.diagnosis.catalogue import DROP
    from crashdem.diagnosis.cli import _runnable, _search_setup
    from crashdem.diagnosis.distributed import scenario_overrides
    from crashdem.diagnosis.generator_dem import scenario_path

    scen = scenario.load(scenario_path())
    assert scen.get("physics.soil_layering.enabled")
    assert scen.get("physics.soil_layering.depth") == 1.0
    floor = {"physics.boundary_proximity.enabled": True}
    for depth, layered in ((0.6, False), (1.0, False), (1.05, True), (1.25, True)):
        ov = scenario_overrides(scen, {**floor, "physics.boundary_proximity.floor_depth": depth})
        assert ov.get("physics.soil_layering.enabled", True) is layered, depth
        assert _runnable(scen, ov)
    own = {**floor, "physics.boundary_proximity.floor_depth": 0.6,
           "physics.soil_layering.enabled": True}
    assert scenario_overrides(scen, own)["physics.soil_layering.enabled"] is True
    assert not _runnable(scen, own)  # a layer interface below the floor is refused
    searched, _, _ = _search_setup(scen, False, "coarse", {}, tmp_path)
    assert searched["boundary_proximity"].values == DROP.full_search["boundary_proximity"].values
    assert "soil_layering" not in searched  # the scenario has it switched on


def test_cli_replicates_option():
    """``--replicates``: seeds scenario.seed + 1 ... + N; by default 4 with the full-model search
    and none without; a count outside 0-32 is refused naming the option and the range."""
    scenario = pytest.importorskip("crashdem.scenario")
    from crashdem.diagnosis.cli import DEFAULT_REPLICATES, _replicates

    scen = scenario.loads(SCENARIO_TOML).with_overrides({"scenario.seed": 7})
    assert _replicates(scen, None, True) == [{"scenario.seed": 7 + i}
                                             for i in range(1, DEFAULT_REPLICATES + 1)]
    assert _replicates(scen, None, False) == []
    assert _replicates(scen, 2, False) == [{"scenario.seed": 8}, {"scenario.seed": 9}]
    for bad in (-1, 33):
        with pytest.raises(ValueError, match=r"--replicates=.*\[0, 32\]"):
            _replicates(scen, bad, True)


def test_full_search_levels_and_vertex():
    """``FullSearch``: levels must ascend, a log scale needs positive levels; ``located``
    excludes the last level towards the fading end and the interval before it; the refinement
    vertex of an exact parabola in Delta BIC is its maximum."""
    from crashdem.diagnosis.catalogue import FullSearch
    from crashdem.diagnosis.confirm import _search_vertex

    with pytest.raises(ValueError, match="ascending"):
        FullSearch("d", "m", ("k",), (0.5, 0.4))
    with pytest.raises(ValueError, match="log"):
        FullSearch("c", "Pa", ("k",), (0.0, 1.0), scale="log")
    with pytest.raises(ValueError, match="fades"):
        FullSearch("d", "m", ("k",), (0.1, 0.2), fades="sideways")
    deep = FullSearch("floor_depth", "m", ("k",), (0.6, 0.7, 0.8, 0.9))
    assert deep.located(0.6) and deep.located(0.8) and not deep.located(0.85)
    assert not deep.located(0.9)
    weak = FullSearch("cohesion", "Pa", ("k",), (1e4, 2e4, 4e4), scale="log", fades="low")
    assert not weak.located(1e4) and not weak.located(1.5e4) and weak.located(2e4)
    assert deep.overrides(0.7) == {"k": 0.7}
    rows = [{"hypothesis": "b", "search_value": x,
             "delta_bic_vs_reference": 50.0 - 1000.0 * (x - 0.73) ** 2} for x in deep.values]
    best = max(rows, key=lambda r: r["delta_bic_vs_reference"])
    v = _search_vertex(best, rows, deep)
    assert v["value"] == pytest.approx(0.73, abs=1e-9)
    assert _search_vertex(rows[0], rows, deep) is None  # an edge level has no bracket


def test_cli_diagnose_end_to_end(tmp_path):
    """``crashdem diagnose`` on a CSV recording written by ``crashdem.recordings``."""
    recordings = pytest.importorskip("crashdem.recordings")
    pytest.importorskip("crashdem.cli")
    case = concealed_case(32, "structural_crush")
    rec_path = tmp_path / "rec.csv"
    recordings.write_recording(rec_path, case.recording)
    rc, d = _cli_rom_diagnose(tmp_path, rec_path)
    assert rc == 0
    assert d["missing_physics"] == "structural_crush"
    assert d["simulations"]["baseline_source"] == "rom"
    assert (tmp_path / "out" / "overlay_accel_z.png").exists()


def test_cli_diagnose_refuses_a_directory_another_diagnosis_writes(tmp_path, capsys):
    """Two ``crashdem diagnose`` into one ``--out``: their runs write fixed file names there, so
    the second is refused at once (``DIR/report.lock``), naming the directory, and writes
    nothing; once the first is gone the directory is free again."""
    import fcntl
    import os

    rec_path = tmp_path / "missing.csv"  # never read while the directory is taken
    (tmp_path / "out").mkdir()
    fd = os.open(tmp_path / "out" / "report.lock", os.O_RDWR | os.O_CREAT)
    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)  # a diagnosis running there
    try:
        rc, d = _cli_rom_diagnose(tmp_path, rec_path)
    finally:
        os.close(fd)
    assert rc == 2 and d is None
    err = capsys.readouterr().err
    assert "another diagnosis is writing into this directory now" in err and "report.lock" in err
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["report.lock"]
    rc, _ = _cli_rom_diagnose(tmp_path, rec_path)  # free: now it fails on the recording itself
    err = capsys.readouterr().err
    assert rc == 2 and "another diagnosis" not in err and "missing.csv" in err
    assert not (tmp_path / "out" / "report.lock").exists()


def test_cli_rom_baseline_filter_class(tmp_path):
    """``crashdem diagnose --baseline rom`` on a CSV recording filtered at CFC 180 that does not
    say so: the class is measured and the ROM baseline is compared at it (its raw channels are
    simulated), named ``sensor_dynamics`` with the class."""
    from crashdem import recordings
    from crashdem.diagnosis.generator import acquire

    rec = acquire(RomParams(), np.random.default_rng(12), cfc=180.0)
    rec_path = recordings.write_recording(tmp_path / "rec.csv",
                                          {k: replace(s, cfc=None) for k, s in rec.items()})
    rc, d = _cli_rom_diagnose(tmp_path, rec_path)
    assert rc == 0
    assert d["missing_physics"] == "sensor_dynamics", d["decision"]
    assert d["fit"]["filter_class"]["class"] == 180.0
    assert d["fit"]["filter_class"]["channels"]["accel_z"]["refilter"] == "from the raw channel"


def test_cli_units_given_on_the_command_line(tmp_path):
    """A plain CSV (header ``time,accel_z,velocity_z``, no units) diagnosed with ``--unit``;
    without it the error names the column and the option."""
    from crashdem.diagnosis.generator import acquire

    rec = acquire(RomParams(speed_offset=-2.0), np.random.default_rng(13))
    a, v = rec["accel_z"], rec["velocity_z"]
    rows = "\n".join(f"{float(t)!r},{float(x)!r},{float(y)!r}"
                      for t, x, y in zip(a.t, a.data / 9.80665, v.data))
    path = tmp_path / "plain.csv"
    path.write_text("time,accel_z,velocity_z\n" + rows + "\n", encoding="utf-8")
    assert _cli_rom_diagnose(tmp_path, path)[0] != 0  # no units: refused with the column named
    rc, d = _cli_rom_diagnose(tmp_path, path, "--unit", "accel_z=g", "--unit", "velocity_z=m/s")
    assert rc == 0
    assert d["missing_physics"] == "initial_conditions", d["decision"]


def test_cli_leaves_out_a_channel_it_cannot_read(tmp_path, capsys):
    """A recording with a column in a unit crashdem does not know (another code's temperature
    in degC) beside the channels the diagnosis uses is diagnosed as without it; the report
    says which channel was left out and why. A channel the diagnosis reads by its name that
    cannot be read (``accel_z`` in a unit it does not know) is an error naming it, not a
    diagnosis on the velocity alone. A column of another name in an unknown unit is left out
    like the temperature (nothing tells it from one), and the report says so."""
    from crashdem.diagnosis.generator import acquire

    rec = acquire(RomParams(speed_offset=-2.0), np.random.default_rng(13))
    a, v = rec["accel_z"], rec["velocity_z"]
    rows = "\n".join(f"{float(t)!r},{float(x)!r},{float(y)!r},21.5"
                      for t, x, y in zip(a.t, a.data, v.data))
    path = tmp_path / "extra.csv"
    path.write_text("time [s],accel_z [m/s^2],velocity_z [m/s],temperature [degC]\n" + rows
                    + "\n", encoding="utf-8")
    rc, d = _cli_rom_diagnose(tmp_path, path)
    assert rc == 0
    assert d["missing_physics"] == "initial_conditions", d["decision"]
    assert "unknown unit 'degC'" in d["fit"]["recorded_channels_skipped"]["temperature"]
    assert "Not used, unusable: `temperature`" in (tmp_path / "out" / "report.md").read_text()
    bad = tmp_path / "bad.csv"
    bad.write_text(path.read_text().replace("accel_z [m/s^2]", "accel_z [furlong/s^2]"),
                   encoding="utf-8")
    from crashdem import cli

    capsys.readouterr()
    assert cli.main(["diagnose", "--scenario", str(tmp_path / "s.toml"), "--recording",
                     str(bad), "--out", str(tmp_path / "out2"), "--baseline", "rom"]) != 0
    err = capsys.readouterr().err
    assert "channel 'accel_z': unknown unit 'furlong/s^2'" in err, err
    # a column of another name in an unknown unit cannot be told from a temperature: it is
    # left out, and the report says so beside a diagnosis of what remains (the velocity)
    other = tmp_path / "other.csv"
    other.write_text(bad.read_text().replace("accel_z [furlong/s^2]", "acc [furlong/s^2]")
                     .replace("velocity_z [m/s]", "vel [m/s]"), encoding="utf-8")
    rc, d = _cli_rom_diagnose(tmp_path, other)
    assert rc == 0 and set(d["fit"]["recorded_channels"]) == {"velocity_z"}
    assert set(d["fit"]["recorded_channels_skipped"]) == {"acc", "temperature"}


def test_recording_units_do_not_matter(layering_case):
    """Same diagnosis when the recorded acceleration is given in g (converted to SI on entry)."""
    from crashdem.signal import G0, Signal

    a = layering_case.recording["accel_z"]
    rec_g = dict(layering_case.recording)
    rec_g["accel_z"] = Signal("accel_z", a.t, a.data / G0, "g", a.cfc)
    rep = diagnose(simulate(RomParams()), rec_g)
    assert rep.missing_physics == "soil_layering"
    h = rep.hypotheses[0]
    for k, v in layering_case.values.items():
        assert abs(h["parameters"][k] / v - 1.0) < 0.15
    assert "adds the missing peak" in h["evidence"] or "removes" in h["evidence"]


def test_channel_map_finds_channels_of_other_codes():
    """Recordings from other codes name their channels differently: crashdem's impactor names,
    ISO/TS 13499 codes (dimension AC/VE, direction Z) and a unique channel of the right unit are
    matched to the model channels; ambiguity or no match is an error naming what was recorded."""
    from crashdem.diagnosis.cli import _channel_map
    from crashdem.signal import Signal

    t = np.linspace(0.0, 0.1, 11)

    def s(unit):
        return Signal("x", t, np.zeros_like(t), unit, None, {})

    assert _channel_map(None, {"acc": s("g"), "vel": s("m/s"), "F": s("kN")}) == {
        "acc": "accel_z", "vel": "velocity_z"}
    assert _channel_map(None, {"10HEAD0000CGACZD": s("g"), "10HEAD0000CGACXD": s("g"),
                               "10HEAD0000CGVEZD": s("m/s")}) == {
        "10HEAD0000CGACZD": "accel_z", "10HEAD0000CGVEZD": "velocity_z"}
    assert _channel_map(None, {"drop_mass_accel_z": s("m/s^2"),
                               "drop_mass_accel_x": s("m/s^2")}) == {"drop_mass_accel_z": "accel_z"}
    assert _channel_map(None, {"ax": s("g"), "az": s("g")}) == {"az": "accel_z"}
    with pytest.raises(ValueError, match="no recorded channel found.*Pa"):
        _channel_map(None, {"p": s("Pa")})
    with pytest.raises(ValueError, match="a1"):
        _channel_map(None, {"a1": s("g"), "a2": s("g")})


def test_channel_map_reads_force_and_position_of_other_codes():
    """Another DEM code writes the contact force on the impactor and its position rather than
    an acceleration and a velocity: without an acceleration, a unique force channel (unit N/kN,
    or ISO dimension FO along Z) stands for ``accel_z`` and is divided by the impactor mass;
    without a velocity, a unique length channel (m/mm, or ISO DS along Z) stands for
    ``velocity_z`` and is differentiated. A channel whose unit cannot stand for its model
    channel is an error naming the channel, its unit and the units accepted."""
    from crashdem.diagnosis.cli import _channel_map, _convert
    from crashdem.signal import Signal

    t = np.linspace(0.0, 0.1, 101)

    def s(unit, data=None, name="x"):
        return Signal(name, t, np.zeros_like(t) if data is None else data, unit, None, {})

    assert _channel_map(None, {"Fz": s("kN"), "z": s("m")}) == {"Fz": "accel_z", "z": "velocity_z"}
    assert _channel_map(None, {"10SPHE0000CGFOZD": s("N"), "10SPHE0000CGFOXD": s("N"),
                               "10SPHE0000CGDSZD": s("mm")}) == {
        "10SPHE0000CGFOZD": "accel_z", "10SPHE0000CGDSZD": "velocity_z"}
    # an acceleration or velocity present is preferred to a force or position
    assert _channel_map(None, {"a": s("g"), "F": s("N"), "z": s("m")}) == {
        "a": "accel_z", "z": "velocity_z"}
    # conversions: 1.7 kN on 850 kg is 2 m/s^2; z = 3 - 5 t^2 [mm] gives v = -10 t mm/s
    a, how = _convert(s("kN", np.full_like(t, 1.7)), "accel_z", 850.0)
    assert a.unit == "m/s^2" and np.allclose(a.data, 2.0) and "850 kg" in how
    v, how = _convert(s("mm", 3.0 - 5.0 * t**2), "velocity_z", 850.0)
    assert v.unit == "m/s" and np.allclose(v.data[1:-1], -0.01 * t[1:-1]) and "derivative" in how
    same, how = _convert(s("g"), "accel_z", 850.0)
    assert how is None and same.unit == "g"
    with pytest.raises(ValueError, match=r"p:accel_z.*'Pa'.*m/s\^2 or N"):
        _convert(s("Pa", name="p"), "accel_z", 850.0)
    with pytest.raises(ValueError, match=r"v:velocity_z.*'g'.*m/s or m"):
        _convert(s("g", name="v"), "velocity_z", 850.0)


def test_cli_diagnoses_a_force_and_penetration_recording(tmp_path):
    """A recording as another code would write it -- contact force [kN] and penetration [mm],
    positive down, no acceleration or velocity -- diagnosed by the CLI: the speed offset of the
    truth (-2.5 m/s) is named, its value within 2 % (read from the differentiated free fall),
    and the report says how each model channel was obtained."""
    from scipy.integrate import cumulative_trapezoid

    from crashdem import recordings
    from crashdem.diagnosis.generator import acquire
    from crashdem.signal import Signal

    rec = acquire(RomParams(speed_offset=-2.5), np.random.default_rng(14))
    a, v = rec["accel_z"], rec["velocity_z"]
    force = Signal("F_contact", a.t, a.data * RomParams().mass / 1e3, "kN", a.cfc)
    pen = Signal("penetration", v.t, -1e3 * cumulative_trapezoid(v.data, v.t, initial=0.0),
                 "mm", v.cfc)
    rec_path = recordings.write_recording(tmp_path / "rec.csv", [force, pen])
    rc, d = _cli_rom_diagnose(tmp_path, rec_path)
    assert rc == 0
    assert d["missing_physics"] == "initial_conditions", d["decision"]
    h = next(h for h in d["hypotheses"] if h["name"] == "initial_conditions")
    assert h["parameters"]["speed_offset"] == pytest.approx(-2.5, rel=0.02)
    conv = d["fit"]["recorded_channels"]
    assert conv["accel_z"]["recorded"] == "F_contact" and "mass" in conv["accel_z"]["converted"]
    assert conv["velocity_z"]["recorded"] == "penetration"
    assert "derivative" in conv["velocity_z"]["converted"]
    assert d["fit"]["sign_convention"]["velocity_z"]["flipped"]


def test_confirmation_falls_back_to_local_runs_when_the_cluster_is_unusable():
    """A Dask simulator that cannot start (OSError) hands the batch to the in-process runner
    once and says why; a failed run (RuntimeError) is not masked."""
    from crashdem.diagnosis.cli import _LocalFallback

    class Broken:
        def map(self, batch):
            raise OSError("no free port")

        def describe(self):
            return {"scheduler": None}

    prepared = []
    fb = _LocalFallback(Broken(), lambda ov: {"ran": ov}, lambda: prepared.append(1))
    assert fb.map([{"a": 1}, {"a": 2}]) == [{"ran": {"a": 1}}, {"ran": {"a": 2}}]
    assert fb({"a": 3}) == {"ran": {"a": 3}}
    assert prepared == [1] and "OSError: no free port" in fb.describe()["fallback_in_process"]

    class Failing:
        def map(self, batch):
            raise RuntimeError("full-simulation confirmation: 1 of 1 runs failed")

    with pytest.raises(RuntimeError, match="runs failed"):
        _LocalFallback(Failing(), lambda ov: ov, lambda: None).map([{}])


def test_cli_diagnoses_a_glider_recording(tmp_path):
    """``crashdem diagnose`` on a glider scenario (``validation/scenarios/glider_real.toml``):
    the planar model is built from the scenario's fuselage, slope, rear wall and sensors
    (``cli.planar_from_scenario``), the recording's ``rear_accel_x`` / ``rear_accel_z`` /
    ``pitch_rate`` are matched by the glider's names, and a crushable nose concealed in a
    planar-truth recording (other step, nose size and mount position) is named with its
    crush force and stroke within 15 %, the report saying which catalogue was used."""
    from pathlib import Path

    from crashdem import cli, recordings
    from crashdem import scenario as sc
    from crashdem.diagnosis.cli import planar_from_scenario
    from crashdem.diagnosis.generator_planar import planar_concealed_case

    toml = Path(__file__).resolve().parents[3] / "validation" / "scenarios" / "glider_real.toml"
    base = planar_from_scenario(sc.load(toml))
    assert base.soil.mass == pytest.approx(343.0) and base.slope == pytest.approx(math.pi / 4)
    assert 1.0 < base.wall_distance < 2.4 and base.nose_offset > 1.0
    case = planar_concealed_case(11, "structural_crush", base=base)
    names = {"accel_x": "rear_accel_x", "accel_z": "rear_accel_z", "pitch_rate": "pitch_rate"}
    rec_path = recordings.write_recording(
        tmp_path / "glider.csv", {names[k]: replace(s, name=names[k]) for k, s in case.recording.items()})
    out = tmp_path / "out"
    rc = cli.main(["diagnose", "--scenario", str(toml), "--recording", str(rec_path),
                   "--out", str(out), "--baseline", "rom"])
    assert rc == 0
    d = json.loads((out / "report.json").read_text())
    assert d["catalogue_model"] == "planar"
    assert d["channels"] == ["accel_x", "accel_z", "pitch_rate"]
    assert d["missing_physics"] == "structural_crush", d["decision"]
    h = d["hypotheses"][0]
    for k, v in case.values.items():
        assert abs(h["parameters"][k] / v - 1.0) < 0.15, (k, h["parameters"][k], v)
    assert h["scenario_overrides"]["physics.structural_crush.enabled"] is True
    assert (out / "overlay_accel_x.png").exists() and (out / "overlay_pitch_rate.png").exists()


def test_result_channels_ignore_a_failed_sensor_elsewhere_in_the_run(tmp_path):
    """A run whose nose accelerometer is marked failed (NaN after its failure, by design) is
    still read for the diagnosed channels: the full-DEM confirmation of a glider candidate
    must not be lost to an unrelated channel (it was: a pitch-offset run of the small glider
    broke the front pair). The channels read are the stored CFC-filtered ones, named by the
    model."""
    from crashdem.diagnosis.cli import _result_channels
    from crashdem.results import ResultWriter, open_result
    from crashdem.sensors import Accelerometer, BodyState, Gyroscope, SensorSet
    from crashdem.signal import G0

    ss = SensorSet([
        Accelerometer(name="rear_accel_x", body="glider", position=(-2.0, 0, 0.1),
                      axis=(1, 0, 0), full_scale=250 * G0, cfc=60),
        Accelerometer(name="front_accel_z", body="glider", position=(1.5, 0, 0),
                      axis=(0, 0, 1), full_scale=5 * G0, failure_factor=1.2, cfc=60),
        Gyroscope(name="pitch_rate", body="glider", cfc=60)], fs=12500.0)
    path = tmp_path / "run.h5"
    with ResultWriter(path, scenario_toml='title = "g"\n', parameters={"title": "g"}) as w:
        w.declare_sensors(ss)
        for i in range(2000):
            t = i * 3.0e-5
            pulse = 15 * G0 * math.sin(math.pi * t / 0.06) ** 2
            ss.record(t, {"glider": BodyState(position=(0, 0, 1), rotation=np.eye(3),
                                              acceleration=(pulse, 0, pulse),
                                              angular_velocity=(0, -math.sin(40 * t), 0))}, {})
        w.append_sensors(ss)
    with open_result(path) as res:
        assert not np.all(np.isfinite(res["front_accel_z"].data))  # the failure is real
        want = res["rear_accel_x"].data
    got = _result_channels(path, {"rear_accel_x": "accel_x", "pitch_rate": "pitch_rate",
                                  "accel_z": "accel_z"})
    assert got["accel_z"] is None  # no rear_accel_z in this run
    assert np.array_equal(got["accel_x"].data, want) and got["accel_x"].cfc == 60.0
    assert got["pitch_rate"].unit == "rad/s"


def test_library_screening_model_follows_the_given_impact_speed():
    """``diagnose(base, rec, impact_speed=v)`` without ``rom_base`` screens with the sphere drop
    at ``v`` (a 5 m drop here, not the default 16.4 m/s), so it reproduces the baseline without
    a model-error floor; a +3 m/s offset of a 9.9 m/s impact is
    measured and named, its value within 2 %; a ``rom_base`` at another speed than
    ``impact_speed`` is refused, naming both. Oracle: the truth's offset. Measured before the
    fix, on a Yade recording of a 5 m drop with +3.25 m/s: the screening model at 16.4 m/s read
    the impact as model error (8.8 g RMS) and named nothing."""
    from crashdem.diagnosis import _drop_rom

    v = math.sqrt(2.0 * 9.81 * 5.0)
    base = simulate(RomParams(impact_speed=v))
    rec = acquire(RomParams(impact_speed=v, speed_offset=3.0), np.random.default_rng(5))
    rep = diagnose(base, rec, impact_speed=v)
    # the screening model reproduces the (ROM) baseline: no model-error floor (at 16.4 m/s:
    # 193 m/s^2 against a 473 m/s^2 peak, measured)
    peak = float(np.max(np.abs(base["accel_z"].data)))
    assert rep.fit.get("model_error", {}).get("accel_z", {}).get("sigma", 0.0) < 0.05 * peak
    assert rep.missing_physics == "initial_conditions", rep.decision
    h = next(h for h in rep.hypotheses if h["name"] == "initial_conditions")
    assert h["parameters"]["speed_offset"] == pytest.approx(3.0, rel=0.02)
    assert _drop_rom(None, v).v0 == pytest.approx(v)
    assert _drop_rom(None, None) == RomParams()
    with pytest.raises(ValueError, match=r"impact_speed=9\.9.*rom_base\.v0 is 16\.4"):
        diagnose(base, rec, impact_speed=v, rom_base=RomParams())


@pytest.mark.parametrize("replicate_bics, named", [((-10.0, 5.0), None), ((0.0, 1.0), "a")])
def test_two_effects_closer_than_the_realisation_scatter_are_not_told_apart(replicate_bics,
                                                                            named):
    """Two decisive effects 3 apart in Delta BIC (30 and 27): with replicates whose Delta BIC
    scatters by 10.6 (sample standard deviation of -10 and 5) a realisation moves each run by
    more than the gap, so neither is named (``fit.confirmation_ambiguous``); with replicates
    that scatter by 0.7 the margin is ``AMBIGUITY_MARGIN`` (2) and the better one is named.
    Oracle: the rule written out (margin = max(2, scatter))."""
    from crashdem.diagnosis import AMBIGUITY_MARGIN
    from crashdem.diagnosis.confirm import (
        REPLICATE,
        _ambiguity_margin,
        _Confirmation,
        _FullTier,
        _realisation_floor,
    )

    rows = [_run("recalibration", 0.0, 0.70), _run("a", 30.0, 0.90), _run("b", 27.0, 0.90)] + [
        _run(REPLICATE, db, 0.72) for db in replicate_bics]
    floor = _realisation_floor(rows, 0.70)
    assert floor["scatter"] == pytest.approx(float(np.std(replicate_bics, ddof=1)))
    assert _ambiguity_margin(floor) == max(AMBIGUITY_MARGIN, floor["scatter"])
    c = object.__new__(_Confirmation)
    c.rep = type("R", (), {"missing_physics": None, "fit": {}})()
    c.searched, c.model_free = {}, None
    d = c.decide(_FullTier(rows, 0.70, floor))
    assert d.confirmed == named
    assert (d.ambiguous == ["a", "b"]) == (named is None)
    assert ("confirmation_ambiguous" in c.rep.fit) == (named is None)


def test_an_effect_stands_by_its_best_decisive_run():
    """Effect b's most likely run (Delta BIC 29) fails the score margin, another of its runs
    (26, score 0.90) passes every rule: b stands by that run, so it is a rival of a (30) and,
    3 apart against a realisation scatter of 10.6, neither is named. Before, b stood by its
    failing run and a was named (measured: a Yade 18.45 m floor recording named cohesion)."""
    from crashdem.diagnosis.confirm import REPLICATE, _Confirmation, _FullTier, _realisation_floor

    b_likely, b_decisive = _run("b", 29.0, 0.70), _run("b", 26.0, 0.90)
    rows = [_run("recalibration", 0.0, 0.70), _run("a", 30.0, 0.90), b_likely, b_decisive,
            _run(REPLICATE, -10.0, 0.72), _run(REPLICATE, 5.0, 0.72)]
    floor = _realisation_floor(rows, 0.70)
    c = object.__new__(_Confirmation)
    c.rep = type("R", (), {"missing_physics": None, "fit": {}})()
    c.searched, c.model_free = {}, None
    assert c.standing(rows[1:], floor)["b"] is b_decisive
    # without a decisive run an effect stands by its most likely one
    assert c.standing([rows[1], b_likely], floor)["b"] is b_likely
    d = c.decide(_FullTier(rows, 0.70, floor))
    assert d.confirmed is None and d.ambiguous == ["a", "b"]


def test_detectability_separates_levels_from_the_realisation_scatter():
    """A level that moves the baseline simulation less than the least different replicate
    packing is "not visible at this resolution". Synthetic rows on a constant baseline, unit
    noise, no model error: the separation is the mean squared offset (oracle: written out), so
    replicates offset by 1 and 2 give 1 and 4 (threshold 1); cohesion levels (fading at the low
    end) offset by 0.1, 0.5, 2 and 3 are visible from the third, whose weaker neighbour the
    verdict names; a floor (fading at the high end) offset by 3, 2 and 0.5 is visible up to
    the second; contact damping offset by 2 everywhere is visible at every level (no note);
    particle rotation at most 0.5 at no level."""
    from crashdem.diagnosis.catalogue import DROP_FULL_SEARCH as FS
    from crashdem.diagnosis.confirm import REPLICATE, _detectability, _invisible_note
    from crashdem.signal import Signal

    t = np.linspace(-0.01, 0.1, 111)
    base = {"accel_z": Signal("accel_z", t, np.zeros_like(t), "m/s^2")}
    noise = {"accel_z": type("N", (), {"sigma": 1.0})()}
    rep = type("R", (), {"channels": ["accel_z"], "baseline": base, "noise": noise,
                         "fit": {"score_window_s": [0.0, 0.1], "model_error": {}}})()

    def row(name, offset, value=None):
        r = {"hypothesis": name, "aligned": {"accel_z": Signal("accel_z", t, np.full_like(
            t, offset), "m/s^2")}}
        if value is not None:
            r["search_value"] = value
        return r

    coh = FS["cohesion"].values  # 3e4 ... 4.8e5, fades low
    fl = FS["boundary_proximity"].values
    rows = ([row(REPLICATE, 1.0), row(REPLICATE, 2.0)]
            + [row("cohesion", o, v) for o, v in zip((0.1, 0.5, 0.5, 2.0, 3.0), coh)]
            + [row("boundary_proximity", o, v) for o, v in zip((3, 3, 3, 3, 2.0, 0.5), fl)]
            + [row("contact_damping", 2.0, v) for v in FS["contact_damping"].values]
            + [row("particle_rotation", 0.5, v) for v in FS["particle_rotation"].values])
    det = _detectability(rep, rows, FS)
    assert det["replicates"] == pytest.approx([1.0, 4.0])
    assert det["threshold"] == pytest.approx(1.0)
    e = det["effects"]
    assert e["cohesion"]["visible_from"] == coh[3]
    assert e["cohesion"]["levels"][0] == pytest.approx([coh[0], 0.01])
    assert e["boundary_proximity"]["visible_from"] == fl[4]
    assert e["contact_damping"]["visible_from"] == FS["contact_damping"].values[-1]
    assert e["particle_rotation"]["visible_from"] is None
    note = _invisible_note(det, "cohesion", FS["cohesion"])
    assert note.startswith(f"a cohesion of {coh[2]:.4g} Pa or less") and "not visible" in note
    assert _invisible_note(det, "boundary_proximity", FS["boundary_proximity"]).startswith(
        f"a floor_depth of {fl[5]:.4g} m or more")
    assert _invisible_note(det, "contact_damping", FS["contact_damping"]) is None
    assert "no level of it" in _invisible_note(det, "particle_rotation", FS["particle_rotation"])
    # without replicates there is no scale to compare with
    assert _detectability(rep, [r for r in rows if r["hypothesis"] != REPLICATE], FS) is None


@pytest.mark.parametrize("level", [-9.81, +9.81, -0.4 * 9.81])
def test_kinematic_acceleration_is_read_as_the_specific_force(layering_case, level):
    """A drop recording whose acceleration reads -g in free fall (another code's kinematic
    acceleration) or +g is the specific force shifted by g: the diagnosis adds it back before
    comparing (``fit.free_fall_convention``) and reaches the same answer, parameters and score
    as on the recording as a lab writes it. A level that is not +-g (here -0.4 g) is a bias
    and stays as recorded. Oracle: the unshifted recording's diagnosis."""
    from crashdem.signal import Signal

    base = simulate(RomParams())
    rec = layering_case.recording
    a = rec["accel_z"]
    shifted = {**rec, "accel_z": Signal("accel_z", a.t, a.data + level, a.unit, a.cfc)}
    ref = diagnose(base, rec)
    rep = diagnose(base, shifted)
    ff = rep.fit["free_fall_convention"]["accel_z"]
    assert ff["free_fall_mean"] == pytest.approx(
        ref.fit["free_fall_convention"]["accel_z"]["free_fall_mean"] + level, abs=1e-9)
    assert ref.fit["free_fall_convention"]["accel_z"]["added"] == 0.0
    if abs(level) > 5.0:
        assert ff["read_as"] == "kinematic acceleration" and ff["added"] == -level
        assert rep.missing_physics == ref.missing_physics
        assert rep.hypotheses[0]["name"] == ref.hypotheses[0]["name"]
        assert rep.fit["after"]["overall"] == pytest.approx(ref.fit["after"]["overall"], abs=1e-6)
    else:
        assert ff["read_as"] == "specific force" and ff["added"] == 0.0
        assert rep.fit["before"]["overall"] < ref.fit["before"]["overall"]


@pytest.mark.parametrize("coarse_level_db, coarse_score, named", [
    (9.4, 0.692, None), (20.0, 0.692, None), (20.0, 0.73, "soil_layering")])
def test_a_claim_must_also_hold_on_the_search_tier(coarse_level_db, coarse_score, named):
    """Two-tier confirmation (the CLI at a resolution finer than the coarse search): the
    replicates run on the search tier, so the full runs have only the reference as their floor.
    The screening claims layering and its full run beats the reference (28.2, score 0.766 >
    0.691); on the search tier its best level reaches 9.4 against the best replicate's 26.2,
    (score 0.692 against 0.736), i.e. decisively worse than another packing of the coarse bed,
    so the claim does not stand and nothing is named (the floor's full run fails the score
    margin). At 20 (within ACCEPT_MARGIN of 26.2) but still 0.044 below in score it does not
    stand either; at 20 and 0.73 it stands. Numbers: the Yade floor
    recording 12 at the default resolution, which named layering before."""
    from crashdem.diagnosis.catalogue import DROP_FULL_SEARCH as FS
    from crashdem.diagnosis.confirm import (
        REPLICATE,
        _Confirmation,
        _FullTier,
        _realisation_floor,
        _SearchTier,
    )

    tier_rows = ([_run("baseline", 0.0, 0.691)]
                 + [_run("soil_layering", db, sc, v) for db, sc, v in
                    ((-10.3, 0.65, 0.2), (coarse_level_db, coarse_score, 0.3), (-14.2, 0.6, 0.4),
                     (17.2, 0.57, 0.5))]
                 + [_run("boundary_proximity", 50.8, 0.762, 0.7)]
                 + [_run(REPLICATE, db, sc) for db, sc in ((-5.4, 0.52), (14.5, 0.64),
                                                           (26.2, 0.736), (9.0, 0.69))])
    tier = _SearchTier(tier_rows, _realisation_floor(tier_rows, 0.691), [], [], {})
    rows = [_run("recalibration", 0.0, 0.691), _run("soil_layering", 28.2, 0.766),
            _run("boundary_proximity", 14.7, 0.622, 0.7)]
    full = _FullTier(rows, 0.691, _realisation_floor(rows, 0.691))
    c = object.__new__(_Confirmation)
    c.rep = type("R", (), {"missing_physics": "soil_layering", "fit": {}})()
    c.searched, c.model_free = dict(FS), None
    d = c.decide(full, tier)
    assert d.confirmed == named
    assert (d.unsupported is None) == (named is not None)
    if named is None:
        assert "decisively worse than the best replicate packing there" in d.unsupported
        assert f"Delta BIC {coarse_level_db:.1f}" in d.unsupported and "26.2" in d.unsupported
    # without the search tier (the replicates among the full runs) the rule does not apply
    assert c.decide(full).confirmed == "soil_layering"


@pytest.mark.parametrize("floor_db, floor_score, named", [
    (47.6, 0.646, None), (47.6, 0.640, "soil_layering"), (40.0, 0.646, "soil_layering")])
def test_a_named_level_outranked_on_the_search_tier_is_not_told_apart(floor_db, floor_score,
                                                                      named):
    """Two-tier confirmation: layering's best coarse level (0.3 m, Delta BIC 42.0, score 0.72)
    is promoted and its full run beats the reference decisively. The floor's best coarse level
    (0.7 m) fits with a higher likelihood (47.6) and scores no worse than the best replicate
    (0.646 against 0.645) but misses the 0.02 score margin of promotion, so it never ran in the
    full model: the two are not told apart and neither is named (``fit.confirmation_ambiguous``,
    both verdict lines say why). A floor level scoring below the replicates (0.640), or less
    likely than layering's (40.0), does not contest: layering is named. Without the search tier
    (one tier, every run judged in the same decision) the rule does not apply. Numbers: the
    Yade floor recording at 0.6 m depth on the default CLI path, which named layering before."""
    from crashdem.diagnosis.catalogue import DROP_FULL_SEARCH as FS
    from crashdem.diagnosis.confirm import (
        REPLICATE,
        _Confirmation,
        _FullTier,
        _realisation_floor,
        _SearchTier,
    )

    tier_rows = ([_run("baseline", 0.0, 0.60)]
                 + [_run("soil_layering", db, sc, v) for db, sc, v in
                    ((22.7, 0.74, 0.2), (42.0, 0.72, 0.3), (14.6, 0.66, 0.4))]
                 + [_run("boundary_proximity", db, sc, v) for db, sc, v in
                    ((33.7, 0.62, 0.6), (floor_db, floor_score, 0.7), (14.4, 0.43, 0.8))]
                 + [_run(REPLICATE, db, sc) for db, sc in ((-4.0, 0.50), (10.5, 0.53),
                                                           (17.5, 0.645), (5.8, 0.615))])
    tier = _SearchTier(tier_rows, _realisation_floor(tier_rows, 0.60), [], [], {})
    assert tier.floor["score"] == 0.645 and tier.floor["delta_bic"] == 17.5
    rows = [_run("recalibration", 0.0, 0.60), _run("soil_layering", 64.5, 0.84, 0.3)]
    full = _FullTier(rows, 0.60, _realisation_floor(rows, 0.60))

    def confirmation():
        c = object.__new__(_Confirmation)
        c.rep = type("R", (), {"missing_physics": None, "fit": {}})()
        c.searched, c.model_free = dict(FS), None
        return c

    c = confirmation()
    d = c.decide(full, tier)
    assert d.confirmed == named
    assert ("confirmation_ambiguous" in c.rep.fit) == (named is None)
    if named is None:
        assert d.ambiguous == ["soil_layering", "boundary_proximity"]
        assert d.contested["delta_bic"] == 47.6 and d.contested["own_delta_bic"] == 42.0
        assert d.contested["tier"] == "search simulator" and d.contested["value"] == 0.7
        assert d.best is rows[0]
        v = c.verdicts(full, d)
        assert "not told apart" in v["soil_layering"] and "boundary_proximity" in v["soil_layering"]
        c.replicates = []
        line = c.sentence(full, tier, d)
        assert ("soil_layering would be named, but boundary_proximity fits the recording with a "
                "higher likelihood on the search simulator (Delta BIC 47.6 against 42.0)") in line
        assert line.endswith("neither named; no missing physics confirmed")
    else:
        assert d.contested is None and d.best is rows[1]
    assert confirmation().decide(full).confirmed == "soil_layering"


@pytest.mark.parametrize("confirmed", ["boundary_proximity", None])
def test_ranking_follows_the_confirmation(confirmed):
    """After the full-model confirmation the hypotheses are ordered by the evidence it ended
    with: the answer first (the named effect, else the recalibration), then the effects the
    full model ran by their best located run's Delta BIC above the realisation floor (the
    recalibration at 0; a level at the fading end does not count), then those it did not run
    in the screening's order. Oracle: the order worked out by hand from the numbers below."""
    from crashdem.diagnosis.catalogue import DROP_FULL_SEARCH as FS
    from crashdem.diagnosis.confirm import REPLICATE, _Confirmation, _FullTier, _realisation_floor

    rows = ([_run("recalibration", 0.0, 0.80), _run("cohesion", -5.0, 0.78),
             _run("boundary_proximity", 40.0, 0.86, 0.7),
             _run("boundary_proximity", 60.0, 0.88, 1.25), _run("soil_layering", 12.0, 0.81, 0.3)]
            + [_run(REPLICATE, db, 0.80) for db in (15.0, 3.0)])
    full = _FullTier(rows, 0.80, _realisation_floor(rows, 0.80))
    screening = ["cohesion", "recalibration", "soil_layering", "boundary_proximity",
                 "structural_crush"]
    c = object.__new__(_Confirmation)
    c.rep = type("R", (), {"hypotheses": [{"name": n} for n in screening], "fit": {}})()
    c.searched = dict(FS)
    c.rerank(full, None, type("D", (), {"confirmed": confirmed})())
    order = [h["name"] for h in c.rep.hypotheses]
    rest = ["soil_layering", "cohesion", "structural_crush"]  # -3, -20 over the floor; not run
    assert order == (["boundary_proximity", "recalibration"] + rest if confirmed else
                     ["recalibration", "boundary_proximity"] + rest)
    by = {h["name"]: h for h in c.rep.hypotheses}
    assert [by[n]["screening_rank"] for n in screening] == [1, 2, 3, 4, 5]
    ev = by["boundary_proximity"]["full_model_evidence"]
    assert (ev["value"], ev["delta_bic_vs_reference"], ev["delta_bic_vs_floor"]) == (
        0.7, 40.0, 25.0)
    assert by["cohesion"]["full_model_evidence"]["delta_bic_vs_floor"] == -20.0
    assert "full_model_evidence" not in by["structural_crush"]
    assert "full_model_evidence" not in by["recalibration"]
    assert c.rep.fit["ranking"].startswith("the answer first")


@pytest.mark.parametrize("confirmed", [None, "cohesion"])
def test_report_settles_on_the_confirmations_answer(layering_case, confirmed):
    """The screening claims the layering; when the full model rejects it (nothing named) the
    report's best explanation, "after" fit, refitted curve and remaining mismatch become the
    recalibration's (its screening refit), and when it names another effect, that effect's;
    the screening's choice is kept in ``fit.screening_after``."""
    from crashdem.diagnosis.confirm import _Confirmation

    rep = diagnose(simulate(RomParams()), layering_case.recording)
    assert rep.best == "soil_layering"
    claim_after = rep.fit["after"]["overall"]
    c = object.__new__(_Confirmation)
    c.rep, c.chans = rep, rep.channels
    c.settle(type("D", (), {"confirmed": confirmed})())
    answer = confirmed or "recalibration"
    assert rep.best == answer and rep.fit["after_hypothesis"] == answer
    assert rep.fit["after"] == rep.fits[answer].scores
    assert rep.fit["screening_after"] == {"hypothesis": "soil_layering", "overall": claim_after,
                                          "residual_rms_sigma":
                                              rep.fits["soil_layering"].rms_sigma}
    if confirmed is None:
        assert rep.refitted["accel_z"] is rep.fits["recalibration"].aligned["accel_z"]
        # the recalibration leaves the layering's second peak unexplained
        assert rep.after_mismatch and rep.fits["recalibration"].rms_sigma > \
            rep.fits["soil_layering"].rms_sigma


def test_an_effect_whose_profile_peaks_where_it_fades_names_nothing():
    """An effect whose best search level is the one at the end of its span where it fades
    (layering: the deepest interface) is not located by any of its runs: the recording asks for
    less of it than the span gives. Numbers: the Yade floor recording 12 (bed 0.76 m) at
    0.075 m grains searched on the scenario itself, where layering's deepest level fitted best
    (74.8) and layering was named at 0.4 m (38.7) over the floor at 0.6 m (21.5); now the floor
    is named and layering's verdict says why not. Controls: the same rows with the deepest level
    below 38.7, or without a decisive rival (the floor's score 0.70, less than 0.02 above the
    reference's 0.691), name layering."""
    from crashdem.diagnosis.catalogue import DROP_FULL_SEARCH as FS
    from crashdem.diagnosis.confirm import (
        REPLICATE,
        _ambiguity_margin,
        _Confirmation,
        _FullTier,
        _realisation_floor,
    )

    def decide(deepest, floor_score=0.761, claim="soil_layering"):
        rows = ([_run("recalibration", 0.0, 0.691), _run("soil_layering", 18.0, 0.70)]
                + [_run("soil_layering", db, sc, v) for db, sc, v in
                   ((-4.5, 0.616, 0.2), (12.9, 0.737, 0.3), (38.7, 0.748, 0.4),
                    (deepest, 0.832, 0.5))]
                + [_run("boundary_proximity", db, sc, v) for db, sc, v in
                   ((21.5, floor_score, 0.6), (14.7, 0.622, 0.7), (6.8, 0.568, 0.8),
                    (-8.8, 0.484, 1.25))]
                + [_run(REPLICATE, db, sc) for db, sc in ((-2.6, 0.595), (12.4, 0.589))])
        full = _FullTier(rows, 0.691, _realisation_floor(rows, 0.691))
        c = object.__new__(_Confirmation)
        c.rep = type("R", (), {"missing_physics": claim, "fit": {}})()
        c.searched, c.model_free = dict(FS), None
        return c, full, c.decide(full)

    c, full, d = decide(74.8)
    assert c.faded_out(full.rows) == {"soil_layering"}
    assert d.confirmed == "boundary_proximity"
    why = c.verdicts(full, d)["soil_layering"]
    assert why.startswith("its best level is at the end of the span where the effect fades "
                          "(interface_depth = 0.5 m, Delta BIC 74.8)"), why
    c, full, d = decide(30.0)
    assert c.faded_out(full.rows) == set() and d.confirmed == "soil_layering"
    # without a decisive rival the effect keeps its located levels (the Yade free-rotation
    # recording 12 on the coarse tier: best at rolling resistance 0.2, the fading end)
    c, full, d = decide(74.8, floor_score=0.70)
    assert c.faded_out(full.rows) == {"soil_layering"} and d.confirmed == "soil_layering"
    # ... when the screening claimed it; unclaimed, its located best (38.7) lies more than the
    # replicates' scatter below the fading end (74.8): the optimum is beyond the span, and
    # nothing is named (the Yade 10 m floor recording 12 was named layering so)
    c, full, d = decide(74.8, floor_score=0.70, claim=None)
    margin = _ambiguity_margin(full.floor)
    assert 74.8 - 38.7 > margin and set(c.beyond_span(full.rows[1:], full.floor)) == {
        "soil_layering"}
    assert d.confirmed is None and "soil_layering" not in d.best_by_effect
    why = c.verdicts(full, d)["soil_layering"]
    assert why.endswith(f"its best run short of that end (0.4 m, Delta BIC 38.7) is more than "
                        f"{margin:.3g} below it: the optimum lies beyond the span: names "
                        f"nothing"), why
    # within the margin of the end it stands by its located levels, claimed or not
    c, full, d = decide(38.7 + 0.9 * _ambiguity_margin(full.floor), floor_score=0.70,
                        claim=None)
    assert c.faded_out(full.rows) == {"soil_layering"} and not c.beyond_span(
        full.rows[1:], full.floor)
    assert d.best_by_effect["soil_layering"]["search_value"] == 0.4


def test_realisation_interval_of_a_named_value():
    """The values of a searched effect that fit within the ambiguity margin of its best run
    (``_realisation_interval``): linear in the search coordinate between runs, open on a side
    where the profile never drops below the best minus the margin, and always holding the
    adopted value. The adopted uncertainty is the larger of the noise's (curvature) and the
    interval's reach (``_adopt_full_parameters``)."""
    from crashdem.diagnosis.catalogue import FullSearch
    from crashdem.diagnosis.confirm import (
        _adopt_full_parameters,
        _profile_scatter,
        _realisation_interval,
    )

    deep = FullSearch("floor_depth", "m", ("k",), (0.6, 0.7, 0.8, 0.9, 1.05, 1.25))
    prof = {0.6: 10.0, 0.7: 30.0, 0.8: 40.0, 0.9: 36.0, 1.05: 20.0, 1.25: 5.0}
    lv = [{"hypothesis": "b", "search_value": v, "delta_bic_vs_reference": d}
          for v, d in prof.items()]
    iv = _realisation_interval(lv, 0.8, 8.0, deep)
    # threshold 32: between 0.7 (30) and 0.8 (40) at 0.72; between 0.9 (36) and 1.05 (20) at
    # 0.9 + 4/16 x 0.15 = 0.9375
    assert iv["low"] == pytest.approx(0.72) and iv["high"] == pytest.approx(0.9375)
    assert iv["open"] == [False, False] and iv["margin"] == 8.0
    # a margin larger than every drop: open on both sides, ends at the span's end runs
    wide = _realisation_interval(lv, 0.8, 50.0, deep)
    assert (wide["low"], wide["high"], wide["open"]) == (0.6, 1.25, [True, True])
    # the best at an end of the span: open there
    edge = _realisation_interval(lv[2:], 0.8, 8.0, deep)
    assert edge["low"] == 0.8 and edge["open"] == [True, False]
    # a jagged profile (each level its own packing): a run within the margin beyond a dip
    # counts, the span of all of them is the interval
    jag = [dict(r, delta_bic_vs_reference={0.6: 35.0, 0.7: 20.0}.get(r["search_value"],
                                                                       r["delta_bic_vs_reference"]))
           for r in lv]
    assert _realisation_interval(jag, 0.8, 8.0, deep)["low"] == 0.6
    assert _realisation_interval(jag, 0.8, 8.0, deep)["open"] == [True, False]
    # an adopted value outside the profile's interval (a full-tier run) widens it
    assert _realisation_interval(lv, 1.05, 8.0, deep)["high"] == 1.05
    # log-scaled searches interpolate in log(value)
    coh = FullSearch("cohesion", "Pa", ("k",), (1e4, 1e5, 1e6), scale="log", fades="low")
    lvc = [{"hypothesis": "c", "search_value": v, "delta_bic_vs_reference": d}
           for v, d in ((1e4, 0.0), (1e5, 20.0), (1e6, 0.0))]
    ivc = _realisation_interval(lvc, 1e5, 10.0, coh)
    assert ivc["low"] == pytest.approx(10 ** 4.5) and ivc["high"] == pytest.approx(10 ** 5.5)
    assert _realisation_interval(lv[:1], 0.6, 8.0, deep) is None

    # the adopted uncertainty, on an exact parabola (no scatter of the levels about it):
    # 40 - 1000 (x - 0.8)^2, curvature 1 / sqrt(500) = 0.0447 m
    par = [{"hypothesis": "b", "search_value": v,
            "delta_bic_vs_reference": 40.0 - 1000.0 * (v - 0.8) ** 2} for v in deep.values]
    assert _profile_scatter(par, deep) == pytest.approx(0.0, abs=1e-9)
    rep = type("R", (), {})()
    rep.hypotheses = [{"name": "b", "parameters": {"floor_depth": 0.85},
                       "uncertainty": {"floor_depth": 0.01}}]
    rep.fit = {}
    best = {**par[2], "overrides": {"k": 0.8}, "score": 0.9}
    # the replicates scatter by 8: the runs within 8 of the best span 0.72-0.88 m, a reach
    # of 0.08 m beyond the curvature's 0.0447 m
    _adopt_full_parameters(rep, best, deep, par, {"delta_bic": 0.0, "score": 0.8,
                                                  "scatter": 8.0})
    h = rep.hypotheses[0]
    assert h["parameters"]["floor_depth"] == 0.8
    assert h["uncertainty"]["floor_depth"] == pytest.approx(0.08)
    assert h["full_model"]["noise_uncertainty"]["floor_depth"] == pytest.approx(500 ** -0.5)
    named = rep.fit["full_search"]["named"]
    assert named["parameter"] == "floor_depth"
    assert (named["interval"]["low"], named["interval"]["high"]) == (
        pytest.approx(0.72), pytest.approx(0.88))
    # with a small scatter the margin is AMBIGUITY_MARGIN (2): 0.78-0.82 m, inside the
    # curvature's reach, which is then reported
    _adopt_full_parameters(rep, best, deep, par, {"delta_bic": 0.0, "score": 0.8,
                                                  "scatter": 0.5})
    iv2 = rep.fit["full_search"]["named"]["interval"]
    assert iv2["margin"] == 2.0 and iv2["low"] == pytest.approx(0.78)
    assert iv2["high"] == pytest.approx(0.82)
    assert h["uncertainty"]["floor_depth"] == pytest.approx(500 ** -0.5)
    # levels that scatter about the parabola more than the replicates do set the margin:
    # the jagged profile's residual standard deviation about its least-squares parabola
    u = np.array(deep.values)
    d = np.array([r["delta_bic_vs_reference"] for r in jag])
    want = math.sqrt(np.sum((d - np.polyval(np.polyfit(u, d, 2), u)) ** 2) / 3)
    assert _profile_scatter(jag, deep) == pytest.approx(want) and want > 8.0
    _adopt_full_parameters(rep, {**jag[2], "overrides": {"k": 0.8}, "score": 0.9}, deep, jag,
                           {"delta_bic": 0.0, "score": 0.8, "scatter": 8.0})
    assert rep.fit["full_search"]["named"]["interval"]["margin"] == pytest.approx(want)
    assert _profile_scatter(jag[:3], deep) == 0.0  # fewer than four levels


def test_a_named_value_of_another_quantity_joins_the_screening_parameters():
    """A named searched effect whose full-model value is not a screening parameter (free
    rotation: the screening model fits a friction ratio and a mobilisation depth, the full model
    a rolling coefficient) reports that value in ``parameters`` with its uncertainty and unit,
    beside the screening's (kept in ``screening_parameters`` too). Measured at the default
    resolution (``validation/diagnose_cost.py --effect particle_rotation --value 0.1``): the
    report named free rotation with ``parameters`` friction_ratio 0.253 and mobilisation_depth
    0.126 m, while the rolling coefficient the recording was fitted with (0.0) stood only in
    ``full_model``."""
    from crashdem.diagnosis.catalogue import DROP_FULL_SEARCH
    from crashdem.diagnosis.confirm import _adopt_full_parameters

    fs = DROP_FULL_SEARCH["particle_rotation"]
    rows = [{"hypothesis": "particle_rotation", "search_value": v, "delta_bic_vs_reference": d,
             "overrides": fs.overrides(v), "score": sc}
            for v, d, sc in ((0.0, 30.0, 0.80), (0.05, 24.0, 0.79), (0.2, 5.0, 0.74))]
    screened = {"friction_ratio": 0.252839520561533, "mobilisation_depth": 0.12588039688691963}
    rep = type("R", (), {})()
    rep.hypotheses = [{"name": "particle_rotation", "parameters": dict(screened),
                       "uncertainty": {"friction_ratio": 0.089, "mobilisation_depth": 0.071},
                       "units": {"friction_ratio": "1", "mobilisation_depth": "m"}}]
    rep.fit = {}
    _adopt_full_parameters(rep, rows[0], fs, rows, {"delta_bic": 0.0, "score": 0.62,
                                                    "scatter": 5.1})
    h = rep.hypotheses[0]
    assert h["parameters"] == {**screened, "rolling_coefficient": 0.0}
    assert h["screening_parameters"] == screened
    assert h["units"]["rolling_coefficient"] == "1"
    assert h["uncertainty"]["rolling_coefficient"] == \
        h["full_model"]["uncertainty"]["rolling_coefficient"] > 0.0
    assert h["scenario_overrides"]["physics.particle_rotation.rolling_coefficient"] == 0.0


def test_a_named_restitution_reports_its_rebound_restitution():
    """A named contact damping carries the rebound ratio of a head-on contact at its nominal
    restitution and at its interval's ends (``confirm.DERIVED``; oracle: the closed form of
    ``soil.contact_laws.no_tension_restitution``, itself tested against an ODE), in the JSON
    and the readable report; other searched parameters carry none."""
    from crashdem.diagnosis.catalogue import DROP_FULL_SEARCH
    from crashdem.diagnosis.confirm import _adopt_full_parameters
    from soil import Material

    fs = DROP_FULL_SEARCH["contact_damping"]
    prof = {0.1: 30.0, 0.2: 36.0, 0.3: 31.0, 0.5: 20.0}
    lv = [{"hypothesis": "contact_damping", "search_value": v, "delta_bic_vs_reference": d}
          for v, d in prof.items()]
    rep = type("R", (), {})()
    rep.hypotheses = [{"name": "contact_damping", "parameters": {"restitution": 0.25},
                       "uncertainty": {"restitution": 0.1}}]
    rep.fit = {}
    _adopt_full_parameters(rep, {**lv[1], "overrides": {"k": 0.2}, "score": 0.9}, fs, lv,
                           {"delta_bic": 0.0, "score": 0.8, "scatter": 8.0})
    named = rep.fit["full_search"]["named"]
    der = named["derived"]
    rebound = Material(young=1e7, density=2650.0, friction_angle=0.5,
                       restitution=0.2).rebound_restitution
    assert der["name"] == "rebound_restitution" and der["unit"] == "1"
    assert der["value"] == pytest.approx(rebound, rel=1e-12)
    assert der["value"] == pytest.approx(0.3249, abs=1e-3)
    lo, hi = named["interval"]["low"], named["interval"]["high"]
    want = [Material(young=1e7, density=2650.0, friction_angle=0.5,
                     restitution=v).rebound_restitution for v in (lo, hi)]
    assert der["interval"] == pytest.approx(want, rel=1e-12) and want[0] < der["value"] < want[1]
    assert rep.hypotheses[0]["full_model"]["derived"] == der
    # in the search's no-tension form the same; in its tension form (the dashpot pulls, as in
    # Yade's CundallStrackVisco) the rebound is the nominal restitution itself
    for form, want_value in (("no_tension", rebound), ("tension", 0.2)):
        rep.fit = {}
        _adopt_full_parameters(rep, {**lv[1], "overrides": {"k": 0.2}, "score": 0.9},
                               fs.with_form(form), lv,
                               {"delta_bic": 0.0, "score": 0.8, "scatter": 8.0})
        got = rep.fit["full_search"]["named"]
        assert got["form"] == form
        assert got["derived"]["value"] == pytest.approx(want_value, rel=1e-12)
    assert got["derived"]["interval"] == pytest.approx([lo, hi], rel=1e-12)
    # a floor depth derives nothing
    floor = DROP_FULL_SEARCH["boundary_proximity"]
    fl = [{"hypothesis": "boundary_proximity", "search_value": v, "delta_bic_vs_reference": d}
          for v, d in zip(floor.values, (5.0, 20.0, 30.0, 22.0, 10.0, 3.0))]
    rep.hypotheses = [{"name": "boundary_proximity", "parameters": {"floor_depth": 0.8}}]
    rep.fit = {}
    _adopt_full_parameters(rep, {**fl[2], "overrides": {}, "score": 0.9}, floor, fl,
                           {"delta_bic": 0.0, "score": 0.8, "scatter": 2.0})
    assert "derived" not in rep.fit["full_search"]["named"]
    assert "derived" not in rep.hypotheses[0]["full_model"]


def test_a_recording_longer_than_the_simulation_is_compared_where_both_exist(layering_case):
    """A recording that runs past the end of the baseline simulation is cut there
    (``_crop_to_simulation``): the simulation has no value after its end, and holding its last
    sample would judge every run on a made-up tail. Same report as for the recording cut by
    hand; the report says where it was cut and how much longer a simulation must run. Measured
    before the cut on a 0.30 s DEM-truth recording against the 0.12 s baseline: floor 12 named
    at 1.05 m instead of 0.80 m."""
    from crashdem.signal import Signal

    base = simulate(RomParams())
    t_end = 0.10
    short = {k: Signal(s.name, s.t[s.t <= t_end], s.data[s.t <= t_end], s.unit, s.cfc)
             for k, s in base.items()}
    rec = layering_case.recording
    long_rep = diagnose(short, rec)
    cut = long_rep.fit["cropped_to_simulation"]
    assert cut is not None
    assert cut["recording_end_s"] == pytest.approx(max(s.t[-1] for s in rec.values()))
    assert cut["simulation_short_by_s"] == pytest.approx(
        cut["recording_end_s"] - cut["compared_until_s"])
    assert "past the end of the simulation" in long_rep.decision
    end = cut["compared_until_s"]
    assert all(s.t[-1] <= end for s in long_rep.recording.values())
    by_hand = {k: Signal(s.name, s.t[s.t <= end], s.data[s.t <= end], s.unit, s.cfc)
               for k, s in rec.items()}
    hand_rep = diagnose(short, by_hand)
    assert hand_rep.fit["cropped_to_simulation"] is None
    assert long_rep.missing_physics == hand_rep.missing_physics
    assert [h["name"] for h in long_rep.hypotheses] == [h["name"] for h in hand_rep.hypotheses]
    assert long_rep.fit["before"]["overall"] == hand_rep.fit["before"]["overall"]
    assert long_rep.fit["after"]["overall"] == hand_rep.fit["after"]["overall"]
    # a recording within the simulation's span (0.15 s) is not touched
    assert diagnose(base, by_hand).fit["cropped_to_simulation"] is None


def test_grain_radius_factor_of_the_numerics_check(tmp_path):
    """``numerics.radius_scale`` (the numerics check's runs) becomes the scenario's grain radius
    times the factor, on top of a radius the overrides set themselves (the coarse search tier),
    and is no scenario field; a factor outside [0.5, 2] and a bad ``--numerics-check`` are errors
    naming the field and the allowed range."""
    scenario = pytest.importorskip("crashdem.scenario")
    from crashdem.diagnosis.cli import _grain_scales, _numerics_scales
    from crashdem.diagnosis.distributed import RADIUS_SCALE_KEY, scenario_overrides
    from crashdem.diagnosis.generator_dem import scenario_path

    scen = scenario.load(scenario_path())
    r0 = scen.get("soil.radius")
    ov = scenario_overrides(scen, {RADIUS_SCALE_KEY: 0.9, "physics.cohesion.enabled": True})
    assert ov["soil.radius"] == pytest.approx(0.9 * r0) and RADIUS_SCALE_KEY not in ov
    assert scen.with_overrides(ov).get("soil.radius") == pytest.approx(0.9 * r0)
    assert scenario_overrides(scen, {RADIUS_SCALE_KEY: 1.1, "soil.radius": 0.1})[
        "soil.radius"] == pytest.approx(0.11)
    assert "soil.radius" not in scenario_overrides(scen, {"physics.cohesion.enabled": True})
    with pytest.raises(ValueError, match=r"numerics.radius_scale=3.0: must be in \[0.5, 2\]"):
        scenario_overrides(scen, {RADIUS_SCALE_KEY: 3.0})
    assert _numerics_scales(None) == (0.9, 1.1) and _numerics_scales("off") == ()
    assert _numerics_scales("0.8,1.2") == (0.8, 1.2)
    with pytest.raises(ValueError, match=r"--numerics-check='0.9,x'.*\[0.5, 2\]"):
        _numerics_scales("0.9,x")
    with pytest.raises(ValueError, match=r"--numerics-check='0.3'.*factor 0.3 is outside"):
        _numerics_scales("0.3")
    # the grain check's factors are read the same way, named by their own option
    assert _grain_scales(None) == () and _grain_scales("0.9,1.1") == (0.9, 1.1)
    assert _grain_scales("off") == ()
    with pytest.raises(ValueError, match=r"--grain-check='2.5'.*factor 2.5 is outside"):
        _grain_scales("2.5")


def test_auto_search_runs_on_a_small_bed_itself(tmp_path):
    """``--full-search auto``: a scenario finer than the coarse tier is searched on itself when
    its impacts are cheap (``search_load`` at most ``AUTO_FULL_LOAD``) and on the coarse tier
    otherwise; ``full`` and ``coarse`` are not affected. ``bed_grains`` is the solid fraction
    x bed volume / mean grain volume (checked against the formula), and it does not undercount
    a deposited bed (the gate's cost would then be more than it says): a 0.8 m tank at 0.05 m
    grains deposits 70 % of it (the wall's loose band is widest there; the 2 m and 6 m tanks at
    0.075 m: 79 % and 88 %), asserted 60-100 %. ``search_load`` counts the grains in steps of
    the campaign bed: it scales with 1 / safety, 1 / the smallest radius and sqrt(E / rho) of
    the stiffest soil, or with 1 / an explicit step."""
    scenario = pytest.importorskip("crashdem.scenario")
    from crashdem.diagnosis.cli import (
        AUTO_FULL_LOAD,
        BED_SOLID_FRACTION,
        _search_setup,
        bed_grains,
        search_load,
    )
    from crashdem.diagnosis.generator_dem import scenario_path
    from crashdem.run import packing_spec
    from soil import packing as pk

    campaign = scenario.load(scenario_path()).with_overrides(
        {"physics.soil_layering.enabled": False})
    r = campaign.get("soil.radius")
    assert r == 0.075 and campaign.get("container.diameter") == 6.0
    lo, hi = r * (1 - campaign.get("soil.radius_spread")), r * (1 + campaign.get("soil.radius_spread"))
    grain = 4 / 3 * math.pi * (hi**4 - lo**4) / (4 * (hi - lo))
    for diameter, coarse in ((6.0, True), (3.0, True), (2.0, False)):
        scen = campaign.with_overrides({"container.diameter": diameter})
        n = bed_grains(scen)
        expect = BED_SOLID_FRACTION * math.pi * diameter**2 / 4 * campaign.get(
            "container.soil_depth") / grain
        assert n == pytest.approx(expect, rel=1e-12)
        assert search_load(scen) == pytest.approx(n, rel=1e-12)  # the reference soil and step
        assert (search_load(scen) > AUTO_FULL_LOAD) is coarse
        _, sim, how = _search_setup(scen, False, "auto", {}, tmp_path / str(diameter))
        assert (sim is not None) is coarse, (diameter, how)
        assert ("coarse" in how) is coarse and ("small bed" in how) is (not coarse)
        assert _search_setup(scen, False, "full", {}, tmp_path)[1] is None
        assert _search_setup(scen, False, "coarse", {}, tmp_path / "c")[1] is not None
    small = campaign.with_overrides({"container.diameter": 2.0})
    n = bed_grains(small)
    # what makes a step shorter makes the load larger, by its factor
    for ov, factor in (({"solver.safety": 0.1}, 3.0),
                       ({"soil.material.young": 8.0e7}, 2.0),
                       ({"physics.soil_layering.enabled": True,
                         "physics.soil_layering.lower_young_factor": 4.0}, 2.0)):
        assert search_load(small.with_overrides(ov)) == pytest.approx(n * factor, rel=1e-9), ov
    # the campaign's own 1 m compacted layer (E x 3) makes the 2 m tank's steps sqrt(3) shorter
    layered = scenario.load(scenario_path()).with_overrides({"container.diameter": 2.0})
    assert search_load(layered) == pytest.approx(n * math.sqrt(3.0), rel=1e-9)
    assert search_load(layered) > AUTO_FULL_LOAD
    dt_ref = 0.3 * 0.06 / math.sqrt(2.0e7 / 2650.0)
    assert search_load(small.with_overrides({"solver.dt": dt_ref / 5})) == pytest.approx(5 * n)
    assert _search_setup(small.with_overrides({"solver.safety": 0.1}), False, "auto", {},
                         tmp_path / "safety")[1] is not None  # 3 x the load: coarse
    # a floor ends the bed: fewer grains
    floor = small.with_overrides({"physics.boundary_proximity.enabled": True,
                                  "physics.boundary_proximity.floor_depth": 0.5})
    assert bed_grains(floor) == pytest.approx(n * 0.5 / 2.0)

    from crashdem.cli import build_parser

    diag = next(a for a in build_parser()._subparsers._group_actions[0].choices["diagnose"]._actions
                if "--full-search" in a.option_strings)
    assert f"about {AUTO_FULL_LOAD:,} grains" in diag.help  # the help states the gate
    # against a deposited bed (a small one)
    tiny = campaign.with_overrides({"container.diameter": 0.8, "container.soil_depth": 0.4,
                                    "soil.radius": 0.05, "scenario.threads": 1})
    packed = pk.build(packing_spec(tiny))
    assert 0.6 * bed_grains(tiny) <= len(packed.radius) <= bed_grains(tiny)


def test_search_tier_is_never_finer_or_larger_than_the_scenario(tmp_path):
    """The coarse search tier (``cli.search_tier``) takes ``SEARCH_COARSE``'s 0.10 m grains,
    0.10 spread and 2 m container only where they coarsen or shrink the scenario: a tank
    smaller than 2 m keeps its own size (searched in a 2 m tank its walls would move away from
    the impact), coarser grains keep theirs, a narrower spread keeps its own; a box is
    clamped side by side. ``_search_setup`` runs the tier it describes, and a scenario the tier
    would not change is searched on itself. The layering search carries the top grain row of
    the bed its levels run on (one mean grain diameter of that simulator), where the
    realisation floor makes the bed stiffer below its top row."""
    scenario = pytest.importorskip("crashdem.scenario")
    from crashdem.diagnosis.catalogue import stiffer_soil_depths
    from crashdem.diagnosis.cli import SEARCH_COARSE, _search_setup, search_tier
    from crashdem.diagnosis.generator_dem import scenario_path

    campaign = scenario.load(scenario_path()).with_overrides(
        {"physics.soil_layering.enabled": False})
    assert search_tier(campaign) == {"soil.radius": 0.10, "soil.radius_spread": 0.10,
                                     "container.diameter": 2.0}
    assert search_tier(campaign) == {k: v for k, v in SEARCH_COARSE.items()
                                     if k not in ("container.length", "container.width")}
    cases = [  # overrides, expected tier, what auto does
        ({"container.diameter": 1.5, "soil.radius": 0.05},
         {"soil.radius": 0.10, "soil.radius_spread": 0.10, "container.diameter": 1.5}, "coarse"),
        ({"soil.radius": 0.15, "soil.radius_spread": 0.0},
         {"soil.radius": 0.15, "soil.radius_spread": 0.0, "container.diameter": 2.0}, None),
        ({"container.shape": "box", "container.length": 1.5, "container.width": 3.0,
          "soil.radius": 0.05},
         {"soil.radius": 0.10, "soil.radius_spread": 0.10, "container.length": 1.5,
          "container.width": 2.0}, "coarse"),
        ({"container.diameter": 2.0, "soil.radius": 0.10}, None, "itself"),
    ]
    for i, (ov, tier, auto) in enumerate(cases):
        scen = campaign.with_overrides(ov)
        got = search_tier(scen)
        if tier is not None:
            assert got == tier, ov
        # the tier never refines or enlarges the scenario
        assert got["soil.radius"] >= scen.get("soil.radius")
        assert got["soil.radius_spread"] <= scen.get("soil.radius_spread")
        for k in ("container.diameter", "container.length", "container.width"):
            if k in got:
                assert got[k] <= scen.get(k), (ov, k)
        searched, sim, how = _search_setup(scen, False, "coarse", {}, tmp_path / f"c{i}")
        assert sim is not None
        for k, v in got.items():
            assert f"{k}={v:g}" in how, (ov, how)
        # the realisation floor's top grain row is the coarse bed's: one of its grain diameters
        assert searched["soil_layering"].top_row_depth == pytest.approx(2 * got["soil.radius"])
        assert stiffer_soil_depths(searched["soil_layering"])[1] == pytest.approx(
            2 * got["soil.radius"])
        searched, sim, how = _search_setup(scen, False, "auto", {}, tmp_path / f"a{i}")
        if auto == "coarse":
            assert sim is not None and "coarse" in how, (ov, how)
        elif auto == "itself":
            assert sim is None and how.endswith("on the scenario itself"), (ov, how)
            assert searched["soil_layering"].top_row_depth == pytest.approx(
                2 * scen.get("soil.radius"))
    searched, sim, _ = _search_setup(campaign, False, "full", {}, tmp_path / "f")
    assert sim is None and searched["soil_layering"].top_row_depth == 0.15
    assert stiffer_soil_depths(searched["soil_layering"]) == (WHOLE_BED_DEPTH, 0.15)
    with pytest.raises(ValueError, match="top_row_depth=0.0: must be a finite depth > 0"):
        replace(searched["soil_layering"], top_row_depth=0.0)
    # the floor's bed with the other contact law: a linear scenario's, not a Hertz one's
    assert searched["soil_layering"].hertz_floor == 4.0
    hz = campaign.with_overrides({"physics.soil_layering.enabled": False,
                                  "soil.contact_law": "hertz_mindlin"})
    assert _search_setup(hz, False, "full", {}, tmp_path / "h")[0][
        "soil_layering"].hertz_floor is None
    with pytest.raises(ValueError, match="hertz_floor=0.0: must be a finite factor > 0"):
        replace(searched["soil_layering"], hertz_floor=0.0)


@pytest.mark.parametrize("truth, runs, named", [(0.43, [0.5, 0.4], 0.4),
                                                 (0.53, [0.5, 0.4], 0.5),
                                                 (0.58, [0.5], 0.6),
                                                 (0.75, [], 0.7),
                                                 (0.2, [0.5, 0.4], 0.4)])
def test_a_search_goes_on_beyond_its_strong_end_while_that_end_fits_best(truth, runs, named):
    """The floor's levels (0.6 ... 1.25 m) end at 0.6 m on the strong side; a floor nearer than
    that fits best at 0.6 m, so the next extension value (0.5 m, then 0.4 m) is run while the
    strong end of the span run so far fits best, and no further (a profile peaked at the truth,
    Delta BIC 60 - 100 |depth - truth|): a truth of 0.58 m runs 0.5 m and stops at the 0.6 m
    optimum, one of 0.53 m runs 0.4 m to find 0.5 m the better. The extended span is what the refinement, the numerics
    check and the report see; a floor deeper than 0.6 m runs nothing more. A truth beyond every
    extension value stops at the last (0.4 m), which then is the strong end."""
    from crashdem.diagnosis.catalogue import DROP_FULL_SEARCH as FS
    from crashdem.diagnosis.confirm import _Confirmation

    def prof(x):
        return 60.0 - 100.0 * abs(x - truth)

    asked: list = []
    c = object.__new__(_Confirmation)
    c.searched, c.beds, c.cfc_key = {"boundary_proximity": FS["boundary_proximity"]}, [{}], {}

    def run(sim, requests):
        asked.extend(x for _, _, x in requests)
        return [_run(n, prof(x), 0.8, x) for n, _, x in requests]

    c.run = run
    rows = [_run("boundary_proximity", prof(x), 0.8, x) for x in FS["boundary_proximity"].values]
    extra = c.extended(None, rows, lambda r: {**r, "finished": True})
    assert asked == runs
    assert [r["search_value"] for r in extra] == runs
    assert all(r["extension"] and r["finished"] for r in extra)
    fs = c.searched["boundary_proximity"]
    assert fs.values == tuple(sorted((*runs, *FS["boundary_proximity"].values)))
    assert fs.strong_end == min(fs.values) and len(fs.extension) == 2 - len(runs)
    best = max([*rows, *extra], key=lambda r: r["delta_bic_vs_reference"])
    assert best["search_value"] == named
    assert FS["boundary_proximity"].extension == (0.5, 0.4)  # the catalogue is not changed


def test_extension_values_must_lie_outward_from_the_strong_end():
    from crashdem.diagnosis.catalogue import FullSearch

    with pytest.raises(ValueError, match=r"extension=\(0.7,\).*outward from the strong end 0.6"):
        FullSearch("floor_depth", "m", ("k",), (0.6, 0.8), extension=(0.7,))
    with pytest.raises(ValueError, match=r"extension"):
        FullSearch("c", "Pa", ("k",), (1.0, 2.0), scale="log", fades="low", extension=(1.5,))
    fs = FullSearch("c", "Pa", ("k",), (1.0, 2.0), scale="log", fades="low", extension=(4.0,))
    assert fs.strong_end == 2.0 and fs.extended().values == (1.0, 2.0, 4.0)
    with pytest.raises(ValueError, match="no value left"):
        fs.extended().extended()


def test_a_named_depth_the_numerics_check_cannot_resolve_is_withdrawn(monkeypatch):
    """A named interface depth is withdrawn when its best level at the model's grains is the
    edge of the located span (0.4 m, the last level short of the fading 0.5 m) and, at both
    grain-radius factors of the numerics check, its profile's optimum lies beyond that edge:
    the value was one bed's packing, not a located depth. The recording: layering at 0.33 m;
    the stand-in model is the scenario ROM with its interface acting shallower than asked by
    0.07 m at the own grains (so the 0.4 m level fits best) and by 0.25 m at another grain size
    (so the reruns fit best at the deepest level, 0.5 m). Then nothing is named, the verdict
    and the decision say why, the check is kept under ``fit.full_search.withdrawn``, and its
    runs are counted. Controls keep the name: reruns that locate the optimum (no shift at the
    other grains: 0.33 m), a value named inside the span (no shift at the own grains: best
    level 0.3 m) whose reruns drift out, and the screening's claim. The screening model here
    claims the layering (it is the truth's own form), so for the withdrawal its claim is
    dropped, as when the screening names nothing."""
    from crashdem import scenario
    from crashdem.diagnosis import confirm
    from crashdem.diagnosis.catalogue import DROP
    from crashdem.diagnosis.cli import rom_from_scenario
    from crashdem.diagnosis.confirm import _Confirmation, _Decision
    from crashdem.diagnosis.distributed import RADIUS_SCALE_KEY

    fs = {"soil_layering": DROP.full_search["soil_layering"]}
    truth = rom_from_scenario(scenario.loads(SCENARIO_TOML).with_overrides(
        fs["soil_layering"].overrides(0.33)))
    recording = acquire(truth, np.random.default_rng(5))
    inner = _scenario_rom_simulator([])

    def diagnose_with(own_shift, other_shift, claimed=False):
        def screened(*a, **kw):
            rep = diagnose(*a, **kw)
            if not claimed:
                rep.missing_physics = None
            return rep

        monkeypatch.setattr(confirm, "diagnose", screened)

        def shallower(ov):
            ov = dict(ov)
            if "physics.soil_layering.depth" in ov:
                d = own_shift if float(ov.get(RADIUS_SCALE_KEY, 1.0)) == 1.0 else other_shift
                ov["physics.soil_layering.depth"] = max(ov["physics.soil_layering.depth"] - d,
                                                        0.05)
            return inner(ov)

        return screen_then_confirm(simulate(RomParams()), recording, shallower, top_k=0,
                                   full_search=fs, numerics=(0.9, 1.1))

    rep = diagnose_with(0.07, 0.25)
    assert rep.missing_physics is None, rep.decision
    wd = rep.fit["full_search"]["withdrawn"]["soil_layering"]
    assert [p["value"] for p in wd["numerics"]["values"]] == [0.5, 0.5]
    assert wd["numerics"]["own_best_level"] == 0.4
    assert "at every other grain size" in wd["reason"]
    assert rep.fit["confirmation_verdicts"]["soil_layering"].startswith(
        "named, then withdrawn: its best level at the model's grains (interface_depth = 0.4 m) "
        "is at or beyond the edge of the located span")
    assert "soil_layering withdrawn: " in rep.decision
    assert rep.simulations["numerics_simulations"] == 2 * len(fs["soil_layering"].values)
    assert "named" not in rep.fit["full_search"]

    for own_shift, other_shift, best, claimed in ((0.07, 0.0, 0.4, False),
                                                  (0.0, 0.25, 0.3, False),
                                                  (0.07, 0.25, 0.4, True)):
        kept = diagnose_with(own_shift, other_shift, claimed)
        assert kept.missing_physics == "soil_layering", kept.decision
        assert "withdrawn" not in kept.fit["full_search"]
        assert kept.fit["full_search"]["named"]["numerics"]["own_best_level"] == best

    # the rule on the measured values: only when every factor located a value, never on the
    # screening's claim
    c = object.__new__(_Confirmation)
    c.searched = dict(DROP.full_search)
    c.rep = type("R", (), {"missing_physics": None})()

    def why(name, values, own, at_edge=None):
        fs = c.searched[name]
        edge = fs.edge
        if at_edge is None:
            at_edge = own >= edge if fs.fades == "high" else own <= edge
        d = _Decision(name, {"search_value": own}, None, False, None)
        return c.unresolved(d, {"hypothesis": name, "own_best_level": own,
                                "own_at_edge": at_edge, "values": [
            {"radius_scale": f, "value": v} for f, v in zip((0.9, 1.1), values)]})

    # the Yade 5 m cohesion 11 (floor named at 1.05 m) and floor 12 (layering at 0.4 m)
    assert why("boundary_proximity", [1.25, 1.25], 1.05) is not None
    assert why("soil_layering", [0.413, 0.5], 0.4) is not None
    # the DEM floor 12, named inside the span at 0.8 m: its reruns' drift is its uncertainty
    assert why("boundary_proximity", [1.056, 1.25], 0.8) is None
    assert why("boundary_proximity", [1.25, 1.0], 1.05) is None
    assert why("boundary_proximity", [None, 1.25], 1.05) is None
    # a flat profile: its first level is "best" at the fading end, but strictly nothing is
    assert why("cohesion", [3e4, 3e4], 3e4, at_edge=False) is None
    # Yade 13.7 m null 30: damping named at 0.1, its own best level the fading end 0.5
    assert why("contact_damping", [0.5, 0.5], 0.5) is not None
    # Yade 18.45 m damping 11 / 12: best level 0.1, reruns 0.5
    assert why("contact_damping", [0.5, 0.5], 0.1) is None
    # Yade free rotation 12 through the CLI: best level 0.2, reruns 0.2, the screening's claim
    assert why("particle_rotation", [0.2, 0.2], 0.2) is not None
    c.rep.missing_physics = "particle_rotation"
    assert why("particle_rotation", [0.2, 0.2], 0.2) is None


def _form_simulator(calls: list):
    """``_scenario_rom_simulator`` in which the two forms of a layer differ: a compacted lower
    layer (``physics.soil_layering.compacted = true``, denser as well as stiffer) resists as a
    stiffness-only layer of 1.8 x its modulus factor does (within the ROM's strength ratio)."""
    inner = _scenario_rom_simulator(calls)

    def full(overrides):
        ov = dict(overrides)
        if ov.pop("physics.soil_layering.compacted", True) and ov.get(
                "physics.soil_layering.enabled"):
            ov["physics.soil_layering.lower_young_factor"] = 1.8 * float(
                ov.get("physics.soil_layering.lower_young_factor", 3.0))
        return inner(ov)

    return full


@pytest.mark.parametrize("form", ["stiffness", "compacted"])
def test_the_layer_form_that_made_the_recording_is_the_one_kept(form):
    """A layer at 0.3 m made in one form (``catalogue.LAYER_FORMS``) is searched in both; the
    form that made it fits best and is kept (``fit.full_search.forms``), the level runs of the
    other are reported (``form_kept`` false) and counted, the named depth is that form's and
    the scenario fix carries the form's key. Fails when the forms are pooled together, when the
    first form is always kept, or when the dropped form's runs go uncounted."""
    from crashdem import scenario as sc
    from crashdem.diagnosis.catalogue import DROP
    from crashdem.diagnosis.cli import rom_from_scenario

    truth = {"physics.soil_layering.enabled": True, "physics.soil_layering.depth": 0.3,
             "physics.soil_layering.lower_young_factor": 5.0,
             "physics.soil_layering.compacted": form == "compacted"}
    calls: list = []
    sim = _form_simulator(calls)
    p = rom_from_scenario(sc.loads(SCENARIO_TOML).with_overrides(
        {k: v for k, v in truth.items() if k != "physics.soil_layering.compacted"}
        | ({"physics.soil_layering.lower_young_factor": 9.0} if form == "compacted" else {})))
    rec = acquire(p, np.random.default_rng(7))
    rep = screen_then_confirm(simulate(RomParams()), rec, sim, top_k=2, numerics=())
    fs_info = rep.fit["full_search"]
    assert fs_info["forms"]["soil_layering"]["chosen"] == form, fs_info["forms"]
    other = "compacted" if form == "stiffness" else "stiffness"
    got = fs_info["forms"]["soil_layering"]["forms"]
    assert got[form]["delta_bic_vs_reference"] > got[other]["delta_bic_vs_reference"]
    lay = [lv for lv in fs_info["levels"] if lv["hypothesis"] == "soil_layering"
           and not lv["refined"] and not lv["extension"]]
    n = len(DROP.full_search["soil_layering"].values)
    assert sorted(lv["form"] for lv in lay) == sorted([form] * n + [other] * n)
    assert all(lv["form_kept"] == (lv["form"] == form) for lv in lay)
    assert all(not lv["located"] for lv in lay if lv["form"] == other)
    assert rep.simulations["full_simulations"] == len(calls)
    assert rep.missing_physics == "soil_layering", rep.decision
    h = next(h for h in rep.hypotheses if h["name"] == "soil_layering")
    assert h["full_model"]["form"] == form
    assert h["scenario_overrides"]["physics.soil_layering.compacted"] == (form == "compacted")
    assert abs(h["parameters"]["interface_depth"] / 0.3 - 1.0) < 0.15, h["parameters"]


def _diagnose_stiffer_below(depth: float, tiered: bool = False):
    """``screen_then_confirm`` on a recording of the bed with its grains 5 x stiffer below
    ``depth`` [m] (stiffness form; the stand-in full model, 5 level beds, 4 replicates; with
    ``tiered`` the search, the replicates and the realisation floor on a separate search
    simulator); every run is counted, each distinct run once (the floor's bed x5 stiffer below
    0.15 m is the search's own 0.15 m x5 level, run once)."""
    from crashdem import scenario as sc
    from crashdem.diagnosis.cli import rom_from_scenario

    calls: list = []
    search_calls: list = []
    p = rom_from_scenario(sc.loads(SCENARIO_TOML).with_overrides(
        {"physics.soil_layering.enabled": True, "physics.soil_layering.depth": depth,
         "physics.soil_layering.lower_young_factor": 5.0}))
    rec = acquire(p, np.random.default_rng(7))
    kw = {"search_simulator": _form_simulator(search_calls)} if tiered else {}
    rep = screen_then_confirm(simulate(RomParams()), rec, _form_simulator(calls), top_k=2,
                              numerics=(), level_beds=5,
                              replicates=[{"scenario.seed": s} for s in (2, 3, 4, 5)], **kw)
    for c in (calls, search_calls):
        assert len({json.dumps(ov, sort_keys=True) for ov in c}) == len(c)
    assert rep.simulations["full_simulations"] == len(calls)
    if tiered:
        assert rep.simulations["search_simulations"] == len(search_calls)
        assert len(calls) <= 1 + 2 and rep.fit["realisation"]["tier"] == "search simulator"
        assert not any(ov.get("physics.soil_layering.depth") == WHOLE_BED_DEPTH for ov in calls)
    return rep


@pytest.mark.parametrize("tiered", [False, True], ids=["one tier", "search tier"])
def test_a_stiffer_soil_is_not_named_a_layer(tiered):
    """A recording of the whole bed made stiffer (every grain's modulus x5: a wrong soil value,
    a recalibration) is not named ``soil_layering``, whose shallowest level (0.15 m, x5) comes
    close to it: the full tier runs the whole bed x2 and x5 stiffer on the level beds
    (``catalogue.stiffer_soil_overrides``) and an effect has to beat them as it beats the
    replicates (``fit.realisation.stiffer_soil``, counted in the full runs). A layer at 0.3 m is
    still named. On a two-tier confirmation the runs are the search tier's, beside its
    replicates, and set the floor its levels are promoted against; the screening's claim (a
    layer, here) is held there to the replicates and the bed made as stiff as the layer levels
    (x5: ``layer_level_factor``), which its best level fits decisively worse than. Fails
    without the whole-bed runs (the layer at 0.15 m is named), and on two tiers without them
    in the claim's floor (the claim, whose full run has only the reference to beat, is named)."""
    from crashdem.diagnosis.catalogue import DROP, layer_level_factor, stiffer_soil_overrides

    lay = DROP.full_search["soil_layering"]
    ov = stiffer_soil_overrides(lay, 5.0)
    assert ov["physics.soil_layering.depth"] == WHOLE_BED_DEPTH
    assert ov["physics.soil_layering.compacted"] is False
    assert ov["physics.soil_layering.lower_young_factor"] == 5.0
    assert stiffer_soil_overrides(lay.with_form("compacted"), 5.0) is None
    assert stiffer_soil_overrides(lay.with_form("stiffness"), 2.0)[
        "physics.soil_layering.lower_young_factor"] == 2.0

    assert layer_level_factor(lay) == 5.0 == max(STIFFER_SOIL_FACTORS)
    assert layer_level_factor(lay.with_form("compacted")) is None is layer_level_factor(None)
    rep = _diagnose_stiffer_below(WHOLE_BED_DEPTH, tiered)
    assert rep.missing_physics is None, rep.decision
    if tiered:
        assert ("worse than the best replicate packing there or the bed made as stiff as its "
                "levels" in rep.fit["confirmation_verdicts"]["soil_layering"])
    stiff = rep.fit["realisation"]["stiffer_soil"]
    top = min(lay.values)
    assert [(s["form"], s["young_factor"], s["below_m"]) for s in stiff] == [
        ("whole bed", 2.0, WHOLE_BED_DEPTH), ("whole bed", 5.0, WHOLE_BED_DEPTH),
        (f"below {top:g} m", 2.0, top), (f"below {top:g} m", 5.0, top)]
    assert all(s["runs"] == 5 for s in stiff)
    assert rep.fit["realisation"]["floor_delta_bic"] == pytest.approx(
        max(s["delta_bic_vs_reference"] for s in stiff))
    assert ("and the whole bed x2 / x5 stiffer and the bed below 0.15 m x2 / x5 stiffer"
            in rep.decision)
    rep = _diagnose_stiffer_below(0.3, tiered)
    assert rep.missing_physics == "soil_layering", rep.decision


def test_a_grain_factor_scales_the_top_grain_row(monkeypatch):
    """The grain check and the grain fit make the confirmation again with every grain radius
    times a factor: the top grain row of the levels' bed (``FullSearch.top_row_depth``, where
    the floor makes the bed stiffer below) is one grain diameter, so it scales with them; a
    search without it (the shallowest level) and the other effects are passed on as they are."""
    from crashdem.diagnosis import confirm
    from crashdem.diagnosis.catalogue import DROP

    seen: dict = {}
    monkeypatch.setattr(confirm, "_confirm_pass",
                        lambda base, rec, full, search, **kw: seen.update(kw))
    lay = replace(DROP.full_search["soil_layering"], top_row_depth=0.15)
    fs = {"soil_layering": lay, "cohesion": DROP.full_search["cohesion"]}
    confirm._scaled_pass(1.25, {}, lambda ov: {}, None, full_search=fs)
    assert seen["full_search"]["soil_layering"].top_row_depth == pytest.approx(0.1875)
    assert seen["full_search"]["cohesion"] is fs["cohesion"]
    assert fs["soil_layering"].top_row_depth == 0.15  # the caller's search is not changed
    confirm._scaled_pass(0.8, {}, lambda ov: {}, None, full_search=dict(DROP.full_search))
    assert seen["full_search"]["soil_layering"].top_row_depth is None


@pytest.mark.parametrize("tiered", [False, True], ids=["one tier", "search tier"])
def test_a_bed_stiffer_below_its_top_grain_row_is_in_the_realisation_floor(tiered):
    """The floor holds the bed made 2 x and 5 x stiffer below its top grain row, the
    stiffness-form layer at the search's shallowest level (0.15 m: one diameter of the
    campaign's grains; ``catalogue.stiffer_soil_depths``): how stiff the surface row is against
    the confined grains is not one of the catalogue's physics (a Hertzian contact law, another
    code's surface). On a recording of that bed the 0.15 m layer level fits no better than the
    floor, so the search cannot name it (on the Yade recordings every such name came from the
    search; a claim of the screening model is held to the floor as before, and stands here,
    where the screening model made the recording). The same bed stiffer below 0.2 m, a grain
    deeper, is still named a layer. The same on a two-tier confirmation, where the floor is the
    search tier's. Fails without the below-the-top-row runs (the floor is the whole bed's, below
    the 0.15 m level)."""
    from crashdem.diagnosis.catalogue import DROP, stiffer_soil_depths

    lay = DROP.full_search["soil_layering"]
    assert stiffer_soil_depths(lay) == (WHOLE_BED_DEPTH, 0.15)
    assert stiffer_soil_depths(None) == ()

    rep = _diagnose_stiffer_below(0.15, tiered)
    real = rep.fit["realisation"]
    below = [s for s in real["stiffer_soil"] if s["below_m"] == 0.15]
    assert [s["young_factor"] for s in below] == [2.0, 5.0] and all(
        s["runs"] == 5 for s in below)
    level = next(lv for lv in rep.fit["full_search"]["levels"]
                 if lv["hypothesis"] == "soil_layering" and lv["form"] == "stiffness"
                 and lv["value"] == 0.15 and not lv["refined"])
    # the 0.15 m x5 level is the below-the-top-row x5 run: the same runs, the same change
    assert below[1]["delta_bic_vs_reference"] == pytest.approx(level["delta_bic_vs_reference"])
    assert real["floor_delta_bic"] == pytest.approx(
        max(s["delta_bic_vs_reference"] for s in below))
    assert real["floor_delta_bic"] >= level["delta_bic_vs_reference"]
    whole = [s for s in real["stiffer_soil"] if s["form"] == "whole bed"]
    assert max(s["delta_bic_vs_reference"] for s in whole) < level["delta_bic_vs_reference"]
    rep = _diagnose_stiffer_below(0.2, tiered)
    assert rep.missing_physics == "soil_layering", rep.decision
    h = next(h for h in rep.hypotheses if h["name"] == "soil_layering")
    assert abs(h["parameters"]["interface_depth"] / 0.2 - 1.0) < 0.15, h["parameters"]


def test_each_form_reads_back_as_itself():
    """``FullSearch.form_of`` on the overrides of each variant's levels gives that variant's
    form, also for a form that only adds a key to another's (its value in ``fixed`` tells them
    apart; matching a form by its own keys alone read the second form's runs as the first's);
    a kept form reads as itself, a search of one form as None; too few forms, or two of one
    name, are refused naming the field."""
    from crashdem.diagnosis.catalogue import FullSearch

    lay = "physics.soil_layering."
    fs = FullSearch("interface_depth", "m", (lay + "depth",), (0.2, 0.3),
                    {lay + "enabled": True, lay + "lower_young_factor": 5.0},
                    forms=(("stiffness", {lay + "compacted": False}),
                           ("compacted", {lay + "compacted": True}),
                           ("stiffness_x10", {lay + "compacted": False,
                                              lay + "lower_young_factor": 10.0})))
    assert fs.n_levels == 6
    for v in fs.variants():
        for x in v.values:
            assert fs.form_of({**v.overrides(x), "scenario.seed": 2}) == v.form
    assert fs.with_form("stiffness_x10").form_of({}) == "stiffness_x10"
    assert FullSearch("restitution", "1", ("k",), (0.1, 0.2)).form_of({"k": 0.1}) is None
    with pytest.raises(ValueError, match="forms: no form 'none'"):
        fs.with_form("none")
    for bad in ((("a", {}),), (("a", {}), ("a", {"k": 1}))):
        with pytest.raises(ValueError, match="FullSearch.interface_depth.forms"):
            replace(fs, forms=bad)


@pytest.mark.parametrize("level_105, level_125, named, why", [
    ((-2.9, 0.789), (35.0, 0.862), None, "no level of it short of the end where it fades"),
    ((-2.9, 0.789), (5.0, 0.80), None, "its best level (1.05 m, Delta BIC -2.9"),
    ((30.0, 0.85), (35.0, 0.862), "boundary_proximity", None)])
def test_a_screened_candidate_must_also_hold_on_the_search_tier(level_105, level_125, named,
                                                                why):
    """Two-tier confirmation (the CLI at the drop scenario's own resolution): the screening
    claims nothing, its two best candidates run in the full model, and the replicates ran on
    the search tier. The floor candidate's full run (a 2.21 m floor, the screening's reflected
    pulse: in the DEM a deeper bed, i.e. another deposition) beats the reference decisively
    (15.1, score 0.860 against 0.832). On the search tier the floor's profile rises to its
    fading end (1.25 m, 35.0) from -2.9 at 1.05 m, more than the replicates' scatter (11.8)
    below it, so no located level stands for the floor; with the end level low (5.0) its best
    located level (1.05 m, -2.9) is decisively worse than the best replicate (22.1). Either
    way the candidate does not hold there, as the screening's claim would not, and nothing is
    named. With a located level that holds (30.0, 0.85) it is named. Numbers:
    ``validation/diagnose_cost.py`` (contact restitution 0.15 at 0.075 m grains), which named
    ``boundary_proximity`` before (session 38)."""
    from crashdem.diagnosis.catalogue import DROP_FULL_SEARCH as FS
    from crashdem.diagnosis.confirm import (
        REPLICATE,
        _Confirmation,
        _FullTier,
        _realisation_floor,
        _SearchTier,
    )

    tier_rows = ([_run("baseline", 0.0, 0.832)]
                 + [_run("boundary_proximity", db, sc, v) for db, sc, v in
                    ((-21.2, 0.529, 0.6), (-26.2, 0.551, 0.7), (-5.9, 0.681, 0.8),
                     (-26.4, 0.602, 0.9), (*level_105, 1.05), (*level_125, 1.25))]
                 + [_run("contact_damping", db, sc, v) for db, sc, v in
                    ((38.4, 0.848, 0.1), (39.1, 0.846, 0.2), (39.0, 0.84, 0.3), (37.1, 0.84, 0.5))]
                 + [_run(REPLICATE, db, sc) for db, sc in ((2.6, 0.742), (-0.5, 0.741),
                                                           (-4.6, 0.645), (22.1, 0.780))])
    tier = _SearchTier(tier_rows, _realisation_floor(tier_rows, 0.832), [], [], {})
    rows = [_run("recalibration", 0.0, 0.608), _run("boundary_proximity", 15.1, 0.860),
            _run("contact_damping", 8.4, 0.902)]
    full = _FullTier(rows, 0.832, _realisation_floor(rows, 0.832))
    c = object.__new__(_Confirmation)
    c.rep = type("R", (), {"missing_physics": None, "fit": {}})()
    c.searched, c.model_free = dict(FS), None
    d = c.decide(full, tier)
    assert d.confirmed == named
    if named is None:
        line = d.unheld["boundary_proximity"]
        assert line.startswith("a screened candidate, but on the search simulator ")
        assert why in line
        assert c.verdicts(full, d)["boundary_proximity"] == line
        assert d.best is rows[0]
    else:
        assert d.unheld == {} and d.best is rows[1]
    # one tier (the replicates among the full runs): the rule does not apply
    assert c.decide(full).confirmed == "boundary_proximity"


def test_a_candidate_the_screening_left_off_runs_at_its_search_level():
    """Two-tier confirmation: a screened candidate of a searched effect whose mapped parameter
    the screening left at its ``off`` value (the floor at the modelled 2 m bed: the screening
    model did not place it) runs in the full model at the level that stands for the effect on
    the search tier, not at the catalogue's nominal value, and is reported with that value,
    its uncertainty from the search tier's profile. A candidate the screening placed keeps its
    own value, and one tier has no search level to take. Rows: ``validation/diagnose_cost.py
    --effect boundary_proximity --value 0.8`` (session 39), whose floor candidate ran at the
    nominal 1.2 m and was named there while the search tier stood at 0.9 m."""
    from crashdem.diagnosis.catalogue import DROP_FULL_SEARCH as FS
    from crashdem.diagnosis.catalogue import drop_catalogue
    from crashdem.diagnosis.confirm import (
        REPLICATE,
        _adopt_full_parameters,
        _Confirmation,
        _confirmation_overrides,
        _realisation_floor,
        _SearchTier,
    )

    fs = FS["boundary_proximity"]
    levels = [_run("boundary_proximity", db, sc, v) for db, sc, v in
              ((-22.6, 0.72, 0.6), (-47.5, 0.667, 0.7), (-25.9, 0.638, 0.8), (6.8, 0.825, 0.9),
               (-14.0, 0.683, 1.05), (-26.1, 0.73, 1.25))]
    for r in levels:
        r["overrides"] = fs.overrides(r["search_value"])
    tier_rows = ([_run("baseline", 0.0, 0.611)] + levels
                 + [_run(REPLICATE, db, sc) for db, sc in ((-13.4, 0.77), (-9.3, 0.76),
                                                           (8.8, 0.774), (-21.2, 0.635))])
    floor = _realisation_floor(tier_rows, 0.696)
    tier = _SearchTier(tier_rows, floor, [], [], {}, {"boundary_proximity": levels[3]})
    cat = drop_catalogue(RomParams())
    c = object.__new__(_Confirmation)
    c.rep = type("R", (), {"catalogue": cat})()
    c.searched = dict(FS)

    def cand(depth):
        return {"name": "boundary_proximity", "recalibration": {},
                "parameters": {"floor_depth": depth, "wave_reflection": 1.0}}

    left_off = cand(1.9999998)
    # before: the nominal value (1.2 m) took the screening's place
    assert _confirmation_overrides(left_off, cat)["physics.boundary_proximity.floor_depth"] == 1.2
    assert c.level_for_candidate(left_off, tier) is levels[3]
    assert c.level_for_candidate(cand(0.85), tier) is None  # placed by the screening
    assert c.level_for_candidate(left_off, None) is None  # one tier
    assert c.level_for_candidate({**left_off, "name": "sensor_dynamics"}, tier) is None
    # ``record`` asks again for the named candidate: the same level
    assert c.level_for_candidate(left_off, tier) is levels[3]

    # named: the value reported is the level it ran at, not the screening's 2 m
    h = {**left_off, "uncertainty": {"floor_depth": 0.07, "wave_reflection": 0.15}}
    rep = type("R", (), {"hypotheses": [h], "fit": {}})()
    run = {**_run("boundary_proximity", 23.9, 0.881), "overrides": dict(levels[3]["overrides"])}
    _adopt_full_parameters(rep, {**run, "search_value": 0.9}, fs, tier_rows, floor)
    assert h["parameters"]["floor_depth"] == 0.9
    assert h["screening_parameters"]["floor_depth"] == 1.9999998
    assert h["scenario_overrides"]["physics.boundary_proximity.floor_depth"] == 0.9
    assert h["full_model"]["uncertainty"]["floor_depth"] > 0.0
    assert rep.fit["full_search"]["named"]["floor_depth"] == 0.9


def test_a_candidate_whose_full_run_is_the_baseline_is_not_run():
    """A screened candidate with every mapped parameter at its ``off`` value, the nominal put
    in its place included (a speed offset of 0 m/s: nominal and off are both 0), would run
    the baseline simulation again: it is not run (``skipped``, with the reason) and keeps its
    place among the ``top_k``, unless it is the screening's claim. A candidate the nominal
    switches on (a floor left at the modelled bed runs at 1.2 m) and one with a model form of
    its own are run. Measured at the default resolution: such a run gave the reference's own
    score (0.832) and Delta BIC -3.1."""
    from crashdem.diagnosis.catalogue import drop_catalogue
    from crashdem.diagnosis.confirm import _Confirmation, _runs_the_baseline

    cat = drop_catalogue(RomParams())
    speed0 = {"name": "initial_conditions", "parameters": {"speed_offset": 0.01},
              "recalibration": {}}
    floor_off = {"name": "boundary_proximity", "recalibration": {},
                 "parameters": {"floor_depth": 2.0, "wave_reflection": 1.0}}
    damping = {"name": "contact_damping", "parameters": {"restitution": 0.3},
               "recalibration": {}}
    assert _runs_the_baseline(speed0, cat)
    assert not _runs_the_baseline({**speed0, "parameters": {"speed_offset": 1.5}}, cat)
    assert not _runs_the_baseline(floor_off, cat)
    assert not _runs_the_baseline({**speed0, "variant": "mount"}, cat)

    def chosen(missing, hyps, top_k=2):
        c = object.__new__(_Confirmation)
        c.rep = type("R", (), {"catalogue": cat, "missing_physics": missing,
                               "fit": {"recalibration_unexplained": True},
                               "hypotheses": [{"name": "recalibration"}, *hyps]})()
        c.top_k, c.skipped = top_k, {}
        return [h["name"] for h in c._candidates()], c.skipped

    names, skipped = chosen(None, [damping, speed0, floor_off])
    assert names == ["contact_damping"]  # the offset keeps its place: no third run
    assert "the baseline simulation" in skipped["initial_conditions"]
    assert chosen(None, [speed0, damping, floor_off])[0] == ["contact_damping"]
    assert chosen(None, [damping, floor_off, speed0])[0] == ["contact_damping",
                                                              "boundary_proximity"]
    # the screening's claim runs whatever its value
    assert chosen("initial_conditions", [speed0, damping]) == (
        ["initial_conditions", "contact_damping"], {})


def test_grain_fit_tier_is_the_scenario_grains_in_the_search_tier_container(tmp_path):
    """``--grain-fit-tier tier``: when the search runs on the coarse tier, the grain fit runs
    on the scenario's own grains in that tier's container (``cli.grain_fit_tier``), as long
    as one impact there costs at most ``GRAIN_FIT_TIER_LOAD``; the campaign scenario with its
    compacted layer (load 3,553 in the 2 m tank) does. Finer grains than that, ``search`` (the
    default), or a search on the scenario itself leave it on the search's simulator; ``full``
    takes the confirmation's simulator; no grain fit, no tier; an unknown mode is an error
    naming the option."""
    scenario = pytest.importorskip("crashdem.scenario")
    from crashdem.cli import build_parser
    from crashdem.diagnosis.cli import (
        GRAIN_FIT_TIER_LOAD,
        _grain_fit_setup,
        grain_fit_tier,
        search_load,
    )
    from crashdem.diagnosis.generator_dem import scenario_path

    campaign = scenario.load(scenario_path())
    assert campaign.get("physics.soil_layering.enabled")
    assert grain_fit_tier(campaign) == {"container.diameter": 2.0}
    load = search_load(campaign.with_overrides(grain_fit_tier(campaign)))
    assert load == pytest.approx(3553, abs=1) and load <= GRAIN_FIT_TIER_LOAD

    coarse_search = object()  # a search on the coarse tier (only its presence is read)

    def setup(scen, mode="tier", search=coarse_search, factors=(1.25,), name="g"):
        return _grain_fit_setup(scen, search, factors, mode, {}, tmp_path / name)

    sim, how = setup(campaign)
    assert callable(sim)
    assert "the scenario's grains in the coarse tier's container (container.diameter=2" in how
    assert "3,553 <= 5,000" in how
    assert setup(campaign, factors=()) == (None, None)
    sim, how = setup(campaign, "search")
    assert sim is None and "--grain-fit-tier search" in how
    parser = build_parser()
    args = parser.parse_args(["diagnose", "--scenario", "s.toml", "--recording", "r.csv",
                              "--out", "o"])
    assert args.grain_fit_tier is None  # the CLI reads None as "search"
    sim, how = setup(campaign, search=None)
    assert sim is None and "the scenario itself" in how
    fine = campaign.with_overrides({"soil.radius": 0.05})
    sim, how = setup(fine, name="fine")
    assert sim is None and f"> {GRAIN_FIT_TIER_LOAD:,}" in how, how
    full = object()
    assert _grain_fit_setup(campaign, object(), (1.25,), "full", {}, tmp_path / "f",
                            full_sim=full)[0] is full
    with pytest.raises(ValueError, match="--grain-fit-tier='coarse': must be one of search, "
                                         "tier, full"):
        setup(campaign, "coarse")


def test_grain_choice_moves_only_beyond_the_packing_scatter():
    """``confirm.grain_choice``: another grain size is taken only when its mean BIC beats the
    model's grains by the margin and by ``GRAIN_FIT_SE`` standard errors of the difference.
    Measured figures: the full-model grain fit at the default resolution on a recording of
    1.25 x grains (43.9 +- 9.7 at 1 x, 29.2 +- 14.3 at 0.8 x, 5 realisations each: 14.7 is
    1.9 standard errors, so it stays, where the margin alone took 0.8 x and then named a
    floor); the Yade null 24 on the small bed (session 48: 63.4 +- 5.9 at 1 x, 70.1 +- 4.0 at
    0.8 x, 42.9 +- 6.2 at 1.25 x, 37.4 +- 10.2 at 1.5 x: it moves, to 1.25 x, by 5.4 standard
    errors, the nearest within the margin of the best). One realisation per size has no
    scatter to weigh: the margin alone decides."""
    from crashdem.diagnosis.confirm import GRAIN_FIT_MARGIN, GRAIN_FIT_SE, grain_choice

    def size(f, mean, sd, n=5):
        return {"radius_scale": f, "bic_mean": mean, "bic_sd": sd, "realisations": n}

    default_res = [size(1.0, 43.9, 9.7), size(0.8, 29.2, 14.3), size(1.25, 39.2, 15.6),
                   size(1.5, 46.3, 22.2)]
    assert grain_choice(default_res) == 1.0
    d = {s["radius_scale"]: s for s in default_res}
    assert d[0.8]["delta_bic_vs_model"] == pytest.approx(14.7)
    assert d[0.8]["se_vs_model"] == pytest.approx(math.sqrt((9.7**2 + 14.3**2) / 5))
    assert GRAIN_FIT_MARGIN < d[0.8]["delta_bic_vs_model"] < GRAIN_FIT_SE * d[0.8]["se_vs_model"]
    # the same means with half the scatter: it moves
    assert grain_choice([size(1.0, 43.9, 4.8), size(0.8, 29.2, 7.1)]) == 0.8

    yade = [size(1.0, 63.4, 5.9), size(0.8, 70.1, 4.0), size(1.25, 42.9, 6.2),
            size(1.5, 37.4, 10.2)]
    assert grain_choice(yade) == 1.25
    assert yade[2]["delta_bic_vs_model"] / yade[2]["se_vs_model"] == pytest.approx(5.4, abs=0.05)
    # with sds of at most 4, two standard errors stay below the margin: the margin decides
    assert GRAIN_FIT_SE * math.sqrt(2 * 4.0**2 / 5) < GRAIN_FIT_MARGIN
    assert grain_choice([size(1.0, 50.0, 4.0), size(1.25, 43.9, 4.0)]) == 1.25
    assert grain_choice([size(1.0, 50.0, 4.0), size(1.25, 44.0, 4.0)]) == 1.0  # the margin

    single = [size(1.0, 50.0, None, 1), size(1.25, 43.0, None, 1)]
    assert grain_choice(single) == 1.25 and single[1]["se_vs_model"] == 0.0
    assert grain_choice([size(1.25, 10.0, 1.0)]) == 1.0  # the model's grains not rated


@pytest.mark.parametrize("tiered", [False, True], ids=["one tier", "search tier"])
def test_a_recording_the_other_contact_law_explains_is_not_claimed(tiered):
    """The realisation floor holds the whole bed with the Hertz-Mindlin law (``FullSearch.
    hertz_floor``, ``catalogue.hertz_floor_overrides``: the scenario's bed, the law switched,
    4 x the modulus), beside the replicates and the stiffer beds: a recording that crashdem's
    own bed under the other law explains is not missing physics. Stand-in: the full model's
    Hertz-Mindlin run is the layer at 0.3 m (which the ROM stand-in cannot make otherwise), and
    the recording is that layer: it is named without the Hertz run (``test_a_stiffer_soil_is_
    not_named_a_layer``) and not with it; the Hertz runs are made on every level bed, counted,
    reported (form ``Hertz-Mindlin``) and named in the decision. Fails without the run in the
    floor."""
    from crashdem import scenario as sc
    from crashdem.diagnosis.catalogue import DROP, HERTZ_FLOOR_FORM, hertz_floor_overrides
    from crashdem.diagnosis.cli import rom_from_scenario

    lay = replace(DROP.full_search["soil_layering"], hertz_floor=4.0)
    ov = hertz_floor_overrides(lay)
    assert ov["soil.contact_law"] == "hertz_mindlin"
    assert ov["physics.soil_layering.depth"] == WHOLE_BED_DEPTH
    assert ov["physics.soil_layering.lower_young_factor"] == 4.0
    assert hertz_floor_overrides(DROP.full_search["soil_layering"]) is None
    assert hertz_floor_overrides(lay.with_form("compacted")) is None
    # a layer no level makes (they run x5)
    layer = {"physics.soil_layering.enabled": True, "physics.soil_layering.depth": 0.3,
             "physics.soil_layering.lower_young_factor": 2.5}

    def with_law(calls):
        inner = _form_simulator(calls)

        def full(overrides):
            o = dict(overrides)
            if o.pop("soil.contact_law", "linear") == "hertz_mindlin":
                o.update(layer)
                calls.append(None)  # counted once: the inner call is popped below
                out = inner(o)
                calls.pop()
                calls[-1] = dict(overrides)
                return out
            return inner(o)

        return full

    calls: list = []
    search_calls: list = []
    p = rom_from_scenario(sc.loads(SCENARIO_TOML).with_overrides(layer))
    rec = acquire(p, np.random.default_rng(7))
    kw = {"search_simulator": with_law(search_calls)} if tiered else {}
    rep = screen_then_confirm(simulate(RomParams()), rec, with_law(calls), top_k=2,
                              numerics=(), level_beds=5, full_search={
                                  **DROP.full_search, "soil_layering": lay},
                              replicates=[{"scenario.seed": s} for s in (2, 3, 4, 5)], **kw)
    assert rep.missing_physics is None, rep.decision
    hz = [s for s in rep.fit["realisation"]["stiffer_soil"] if s["form"] == HERTZ_FLOOR_FORM]
    assert len(hz) == 1 and hz[0]["young_factor"] == 4.0 and hz[0]["runs"] == 5
    assert rep.fit["realisation"]["floor_delta_bic"] == pytest.approx(
        hz[0]["delta_bic_vs_reference"])
    made = [c for c in (search_calls if tiered else calls)
            if c.get("soil.contact_law") == "hertz_mindlin"]
    assert len(made) == 5
    assert "the whole bed with the Hertz-Mindlin law (x4 the modulus)" in rep.decision
    assert rep.simulations["full_simulations"] == len(calls)


def _modulus_simulator(calls: list, hertz: dict[str, Any] | None = None):
    """``_form_simulator`` that also takes the grains' impact modulus factor
    (``soil.impact_young_factor``): the whole bed that many times stiffer, which the ROM knows as
    a stiffness layer just below the surface (``WHOLE_BED_DEPTH``); a run in the Hertz-Mindlin
    law is the recording made with ``hertz`` (scenario keys) when given, else the linear law's."""
    inner = _form_simulator(calls)

    def full(overrides):
        o = dict(overrides)
        f = float(o.pop("soil.impact_young_factor", 1.0))
        law = o.pop("soil.contact_law", "linear")
        extra = dict(hertz) if law == "hertz_mindlin" and hertz else {}
        if f != 1.0 and not extra:
            assert not o.get("physics.soil_layering.enabled")  # no layering is searched here
            extra = {"physics.soil_layering.enabled": True,
                     "physics.soil_layering.depth": WHOLE_BED_DEPTH,
                     "physics.soil_layering.lower_young_factor": f}
        if not extra:
            return inner(o)
        out = inner({**o, **extra})
        calls[-1] = dict(overrides)  # the call as the diagnosis made it
        return out

    return full


def _diagnose_without_layering(truth: dict[str, Any], bed_floor, tiered: bool = False,
                               hertz: dict[str, Any] | None = None):
    """``screen_then_confirm`` as ``crashdem diagnose`` makes it on a scenario with its own
    layering, where the layering is not searched: a recording of the stand-in with ``truth``
    (scenario keys), the drop search without ``soil_layering``, 5 level beds, 4 replicates
    and ``bed_floor`` (``catalogue.BedFloor``); with ``tiered`` the search and the floor on a
    search simulator. Every run is counted, each distinct run once. The screening leaves the
    layering out too: a claim of it would move the scenario's own interface, which no level of
    the search runs (on two tiers its full run has only the reference to beat, and the
    stand-in's recording of a stiffer bed is claimed as a layer there)."""
    from crashdem import scenario as sc
    from crashdem.diagnosis.catalogue import DROP
    from crashdem.diagnosis.cli import rom_from_scenario

    calls: list = []
    search_calls: list = []
    rec = acquire(rom_from_scenario(sc.loads(SCENARIO_TOML).with_overrides(truth)),
                  np.random.default_rng(7))
    kw = {"search_simulator": _modulus_simulator(search_calls, hertz)} if tiered else {}
    rep = screen_then_confirm(
        simulate(RomParams()), rec, _modulus_simulator(calls, hertz), top_k=2, numerics=(),
        level_beds=5, full_search={k: v for k, v in DROP.full_search.items()
                                   if k != "soil_layering"},
        replicates=[{"scenario.seed": s} for s in (2, 3, 4, 5)], bed_floor=bed_floor,
        hypotheses=[n for n in DROP.names if n != "soil_layering"], **kw)
    for c in (calls, search_calls):
        assert len({json.dumps(ov, sort_keys=True) for ov in c}) == len(c)
    assert rep.simulations["full_simulations"] == len(calls)
    if tiered:
        assert rep.simulations["search_simulations"] == len(search_calls)
        assert not any("soil.impact_young_factor" in ov for ov in calls)
    return rep, (search_calls if tiered else calls)


@pytest.mark.parametrize("tiered", [False, True], ids=["one tier", "search tier"])
def test_a_stiffer_soil_is_in_the_floor_when_the_layering_is_the_scenarios(tiered, tmp_path):
    """On a scenario with its own layering (the campaign's compacted lower part) the layering
    is not searched, so the floor had no stiffer bed: a recording of the whole bed 5 x stiffer
    (a wrong soil value, a recalibration) was named ``cohesion``, whose strong levels stand in
    for a stiffer bed. With ``catalogue.BedFloor`` the whole bed runs x2 and x5 stiffer through
    the grains' impact modulus and in the Hertz-Mindlin law at x4, on the 5 level beds, beside
    the replicates (``fit.realisation.stiffer_soil``, counted), and nothing is named; a
    cohesion, a floor and a contact damping are still named, at their values. Fails without
    the runs (cohesion is named)."""
    from crashdem.diagnosis.catalogue import HERTZ_FLOOR_FORM, BedFloor

    stiff = {"physics.soil_layering.enabled": True,
             "physics.soil_layering.depth": WHOLE_BED_DEPTH,
             "physics.soil_layering.lower_young_factor": 5.0}
    rep, _ = _diagnose_without_layering(stiff, None, tiered)
    assert rep.missing_physics == "cohesion", rep.decision
    assert not rep.fit["realisation"].get("stiffer_soil")

    floor = BedFloor(hertz=4.0)
    assert floor.factors == STIFFER_SOIL_FACTORS
    rep, made = _diagnose_without_layering(stiff, floor, tiered)
    assert rep.missing_physics is None, rep.decision
    real = rep.fit["realisation"]
    assert [(s["form"], s["young_factor"], s["runs"]) for s in real["stiffer_soil"]] == [
        ("whole bed", 2.0, 5), ("whole bed", 5.0, 5), (HERTZ_FLOOR_FORM, 4.0, 5)]
    assert real["floor_delta_bic"] == pytest.approx(
        max(s["delta_bic_vs_reference"] for s in real["stiffer_soil"]))
    # each stiffer run on a level bed: the baseline's packing and the 4 replicates'
    seeds = sorted(ov.get("scenario.seed", 1) for ov in made
                   if ov.get("soil.impact_young_factor") == 5.0)
    assert seeds == [1, 2, 3, 4, 5]
    assert sum(ov.get("soil.contact_law") == "hertz_mindlin" for ov in made) == 5
    assert ("and the whole bed x2 / x5 stiffer and the whole bed with the Hertz-Mindlin law "
            "(x4 the modulus)" in rep.decision)
    write_report(rep, tmp_path, plots=False)
    md = (tmp_path / "report.md").read_text()
    assert "in the whole bed (both layers of the scenario's own layering" in md
    assert "below its top grain row" not in md

    for truth, name, key, value in (
            ({"physics.cohesion.enabled": True, "physics.cohesion.normal_strength": 1.2e5,
              "physics.cohesion.shear_strength": 1.2e5}, "cohesion", "cohesion", 1.2e5),
            ({"physics.boundary_proximity.enabled": True,
              "physics.boundary_proximity.floor_depth": 0.9}, "boundary_proximity",
             "floor_depth", 0.9),
            ({"physics.contact_damping.enabled": True,
              "physics.contact_damping.restitution": 0.2}, "contact_damping", "restitution",
             0.2)):
        rep, _ = _diagnose_without_layering(truth, floor, tiered)
        assert rep.missing_physics == name, rep.decision
        h = next(h for h in rep.hypotheses if h["name"] == name)
        assert abs(h["parameters"][key] / value - 1.0) < 0.15, h["parameters"]


def test_the_bed_floor_is_the_command_lines_on_a_layered_scenario(monkeypatch):
    """``crashdem diagnose`` gives the floor's stiffer soil through the modulus
    (``cli._bed_floor``) when the scenario has its own layering and the search runs: with the
    Hertz-Mindlin run at ``HERTZ_FLOOR_YOUNG_FACTOR`` for a linear scenario, without it for a
    Hertz-Mindlin one; not when the layering is searched (its stiffness form makes the runs),
    nor without a search, nor without a layering. A law fit that takes the other law drops the
    Hertz-Mindlin run (it would be that law at another modulus), as it drops
    ``FullSearch.hertz_floor``. Bad factors name the field and the range."""
    from types import SimpleNamespace

    from crashdem import scenario as sc
    from crashdem.diagnosis import confirm
    from crashdem.diagnosis.catalogue import DROP, HERTZ_FLOOR_YOUNG_FACTOR, BedFloor
    from crashdem.diagnosis.cli import _bed_floor

    base = sc.loads(SCENARIO_TOML)
    layered = base.with_overrides({"physics.soil_layering.enabled": True,
                                   "physics.soil_layering.depth": 1.0})
    fs = {k: v for k, v in DROP.full_search.items() if k != "soil_layering"}
    assert _bed_floor(layered, fs) == BedFloor(hertz=HERTZ_FLOOR_YOUNG_FACTOR)
    assert _bed_floor(layered.with_overrides({"soil.contact_law": "hertz_mindlin"}),
                      fs) == BedFloor()
    assert _bed_floor(layered, {}) is None
    assert _bed_floor(base, fs) is None
    assert _bed_floor(base, DROP.full_search) is None
    assert BedFloor(hertz=4.0).overrides() == [
        (2.0, {"soil.impact_young_factor": 2.0}), (5.0, {"soil.impact_young_factor": 5.0}),
        (4.0, {"soil.impact_young_factor": 4.0, "soil.contact_law": "hertz_mindlin"})]
    for bad in ({"factors": (2.0, 0.0)}, {"hertz": 1e3}, {"factors": (float("nan"),)}):
        with pytest.raises(ValueError, match=r"BedFloor\.(factors|hertz).*impact_young_factor"):
            BedFloor(**bad)

    class Stop(Exception):
        pass

    seen: dict = {}

    def varied(make, rec, full, search, **kw):
        seen.update(kw, law=make(full).law)
        raise Stop

    monkeypatch.setattr(confirm, "_confirm_pass", lambda *a, **kw: SimpleNamespace(
        c=SimpleNamespace(model_free=None, cfc_key={})))
    monkeypatch.setattr(confirm, "_varied_pass", varied)
    for law, hertz in (("hertz_mindlin", None), (confirm.OWN_LAW, 4.0)):
        monkeypatch.setattr(confirm, "_law_fit", lambda *a, _law=law, **kw: {"chosen": {
            "impact_young_factor": 4.0, "contact_law": _law}})
        with pytest.raises(Stop):
            screen_then_confirm({}, {}, lambda ov: {}, law_fit=(2.0, 4.0),
                                bed_floor=BedFloor(hertz=4.0), full_search=fs)
        assert seen["bed_floor"] == BedFloor(hertz=hertz)
        assert seen["law"] == (None if law == confirm.OWN_LAW else law)
