"""Empirical impact-force formulas for rock blocks on granular cushions.

All functions take SI inputs and return SI outputs (N, m); the formulas are written in their
native unit systems (kN, kN/m^2, t, kJ) inside, and converted at the boundary.

Notes
-----
Japan Road Association, Rockfall Countermeasure Handbook (2017) and Swiss ASTRA 12 006 (2008),
as transcribed in ``/work/shared/reference/anchors.md`` section 1.2 (formula text marked [M]
there: memory of the literature, checked here only against the [D] table derived from it).
Labiouse, Descoeudres & Montani (1996) is the ASTRA predecessor without the thickness and
friction terms (also [M]).
"""
from __future__ import annotations

import math

#: Standard gravity used to convert the block mass into a weight [m/s^2].
G = 9.81


def _positive(name: str, value: float, unit: str) -> None:
    if not (math.isfinite(value) and value > 0.0):
        raise ValueError(f"{name}={value!r}: must be > 0 [{unit}]")


def fall_height(speed: float, g: float = G) -> float:
    """Free-fall height giving an impact speed, ``H = v^2 / (2 g)`` [m].

    Parameters
    ----------
    speed : float
        Impact speed [m/s], > 0.
    g : float
        Gravity [m/s^2].

    Notes
    -----
    Energy conservation in free fall (no drag).
    """
    _positive("speed", speed, "m/s")
    return speed * speed / (2.0 * g)


def japan_force(mass: float, height: float, lame: float, g: float = G) -> float:
    """Peak impact force of the Japanese Rockfall Countermeasure Handbook [N].

    ``P = 2.108 (m g)^(2/3) lambda^(2/5) H^(3/5)`` with P in kN, m g in kN, lambda in kN/m^2,
    H in m.

    Parameters
    ----------
    mass : float
        Block mass [kg], > 0.
    height : float
        Fall height [m], > 0 (use :func:`fall_height` for a given impact speed).
    lame : float
        Lame constant of the cushion [Pa], > 0 (design default 1e6 Pa = 1000 kN/m^2, soft sand).
    g : float
        Gravity [m/s^2].

    Returns
    -------
    float
        Peak force [N].

    Notes
    -----
    Japan Road Association, Rockfall Countermeasure Handbook, Dec 2017 (Hertz contact of a
    sphere on a semi-infinite elastic cushion); anchors.md section 1.2.
    """
    _positive("mass", mass, "kg")
    _positive("height", height, "m")
    _positive("lame", lame, "Pa")
    weight_kn = mass * g / 1e3
    p_kn = 2.108 * weight_kn ** (2.0 / 3.0) * (lame / 1e3) ** 0.4 * height ** 0.6
    return p_kn * 1e3


def astra_force(mass: float, speed: float, radius: float, thickness: float, modulus: float,
                friction_angle: float, c: float = 1.0) -> float:
    """Peak impact force of the Swiss ASTRA 12 006 guideline [N].

    ``F = C 2.8 e^(-1/2) r^(0.7) M_E^(0.4) tan(phi) (m v^2 / 2)^(0.6)`` with F in kN, e and r
    in m, M_E in kN/m^2, m in t, v in m/s (so the energy is in kJ).

    Parameters
    ----------
    mass : float
        Block mass [kg], > 0.
    speed : float
        Impact speed [m/s], > 0.
    radius : float
        Block radius [m], > 0.
    thickness : float
        Cushion thickness e [m], > 0.
    modulus : float
        Oedometric (plate-load) modulus M_E of the cushion [Pa], > 0.
    friction_angle : float
        Friction angle of the cushion [rad], in (0, pi/2).
    c : float
        Construction-type factor C (about 1), > 0.

    Returns
    -------
    float
        Peak force [N].

    Notes
    -----
    ASTRA 12 006 (2008), "Einwirkungen infolge Steinschlags auf Schutzgalerien";
    anchors.md section 1.2.
    """
    for name, v, u in (("mass", mass, "kg"), ("speed", speed, "m/s"), ("radius", radius, "m"),
                       ("thickness", thickness, "m"), ("modulus", modulus, "Pa"), ("c", c, "-")):
        _positive(name, v, u)
    if not 0.0 < friction_angle < math.pi / 2:
        raise ValueError(f"friction_angle={friction_angle!r}: must be in (0, pi/2) [rad]")
    energy_kj = 0.5 * (mass / 1e3) * speed * speed
    f_kn = (c * 2.8 * thickness ** -0.5 * radius ** 0.7 * (modulus / 1e3) ** 0.4
            * math.tan(friction_angle) * energy_kj ** 0.6)
    return f_kn * 1e3


def labiouse_force(mass: float, height: float, radius: float, modulus: float,
                   g: float = G) -> float:
    """Peak impact force of Labiouse, Descoeudres & Montani (1996) [N].

    ``P = 1.765 M_E^(0.4) R^(0.2) (m g H)^(0.6)`` with P in kN, M_E in kN/m^2, R in m,
    m g H in kN m.

    Notes
    -----
    Labiouse et al. (1996), Struct. Eng. Int. 6(3):171-175; anchors.md section 1.2 ([M]: not
    checked against the paper; reported for information, not used as a test threshold).
    """
    for name, v, u in (("mass", mass, "kg"), ("height", height, "m"), ("radius", radius, "m"),
                       ("modulus", modulus, "Pa")):
        _positive(name, v, u)
    return 1.765 * (modulus / 1e3) ** 0.4 * radius ** 0.2 * (mass * g * height / 1e3) ** 0.6 * 1e3


def triangular_penetration(mass: float, speed: float, force: float) -> float:
    """Penetration of a triangular force pulse that stops the block, ``d = m v^2 / F`` [m].

    Notes
    -----
    Work-energy balance ``m v^2 / 2 = F d / 2`` for a force rising linearly with penetration
    (ASTRA 12 006 reading; anchors.md section 1.2).
    """
    for name, v, u in (("mass", mass, "kg"), ("speed", speed, "m/s"), ("force", force, "N")):
        _positive(name, v, u)
    return mass * speed * speed / force
