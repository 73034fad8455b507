"""Integration of triangle-mesh boundaries with the DEM engine (soil.Simulation)."""

import math

import numpy as np
import pytest

import soil
from soil.contact_laws import contact_duration
from soil.mesh import TriangleMesh
from tests.soil.test_engine import _impact

E = 2e7  # [Pa]
RHO = 2650.0  # [kg/m^3]
R = 0.05  # [m]
# leapfrog with dt = t_c / 200: the measured contact duration is quantised by dt (+-2 dt) and
# the symplectic energy error is O((omega dt)^2) ~ 2.5e-4
STEPS_PER_CONTACT = 200
RESTITUTION_TOL = 1e-3


@pytest.mark.parametrize("foot", [(1 / 6, 1 / 6), (0.0, 0.1), (0.05, -0.02)],
                         ids=["shared_vertex", "shared_edge", "face"])
def test_facet_impact_is_one_linear_spring(foot):
    """Oracle: undamped linear spring, t_c = pi sqrt(m / k_n) with the facet convention
    k_n = 2 E r E 2r / (E r + E 2r) = 4/3 E r (Yade Ig2_Facet_Sphere_ScGeom, ARCHITECTURE 1);
    restitution 1 (energy conservation). The impact point is a vertex shared by 6 triangles, an
    edge shared by 2, or a face interior: one contact at every step, so the same duration."""
    m = 4.0 / 3.0 * math.pi * R**3 * RHO
    kn = 4.0 / 3.0 * E * R
    t_c = contact_duration(m, kn)
    dt = t_c / STEPS_PER_CONTACT
    mesh = TriangleMesh.plane_patch((1.0, 1.0), (3, 3))
    p = soil.Particles(x=[[foot[0], foot[1], R + 1e-4]], radius=[R], v=[[0.0, 0.0, -1.0]])
    mat = soil.Material(young=E, density=RHO, friction_angle=0.0, stiffness_ratio=0.25)
    sim = soil.Simulation(p, [mat], [soil.BoundaryBody(shapes=[mesh])], gravity=(0, 0, 0),
                          dt=dt)
    dur, v_before, v_after, max_contacts = _one_impact(sim, 10 * STEPS_PER_CONTACT)
    assert max_contacts == 1
    assert abs(dur - t_c) <= 2 * dt
    assert abs(-v_after[2] / v_before[2] - 1.0) < RESTITUTION_TOL
    np.testing.assert_allclose(v_after[:2], 0.0, atol=1e-12)


def _one_impact(sim, n_max):
    """``test_engine._impact`` of particle 0, counting the contacts at each step: returns
    (duration, v before, v after, most contacts at one step)."""
    most = [0]

    def in_contact(s):
        n_c = len(s.contacts()["i"])
        most[0] = max(most[0], n_c)
        return n_c > 0

    dur, vb, va = _impact(sim, 0, n_max, in_contact)
    return dur, vb, va, most[0]


def test_hertz_mindlin_facet_impact_is_the_sphere_on_a_plane():
    """Oracle: Hertz's impact of a sphere on a plane (R* = r, Johnson 1985) through a triangle
    mesh (``soil.Material.contact_law="hertz_mindlin"``): one contact at a shared vertex, the
    duration 2.9432 delta_max / v (+-2 dt) and the rebound 1 (1e-3); a facet takes the
    grain's own radius as a plane does (the linear law's facet convention 2r is not Hertz's)."""
    from soil.contact_laws import hertz_contact_duration

    nu = 0.25
    m = 4.0 / 3.0 * math.pi * R**3 * RHO
    t_c = hertz_contact_duration(m, E / (2 * (1 - nu**2)), R, 1.0)
    dt = t_c / 400
    mesh = TriangleMesh.plane_patch((1.0, 1.0), (3, 3))
    p = soil.Particles(x=[[1 / 6, 1 / 6, R + 1e-6]], radius=[R], v=[[0.0, 0.0, -1.0]])
    mat = soil.Material(young=E, density=RHO, friction_angle=0.0, contact_law="hertz_mindlin",
                        poisson=nu)
    sim = soil.Simulation(p, [mat], [soil.BoundaryBody(shapes=[mesh])], gravity=(0, 0, 0),
                          dt=dt)
    dur, v_before, v_after, max_contacts = _one_impact(sim, 4000)
    assert max_contacts == 1
    assert abs(dur - t_c) <= 2 * dt
    assert abs(-v_after[2] / v_before[2] - 1.0) < 1e-3
