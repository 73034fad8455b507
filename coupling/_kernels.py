"""Small Numba kernels of the exchange (3-vectors and 3x3 matrices; SI units).

numpy calls on 3-vectors cost microseconds each in Python; these kernels keep the per-exchange
overhead of the coupling small beside a DEM step.
"""

import functools
import math

import numba
import numpy as np

jit = functools.partial(numba.njit, cache=True)


@jit
def rotation_increment(w, dt):
    """``expm(skew(w) dt)`` (3x3).

    Notes
    -----
    Rodrigues: ``exp(K) = I + sin(a)/a K + (1 - cos a)/a^2 K^2``, ``a = |w| dt``.
    """
    out = np.eye(3)
    kx = w[0] * dt
    ky = w[1] * dt
    kz = w[2] * dt
    a = math.sqrt(kx * kx + ky * ky + kz * kz)
    if a == 0.0:
        return out
    s = math.sin(a) / a
    c = (1.0 - math.cos(a)) / (a * a)
    k = np.array([[0.0, -kz, ky], [kz, 0.0, -kx], [-ky, kx, 0.0]])
    k2 = k @ k
    for i in range(3):
        for j in range(3):
            out[i, j] += s * k[i, j] + c * k2[i, j]
    return out


@jit
def newton_euler(force, torque, mass, gravity, rotation, inertia_body_inv, inertia_body, w):
    """Accelerations of a rigid body: ``a = F/m + g``, ``alpha = J_w^-1 (T - w x J_w w)``.

    Parameters
    ----------
    force, torque : (3,) world frame [N], [N m] (torque about the CG)
    mass : float [kg]
    gravity : (3,) [m/s^2]
    rotation : (3, 3) body -> world
    inertia_body_inv, inertia_body : (3, 3) about the CG, body axes [1/(kg m^2)], [kg m^2]
    w : (3,) world angular velocity [rad/s]

    Returns
    -------
    a, alpha : (3,) [m/s^2], [rad/s^2]

    Notes
    -----
    Newton–Euler equations about the CG (Goldstein, *Classical Mechanics*, §5.5), with
    ``J_w = R J R^T`` and ``J_w^-1 = R J^-1 R^T``.
    """
    a = np.empty(3)
    for i in range(3):
        a[i] = force[i] / mass + gravity[i]
    wb = rotation.T @ w  # body-frame angular velocity
    lb = inertia_body @ wb
    lw = rotation @ lb  # world angular momentum
    rhs = np.empty(3)
    rhs[0] = torque[0] - (w[1] * lw[2] - w[2] * lw[1])
    rhs[1] = torque[1] - (w[2] * lw[0] - w[0] * lw[2])
    rhs[2] = torque[2] - (w[0] * lw[1] - w[1] * lw[0])
    alpha = rotation @ (inertia_body_inv @ (rotation.T @ rhs))
    return a, alpha
