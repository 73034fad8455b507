"""ExudynRigidBody: free flight, torque-free rotation, loads, clocks and errors."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import bodies

#: RK44 integrates a quadratic in t exactly; what is left is round-off of ~1e3 steps on
#: O(10) m values: 1e-12 relative.
PARABOLA_RTOL = 1e-12
#: torque-free top: RK44 at h = 2e-3 s over 1 s with |omega| ~ 10 rad/s gives a local error
#: ~(h |omega|)^5 / 120 ~ 3e-11 per step, ~1e-8 over 500 steps; 1e-7 bounds it with margin.
TOP_ATOL = 1e-7
#: RK44 is fourth order; the observed order of the asymmetric-body invariants must be > 3.5
#: (0.5 below nominal for the pre-asymptotic range of a 3-level study).
RK44_MIN_ORDER = 3.5


def _body(inertia, mass=10.0):
    v, t = bodies.mesh.icosphere(0.1, 0)
    return bodies.RigidBodySpec("test", mass, inertia, v, t)


def _run(model, t_end, h, force=(0, 0, 0), torque=(0, 0, 0)):
    n = int(round(t_end / h))
    t = model.time
    for _ in range(n):
        model.apply(force, torque)
        model.advance(t, t + h)
        t += h
    return model.state()


def test_free_flight_parabola():
    """Oracle: analytic parabola x0 + v0 t + g t^2/2 and v0 + g t (Exudyn applies gravity)."""
    spec = bodies.glider_fuselage()
    x0, v0, g = np.array([1.0, 2.0, 30.0]), np.array([18.33, -1.0, 4.0]), np.array([0, 0, -9.81])
    m = bodies.ExudynRigidBody(spec, x0, np.eye(3), v0, (0, 0, 0), gravity=g)
    s = _run(m, 1.0, 1e-3)
    np.testing.assert_allclose(s.position, x0 + v0 * 1.0 + 0.5 * g, rtol=PARABOLA_RTOL)
    np.testing.assert_allclose(s.velocity, v0 + g, rtol=PARABOLA_RTOL, atol=1e-12)
    np.testing.assert_allclose(s.acceleration, g, rtol=PARABOLA_RTOL)
    assert s.time == pytest.approx(1.0, rel=1e-12)


def test_gravity_counted_once_either_way():
    """Oracle: Newton's second law; weight from Exudyn or from the caller gives the same
    trajectory, never both."""
    spec = bodies.drop_sphere()
    g = np.array([0.0, 0.0, -9.81])
    f_ext = np.array([100.0, 0.0, 2000.0])
    a = bodies.ExudynRigidBody(spec, (0, 0, 1), gravity=g, gravity_in_exudyn=True)
    b = bodies.ExudynRigidBody(spec, (0, 0, 1), gravity=g, gravity_in_exudyn=False)
    sa = _run(a, 0.1, 1e-3, force=f_ext)
    sb = _run(b, 0.1, 1e-3, force=f_ext + spec.mass * g)
    np.testing.assert_allclose(sa.position, sb.position, rtol=PARABOLA_RTOL)
    np.testing.assert_allclose(sa.acceleration, f_ext / spec.mass + g, rtol=PARABOLA_RTOL)
    np.testing.assert_allclose(sb.acceleration, sa.acceleration, rtol=PARABOLA_RTOL)
    np.testing.assert_allclose(sa.velocity, (f_ext / spec.mass + g) * 0.1, rtol=1e-10)


def test_symmetric_top_precession_closed_form():
    """Oracle: torque-free axisymmetric body (I1 = I2 != I3): the symmetry axis precesses
    about the constant angular momentum L at the rate |L| / I1 (Landau & Lifshitz,
    Mechanics §33)."""
    i1, i3 = 2.0, 0.8
    spec = _body(np.diag([i1, i1, i3]))
    r0 = Rotation.from_euler("xyz", [0.3, -0.2, 0.5]).as_matrix()
    w_body = np.array([1.5, -0.7, 9.0])
    w0 = r0 @ w_body
    m = bodies.ExudynRigidBody(spec, (0, 0, 0), r0, (0, 0, 0), w0, gravity=(0, 0, 0))
    L = r0 @ (np.diag([i1, i1, i3]) @ w_body)
    omega_p = np.linalg.norm(L) / i1
    for t_check in (0.5, 1.0):
        s = _run(m, t_check - m.time, 2e-3)
        prec = Rotation.from_rotvec(L / np.linalg.norm(L) * omega_p * t_check).as_matrix()
        np.testing.assert_allclose(s.rotation[:, 2], prec @ r0[:, 2], atol=TOP_ATOL)
        _, l_now = m.momentum()
        np.testing.assert_allclose(l_now, L, atol=TOP_ATOL * np.linalg.norm(L))


def test_asymmetric_body_invariants_converge_at_fourth_order():
    """Oracles: conservation of world angular momentum and kinetic energy of a torque-free
    asymmetric body (intermediate-axis tumbling), and the observed order of their drift
    (RK44: 4)."""
    inertia = np.array([[3.0, 0.2, 0.0], [0.2, 2.0, 0.1], [0.0, 0.1, 1.2]])
    spec = _body(inertia)
    w0 = np.array([0.1, 6.0, 0.3])  # close to the unstable intermediate axis
    errs = []
    for h in (8e-3, 4e-3, 2e-3):
        m = bodies.ExudynRigidBody(spec, (0, 0, 0), np.eye(3), (0, 0, 0), w0, gravity=(0, 0, 0))
        l0, e0 = m.momentum()[1], m.kinetic_energy()
        _run(m, 2.0, h)
        errs.append(max(np.linalg.norm(m.momentum()[1] - l0) / np.linalg.norm(l0),
                        abs(m.kinetic_energy() - e0) / e0))
    errs = np.array(errs)
    assert errs[-1] < 1e-6
    rates = np.log2(errs[:-1] / errs[1:])
    assert (rates > RK44_MIN_ORDER).all(), (errs, rates)


def test_impulse_response_of_an_eccentric_force():
    """Oracle: rigid-body impulse response dv = J/m, d omega = I^-1 (r x J) for a short
    force pulse acting at an offset r from the CG (body at rest, no gravity)."""
    spec = bodies.glider_fuselage()
    m = bodies.ExudynRigidBody(spec, (0, 0, 0), np.eye(3), gravity=(0, 0, 0))
    r = np.array([1.8, 0.0, -0.35])  # a nose contact point relative to the CG
    f = np.array([-2.0e4, 0.0, 3.0e4])
    tau, h = 2e-4, 1e-5
    s = _run(m, tau, h, force=f, torque=np.cross(r, f))
    impulse = f * tau
    np.testing.assert_allclose(s.velocity, impulse / spec.mass, rtol=1e-10)
    # first order in tau: the body rotates by ~|d omega| tau / 2 during the pulse
    rot_angle = np.linalg.norm(s.angular_velocity) * tau
    expected = np.linalg.solve(spec.inertia, np.cross(r, impulse))
    np.testing.assert_allclose(s.angular_velocity, expected, rtol=2 * rot_angle + 1e-10)


def test_clock_checks_and_bad_input():
    """The model refuses to integrate from a time other than its own and bad loads."""
    m = bodies.ExudynRigidBody(bodies.drop_sphere(), (0, 0, 1), time=0.5)
    with pytest.raises(ValueError, match="model time"):
        m.advance(0.0, 0.1)
    with pytest.raises(ValueError, match="must be > t0"):
        m.advance(0.5, 0.5)
    with pytest.raises(ValueError, match="force"):
        m.apply((0, np.nan, 0), (0, 0, 0))
    with pytest.raises(ValueError, match="rotation"):
        bodies.ExudynRigidBody(bodies.drop_sphere(), (0, 0, 1), rotation=2 * np.eye(3))
    m.advance(0.5, 0.6)
    assert m.time == pytest.approx(0.6)
