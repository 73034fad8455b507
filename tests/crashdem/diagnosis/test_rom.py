"""Reduced-order impact model: analytic limits, convergence order, terms checked alone."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from crashdem.diagnosis import _dsp
from crashdem.diagnosis.rom import RomParams, RomSettings, RomSimulator, restitution_to_zeta, run_raw

RAW = dict(sample_rate=1000.0, cfc=None)


@given(st.floats(min_value=1e-3, max_value=1.0))
@settings(max_examples=60, deadline=None)
def test_restitution_zeta_inverse(e):
    """Oracle: free response of a linear spring-dashpot, e = exp(-zeta pi / sqrt(1 - zeta^2))."""
    z = restitution_to_zeta(e)
    assert 0.0 <= z < 1.0
    assert math.exp(-z * math.pi / math.sqrt(1.0 - z * z)) == pytest.approx(e, rel=1e-12)


def test_poncelet_drag_limit_matches_closed_form():
    """Oracle: with only the inertial drag (rigid-plastic soil, no gravity, no floor),
    m v dv/dz = -C rho pi (2 R z - z^2) v^2 integrates to
    v = v0 exp(-(C rho pi / m) (R z^2 - z^3 / 3)) for z <= R. The scheme is first order, so the
    error must halve with dt (observed order > 0.9) and be below 1e-4 at dt = 1 us."""
    q = RomParams(surface_strength=0.0, strength_gradient=0.0, soil_modulus=1e11,
                  floor_stiffening=0.0, wave_reflection=0.0, gravity=0.0)
    errs = []
    for dt in (4e-6, 2e-6, 1e-6):
        t, a, v, d = run_raw(q, RomSettings(dt=dt, t_end=0.02, **RAW))
        m = d < q.radius
        k = q.drag_coefficient * q.density * math.pi / q.mass
        va = q.v0 * np.exp(-k * (q.radius * d[m] ** 2 - d[m] ** 3 / 3.0))
        errs.append(float(np.max(np.abs(-v[m] / va - 1.0))))
    errs = np.array(errs)
    rates = np.log2(errs[:-1] / errs[1:])
    assert (rates > 0.9).all(), rates
    assert errs[-1] < 1e-4


def test_symplectic_rom_converges_first_order_to_midpoint_truth():
    """Oracle: observed convergence order of the maximum penetration of the full baseline (all
    terms on) towards the midpoint-RK2 solution at dt = 1 us; semi-implicit Euler with a return
    mapping is first order (rates > 0.8)."""
    p = RomParams()

    def depth(dt, method):
        return run_raw(p, RomSettings(dt=dt, t_end=0.06, method=method, **RAW))[3].max()

    ref = depth(1e-6, "midpoint")
    errs = np.array([abs(depth(dt, "symplectic") - ref) for dt in (4e-5, 2e-5, 1e-5)])
    rates = np.log2(errs[:-1] / errs[1:])
    assert (rates > 0.8).all(), rates


def test_crush_plateau_equals_crush_strength_over_body_mass():
    """Oracle: while the nose crushes, the crush element carries exactly F_c, so the body's
    specific force is F_c / (m (1 - nose fraction)); checked on the raw (unfiltered) output."""
    p = RomParams(crush_strength=2.0e5, crush_stroke=0.15)
    t, a, v, d = run_raw(p, RomSettings(dt=2e-5, t_end=0.06, **RAW))
    plateau = p.crush_strength / (p.mass * (1.0 - p.nose_mass_fraction))
    assert np.max(a[t < 0.012]) == pytest.approx(plateau, rel=1e-9)


@pytest.mark.parametrize("fn, zeta", [(50.0, 0.05), (120.0, 0.2)])
def test_mount_filters_resonant_gain(fn, zeta):
    """Oracle: base-excitation transmissibility at resonance |H(fn)| = sqrt(1 + (2 zeta)^2) /
    (2 zeta). Tustin pre-warped at fn is exact there (tolerance 1 %: finite record, steady-state
    fit); the first-order hold within 2 % at 50 kHz (its error is O((2 pi fn dt)^2) < 1e-3)."""
    dt = 2e-5
    t = np.arange(0.0, 40.0 / fn, dt)
    x = np.sin(2 * math.pi * fn * t)
    gain = math.sqrt(1 + (2 * zeta) ** 2) / (2 * zeta)
    for f in (_dsp.mount_filter_bilinear, _dsp.mount_filter_exact):
        y = f(x, dt, fn, zeta)
        tail = t > 30.0 / fn  # transient decays as exp(-zeta wn t): < 1e-4 after 30 periods at zeta 0.05
        amp = math.sqrt(2.0 * np.mean(y[tail] ** 2))
        assert amp == pytest.approx(gain, rel=0.02 if f is _dsp.mount_filter_exact else 0.01)


@pytest.mark.parametrize("fn, zeta", [(50.0, 0.05), (120.0, 0.2)])
def test_lowpass_form_resonant_gain(fn, zeta):
    """Oracle: seismic-transducer low-pass wn^2/(s^2 + 2 zeta wn s + wn^2) at resonance has
    |H(fn)| = 1/(2 zeta) (the transmissibility's damper term removed: ``form = 0``)."""
    dt = 2e-5
    t = np.arange(0.0, 40.0 / fn, dt)
    x = np.sin(2 * math.pi * fn * t)
    for f in (_dsp.mount_filter_bilinear, _dsp.mount_filter_exact):
        y = f(x, dt, fn, zeta, 0.0)
        tail = t > 30.0 / fn
        amp = math.sqrt(2.0 * np.mean(y[tail] ** 2))
        assert amp == pytest.approx(1.0 / (2.0 * zeta), rel=0.02 if f is _dsp.mount_filter_exact else 0.01)


def test_mount_design_is_made_once_and_is_the_fresh_design():
    """The screening fits filter thousands of model runs through one mount: its (b, a) and
    steady state are designed once per (dt, fn, zeta, form) (``_dsp._mount_design``), read-only,
    and the filtered record equals, bit for bit, the one of a design made afresh (scipy's
    ``bilinear`` and ``lfilter_zi``), from rest (first sample 0) and from a steady first
    sample."""
    from scipy import signal as sps

    dt, fn, zeta = 1.0 / 12500.0, 173.2, 0.31
    rng = np.random.default_rng(3)
    x = 9.81 + rng.normal(size=800)
    _dsp._mount_design.cache_clear()
    for form in (1.0, 0.0):
        wp = 2.0 / dt * math.tan(math.pi * fn * dt)
        b, a = sps.bilinear(_dsp._numerator(form, zeta, wp), [1.0, 2.0 * zeta * wp, wp * wp],
                            fs=1.0 / dt)
        fresh = sps.lfilter(b, a, x, zi=sps.lfilter_zi(b, a) * x[0])[0]
        for _ in range(3):
            assert np.array_equal(_dsp.mount_filter_bilinear(x, dt, fn, zeta, form), fresh)
        x0 = np.concatenate([[0.0], x[1:]])
        assert np.array_equal(_dsp.mount_filter_bilinear(x0, dt, fn, zeta, form),
                              sps.lfilter(b, a, x0))
    info = _dsp._mount_design.cache_info()
    assert (info.misses, info.hits) == (2, 6)
    b, _, _ = _dsp._mount_design(dt, fn, zeta, 1.0)
    with pytest.raises(ValueError, match="read-only"):
        b[0] = 1.0


@pytest.mark.parametrize("model, form", [("mount", 1.0), ("lowpass", 0.0)])
def test_rom_mount_forms_equal_the_run_sensor_models(model, form):
    """Oracle: two independent exact discretisations of the same transfer function -- the
    diagnosis's first-order-hold filter (scipy ``cont2discrete``) and the run's
    ``MountDynamics.apply`` (matrix exponential of the augmented system) -- agree to round-off
    on a piecewise-linear input; the Tustin filter of the screening model within 1 % of the
    peak response at 12.5 kHz."""
    from crashdem.sensors import MountDynamics
    from crashdem.signal import Signal

    fs = 12500.0
    t = np.arange(0.0, 0.2, 1.0 / fs)
    x = np.where(t > 0.01, 100.0 * np.sin(2 * math.pi * 30.0 * (t - 0.01))
                 * np.exp(-((t - 0.05) ** 2) / 1e-3), 0.0)
    y_run = MountDynamics(55.0, 0.12, model).apply(Signal("a", t, x, "m/s^2")).data
    y_exact = _dsp.mount_filter_exact(x, 1.0 / fs, 55.0, 0.12, form)
    y_tustin = _dsp.mount_filter_bilinear(x, 1.0 / fs, 55.0, 0.12, form)
    assert np.max(np.abs(y_exact - y_run)) < 1e-9 * np.max(np.abs(y_run))
    assert np.max(np.abs(y_tustin - y_run)) < 0.01 * np.max(np.abs(y_run))
    # the two models differ (by the damper term) by more than the discretisation error
    other = MountDynamics(55.0, 0.12, "lowpass" if model == "mount" else "mount")
    assert np.max(np.abs(other.apply(Signal("a", t, x, "m/s^2")).data - y_run)) > \
        0.02 * np.max(np.abs(y_run))


def test_parameter_errors_name_field_value_and_range():
    with pytest.raises(ValueError, match=r"RomParams\.soil_modulus=-3.*must be in \(0, 1e\+11\] \[Pa\]"):
        RomParams(soil_modulus=-3e7)
    with pytest.raises(ValueError, match=r"RomParams\.restitution=0.*\(0, 1\]"):
        RomParams(restitution=0.0)
    with pytest.raises(ValueError, match=r"RomParams\.mount_form=2.*must be in \[0, 1\]"):
        RomParams(mount_form=2.0)
    with pytest.raises(ValueError, match="unknown parameter 'cohesionn'"):
        RomParams().with_values({"cohesionn": 1.0})


def test_simulator_interface_and_free_fall_prefix():
    """Oracle: before contact the body is in free fall: specific force 0 and velocity
    -(v0 + g t) (kinematics); the simulator counts its calls."""
    sim = RomSimulator(settings=RomSettings(t_pre=0.1))
    out = sim({"strength_scale": 1.1})
    assert sim.calls == 1 and set(out) >= {"accel_z", "velocity_z"}
    v = out["velocity_z"]
    # clear of the record start (filter start-up, 10 ms padding) and of the CFC 60 filter's
    # backward spread of the impact kink (the 4-pole response has decayed below 1e-6 at 30 ms)
    pre = (v.t > -0.08) & (v.t < -0.03)
    expected = -(16.4 + 9.81 * v.t[pre])
    assert np.max(np.abs(v.data[pre] - expected)) < 1e-6 * 16.4
