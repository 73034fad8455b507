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
