"""Diagnosis of glider-crash recordings with concealed effects (planar-model truth).

Truth: the reference glider's planar model (``generator_planar.GLIDER_BASE``, = what
``crashdem diagnose`` builds from ``validation/scenarios/glider_real.toml``) with one
catalogue effect drawn from the seed, at a 4x smaller step, with its soil strength, drag and
stiffness each off by a factor drawn in 0.9-1.1 and the accelerometer 5 cm further aft,
acquired like the lab channels (rear accelerometers x/z on 250 g channels, pitch-rate gyro;
12.5 kHz integrating acquisition, white noise, trigger offset, CFC 60). Diagnosis: the planar
screening model and its catalogue (``catalogue.planar_catalogue``: the rear wall for
``boundary_proximity``, path angle and attitude for ``initial_conditions``). Oracle: the
generator's hidden truth.

The glider records no free-fall velocity, so neither the impact-speed measurement nor the
accelerometer/velocity check helps here: every effect is found by the fits.

Measured (2026-11-22): 14/14 top-ranked right, 12/14 claimed (the free rotation is top-ranked
but not decisive: Delta BIC 5.4 / 2.9), nulls claim nothing; parameters within 15 % except the
rotation's friction ratio (-33 % on seed 12) and the restitution (-24 % on seed 12: at
e < 0.1 the dashpot saturates against the plastic cap while loading, so only the unloading
informs it). Scores 0.31-0.96 -> 0.970-0.981 (nulls: 0.974).
"""
from __future__ import annotations

from collections import Counter

import pytest

from crashdem.diagnosis.generator import ACCEPT_PARAM_RTOL as PARAM_RTOL
from crashdem.diagnosis.generator import ACCEPT_SCORE_AFTER as MIN_SCORE_AFTER
from crashdem.diagnosis.generator import ACCEPT_SCORE_GAIN as MIN_SCORE_GAIN
from crashdem.diagnosis.generator import ACCEPT_TOP1_RATE as MIN_TOP1_RATE
from crashdem.diagnosis.generator_planar import GLIDER_BASE, PLANAR_EFFECT_DRAWS, diagnose_cases

EFFECTS = tuple(PLANAR_EFFECT_DRAWS)
SEEDS = (11, 12)
NULL_SEEDS = (21, 22)
#: effects whose parameters are well posed on these recordings (see module notes)
WELL_POSED = ("boundary_proximity", "cohesion", "sensor_dynamics", "structural_crush",
              "initial_conditions")


@pytest.fixture(scope="module")
def glider_runs():
    cases = [(e, s) for e in EFFECTS for s in SEEDS] + [(None, s) for s in NULL_SEEDS]
    # generated and diagnosed one per core (the same reports as one by one)
    out = diagnose_cases([(s, e) for e, s in cases])
    conf = Counter((c.effect or "null", r.hypotheses[0]["name"]) for c, r in out)
    print("\nglider (planar truth) -- truth -> top-ranked:")
    for (tr, top), n in sorted(conf.items()):
        print(f"  {tr:20s} -> {top:25s} x{n}")
    for c, r in out:
        h = r.hypotheses[0]
        print(f"  {str(c.effect):20s} seed {c.seed}: claimed={r.missing_physics} "
              f"dBIC={h['delta_bic_vs_recalibration']:.1f} score {r.fit['before']['overall']:.3f}"
              f" -> {r.fit['after']['overall']:.3f} truth={c.values} "
              f"fitted={ {k: round(v, 4) for k, v in h['parameters'].items()} }")
    return out


def _rel_errors(c, r):
    h = next(h for h in r.hypotheses if h["name"] == c.effect)
    return {k: abs(h["parameters"][k] / v - 1.0) for k, v in c.values.items()}


def test_glider_top_ranked_is_the_concealed_effect(glider_runs):
    """Issue 7: the top-ranked hypothesis is the concealed effect in at least 90 % of cases;
    and it is *claimed* (Delta BIC > 10 over the recalibration) in at least 80 % (the free
    rotation is top-ranked but not decisive once the soil's own values are off by up to 10 %:
    Delta BIC 3-5, measured)."""
    effect_runs = [(c, r) for c, r in glider_runs if c.effect is not None]
    top = [c.effect == r.hypotheses[0]["name"] for c, r in effect_runs]
    claimed = [c.effect == r.missing_physics for c, r in effect_runs]
    wrong = [(c.effect, c.seed, r.hypotheses[0]["name"], r.missing_physics)
             for c, r in effect_runs if r.missing_physics not in (None, c.effect)]
    assert sum(top) / len(top) >= MIN_TOP1_RATE, [
        (c.effect, c.seed, r.hypotheses[0]["name"]) for (c, r), ok in zip(effect_runs, top) if not ok]
    assert sum(claimed) / len(claimed) >= 0.8, claimed
    assert not wrong, wrong
    assert len({c.effect for c, _ in effect_runs}) >= 5


def test_glider_null_cases_claim_no_missing_physics(glider_runs):
    for c, r in glider_runs:
        if c.effect is None:
            assert r.missing_physics is None, (c.seed, r.decision)


def test_glider_well_posed_parameters_within_15_percent(glider_runs):
    """The wall distance, the cohesion, the sensor's frequency and damping, the crush force
    and stroke and the attitude offset within 15 % of the truth."""
    for c, r in glider_runs:
        if c.effect in WELL_POSED:
            err = _rel_errors(c, r)
            assert max(err.values()) < PARAM_RTOL, (c.effect, c.seed, err)


@pytest.mark.xfail(reason="measured: rotation friction ratio +4/-33 % (not decisive, Delta BIC "
                          "3-5), restitution +7/-24 % (e < 0.1 moves the pulse little); see the "
                          "module notes", strict=False)
def test_glider_all_parameters_within_15_percent(glider_runs):
    for c, r in glider_runs:
        if c.effect is not None:
            err = _rel_errors(c, r)
            assert max(err.values()) < PARAM_RTOL, (c.effect, c.seed, err)


def test_glider_score_improves(glider_runs):
    """ISO/TS 18571 >= 0.85 after, and +0.1 where that stays below the ceiling the null
    recordings reach after recalibration (the truth's other soil values and numerics cap every
    score there: 0.974 measured); closer to the ceiling, the refit must reach it within the
    0.02 the confirmation treats as a meaningful score difference."""
    from crashdem.diagnosis import CONFIRM_MIN_GAIN

    ceiling = min(r.fit["after"]["overall"] for c, r in glider_runs if c.effect is None)
    for c, r in glider_runs:
        if c.effect is None:
            continue
        before, after = r.fit["before"]["overall"], r.fit["after"]["overall"]
        assert after >= MIN_SCORE_AFTER, (c.effect, c.seed, before, after)
        if before + MIN_SCORE_GAIN <= ceiling:
            assert after - before >= MIN_SCORE_GAIN, (c.effect, c.seed, before, after)
        else:
            assert after > before and after >= ceiling - CONFIRM_MIN_GAIN, (
                c.effect, c.seed, before, after, ceiling)


def test_glider_report_names_the_planar_catalogue(glider_runs):
    c, r = next((c, r) for c, r in glider_runs if c.effect == "boundary_proximity")
    d = r.to_dict()
    assert d["catalogue_model"] == "planar"
    assert "soil_layering" in d["catalogue_not_represented"]
    wall = next(h for h in d["catalogue"] if h["name"] == "boundary_proximity")
    assert [p["name"] for p in wall["parameters"]] == ["wall_distance", "wall_stiffness"]
    assert r.channels == ["accel_x", "accel_z", "pitch_rate"]


def test_glider_base_is_the_reference_scenario():
    """``GLIDER_BASE`` is what ``crashdem diagnose`` builds from the reference glider scenario
    (fuselage, slope, wall and sensors): a change there must be carried into the generator."""
    from dataclasses import asdict
    from pathlib import Path

    from crashdem import scenario as sc
    from crashdem.diagnosis.cli import planar_from_scenario

    toml = Path(__file__).resolve().parents[3] / "validation" / "scenarios" / "glider_real.toml"
    got, want = asdict(planar_from_scenario(sc.load(toml))), asdict(GLIDER_BASE)
    for k, v in want.items():
        if k == "soil":
            for kk, vv in v.items():
                assert got["soil"][kk] == pytest.approx(vv, rel=1e-9), kk
        else:
            assert got[k] == pytest.approx(v, rel=1e-9), k
