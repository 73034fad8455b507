"""``soil.portable``: the element-wise functions whose bits must not depend on the CPU."""
from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

import soil
from soil.portable import cube, sphere_volume


@settings(deadline=None, max_examples=30)
@given(st.lists(st.floats(1e-6, 1e3), min_size=1, max_size=200))
def test_cube_is_the_c_librarys_pow(values):
    """Oracle: Python's ``math.pow`` (the C library's ``pow``), element by element, bit for bit
    (NumPy's ``a ** 3`` is one bit off it on AVX-512 CPUs)."""
    a = np.array(values)
    got = cube(a)
    want = np.array([math.pow(v, 3.0) for v in values])
    assert got.dtype == np.float64 and np.array_equal(got, want)
    assert np.array_equal(sphere_volume(a), 4.0 / 3.0 * np.pi * want)


def test_grain_masses_come_from_the_portable_cube():
    """Oracle: 4/3 pi pow(r, 3) rho from the C library, bit for bit, for every grain (the input
    a chaotic DEM run amplifies: one bit gives another realisation of a bed)."""
    rng = np.random.default_rng(4)
    r = rng.uniform(0.04, 0.06, 257)
    p = soil.Particles(x=np.zeros((257, 3)), radius=r)
    p.set_masses(np.array([2650.0]))
    want = np.array([4.0 / 3.0 * math.pi * math.pow(v, 3.0) * 2650.0 for v in r])
    assert np.array_equal(p.mass, want)
