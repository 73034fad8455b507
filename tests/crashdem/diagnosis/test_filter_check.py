"""Filter class read from a recording's pre-event noise (``filter_check``) and the diagnosis of a
recording filtered with another CFC class than the simulation (``sensor_dynamics``, form
``filter_class``).

Oracle: the class the ROM truth generator filtered the recording with (integrating 12.5 kHz
acquisition, white noise, SAE J211 at the drawn class); the check only sees the samples.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from crashdem.diagnosis import diagnose
from crashdem.diagnosis.filter_check import filter_class_check
from crashdem.diagnosis.generator import acquire
from crashdem.diagnosis.mismatch import estimate_noise
from crashdem.diagnosis.rom import RomParams, RomSettings, simulate


def _quiet(rec):
    return estimate_noise(rec["accel_z"]).window


@pytest.mark.parametrize("cfc", [60.0, 180.0, 600.0, 1000.0])
@pytest.mark.parametrize("seed", [1, 2])
def test_class_measured_from_the_noise_spectrum(cfc, seed):
    rec = acquire(RomParams(), np.random.default_rng(seed), cfc=cfc)
    for ch in ("accel_z", "velocity_z"):
        r = filter_class_check(rec[ch], _quiet(rec), declared=cfc)
        assert r["applicable"], r
        assert r["measured"] == cfc
        assert not r["contradicts_declared"]
        # the neighbouring classes are far apart in likelihood
        assert r["delta_bic_next"] > 5.0


@pytest.mark.parametrize("cfc", [180.0, 600.0, 1000.0])
def test_declared_class_contradicted(cfc):
    """A file that says CFC 60 about a CFC ``cfc`` channel is contradicted decisively."""
    rec = acquire(RomParams(), np.random.default_rng(7), cfc=cfc)
    r = filter_class_check(rec["accel_z"], _quiet(rec), declared=60.0)
    assert r["contradicts_declared"] and r["decisive"]
    assert r["delta_bic_declared"] > 100.0


def test_not_applicable_without_quiet_noise():
    rec = acquire(RomParams(), np.random.default_rng(1), cfc=60.0)
    a = rec["accel_z"]
    assert not filter_class_check(a, None)["applicable"]
    short = (float(a.t[0]), float(a.t[0]) + 50 / a.fs)
    r = filter_class_check(a, short)
    assert not r["applicable"] and "samples" in r["reason"]
    clean = replace(a, data=np.zeros_like(a.data))
    r = filter_class_check(clean, _quiet(rec))
    assert not r["applicable"] and "noise" in r["reason"]


@pytest.mark.parametrize("declared", [True, False])
def test_diagnosis_names_the_filter_class(declared):
    """Same physics, the recording filtered at CFC 180 (declared by the file or not), the
    simulation at CFC 60: ``sensor_dynamics`` in its filter-class form, the baseline compared
    re-filtered from its raw channels, the scenario fix ``instrumentation.cfc = 180`` and a
    better fit after."""
    rec = acquire(RomParams(), np.random.default_rng(4), cfc=180.0, trigger_offset=0.001)
    if not declared:
        rec = {k: replace(s, cfc=None) for k, s in rec.items()}
    base = simulate(RomParams())
    raw = simulate(RomParams(), RomSettings(cfc=None))
    rep = diagnose(base, rec, baseline_raw=raw)
    assert rep.missing_physics == "sensor_dynamics"
    h = next(h for h in rep.hypotheses if h["name"] == "sensor_dynamics")
    assert h["variant"] == "filter_class"
    assert h["parameters"] == {"filter_class": 180.0}
    assert h["scenario_overrides"] == {"instrumentation.cfc": 180.0}
    fc = rep.fit["filter_class"]
    assert fc["mismatch"] and fc["class"] == 180.0 and fc["delta_bic"] > 100.0
    assert fc["channels"]["accel_z"]["refilter"] == "from the raw channel"
    assert rep.fit["residual_rms_sigma_after"] < 0.5 * rep.fit["residual_rms_sigma_before"]
    assert rep.fit["after"]["overall"] > rep.fit["before"]["overall"]


def test_same_class_is_not_a_filter_mismatch():
    """Null: recording and simulation at CFC 60 -> no filter-class claim (the file need not
    declare the class)."""
    rec = acquire(RomParams(), np.random.default_rng(5), cfc=60.0)
    rec = {k: replace(s, cfc=None) for k, s in rec.items()}
    rep = diagnose(simulate(RomParams()), rec)
    assert not rep.fit["filter_class"]["mismatch"]
    assert rep.fit["filter_class"]["channels"]["accel_z"]["class_used"] == 60.0
    assert rep.missing_physics is None


def test_lower_class_refiltered_without_raw():
    """CFC 60 recording, CFC 180 simulation, no raw channels: the baseline is filtered down."""
    rec = acquire(RomParams(), np.random.default_rng(6), cfc=60.0)
    base = simulate(RomParams(), RomSettings(cfc=180.0))
    rep = diagnose(base, rec)
    assert rep.missing_physics == "sensor_dynamics"
    fc = rep.fit["filter_class"]
    assert fc["class"] == 60.0
    assert fc["channels"]["accel_z"]["refilter"].startswith("from the filtered channel")


def test_unfiltered_baseline_is_compared_at_the_recording_class():
    """A raw (unfiltered) simulation against a CFC 60 recording of the same physics: the
    baseline is filtered at the recording's class, which is processing, not missing physics."""
    rec = acquire(RomParams(), np.random.default_rng(11), cfc=60.0)
    rep = diagnose(simulate(RomParams(), RomSettings(cfc=None)), rec)
    fc = rep.fit["filter_class"]
    assert not fc["mismatch"]
    assert fc["channels"]["accel_z"]["refilter"].startswith("unfiltered baseline")
    assert rep.missing_physics is None


@pytest.mark.parametrize("offset", [0.0, -2.5])
def test_raw_noise_free_output_is_compared_at_the_baseline_class(offset):
    """A simulation's raw output as the "recording" (another code: no noise, no filter, no class
    declared, starting 20 ms before contact): its class cannot be read from noise, its event
    holds power above 6.67 x CFC 60, so the diagnosis filters it at the baseline's CFC 60
    (processing, not a finding); the impact speed is read from the free fall as recorded.
    Null -> nothing claimed; a speed offset -> named within 2 %. (Yade's raw output, starting
    under 1 ms before contact, is in tests/validation/test_diagnosis_yade.py.)"""
    raw = simulate(RomParams(speed_offset=offset), RomSettings(cfc=None, t_pre=0.02))
    rec = {k: raw[k] for k in ("accel_z", "velocity_z")}
    rep = diagnose(simulate(RomParams()), rec, impact_speed=RomParams().v0)
    fc = rep.fit["filter_class"]
    assert not fc["mismatch"]
    assert "accel_z" in fc["recording_filtered"]
    assert fc["channels"]["accel_z"]["event_power_above"]["fraction"] > 1e-6
    chk = rep.fit["impact_speed_check"]
    assert chk["offset"] == pytest.approx(offset, abs=0.05)
    if offset == 0.0:
        assert rep.missing_physics is None, rep.decision
    else:
        assert rep.missing_physics == "initial_conditions"
        h = next(x for x in rep.hypotheses if x["name"] == "initial_conditions")
        assert h["parameters"]["speed_offset"] == pytest.approx(offset, rel=0.02)


def test_noise_free_recording_at_the_baseline_class_is_kept():
    """A noise-free recording filtered at the baseline's CFC 60 (no class declared): the band
    test finds no power beyond the class, the recording is taken to be at CFC 60 and left as it
    is."""
    rec = acquire(RomParams(), np.random.default_rng(1), cfc=60.0,
                  noise={"accel_z": 0.0, "velocity_z": 0.0})
    rec = {k: replace(s, cfc=None) for k, s in rec.items()}
    rep = diagnose(simulate(RomParams()), rec)
    fc = rep.fit["filter_class"]
    assert fc["recording_filtered"] == [] and not fc["mismatch"]
    assert all(v["class_used"] == 60.0 for v in fc["channels"].values())
    # the velocity's pre-event noise is at the floor: its class comes from the band test (the
    # acceleration's quiet window holds the filter's precursor of the impact, which the noise
    # spectrum reads as CFC 60)
    assert fc["channels"]["velocity_z"]["event_power_above"]["fraction"] < 1e-6
    assert rep.missing_physics is None


@pytest.mark.parametrize("offset", [0.0, -2.5])
def test_non_uniform_time_axis_is_resampled(offset):
    """Another code's output at variable time steps (intervals 0.7-1.3 x the mean, no noise,
    no filter): resampled on a uniform grid at the median rate, then diagnosed as usual (null
    -> nothing claimed; a speed offset -> named within 2 %)."""
    fine = simulate(RomParams(speed_offset=offset), RomSettings(cfc=None, t_pre=0.02,
                                                                  sample_rate=20000.0, dt=5e-6))
    rng = np.random.default_rng(14)
    t = np.cumsum(rng.uniform(0.7, 1.3, 1400) * 1e-4) + float(fine["accel_z"].t[0])
    t = t[t <= fine["accel_z"].t[-1]]
    rec = {k: replace(fine[k], t=t, data=np.interp(t, fine[k].t, fine[k].data))
           for k in ("accel_z", "velocity_z")}
    rep = diagnose(simulate(RomParams()), rec, impact_speed=RomParams().v0)
    rs = rep.fit["resampled"]
    assert set(rs) == {"accel_z", "velocity_z"}
    assert rs["accel_z"]["max_interval_deviation"] > 0.2
    assert rep.recording["accel_z"].fs == pytest.approx(rs["accel_z"]["rate_hz"])
    if offset == 0.0:
        assert rep.missing_physics is None, rep.decision
    else:
        assert rep.missing_physics == "initial_conditions", rep.decision
        h = next(x for x in rep.hypotheses if x["name"] == "initial_conditions")
        assert h["parameters"]["speed_offset"] == pytest.approx(offset, rel=0.02)
