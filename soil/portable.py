"""Element-wise functions that give the same bits on every x86-64 machine.

NumPy dispatches some float64 ufuncs to AVX-512 code when the CPU has it (``np.show_runtime()``
lists ``X86_V4`` / ``AVX512_*`` under "found"). Their results differ from the C library's in the
last bit: ``exp``, ``log``, ``tan``, ``arcsin``, ``arccos``, ``arctan``, ``arctan2``, ``sinh``,
``cosh``, ``cbrt``, ``expm1``, ``log1p``, ``log2``, ``log10``, ``exp2`` and ``power`` with any
exponent but the special-cased 0.5, 1, 2 and -1 (so ``r ** 3``); ``sin``, ``cos``, ``sqrt``,
sums, products, ``dot`` and ``@`` agree (measured with ``NPY_DISABLE_CPU_FEATURES="AVX512_ICL
X86_V4"`` on an AMD EPYC Zen 5, NumPy 2.4.6). A DEM run is chaotic: one grain mass one bit off
gives another realisation of the bed. That was the difference between the machines of sessions
21-28 and session 30's (docs/diagnosis.md, "Another machine, another realisation"): grain
masses from ``4/3 pi r**3``. These functions go through the C library (Numba's ``math``, as
Python's own floats do), as NumPy does on a machine without AVX-512, so every machine gives the
results those machines gave.
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["cube", "sphere_volume"]


@numba.vectorize(["float64(float64)"], cache=True)
def _cube(v):
    return math.pow(v, 3.0)


def cube(a) -> np.ndarray:
    """``a ** 3`` element-wise, as the C library's ``pow`` gives it (float64 array)."""
    return _cube(np.asarray(a, dtype=np.float64))


def sphere_volume(radius) -> np.ndarray:
    """4/3 pi r^3 [m^3] element-wise, evaluated as ``4.0 / 3.0 * np.pi * cube(r)`` (the
    expression the engine used before with ``r**3``, so the rounding of the factors is kept)."""
    return 4.0 / 3.0 * np.pi * cube(radius)
