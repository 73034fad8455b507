"""Scalar contact laws (Numba), each testable alone.

Conventions: the normal ``n`` points from body i to body j (for a boundary contact: from the
wall to the particle), the overlap ``delta > 0`` in compression, and the normal force ``fn`` is
positive in compression (repulsive). Shear springs are stored as forces acting on body j (Yade
``shearForce``), updated incrementally: ``Fs <- rotate(Fs) - ks * du_s``.
"""

from __future__ import annotations

import functools
import math

import numba

jit = functools.partial(numba.njit, cache=True)

__all__ = [
    "normal_stiffness",
    "shear_stiffness",
    "damping_ratio",
    "damping_coefficient",
    "rotate_shear",
    "linear_normal_force",
    "coulomb_cap",
    "cohesive_normal_force",
    "cohesive_shear_cap",
    "moment_cap",
    "rolling_stiffness",
    "contact_duration",
    "no_tension_restitution",
    "rebound_restitution",
    "hertz_coefficients",
    "hertz_damping_coefficient",
    "hertz_normal_dissipation",
    "varying_spring_dissipation",
    "hertz_max_overlap",
    "hertz_contact_duration",
]

#: ``Material.contact_law`` codes in the material table (``soil._kernels.M_LAW``)
LAW_LINEAR = 0
LAW_HERTZ_MINDLIN = 1
#: the contact laws by name, in code order
CONTACT_LAWS = ("linear", "hertz_mindlin")


@jit
def normal_stiffness(young_i: float, r_i: float, young_j: float, r_j: float) -> float:
    """Normal stiffness of two springs in series, k_n = 2 E_i R_i E_j R_j / (E_i R_i + E_j R_j).

    Parameters
    ----------
    young_i, young_j : float
        Young's moduli [Pa].
    r_i, r_j : float
        Characteristic radii on each side [m] (sphere radius; wall side: the sphere's own
        radius; triangle facet side: 2 r).

    Returns
    -------
    float
        k_n [N/m].

    Notes
    -----
    Varriale (2019) eqs. 3.2-3.6; Yade ``Ip2_FrictMat_FrictMat_FrictPhys``.
    """
    a = young_i * r_i
    b = young_j * r_j
    return 2.0 * a * b / (a + b)


@jit
def shear_stiffness(
    young_i: float, r_i: float, ratio_i: float, young_j: float, r_j: float, ratio_j: float
) -> float:
    """Shear stiffness in series form.

    k_s = 2 (E_i R_i v_i)(E_j R_j v_j) / (E_i R_i v_i + E_j R_j v_j).

    ``v`` is the ks/kn ratio (Yade ``FrictMat.poisson``). Equal ratios give k_s = v k_n.

    Returns
    -------
    float
        k_s [N/m]; 0 when either side has ratio 0.

    Notes
    -----
    Yade ``Ip2_FrictMat_FrictMat_FrictPhys`` (Ks = 2 Ea Ra Va Eb Rb Vb / (Ea Ra Va + Eb Rb Vb)).
    """
    a = young_i * r_i * ratio_i
    b = young_j * r_j * ratio_j
    if a + b <= 0.0:
        return 0.0
    return 2.0 * a * b / (a + b)


@jit
def damping_ratio(restitution: float) -> float:
    """zeta = -ln e / sqrt(pi^2 + ln^2 e) for a linear spring-dashpot [-].

    Notes
    -----
    Exact restitution of the linear damped oscillator (e.g. Schwager & Poeschel 2007).
    """
    if restitution >= 1.0:
        return 0.0
    le = math.log(restitution)
    return -le / math.sqrt(math.pi * math.pi + le * le)


@jit
def damping_coefficient(zeta: float, m_eff: float, kn: float) -> float:
    """c_n = 2 zeta sqrt(m* k_n) [N s/m].

    Notes
    -----
    Critical damping of a linear oscillator scaled by zeta.
    """
    return 2.0 * zeta * math.sqrt(m_eff * kn)


def no_tension_restitution(zeta: float) -> float:
    """Rebound ratio of a binary head-on contact under this module's normal law [-]: the linear
    spring-dashpot of damping ratio ``zeta`` whose force never pulls (``linear_normal_force``).

    The contact opens where k_n delta + c_n delta_dot first reaches 0, before the overlap is
    gone, so the dashpot does less work than in the full oscillator, and a contact of nominal
    restitution e (``damping_ratio(e)``, the convention of Yade's ``betan`` and of codes whose
    dashpot may pull) rebounds faster than e: 0.253 for e = 0.1, 0.325 for 0.2, 0.550 for 0.5.
    With the natural frequency 1 and x the overlap (x(0) = 0, x'(0) = 1):

    * zeta < 1: release at w_d t = pi - atan2(2 zeta w_d, 1 - 2 zeta^2), w_d = sqrt(1 - zeta^2);
    * zeta = 1: release at t = 2, ratio e^-2;
    * zeta > 1: release at t = ln((zeta + s) / (zeta - s)) / s, s = sqrt(zeta^2 - 1);

    the ratio is -x'(t) there (Schwager & Poeschel 2008, Granular Matter 10, "Coefficient of
    restitution and linear-dashpot model revisited"). Tested against an ODE integration and the
    engine's own rebound (tests/soil/test_engine.py).
    """
    z = float(zeta)
    if not math.isfinite(z) or z < 0.0:
        raise ValueError(f"zeta={zeta!r}: must be finite and >= 0 [-]")
    if z == 0.0:
        return 1.0
    if z < 1.0:
        wd = math.sqrt(1.0 - z * z)
        th = math.pi - math.atan2(2.0 * z * wd, 1.0 - 2.0 * z * z)
        t = th / wd
        return -math.exp(-z * t) * (math.cos(th) - z / wd * math.sin(th))
    if z == 1.0:
        return math.exp(-2.0)
    s = math.sqrt(z * z - 1.0)
    r1, r2 = -z + s, -z - s
    t = math.log((z + s) / (z - s)) / s
    return -(r1 * math.exp(r1 * t) - r2 * math.exp(r2 * t)) / (2.0 * s)


def rebound_restitution(restitution: float) -> float:
    """Rebound ratio of a head-on binary contact of nominal restitution e in (0, 1] under this
    module's normal law [-]: ``no_tension_restitution(damping_ratio(e))`` (0.253 for e = 0.1,
    0.325 for 0.2, 1 for 1)."""
    e = float(restitution)
    if not (0.0 < e <= 1.0):
        raise ValueError(f"restitution={restitution!r}: must be in (0, 1] [-]")
    return no_tension_restitution(damping_ratio(e))


@jit
def contact_duration(m_eff: float, kn: float) -> float:
    """Undamped linear-spring contact duration t_c = pi sqrt(m*/k_n) [s].

    Notes
    -----
    Half period of the harmonic oscillator.
    """
    return math.pi * math.sqrt(m_eff / kn)


@jit
def rotate_shear(fx, fy, fz, n0x, n0y, n0z, nx, ny, nz, twist):
    """Carry a tangential spring (force) vector with the contact frame.

    Parameters
    ----------
    fx, fy, fz : float
        Shear spring of the previous step.
    n0x, n0y, n0z : float
        Previous unit normal.
    nx, ny, nz : float
        Current unit normal.
    twist : float
        Twist angle about the normal during the step [rad] (0.5 dt n.(w_i + w_j)).

    Returns
    -------
    tuple of float
        The rotated spring, projected on the plane normal to ``n``.

    Notes
    -----
    Yade ``ScGeom::rotate``: F -= F x (n_prev x n); F -= F x (twist n); then the remaining
    normal component is removed (the task's projection rule).
    """
    # orthonormal axis a = n_prev x n
    ax = n0y * nz - n0z * ny
    ay = n0z * nx - n0x * nz
    az = n0x * ny - n0y * nx
    cx = fy * az - fz * ay
    cy = fz * ax - fx * az
    cz = fx * ay - fy * ax
    fx -= cx
    fy -= cy
    fz -= cz
    tx = twist * nx
    ty = twist * ny
    tz = twist * nz
    cx = fy * tz - fz * ty
    cy = fz * tx - fx * tz
    cz = fx * ty - fy * tx
    fx -= cx
    fy -= cy
    fz -= cz
    fn = fx * nx + fy * ny + fz * nz
    return fx - fn * nx, fy - fn * ny, fz - fn * nz


@jit
def linear_normal_force(kn: float, delta: float, cn: float, delta_dot: float,
                        tension: bool = False):
    """Linear spring (+ optional dashpot) normal force, no tension unless ``tension``.

    Parameters
    ----------
    kn : float
        Normal stiffness [N/m].
    delta : float
        Overlap [m] (> 0 in compression).
    cn : float
        Dashpot coefficient [N s/m] (0 = undamped).
    delta_dot : float
        Overlap rate [m/s] (> 0 approaching).
    tension : bool
        The dashpot may pull while the contact opens (the overlap still > 0): Yade's
        ``Law2_ScGeom_FrictViscoPhys_CundallStrackVisco`` and codes like it. Then a head-on
        binary contact rebounds at exactly the nominal restitution.

    Returns
    -------
    fn : float
        Normal force [N], >= 0 unless ``tension``.
    f_visc : float
        Non-elastic part fn - kn delta [N] (its power f_visc * delta_dot is dissipated).

    Notes
    -----
    Cundall & Strack (1979); Yade ``Law2_ScGeom_FrictPhys_CundallStrack``. A damped linear
    spring goes tensile just before separation; the force is clamped at 0 (no tension), unless
    ``tension``.
    """
    fe = kn * delta
    fn = fe + cn * delta_dot
    if fn < 0.0 and not tension:
        fn = 0.0
    return fn, fn - fe


@jit
def coulomb_cap(fx, fy, fz, fn_limit, ks):
    """Cap a trial shear force at the Coulomb limit |F_s| <= fn_limit.

    Parameters
    ----------
    fx, fy, fz : float
        Trial shear force [N].
    fn_limit : float
        Maximum shear force [N] (|F_n| tan phi, plus adhesion for bonds).
    ks : float
        Shear stiffness [N/m] (for the dissipated energy).

    Returns
    -------
    tuple
        (fx, fy, fz, dissipated [J], slipped)

    Notes
    -----
    Yade ``Law2_ScGeom_FrictPhys_CundallStrack``; plastic dissipation
    ((trial - capped)/ks) . capped as in Yade's ``plasticDissipation``.
    """
    f2 = fx * fx + fy * fy + fz * fz
    lim = fn_limit if fn_limit > 0.0 else 0.0
    if f2 <= lim * lim:
        return fx, fy, fz, 0.0, False
    f = math.sqrt(f2)
    s = lim / f
    cx = fx * s
    cy = fy * s
    cz = fz * s
    diss = 0.0
    if ks > 0.0:
        diss = ((fx - cx) * cx + (fy - cy) * cy + (fz - cz) * cz) / ks
    return cx, cy, cz, diss, True


@jit
def cohesive_normal_force(kn: float, un: float, unp: float, an: float, plastic: bool):
    """Normal force of a (possibly) bonded contact, compression positive.

    F_n = kn (u_n - u_n^p), limited below by -a_n (tension). Fragile bond (plastic=False):
    exceeding the limit breaks the bond (returned flag), and the force becomes max(kn u_n, 0).
    Plastic bond: F_n = -a_n and u_n^p = u_n + a_n / kn.

    Parameters
    ----------
    kn : float
        [N/m]
    un : float
        Overlap [m] (negative = gap, tension for a bond).
    unp : float
        Plastic normal displacement [m].
    an : float
        Normal adhesion [N] (0 = no bond).
    plastic : bool

    Returns
    -------
    tuple
        (fn [N], unp_new [m], broken [bool], plastic_work [J])

    Notes
    -----
    Yade ``Law2_ScGeom6D_CohFrictPhys_CohesionMoment::go`` (normal part); Varriale (2019)
    section 3.2.3.
    """
    fn = kn * (un - unp)
    if -fn > an:
        if plastic and an > 0.0:
            unp_new = un + an / kn
            return -an, unp_new, False, an * abs(unp_new - unp)
        # fragile: bond (if any) breaks, purely frictional contact from now on
        fn = kn * un
        if fn < 0.0:
            fn = 0.0
        return fn, 0.0, an > 0.0, 0.0
    return fn, unp, False, 0.0


@jit
def cohesive_shear_cap(fx, fy, fz, fn, tan_phi, at, bonded, ks):
    """Shear limit of a cohesive contact: |F_s| <= a_t + F_n tan(phi) (>= 0).

    A bonded (fragile) contact that reaches the limit breaks: a_t = 0 and the limit becomes
    max(0, F_n tan phi).

    Returns
    -------
    tuple
        (fx, fy, fz, dissipated [J], broken [bool])

    Notes
    -----
    Yade ``Law2_ScGeom6D_CohFrictPhys_CohesionMoment::go`` (shear part, cohesionDisablesFriction
    = False).
    """
    lim = at + fn * tan_phi
    if lim < 0.0:
        lim = 0.0
    f2 = fx * fx + fy * fy + fz * fz
    if f2 <= lim * lim:
        return fx, fy, fz, 0.0, False
    broken = False
    if bonded:
        broken = True
        lim = fn * tan_phi
        if lim < 0.0:
            lim = 0.0
    gx, gy, gz, diss, _ = coulomb_cap(fx, fy, fz, lim, ks)
    return gx, gy, gz, diss, broken


@jit
def moment_cap(mx, my, mz, m_limit, k):
    """Cap an elastic moment spring at |M| <= m_limit (m_limit < 0: no cap).

    Returns
    -------
    tuple
        (mx, my, mz, dissipated [J])

    Notes
    -----
    Yade ``Law2_ScGeom6D_CohFrictPhys_CohesionMoment`` (etaRoll/etaTwist caps); Ai et al. (2011)
    type C rolling limit; dissipation ((trial - capped)/k) . capped.
    """
    if m_limit < 0.0:
        return mx, my, mz, 0.0
    gx, gy, gz, diss, _ = coulomb_cap(mx, my, mz, m_limit, k)
    return gx, gy, gz, diss


@jit
def rolling_stiffness(kn: float, mu_r: float, r_eff: float) -> float:
    """Rolling stiffness k_r = 2.25 k_n mu_r^2 R*^2 [N m/rad].

    Notes
    -----
    Ai, Chen, Rotter & Ooi (2011), Powder Technol. 206, eq. 11 (type C model).
    """
    return 2.25 * kn * mu_r * mu_r * r_eff * r_eff


@jit
def spring_dissipation(ox, oy, oz, fx, fy, fz, dux, duy, duz, k):
    """Energy dissipated by a capped incremental spring over one step (centred form).

    D = -1/2 (F_old + F_new) . du - (|F_new|^2 - |F_old|^2) / (2 k): the trapezoidal work put
    into the spring minus the change of its stored energy. It is exactly 0 while the spring
    sticks, equals Yade's ((trial - capped)/k) . capped in steady sliding, and, unlike Yade's
    form, stays second-order consistent with the leapfrog kinetic energy when the cap varies in
    time (Yade's form lags half a step: an O(dt) ledger error in impacts).

    Parameters
    ----------
    ox, oy, oz : float
        Spring force (or moment) of the previous step, carried to the current frame.
    fx, fy, fz : float
        Capped spring force of this step.
    dux, duy, duz : float
        Relative displacement (or rotation) increment of this step (F_trial = F_old - k du).
    k : float
        Spring stiffness.

    Notes
    -----
    Work identity of the leapfrog scheme: KE_{n+1/2} - KE_{n-1/2} = F_n . (x_{n+1} - x_{n-1}) / 2.
    """
    if k <= 0.0:
        return 0.0
    w = -0.5 * ((ox + fx) * dux + (oy + fy) * duy + (oz + fz) * duz)
    de = 0.5 * ((fx * fx + fy * fy + fz * fz) - (ox * ox + oy * oy + oz * oz)) / k
    return w - de


@jit
def normal_dissipation(fn_old, fn, delta, d_delta, kn):
    """Energy dissipated by a damped normal contact over one step (centred form).

    D = 1/2 (F_old + F_new) d_delta - kn (delta_+^2 - delta_old,+^2) / 2, with
    delta_old = delta - d_delta and x_+ = max(x, 0): trapezoidal work of the normal force minus the
    change of the elastic energy (the dashpot power, consistent with the leapfrog work identity).

    Parameters
    ----------
    fn_old, fn : float
        Normal force of the previous and of this step [N].
    delta : float
        Overlap now [m]; d_delta : overlap increment of the step [m].
    kn : float
        [N/m].

    Notes
    -----
    Leapfrog work identity KE_{n+1/2} - KE_{n-1/2} = F_n . (x_{n+1} - x_{n-1}) / 2.
    """
    d0 = delta - d_delta
    e1 = delta if delta > 0.0 else 0.0
    e0 = d0 if d0 > 0.0 else 0.0
    return 0.5 * (fn_old + fn) * d_delta - 0.5 * kn * (e1 * e1 - e0 * e0)


# ----------------------------------------------------------------------------------------------
# Hertz-Mindlin (no-slip Mindlin shear, Thornton's unloading rule, Tsuji's damping)
# ----------------------------------------------------------------------------------------------
@jit
def hertz_coefficients(young_i: float, nu_i: float, young_j: float, nu_j: float,
                       r_eff: float):
    """Coefficients of the Hertz-Mindlin contact: ``(k_no, k_so)`` with the normal force
    F_n = k_no delta^(3/2) and the tangent shear stiffness k_s = k_so delta^(1/2).

    k_no = 4/3 E* sqrt(R*), k_so = 8 G* sqrt(R*), with 1/E* = (1 - nu_i^2)/E_i
    + (1 - nu_j^2)/E_j and 1/G* = (2 - nu_i)/G_i + (2 - nu_j)/G_j, G = E / (2 (1 + nu)).

    Parameters
    ----------
    young_i, young_j : float
        Young's moduli [Pa].
    nu_i, nu_j : float
        Poisson's ratios [-] (true ones, not the linear law's ks/kn).
    r_eff : float
        Effective radius R* [m]: R_i R_j / (R_i + R_j) for two spheres, the sphere's own radius
        on a plane.

    Returns
    -------
    tuple of float
        (k_no [N/m^1.5], k_so [N/m^1.5]).

    Notes
    -----
    Hertz (1882); Mindlin (1949) no-slip tangential stiffness 8 G* a with the contact radius
    a = sqrt(R* delta) (e.g. Di Renzo & Di Maio 2004, Chem. Eng. Sci. 59:525, eqs. 1-6). For
    two grains of one material k_so = 4 G sqrt(R*) / (2 - nu), Yade's
    ``Ip2_FrictMat_FrictMat_MindlinPhys`` ``kso`` (which averages G and nu between two
    materials where this form is exact in series).
    """
    e_star = 1.0 / ((1.0 - nu_i * nu_i) / young_i + (1.0 - nu_j * nu_j) / young_j)
    g_i = young_i / (2.0 * (1.0 + nu_i))
    g_j = young_j / (2.0 * (1.0 + nu_j))
    g_star = 1.0 / ((2.0 - nu_i) / g_i + (2.0 - nu_j) / g_j)
    sr = math.sqrt(r_eff)
    return 4.0 / 3.0 * e_star * sr, 8.0 * g_star * sr


@jit
def hertz_damping_coefficient(zeta: float, m_eff: float, kn_tangent: float) -> float:
    """Normal dashpot of the Hertz contact, c_n = 2 sqrt(5/6) zeta sqrt(m* k_n,t) [N s/m].

    ``k_n,t = 3/2 k_no delta^(1/2)`` is the tangent normal stiffness, so c_n grows as
    delta^(1/4) and the restitution does not depend on the impact speed.

    Notes
    -----
    Tsuji, Tanaka & Ishida (1992), Powder Technol. 71:239; zeta from the nominal restitution
    as for the linear law (``damping_ratio``), the convention of Yade's
    ``Ip2_FrictMat_FrictMat_MindlinPhys.en`` (alpha sqrt(m*) delta^(1/4)) and of codes like it.
    """
    return 2.0 * math.sqrt(5.0 / 6.0) * zeta * math.sqrt(m_eff * kn_tangent)


@jit
def hertz_normal_dissipation(fn_old, fn, delta, delta_old, kno):
    """Energy dissipated by a damped Hertz contact over one step (centred form) [J].

    D = 1/2 (F_old + F_new) (delta - delta_old) - 2/5 k_no (delta_+^(5/2) - delta_old,+^(5/2)):
    the trapezoidal work of the normal force minus the change of the Hertz elastic energy
    (``normal_dissipation`` for the linear spring).
    """
    e1 = delta if delta > 0.0 else 0.0
    e0 = delta_old if delta_old > 0.0 else 0.0
    return (0.5 * (fn_old + fn) * (delta - delta_old)
            - 0.4 * kno * (e1 * e1 * math.sqrt(e1) - e0 * e0 * math.sqrt(e0)))


@jit
def varying_spring_dissipation(ox, oy, oz, fx, fy, fz, dux, duy, duz, k_old, k):
    """``spring_dissipation`` for a spring whose stiffness changed during the step [J].

    D = -1/2 (F_old + F_new) . du - (|F_new|^2 / (2 k) - |F_old|^2 / (2 k_old)): the trapezoidal
    work minus the change of the stored energy, each end with its own stiffness. With the
    Mindlin shear spring and Thornton's unloading rule (the stored force scaled by k / k_old
    when the overlap shrinks) D >= 0 to first order: a stiffening spring at constant force
    stores less, a softening one sheds the scaled-off part.

    Parameters
    ----------
    ox, oy, oz : float
        Spring force of the previous step carried to the current frame (before any scaling).
    fx, fy, fz : float
        Spring force of this step (scaled, capped).
    dux, duy, duz : float
        Relative displacement increment of this step.
    k_old, k : float
        Stiffness of the previous step and of this one (0 = nothing stored at that end).
    """
    w = -0.5 * ((ox + fx) * dux + (oy + fy) * duy + (oz + fz) * duz)
    e1 = 0.5 * (fx * fx + fy * fy + fz * fz) / k if k > 0.0 else 0.0
    e0 = 0.5 * (ox * ox + oy * oy + oz * oz) / k_old if k_old > 0.0 else 0.0
    return w - (e1 - e0)


def hertz_max_overlap(m_eff: float, e_star: float, r_eff: float, speed: float) -> float:
    """Largest overlap of an undamped Hertz impact, delta_max = (15 m* v^2 / (16 E* sqrt(R*)))
    ^(2/5) [m] (energy balance 1/2 m* v^2 = 2/5 k_no delta_max^(5/2))."""
    return (15.0 * m_eff * speed ** 2 / (16.0 * e_star * math.sqrt(r_eff))) ** 0.4


def hertz_contact_duration(m_eff: float, e_star: float, r_eff: float, speed: float) -> float:
    """Duration of an undamped Hertz impact, t_c = 2 (delta_max / v) int_0^1 dx / sqrt(1 -
    x^(5/2)) = 2.9432 delta_max / v [s] (Johnson 1985, Contact Mechanics, eq. 11.24)."""
    # int_0^1 (1 - x^(5/2))^(-1/2) dx = sqrt(pi) Gamma(7/5) / Gamma(9/10)
    c = math.sqrt(math.pi) * math.gamma(1.4) / math.gamma(0.9)
    return 2.0 * c * hertz_max_overlap(m_eff, e_star, r_eff, speed) / speed
