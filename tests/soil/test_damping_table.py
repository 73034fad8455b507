"""The contact kernels read each material's damping ratios from the material table
(``M_ZETA`` / ``M_SHEAR_ZETA``, filled by ``contact_laws.damping_ratio``) instead of evaluating
``damping_ratio(min(e_i, e_j))`` per contact and step: the table holds exactly those bits, a
contact of two materials is damped by the lower restitution's ratio (normal and shear dashpots,
either order, grain pairs and boundary bodies), and a contact force is the formula's to the
last bit."""

from __future__ import annotations

import math

import numpy as np
import pytest

import soil
from soil import _kernels as K
from soil.contact_laws import damping_ratio, normal_stiffness
from soil.simulation import _material_table

E = 2e7  # [Pa]
RHO = 2650.0  # [kg/m^3]
R = 0.05  # [m]
G = 9.81  # [m/s^2]
M = 4.0 / 3.0 * math.pi * R**3 * RHO


def mat(**kw):
    return soil.Material(young=E, density=RHO, friction_angle=1.4, stiffness_ratio=0.25, **kw)


def _bits(a):
    return np.asarray(a, np.float64).view(np.int64)


def test_material_table_holds_the_damping_ratios_bit_for_bit():
    """Oracle: the formula zeta = -ln e / sqrt(pi^2 + ln^2 e) evaluated in plain Python (its
    source, not the compiled function) and the compiled function itself: the same bits in the
    table's zeta columns; no damping (None or 1) is zeta = 0."""
    es = [None, 1.0, 0.999, 0.55, 0.5, 0.4, 0.3, 0.2, 0.1, 1e-3, 1e-9]
    materials = [mat(restitution=e, shear_restitution=es[-1 - k]) for k, e in enumerate(es)]
    tab = _material_table(materials)
    assert tab.shape == (len(materials), K.M_NCOL)
    for col_e, col_z in ((K.M_RESTITUTION, K.M_ZETA), (K.M_SHEAR_RESTITUTION, K.M_SHEAR_ZETA)):
        e = tab[:, col_e]
        assert np.array_equal(_bits(tab[:, col_z]), _bits([damping_ratio(x) for x in e]))
        assert np.array_equal(_bits(tab[:, col_z]), _bits([damping_ratio.py_func(x) for x in e]))
        assert np.all(tab[e == 1.0, col_z] == 0.0)
        assert np.all(tab[e < 1.0, col_z] > 0.0)
    assert tab[0, K.M_ZETA] == 0.0 and tab[0, K.M_SHEAR_ZETA] > 0.0
    assert tab[-1, K.M_SHEAR_ZETA] == 0.0
    # the columns are the ones the material reports for itself
    for m, row in zip(materials, tab):
        assert row[K.M_ZETA] == m.damping_ratio


def _oblique_pair(materials, ids):
    """Two grains meeting obliquely (normal and sticking shear motion), no gravity."""
    p = soil.Particles(x=[[0.0, 0.0, 0.0], [2 * R - 1e-4, 0.0, 0.0]], radius=R, material=ids,
                       v=[[0.3, 0.05, 0.0], [-0.3, -0.05, 0.0]])
    sim = soil.Simulation(p, materials, gravity=(0, 0, 0))
    sim.step(300)
    return sim


def _sliding_on_wall(materials, grain, wall):
    """A grain dropped on a plane with a tangential velocity (normal and shear contact)."""
    p = soil.Particles(x=[[0.0, 0.0, R + 1e-4]], radius=[R], material=[grain],
                       v=[[0.05, 0.02, -0.5]])
    plane = soil.BoundaryBody(shapes=[soil.Plane()], material=wall)
    sim = soil.Simulation(p, materials, [plane], gravity=(0, 0, -G))
    sim.step(300)
    return sim


def _state(sim):
    p = sim.particles
    en = sim.energy()
    return (p.x.tobytes() + p.v.tobytes() + p.f.tobytes()
            + np.float64([en["dissipated_viscous"], en["dissipated_friction"]]).tobytes())


@pytest.mark.parametrize("tension", [False, True])
@pytest.mark.parametrize("law", ["linear", "hertz_mindlin"])
def test_a_mixed_contact_is_damped_by_the_lower_restitution(law, tension):
    """Oracle: identity (bit for bit). The normal dashpot of a contact between materials of
    restitutions 0.3 and 0.7 is the one of e = 0.3, its shear dashpot (0.7 and 0.3 the other
    way round) the one of e_s = 0.3: the run equals that of one material with e = e_s = 0.3,
    whichever material each grain (or the wall) has; an undamped run differs, and so does one
    with the higher restitution."""
    a = mat(restitution=0.3, shear_restitution=0.7, contact_law=law, dashpot_tension=tension)
    b = mat(restitution=0.7, shear_restitution=0.3, contact_law=law, dashpot_tension=tension)
    low = mat(restitution=0.3, shear_restitution=0.3, contact_law=law, dashpot_tension=tension)
    high = mat(restitution=0.7, shear_restitution=0.7, contact_law=law, dashpot_tension=tension)
    none = mat(contact_law=law, dashpot_tension=tension)
    ref = _state(_oblique_pair([low], [0, 0]))
    assert _state(_oblique_pair([a, b], [0, 1])) == ref
    assert _state(_oblique_pair([a, b], [1, 0])) == ref
    assert _state(_oblique_pair([high], [0, 0])) != ref
    assert _state(_oblique_pair([none], [0, 0])) != ref
    ref_w = _state(_sliding_on_wall([low], 0, 0))
    assert _state(_sliding_on_wall([a, b], 0, 1)) == ref_w
    assert _state(_sliding_on_wall([a, b], 1, 0)) == ref_w
    assert _state(_sliding_on_wall([high], 0, 0)) != ref_w
    sim = _sliding_on_wall([none], 0, 0)
    assert _state(sim) != ref_w and sim.energy()["dissipated_viscous"] == 0.0


@pytest.mark.parametrize("e_grain, e_wall", [(0.3, 0.8), (0.8, 0.3), (0.45, None)])
def test_the_damped_normal_force_is_the_formula_to_the_last_bit(e_grain, e_wall):
    """Oracle: the linear spring-dashpot f_n = k_n delta + 2 zeta sqrt(m* k_n) delta_dot with
    zeta = damping_ratio(min(e_i, e_j)) evaluated here, for the force the engine computes at
    t = 0 (an approaching, overlapping contact): grain pairs and a grain on a plane, the same
    bits."""
    materials = [mat(restitution=e_grain), mat(restitution=e_wall)]
    e = min(e_grain, 1.0 if e_wall is None else e_wall)
    zeta = damping_ratio(e)
    ov = 2e-4
    vz = -0.7
    # a grain on a plane (boundary contacts)
    p = soil.Particles(x=[[0.0, 0.0, R - ov]], radius=[R], v=[[0.0, 0.0, vz]])
    sim = soil.Simulation(p, materials, [soil.BoundaryBody(shapes=[soil.Plane()], material=1)],
                          gravity=(0, 0, 0))
    c = sim.contacts()
    m = sim.particles.mass[0]
    kn = normal_stiffness(E, R, E, R)
    delta = R - (R - ov)
    assert c["fn"][0] == kn * delta + 2.0 * zeta * math.sqrt(m * kn) * -vz
    # two grains along x (pair contacts)
    p = soil.Particles(x=[[0.0, 0.0, 0.0], [2 * R - ov, 0.0, 0.0]], radius=R, material=[0, 1],
                       v=[[-vz, 0.0, 0.0], [0.0, 0.0, 0.0]])
    sim = soil.Simulation(p, materials, gravity=(0, 0, 0))
    c = sim.contacts()
    mi, mj = sim.particles.mass
    m_eff = mi * mj / (mi + mj)
    delta = R + R - (2 * R - ov)
    assert c["fn"][0] == kn * delta + 2.0 * zeta * math.sqrt(m_eff * kn) * -vz
    assert zeta > 0.0 or e == 1.0
