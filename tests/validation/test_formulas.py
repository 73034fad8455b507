"""Empirical cushion formulas against the [D] table of anchors.md section 1.1.

Oracle: the reference numbers of that table (850 kg, 0.90 m sphere; Japan with lambda = 1000 /
5000 kN/m^2; ASTRA with M_E = 1e4 / 5e4 kN/m^2, phi = 40 deg, e = 2 m, r = 0.45 m), derived
independently by hand from the formula text.
"""
from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from validation.campaign import formulas as fm

MASS = 850.0  # [kg]
RADIUS = 0.45  # [m]
#: The table prints forces to 1 kN: half a unit of the last printed digit [N].
FORCE_TOL = 0.5e3
#: Penetrations are printed to 0.01 m [m].
PEN_TOL = 0.005
#: Decelerations are printed to 1 g [g].
G_TOL = 0.5

# v [m/s], Japan 1000, Japan 5000, ASTRA 1e4, ASTRA 5e4 [kN], d [m], F/(m g) [g]
TABLE = [
    (9.9, 361, 687, 354, 675, 0.24, 43),
    (14.0, 547, 1041, 537, 1023, 0.31, 64),
    (16.4, 661, 1258, 649, 1236, 0.35, 78),
    (19.0, 789, 1501, 775, 1475, 0.40, 93),
]


@pytest.mark.parametrize("row", TABLE, ids=[f"v{r[0]}" for r in TABLE])
def test_japan_matches_anchor_table(row):
    """Oracle: anchors.md [D] table, Japan column (H = v^2 / 2g)."""
    v, j1, j5 = row[0], row[1], row[2]
    h = fm.fall_height(v)
    assert fm.japan_force(MASS, h, 1e6) == pytest.approx(j1 * 1e3, abs=FORCE_TOL)
    assert fm.japan_force(MASS, h, 5e6) == pytest.approx(j5 * 1e3, abs=FORCE_TOL)


@pytest.mark.parametrize("row", TABLE, ids=[f"v{r[0]}" for r in TABLE])
def test_astra_matches_anchor_table(row):
    """Oracle: anchors.md [D] table, ASTRA columns, penetration d = m v^2 / F and F / (m g)."""
    v, a1, a5, d, g_ratio = row[0], row[3], row[4], row[5], row[6]
    phi = math.radians(40.0)
    f1 = fm.astra_force(MASS, v, RADIUS, 2.0, 1e7, phi)
    assert f1 == pytest.approx(a1 * 1e3, abs=FORCE_TOL)
    assert fm.astra_force(MASS, v, RADIUS, 2.0, 5e7, phi) == pytest.approx(a5 * 1e3, abs=FORCE_TOL)
    assert fm.triangular_penetration(MASS, v, f1) == pytest.approx(d, abs=PEN_TOL)
    assert f1 / (MASS * fm.G) == pytest.approx(g_ratio, abs=G_TOL)


@settings(max_examples=50, deadline=None)
@given(v=st.floats(1.0, 40.0), k=st.floats(1.1, 10.0))
def test_scaling_exponents(v, k):
    """Oracle: the formulas' exponents (F ~ H^0.6 ~ v^1.2; ~ lambda^0.4; ~ e^-0.5)."""
    h = fm.fall_height(v)
    rel = 1e-12
    assert fm.japan_force(MASS, k * h, 1e6) / fm.japan_force(MASS, h, 1e6) == pytest.approx(
        k ** 0.6, rel=rel)
    assert fm.japan_force(MASS, h, k * 1e6) / fm.japan_force(MASS, h, 1e6) == pytest.approx(
        k ** 0.4, rel=rel)
    phi = math.radians(35.0)
    a = fm.astra_force(MASS, v, RADIUS, 2.0, 1e7, phi)
    assert fm.astra_force(MASS, v, RADIUS, 2.0 * k, 1e7, phi) / a == pytest.approx(
        k ** -0.5, rel=rel)
    assert fm.astra_force(MASS, v * k, RADIUS, 2.0, 1e7, phi) / a == pytest.approx(
        k ** 1.2, rel=rel)


@pytest.mark.parametrize("call", [
    lambda: fm.japan_force(-1.0, 5.0, 1e6),
    lambda: fm.japan_force(850.0, 0.0, 1e6),
    lambda: fm.astra_force(850.0, 10.0, 0.45, 2.0, 1e7, math.pi / 2),
    lambda: fm.astra_force(850.0, 10.0, 0.45, -2.0, 1e7, 0.5),
    lambda: fm.triangular_penetration(850.0, 10.0, 0.0),
])
def test_invalid_inputs_name_the_field(call):
    """Invalid inputs raise ValueError naming the field and the allowed range."""
    with pytest.raises(ValueError, match=r"=.*must be"):
        call()
