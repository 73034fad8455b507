"""Concealed-effect recordings of the glider crash (planar model truth), for testing the
diagnosis of glider scenarios.

The truth is the planar 3-DOF impactor (``rom_planar``) with one catalogue effect drawn from a
seed (hidden from the diagnosis), run with numerics and soil values that differ from the
diagnosing model in ways that are not the effect: a 4x smaller step (5 us instead of 20 us),
soil strength, drag and stiffness each off by a factor drawn in 0.9-1.1 (what the diagnosis
must report as a recalibration, not as missing physics), the accelerometer 5 cm further aft.
``nose_scale`` also changes the nose sphere's radius (an impactor-geometry error of the
model; measured separately, see docs/diagnosis.md). It is acquired like the glider's
lab channels (``generator.acquire_samples``: 12.5 kHz integrating acquisition, white sensor
noise, trigger offset, SAE J211 CFC 60): the rear accelerometer pair ``accel_x`` /
``accel_z`` (250 g channels, 0.5 g raw noise) and the pitch-rate gyro ``pitch_rate``
(0.5 deg/s raw noise).

Notes
-----
The glider's channels have no free-fall velocity segment, so the diagnosis cannot measure the
impact speed or run the accelerometer/velocity check here: every effect is found by the fits.
Base: ``GLIDER_BASE`` = ``cli.planar_from_scenario`` of ``validation/scenarios/glider_real.toml``
(the reference glider and container; ``tests/crashdem/diagnosis/test_concealed_glider.py``
checks that the two agree): 343 kg, pitch inertia 230 kg m^2, nose sphere of 0.30 m (half the
fuselage width) 1.96 m ahead of the CG, a crushable nose of 0.86 % of the mass (the full
model's nose cone ahead of ``glider.NOSE_CUT_STATION``), rear accelerometer 5 cm ahead of and
0.31 m below the CG, rear wall 1.56 m ahead of the first contact (plate stiffness 2.2 MN/m).
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from crashdem.diagnosis.generator import (EFFECT_DRAWS, PRE_TRIGGER, TRIGGER_JITTER, ConcealedCase,
                                          acquire_samples, draw_effect)
from crashdem.diagnosis.rom import SCALE_KEYS, RomParams, RomSettings
from crashdem.diagnosis.rom_planar import PlanarParams, run_planar_raw, simulate_planar
from crashdem.signal import Signal

__all__ = ["GLIDER_BASE", "PLANAR_EFFECT_DRAWS", "PlanarConcealedCase", "planar_concealed_case",
           "planar_baseline", "RAW_NOISE_PLANAR", "RECORD_END", "diagnose_cases"]

#: the diagnosed glider model: ``planar_from_scenario(glider_real.toml)`` (module notes)
GLIDER_BASE = PlanarParams(
    soil=RomParams(mass=343.0, radius=0.3, impact_speed=18.336561571079784, density=1696.0,
                   floor_depth=1.2020815280171306, nose_mass_fraction=0.008593264427150154),
    pitch_inertia=230.07901439892345, nose_offset=1.9625576567837868,
    nose_height=0.07220942308704384, slope=math.radians(45.0), path_angle=0.026753026376064058,
    pitch=0.0, friction=math.tan(math.radians(30.0)), wall_distance=1.5615089845078458,
    wall_stiffness=2210212.8349608486, mount_x=0.051048672275940454, mount_z=-0.3082551603498543)
#: range of the truth's soil scale factors (strength, drag, stiffness), drawn per case
RECAL_RANGE = (0.9, 1.1)
#: truth integration step [s] (diagnosing model: 2e-5 s)
TRUTH_DT = 5.0e-6
#: record after first contact [s] (the reference event lasts about 0.25 s)
RECORD_END = 0.25
#: raw white noise per channel (SI): 0.5 g on the 250 g accelerometers, 0.5 deg/s on the gyro
RAW_NOISE_PLANAR = {"accel_x": 0.5 * 9.80665, "accel_z": 0.5 * 9.80665,
                    "pitch_rate": math.radians(0.5)}

#: effect -> {parameter: (low, high, "lin"|"log")}; ranges visible above the noise. The soil
#: and sensor effects draw what the drop truth draws (``generator.EFFECT_DRAWS``); the wall,
#: the crush (the glider's soil peak is ~100 kN, not the drop's ~600 kN) and the attitude are
#: the glider's own
PLANAR_EFFECT_DRAWS: dict[str, dict[str, tuple[float, float, str]]] = {
    "boundary_proximity": {"wall_distance": (0.85, 1.15, "lin")},
    **{e: EFFECT_DRAWS[e] for e in ("cohesion", "particle_rotation", "contact_damping",
                                    "sensor_dynamics")},
    "structural_crush": {"crush_strength": (4.0e4, 8.0e4, "log"), "crush_stroke": (0.1, 0.25, "lin")},
    "initial_conditions": {"pitch_offset": (0.06, 0.12, "lin")},  # sign drawn separately
}


#: a generated glider recording and its hidden truth: the drop generator's case record, its
#: ``truth`` a ``PlanarParams``
PlanarConcealedCase = ConcealedCase


def planar_concealed_case(seed: int, effect: str | None, *,
                          base: PlanarParams = GLIDER_BASE,
                          nose_scale: float = 1.0) -> PlanarConcealedCase:
    """A glider recording with ``effect`` (a catalogue name, or None for a null case) drawn
    from ``seed``, made by the truth numerics (soil scale factors drawn in ``RECAL_RANGE``)
    and acquired like the lab channels; ``nose_scale`` multiplies the truth's nose radius."""
    rng = np.random.default_rng(seed)
    values = draw_effect(effect, rng, PLANAR_EFFECT_DRAWS, "pitch_offset") \
        if effect is not None else {}
    recal = {k: float(rng.uniform(*RECAL_RANGE)) for k in SCALE_KEYS}
    truth = base.with_values(recal).with_values(values)
    truth = replace(truth, soil=replace(truth.soil, radius=nose_scale * truth.soil.radius),
                    mount_x=truth.mount_x - 0.05)
    t, fx, fz, w, _ = run_planar_raw(truth, RomSettings(dt=TRUTH_DT, t_end=RECORD_END + 0.01,
                                                        cfc=None))
    offset = float(rng.uniform(-TRIGGER_JITTER, TRIGGER_JITTER))
    rec = acquire_samples(t, {"accel_x": (fx, "m/s^2"), "accel_z": (fz, "m/s^2"),
                              "pitch_rate": (w, "rad/s")}, truth.v0, rng, t_pre=PRE_TRIGGER,
                          t_end=RECORD_END, trigger_offset=offset, noise=RAW_NOISE_PLANAR,
                          source=f"crashdem.diagnosis.generator_planar (dt={TRUTH_DT:g} s)")
    return PlanarConcealedCase(effect, values, recal, seed, rec, truth, offset)


def planar_baseline(base: PlanarParams = GLIDER_BASE) -> dict[str, Signal]:
    """The diagnosed glider simulation (the planar model at its own numerics, no effect)."""
    return simulate_planar(base, RomSettings(t_pre=PRE_TRIGGER, t_end=RECORD_END))


def _diagnosed_case(job: tuple[int, str | None]):
    """Worker of ``diagnose_cases``: one glider case generated and diagnosed."""
    from crashdem.diagnosis import diagnose

    seed, effect = job
    case = planar_concealed_case(seed, effect)
    return case, diagnose(planar_baseline(), case.recording, rom_base=GLIDER_BASE)


def diagnose_cases(cases, workers: int | None = None) -> list:
    """``(case, report)`` of each glider case ``(seed, effect)``: ``planar_concealed_case``
    diagnosed by ``diagnose`` against ``planar_baseline()`` (``rom_base=GLIDER_BASE``), the
    cases spread over ``workers`` processes (``parallel.map_processes``; the same reports as one
    by one, in the order of ``cases``)."""
    from crashdem.diagnosis.parallel import map_processes

    return map_processes(_diagnosed_case, [(int(s), e) for s, e in cases], workers)
