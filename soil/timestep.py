"""Critical time step estimates."""

from __future__ import annotations

import numpy as np

__all__ = ["pwave_time_step", "stiffness_time_step"]


def pwave_time_step(radius: np.ndarray, young: np.ndarray, density: np.ndarray) -> float:
    """P-wave time step dt_p = min_i r_i / sqrt(E_i / rho_i) [s].

    Parameters
    ----------
    radius : (N,) [m]
    young : (N,) [Pa]
        Young's modulus of each particle's material.
    density : (N,) [kg/m^3]

    Notes
    -----
    Yade ``PWaveTimeStep()`` (utils).
    """
    if len(radius) == 0:
        return float("inf")
    return float(np.min(radius / np.sqrt(young / density)))


def stiffness_time_step(mass: np.ndarray, stiffness_sum: np.ndarray) -> float:
    """Contact-stiffness time step dt_k = min_i sqrt(m_i / sum_c k_n,c) [s] (inf without contacts).

    Notes
    -----
    Yade ``GlobalStiffnessTimeStepper`` (sqrt(m/K) per body, translational part, with the
    directional stiffness bounded by the sum of the normal stiffnesses since ks <= kn).
    """
    mask = stiffness_sum > 0.0
    if not np.any(mask):
        return float("inf")
    return float(np.min(np.sqrt(mass[mask] / stiffness_sum[mask])))
