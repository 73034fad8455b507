"""The model-error machinery of the diagnosis (fast, no DEM): weights and independent samples
of ``FitProblem.model_error``, the residual-correlation n_eff, BIC requalification and the
baseline anchor (discrepancy)."""
from __future__ import annotations

import math

import numpy as np

import crashdem.diagnosis as dg
from crashdem.diagnosis import _dsp
from crashdem.diagnosis.fit import FitProblem
from crashdem.diagnosis.mismatch import NoiseEstimate
from crashdem.signal import Signal

FS = 12500.0


def _sig(x, t):
    return Signal("accel_z", t, x, "m/s^2", 60.0)


def _problem(model_error=None):
    t = np.arange(-0.05, 0.15, 1.0 / FS)
    rec = {"accel_z": _sig(np.zeros_like(t), t)}
    noise = {"accel_z": NoiseEstimate(0.5, "test", (-0.05, -0.01), "m/s^2")}
    return FitProblem(rec, noise, ["accel_z"], lambda v: rec, t0=0.0,
                      model_error=model_error or {})


def test_model_error_weights_and_n_eff():
    """Weight = 1 / sqrt(sigma_n^2 + sigma_m^2); n_eff = N / tau with tau the variance-weighted
    correlation length (here the model error dominates: tau ~ tau_m = 10 ms -> 15 samples
    over the 0.15 s window), never more than the bandwidth count."""
    p0 = _problem()
    p1 = _problem({"accel_z": (5.0, 0.010)})
    assert math.isclose(p0.weights["accel_z"], 1 / 0.5)
    assert math.isclose(p1.weights["accel_z"], 1 / math.sqrt(0.25 + 25.0))
    n = np.count_nonzero(p0.recording["accel_z"].t >= 0.0)
    assert math.isclose(p0.n_eff, min(_dsp.effective_samples(n, FS, 60.0), p0.n))
    tau_n = n / _dsp.effective_samples(n, FS, 60.0) / FS
    tau = (0.25 * tau_n + 25.0 * 0.010) / 25.25
    assert math.isclose(p1.n_eff, n / (tau * FS), rel_tol=1e-9)
    assert p1.n_eff < p0.n_eff


def test_residual_correlation_white_vs_correlated():
    """Integral correlation length: ~1 sample for white noise, ~ the filter's length for a
    moving average of 50 samples (1 + 2 sum (1 - k/50) = 50)."""
    rng = np.random.default_rng(0)
    w = rng.normal(size=20000)
    assert dg._residual_correlation(w) < 1.2
    ma = np.convolve(w, np.ones(50) / 50, mode="valid")
    assert 35.0 < dg._residual_correlation(ma) < 65.0


def test_requalify_recomputes_bic_and_inflates_uncertainty():
    """Fewer independent samples: BIC and penalty with the new n_eff, uncertainty x
    sqrt(n_old / n_new), ordering by RSS kept for equal k."""
    from crashdem.diagnosis.fit import FitResult

    def fr(rss, k):
        return FitResult("x", {}, {"a": 1.0}, {}, 0.0, rss, 1000, 100.0, k, 0.0, 0.0, {}, {}, [], 0)

    a, b = fr(1000.0, 2), fr(500.0, 3)
    dg._requalify([a, b], 25.0)
    assert math.isclose(a.bic, 25.0 * math.log(1.0) + 2 * math.log(25.0))
    assert math.isclose(b.bic, 25.0 * math.log(0.5) + 3 * math.log(25.0))
    assert math.isclose(a.uncertainty["a"], 2.0) and a.n_eff == 25.0


def test_discrepancy_anchor_is_exact_on_the_baseline():
    """Anchoring: the calibrated screening model plus the discrepancy reproduces the baseline
    exactly on the screening model's time axis (after contact), and is zero before the
    baseline's first sample."""
    t = np.arange(-0.02, 0.12, 1.0 / FS)
    rom = {"accel_z": _sig(np.where(t > 0, 100.0 * np.sin(30 * t), 0.0), t)}
    tb = np.arange(-0.0005, 0.12, 1.0 / FS)
    base = {"accel_z": _sig(np.where(tb > 0, 120.0 * np.sin(28 * tb) + 5.0, 0.0), tb)}
    shift = 0.0
    d = dg._discrepancy(base, rom, shift, ["accel_z"])["accel_z"]
    inside = (t >= tb[0]) & (t <= tb[-1])
    np.testing.assert_allclose((rom["accel_z"].data + d.data)[inside],
                               np.interp(t[inside], tb, base["accel_z"].data), atol=1e-9)
    assert np.all(d.data[t < tb[0]] == 0.0)


def _loading_unloading(t, t_stop, z_max):
    """Tip depth that rises from 0 at t = 0 to z_max at t_stop (sine quarter), then recedes."""
    z = np.where(t <= 0.0, 0.0, z_max * np.sin(0.5 * math.pi * np.clip(t / t_stop, 0.0, 1.0)))
    after = t > t_stop
    z[after] = z_max - 0.5 * (t[after] - t_stop)
    return z


def test_depth_index_is_the_identity_on_the_calibrated_run():
    """The depth-indexed anchor gives back the time itself when the hypothesis run is the
    calibrated run (the anchor then reproduces the baseline exactly, as the time anchor)."""
    t = np.arange(-0.02, 0.15, 1.0 / FS)
    z = _loading_unloading(t, 0.10, 0.5)
    np.testing.assert_allclose(dg._depth_index(t, z, z), t, atol=1e-12)


def test_depth_index_maps_equal_depths_and_continues_after_the_stop():
    """Oracle: a hypothesis run that goes through the same depths s times faster (z_h(t) =
    z_c(s t)) is indexed at s t while it penetrates; after its own deepest point it advances
    with time from there (tau = t_stop_c + (t - t_stop_c / s)); deeper than the calibrated run
    it continues in time from the calibrated run's deepest point; before contact tau = t."""
    t = np.arange(-0.02, 0.15, 0.2 / FS)
    s, t_c = 1.6, 0.10
    zc = _loading_unloading(t, t_c, 0.5)
    zh = _loading_unloading(t * s, t_c, 0.5)
    tau = dg._depth_index(t, zh, zc)
    load = (t > 0.002) & (t <= t_c / s - 0.002)
    np.testing.assert_allclose(tau[load], s * t[load], atol=2e-4)  # interpolation of the sine
    i_h = int(np.argmax(zh))
    after = t > t[i_h] + 0.001
    np.testing.assert_allclose(tau[after], tau[i_h] + t[after] - t[i_h], atol=1e-12)
    assert abs(tau[i_h] - t_c) < 2e-3
    assert np.all(tau[t <= 0.0] == t[t <= 0.0])
    # deeper than the calibrated run: continues in time from its deepest point
    zd = _loading_unloading(t, 0.12, 0.6)
    tau_d = dg._depth_index(t, zd, zc)
    first = int(np.argmax(zd > 0.5))
    deeper = (zd > 0.5) & (np.arange(t.size) <= int(np.argmax(zd)))
    np.testing.assert_allclose(tau_d[deeper], t_c + (t[deeper] - t[first]), atol=2e-4)
