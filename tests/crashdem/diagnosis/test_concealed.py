"""End-to-end diagnosis on concealed-effect recordings (truth: midpoint RK2 at 5 us with an
integrating acquisition, 12.5 kHz, sensor noise, trigger offset, CFC 60; diagnosis: semi-implicit
Euler ROM at 20 us). Oracle for every assertion: the generator's hidden truth (effect name and
parameter values), which the diagnosis never sees.

Score: ISO/TS 18571 overall rating from ``crashdem.metrics`` over the event window (onset - 5 ms
to 10 ms after the pulse), averaged over the diagnosed channels (``accel_z``, ``velocity_z``);
``fit.metric_name()`` reports the fallback if the metric module is missing.
"""
from __future__ import annotations

from collections import Counter

import numpy as np
import pytest

from crashdem.diagnosis import diagnose, fit
from crashdem.diagnosis.generator import ACCEPT_PARAM_RTOL as PARAM_RTOL
from crashdem.diagnosis.generator import ACCEPT_SCORE_AFTER as MIN_SCORE_AFTER
from crashdem.diagnosis.generator import ACCEPT_SCORE_GAIN as MIN_SCORE_GAIN
from crashdem.diagnosis.generator import ACCEPT_TOP1_RATE as MIN_TOP1_RATE
from crashdem.diagnosis.generator import diagnose_cases
from crashdem.diagnosis.rom import RomParams, simulate

#: effects whose ISO/TS 18571 footprint leaves room for the 0.1 improvement criterion
EFFECTS = ("soil_layering", "boundary_proximity", "cohesion", "particle_rotation",
           "sensor_dynamics", "structural_crush", "initial_conditions")
#: contact damping changes only the unloading and the rebound: baseline ISO stays >= 0.9, so
#: an improvement of 0.1 is arithmetically impossible for it; it is checked separately
DAMPING = "contact_damping"
SEEDS = (11, 12)
NULL_SEEDS = (21, 22)
#: a null case with wrong existing parameters: must come out as recalibration
RECAL_SEED = 23
RECAL_TRUTH = {"strength_scale": 1.25, "stiffness_scale": 0.8}


@pytest.fixture(scope="module")
def runs():
    cases = [(e, s) for e in (*EFFECTS, DAMPING) for s in SEEDS] + [(None, s) for s in NULL_SEEDS]
    # generated and diagnosed (against simulate(RomParams())) one per core, in this order
    out = diagnose_cases([(s, e) for e, s in cases] + [(RECAL_SEED, None, RECAL_TRUTH)])
    # confusion matrix (truth row -> top-ranked hypothesis) and per-case numbers
    conf = Counter((c.effect or "null", r.hypotheses[0]["name"]) for c, r, _ in out)
    print("\nconfusion (truth -> top-ranked):")
    for (tr, top), n in sorted(conf.items()):
        print(f"  {tr:20s} -> {top:20s} x{n}")
    print(f"metric: {fit.metric_name()}")
    for c, r, dt in out:
        print(f"  {str(c.effect):20s} seed {c.seed}: claim={r.missing_physics} "
              f"score {r.fit['before']['overall']:.3f} -> {r.fit['after']['overall']:.3f} "
              f"runs={r.simulations['screening_runs']} {dt:.1f} s")
    return out


def _effect_runs(runs):
    return [(c, r) for c, r, _ in runs if c.effect is not None]


def test_top_ranked_is_the_concealed_effect(runs):
    """>= 90 % of the concealed-effect cases rank the concealed effect first, and the same
    share claims it as the missing physics."""
    er = _effect_runs(runs)
    assert len({c.effect for c, _ in er}) >= 5 and len(er) >= 10
    top = np.mean([r.hypotheses[0]["name"] == c.effect for c, r in er])
    claimed = np.mean([r.missing_physics == c.effect for c, r in er])
    assert top >= MIN_TOP1_RATE, top
    assert claimed >= MIN_TOP1_RATE, claimed


def test_parameters_recovered_within_15_percent(runs):
    """Every drawn parameter of the concealed effect is recovered within 15 % (cases where the
    effect is ranked first)."""
    bad = []
    for c, r in _effect_runs(runs):
        h = r.hypotheses[0]
        if h["name"] != c.effect:
            continue
        for k, v in c.values.items():
            if abs(h["parameters"][k] / v - 1.0) > PARAM_RTOL:
                bad.append((c.effect, c.seed, k, v, h["parameters"][k]))
    assert not bad, bad


def test_score_improves_by_0p1_and_ends_above_0p85(runs):
    """ISO/TS 18571 (overall, event window) improves by >= 0.1 and ends >= 0.85."""
    for c, r in _effect_runs(runs):
        if c.effect == DAMPING:
            continue
        before, after = r.fit["before"]["overall"], r.fit["after"]["overall"]
        assert after >= MIN_SCORE_AFTER, (c.effect, c.seed, after)
        assert after - before >= MIN_SCORE_GAIN, (c.effect, c.seed, before, after)


def test_contact_damping_scores(runs):
    """Contact damping: the baseline already rates >= 0.9 (the effect lives in the unloading
    and rebound), so the check is: the refit ends >= 0.85 and above the baseline."""
    for c, r in _effect_runs(runs):
        if c.effect != DAMPING:
            continue
        before, after = r.fit["before"]["overall"], r.fit["after"]["overall"]
        assert before >= 0.9
        assert after >= MIN_SCORE_AFTER and after > before


def test_null_cases_claim_no_missing_physics(runs):
    """Null recordings (baseline truth, other numerics, noise) claim no missing physics; the
    recalibration null case is reported as recalibration with the true scale factors within
    15 %."""
    nulls = [(c, r) for c, r, _ in runs if c.effect is None]
    assert len(nulls) == len(NULL_SEEDS) + 1
    for c, r in nulls:
        assert r.missing_physics is None, (c.seed, r.decision)
    c, r = next((c, r) for c, r in nulls if c.recalibration)
    assert r.best == "recalibration"
    rec = next(h for h in r.hypotheses if h["name"] == "recalibration")["recalibration"]
    for k, v in RECAL_TRUTH.items():
        assert abs(rec[k] / v - 1.0) < PARAM_RTOL, (k, rec[k], v)


def test_report_has_required_fields(runs):
    """Schema of the report for one case (issue 7 list of fields)."""
    _, r, _ = runs[0]
    d = r.to_dict()
    assert d["mismatch"] and {"channel", "t_start_s", "t_end_s", "feature", "size"} <= set(d["mismatch"][0])
    h = d["hypotheses"][0]
    assert {"name", "parameters", "uncertainty", "score_before", "score_after", "evidence",
            "complexity_penalty"} <= set(h)
    assert all(np.isfinite(v) and v >= 0 for v in h["uncertainty"].values())
    assert "missing_physics" in d
    assert {"metric", "before", "after"} <= set(d["fit"])
    for key in ("per_channel", "overall"):
        assert key in d["fit"]["before"] and key in d["fit"]["after"]
    ch = d["channels"][0]
    assert {"score", "peak_error", "timing_error_s", "rms_error"} <= set(d["fit"]["after"]["per_channel"][ch])


@pytest.mark.parametrize("form, label", [(0.0, "lowpass"), (1.0, "mount")])
def test_sensor_model_form_is_identified(form, label):
    """Oracle: a truth whose accelerometer is a seismic low-pass (form 0) or a resonant mount
    (form 1), 60 Hz, zeta 0.12 -- the two standard sensor models (``sensors.MountDynamics``);
    the diagnosis fits both forms of ``sensor_dynamics`` and must name the truth's form, with
    the frequency within 15 % and the damping within 30 % (a damping ratio is the weaker-
    determined of the two)."""
    from crashdem.diagnosis.generator import acquire

    truth = RomParams(mount_frequency=60.0, mount_damping=0.12, mount_form=form)
    rec = acquire(truth, np.random.default_rng(5), trigger_offset=0.001)
    rep = diagnose(simulate(RomParams()), rec)
    assert rep.missing_physics == "sensor_dynamics"
    h = next(x for x in rep.hypotheses if x["name"] == "sensor_dynamics")
    assert h["variant"] == label
    assert h["scenario_overrides"]["physics.sensor_dynamics.model"] == label
    assert h["parameters"]["mount_frequency"] == pytest.approx(60.0, rel=0.15)
    assert h["parameters"]["mount_damping"] == pytest.approx(0.12, rel=0.30)


@pytest.mark.parametrize("offset", [-3.0, 0.0, 2.2])
def test_impact_speed_measured_from_the_free_fall(offset):
    """Oracle: the truth's speed offset. With the baseline's impact speed given, the offset is
    read from the recording's pre-contact free-fall velocity (``measured_impact_speed``): within
    0.05 m/s of the truth, named as ``initial_conditions`` when it is there (within 2 %), and
    nothing claimed when it is not."""
    from crashdem.diagnosis.generator import acquire

    truth = RomParams(speed_offset=offset)
    rec = acquire(truth, np.random.default_rng(8), trigger_offset=-0.0015)
    rep = diagnose(simulate(RomParams()), rec, impact_speed=RomParams().v0)
    chk = rep.fit["impact_speed_check"]
    assert chk["offset"] == pytest.approx(offset, abs=0.05)
    assert chk["sigma"] < 0.1
    if offset == 0.0:
        assert rep.missing_physics is None
    else:
        assert rep.missing_physics == "initial_conditions"
        h = next(x for x in rep.hypotheses if x["name"] == "initial_conditions")
        assert h["parameters"]["speed_offset"] == pytest.approx(offset, rel=0.02)


@pytest.mark.parametrize("offset", [-3.0, 2.2])
def test_impact_speed_measured_from_a_velocity_alone(offset):
    """A recording holding only the impactor velocity (no accelerometer): the onset is that of
    the velocity's derivative, the speed offset is read from the free fall before it (within
    0.05 m/s of the truth) and named; without the velocity-derivative onset the velocity ramp
    of the free fall read as the event and misaligned the baseline by ~50 ms."""
    from crashdem.diagnosis.generator import acquire

    rec = acquire(RomParams(speed_offset=offset), np.random.default_rng(8),
                  trigger_offset=-0.0015)
    rep = diagnose(simulate(RomParams()), {"velocity_z": rec["velocity_z"]},
                   impact_speed=RomParams().v0)
    chk = rep.fit["impact_speed_check"]
    assert chk["used"] and chk["offset"] == pytest.approx(offset, abs=0.05)
    assert rep.missing_physics == "initial_conditions", rep.decision
    assert rep.fit["before"]["per_channel"]["velocity_z"]["timing_error_s"] == pytest.approx(
        0.0, abs=0.01)


@pytest.mark.parametrize("truth_floor", [2.5, 0.8])
def test_a_bed_deeper_than_modelled_is_not_a_nearer_floor(truth_floor):
    """Oracle: the truth's floor, with the diagnosed model's bed 1.5 m thick
    (``RomParams(floor_depth=1.5)``, as ``cli.rom_from_scenario`` gives for a scenario of
    ``container.soil_depth = 1.5``). A floor nearer than modelled (0.8 m) is named
    ``boundary_proximity`` within 15 %; a bed deeper than modelled (2.5 m) is not: the
    entry is a floor nearer than modelled (``catalogue.drop_catalogue``), and the drop
    catalogue's fixed 0.4-3 m range had named it there (Delta BIC 351)."""
    from crashdem.diagnosis.generator import acquire

    base = RomParams(floor_depth=1.5)
    rng = np.random.default_rng(21)
    rec = acquire(base.with_values({"floor_depth": truth_floor}), rng,
                  trigger_offset=float(rng.uniform(-0.002, 0.002)))
    rep = diagnose(simulate(base), rec, rom_base=base)
    h = next(x for x in rep.hypotheses if x["name"] == "boundary_proximity")
    assert h["parameters"]["floor_depth"] <= 1.5
    if truth_floor < 1.5:
        assert rep.missing_physics == "boundary_proximity", rep.decision
        assert h["parameters"]["floor_depth"] == pytest.approx(truth_floor, rel=PARAM_RTOL)
    else:
        assert rep.missing_physics is None, rep.decision


def test_working_rate_decimates_without_edge_transients():
    """A channel sampled above ``MAX_SAMPLE_RATE`` is decimated by the smallest integer factor
    that brings it to or below it; a free-fall ramp plus a 300 Hz tone (well inside the new
    band) comes through within 1e-3 m/s inside (measured 1.4e-4: the FIR's passband gain is
    1 +- 3e-4) and 0.01 m/s at the ends (measured 4.6e-3: the tone is not on
    the padding line; 0.01 m/s is a fifth of the lab's raw velocity noise, while a zero-padded
    anti-alias filter bends the first sample by 7 m/s), and a channel at or below the rate is
    returned as it is."""
    from crashdem.diagnosis import MAX_SAMPLE_RATE, working_rate
    from crashdem.signal import Signal

    fs = 8.0 * MAX_SAMPLE_RATE
    t = np.arange(-0.05, 0.1, 1.0 / fs)
    x = -16.4 - 9.81 * t + 0.5 * np.sin(2 * np.pi * 300.0 * t)
    out, info = working_rate({"v": Signal("v", t, x, "m/s"), "a": Signal("a", t[::8], x[::8], "m/s")})
    v = out["v"]
    assert info["v"]["factor"] == 8 and v.fs == pytest.approx(MAX_SAMPLE_RATE)
    assert "a" not in info and out["a"].data is not None and out["a"].t.size == t[::8].size
    ref = -16.4 - 9.81 * v.t + 0.5 * np.sin(2 * np.pi * 300.0 * v.t)
    err = np.abs(v.data - ref)
    assert np.max(err[20:-20]) < 1e-3 and np.max(err) < 0.01


def test_recording_sampled_at_100_khz_is_diagnosed():
    """A recording at 100 kHz (another code's output every few steps) was refused by the
    screening model's step check; it is decimated to 20 kHz and diagnosed like a lab channel:
    the speed offset named within 2 %, the decimation reported."""
    from crashdem.diagnosis.generator import acquire

    rec = acquire(RomParams(speed_offset=-3.0), np.random.default_rng(8), sample_rate=100_000.0)
    rep = diagnose(simulate(RomParams()), rec, impact_speed=RomParams().v0)
    assert rep.missing_physics == "initial_conditions", rep.decision
    h = next(x for x in rep.hypotheses if x["name"] == "initial_conditions")
    assert h["parameters"]["speed_offset"] == pytest.approx(-3.0, rel=0.02)
    assert rep.fit["decimated"]["accel_z"]["factor"] == 5


def test_impact_speed_of_another_unit_is_not_used():
    """A velocity in another unit than it says (km/h labelled m/s) gives a 'recorded impact
    speed' far from the baseline's: it is reported with the reason and not used as a speed
    offset (no crash, no claim from it)."""
    from crashdem.diagnosis.generator import acquire
    from crashdem.signal import Signal

    rec = acquire(RomParams(), np.random.default_rng(9))
    v = rec["velocity_z"]
    rec["velocity_z"] = Signal("velocity_z", v.t, 3.6 * v.data, v.unit, v.cfc)
    rep = diagnose(simulate(RomParams()), {"accel_z": rec["accel_z"], "velocity_z": rec["velocity_z"]},
                   impact_speed=RomParams().v0, hypotheses=["initial_conditions"])
    chk = rep.fit["impact_speed_check"]
    assert chk["used"] is False and "50 %" in chk["reason"]


@pytest.mark.parametrize("flip", [("accel_z",), ("velocity_z",), ("accel_z", "velocity_z")])
def test_opposite_sign_convention_is_flipped(flip):
    """Channels recorded with the opposite sign convention (z down: deceleration negative,
    velocity down-positive) are recognised against the baseline, flipped and diagnosed as if
    recorded in the simulation's convention: the speed offset of the truth is named within 2 %
    as without the flip; unflipped channels are reported as such."""
    from crashdem.diagnosis.generator import acquire
    from crashdem.signal import Signal

    rec = acquire(RomParams(speed_offset=-2.5), np.random.default_rng(10))
    for ch in flip:
        s = rec[ch]
        rec[ch] = Signal(ch, s.t, -s.data, s.unit, s.cfc)
    rep = diagnose(simulate(RomParams()), rec, impact_speed=RomParams().v0)
    signs = rep.fit["sign_convention"]
    assert {ch for ch, v in signs.items() if v["flipped"]} == set(flip)
    assert all(abs(v["cosine"]) > 0.8 for v in signs.values())
    assert rep.missing_physics == "initial_conditions"
    h = next(x for x in rep.hypotheses if x["name"] == "initial_conditions")
    assert h["parameters"]["speed_offset"] == pytest.approx(-2.5, rel=0.02)
