"""Tests of crashdem.sensors: rigid-body kinematics of virtual sensors, acquisition, load cells."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from crashdem.sensors import (
    PITCH_AXIS,
    Accelerometer,
    BodyForce,
    BodyState,
    BoundaryContacts,
    Gyroscope,
    LoadCell,
    MountDynamics,
    PitchAngle,
    PointKinematics,
    SensorSet,
    integrate_signal,
    j211_axis,
    pitch_from_rotation,
)
from crashdem.signal import G0, Signal

GRAV = np.array([0.0, 0.0, -9.81])
#: floating-point tolerance for closed-form kinematics evaluated with O(10) flops on O(1e3)
#: magnitudes: 1e3 * 1e-16 * a few ops -> 1e-12 relative; 1e-9 absolute leaves 1000x margin
FP_ABS = 1e-9
FS = 12500.0
T = 1.0 / FS


def rot(axis, angle: float) -> np.ndarray:
    """Rodrigues rotation matrix about a unit axis (independent of the code under test)."""
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(angle) * kx + (1 - math.cos(angle)) * kx @ kx


def run(sensors, states_fn, t_grid, sampling="linear", contacts_fn=None, t0=0.0,
        gravity=GRAV, fs=FS):
    ss = SensorSet(sensors, fs=fs, t0=t0, gravity=gravity, sampling=sampling)
    for t in t_grid:
        ss.record(t, states_fn(t), contacts_fn(t) if contacts_fn else None)
    return ss, ss.signals()


# ------------------------------------------------------------------------------ accelerometers
def test_free_fall_reads_zero_specific_force():
    """Oracle: equivalence principle -- a rigid body in free fall (a = g, alpha = 0, any
    constant omega and attitude) has zero specific force at the CG; off the CG only the
    centripetal term remains, which is zero for omega = 0."""
    r0 = rot((1, 2, 3), 0.7)
    sensors = [Accelerometer(name=f"a{i}", body="b", position=p, axis=ax)
               for i, (p, ax) in enumerate([((0, 0, 0), (1, 0, 0)), ((0.3, -0.2, 0.1), (0, 0, 1)),
                                            ((-1, 0.5, 0.2), (1, 1, 1))])]

    def states(t):
        return {"b": BodyState(position=GRAV * t * t / 2, rotation=r0, velocity=GRAV * t,
                               acceleration=GRAV)}

    _, sig = run(sensors, states, np.arange(0, 0.01, 3.7e-5))
    for s in sig.values():
        assert s.t.size > 100
        assert np.max(np.abs(s.data)) < FP_ABS


def test_at_rest_reads_plus_one_g_up_and_j211_z_reads_minus_one_g():
    """Oracle: a body at rest on the ground has specific force -g, i.e. +|g| along the upward
    body z axis, |g| cos(tilt) on a tilted body, and -|g| along J211 z (down)."""
    tilt = 0.3
    sensors = [Accelerometer(name="up", body="b", axis=(0, 0, 1)),
               Accelerometer(name="j211z", body="b", axis=j211_axis("z")),
               Accelerometer(name="tilted", body="c", axis=(0, 0, 1), position=(1, 0, 0))]

    def states(t):
        return {"b": BodyState(position=(0, 0, 0), rotation=np.eye(3)),
                "c": BodyState(position=(0, 0, 0), rotation=rot((0, 1, 0), tilt))}

    _, sig = run(sensors, states, np.arange(0, 0.005, 2.3e-5), gravity=(0, 0, -G0))
    assert np.allclose(sig["up"].data, G0, atol=FP_ABS, rtol=0)
    assert np.allclose(sig["up"].in_g().data, 1.0, atol=FP_ABS, rtol=0)
    assert np.allclose(sig["j211z"].data, -G0, atol=FP_ABS, rtol=0)
    assert np.allclose(sig["tilted"].data, G0 * math.cos(tilt), atol=FP_ABS, rtol=0)


def test_spinning_body_centripetal_and_tangential_with_interpolation_bound():
    """Oracle: analytic rigid-body kinematics for a spin-up about z, omega = alpha t,
    psi = alpha t^2/2: at r along body x the specific force is -omega^2 r (radial, outward axis)
    and +alpha r (tangential, body y). Linear point sampling between DEM instants has the
    interpolation error bound dt^2/8 max|y''| = dt^2/8 * 2 alpha^2 r (radial channel)."""
    alpha, r, dt = 400.0, 0.8, 3.3e-5
    sensors = [Accelerometer(name="radial", body="b", position=(r, 0, 0), axis=(1, 0, 0)),
               Accelerometer(name="inward", body="b", position=(r, 0, 0), axis=(-1, 0, 0)),
               Accelerometer(name="tangential", body="b", position=(r, 0, 0), axis=(0, 1, 0)),
               Accelerometer(name="cg", body="b", axis=(1, 0, 0))]
    w_hat = np.array([0.0, 0.0, 1.0])

    def states(t):
        return {"b": BodyState(position=(0, 0, 0), rotation=rot(w_hat, alpha * t * t / 2),
                               angular_velocity=alpha * t * w_hat,
                               angular_acceleration=alpha * w_hat)}

    _, sig = run(sensors, states, np.arange(0, 0.02, dt), gravity=(0, 0, 0))
    t = sig["radial"].t
    bound = dt ** 2 / 8 * 2 * alpha ** 2 * r + FP_ABS
    assert np.max(np.abs(sig["radial"].data + (alpha * t) ** 2 * r)) <= bound
    assert np.max(np.abs(sig["inward"].data - (alpha * t) ** 2 * r)) <= bound
    assert np.allclose(sig["tangential"].data, alpha * r, atol=FP_ABS, rtol=0)
    assert np.max(np.abs(sig["cg"].data)) < FP_ABS
    # the bound is not vacuous: the signal is much larger than it
    assert np.max(np.abs(sig["radial"].data)) > 1e4 * bound


@settings(max_examples=25, deadline=None)
@given(st.lists(st.floats(-2, 2), min_size=12, max_size=12))
def test_specific_force_matches_finite_difference_of_mount_trajectory(c):
    """Oracle: independent implementation -- the mount point's world trajectory
    x_P(t) = x(t) + R(t) r is differentiated twice by central differences (error O(h^2)),
    omega and alpha from R' R^T; f = R^T (x_P'' - g) . axis must equal the sensor output."""
    c = np.asarray(c)
    r_b, axis = c[0:3], c[3:6] + np.array([0.0, 0.0, 2.5])  # axis never zero
    w0, w1 = c[6:9], c[9:12]

    def rot_t(t):  # two non-commuting rotations: omega and alpha are not parallel
        return rot(w0 + (1e-3, 0, 0), t * np.linalg.norm(w0 + (1e-3, 0, 0))) @ \
            rot((0.3, 1, 0.2), t * t * (1 + np.linalg.norm(w1)))

    def x_t(t):
        return np.array([math.sin(t), t ** 3, math.cos(2 * t)])

    t, h = 0.37, 1e-4
    rs = [rot_t(t + k * h) for k in (-2, -1, 0, 1, 2)]
    xs = [x_t(t + k * h) + rs[i] @ r_b for i, k in enumerate((-2, -1, 0, 1, 2))]
    a_p = (xs[3] - 2 * xs[2] + xs[1]) / h ** 2

    def omega(k):  # world angular velocity from R' R^T (central difference)
        rd = (rs[k + 1] - rs[k - 1]) / (2 * h)
        m = rd @ rs[k].T
        return np.array([m[2, 1], m[0, 2], m[1, 0]])

    w = omega(2)
    alpha_w = (omega(3) - omega(1)) / (2 * h)
    a_cg = (x_t(t + h) - 2 * x_t(t) + x_t(t - h)) / h ** 2
    expected = (rs[2].T @ (a_p - GRAV)) @ (axis / np.linalg.norm(axis))
    acc = Accelerometer(name="a", body="b", position=tuple(r_b), axis=tuple(axis))
    ss = SensorSet([acc], sampling="linear", t0=t, gravity=GRAV)
    ss.record(t, {"b": BodyState(position=x_t(t), rotation=rs[2], angular_velocity=w,
                                 acceleration=a_cg, angular_acceleration=alpha_w)})
    got = ss.signals()["a"].data[0]
    # finite differences with h = 1e-4 on O(10) derivatives: truncation ~h^2 * 1e3 = 1e-5,
    # round-off ~1e-16 * 10 / h^2 = 1e-7 (second difference) -> 1e-4 abs leaves margin
    assert abs(got - expected) < 1e-4 * max(1.0, abs(expected))


def test_full_scale_clipping_and_failure_flag():
    """Oracle: analytic ramp a(t) = k t along body x (gravity along z does not project):
    samples whose support lies below the full scale FS equal k t, none exceeds FS and the
    plateau reads exactly FS; with failure_factor 1.5 the channel fails at the first DEM instant
    past 1.5 FS / k, and every sample whose support extends past the last DEM instant before
    it is NaN (the valid ones equal the clipped channel's)."""
    fs_range = 250 * G0
    k = 400 * G0 / 0.01  # ramps to 400 g in 10 ms
    dt = 2e-5
    sensors = [Accelerometer(name="clip", body="b", axis=(1, 0, 0), full_scale=fs_range),
               Accelerometer(name="fail", body="b", axis=(1, 0, 0), full_scale=fs_range,
                             failure_factor=1.5)]

    def states(t):
        return {"b": BodyState(position=(0, 0, 0), rotation=np.eye(3),
                               acceleration=(k * t, 0, 0))}

    for mode in ("linear", "box"):
        _, sig = run(sensors, states, np.arange(0, 0.012, dt), sampling=mode)
        clip = sig["clip"]
        assert np.max(clip.data) <= fs_range
        assert np.any(clip.data == fs_range)
        below = clip.t + T < fs_range / k  # windows entirely below the full scale
        assert np.allclose(clip.data[below], k * clip.t[below], rtol=1e-9, atol=FP_ABS)
        fail = sig["fail"]
        t_fail = fail.meta["failed_at"]
        assert 1.5 * fs_range / k <= t_fail <= 1.5 * fs_range / k + dt + 1e-12
        assert fail.meta["valid_until"] == pytest.approx(t_fail - dt, abs=1e-12)
        support_end = fail.t + (T / 2 if mode == "box" else 0.0)
        valid = support_end <= fail.meta["valid_until"]
        assert np.all(np.isfinite(fail.data[valid])) and np.all(np.isnan(fail.data[~valid]))
        assert np.array_equal(fail.data[valid], clip.data[valid])


# ------------------------------------------------------------------------------ gyro and pitch
def test_gyro_and_pitch_angle_from_prescribed_pitch_motion():
    """Oracle: prescribed planar pitch theta(t) = th0 + A sin(2 pi f t) about the body pitch axis
    (nose-up positive): the gyro reads theta', the exact pitch reads theta (to round-off) and
    the DEM-rate trapezoidal integral reads theta within the trapezoid error bound
    t dt^2/12 max|theta'''|; the nose's world z has the sign of theta (nose-up positive)."""
    th0, amp, f, dt = 0.05, 0.3, 20.0, 2.5e-5
    wf = 2 * math.pi * f
    pitch_axis = np.array(PITCH_AXIS)

    def theta(t):
        return th0 + amp * math.sin(wf * t)

    def states(t):
        rm = rot(pitch_axis, theta(t))  # rotation about the body pitch axis = world axis here
        return {"b": BodyState(position=(0, 0, 0), rotation=rm,
                               angular_velocity=amp * wf * math.cos(wf * t) * pitch_axis,
                               angular_acceleration=-amp * wf ** 2 * math.sin(wf * t) * pitch_axis)}

    sensors = [Gyroscope(name="q", body="b"), PitchAngle(name="exact", body="b"),
               PitchAngle(name="integ", body="b", method="integrated"),
               PitchAngle(name="integ0", body="b", method="integrated", initial="zero")]
    t_end = 0.1
    _, sig = run(sensors, states, np.arange(0, t_end, dt))
    t = sig["q"].t
    th = th0 + amp * np.sin(wf * t)
    # linear interpolation between DEM instants: dt^2/8 max|y''|
    assert np.max(np.abs(sig["q"].data - amp * wf * np.cos(wf * t))) <= \
        dt ** 2 / 8 * amp * wf ** 3 + FP_ABS
    assert np.max(np.abs(sig["exact"].data - th)) <= dt ** 2 / 8 * amp * wf ** 2 + FP_ABS
    trap = t_end * dt ** 2 / 12 * amp * wf ** 3 + dt ** 2 / 8 * amp * wf ** 2 + FP_ABS
    assert np.max(np.abs(sig["integ"].data - th)) <= trap
    assert np.max(np.abs(sig["integ0"].data - (th - th0))) <= trap
    # nose-up convention: positive pitch lifts the nose (body x) above the horizon
    assert rot(pitch_axis, 0.2)[2, 0] > 0 and pitch_from_rotation(rot(pitch_axis, 0.2)) > 0
    # lab procedure: trapezoidal integral of the sampled gyro matches the exact pitch to the
    # trapezoid bound at the sample interval T
    lab = integrate_signal(sig["q"], initial=th[0])
    assert lab.unit == "rad"
    assert np.max(np.abs(lab.data - th)) <= t_end * T ** 2 / 12 * amp * wf ** 3 + trap


def test_exact_pitch_is_euler_pitch_under_yaw_and_roll_and_integrated_differs_in_3d():
    """Oracle: analytic z-y-x Tait-Bryan decomposition R = Rz(psi) Ry(-theta) Rx(phi)
    (crashdem axes; -theta about y = nose-up theta): pitch_from_rotation returns theta for any
    yaw and roll. With simultaneous roll the integrated body pitch rate is not the Euler pitch
    (they differ by more than the integration error), as documented."""
    for psi, th, phi in [(0.0, 0.4, 0.0), (1.2, -0.3, 0.0), (-2.5, 0.7, 0.9), (0.3, 1.2, -2.0)]:
        rm = rot((0, 0, 1), psi) @ rot((0, 1, 0), -th) @ rot((1, 0, 0), phi)
        assert pitch_from_rotation(rm) == pytest.approx(th, abs=1e-12)
    # roll rate p about body x while pitching: theta_dot = q cos(phi) - r sin(phi)
    p_rate, q_rate, dt = 10.0, 2.0, 1e-4

    def states(t):
        rm = rot((0, 1, 0), -q_rate * t) @ rot((1, 0, 0), p_rate * t)
        w = q_rate * np.array([0, -1.0, 0]) + p_rate * (rot((0, 1, 0), -q_rate * t) @ [1, 0, 0])
        return {"b": BodyState(position=(0, 0, 0), rotation=rm, angular_velocity=w)}

    sensors = [PitchAngle(name="exact", body="b"),
               PitchAngle(name="integ", body="b", method="integrated")]
    _, sig = run(sensors, states, np.arange(0, 0.2, dt))
    t = sig["exact"].t
    assert np.allclose(sig["exact"].data, q_rate * t, atol=1e-6)
    assert np.max(np.abs(sig["integ"].data - sig["exact"].data)) > 0.05


# ------------------------------------------------------------------------------ acquisition
@pytest.mark.parametrize("mode", ["linear", "box"])
@pytest.mark.parametrize("dt", [2.3e-5, 1.7e-4, 2.3e-4])
def test_exact_sampling_instants(mode, dt):
    """Oracle: definition of the acquisition grid -- samples at exactly t0 + k/fs, consecutive
    k, covering every instant whose support ([t_k] or [t_k - T/2, t_k + T/2]) lies inside the
    recorded DEM time range, for DEM steps finer and coarser than T."""
    t0, t_start, n = 0.00013, 0.0004, 400
    t_dem = t_start + dt * np.arange(n)
    ss, sig = run([Gyroscope(name="q", body="b")],
                  lambda t: {"b": BodyState(position=(0, 0, 0), rotation=np.eye(3))},
                  t_dem, sampling=mode, t0=t0)
    t = sig["q"].t
    half = T / 2 if mode == "box" else 0.0
    k0 = math.ceil((t_dem[0] + half - t0) * FS - 1e-9)
    k1 = math.floor((t_dem[-1] - half - t0) * FS + 1e-9)
    assert np.array_equal(t, t0 + np.arange(k0, k1 + 1) / FS)
    assert t[0] - half >= t_dem[0] and t[-1] + half <= t_dem[-1]
    assert ss.n_samples == t.size


@settings(max_examples=40, deadline=None)
@given(fs=st.floats(1e3, 5e4), dt=st.floats(1e-6, 5e-4), t0=st.floats(-1e-3, 1e-3),
       t_start=st.floats(0.0, 2e-3), mode=st.sampled_from(["linear", "box"]))
@example(fs=12500.0, dt=8e-5, t0=0.0, t_start=0.0, mode="linear")  # DEM steps on the grid
@example(fs=12500.0, dt=8e-5, t0=0.0, t_start=0.0, mode="box")
@example(fs=12500.0, dt=2.3e-4, t0=0.0, t_start=4e-5, mode="box")  # first instant on an edge
@example(fs=1e3, dt=1e-6, t0=0.0, t_start=0.0, mode="box")  # 1000 steps per sample
def test_sampling_grid_property(fs, dt, t0, t_start, mode):
    """Oracle: definition of the acquisition grid, over the valid range (Hypothesis, with
    pinned edge cases: steps on the grid, a first instant on a window edge, T/dt = 1000):
    consecutive k, t = t0 + k/fs exactly, every sample's support inside the recorded range,
    and no instant whose support fits is missed; a constant channel reads the constant."""
    n = int(min(300, 0.01 / dt)) + 2
    t_dem = t_start + dt * np.arange(n)
    ss = SensorSet([Gyroscope(name="q", body="b")], fs=fs, t0=t0, sampling=mode)
    state = {"b": BodyState(position=(0, 0, 0), rotation=np.eye(3),
                            angular_velocity=(0, -0.7, 0))}
    for t in t_dem:
        ss.record(t, state)
    s = ss.signals()["q"]
    half = 0.5 / fs if mode == "box" else 0.0
    k = np.round((s.t - t0) * fs).astype(int)
    assert np.array_equal(s.t, t0 + k / fs)
    if s.t.size:
        assert np.all(np.diff(k) == 1)
        assert s.t[0] - half >= t_dem[0] - 1e-15 and s.t[-1] + half <= t_dem[-1] + 1e-15
    # no instant whose support [t_k - h/fs, t_k + h/fs] fits in the recorded range is missed
    # (support start/end written as the sampler's window edges t0 + (k -+ 1/2)/fs)
    h = 0.5 if mode == "box" else 0.0
    k_first = math.floor((t_dem[0] - t0) * fs) - 1
    k_last = math.ceil((t_dem[-1] - t0) * fs) + 1
    fits = [kk for kk in range(k_first, k_last + 1)
            if t0 + (kk - h) / fs >= t_dem[0] and t0 + (kk + h) / fs <= t_dem[-1]]
    # instants within round-off of the range edges may go either way
    tol = 1e-12
    certain = [kk for kk in fits if t0 + (kk - h) / fs > t_dem[0] + tol
               and t0 + (kk + h) / fs < t_dem[-1] - tol]
    assert set(certain) <= set(k.tolist())
    assert set(k.tolist()) <= set(fits) | {kk for kk in range(k_first, k_last + 1)
                                            if abs(t0 + (kk - h) / fs - t_dem[0]) <= tol
                                            or abs(t0 + (kk + h) / fs - t_dem[-1]) <= tol}
    assert np.allclose(s.data, 0.7, rtol=1e-12, atol=0)


@pytest.mark.parametrize("mode", ["linear", "box"])
def test_sampling_error_bound_and_second_order_convergence(mode):
    """Oracle: analytic motion a(t) = A sin(w t) along x. 'linear' must match A sin(w t_k)
    within dt^2/8 A w^2; 'box' must match the exact window mean
    A sin(w t_k) sin(w T/2)/(w T/2) within dt^2/12 (1 + 2 dt/T) A w^2 (trapezoid rule over the
    whole and partial steps of the window). Halving dt must reduce the error with
    an observed order > 1.8 (both rules are second order)."""
    amp, f = 100.0, 1000.0
    w = 2 * math.pi * f
    errs = []
    for dt in (4e-5, 2e-5, 1e-5, 5e-6):
        # DEM grid offset by a fixed fraction of dt, so that the samples sit at the same
        # relative position inside their step for every dt (a clean dt^2 sequence)
        t_dem = (np.arange(int(0.004 / dt)) + 0.37) * dt

        def states(t):
            return {"b": BodyState(position=(0, 0, 0), rotation=np.eye(3),
                                   acceleration=(amp * math.sin(w * t), 0, 0))}

        _, sig = run([Accelerometer(name="a", body="b")], states, t_dem, sampling=mode)
        s = sig["a"]
        if mode == "linear":
            exact = amp * np.sin(w * s.t)
            bound = dt ** 2 / 8 * amp * w ** 2
        else:
            x = w * T / 2
            exact = amp * np.sin(w * s.t) * math.sin(x) / x
            bound = dt ** 2 / 12 * (1 + 2 * dt / T) * amp * w ** 2
        err = np.max(np.abs(s.data - exact))
        assert err <= bound + FP_ABS
        errs.append(err)
    errs = np.array(errs)
    rates = np.log2(errs[:-1] / errs[1:])
    assert (rates > 1.8).all(), rates


def test_box_sampling_suppresses_aliasing_of_content_above_nyquist():
    """Oracle: analytic transfer functions -- a 12.4 kHz sine sampled at 12.5 kHz aliases to
    100 Hz at full amplitude with point sampling, while the box window mean passes it with
    |sinc(f/fs)| = 0.0081 (plus the DEM reconstruction bound dt^2/12 (1 + 2 dt/T) w^2)."""
    f, dt = 12400.0, 2e-6
    w = 2 * math.pi * f
    t_dem = (np.arange(5000) + 0.5) * dt
    amp = {}
    for mode in ("linear", "box"):
        _, sig = run([Accelerometer(name="a", body="b")],
                     lambda t: {"b": BodyState(position=(0, 0, 0), rotation=np.eye(3),
                                               acceleration=(math.sin(w * t), 0, 0))},
                     t_dem, sampling=mode)
        amp[mode] = np.max(np.abs(sig["a"].data))
    gain = abs(math.sin(math.pi * f / FS) / (math.pi * f / FS))
    recon = dt ** 2 / 12 * (1 + 2 * dt / T) * w ** 2
    assert amp["box"] <= gain + recon
    # the alias is a 100 Hz sine seen 125 times per period over one period: its sampled peak
    # is >= cos(pi/125) = 0.9997, less the interpolation bound dt^2/8 w^2 = 0.003
    assert amp["linear"] >= math.cos(math.pi / 125) - dt ** 2 / 8 * w ** 2


def test_box_sampling_conserves_the_impulse_of_a_step_force():
    """Oracle: conservation -- with box sampling the sum of samples times T equals the
    integral of the piecewise-linear DEM reconstruction over the covered windows, i.e. the
    velocity change (impulse / m); checked on a noisy leapfrog-like acceleration history."""
    rng = np.random.default_rng(3)
    dt = 1.1e-5
    t_dem = np.arange(0, 0.01, dt)
    acc = 50 * rng.standard_normal(t_dem.size) + 200 * np.sin(300 * t_dem)
    lookup = dict(zip(t_dem.tolist(), acc.tolist()))
    _, sig = run([Accelerometer(name="a", body="b")],
                 lambda t: {"b": BodyState(position=(0, 0, 0), rotation=np.eye(3),
                                           acceleration=(lookup[t], 0, 0))},
                 t_dem, sampling="box")
    s = sig["a"]
    lo, hi = s.t[0] - T / 2, s.t[-1] + T / 2
    fine = np.union1d(t_dem[(t_dem > lo) & (t_dem < hi)], [lo, hi])
    integral = np.trapezoid(np.interp(fine, t_dem, acc), fine)
    # round-off of a sum of ~1000 terms of magnitude ~1e-2 m/s
    assert s.data.sum() * T == pytest.approx(integral, rel=1e-10, abs=1e-12)
    # and the noise is reduced: the window mean of the piecewise-linear reconstruction of white
    # noise over N = T/dt = 7.3 steps has std ~ sqrt(2/(3N)) ~ 0.30 of the DEM-rate std (50);
    # 0.5 leaves margin for the sampling spread of a 125-sample std estimate (~6 %)
    assert np.std(s.data - 200 * np.sin(300 * s.t)) < 0.5 * 50


def test_mount_dynamics_matches_analytic_ramp_response():
    """Oracle: analytic response of y'' + 2 zeta wn y' + wn^2 y = wn^2 u to a ramp u = c t from
    rest: y = c (t - 2 zeta/wn + e^{-zeta wn t} (2 zeta/wn cos wd t + (2 zeta^2 - 1)/wd sin wd t)).
    The first-order-hold discretisation is exact for piecewise-linear input, so the DEM-rate
    value matches to round-off for any step; sampling adds only the linear-interpolation error."""
    fn, zeta, c = 400.0, 0.05, 5000.0
    wn = 2 * math.pi * fn
    wd = wn * math.sqrt(1 - zeta ** 2)
    dyn = MountDynamics(natural_frequency=fn, damping_ratio=zeta)

    def y_exact(t):
        return c * (t - 2 * zeta / wn + np.exp(-zeta * wn * t) * (
            2 * zeta / wn * np.cos(wd * t) + (2 * zeta ** 2 - 1) / wd * np.sin(wd * t)))

    # DEM instants on the sample grid (t_k = k/fs): no interpolation error enters
    t_dem = np.arange(250) / FS
    _, sig = run([Accelerometer(name="a", body="b", dynamics=dyn),
                  Accelerometer(name="ideal", body="b")],
                 lambda t: {"b": BodyState(position=(0, 0, 0), rotation=np.eye(3),
                                           acceleration=(c * t, 0, 0))},
                 t_dem, sampling="linear")
    s = sig["a"]
    # FOH is exact; residual is round-off of expm and of the recursion over 250 steps
    assert np.max(np.abs(s.data - y_exact(s.t))) < 1e-9 * c
    # the dynamics are active: the output lags the ramp by up to ~c 2 zeta/wn
    assert np.max(np.abs(s.data - sig["ideal"].data)) > 0.5 * c * 2 * zeta / wn


def test_mount_dynamics_apply_to_stored_signal_equals_dem_rate_model():
    """Oracle: analytic ramp response (as above) for MountDynamics.apply on a sampled ramp, and
    identity with the DEM-rate model when the DEM instants are the sample instants."""
    fn, zeta, c = 250.0, 0.1, 300.0
    dyn = MountDynamics(natural_frequency=fn, damping_ratio=zeta)
    wn = 2 * math.pi * fn
    wd = wn * math.sqrt(1 - zeta ** 2)
    t = np.arange(400) / FS
    out = dyn.apply(Signal("x", t, c * t, "m/s^2"))
    exact = c * (t - 2 * zeta / wn + np.exp(-zeta * wn * t) * (
        2 * zeta / wn * np.cos(wd * t) + (2 * zeta ** 2 - 1) / wd * np.sin(wd * t)))
    assert np.max(np.abs(out.data - exact)) < 1e-9 * c
    assert out.meta["dynamics"]["natural_frequency"] == fn
    _, sig = run([Accelerometer(name="a", body="b", dynamics=dyn)],
                 lambda tt: {"b": BodyState(position=(0, 0, 0), rotation=np.eye(3),
                                            acceleration=(c * math.sin(900 * tt), 0, 0))},
                 t, sampling="linear")
    ideal = Signal("a", sig["a"].t, c * np.sin(900 * sig["a"].t), "m/s^2")
    # same recursion on the same instants; differences are round-off of the input values
    assert np.allclose(dyn.apply(ideal).data, sig["a"].data, rtol=0, atol=1e-9 * c)


def test_mount_resonance_amplification_at_fn():
    """Oracle: steady-state gain of a second-order system driven at its natural frequency is
    1/(2 zeta) (analytic frequency response)."""
    fn, zeta = 500.0, 0.1
    wn = 2 * math.pi * fn
    _, sig = run([Accelerometer(name="a", body="b",
                                dynamics=MountDynamics(natural_frequency=fn,
                                                       damping_ratio=zeta))],
                 lambda t: {"b": BodyState(position=(0, 0, 0), rotation=np.eye(3),
                                           acceleration=(math.sin(wn * t), 0, 0))},
                 np.arange(0, 0.05, 2e-5), sampling="linear")
    s = sig["a"].window(0.03, 0.05)  # transient decays as exp(-zeta wn t): e^-9.4 by t = 0.03
    # sampling at 12.5 kHz (25 samples per period) sees the peak within 1 - cos(pi/25) = 0.8 %
    assert np.max(np.abs(s.data)) == pytest.approx(1 / (2 * zeta), rel=0.01)


def test_mount_model_transmissibility_gain_at_fn():
    """Oracle: the base-excitation transmissibility (2 zeta wn s + wn^2)/(s^2 + 2 zeta wn s +
    wn^2) of a resonant mount has |H(fn)| = sqrt(1 + (2 zeta)^2) / (2 zeta) (Thomson & Dahl 3.5),
    above the low-pass's 1/(2 zeta)."""
    fn, zeta = 500.0, 0.3
    wn = 2 * math.pi * fn
    _, sig = run([Accelerometer(name="a", body="b",
                                dynamics=MountDynamics(natural_frequency=fn, damping_ratio=zeta,
                                                       model="mount"))],
                 lambda t: {"b": BodyState(position=(0, 0, 0), rotation=np.eye(3),
                                           acceleration=(math.sin(wn * t), 0, 0))},
                 np.arange(0, 0.05, 2e-5), sampling="linear")
    s = sig["a"].window(0.03, 0.05)
    assert np.max(np.abs(s.data)) == pytest.approx(math.sqrt(1 + (2 * zeta) ** 2) / (2 * zeta),
                                                   rel=0.01)


def test_mount_model_must_be_known():
    with pytest.raises(ValueError, match=r"MountDynamics\.model='spring'.*\('lowpass', 'mount'\)"):
        MountDynamics(100.0, 0.1, "spring")


# ------------------------------------------------------------------------------ load cells
def test_load_cell_footprints_partition_a_force_field():
    """Oracle: partition -- eight rectangular cells tiling a 2 x 4 grid on the floor count every
    contact in the tiled region exactly once (points placed on shared edges included), so the
    sum of the readings equals the total normal force of the contacts inside the region;
    contacts outside or above the plane tolerance are ignored; pushing down reads positive."""
    rng = np.random.default_rng(7)
    a, b = 0.25, 0.5  # half sizes [m]
    cells = [LoadCell(name=f"c{i}{j}", boundary="floor", center=((2 * i - 1) * a, (2 * j - 3) * b,
                                                                    0.0),
                      half_size=(a, b), plane_tolerance=0.02)
             for i in range(2) for j in range(4)]
    n = 4000
    pts = np.column_stack([rng.uniform(-0.7, 0.7, n), rng.uniform(-2.2, 2.2, n),
                           rng.uniform(-0.01, 0.01, n)])
    pts[:200, 0] = 0.0  # exactly on the shared edge x = 0
    pts[200:400, 1] = rng.choice([-1.0, 0.0, 1.0], 200)  # exactly on shared edges in y
    pts[400:450, 2] = 0.05  # above the plane tolerance
    forces = np.column_stack([rng.normal(0, 10, n), rng.normal(0, 10, n),
                              -rng.uniform(0, 100, n)])
    counts = np.sum([c.inside(pts) for c in cells], axis=0)
    in_region = (pts[:, 0] >= -0.5) & (pts[:, 0] < 0.5) & (pts[:, 1] >= -2) & (pts[:, 1] < 2) & \
        (np.abs(pts[:, 2]) <= 0.02)
    assert np.array_equal(counts, in_region.astype(int))
    contacts = {"floor": BoundaryContacts(pts, forces)}
    _, sig = run(cells, lambda t: {}, [0.0, T, 2 * T], contacts_fn=lambda t: contacts)
    total = sum(s.data[0] for s in sig.values())
    assert total == pytest.approx(-forces[in_region, 2].sum(), rel=1e-12)
    assert all(s.data[0] > 0 for s in sig.values())


def test_load_cell_disc_on_tilted_plane():
    """Oracle: analytic geometry -- on a plane with normal n, a disc footprint of radius R
    collects exactly the contacts within R of its centre (in-plane distance), and reads the sum
    of -f.n over them (tangential components do not count)."""
    n_vec = np.array([0.0, 0.6, 0.8])
    u = np.array([1.0, 0.0, 0.0])
    v = np.cross(n_vec, u)
    c0 = np.array([0.2, -0.1, 0.3])
    cell = LoadCell(name="d", boundary="wall", center=tuple(c0), normal=tuple(n_vec), radius=0.1)
    rng = np.random.default_rng(1)
    pu, pv = rng.uniform(-0.2, 0.2, (2, 500))
    pts = c0 + np.outer(pu, u) + np.outer(pv, v)
    f = -np.outer(rng.uniform(1, 5, 500), n_vec) + np.outer(rng.normal(0, 3, 500), u)
    inside = pu ** 2 + pv ** 2 < 0.01
    _, sig = run([cell], lambda t: {}, [0.0, T],
                 contacts_fn=lambda t: {"wall": BoundaryContacts(pts, f)})
    assert sig["d"].data[0] == pytest.approx(-(f[inside] @ n_vec).sum(), rel=1e-12)
    # no contacts at all reads zero
    _, sig0 = run([cell], lambda t: {}, [0.0, T])
    assert sig0["d"].data[0] == 0.0


# ------------------------------------------------------------------------------ other channels
def test_point_kinematics_and_body_force():
    """Oracle: analytic kinematics of a body translating at constant velocity while spinning at
    constant rate about z: a point at r has position x + R r, velocity v + omega x R r, and the
    body force sensor returns the projection of the given force."""
    v0, om, r = np.array([1.0, -2.0, 0.5]), 3.0, np.array([0.4, 0.0, 0.1])

    def states(t):
        rm = rot((0, 0, 1), om * t)
        return {"b": BodyState(position=v0 * t, rotation=rm, velocity=v0,
                               angular_velocity=(0, 0, om), force=(10.0, 20.0, 30.0 + t),
                               torque=(0.0, 0.0, 5.0))}

    sensors = [PointKinematics(name="px", body="b", quantity="position", point=tuple(r),
                               axis=(1, 0, 0)),
               PointKinematics(name="dz", body="b", quantity="position", axis=(0, 0, 1),
                               relative=True),
               PointKinematics(name="vy", body="b", quantity="velocity", point=tuple(r),
                               axis=(0, 1, 0)),
               BodyForce(name="fz", body="b"),
               BodyForce(name="mz", body="b", quantity="torque")]
    _, sig = run(sensors, states, np.arange(0, 0.01, 1e-5))
    t = sig["px"].t
    assert np.allclose(sig["px"].data, v0[0] * t + r[0] * np.cos(om * t), atol=1e-8)
    assert np.allclose(sig["dz"].data, v0[2] * t, atol=1e-12)
    assert np.allclose(sig["vy"].data, v0[1] + om * r[0] * np.cos(om * t), atol=1e-8)
    assert np.allclose(sig["fz"].data, 30.0 + t, atol=1e-12)
    assert sig["fz"].unit == "N" and sig["mz"].unit == "N*m" and sig["vy"].unit == "m/s"


def test_drain_returns_each_sample_once_and_metadata():
    """Oracle: bookkeeping -- concatenated drains equal signals(); channel metadata carries unit,
    sample rate, position, direction, ISO code and CFC class."""
    acc = Accelerometer(name="rear_accel_x", body="b", position=(-2.0, 0, 0.1),
                        iso_code="10VEHC0000REACX0", cfc=60, full_scale=250 * G0)
    ss = SensorSet([acc, Gyroscope(name="q", body="b")])
    parts = []
    for i, t in enumerate(np.arange(0, 0.01, 3e-5)):
        ss.record(t, {"b": BodyState(position=(0, 0, 0), rotation=np.eye(3),
                                     acceleration=(math.sin(100 * t), 0, 0))})
        if i % 37 == 0:
            parts.append(ss.drain())
    parts.append(ss.drain())
    tt = np.concatenate([p["rear_accel_x"][0] for p in parts])
    dd = np.concatenate([p["rear_accel_x"][1] for p in parts])
    s = ss.signals()["rear_accel_x"]
    assert np.array_equal(tt, s.t) and np.array_equal(dd, s.data)
    m = s.meta
    assert (m["iso_code"], m["cfc_class"], m["sample_rate"], m["unit"]) == \
        ("10VEHC0000REACX0", 60.0, FS, "m/s^2")
    assert m["position"] == [-2.0, 0.0, 0.1] and m["direction"] == [1.0, 0.0, 0.0]
    assert s.cfc is None


@pytest.mark.parametrize("make, match", [
    (lambda: Accelerometer(name="a", body="b", full_scale=-1.0), "Accelerometer.full_scale=-1.0"),
    (lambda: Accelerometer(name="a", body="b", axis=(0, 0, 0)), "Accelerometer.axis"),
    (lambda: Accelerometer(name="a", body="b", failure_factor=2.0), "needs a finite full_scale"),
    (lambda: Accelerometer(name="a", body="b", iso_code="short"), "iso_code='short'"),
    (lambda: MountDynamics(natural_frequency=0.0, damping_ratio=0.1), "natural_frequency=0.0"),
    (lambda: MountDynamics(natural_frequency=1.0, damping_ratio=-0.1), "damping_ratio=-0.1"),
    (lambda: PitchAngle(name="p", body="b", method="euler"), "PitchAngle.method='euler'"),
    (lambda: LoadCell(name="l", boundary="f"), "exactly one of radius"),
    (lambda: LoadCell(name="l", boundary="f", radius=-1.0), "LoadCell.radius=-1.0"),
    (lambda: SensorSet([Gyroscope(name="q", body="b")], fs=0.0), "SensorSet.fs=0.0"),
    (lambda: SensorSet([Gyroscope(name="q", body="b")], sampling="zoh"), "sampling='zoh'"),
    (lambda: SensorSet([Gyroscope(name="q", body="b"), Gyroscope(name="q", body="c")]),
     "duplicate names"),
])
def test_invalid_parameters_name_field_and_range(make, match):
    """Oracle: the error contract -- messages name the field, the value and the allowed range."""
    with pytest.raises(ValueError, match=match.replace("(", r"\(").replace(")", r"\)")):
        make()


def test_record_rejects_non_increasing_time_and_missing_body():
    """Oracle: the input contract -- time must increase; a missing body is named."""
    ss = SensorSet([Gyroscope(name="q", body="b")])
    s = {"b": BodyState(position=(0, 0, 0), rotation=np.eye(3))}
    ss.record(0.0, s)
    with pytest.raises(ValueError, match="must be > previous"):
        ss.record(0.0, s)
    with pytest.raises(KeyError, match="body 'b' not in the recorded states"):
        ss.record(1e-5, {"c": s["b"]})


def test_sensor_set_from_scenario_and_body_mounts():
    """Oracle: the scenario contract -- sample rate, CFC, main-accelerometer full scale and the
    physics.sensor_dynamics switch are taken from the scenario; a lower-range mount keeps its
    own range; gyro mounts become gyroscopes; pitch and CG channels are added."""
    from crashdem import scenario as sc
    from crashdem.sensors import sensor_set_from_scenario

    # duck-typed stand-in with the fields of bodies.SensorMount (importing ``bodies`` from a
    # test under tests/ picks up the namespace package tests/bodies when tests/ is on sys.path)
    @dataclass(frozen=True)
    class SensorMount:
        name: str
        position: tuple
        axis: tuple
        kind: str
        full_scale: float

    mounts = [SensorMount("accel_x", (0, 0, 0.1), (1, 0, 0), "accelerometer", 200 * G0),
              SensorMount("accel_y", (0, 0, 0.1), (0, 1, 0), "accelerometer", 50 * G0),
              SensorMount("pitch_rate", (0.2, 0, 0), PITCH_AXIS, "gyro", 20.0)]
    scen = sc.loads("[instrumentation]\nsample_rate = 10000.0\naccel_full_scale_g = 250.0\n"
                    "[physics.sensor_dynamics]\nenabled = true\nnatural_frequency = 300.0\n"
                    "damping_ratio = 0.2\ncfc = 180.0\n")
    floor = LoadCell(name="floor_1", boundary="floor", radius=0.1)
    ss = sensor_set_from_scenario(scen, mounts, body="sphere", load_cells=[floor])
    info = ss.channel_info()
    assert ss.fs == 10000.0
    assert info["accel_x"]["full_scale"] == pytest.approx(250 * G0)
    assert info["accel_y"]["full_scale"] == pytest.approx(50 * G0)
    assert info["accel_x"]["dynamics"] == {"natural_frequency": 300.0, "damping_ratio": 0.2,
                                           "model": "lowpass"}
    assert info["accel_x"]["cfc_class"] == 180.0 and info["pitch_rate"]["kind"] == "gyroscope"
    assert info["pitch_rate"]["full_scale"] == 20.0
    assert {"pitch_angle", "pitch_angle_integrated", "cg_velocity_z", "cg_displacement_z",
            "floor_1"} <= set(ss.names)
    # defaults: no dynamics, instrumentation CFC 60
    ss0 = sensor_set_from_scenario(sc.loads(""), mounts, body="sphere")
    assert "dynamics" not in ss0.channel_info()["accel_x"]
    assert ss0.channel_info()["accel_x"]["cfc_class"] == 60.0


def test_boundary_contacts_from_engine_contact_arrays():
    """Oracle: Newton's third law -- from the engine's contact arrays (normal from the wall to
    the particle, fn > 0 in compression, fs on the particle) the force on the boundary is
    -(fn n + fs); a floor load cell reads the sum of fn of its body's contacts only."""
    contacts = {
        "body": np.array([-1, 0, 0, 1, 0]),
        "normal": np.tile([0.0, 0.0, 1.0], (5, 1)),
        "fn": np.array([9.0, 5.0, 7.0, 11.0, 3.0]),
        "fs": np.array([[0, 0, 0], [1.0, 0, 0], [0, -2.0, 0], [0, 0, 0], [0.5, 0.5, 0]]),
        "point": np.array([[0, 0, 0], [0.01, 0, 0], [0, 0.02, 0], [0, 0, 0], [5.0, 0, 0]]),
    }
    bc = BoundaryContacts.from_contacts(contacts, body=0)
    assert bc.points.shape == (3, 3)
    assert np.array_equal(bc.forces[:, 2], [-5.0, -7.0, -3.0])
    assert np.array_equal(bc.forces[0], [-1.0, 0.0, -5.0])
    cell = LoadCell(name="c", boundary="floor", radius=0.1)
    _, sig = run([cell], lambda t: {}, [0.0, T], contacts_fn=lambda t: {"floor": bc})
    assert sig["c"].data[0] == 12.0  # contacts 1 and 2; contact 4 lies outside the disc
