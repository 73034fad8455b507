"""Frozen, validated parameter dataclasses of the soil DEM engine.

Every field carries its unit in a comment; ``__post_init__`` checks the allowed range and the
error names the field, the value and the range, e.g.
``ValueError("Material.young=-3e7: must be > 0 [Pa]")``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

from .contact_laws import CONTACT_LAWS

__all__ = ["Cohesion", "Rolling", "Material"]


def _fail(cls: str, field: str, value, rule: str) -> None:
    raise ValueError(f"{cls}.{field}={value!r}: {rule}")


def _finite(cls: str, field: str, value) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        _fail(cls, field, value, "must be a real number")
    if not math.isfinite(v):
        _fail(cls, field, value, "must be finite")
    return v


def _positive(cls: str, field: str, value, unit: str) -> None:
    if _finite(cls, field, value) <= 0.0:
        _fail(cls, field, value, f"must be > 0 [{unit}]")


def _non_negative(cls: str, field: str, value, unit: str) -> None:
    if _finite(cls, field, value) < 0.0:
        _fail(cls, field, value, f"must be >= 0 [{unit}]")


@dataclass(frozen=True)
class Cohesion:
    """Cohesive-frictional bond parameters (Yade ``CohFrictMat`` / ``CohFrictPhys``).

    Parameters
    ----------
    normal_strength : float
        Tensile strength [Pa]; bond normal adhesion a_n = normal_strength * min(R1, R2)^2 [N].
    shear_strength : float
        Shear strength [Pa]; a_t = shear_strength * min(R1, R2)^2 [N].
    bending_modulus_factor : float
        alphaKr [-]: bending stiffness k_b = alphaKr * ks * R1 * R2 [N m/rad].
    twisting_modulus_factor : float
        alphaKtw [-]: twisting stiffness k_t = alphaKtw * ks * R1 * R2 [N m/rad].
    bending_cap : float or None
        etaRoll [-]: |M_b| <= etaRoll * min(R1, R2) * |F_n| (behaves as rolling friction);
        None = no cap (Yade etaRoll < 0).
    twisting_cap : float or None
        etaTwist [-]: |M_t| <= etaTwist * min(R1, R2) * |F_n|; None = no cap.
    plastic : bool
        False (Yade ``fragile=True``): reaching the tensile limit breaks the bond. True: normal
        plasticity, the tensile force stays at -a_n and the plastic normal displacement grows.
    moments : bool
        Whether bonded contacts carry bending/twisting moments (Yade ``momentRotationLaw``).

    Notes
    -----
    Yade ``Ip2_CohFrictMat_CohFrictMat_CohFrictPhys`` (adhesions from strength * min(R)^2,
    kr = alphaKr ks R1 R2) and thesis Varriale (2019) section 3.2.3.
    """

    normal_strength: float  # [Pa], >= 0
    shear_strength: float  # [Pa], >= 0
    bending_modulus_factor: float = 0.0  # [-], >= 0
    twisting_modulus_factor: float = 0.0  # [-], >= 0
    bending_cap: float | None = None  # [-], >= 0 or None
    twisting_cap: float | None = None  # [-], >= 0 or None
    plastic: bool = False
    moments: bool = True

    def __post_init__(self) -> None:
        c = "Cohesion"
        _non_negative(c, "normal_strength", self.normal_strength, "Pa")
        _non_negative(c, "shear_strength", self.shear_strength, "Pa")
        _non_negative(c, "bending_modulus_factor", self.bending_modulus_factor, "-")
        _non_negative(c, "twisting_modulus_factor", self.twisting_modulus_factor, "-")
        if self.bending_cap is not None:
            _non_negative(c, "bending_cap", self.bending_cap, "-")
        if self.twisting_cap is not None:
            _non_negative(c, "twisting_cap", self.twisting_cap, "-")


@dataclass(frozen=True)
class Rolling:
    """Rolling resistance, Ai, Chen, Rotter & Ooi (2011) type C (EPSD without viscous part).

    Parameters
    ----------
    coefficient : float
        mu_r [-]: k_r = 2.25 k_n mu_r^2 R*^2, |M_r| <= mu_r R* |F_n|.

    Notes
    -----
    Ai J., Chen J.-F., Rotter J. M., Ooi J. Y. (2011) Powder Technol. 206:269-282, eqs. 11-13.
    """

    coefficient: float  # [-], >= 0

    def __post_init__(self) -> None:
        _non_negative("Rolling", "coefficient", self.coefficient, "-")


@dataclass(frozen=True)
class Material:
    """Soil / wall material (Yade ``FrictMat`` + optional cohesion and rolling resistance).

    Parameters
    ----------
    young : float
        Young's modulus E [Pa] (contact modulus, thesis eq. 3.2-3.6).
    density : float
        Grain density [kg/m^3].
    friction_angle : float
        Inter-particle friction angle phi [rad], in [0, pi/2).
    stiffness_ratio : float
        ks/kn (Yade ``FrictMat.poisson``) [-], in [0, 1].
    restitution : float or None
        Coefficient of restitution e in (0, 1] for viscous normal damping; None = no damping.
    shear_restitution : float or None
        Restitution e_s in (0, 1] of a viscous *shear* dashpot in parallel with the shear
        spring; None = none (the default, and the thesis's). Its damping ratio is
        ``damping_ratio(e_s)`` of the shear spring: c_s = 2 zeta_s sqrt(m* k_s) with the linear
        law, 2 sqrt(5/6) zeta_s sqrt(m* k_s,t) (Tsuji's form, as the normal dashpot's) with the
        Hertz-Mindlin law, where k_s,t is the Mindlin tangent shear stiffness. It acts while
        the contact sticks and is switched off while it slides (Yade
        ``Law2_ScGeom_ViscElPhys_Basic`` and ``Law2_ScGeom_MindlinPhys_Mindlin`` with
        ``betas`` / ``es``; EDEM's and LIGGGHTS' Hertz-Mindlin damp the shear at the normal
        ratio). Not on cohesive bonds. A pair takes the smaller of its two materials' values.
    dashpot_tension : bool
        The normal dashpot may pull while a contact opens (Yade
        ``Law2_ScGeom_FrictViscoPhys_CundallStrackVisco``, and codes like it); default False: the
        contact force never pulls (``contact_laws.linear_normal_force``). No effect without
        ``restitution``.
    cohesion : Cohesion or None
    rolling : Rolling or None
    name : str
    contact_law : str
        ``"linear"`` (default): Cundall-Strack springs k_n = E r, k_s = stiffness_ratio k_n
        (Yade ``Law2_ScGeom_FrictPhys_CundallStrack``, the thesis's law). ``"hertz_mindlin"``:
        F_n = 4/3 E* sqrt(R*) delta^(3/2) and the Mindlin shear stiffness 8 G* sqrt(R* delta)
        from ``young`` and ``poisson`` (``contact_laws.hertz_coefficients``), the shear force
        scaled down with the stiffness when the overlap shrinks (Thornton), the dashpot of
        ``restitution`` as Tsuji's (``contact_laws.hertz_damping_coefficient``). With
        ``cohesion`` a bond is the cohesive law's linear springs (from ``young`` and
        ``stiffness_ratio``); a contact without a bond, or whose bond broke, is Hertz-Mindlin.
        A pair of two materials uses the Hertz-Mindlin law when either has it.
    poisson : float
        Poisson's ratio nu [-], in [0, 0.5); used by ``contact_law="hertz_mindlin"`` only (the
        linear law's ks/kn is ``stiffness_ratio``).

    Notes
    -----
    Yade ``Ip2_FrictMat_FrictMat_FrictPhys``; Varriale (2019) eqs. 3.2-3.6; Hertz-Mindlin as
    Yade ``Law2_ScGeom_MindlinPhys_Mindlin``.
    """

    young: float  # [Pa], > 0
    density: float  # [kg/m^3], > 0
    friction_angle: float  # [rad], in [0, pi/2)
    stiffness_ratio: float = 0.25  # [-], in [0, 1]
    restitution: float | None = None  # [-], in (0, 1] or None
    dashpot_tension: bool = False
    cohesion: Cohesion | None = None
    rolling: Rolling | None = None
    name: str = "material"
    contact_law: str = "linear"  # "linear" | "hertz_mindlin"
    poisson: float = 0.25  # [-], in [0, 0.5); Hertz-Mindlin only
    shear_restitution: float | None = None  # [-], in (0, 1] or None

    def __post_init__(self) -> None:
        c = "Material"
        _positive(c, "young", self.young, "Pa")
        _positive(c, "density", self.density, "kg/m^3")
        phi = _finite(c, "friction_angle", self.friction_angle)
        if not 0.0 <= phi < 0.5 * math.pi:
            _fail(c, "friction_angle", self.friction_angle, "must be in [0, pi/2) [rad]")
        sr = _finite(c, "stiffness_ratio", self.stiffness_ratio)
        if not 0.0 <= sr <= 1.0:
            _fail(c, "stiffness_ratio", self.stiffness_ratio, "must be in [0, 1] [-]")
        if self.restitution is not None:
            e = _finite(c, "restitution", self.restitution)
            if not 0.0 < e <= 1.0:
                _fail(c, "restitution", self.restitution, "must be in (0, 1] or None [-]")
        if self.shear_restitution is not None:
            es = _finite(c, "shear_restitution", self.shear_restitution)
            if not 0.0 < es <= 1.0:
                _fail(c, "shear_restitution", self.shear_restitution,
                      "must be in (0, 1] or None [-]")
        if not isinstance(self.dashpot_tension, bool):
            _fail(c, "dashpot_tension", self.dashpot_tension, "must be a bool")
        if self.cohesion is not None and not isinstance(self.cohesion, Cohesion):
            _fail(c, "cohesion", self.cohesion, "must be a soil.Cohesion or None")
        if self.rolling is not None and not isinstance(self.rolling, Rolling):
            _fail(c, "rolling", self.rolling, "must be a soil.Rolling or None")
        if not isinstance(self.name, str):
            _fail(c, "name", self.name, "must be a str")
        if self.contact_law not in CONTACT_LAWS:
            _fail(c, "contact_law", self.contact_law, f"must be one of {CONTACT_LAWS}")
        nu = _finite(c, "poisson", self.poisson)
        if not 0.0 <= nu < 0.5:
            _fail(c, "poisson", self.poisson, "must be in [0, 0.5) [-]")

    @property
    def damping_ratio(self) -> float:
        """Viscous damping ratio zeta = -ln e / sqrt(pi^2 + ln^2 e) [-] (0 when e is None or 1).

        Notes
        -----
        Linear spring-dashpot restitution, e.g. Schwager & Poeschel (2007) / Yade
        ``Ip2_FrictMat_FrictMat_MindlinPhys`` betan convention for a linear spring; the value
        the contact kernels use (``contact_laws.damping_ratio``).
        """
        from .contact_laws import damping_ratio

        return 0.0 if self.restitution is None else damping_ratio(self.restitution)

    @property
    def rebound_restitution(self) -> float:
        """Rebound ratio of a head-on binary contact of two grains of this material [-]:
        ``restitution`` is the nominal one of the linear spring-dashpot (its ``damping_ratio``,
        as in Yade), and the contact force never pulls, so a contact opens early and rebounds
        faster (``contact_laws.no_tension_restitution``): 0.253 for e = 0.1, 0.325 for 0.2;
        e itself with ``dashpot_tension``. 1 when e is None or 1. What a rebound measured on
        grains, or another code's restitution whose dashpot may pull, compares with."""
        from .contact_laws import rebound_restitution

        if self.restitution is None:
            return 1.0
        return float(self.restitution) if self.dashpot_tension else rebound_restitution(
            self.restitution)

    def to_dict(self) -> dict:
        """Plain-dict form (nested dataclasses as dicts)."""
        out = {}
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, (Cohesion, Rolling)):
                v = {g.name: getattr(v, g.name) for g in fields(v)}
            out[f.name] = v
        return out

    @classmethod
    def from_dict(cls, d: dict) -> "Material":
        d = dict(d)
        if d.get("cohesion") is not None:
            d["cohesion"] = Cohesion(**d["cohesion"])
        if d.get("rolling") is not None:
            d["rolling"] = Rolling(**d["rolling"])
        return cls(**d)
