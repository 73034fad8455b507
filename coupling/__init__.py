"""DEM <-> Exudyn coupling of crashdem.

Public API
----------
CoSimulation(sim, body_index, model, exchange_every=1) : the exchange loop (DEM owns time);
    .run(t_end, on_step=cb), .exchange(), .ledger, .momentum_balance(), .body_state(),
    .state_dict() / CoSimulation.from_state_dict(sim, body_index, model, d)
EnergyLedger : energy accounts of the coupled system
boundary_for(spec, material, ...) : the ``soil.BoundaryBody`` matching a ``RigidBodySpec``
rotation_increment(w, dt) : expm(skew(w) dt)
"""

from .cosim import CoSimulation, EnergyLedger, rotation_increment
from .shapes import boundary_for

__all__ = ["CoSimulation", "EnergyLedger", "boundary_for", "rotation_increment"]
