"""Tests of the ISO/TS 18571 rating and comparison helpers (crashdem.metrics).

Oracles: analytic sub-score values for pure time shifts and pure scalings (hand-worked from the
published formulas), an analytic integral for the corridor score of a scaled half-sine, an
independent brute-force DTW, invariances the standard implies, and reference numbers from an
independent implementation (VSI Graz ``objective_rating_metrics`` 1.3 from PyPI, class
``ISO18571``, run offline outside this repository on the same generated inputs).
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from crashdem.metrics import (
    ISO18571Params,
    compare,
    corridor_score,
    dtw_align,
    duration,
    iso18571,
    peak_error,
    peak_time_error,
    phase_shift,
    rms_error,
)
from crashdem.signal import G0, Signal

DT = 1e-4  # [s] the 10 kHz grid of the standard
T_END = 0.12  # [s]
#: round-off level for closed-form sub-scores (a few hundred float operations)
ROUNDOFF = 1e-12
#: the VSI reference values were printed with 6 decimals
VSI_TOL = 1e-6


def half_sine(t, t0=0.02, width=0.05, amp=100.0):
    return np.where((t > t0) & (t < t0 + width), amp * np.sin(np.pi * (t - t0) / width), 0.0)


def sig(name, t, x, unit="N"):
    return Signal(name, t, x, unit)


@pytest.fixture(scope="module")
def grid():
    return np.arange(0.0, T_END, DT)


def test_identical_signals_score_one(grid):
    """Identical signals: every sub-score and the overall rating are exactly 1."""
    x = half_sine(grid) - 0.3 * half_sine(grid, 0.07, 0.03, 50)
    r = iso18571(sig("T", grid, x), sig("C", grid, x))
    assert (r.overall, r.corridor, r.phase, r.magnitude, r.slope) == (1.0, 1.0, 1.0, 1.0, 1.0)
    assert r.grade == "excellent" and r.shift_samples == 0


def test_phase_score_follows_linear_rule_and_overall_decreases_with_shift(grid):
    """Oracle: for a pure delay of n samples the best correlation is at lag n (correlation 1),
    so E_P = (0.2 N - n)/(0.2 N) (k_p = 1), 0 beyond 0.2 N; the overall rating must decrease
    monotonically with the delay."""
    T = half_sine(grid)
    n_tot = grid.size
    overall = []
    for n in (0, 5, 10, 20, 40, 80, 160, 250):
        C = half_sine(grid, 0.02 + n * DT)
        r = iso18571(sig("T", grid, T), sig("C", grid, C))
        assert r.shift_samples == min(n, int(0.2 * n_tot))  # the search stops at 0.2 N
        expected = 1.0 if n == 0 else max(0.0, (0.2 * n_tot - n) / (0.2 * n_tot))
        assert abs(r.phase - expected) < ROUNDOFF
        assert r.time_shift == pytest.approx(r.shift_samples * DT, abs=1e-15)
        overall.append(r.overall)
    assert np.all(np.diff(overall) < 0)


def test_overall_decreases_with_amplitude_scaling(grid):
    """The rating decreases monotonically as the candidate is scaled away from the reference."""
    T = half_sine(grid)
    scores = [iso18571(sig("T", grid, T), sig("C", grid, s * T)).overall
              for s in (1.0, 1.05, 1.1, 1.2, 1.4, 1.8, 2.5)]
    assert np.all(np.diff(scores) < 0)


def test_overall_decreases_with_noise(grid):
    """The rating decreases monotonically with the amplitude of one added noise realization."""
    T = half_sine(grid)
    noise = np.random.default_rng(3).standard_normal(grid.size)
    scores = [iso18571(sig("T", grid, T), sig("C", grid, T + a * noise)).overall
              for a in (0.0, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0)]
    assert np.all(np.diff(scores) < 0)


def _corridor_half_sine_analytic(s, a0=0.05, b0=0.5, k=2):
    """(2/pi) * int_0^{pi/2} g(|s-1| sin(theta)) d theta, g the corridor point score."""
    c = abs(s - 1.0)
    th_i = math.asin(min(1.0, a0 / c))
    th_o = math.asin(min(1.0, b0 / c))
    assert k == 2
    # int ((b0 - c sin)/(b0 - a0))^2 = [b0^2 th + 2 b0 c cos + c^2 (th/2 - sin(2th)/4)] / (b0-a0)^2
    F = lambda th: (b0 * b0 * th + 2 * b0 * c * math.cos(th)  # noqa: E731
                    + c * c * (th / 2 - math.sin(2 * th) / 4))
    return (2 / math.pi) * (th_i + (F(th_o) - F(th_i)) / (b0 - a0) ** 2)


@pytest.mark.parametrize("s", [1.3, 0.8, 1.7])
def test_corridor_score_of_scaled_half_sine_matches_integral(s):
    """Oracle: on the interval [0, D] of a half-sine A sin(pi t/D), |C - T| = |s-1| A sin, so Z is
    the mean of g(|s-1| sin(theta)), whose continuous limit is the integral above (a0 = 0.05,
    b0 = 0.5, k_z = 2). A Riemann sum of a function of total variation <= 2 on N + 1 points
    differs from the integral by at most 3/N."""
    width = 0.1
    t = np.arange(0.0, width + DT / 2, DT)
    T = 100.0 * np.sin(np.pi * t / width)
    z = corridor_score(T, s * T)
    n = t.size - 1
    assert abs(z - _corridor_half_sine_analytic(s)) < 3.0 / n


@pytest.mark.parametrize("s", [1.2, 0.7, 3.5])
def test_slope_score_of_scaled_signal_is_linear_rule(grid, s):
    """Oracle: differentiation and the moving average are linear, so C = s T gives
    e_S = |s-1| exactly and E_S = max(0, (2 - |s-1|)/2) (eps_s = 2, k_s = 1); no phase shift
    (the lag-0 correlation is 1)."""
    T = half_sine(grid) - half_sine(grid, 0.075, 0.02, 30)
    r = iso18571(sig("T", grid, T), sig("C", grid, s * T))
    assert r.shift_samples == 0 and r.phase == 1.0
    assert abs(r.slope_error - abs(s - 1)) < ROUNDOFF
    assert abs(r.slope - max(0.0, (2 - abs(s - 1)) / 2)) < ROUNDOFF


@pytest.mark.parametrize("s", [1.2, 0.9, 1.6])
def test_magnitude_score_of_scaled_rectangle(grid, s):
    """Oracle: for a rectangular pulse and C = s T, no warping can pair a nonzero value with a
    closer one, so DTW keeps the diagonal: e_M = |s-1|, E_M = max(0, (0.5 - |s-1|)/0.5)."""
    T = np.where((grid > 0.03) & (grid < 0.07), 50.0, 0.0)
    r = iso18571(sig("T", grid, T), sig("C", grid, s * T))
    assert abs(r.magnitude_error - abs(s - 1)) < ROUNDOFF
    assert abs(r.magnitude - max(0.0, (0.5 - abs(s - 1)) / 0.5)) < ROUNDOFF


def _dtw_bruteforce(x, y, r):
    """Independent full-matrix DTW (squared cost, steps (1,0),(0,1),(1,1), band |i-j| < r)."""
    n = x.size
    D = np.full((n + 1, n + 1), np.inf)
    D[0, 0] = 0.0
    for i in range(1, n + 1):
        for j in range(1, n + 1):
            if abs(i - j) < r:
                D[i, j] = (x[i - 1] - y[j - 1]) ** 2 + min(D[i - 1, j], D[i, j - 1],
                                                          D[i - 1, j - 1])
    return D[n, n]


def test_dtw_matches_bruteforce_cost():
    """Oracle: independent O(n^2) dynamic programme; the warped pair's summed squared difference
    equals the optimal DTW cost, and never exceeds the diagonal (a feasible path)."""
    rng = np.random.default_rng(11)
    for n, band in ((25, 0.2), (40, 0.1), (31, 1.0)):
        x, y = rng.standard_normal(n), rng.standard_normal(n)
        xw, yw = dtw_align(x, y, band)
        r = max(1, math.ceil(band * n))
        cost = float(np.sum((xw - yw) ** 2))
        assert abs(cost - _dtw_bruteforce(x, y, r)) < 1e-12 * max(1.0, cost)
        assert cost <= float(np.sum((x - y) ** 2)) + 1e-12


def test_phase_shift_symmetric_under_swap(grid):
    """The Pearson correlation at a lag is symmetric in its two arguments, so swapping reference
    and candidate gives the same shift (opposite direction) and the same phase score."""
    T = half_sine(grid) + half_sine(grid, 0.075, 0.02, 30)
    C = 0.9 * half_sine(grid, 0.026) + half_sine(grid, 0.083, 0.025, 20)
    n1, d1, r1 = phase_shift(T, C)
    n2, d2, r2 = phase_shift(C, T)
    assert n1 == n2 > 0 and d1 == -d2 and abs(r1 - r2) < ROUNDOFF
    a = iso18571(sig("T", grid, T), sig("C", grid, C))
    b = iso18571(sig("C", grid, C), sig("T", grid, T))
    assert a.phase == b.phase


def test_invariant_to_sign_and_unit(grid):
    """Sub-scores use |.|, L1 norms and correlations: negating both signals, or giving one in g
    and the other in m/s^2, leaves every score unchanged (round-off)."""
    T = half_sine(grid, amp=30.0)
    C = 1.15 * half_sine(grid, 0.023, 0.052, 30.0)
    base = iso18571(sig("T", grid, T, "g"), sig("C", grid, C, "g"))
    neg = iso18571(sig("T", grid, -T, "g"), sig("C", grid, -C, "g"))
    mixed = iso18571(sig("T", grid, T, "g"), sig("C", grid, C * G0, "m/s^2"))
    for r in (neg, mixed):
        for k in ("overall", "corridor", "phase", "magnitude", "slope"):
            assert abs(getattr(r, k) - getattr(base, k)) < 1e-9, k


def test_invariant_to_input_sample_rate():
    """The standard evaluates on a 10 kHz grid: the same analytic signals supplied at 10, 20 and
    50 kHz are resampled to identical grids; linear-interpolation error of a 50 ms half-sine at
    <= 50 us spacing is <= (pi/0.05)^2 * (5e-5)^2 / 8 ~ 1.2e-6 of the peak, far below 1e-4."""
    ref = None
    for fs in (10_000.0, 20_000.0, 50_000.0):
        t = np.arange(round(T_END * fs) + 1) / fs
        T = half_sine(t) + 5 * np.sin(2 * np.pi * 40 * t)
        C = 0.9 * half_sine(t, 0.0227, 0.055) + 5 * np.sin(2 * np.pi * 40 * t)
        r = iso18571(sig("T", t, T), sig("C", t, C), t_window=(0.0, 0.1))
        if ref is None:
            ref = r
        assert r.n_samples == ref.n_samples == 1001
        for k in ("overall", "corridor", "phase", "magnitude", "slope"):
            assert abs(getattr(r, k) - getattr(ref, k)) < 1e-4, (fs, k)


def test_matches_vsi_reference_implementation(grid):
    """Oracle: VSI Graz objective_rating_metrics 1.3 (PyPI), ISO18571 class, default parameters,
    run offline on these exact inputs (10 kHz, 0-0.12 s); values printed to 6 decimals:
    corridor, phase, magnitude, slope, overall."""
    cases = {
        "wider": (half_sine(grid), half_sine(grid, 0.02, 0.06, 90.0),
                  (0.798483, 0.791667, 0.957142, 0.722815, 0.813718)),
        "two_peaks": (half_sine(grid) + half_sine(grid, 0.06, 0.03, -40.0),
                      0.9 * half_sine(grid, 0.022) + half_sine(grid, 0.058, 0.035, -55.0),
                      (0.851094, 0.962500, 0.904501, 0.895300, 0.892898)),
        "scaled": (half_sine(grid), 1.2 * half_sine(grid),
                   (0.869224, 1.0, 0.898218, 0.9, 0.907333)),
    }
    for name, (T, C, ref) in cases.items():
        r = iso18571(sig("T", grid, T), sig("C", grid, C))
        got = (r.corridor, r.phase, r.magnitude, r.slope, r.overall)
        assert np.allclose(got, ref, rtol=0, atol=VSI_TOL), (name, got)


def test_helpers_on_analytic_cases(grid):
    """Oracles: C = 1.2 T gives peak error 0.2; a delay of 3 ms gives peak time error 3 ms; an
    offset c gives rms error c; a half-sine of width D is above 5 % of its peak for
    D (1 - 2 asin(0.05)/pi), within one sample."""
    T = half_sine(grid)
    assert abs(peak_error(sig("T", grid, T), sig("C", grid, 1.2 * T)) - 0.2) < ROUNDOFF
    shifted = half_sine(grid, 0.023)
    assert abs(peak_time_error(sig("T", grid, T), sig("C", grid, shifted)) - 3e-3) < 1.01 * DT
    assert abs(rms_error(sig("T", grid, T), sig("C", grid, T + 7.0)) - 7.0) < 1e-9
    expected = 0.05 * (1 - 2 * math.asin(0.05) / math.pi)
    assert abs(duration(sig("T", grid, T)) - expected) < 2 * DT
    d = compare(sig("T", grid, T), sig("C", grid, 1.2 * T))
    assert d["peak_error"] == pytest.approx(0.2) and d["unit"] == "N"
    assert d["iso18571"] == pytest.approx(0.907333, abs=VSI_TOL)
    assert d["rms_error_relative"] == pytest.approx(0.2, rel=1e-9)
    assert set(d) >= {"corridor", "phase", "magnitude", "slope", "grade", "duration_error",
                      "peak_time_error", "time_shift"}


def test_errors_name_field_and_problem(grid):
    with pytest.raises(ValueError, match=r"ISO18571Params\.a0=0\.6: must be in \(0, b0=0\.5\)"):
        ISO18571Params(a0=0.6)
    with pytest.raises(ValueError, match="weights sum to"):
        ISO18571Params(w_z=0.5)
    with pytest.raises(ValueError, match=r"different SI units \(N vs m/s\^2\)"):
        iso18571(sig("T", grid, half_sine(grid)), sig("C", grid, half_sine(grid), "g"))
    with pytest.raises(ValueError, match=r"t_window=\(0\.0, 0\.5\) s is outside"):
        iso18571(sig("T", grid, half_sine(grid)), sig("C", grid, half_sine(grid)),
                 t_window=(0.0, 0.5))
    with pytest.raises(ValueError, match="identically zero"):
        corridor_score(np.zeros(20), np.ones(20))
