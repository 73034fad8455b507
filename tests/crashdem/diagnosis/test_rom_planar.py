"""Planar 3-DOF impactor ROM: reduction to the vertical drop ROM, mirror symmetry, friction."""
from __future__ import annotations

import math

import numpy as np
import pytest

from crashdem.diagnosis.rom import RomParams, RomSettings, run_raw
from crashdem.diagnosis.rom_planar import PlanarParams, run_planar_raw, simulate_planar

RAW = RomSettings(dt=2e-5, t_end=0.08, sample_rate=1000.0, cfc=None)


def test_vertical_drop_on_level_ground_reduces_to_the_drop_rom():
    """Oracle (independent implementation): level surface, vertical path, nose at the CG and no
    friction is the vertical drop; body-z specific force and penetration must equal the drop
    ROM's to round-off (same force law and integrator, different kinematics code)."""
    soil = RomParams()
    pp = PlanarParams(soil=soil, nose_offset=0.0, slope=0.0, path_angle=math.pi / 2,
                      pitch=0.0, friction=0.0)
    t, fx, fz, w, pen = run_planar_raw(pp, RAW)
    t1, acc, vel, dep = run_raw(soil, RAW)
    assert np.max(np.abs(fz - acc)) < 1e-9 * np.max(np.abs(acc))
    assert np.max(np.abs(pen - np.maximum(dep, 0.0))) < 1e-12
    assert np.max(np.abs(fx)) < 1e-9 and np.max(np.abs(w)) == 0.0


def test_mirror_symmetry_of_the_nose_offset():
    """Oracle (symmetry): on level ground with a vertical path, mirroring the nose offset d -> -d
    mirrors the motion: the pitch rate changes sign, body-x force changes sign, body-z force is
    unchanged (to round-off); a forward nose pitches the body nose-up (positive rate)."""
    base = dict(soil=RomParams(mass=343.0, radius=0.15, impact_speed=10.0), slope=0.0,
                path_angle=math.pi / 2, friction=0.0)
    a = run_planar_raw(PlanarParams(nose_offset=1.0, **base), RAW)
    b = run_planar_raw(PlanarParams(nose_offset=-1.0, **base), RAW)
    scale = np.max(np.abs(a[2]))
    assert np.max(np.abs(a[3] + b[3])) < 1e-9 * np.max(np.abs(a[3]))
    assert np.max(np.abs(a[1] + b[1])) < 1e-9 * scale
    assert np.max(np.abs(a[2] - b[2])) < 1e-9 * scale
    assert a[3][np.argmax(np.abs(a[3]))] > 0.0


def test_friction_decelerates_tangential_motion():
    """Oracle (Coulomb law): sliding along a level surface, friction opposes the tangential
    velocity: with mu > 0 the body-x specific force is negative (decelerating) while the nose
    slides, zero with mu = 0."""
    soil = RomParams(mass=343.0, radius=0.15, impact_speed=18.33)
    shallow = math.radians(10.0)
    f0 = run_planar_raw(PlanarParams(soil=soil, slope=0.0, path_angle=shallow, nose_offset=0.0,
                                     friction=0.0), RAW)
    f1 = run_planar_raw(PlanarParams(soil=soil, slope=0.0, path_angle=shallow, nose_offset=0.0,
                                     friction=0.5), RAW)
    assert np.max(np.abs(f0[1])) < 1e-9
    loaded = f1[2] > 0.05 * np.max(f1[2])
    assert np.all(f1[1][loaded] < 0.0)


def test_glider_defaults_run_and_channels():
    """Interface check (not a physics test): the default 45-degree glider impact returns the
    four channels, all finite; parameter errors name the field."""
    out = simulate_planar(PlanarParams(), RomSettings(t_end=0.2))
    assert set(out) == {"accel_x", "accel_z", "pitch_rate", "penetration"}
    for s in out.values():
        assert np.all(np.isfinite(s.data))
    with pytest.raises(ValueError, match=r"PlanarParams\.slope=2"):
        PlanarParams(slope=2.0)


NO_GRAVITY_SOIL = RomParams(mass=343.0, radius=0.15, impact_speed=10.0, gravity=0.0)


def test_rear_wall_impact_is_a_spring_mass_collision():
    """Oracle (linear oscillator): a nose sliding along level ground (no gravity, no friction,
    so no soil load) into an undamped wall of stiffness k is a mass on a spring: contact lasts
    pi sqrt(m/k), the peak deceleration is v sqrt(k/m) and the body leaves at its impact speed
    (elastic wall, energy conserved)."""
    m, v, k = 343.0, 10.0, 2.0e6
    pp = PlanarParams(soil=NO_GRAVITY_SOIL, nose_offset=0.0, slope=0.0, path_angle=0.0,
                      friction=0.0, wall_distance=0.2, wall_stiffness=k, wall_damping=0.0)
    s = RomSettings(dt=1e-6, t_end=0.05, sample_rate=20000.0, cfc=None)
    t, fx, fz, w, pen = run_planar_raw(pp, s)
    loaded = fx < 0.0
    duration = float(np.count_nonzero(loaded)) * s.dt
    assert abs(duration / (math.pi * math.sqrt(m / k)) - 1.0) < 2e-3
    assert abs(-fx.min() / (v * math.sqrt(k / m)) - 1.0) < 2e-3
    v_out = v + np.sum(fx) * s.dt  # body-x velocity after the contact
    assert abs(v_out / -v - 1.0) < 2e-3
    assert np.max(np.abs(fz)) < 1e-9 and np.max(pen) == 0.0


def test_crush_element_limits_the_axial_load_on_the_body():
    """Oracle (force-limited series element): while the nose crushes (stroke not used up), the
    body's axial specific force is the crush force over the body mass, never more: |a_x| <=
    F_c / (m (1 - nose fraction)); with a rigid nose the same impact decelerates harder."""
    fc = 4.0e4
    soil = RomParams(mass=343.0, radius=0.15, impact_speed=18.33, crush_strength=fc,
                     crush_stroke=0.5)
    pp = PlanarParams(soil=soil, nose_offset=1.3)
    s = RomSettings(dt=5e-6, t_end=0.03, cfc=None)
    t, fx, fz, w, pen = run_planar_raw(pp, s)
    m_b = 343.0 * (1.0 - soil.nose_mass_fraction)
    assert np.max(np.abs(fx)) <= fc / m_b * (1.0 + 1e-9)
    assert np.max(np.abs(fx)) > 0.99 * fc / m_b  # the element does yield
    rigid = run_planar_raw(PlanarParams(soil=RomParams(mass=343.0, radius=0.15,
                                                      impact_speed=18.33), nose_offset=1.3), s)
    assert np.max(np.abs(rigid[1])) > 1.5 * fc / m_b


def test_mount_offset_channel_integrates_to_the_pitch_rate():
    """Oracle (rigid-body kinematics, independent output): an accelerometer a distance L ahead
    of the CG along body x reads a_z(CG) + L dw/dt - ..., so the time integral of
    (a_z(mount) - a_z(CG)) / L equals the pitch rate channel w(t) (to the integration error)."""
    base = dict(soil=RomParams(mass=343.0, radius=0.15, impact_speed=18.33), nose_offset=1.3)
    s = RomSettings(dt=5e-6, t_end=0.15, cfc=None)
    big_l = 1.0
    t, _, fz0, w, _ = run_planar_raw(PlanarParams(**base), s)
    _, fx1, fz1, _, _ = run_planar_raw(PlanarParams(mount_x=big_l, **base), s)
    # the mount term also holds -w^2 L along x; along z only alpha L
    integ = np.concatenate([[0.0], np.cumsum(fz1[1:] - fz0[1:]) * s.dt / big_l])
    assert np.max(np.abs(integ - w)) < 1e-6 * np.max(np.abs(w)) + 1e-9
    assert np.max(np.abs(w)) > 1.0  # the body does rotate


@pytest.mark.parametrize("distance", [0.1, 1.56, math.inf])
def test_planar_catalogue_wall_range_holds_the_modelled_wall(distance):
    """The rear-wall hypothesis nests the baseline for any modelled wall: its ``off`` value is
    the modelled distance (4 m, out of reach, without a wall) and both it and the nominal lie in
    the search range (a wall 0.1 m ahead used to raise a ParameterSpec error)."""
    from crashdem.diagnosis.catalogue import planar_catalogue

    wall = planar_catalogue(PlanarParams(wall_distance=distance)).get("boundary_proximity")
    d = wall.parameters[0]
    assert d.name == "wall_distance"
    assert d.off == (distance if math.isfinite(distance) else 4.0)
    assert d.lo <= d.nominal < d.off <= d.hi
