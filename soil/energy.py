"""Energy ledger of a soil simulation (totals computed on demand from kernel accumulators)."""

from __future__ import annotations

import numpy as np

__all__ = ["ENERGY_KEYS", "balance"]

#: Keys of ``Simulation.energy()`` (all [J] except ``balance_error_relative`` [-]).
ENERGY_KEYS = (
    "kinetic_translational",
    "kinetic_rotational",
    "elastic",
    "elastic_normal",
    "elastic_shear",
    "elastic_moment",
    "dissipated_friction",
    "dissipated_damping",
    "dissipated_viscous",
    "dissipated_global",
    "bond_dissipated",
    "work_gravity",
    "work_boundaries",
    "total",
    "balance_error",
    "balance_error_relative",
)


def balance(e: dict, total0: float) -> dict:
    """Complete the ledger ``e`` with the total and the balance error.

    total = KE_t + KE_r + elastic + dissipated (friction, damping, bonds) - W_gravity - W_bodies;
    balance_error = total - total(t=0) (0 for an exact balance); the relative error is scaled
    by the largest term of the ledger.

    Notes
    -----
    Energy conservation of the particle system with external work (Yade ``O.energy`` ledger
    convention: dissipation and work terms accumulated incrementally).
    """
    total = (
        e["kinetic_translational"] + e["kinetic_rotational"] + e["elastic"]
        + e["dissipated_friction"] + e["dissipated_damping"] + e["bond_dissipated"]
        - e["work_gravity"] - e["work_boundaries"]
    )
    e["total"] = total
    e["balance_error"] = total - total0
    scale = max(
        abs(e[k]) for k in ("kinetic_translational", "kinetic_rotational", "elastic",
                            "dissipated_friction", "dissipated_damping", "bond_dissipated",
                            "work_gravity", "work_boundaries")
    )
    scale = max(scale, abs(total0))
    e["balance_error_relative"] = float(e["balance_error"] / scale) if scale > 0.0 else 0.0
    return e


def kinetic(mass: np.ndarray, v_sync: np.ndarray) -> float:
    """Translational kinetic energy 1/2 sum m v^2 [J] (fixed summation order)."""
    return float(0.5 * np.dot(mass, np.einsum("ij,ij->i", v_sync, v_sync)))
