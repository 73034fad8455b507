"""Tests of the SAE J211-1 CFC filter (crashdem.filters).

Corridor used as the oracle (derived once, ``j211_corridor`` below), SAE J211-1 Fig. 1 as listed in
anchors.md section 2 -- all of these numbers are **[M]** items there (from memory of the standard,
not checked against its text):

* F_L = 0.1 Hz; F_N = 1650, 1000, 300, 100 Hz for CFC 1000, 600, 180, 60           [M]
* flat +-0.5 dB from F_L to F_H (F_H = CFC)                                          [M]
* +0.5/-1 dB at F_H, +0.5/-4 dB at F_N                                               [M]
* above F_N the upper limit falls at -9 dB/octave, floor -30 dB                     [M]

Between F_H and F_N the lower limit is taken as the straight line (in dB vs log f) from -1 dB to
-4 dB, and above F_N there is no lower limit (J211's vertical line "f"). The -24 dB/octave segment
of the upper limit is not used because its break point is not given in anchors.md (it cannot lie
at F_N: a 4-pole filter with a -3 dB point at 5/3 CFC would violate it); instead the asymptotic
-24 dB/octave roll-off of the 4-pole cascade is tested separately.
"""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import signal as sps

from crashdem.filters import (
    J211_FACTOR,
    SampleRateWarning,
    cfc_filter,
    check_sample_rate,
    j211_coefficients,
    j211_response,
    pad_length,
)
from crashdem.signal import Signal

F_L = 0.1  # [Hz] [M]
F_N = {1000: 1650.0, 600: 1000.0, 180: 300.0, 60: 100.0}  # [Hz] [M]
CLASSES = (60, 180, 600, 1000)

#: the measured sine gain must equal the gain computed from the coefficients to this [dB]; the
#: least-squares fit over >= 20 cycles of a pure tone leaves only round-off and the decayed
#: start-up transient (< 1e-9 relative after the exclusion zone), i.e. < 1e-6 dB
SINE_VS_COEFF_DB = 1e-6
#: forward-backward Appendix C vs scipy butter+sosfiltfilt with the same odd padding and
#: steady-state seeding: the same linear recursion, so only floating-point round-off differs
#: (~100 operations per sample, each 1e-16 relative)
SCIPY_RTOL = 1e-11
#: zero-phase symmetry: output of a symmetric input, relative to its peak; round-off only
SYMMETRY_RTOL = 1e-10


def j211_corridor(f: np.ndarray, cfc: int) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper corridor limits [dB] at frequencies ``f`` [Hz] (see module docstring)."""
    f = np.asarray(f, dtype=float)
    f_h, f_n = float(cfc), F_N[cfc]
    upper = np.where(f <= f_n, 0.5, np.maximum(-30.0, 0.5 - 9.0 * np.log2(f / f_n)))
    lower = np.full_like(f, -np.inf)
    lower[(f >= F_L) & (f < f_h)] = -0.5
    mid = (f >= f_h) & (f <= f_n)
    lower[mid] = -1.0 - 3.0 * np.log(f[mid] / f_h) / np.log(f_n / f_h)
    return lower, upper


def sine_gain_db(cfc: float, fs: float, f: float) -> float:
    """Gain [dB] of the implementation measured with a unit sine at ``f`` (least-squares fit)."""
    n_cycles_min = 40
    duration = max(0.2, n_cycles_min / f)
    t = np.arange(int(duration * fs)) / fs
    x = np.sin(2 * np.pi * f * t + 0.3)
    y = cfc_filter(x, fs, cfc)
    # exclude the padding-influenced ends (2 x the default pad each side)
    m = pad_length(fs, cfc) * 2
    tt, yy = t[m:-m], y[m:-m]
    A = np.column_stack([np.sin(2 * np.pi * f * tt), np.cos(2 * np.pi * f * tt)])
    c, *_ = np.linalg.lstsq(A, yy, rcond=None)
    return 20 * np.log10(math.hypot(*c))


@pytest.mark.parametrize("cfc", CLASSES)
@pytest.mark.parametrize("fs_per_cfc", [10.0, 50.0])
def test_computed_response_inside_corridor(cfc, fs_per_cfc):
    """Oracle: J211-1 Fig. 1 corridor [M] (module docstring); |H|^2 from the Appendix C
    coefficients, on a dense log grid from F_L to the Nyquist frequency."""
    fs = fs_per_cfc * cfc
    f = np.geomspace(F_L, 0.4999 * fs, 4000)
    g = 20 * np.log10(j211_response(f, cfc, fs))
    lo, hi = j211_corridor(f, cfc)
    assert np.all(g >= lo), f"below corridor at {f[g < lo][:3]} Hz"
    assert np.all(g <= hi), f"above corridor at {f[g > hi][:3]} Hz"


@pytest.mark.parametrize("cfc", CLASSES)
def test_measured_sine_response_inside_corridor(cfc):
    """Oracle: J211 corridor [M] and the coefficient response; sines through the actual
    forward-backward implementation (padding included) at 0.1 F_H ... 4 F_N."""
    fs = 10_000.0 if cfc < 1000 else 20_000.0
    f_n = F_N[cfc]
    freqs = [0.1 * cfc, 0.5 * cfc, cfc, math.sqrt(cfc * f_n), f_n, 2 * f_n, 4 * f_n]
    for f in freqs:
        g = sine_gain_db(cfc, fs, f)
        lo, hi = j211_corridor(np.array([f]), cfc)
        assert lo[0] <= g <= hi[0], (f, g, lo, hi)
        g_coeff = 20 * np.log10(j211_response(f, cfc, fs))
        assert abs(g - g_coeff) < SINE_VS_COEFF_DB, (f, g, g_coeff)


def test_asymptotic_rolloff_is_24_db_per_octave():
    """Oracle: a 4-pole low-pass rolls off at -24 dB/octave (20*4*log10(2) = 24.08); the
    bilinear transform only steepens it, so at fs = 1000 CFC the octave 8-16 F_N is within
    0.3 dB/octave of the analog value (warping error ~ (pi f/fs)^2 < 1e-2)."""
    cfc, fs = 60.0, 60_000.0
    f1, f2 = 8 * 100.0, 16 * 100.0
    slope = 20 * np.log10(j211_response(f2, cfc, fs) / j211_response(f1, cfc, fs))
    fc = J211_FACTOR * cfc
    analog = 20 * np.log10((1 + (f1 / fc) ** 4) / (1 + (f2 / fc) ** 4))
    assert abs(slope - analog) < 0.3
    assert -24.5 < analog < -23.5


@pytest.mark.parametrize("cfc", CLASSES)
def test_matches_scipy_butter_sosfiltfilt(cfc):
    """Oracle: independent implementation -- scipy.signal.butter(2, 2.0775*CFC, fs=fs) (bilinear
    with pre-warp) + sosfiltfilt with the same odd padding length and steady-state seeding
    (lfilter_zi), anchors.md section 2. Whole record, round-off tolerance ``SCIPY_RTOL``."""
    fs = 20_000.0
    rng = np.random.default_rng(cfc)
    x = np.cumsum(rng.standard_normal(3000)) + 5.0 * np.sin(np.arange(3000) / 40)
    y = cfc_filter(x, fs, cfc)
    sos = sps.butter(2, J211_FACTOR * cfc, fs=fs, output="sos")
    ref = sps.sosfiltfilt(sos, x, padtype="odd", padlen=pad_length(fs, cfc))
    assert np.max(np.abs(y - ref)) < SCIPY_RTOL * np.max(np.abs(x))
    # scipy's own default padding differs only near the ends: check the middle
    ref_default = sps.sosfiltfilt(sos, x)
    m = 2 * pad_length(fs, cfc)
    assert np.max(np.abs(y[m:-m] - ref_default[m:-m])) < 1e-6 * np.max(np.abs(x))


def test_coefficients_equal_scipy_butter():
    """Oracle: scipy.signal.butter(2, K*CFC, fs) implements the same pre-warped bilinear design
    (b = [a0, a1, a2], a = [1, -b1, -b2]); round-off tolerance."""
    for cfc in CLASSES:
        for fs in (10 * cfc, 12_345.0 if cfc < 1000 else 20_000.0):
            a0, a1, a2, b1, b2 = j211_coefficients(cfc, fs)
            b, a = sps.butter(2, J211_FACTOR * cfc, fs=fs)
            np.testing.assert_allclose([a0, a1, a2], b, rtol=1e-12)
            np.testing.assert_allclose([1.0, -b1, -b2], a, rtol=1e-12)


def test_zero_phase_symmetric_pulse_and_impulse():
    """Oracle: forward-backward filtering has zero phase (J211-1 App. C), so a symmetric input
    far from the ends gives a symmetric output, the impulse response is symmetric about the
    impulse, and the input/output cross-correlation of broadband noise peaks at lag 0."""
    fs, cfc = 10_000.0, 180
    n = 4001
    k = np.arange(n) - n // 2
    pulse = np.where(np.abs(k) < 60, np.cos(np.pi * k / 120) ** 2, 0.0)  # symmetric, compact
    y = cfc_filter(pulse, fs, cfc)
    assert np.max(np.abs(y - y[::-1])) < SYMMETRY_RTOL * np.max(np.abs(y))
    assert np.argmax(y) == n // 2
    imp = np.zeros(n)
    imp[n // 2] = 1.0
    h = cfc_filter(imp, fs, cfc)
    assert np.max(np.abs(h - h[::-1])) < SYMMETRY_RTOL * np.max(np.abs(h))
    assert abs(h.sum() - 1.0) < 1e-9  # unit DC gain
    x = np.random.default_rng(1).standard_normal(20_000)
    yx = cfc_filter(x, fs, cfc)
    lags = np.arange(-50, 51)
    m = x.size
    xc = [np.dot(x[100:m - 100], yx[100 + lag:m - 100 + lag]) for lag in lags]
    assert lags[int(np.argmax(xc))] == 0


def test_minus_3db_at_five_thirds_cfc():
    """Oracle: anchors.md section 2 [D]: (sqrt(2)-1)^(1/4) * 2.0775 = 1.6667 (the analog cascade
    is -3 dB at 5/3 CFC); the digital filter's -3 dB point follows the bilinear warp
    f3 = fs/pi * atan((sqrt(2)-1)^(1/4) tan(pi K CFC/fs)) exactly, which is within 1e-3 of 5/3 CFC
    at fs = 100 CFC (warp error ~ x^2 (1 - r^2)/3 = 5e-4 with x = pi K/100)."""
    r = (math.sqrt(2) - 1) ** 0.25
    assert abs(r * J211_FACTOR - 5 / 3) < 1e-4
    for cfc in CLASSES:
        fs = 100.0 * cfc
        from scipy.optimize import brentq
        f3 = brentq(lambda f: 20 * np.log10(j211_response(f, cfc, fs)) + 10 * np.log10(2),
                    cfc, 3 * cfc, xtol=1e-10)
        f3_warp = fs / math.pi * math.atan(r * math.tan(math.pi * J211_FACTOR * cfc / fs))
        assert abs(f3 - f3_warp) < 1e-7 * cfc
        assert abs(f3 / cfc - 5 / 3) < 1e-3
        # and through the implementation: a sine at 5/3 CFC loses 3 dB (warp error + fit)
        assert abs(sine_gain_db(cfc, fs, 5 / 3 * cfc) + 10 * np.log10(2)) < 0.01


def test_end_handling_preserves_constant_and_ramp():
    """Oracle: unit DC gain (a0+a1+a2 = 1-b1-b2) and steady-state seeding keep a constant exact
    at both ends; the odd reflection 2 x0 - x[k] continues a straight line, and a zero-phase
    low-pass passes a ramp unchanged, so a ramp is preserved up to the decayed seed transient."""
    fs, cfc = 10_000.0, 60
    t = np.arange(2000) / fs
    for mode in ("odd", "even", "constant", "none"):
        y = cfc_filter(np.full(t.size, 3.7), fs, cfc, padding=mode)
        assert np.max(np.abs(y - 3.7)) < 1e-12
    ramp = 2.0 + 50.0 * t
    y_odd = cfc_filter(ramp, fs, cfc, padding="odd")
    y_none = cfc_filter(ramp, fs, cfc, padding="none")
    err_odd = np.max(np.abs(y_odd - ramp))
    err_none = np.max(np.abs(y_none - ramp))
    assert err_odd < 1e-6 * np.ptp(ramp)
    assert err_none > 100 * err_odd  # unpadded start-up transient is visible


def test_signal_metadata_and_units():
    """The filtered Signal keeps name/unit/time, sets cfc and records the method (docs)."""
    fs = 10_000.0
    t = np.arange(1000) / fs
    s = Signal("rear_accel_x", t, np.sin(40 * t), "m/s^2", meta={"iso_code": "10VEHCCG0000ACX0"})
    out = cfc_filter(s, cfc=60)
    assert out.cfc == 60.0 and out.unit == "m/s^2" and out.name == "rear_accel_x"
    assert out.meta["iso_code"] == "10VEHCCG0000ACX0"
    f = out.meta["filter"]
    assert f["padding"] == "odd" and f["pad_samples"] == pad_length(fs, 60) == 300
    assert f["design_factor"] == J211_FACTOR and f["fs"] == pytest.approx(fs)
    iso = cfc_filter(s, cfc=60, iso6487=True)
    assert iso.meta["filter"]["design_factor"] == 2.0833
    np.testing.assert_allclose(cfc_filter(s.data, fs, 60), out.data, rtol=0, atol=0)


def test_2d_array_filters_each_row():
    """A (3, n) array is filtered along the last axis exactly like its rows one by one."""
    x = np.random.default_rng(3).standard_normal((3, 800))
    y = cfc_filter(x, 10_000.0, 180)
    for r in range(3):
        np.testing.assert_array_equal(y[r], cfc_filter(x[r], 10_000.0, 180))
    np.testing.assert_array_equal(cfc_filter(x.T, 10_000.0, 180, axis=0), y.T)


def test_error_fs_too_low_names_channel_fs_and_cfc():
    """fs <= 2*2.0775*CFC makes tan(wd T/2) undefined (J211 App. C): hard error."""
    t = np.arange(100) / 400.0
    s = Signal("seat_accel_z", t, np.zeros(100), "g")
    with pytest.raises(ValueError, match=r"seat_accel_z.*fs=400 Hz.*CFC 180"):
        cfc_filter(s, cfc=180)
    with pytest.raises(ValueError, match=r"fs=1000 Hz.*CFC 1000"):
        cfc_filter(np.zeros(100), 1000.0, 1000)


def test_warning_and_strict_error_below_ten_times_cfc():
    """J211-1 recommends fs >= 10 F_H: warning by default, error with strict=True."""
    with pytest.warns(SampleRateWarning, match=r"'ch'.*fs=4000 Hz.*6000 Hz"):
        check_sample_rate(4000.0, 600, "ch")
    with pytest.raises(ValueError, match=r"'ch'.*below the J211-1 recommendation"):
        check_sample_rate(4000.0, 600, "ch", strict=True)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_sample_rate(6000.0, 600, "ch")  # exactly 10 x CFC is fine


def test_errors_bad_inputs():
    """Non-uniform time, NaN data, bad cfc or padding give ValueErrors naming the problem."""
    t = np.arange(500) / 10_000.0
    t2 = t.copy()
    t2[200:] += 3e-5
    with pytest.raises(ValueError, match="'x'.*not uniform"):
        cfc_filter(Signal("x", t2, np.zeros(500), "g"), cfc=60)
    d = np.zeros(500)
    d[7] = np.nan
    with pytest.raises(ValueError, match="'x'.*NaN"):
        cfc_filter(Signal("x", t, d, "g"), cfc=60)
    with pytest.raises(ValueError, match="cfc=-60"):
        cfc_filter(np.zeros(500), 10_000.0, -60)
    with pytest.raises(ValueError, match="padding='mirror'"):
        cfc_filter(np.zeros(500), 10_000.0, 60, padding="mirror")
    with pytest.raises(ValueError, match="fs=None"):
        cfc_filter(np.zeros(500), None, 60)


@settings(max_examples=60, deadline=None)
@given(cfc=st.floats(1.0, 5000.0), ratio=st.floats(4.2, 1000.0))
def test_coefficients_stable_unit_dc_gain(cfc, ratio):
    """Oracle: Appendix C design is a stable Butterworth with unit DC gain for any CFC > 0 and
    fs > 2 K CFC: a0+a1+a2 = 1-b1-b2 and both poles inside the unit circle."""
    fs = ratio * J211_FACTOR * cfc
    a0, a1, a2, b1, b2 = j211_coefficients(cfc, fs)
    assert abs((a0 + a1 + a2) - (1 - b1 - b2)) < 1e-12
    assert np.all(np.abs(np.roots([1.0, -b1, -b2])) < 1.0)
