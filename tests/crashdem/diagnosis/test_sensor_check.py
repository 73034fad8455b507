"""Model-free accelerometer / velocity check (``sensor_check.accel_velocity_check``).

Oracle: the truth sensor of recordings made by the ROM truth generator (midpoint RK2 at 5 us,
exact first-order-hold sensor filter, integrating 12.5 kHz acquisition, noise, CFC 60) -- the
check uses the Tustin filter at the acquisition rate and never sees the truth.
"""
from __future__ import annotations

import numpy as np
import pytest

from crashdem.diagnosis.generator import acquire
from crashdem.diagnosis.rom import RomParams
from crashdem.diagnosis.sensor_check import accel_velocity_check
from crashdem.signal import Signal


@pytest.mark.parametrize("fn, zeta, form, label", [(45.0, 0.08, 0.0, "lowpass"),
                                                   (70.0, 0.15, 1.0, "mount"),
                                                   (150.0, 0.3, 0.0, "lowpass")])
def test_sensor_found_with_form_frequency_and_damping(fn, zeta, form, label):
    rec = acquire(RomParams(mount_frequency=fn, mount_damping=zeta, mount_form=form),
                  np.random.default_rng(3), trigger_offset=0.0012)
    r = accel_velocity_check(rec["accel_z"], rec["velocity_z"])
    assert r["applicable"] and r["detected"]
    assert r["form"] == label
    assert r["mount_frequency"] == pytest.approx(fn, rel=0.03)
    assert r["mount_damping"] == pytest.approx(zeta, rel=0.15)
    assert r["gain"] == pytest.approx(1.0, abs=0.02)
    # the fitted sensor leaves a noise-level difference (ideal-sensor recordings leave 0.75-1.65
    # sigma RMS: the sigma is a MAD estimate from ~100 correlated pre-event samples), the ideal
    # sensor several times more
    assert r["rms_sigma_fitted"] < 2.0
    assert r["rms_sigma_fitted"] < 0.3 * r["rms_sigma_ideal"]


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_ideal_sensor_is_not_flagged(seed):
    """Null: an ideal accelerometer agrees with the velocity's derivative within noise (the
    soil, the speed and the recalibration do not matter to the check)."""
    truth = RomParams(strength_gradient=4e6, interface_depth=0.3, strength_ratio=3.0)
    rec = acquire(truth, np.random.default_rng(seed), trigger_offset=-0.0007)
    r = accel_velocity_check(rec["accel_z"], rec["velocity_z"])
    assert r["applicable"] and not r["detected"]
    assert r["delta_bic"] < 0.0
    assert r["rms_sigma_ideal"] < 1.5


def test_velocity_integrated_from_the_accelerometer_cannot_show_the_sensor():
    """Lab practice: a velocity integrated from the same (resonant) accelerometer agrees with it
    by construction -- the check must say nothing, not invent a sensor."""
    rec = acquire(RomParams(mount_frequency=50.0, mount_damping=0.1, mount_form=0.0),
                  np.random.default_rng(4))
    a = rec["accel_z"]
    dt = 1.0 / a.fs
    v0 = float(rec["velocity_z"].data[0])
    vel = np.concatenate(([0.0], np.cumsum(0.5 * (a.data[1:] + a.data[:-1]) * dt))) \
        - 9.81 * (a.t - a.t[0]) + v0
    r = accel_velocity_check(a, Signal("velocity_z", a.t, vel, "m/s", a.cfc))
    assert r["applicable"] and not r["detected"]


def test_channels_of_another_convention_are_not_compared():
    """A velocity with the opposite sign convention (down positive) is not the derivative of
    this accelerometer's reading: the check reports itself not applicable, and why."""
    rec = acquire(RomParams(), np.random.default_rng(5))
    v = rec["velocity_z"]
    r = accel_velocity_check(rec["accel_z"], Signal("v", v.t, -v.data, "m/s", v.cfc))
    assert not r["applicable"] and not r.get("detected", False)
    assert "gain" in r["reason"]


def test_wide_band_channels_are_not_checked():
    """Above CFC 180 the check is not validated (false detections on wide-band DEM recordings):
    it must say so instead of answering."""
    rec = acquire(RomParams(), np.random.default_rng(6), cfc=1000.0)
    r = accel_velocity_check(rec["accel_z"], rec["velocity_z"])
    assert not r["applicable"] and "CFC" in r["reason"]


def _every(sig: Signal, k: int) -> Signal:
    """Every ``k``-th sample of a recorded channel (a slower acquisition of the same record)."""
    return Signal(sig.name, sig.t[::k], sig.data[::k], sig.unit, sig.cfc, dict(sig.meta))


def test_a_slow_acquisition_is_checked_below_its_nyquist_frequency():
    """A recording sampled at 1.04 kHz (12.5 kHz / 12; J211 asks 600 Hz for CFC 60) holds
    nothing of a mount above its 520 Hz Nyquist frequency. The check searches resonances the
    sampling resolves (up to ``MOUNT_NYQUIST_FRACTION`` of the Nyquist frequency): it runs
    where the 1 kHz end of its span made the filter design singular (``Singular matrix``), it
    does not flag an ideal sensor, and it still finds a 70 Hz mount."""
    from crashdem.diagnosis import _dsp

    ideal = acquire(RomParams(), np.random.default_rng(1), trigger_offset=0.0012)
    r = accel_velocity_check(_every(ideal["accel_z"], 12), _every(ideal["velocity_z"], 12))
    assert r["applicable"] and not r["detected"]
    assert r["mount_frequency"] <= _dsp.MOUNT_NYQUIST_FRACTION * 0.5 * 12500.0 / 12 + 1e-9
    rec = acquire(RomParams(mount_frequency=70.0, mount_damping=0.15, mount_form=1.0),
                  np.random.default_rng(3), trigger_offset=0.0012)
    r = accel_velocity_check(_every(rec["accel_z"], 12), _every(rec["velocity_z"], 12))
    assert r["detected"] and r["mount_frequency"] == pytest.approx(70.0, rel=0.1)
    # the design itself: a resonance at or above the limit is the one at the limit, finite
    x = np.sin(np.linspace(0.0, 20.0, 400))
    y = _dsp.mount_filter_bilinear(x, 1e-3, 1000.0, 0.2)
    assert np.all(np.isfinite(y))
    np.testing.assert_array_equal(y, _dsp.mount_filter_bilinear(x, 1e-3, 450.0, 0.2))
