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


def test_an_aligned_simulation_is_compared_only_where_it_was_simulated(t):
    """A simulation starts at contact; the recording has 80 ms of free fall before it. Aligned
    on the recording's time base (``align`` holds the first simulated value before it), the
    simulation is compared only over the span it was simulated: no window before contact. The
    same samples without that span (the aligned data as a plain signal) show the held value as
    an initial offset of the size free fall makes (g x 80 ms = 0.78 m/s), so the span is what
    removes it."""
    from crashdem.diagnosis.mismatch import SIMULATED_SPAN, align

    v0, g = -15.0, 9.81
    rng = np.random.default_rng(5)
    clean = np.where(t < 0.0, v0 - g * t, v0 + 150.0 * t)
    rec = Signal("velocity_z", t, clean + rng.normal(0.0, 0.01, t.size), "m/s", None)
    ts = t[t >= 0.0]
    sim = Signal("velocity_z", ts, v0 + 150.0 * ts, "m/s", None)
    al = align(rec, sim, 0.0)
    assert al.meta[SIMULATED_SPAN] == (float(ts[0]), float(ts[-1]))
    assert locate_mismatch(rec, al, shift=0.0) == []
    plain = Signal("velocity_z", al.t, al.data, "m/s", None)
    wins = locate_mismatch(rec, plain, shift=0.0)
    assert wins[0].feature == "initial_offset" and all(w.t_end_s < 0.0 for w in wins)
    assert abs(abs(wins[0].size) - g * 0.08) < 0.05
    # aligned again with a shift, the span moves with it
    assert align(rec, al, 0.01).meta[SIMULATED_SPAN] == pytest.approx(
        (float(ts[0]) + 0.01, float(ts[-1]) + 0.01))


def test_feature_changes_say_what_a_fit_adds_and_corrects(t):
    """Oracle: recording = pulses at 15 ms (500 m/s^2) and 38 ms (300); the baseline has the
    first at 350 (150 too low) and lacks the second. A fit with both pulses right adds the
    missing peak and raises the first, most significant first; a fit that only corrects the
    height does not claim the peak; a fit that leaves the first pulse out altogether corrects
    nothing of its height (the peak is missing there, not better); the baseline itself
    changes nothing."""
    from crashdem.diagnosis.mismatch import describe_changes, feature_changes

    first, second = _pulse(t, 0.015, 500.0, 0.004), _pulse(t, 0.038, 300.0, 0.004)
    rec = _signal(t, _recorded(t, first + second, 3))

    def windows(x):
        return locate_mismatch(rec, _signal(t, _dsp.cfc(x, FS, CFC)), shift=0.0)

    before = windows(0.7 * first)
    kinds = {f.feature for f in feature_changes(before, before)}
    assert {"missing_peak", "peak_too_low"} <= kinds
    assert describe_changes(feature_changes(before, before)) is None

    both = feature_changes(before, windows(first + second))
    assert all(c.after == 0.0 for c in both if c.feature in ("missing_peak", "peak_too_low"))
    txt = describe_changes(both)
    assert txt.startswith("adds the missing peak") and "at 38.0 ms on accel_z" in txt
    assert "raises the peak at 15.0 ms on accel_z (error -1" in txt and "-> +0 m/s^2" in txt

    height_only = describe_changes(feature_changes(before, windows(first)))
    assert height_only.startswith("raises the peak at 15.0 ms") and "adds" not in height_only

    changes = feature_changes(before, windows(second))
    low = next(c for c in changes if c.feature == "peak_too_low")
    assert low.after == low.before and low.reduction == 0.0
    assert describe_changes(changes).startswith("adds the missing peak")
    assert "15.0 ms" not in describe_changes(changes)


def test_a_long_mismatch_is_located_lobe_by_lobe(t):
    """Oracle: recording = pulses at 15 ms (500 m/s^2) and 38 ms (300); simulation = the first
    at 650 and, instead of the second, a 150 m/s^2 tail at 60 ms. The simulation is above the
    recording at the first peak, below it at the second and above it in the tail, each
    crossing steeper than a gap of the minimum duration: three windows in time order, each
    owning its own feature (peak too high at 15 ms, the missing peak at 38 ms, the extra peak
    at 60 ms), not one window over the whole event. Each feature is owned by one window only.
    Control: with the first peak too low (the simulation below the recording from the first
    peak to the second) those two lobes are one window."""
    first, second = _pulse(t, 0.015, 500.0, 0.004), _pulse(t, 0.038, 300.0, 0.004)
    tail = _pulse(t, 0.060, 150.0, 0.006)
    rec = _signal(t, _recorded(t, first + second, 4))
    wins = locate_mismatch(rec, _signal(t, _dsp.cfc(1.3 * first + tail, FS, CFC)), shift=0.0)
    assert [w.feature for w in wins] == ["peak_too_high", "missing_peak", "extra_peak"], \
        [w.description for w in wins]
    for w, tc in zip(wins, (0.015, 0.038, 0.060)):
        assert w.t_start_s < tc < w.t_end_s and abs(w.feature_time_s - tc) < TIME_TOL
    assert all(a.t_end_s < b.t_start_s for a, b in zip(wins, wins[1:]))
    owned = [(w.feature, round(w.feature_time_s, 4)) for w in wins] + [
        (f["feature"], round(f["time_s"], 4)) for w in wins for f in w.other_features]
    assert len(owned) == len(set(owned))
    low = locate_mismatch(rec, _signal(t, _dsp.cfc(0.7 * first + tail, FS, CFC)), shift=0.0)
    assert [w.feature for w in low] == ["missing_peak", "extra_peak"]
    assert low[0].t_start_s < 0.015 and "peak_too_low" in [
        f["feature"] for f in low[0].other_features]


def test_an_initial_offset_labels_no_later_window(t):
    """Oracle: the simulation (from contact at 0 s) starts 0.08 m/s off the recording and
    joins it within 1 ms, then runs 0.5 m/s above it from 10 to 40 ms. The offset at contact is
    a feature of that instant; the later lobe is a velocity above the recording, not an
    initial offset, though it starts within a quarter of its length of it."""
    rng = np.random.default_rng(6)
    clean = np.where(t < 0.0, -15.0, -15.0 + 100.0 * t)
    rec = Signal("velocity_z", t, _dsp.cfc(clean + rng.normal(0.0, 0.01, t.size), FS, CFC),
                 "m/s", CFC)
    ts = t[t >= 0.0]
    lobe = 0.5 * np.clip(np.minimum(ts - 0.010, 0.040 - ts) / 0.003, 0.0, 1.0)
    sim = Signal("velocity_z", ts, -15.0 + 100.0 * ts + 0.08 * np.exp(-ts / 0.001) + lobe,
                 "m/s", CFC)
    wins = locate_mismatch(rec, sim, shift=0.0)
    assert len(wins) == 1 and wins[0].t_start_s > 0.008, [w.description for w in wins]
    assert wins[0].feature == "value_too_high" and wins[0].other_features == []


def test_an_overshoot_where_the_residual_crosses_zero_is_no_window_of_its_own(t, monkeypatch):
    """Oracle: recording = pulses at 15 ms (500 m/s^2) and 38 ms (300); simulation = both
    30 % low plus a bump between them, so the residual overshoots above the recording for a
    moment between the two deficits. An 18 m/s^2 bump (its lobe above the recording by some
    12 m/s^2, 20 noise sigma, under a tenth of the deficits) is part of the lobe beside it: two
    windows (each peak too low), where without the merge (``LOBE_MIN_RATIO`` 0) it is a third,
    'force too high'. A 40 m/s^2 bump (a quarter of the deficits) is a window of its own."""
    from crashdem.diagnosis import mismatch

    first, second = _pulse(t, 0.015, 500.0, 0.004), _pulse(t, 0.038, 300.0, 0.004)
    rec = _signal(t, _recorded(t, first + second, 8))

    def windows(bump_height):
        sim = 0.7 * (first + second) + _pulse(t, 0.0265, bump_height, 0.003)
        return locate_mismatch(rec, _signal(t, _dsp.cfc(sim, FS, CFC)), shift=0.0)

    small = windows(18.0)
    assert [w.feature for w in small] == ["peak_too_low", "peak_too_low"], \
        [w.description for w in small]
    monkeypatch.setattr(mismatch, "LOBE_MIN_RATIO", 0.0)
    assert [w.feature for w in windows(18.0)] == ["peak_too_low", "force_too_high",
                                                   "peak_too_low"]
    monkeypatch.undo()
    big = windows(40.0)
    assert [w.feature for w in big] == ["peak_too_low", "force_too_high", "peak_too_low"], \
        [w.description for w in big]
    assert big[1].t_start_s < 0.0265 < big[1].t_end_s


@pytest.mark.parametrize("offset, heads", [(0.05, False), (1.0, True)])
def test_a_small_feature_does_not_head_a_large_window(t, offset, heads):
    """Oracle: the simulated velocity starts ``offset`` above the recording, runs up to 2 m/s
    above it at 30 ms and back by 70 ms. A 0.05 m/s initial offset (2.5 % of the window's
    largest difference) does not describe that window: it is 'value too high', the offset kept
    beside it. A 1 m/s offset (half of it) heads it."""
    rng = np.random.default_rng(9)
    clean = np.where(t < 0.0, -15.0, -15.0 + 50.0 * t)
    rec = Signal("velocity_z", t, _dsp.cfc(clean + rng.normal(0.0, 0.01, t.size), FS, CFC),
                 "m/s", CFC)
    ts = t[t >= 0.0]
    lobe = np.interp(ts, [0.0, 0.03, 0.06, 0.07], [offset, 2.0, offset, 0.0])
    sim = Signal("velocity_z", ts, -15.0 + 50.0 * ts + lobe, "m/s", CFC)
    wins = locate_mismatch(rec, sim, shift=0.0)
    assert len(wins) == 1, [x.description for x in wins]
    w = wins[0]
    assert w.t_start_s < 0.001 and 0.06 < w.t_end_s < 0.08
    assert (w.feature == "initial_offset") == heads, w.description
    if not heads:
        assert w.feature == "value_too_high" and w.size > 0.5
        assert [f["feature"] for f in w.other_features] == ["initial_offset"]
