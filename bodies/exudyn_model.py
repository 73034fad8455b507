"""Exudyn model of one rigid body driven by external force and torque (the only exudyn import).

The body is an Exudyn ``CreateRigidBody`` with a rotation-vector (Lie-group) node at its CG, a
node marker, and a global force and torque load on it. An explicit RK44 solver is stepped
manually from Python so that a DEM code can own the time loop
(``/work/shared/reference/exudyn_coupling.md``).
"""

from __future__ import annotations

from typing import NamedTuple

import exudyn as exu
import exudyn.itemInterface as eii
import numpy as np
from exudyn.utilities import RigidBodyInertia

from .spec import RigidBodySpec

#: tolerance on the agreement of ``advance(t0, ...)`` with the model clock, relative to the
#: step length: times are sums of floats, so they agree to a few ulp of t, far below 1e-6 h.
TIME_MATCH_RTOL = 1e-6


class BodyState(NamedTuple):
    """Kinematic state of the rigid body in the world frame (SI).

    Attributes
    ----------
    position : (3,) CG position [m]
    rotation : (3, 3) rotation matrix body -> world [-]
    velocity : (3,) CG velocity [m/s]
    angular_velocity : (3,) world frame [rad/s]
    acceleration : (3,) CG acceleration from the last applied loads (gravity included) [m/s^2]
    angular_acceleration : (3,) world frame [rad/s^2]
    time : float [s]
    """

    position: np.ndarray
    rotation: np.ndarray
    velocity: np.ndarray
    angular_velocity: np.ndarray
    acceleration: np.ndarray
    angular_acceleration: np.ndarray
    time: float


def _vec3(x, name):
    a = np.asarray(x, dtype=np.float64).reshape(-1)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ValueError(f"ExudynRigidBody.{name}={x!r}: must be a finite 3-vector")
    return a


def _restart_explicit(body, ode2, ode2_t, exu_time: float, owner: str,
                      before_start=None) -> None:
    """Restart ``body``'s explicit Exudyn solver (``body._mbs``, ``body._ss``,
    ``body._solver``) from saved ODE2 coordinates and velocities at Exudyn time ``exu_time``.

    The explicit solver takes its state and clock from the initial configuration and
    ``timeIntegration.startTime`` when it is initialised (setting the current configuration of
    an initialised solver is not seen by its first step): both are set, then a fresh solver is
    initialised. ``before_start()`` runs just before that (state its user functions read).

    Raises
    ------
    ValueError naming ``owner`` when the vectors do not have the system's ODE2 size.
    """
    sd = body._mbs.systemData
    q = np.asarray(ode2, dtype=np.float64)
    q_t = np.asarray(ode2_t, dtype=np.float64)
    n = len(sd.GetODE2Coordinates())
    if q.shape != (n,) or q_t.shape != (n,):
        raise ValueError(f"{owner}.load_state_dict: ode2 shape {q.shape} / ode2_t shape "
                         f"{q_t.shape}: must be ({n},)")
    body._solver.FinalizeSolver(body._mbs, body._ss)
    body._solver = None
    sd.SetODE2Coordinates(q.tolist(), configuration=exu.ConfigurationType.Initial)
    sd.SetODE2Coordinates_t(q_t.tolist(), configuration=exu.ConfigurationType.Initial)
    if before_start is not None:
        before_start()
    body._exu_time = float(exu_time)
    body._ss.timeIntegration.startTime = body._exu_time
    body._solver = exu.MainSolverExplicit()
    body._solver.InitializeSolver(body._mbs, body._ss)


class _RigidBodyReadout:
    """The read-out of one Exudyn rigid-body node shared by :class:`ExudynRigidBody` and the
    rear body of ``bodies.crush.ExudynCrushableBody``. Needs ``_mbs``, ``_node``, ``spec``,
    ``gravity``, ``_force``, ``_torque`` and ``_time`` on the instance."""

    # ------------------------------------------------------------------ state
    @property
    def time(self) -> float:
        """Model clock [s]."""
        return self._time

    @property
    def mass(self) -> float:
        """Body mass [kg]."""
        return self.spec.mass

    @property
    def applied_force(self) -> np.ndarray:
        """Force currently applied through :meth:`apply` [N]."""
        return self._force.copy()

    @property
    def applied_torque(self) -> np.ndarray:
        """Torque currently applied through :meth:`apply` [N m]."""
        return self._torque.copy()

    def inertia_world(self, rotation=None) -> np.ndarray:
        """Inertia about the CG in world axes, ``R J R^T`` [kg m^2]."""
        r = self.rotation() if rotation is None else rotation
        return r @ self.spec.inertia @ r.T

    def position(self) -> np.ndarray:
        """CG position [m]."""
        return np.asarray(self._mbs.GetNodeOutput(self._node, exu.OutputVariableType.Position))

    def velocity(self) -> np.ndarray:
        """CG velocity [m/s]."""
        return np.asarray(self._mbs.GetNodeOutput(self._node, exu.OutputVariableType.Velocity))

    def rotation(self) -> np.ndarray:
        """Rotation matrix body -> world."""
        return np.asarray(self._mbs.GetNodeOutput(
            self._node, exu.OutputVariableType.RotationMatrix)).reshape(3, 3)

    def angular_velocity(self) -> np.ndarray:
        """Angular velocity in the world frame [rad/s]."""
        return np.asarray(self._mbs.GetNodeOutput(
            self._node, exu.OutputVariableType.AngularVelocity))

    def weight(self) -> np.ndarray:
        """Body weight ``m g`` [N]."""
        return self.spec.mass * self.gravity


class ExudynRigidBody(_RigidBodyReadout):
    """One free rigid body in Exudyn, advanced step by step under a held force and torque.

    Parameters
    ----------
    spec : RigidBodySpec
        Mass and inertia about the CG (body frame).
    position : array_like (3,)
        Initial CG position in the world frame [m].
    rotation : array_like (3, 3)
        Initial rotation matrix (body -> world) [-].
    velocity : array_like (3,)
        Initial CG velocity [m/s].
    angular_velocity : array_like (3,)
        Initial angular velocity in the world frame [rad/s].
    gravity : array_like (3,)
        Gravitational acceleration [m/s^2].
    gravity_in_exudyn : bool
        True: Exudyn applies the body weight ``m g`` itself; False: the body weight is NOT
        applied and the caller must include it in :meth:`apply`. The DEM's gravity acts on
        particles only, so with True the weight is counted exactly once.
    time : float
        Initial time of the model clock [s].
    steps_per_advance : int
        RK44 steps per :meth:`advance` call (the load is held over all of them).

    Notes
    -----
    Newton–Euler equations for the CG: ``m a = F + m g``, ``J_w alpha = T - omega x J_w omega``
    with ``J_w = R J R^T`` (Goldstein, *Classical Mechanics*, §5.5); integrated by Exudyn's
    explicit RK44 on a ``NodeRigidBodyRotVecLG`` node.
    """

    def __init__(self, spec: RigidBodySpec, position=(0.0, 0.0, 0.0), rotation=None,
                 velocity=(0.0, 0.0, 0.0), angular_velocity=(0.0, 0.0, 0.0),
                 gravity=(0.0, 0.0, -9.81), gravity_in_exudyn: bool = True,
                 time: float = 0.0, steps_per_advance: int = 1):
        if not isinstance(spec, RigidBodySpec):
            raise TypeError(
                f"ExudynRigidBody.spec: expected RigidBodySpec, got {type(spec).__name__}")
        if int(steps_per_advance) < 1:
            raise ValueError(
                f"ExudynRigidBody.steps_per_advance={steps_per_advance!r}: must be >= 1")
        self.spec = spec
        self.gravity = _vec3(gravity, "gravity")
        self.gravity_in_exudyn = bool(gravity_in_exudyn)
        self.steps_per_advance = int(steps_per_advance)
        self._force = np.zeros(3)
        self._torque = np.zeros(3)
        self._solver = None
        self.reset(position, rotation, velocity, angular_velocity, time)

    # ------------------------------------------------------------------ construction
    def reset(self, position, rotation=None, velocity=(0.0, 0.0, 0.0),
              angular_velocity=(0.0, 0.0, 0.0), time: float = 0.0) -> None:
        """(Re)build the Exudyn system with a new initial state; loads are set to zero."""
        pos = _vec3(position, "position")
        rot = np.eye(3) if rotation is None else np.asarray(rotation, dtype=np.float64)
        if rot.shape != (3, 3) or not np.allclose(rot.T @ rot, np.eye(3), atol=1e-9) \
                or np.linalg.det(rot) <= 0.0:
            raise ValueError(
                f"ExudynRigidBody.rotation={rotation!r}: must be a proper rotation matrix")
        vel = _vec3(velocity, "velocity")
        omega = _vec3(angular_velocity, "angular_velocity")
        if not np.isfinite(time):
            raise ValueError(f"ExudynRigidBody.time={time!r}: must be finite [s]")
        self.close()
        self._sc = exu.SystemContainer()
        mbs = self._sc.AddSystem()
        inertia = RigidBodyInertia(mass=self.spec.mass, inertiaTensor=self.spec.inertia,
                                   com=[0.0, 0.0, 0.0])
        g = self.gravity if self.gravity_in_exudyn else np.zeros(3)
        d = mbs.CreateRigidBody(
            referencePosition=pos, referenceRotationMatrix=rot,
            initialVelocity=vel, initialAngularVelocity=omega,
            inertia=inertia, gravity=g.tolist(),
            nodeType=exu.NodeType.RotationRotationVector, show=False, returnDict=True)
        self._node = d["nodeNumber"]
        self._body = d["bodyNumber"]
        # reference configuration of the node (exact restart rebuilds the same one)
        self._ref_position = pos.copy()
        self._ref_rotation = rot.copy()
        marker = mbs.AddMarker(eii.MarkerNodeRigid(nodeNumber=self._node))
        self._load_force = mbs.AddLoad(eii.LoadForceVector(markerNumber=marker,
                                                           loadVector=[0.0, 0.0, 0.0],
                                                           bodyFixed=False))
        self._load_torque = mbs.AddLoad(eii.LoadTorqueVector(markerNumber=marker,
                                                             loadVector=[0.0, 0.0, 0.0],
                                                             bodyFixed=False))
        mbs.Assemble()
        ss = exu.SimulationSettings()
        ti = ss.timeIntegration
        ti.solverType = exu.DynamicSolverType.RK44
        ti.numberOfSteps = self.steps_per_advance
        # Exudyn's own clock starts at 0 (it refuses negative times, and the staggered coupling
        # starts at -h/2); nothing here depends on absolute time, the model clock is offset.
        ti.startTime = 0.0
        ti.endTime = 1.0
        ti.verboseMode = 0
        ti.explicit.computeEndOfStepAccelerations = False
        ss.solution.file.write = False
        ss.solution.sensors.writePeriod = 1e30
        ss.solution.sensors.active = False
        ss.solution.file.writeInitialValues = False
        self._mbs = mbs
        self._ss = ss
        self._solver = exu.MainSolverExplicit()
        self._solver.InitializeSolver(mbs, ss)
        self._time = float(time)
        self._exu_time = 0.0
        self._force = np.zeros(3)
        self._torque = np.zeros(3)
        self.n_advances = 0

    def close(self) -> None:
        """Finalise the Exudyn solver (idempotent)."""
        if self._solver is not None:
            self._solver.FinalizeSolver(self._mbs, self._ss)
            self._solver = None

    # ------------------------------------------------------------------ stepping
    def apply(self, force, torque) -> None:
        """Set the load held over the next :meth:`advance`.

        Parameters
        ----------
        force : array_like (3,)
            Force on the body, world frame, line of action through the CG [N]. Excludes the
            body weight when ``gravity_in_exudyn`` is True.
        torque : array_like (3,)
            Torque about the CG, world frame [N m].
        """
        f = _vec3(force, "force")
        t = _vec3(torque, "torque")
        self._force = f
        self._torque = t
        self._mbs.SetLoadParameter(self._load_force, "loadVector", f.tolist())
        self._mbs.SetLoadParameter(self._load_torque, "loadVector", t.tolist())

    def advance(self, t0: float, t1: float) -> None:
        """Integrate from ``t0`` (must equal the model clock) to ``t1`` with the held load.

        Raises
        ------
        ValueError
            If ``t0`` is not the model time or ``t1 <= t0``.
        RuntimeError
            If Exudyn's ``SolveSteps`` reports failure.
        """
        h = t1 - t0
        if not h > 0.0:
            raise ValueError(f"ExudynRigidBody.advance: t1={t1!r} must be > t0={t0!r} [s]")
        if abs(t0 - self._time) > TIME_MATCH_RTOL * h + 4.0 * np.spacing(abs(t0) + abs(t1)):
            raise ValueError(
                f"ExudynRigidBody.advance: t0={t0!r} differs from the model time "
                f"{self._time!r} [s]")
        s = self._solver
        s.it.startTime = self._exu_time
        s.it.endTime = self._exu_time + h
        self._ss.timeIntegration.endTime = self._exu_time + h
        if not s.SolveSteps(self._mbs, self._ss):
            raise RuntimeError(f"Exudyn SolveSteps failed on [{t0}, {t1}] s")
        self._exu_time += h
        self._time = self._time + h
        self.n_advances += 1

    def state(self) -> BodyState:
        """Position, rotation, velocity, angular velocity, accelerations and time.

        The accelerations follow from the loads of the last :meth:`apply` and the current
        state by Newton–Euler: ``a = (F + m g)/m`` (``m g`` only if Exudyn applies gravity)
        and ``alpha = J_w^-1 (T - omega x J_w omega)``.

        Notes
        -----
        Newton–Euler equations of a rigid body about its CG (Goldstein §5.5).
        """
        x = self.position()
        r = self.rotation()
        v = self.velocity()
        w = self.angular_velocity()
        f = self._force + (self.weight() if self.gravity_in_exudyn else 0.0)
        a = f / self.spec.mass
        jw = self.inertia_world(r)
        alpha = np.linalg.solve(jw, self._torque - np.cross(w, jw @ w))
        return BodyState(x, r, v, w, a, alpha, self._time)

    def kinetic_energy(self) -> float:
        """Translational + rotational kinetic energy [J]."""
        v = self.velocity()
        w = self.angular_velocity()
        return 0.5 * self.spec.mass * float(v @ v) + 0.5 * float(w @ (self.inertia_world() @ w))

    def momentum(self) -> tuple[np.ndarray, np.ndarray]:
        """Linear momentum [kg m/s] and angular momentum about the CG, world frame [kg m^2/s]."""
        return self.spec.mass * self.velocity(), self.inertia_world() @ self.angular_velocity()

    def state_dict(self) -> dict:
        """Restart state: pose, velocities, clock and the held load (world frame, SI), plus
        the exact Exudyn state (reference configuration, ODE2 coordinates and velocities,
        solver clock) used by :meth:`load_state_dict` for a bit-exact restart."""
        sd = self._mbs.systemData
        return {"position": self.position(), "rotation": self.rotation(),
                "velocity": self.velocity(), "angular_velocity": self.angular_velocity(),
                "time": self._time, "force": self._force.copy(), "torque": self._torque.copy(),
                "reference_position": self._ref_position.copy(),
                "reference_rotation": self._ref_rotation.copy(),
                "ode2": np.array(sd.GetODE2Coordinates(), dtype=np.float64),
                "ode2_t": np.array(sd.GetODE2Coordinates_t(), dtype=np.float64),
                "exu_time": self._exu_time, "n_advances": self.n_advances}

    def load_state_dict(self, d: dict) -> None:
        """Rebuild the Exudyn system at a saved state (see :meth:`state_dict`).

        Notes
        -----
        Exudyn stores the pose as reference + displacement coordinates. When the dict holds
        the reference configuration and the ODE2 coordinates (``state_dict`` of this
        version), the body is rebuilt on the same reference, its coordinates and velocities
        are set exactly (``SystemData.SetODE2Coordinates`` / ``_t``, initial configuration)
        and the solver is initialised at the saved Exudyn clock, so a
        restarted run is bit-identical to an uninterrupted one. An older dict without them
        rebuilds the body on a new reference: identical to round-off only.
        """
        if "ode2" not in d:
            self.reset(d["position"], d["rotation"], d["velocity"], d["angular_velocity"],
                       float(d["time"]))
            self.apply(d["force"], d["torque"])
            return
        self.reset(d["reference_position"], d["reference_rotation"], (0.0, 0.0, 0.0),
                   (0.0, 0.0, 0.0), float(d["time"]))
        _restart_explicit(self, d["ode2"], d["ode2_t"], d["exu_time"], "ExudynRigidBody")
        self.n_advances = int(d.get("n_advances", 0))
        self.apply(d["force"], d["torque"])

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass
