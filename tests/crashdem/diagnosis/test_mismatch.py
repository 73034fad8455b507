"""Mismatch locator on constructed signals (no simulator involved)."""
from __future__ import annotations

import numpy as np
import pytest

from crashdem.diagnosis import _dsp
from crashdem.diagnosis.mismatch import estimate_noise, locate_mismatch
from crashdem.signal import Signal

FS = 12500.0
CFC = 60.0
#: raw white-noise sigma of the constructed recordings [m/s^2]
RAW_SIGMA = 5.0
#: a feature time must be found within 2 ms (the peak of a CFC 60 channel is blunt over ~+-2 ms:
#: 100 Hz bandwidth; 2 ms is a quarter period at 125 Hz)
TIME_TOL = 0.002


def _pulse(t, t_c, height, width):
    return height * np.exp(-0.5 * ((t - t_c) / width) ** 2)


def _signal(t, x, name="accel_z", unit="m/s^2"):
    return Signal(name, t, x, unit, CFC)


def _recorded(t, clean, seed):
    rng = np.random.default_rng(seed)
    return _dsp.cfc(clean + rng.normal(0.0, RAW_SIGMA, t.size), FS, CFC)


@pytest.fixture(scope="module")
def t():
    return np.arange(-0.08, 0.15, 1.0 / FS)


def test_missing_second_peak_found_at_its_time(t):
    """Oracle: constructed recording = two pulses (15 ms, 38 ms), simulation = the first only;
    the locator must report a ``missing_peak`` at 38 ms and nothing elsewhere."""
    first = _pulse(t, 0.015, 500.0, 0.004)
    second = _pulse(t, 0.038, 300.0, 0.004)
    rec = _signal(t, _recorded(t, first + second, 1))
    sim = _signal(t, _dsp.cfc(first, FS, CFC))
    wins = locate_mismatch(rec, sim, shift=0.0)
    assert len(wins) == 1, [w.description for w in wins]
    w = wins[0]
    assert w.feature == "missing_peak"
    assert w.t_start_s < 0.038 < w.t_end_s
    assert abs(w.feature_time_s - 0.038) < TIME_TOL
    # size: the prominence of the missing peak (300 m/s^2 before filtering; CFC 60 on a 4 ms
    # Gaussian keeps > 80 % of it)
    assert 0.8 * 300.0 < w.size < 1.05 * 300.0
    assert "second" in w.description


@pytest.mark.parametrize("seed", range(12))
def test_noise_only_residual_gives_no_window(t, seed):
    """Oracle: recording = simulation + filtered white noise; with a 4 sigma threshold over one
    noise correlation time, false windows are rare (P < 1e-2 per record, Gaussian tail)."""
    clean = _pulse(t, 0.02, 600.0, 0.006)
    rec = _signal(t, _recorded(t, clean, 100 + seed))
    sim = _signal(t, _dsp.cfc(clean, FS, CFC))
    assert locate_mismatch(rec, sim, shift=0.0) == []


def test_noise_estimate_matches_filtered_noise_level():
    """Oracle: the standard deviation of CFC-filtered white noise is
    sigma_raw * sqrt(2 B_eq / fs) (B_eq: equivalent noise bandwidth of the filter); the MAD
    estimate over a 1 s quiet record (~220 independent samples, standard error ~8 %) must be
    within 25 % (3 standard errors)."""
    t = np.arange(-1.0, 0.1, 1.0 / FS)
    clean = _pulse(t, 0.03, 400.0, 0.005)
    rec = _signal(t, _recorded(t, clean, 7))
    est = estimate_noise(rec)
    expected = RAW_SIGMA * np.sqrt(2.0 * _dsp.noise_bandwidth(FS, CFC) / FS)
    assert est.window is not None and est.window[1] < 0.03
    assert abs(est.sigma / expected - 1.0) < 0.25


def test_peak_too_high_and_late_are_sized_in_si(t):
    """Oracle: simulation = recorded pulse x 1.2 delayed by 5 ms -> a peak 20 % too high
    (+100 m/s^2 for a 500 m/s^2 pulse, within 5 %) and 5 ms late (within one sample + 0.5 ms)."""
    clean = _pulse(t, 0.02, 500.0, 0.005)
    rec = _signal(t, _recorded(t, clean, 3))
    sim_hi = _signal(t, _dsp.cfc(1.2 * clean, FS, CFC))
    w = locate_mismatch(rec, sim_hi, shift=0.0)
    feats = {w_.feature: w_ for w_ in w}
    hi = feats.get("peak_too_high") or next(
        (f for w_ in w for f in w_.other_features if f["feature"] == "peak_too_high"), None)
    assert hi is not None
    size = hi.size if hasattr(hi, "size") else hi["size"]
    filtered_peak = float(np.max(_dsp.cfc(clean, FS, CFC)))
    assert abs(size - 0.2 * filtered_peak) < 0.05 * 0.2 * filtered_peak + 4 * 1.0
    late = _signal(t, _dsp.cfc(_pulse(t, 0.025, 500.0, 0.005), FS, CFC))
    w2 = locate_mismatch(rec, late, shift=0.0)
    all_f = [(x.feature, x.size) for x in w2] + [(f["feature"], f["size"]) for x in w2
                                                 for f in x.other_features]
    lat = [s for f, s in all_f if f == "peak_late"]
    assert lat and abs(lat[0] - 0.005) < 1.0 / FS + 0.0005


def test_rebound_too_strong_on_velocity(t):
    """Oracle: constructed velocities that end at +2 m/s (recording) and +3 m/s (simulation)
    -> ``rebound_too_strong`` of +1 m/s (within 2 %)."""
    v_rec = np.where(t < 0, -15.0, -15.0 + 17.0 * np.clip(t / 0.05, 0, 1))
    v_sim = np.where(t < 0, -15.0, -15.0 + 18.0 * np.clip(t / 0.05, 0, 1))
    rng = np.random.default_rng(5)
    rec = Signal("velocity_z", t, _dsp.cfc(v_rec + rng.normal(0, 0.02, t.size), FS, CFC), "m/s", CFC)
    sim = Signal("velocity_z", t, _dsp.cfc(v_sim, FS, CFC), "m/s", CFC)
    wins = locate_mismatch(rec, sim, shift=0.0)
    feats = [(w.feature, w.size) for w in wins] + [(f["feature"], f["size"]) for w in wins
                                                    for f in w.other_features]
    reb = [s for f, s in feats if f == "rebound_too_strong"]
    assert reb and abs(reb[0] - 1.0) < 0.02


def _filtered_as_cut(t_start: float, first: float | None, seed: int = 3) -> Signal:
    """A 165 m/s^2, 60 ms half-sine contact pulse at t = 0 after free fall (0 m/s^2), 0.5 g
    white noise at 12.5 kHz, the record cut at ``t_start`` and then filtered at CFC 60 (the
    first raw sample set to ``first`` when given)."""
    fs = 12500.0
    t = np.arange(t_start, 0.12, 1.0 / fs)
    x = np.where((t >= 0.0) & (t <= 0.06), 165.0 * np.sin(np.pi * np.clip(t, 0, 0.06) / 0.06), 0.0)
    x = x + np.random.default_rng(seed).normal(0.0, 4.9, t.size)
    if first is not None:
        x[0] = first
    return Signal("accel_z", t, _dsp.cfc(x, fs, 60.0), "m/s^2", 60.0)


def test_filter_startup_transient_is_not_the_onset():
    """A record filtered at CFC 60 after it was cut starts with the filter's start-up transient
    (here the first raw sample at -15 m/s^2: the filtered record starts beyond the onset
    threshold of this 165 m/s^2 pulse). The onset is still found at the contact (within 2 ms)
    and the noise window lies after the start-up, as without the transient; a record that
    begins 1 ms before the contact keeps its onset at the contact. Oracle: the pulse's start
    (t = 0) and the white noise's 4.9 m/s^2 through CFC 60 (a fraction of it, not 0)."""
    from crashdem.diagnosis.mismatch import K_ONSET, ONSET_FRACTION, filter_startup, onset_time

    sig = _filtered_as_cut(-0.08, -15.0)
    noise = estimate_noise(sig)
    base = np.median(sig.data[:32])
    thr = max(K_ONSET * noise.sigma, ONSET_FRACTION * np.ptp(sig.data))
    assert abs(sig.data[0] - base) > thr  # the transient crosses the threshold (precondition)
    g = filter_startup(sig)
    assert 0.01 < g < 0.03
    assert onset_time(sig, noise.sigma) == pytest.approx(0.0, abs=0.002)
    assert noise.window[0] >= sig.t[0] + g - 1.0 / sig.fs and noise.window[1] < 0.0
    clean = _filtered_as_cut(-0.08, None)
    assert onset_time(clean, estimate_noise(clean).sigma) == pytest.approx(
        onset_time(sig, noise.sigma), abs=0.0005)
    assert noise.sigma == pytest.approx(estimate_noise(clean).sigma, rel=0.2)
    late = _filtered_as_cut(-0.001, None)
    assert onset_time(late, 0.5) < 0.002
