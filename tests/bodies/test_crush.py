"""The crushable nose (``bodies.split_nose``, ``bodies.ExudynCrushableBody``): mass properties
conserved by the split, analytic crush stroke for a given kinetic energy, momentum, the force
cap before bottoming, bottoming, and the Python replica of the Exudyn connector law."""
from __future__ import annotations

import numpy as np
import pytest

import bodies
from bodies.crush import ExudynCrushableBody, commit_plastic, crush_load

H = 1e-4  # [s] integration step (the DEM step of the glider runs is 1e-4 .. 3e-4 s)


@pytest.fixture(scope="module")
def parts():
    spec = bodies.glider_fuselage()
    rear, nose = bodies.split_nose(spec, 0.5, bodies.GliderBuildUp().laminate_areal_density)
    return spec, rear, nose


def test_split_conserves_mass_cg_inertia(parts):
    """Rear + nose = the whole body: mass, CG and inertia about the whole CG (parallel axes)."""
    spec, rear, nose = parts
    assert rear.mass + nose.mass == pytest.approx(spec.mass, rel=1e-14)
    c_r = rear.cg_in_construction_frame - spec.cg_in_construction_frame
    c_n = nose.cg_in_construction_frame - spec.cg_in_construction_frame
    np.testing.assert_allclose(rear.mass * c_r + nose.mass * c_n, 0.0, atol=1e-12)

    def shift(m, d):
        return m * (d @ d * np.eye(3) - np.outer(d, d))

    j = rear.inertia + shift(rear.mass, c_r) + nose.inertia + shift(nose.mass, c_n)
    np.testing.assert_allclose(j, spec.inertia, rtol=1e-12, atol=1e-9)
    # the nose is the shell ahead of the cut (laminate only): a few kg, ahead of 0.5 m
    assert 1.0 < nose.mass < 10.0
    assert -(nose.vertices + nose.cg_in_construction_frame)[:, 0].max() <= 0.5 + 1e-12
    # sensors stay on the rear body at the same construction-frame place
    for a, b in zip(spec.sensors, rear.sensors):
        np.testing.assert_allclose(a.position + spec.cg_in_construction_frame,
                                   b.position + rear.cg_in_construction_frame, atol=1e-12)


def test_split_rejects_cut_outside_mesh(parts):
    spec, _, _ = parts
    with pytest.raises(ValueError, match="cut_station"):
        bodies.split_nose(spec, 3.0, 4.0)
    with pytest.raises(ValueError, match="crush_force"):
        ExudynCrushableBody(parts[1], parts[2], -1.0, 0.2, H)


def _run(parts, crush_force, stroke, v0, t_end):
    _, rear, nose = parts
    m = ExudynCrushableBody(rear, nose, crush_force, stroke, H, velocity=(v0, 0.0, 0.0),
                            gravity=(0.0, 0.0, 0.0), relative_velocity=v0)
    p0 = m.momentum()
    s_max = 0.0
    n = int(round(t_end / H))
    for i in range(n):
        m.advance(i * H, (i + 1) * H)
        s_max = max(s_max, m.compression)
    return m, p0, s_max


def test_constant_crush_force_gives_analytic_stroke(parts):
    """Nose stopped relative to the aircraft: the relative kinetic energy mu v0^2/2 is
    absorbed at the plateau, s_max = mu v0^2 / (2 F_c) (+ the elastic part, O(F_c/k));
    momentum is conserved (no external load); the element never carried more than F_c."""
    _, rear, nose = parts
    fc, v0 = 2.0e4, 10.0
    mu = rear.mass * nose.mass / (rear.mass + nose.mass)
    s_pred = 0.5 * mu * v0**2 / fc  # 7.3 cm
    m, p0, s_max = _run(parts, fc, 0.5, v0, 0.03)
    assert s_max == pytest.approx(s_pred, abs=2.0 * fc / m.k)
    assert abs(m.s_p - (s_max - fc / m.k)) < 2.0 * fc / m.k  # plastic set = stroke - spring-back
    np.testing.assert_allclose(m.momentum(), p0, rtol=0, atol=1e-9 * np.linalg.norm(p0))
    assert not m.bottomed
    assert m.max_uf_load_before_bottoming <= fc * (1.0 + 1e-12)
    assert m.max_uf_load_before_bottoming == pytest.approx(fc, rel=1e-12)  # plateau reached


def test_bottoming_beyond_stroke(parts):
    """More energy than F_c x stroke: the stroke is used up, the element bottoms and then
    carries more than the crush force (the nose bears on the structure)."""
    fc, stroke, v0 = 2.0e4, 0.004, 10.0  # mu v0^2/2 = 146 J > F_c stroke = 80 J
    m, p0, s_max = _run(parts, fc, stroke, v0, 0.03)
    assert m.bottomed and m.s_p == stroke
    assert s_max > stroke
    assert m.max_uf_load_before_bottoming <= fc * (1.0 + 1e-12)
    assert m.max_load_before_bottoming <= fc * (1.0 + 1e-12)
    np.testing.assert_allclose(m.momentum(), p0, rtol=0, atol=1e-9 * np.linalg.norm(p0))


def test_law_and_return_mapping():
    """Scalar law: elastic below the plateau, capped at it, uncapped once bottomed;
    the return mapping leaves k (s - s_p) = F_c on the plateau."""
    k, fc = 1e7, 5e4
    assert crush_load(1e-3, 0.0, 0.0, fc, 0.2, k, 0.0) == pytest.approx(1e4)
    assert crush_load(1e-2, 0.0, 0.0, fc, 0.2, k, 0.0) == fc
    assert crush_load(0.21, 0.0, 0.2, fc, 0.2, k, 0.0) == pytest.approx(1e5)
    assert crush_load(-1e-3, 0.0, 0.0, fc, 0.2, k, 0.0) == pytest.approx(-1e4)  # tension
    sp = commit_plastic(0.05, 0.0, fc, 0.2, k)
    assert k * (0.05 - sp) == pytest.approx(fc)
    assert commit_plastic(0.5, 0.0, fc, 0.2, k) == 0.2


def test_connector_wrench_replica_matches_exudyn(parts):
    """The Python connector law (used to put the element's load in the fuselage wrench) gives
    the same forces and torques as Exudyn's user-function connector: m dv/dt and J dw/dt
    over a short step with no other load."""
    _, rear, nose = parts
    m = ExudynCrushableBody(rear, nose, 5e4, 0.2, H, gravity=(0.0, 0.0, 0.0))
    m.apply_nose([-2e4, 0.0, 3e3], [0.0, 100.0, 0.0])
    for i in range(50):
        m.advance(i * H, (i + 1) * H)
    st = (m.position(), m.rotation(), m.velocity(), m.angular_velocity(), m.nose_position(),
          m.nose_rotation(), m.nose_velocity(), m.nose_angular_velocity())
    fr, tr, fn, tn, p = m.connector_wrench(*st)
    assert 1e4 < p <= 5e4
    v0, w0, vn0 = m.velocity(), m.angular_velocity(), m.nose_velocity()
    m.apply_nose([0.0, 0.0, 0.0], [0.0, 0.0, 0.0])
    hh = 1e-8
    m.advance(50 * H, 50 * H + hh)
    np.testing.assert_allclose(rear.mass * (m.velocity() - v0) / hh, fr,
                               atol=2e-3 * np.linalg.norm(fr))
    np.testing.assert_allclose(nose.mass * (m.nose_velocity() - vn0) / hh, fn,
                               atol=2e-3 * np.linalg.norm(fn))
    np.testing.assert_allclose(m.inertia_world() @ (m.angular_velocity() - w0) / hh, tr,
                               atol=2e-3 * np.linalg.norm(tr))


def _drive_crush(m, k0, n):
    """Advance the two bodies under varying loads through plateau and bottoming, declaring a
    connector load as the glider exchange does; the trajectory and element history."""
    out = []
    for k in range(k0, k0 + n):
        t = k * H
        m.apply_nose([-4e4 * (1.0 + 0.5 * np.sin(800.0 * t)), 0.0, 6e3], [0.0, 50.0, 0.0])
        st = (m.position(), m.rotation(), m.velocity(), m.angular_velocity(),
              m.nose_position(), m.nose_rotation(), m.nose_velocity(),
              m.nose_angular_velocity())
        fr, tr, _, _, _ = m.connector_wrench(*st)
        m.add_connector_load(fr, tr)
        m.apply(np.array([-2e3, 0.0, 1e3]) + fr, np.array([0.0, -300.0, 0.0]) + tr)
        m.advance(t, t + H)
        out.append((m.position(), m.rotation(), m.velocity(), m.angular_velocity(),
                    m.nose_position(), m.nose_velocity(), m.s_p, m.load, m.compression,
                    m.bottomed, m.max_uf_load_before_bottoming, m.time))
    return out


def test_state_dict_roundtrip_continues_bit_for_bit(parts):
    """Oracle: identity -- a crushable body saved mid-crush (plastic stroke committed, loads
    held, connector load declared) and loaded into a fresh object (through a pickle, as a
    checkpoint does) continues bit for bit like the uninterrupted one, through bottoming;
    a dict of another element is refused."""
    import pickle

    _, rear, nose = parts
    kw = dict(velocity=(18.0, 0.0, -0.5), angular_velocity=(0.0, -0.2, 0.0),
              relative_velocity=2.0)
    a = ExudynCrushableBody(rear, nose, 3e4, 0.1, H, **kw)
    _drive_crush(a, 0, 40)
    assert 0.0 < a.s_p < 0.1 and not a.bottomed  # mid-crush
    fa = np.array([5.0, 6.0, 7.0])
    a.add_connector_load(fa, -fa)  # a declared, not yet applied connector load is kept too
    d = pickle.loads(pickle.dumps(a.state_dict()))
    a.add_connector_load(np.zeros(3), np.zeros(3))
    b = ExudynCrushableBody(rear, nose, 3e4, 0.1, H)  # another initial state
    b.load_state_dict(d)
    assert np.array_equal(b._added[0], fa)
    b.add_connector_load(np.zeros(3), np.zeros(3))
    for k, v in d.items():
        w = b.state_dict()[k]
        if k not in ("added_force", "added_torque"):
            assert np.array_equal(np.asarray(v), np.asarray(w)), k
    ra, rb = _drive_crush(a, 40, 150), _drive_crush(b, 40, 150)
    assert a.bottomed  # the continuation crosses bottoming
    for xa, xb in zip(ra, rb):
        for u, v in zip(xa, xb):
            assert np.array_equal(np.asarray(u), np.asarray(v))
    c = ExudynCrushableBody(rear, nose, 4e4, 0.1, H)
    with pytest.raises(ValueError, match="crush_force"):
        c.load_state_dict(d)
