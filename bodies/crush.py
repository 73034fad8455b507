"""A crushable nose in Exudyn: two rigid bodies (the aircraft and its nose) joined by a
prismatic, elastic-perfectly-plastic, force-limited element with a stroke limit
(``physics.structural_crush``, docs/glider.md, docs/bodies.md).

Model
-----
* ``rear`` and ``nose`` are two Exudyn rigid bodies (rotation-vector nodes at their CGs);
* one ``ObjectConnectorRigidBodySpringDamper`` joins a marker on the rear body at the nose's
  rest position (joint frame = rear body axes) to the nose CG. Its user function is

  - along the body x axis (the fuselage axis): the crush element. With the compression
    ``s = -u_x`` (nose moving aft), the committed plastic stroke ``s_p`` and the compressive
    load ``P = k (s - s_p) + c s'``: ``P <= F_c`` while ``s_p < stroke`` (perfectly plastic
    plateau at the crush force), no cap once ``s_p = stroke`` (bottoming: the nose bears on
    the cockpit structure); tension is elastic;
  - the other five relative coordinates: a stiff penalty (the prismatic guide), natural
    frequency ``omega = PENALTY_OMEGA_H / h`` for the integration step ``h``, damping ratio
    ``PENALTY_DAMPING``; the axial elastic stiffness is the same ``k``.

* after every step the plastic stroke is committed from the end-of-step state (return
  mapping): ``s_p <- min(s - F_c/k, stroke)`` when ``k (s - s_p) > F_c``. Within a step the
  user function uses the committed ``s_p`` and the cap, so the element never carries more than
  ``F_c`` before bottoming.

Interface
---------
``ExudynCrushableBody`` has the interface of ``ExudynRigidBody`` for the rear body (the one
``coupling.CoSimulation`` drives: ``spec`` is the rear spec) plus ``apply_nose`` / ``nose_*``
accessors and ``connector_wrench`` (the connector law evaluated on given poses, the same
function as the Exudyn user function) used by the glider model to put the connector load in
the rear body's wrench seen by the coupling and the sensors (see ``apply``).

Notes
-----
Elastic-perfectly-plastic element with return mapping (Simo & Hughes, *Computational
Inelasticity*, 1998, §1.2); penalty joint (compliant ``RigidBodySpringDamper``, Exudyn
documentation of ``ObjectConnectorRigidBodySpringDamper``).
"""

from __future__ import annotations

import math

import exudyn as exu
import exudyn.itemInterface as eii
import numpy as np
from exudyn.utilities import RigidBodyInertia

from .exudyn_model import (TIME_MATCH_RTOL, BodyState, _restart_explicit, _RigidBodyReadout,
                           _vec3)
from .spec import RigidBodySpec

#: penalty natural frequency times the integration step [-]: RK44 is stable up to 2.8 and
#: accurate (amplitude error < 1e-3 per period) at 0.5
PENALTY_OMEGA_H = 0.5
#: damping ratio of the penalty (prismatic guide) coordinates [-]
PENALTY_DAMPING = 0.5
#: damping ratio of the axial elastic part of the crush element [-] (composite debris; only
#: below the plateau, the load stays capped at the crush force)
AXIAL_DAMPING = 0.2


def crush_load(s: float, s_dot: float, s_p: float, crush_force: float, stroke: float,
               k: float, c: float) -> float:
    """Compressive load of the crush element [N] (positive = compression).

    Parameters
    ----------
    s, s_dot : compression (nose displacement aft relative to the rear body) [m], its rate
        [m/s]
    s_p : committed plastic stroke [m], in [0, stroke]
    crush_force : plateau [N] > 0; stroke : available stroke [m] > 0
    k, c : elastic stiffness [N/m] and damping [N s/m]

    Notes
    -----
    ``P = k (s - s_p) + c s'``, capped at ``crush_force`` while ``s_p < stroke``.
    """
    p = k * (s - s_p) + c * s_dot
    if s_p < stroke and p > crush_force:
        p = crush_force
    return p


def commit_plastic(s: float, s_p: float, crush_force: float, stroke: float, k: float) -> float:
    """Return mapping of the plastic stroke at the end of a step [m]."""
    if s_p < stroke and k * (s - s_p) > crush_force:
        s_p = min(s - crush_force / k, stroke)
    return s_p


def _vee_small(a: np.ndarray) -> np.ndarray:
    """Rotation vector of a rotation matrix (exact log map) [rad]."""
    c = max(-1.0, min(1.0, 0.5 * (np.trace(a) - 1.0)))
    th = math.acos(c)
    w = 0.5 * np.array([a[2, 1] - a[1, 2], a[0, 2] - a[2, 0], a[1, 0] - a[0, 1]])
    if th < 1e-8:
        return w
    return w * th / math.sin(th)


class ExudynCrushableBody(_RigidBodyReadout):
    """The aircraft (rear body) and its crushable nose in one Exudyn system.

    Parameters
    ----------
    rear, nose : RigidBodySpec
        From ``bodies.split_nose`` (CG body frames with parallel axes;
        ``cg_in_construction_frame`` locates both CGs).
    crush_force : float
        Plateau of the crush element [N], > 0.
    stroke : float
        Available crush stroke before bottoming [m], > 0.
    step : float
        Integration step the penalty stiffness is designed for [s], > 0 (the DEM step).
    position, rotation, velocity, angular_velocity : rear body initial state (world, SI)
    gravity : (3,) [m/s^2] (applied by Exudyn to both bodies)
    time : model clock [s]
    relative_velocity : initial compression rate of the element (nose moving aft relative to
        the rear body) [m/s] (0 for a free flight; used by the analytic tests)

    Notes
    -----
    See the module docstring. ``spec`` (the rear spec), ``gravity``, ``gravity_in_exudyn``
    (True), ``apply``, ``advance``, ``reset``, ``state``, ``position`` ... act on the rear body
    as ``ExudynRigidBody`` does, so ``coupling.CoSimulation`` drives it unchanged.
    """

    gravity_in_exudyn = True
    steps_per_advance = 1

    def __init__(self, rear: RigidBodySpec, nose: RigidBodySpec, crush_force: float,
                 stroke: float, step: float, position=(0.0, 0.0, 0.0), rotation=None,
                 velocity=(0.0, 0.0, 0.0), angular_velocity=(0.0, 0.0, 0.0),
                 gravity=(0.0, 0.0, -9.81), time: float = 0.0, relative_velocity: float = 0.0):
        for name, val, unit in (("crush_force", crush_force, "N"), ("stroke", stroke, "m"),
                                ("step", step, "s")):
            if not (np.isfinite(val) and val > 0.0):
                raise ValueError(f"ExudynCrushableBody.{name}={val!r}: must be > 0 [{unit}]")
        if not isinstance(rear, RigidBodySpec) or not isinstance(nose, RigidBodySpec):
            raise TypeError("ExudynCrushableBody.rear/nose: expected RigidBodySpec")
        self.spec = rear
        self.nose_spec = nose
        self.crush_force = float(crush_force)
        self.stroke = float(stroke)
        self.gravity = _vec3(gravity, "gravity")
        #: nose CG in the rear body frame at rest [m]
        self.joint = (np.asarray(nose.cg_in_construction_frame, dtype=float)
                      - np.asarray(rear.cg_in_construction_frame, dtype=float))
        om = PENALTY_OMEGA_H / float(step)
        m_red = rear.mass * nose.mass / (rear.mass + nose.mass)
        self.k = m_red * om * om
        self.c_t = 2.0 * PENALTY_DAMPING * math.sqrt(self.k * m_red)
        self.c_axial = 2.0 * AXIAL_DAMPING * math.sqrt(self.k * m_red)
        jn = np.diag(nose.inertia)
        self.k_rot = jn * om * om
        self.c_rot = 2.0 * PENALTY_DAMPING * np.sqrt(self.k_rot * jn)
        self._solver = None
        self.reset(position, rotation, velocity, angular_velocity, time, relative_velocity)

    # ------------------------------------------------------------------ the law
    def _local_wrench(self, u, rot, v, w, s_p):
        """Connector force and torque in the joint (rear) frame, Exudyn's sign: the force on
        the nose is ``-f``, on the rear ``+f`` (at the joint point); torques alike."""
        p = crush_load(-u[0], -v[0], s_p, self.crush_force, self.stroke, self.k, self.c_axial)
        f = np.array([-p, self.k * u[1] + self.c_t * v[1], self.k * u[2] + self.c_t * v[2]])
        t = self.k_rot * np.asarray(rot) + self.c_rot * np.asarray(w)
        return f, t, p

    def _uf(self, mbs, t, item, displacement, rotation, velocity, angular_velocity, *args):
        f, tq, p = self._local_wrench(np.asarray(displacement), np.asarray(rotation),
                                      np.asarray(velocity), np.asarray(angular_velocity),
                                      self.s_p)
        if self.s_p < self.stroke:  # every load the element carried before bottoming
            self.max_uf_load_before_bottoming = max(self.max_uf_load_before_bottoming, p)
        return [f[0], f[1], f[2], tq[0], tq[1], tq[2]]

    def relative_state(self, x_r, r_r, v_r, w_r, x_n, r_n, v_n, w_n):
        """Relative displacement, rotation, velocity and angular velocity of the nose in the
        joint (rear) frame from world poses (the connector's coordinates)."""
        rj = r_r @ self.joint
        u = r_r.T @ (np.asarray(x_n) - np.asarray(x_r) - rj)
        rot = _vee_small(r_r.T @ r_n)
        v = r_r.T @ (np.asarray(v_n) - np.asarray(v_r) - np.cross(w_r, rj))
        w = r_r.T @ (np.asarray(w_n) - np.asarray(w_r))
        return u, rot, v, w

    def connector_wrench(self, x_r, r_r, v_r, w_r, x_n, r_n, v_n, w_n):
        """The connector load on both bodies for given world poses (same law as the Exudyn
        user function, committed plastic stroke).

        Returns
        -------
        f_rear, t_rear (about the rear CG), f_nose, t_nose (about the nose CG) : (3,) world
        [N], [N m]; and the compressive axial load ``P`` [N]
        """
        r_r = np.asarray(r_r)
        u, rot, v, w = self.relative_state(x_r, r_r, v_r, w_r, x_n, r_n, v_n, w_n)
        f, t, p = self._local_wrench(u, rot, v, w, self.s_p)
        fw = r_r @ f
        tw = r_r @ t
        rj = r_r @ self.joint
        return fw, np.cross(rj, fw) + tw, -fw, -tw, p

    # ------------------------------------------------------------------ construction
    def reset(self, position, rotation=None, velocity=(0.0, 0.0, 0.0),
              angular_velocity=(0.0, 0.0, 0.0), time: float = 0.0,
              relative_velocity: float = 0.0) -> None:
        """(Re)build both bodies, the nose attached at its rest position (no crush, plastic
        stroke zero), moving with the rear body (plus ``relative_velocity`` aft), loads zero."""
        pos = _vec3(position, "position")
        rot = np.eye(3) if rotation is None else np.asarray(rotation, dtype=np.float64)
        if rot.shape != (3, 3) or not np.allclose(rot.T @ rot, np.eye(3), atol=1e-9) \
                or np.linalg.det(rot) <= 0.0:
            raise ValueError(
                f"ExudynCrushableBody.rotation={rotation!r}: must be a proper rotation matrix")
        vel = _vec3(velocity, "velocity")
        omega = _vec3(angular_velocity, "angular_velocity")
        self.close()
        self._sc = exu.SystemContainer()
        mbs = self._sc.AddSystem()
        rj = rot @ self.joint
        # reference configuration of the nodes (the rear body's; the nose's follows from it):
        # an exact restart rebuilds the same one (``load_state_dict``)
        self._ref_position = pos.copy()
        self._ref_rotation = rot.copy()
        bodies = []
        for spec, p, v in ((self.spec, pos, vel),
                           (self.nose_spec, pos + rj, vel + np.cross(omega, rj)
                            - float(relative_velocity) * rot[:, 0])):
            d = mbs.CreateRigidBody(
                referencePosition=p, referenceRotationMatrix=rot, initialVelocity=v,
                initialAngularVelocity=omega,
                inertia=RigidBodyInertia(mass=spec.mass, inertiaTensor=spec.inertia,
                                         com=[0.0, 0.0, 0.0]),
                gravity=self.gravity.tolist(), nodeType=exu.NodeType.RotationRotationVector,
                show=False, returnDict=True)
            bodies.append(d)
        (self._node, self._body), (self._nnode, self._nbody) = (
            (d["nodeNumber"], d["bodyNumber"]) for d in bodies)
        m_r = mbs.AddMarker(eii.MarkerBodyRigid(bodyNumber=self._body,
                                                localPosition=self.joint.tolist()))
        m_n = mbs.AddMarker(eii.MarkerBodyRigid(bodyNumber=self._nbody,
                                                localPosition=[0.0, 0.0, 0.0]))
        self.s_p = 0.0
        self.max_load_before_bottoming = 0.0
        self.max_uf_load_before_bottoming = 0.0
        self.compression = 0.0
        self.load = 0.0
        self.bottomed = False
        mbs.AddObject(eii.ObjectConnectorRigidBodySpringDamper(
            markerNumbers=[m_r, m_n], stiffness=np.zeros((6, 6)).tolist(),
            damping=np.zeros((6, 6)).tolist(), springForceTorqueUserFunction=self._uf))
        self._loads = []
        for node in (self._node, self._nnode):
            mk = mbs.AddMarker(eii.MarkerNodeRigid(nodeNumber=node))
            self._loads.append((
                mbs.AddLoad(eii.LoadForceVector(markerNumber=mk, loadVector=[0.0, 0.0, 0.0],
                                                bodyFixed=False)),
                mbs.AddLoad(eii.LoadTorqueVector(markerNumber=mk, loadVector=[0.0, 0.0, 0.0],
                                                 bodyFixed=False))))
        mbs.Assemble()
        ss = exu.SimulationSettings()
        ti = ss.timeIntegration
        ti.solverType = exu.DynamicSolverType.RK44
        ti.numberOfSteps = 1
        ti.startTime = 0.0
        ti.endTime = 1.0
        ti.verboseMode = 0
        ti.explicit.computeEndOfStepAccelerations = False
        ss.solution.file.write = False
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
        self._added = (np.zeros(3), np.zeros(3))
        self._nose_force = np.zeros(3)
        self._nose_torque = np.zeros(3)
        self.n_advances = 0

    def close(self) -> None:
        """Finalise the Exudyn solver (idempotent)."""
        if self._solver is not None:
            self._solver.FinalizeSolver(self._mbs, self._ss)
            self._solver = None

    # ------------------------------------------------------------------ stepping
    def add_connector_load(self, force, torque) -> None:
        """Declare the connector wrench (from :meth:`connector_wrench`) that the caller put
        into the rear body's wrench; :meth:`apply` removes it again before handing the load to
        Exudyn, whose connector produces that load itself."""
        self._added = (_vec3(force, "force"), _vec3(torque, "torque"))

    def apply(self, force, torque) -> None:
        """Set the external load on the rear body held over the next :meth:`advance`.

        ``force``/``torque`` (world, torque about the rear CG, weight excluded) may include the
        connector wrench declared by :meth:`add_connector_load`; that part is removed here.
        """
        f = _vec3(force, "force")
        t = _vec3(torque, "torque")
        self._force, self._torque = f, t
        fa, ta = self._added
        (lf, lt) = self._loads[0]
        self._mbs.SetLoadParameter(lf, "loadVector", (f - fa).tolist())
        self._mbs.SetLoadParameter(lt, "loadVector", (t - ta).tolist())

    def apply_nose(self, force, torque) -> None:
        """External load on the nose (soil, walls; world, torque about the nose CG) [N, N m]."""
        self._nose_force = _vec3(force, "force")
        self._nose_torque = _vec3(torque, "torque")
        (lf, lt) = self._loads[1]
        self._mbs.SetLoadParameter(lf, "loadVector", self._nose_force.tolist())
        self._mbs.SetLoadParameter(lt, "loadVector", self._nose_torque.tolist())

    def advance(self, t0: float, t1: float) -> None:
        """Integrate both bodies from ``t0`` (the model clock) to ``t1`` (one RK44 step),
        then commit the plastic stroke."""
        h = t1 - t0
        if not h > 0.0:
            raise ValueError(f"ExudynCrushableBody.advance: t1={t1!r} must be > t0={t0!r} [s]")
        if abs(t0 - self._time) > TIME_MATCH_RTOL * h + 4.0 * np.spacing(abs(t0) + abs(t1)):
            raise ValueError(f"ExudynCrushableBody.advance: t0={t0!r} differs from the model "
                             f"time {self._time!r} [s]")
        s = self._solver
        s.it.startTime = self._exu_time
        s.it.endTime = self._exu_time + h
        self._ss.timeIntegration.endTime = self._exu_time + h
        if not s.SolveSteps(self._mbs, self._ss):
            raise RuntimeError(f"Exudyn SolveSteps failed on [{t0}, {t1}] s")
        self._exu_time += h
        self._time += h
        self.n_advances += 1
        self._added = (np.zeros(3), np.zeros(3))
        self._commit()

    def _commit(self) -> None:
        u, rot, v, w = self.relative_state(self.position(), self.rotation(), self.velocity(),
                                           self.angular_velocity(), self.nose_position(),
                                           self.nose_rotation(), self.nose_velocity(),
                                           self.nose_angular_velocity())
        s = -float(u[0])
        p = crush_load(s, -float(v[0]), self.s_p, self.crush_force, self.stroke, self.k,
                       self.c_axial)
        self.load = p
        if not self.bottomed:
            self.max_load_before_bottoming = max(self.max_load_before_bottoming, p)
        self.s_p = commit_plastic(s, self.s_p, self.crush_force, self.stroke, self.k)
        self.bottomed = self.s_p >= self.stroke
        self.compression = s

    # ------------------------------------------------------------------ state
    @property
    def total_mass(self) -> float:
        """Rear + nose mass [kg]."""
        return self.spec.mass + self.nose_spec.mass

    def _out(self, node, var):
        return np.asarray(self._mbs.GetNodeOutput(node, var))

    def nose_position(self) -> np.ndarray:
        """Nose CG position [m]."""
        return self._out(self._nnode, exu.OutputVariableType.Position)

    def nose_velocity(self) -> np.ndarray:
        """Nose CG velocity [m/s]."""
        return self._out(self._nnode, exu.OutputVariableType.Velocity)

    def nose_rotation(self) -> np.ndarray:
        """Nose rotation matrix body -> world."""
        return self._out(self._nnode, exu.OutputVariableType.RotationMatrix).reshape(3, 3)

    def nose_angular_velocity(self) -> np.ndarray:
        """Nose angular velocity, world [rad/s]."""
        return self._out(self._nnode, exu.OutputVariableType.AngularVelocity)

    def state(self) -> BodyState:
        """Rear body state; accelerations from the last :meth:`apply` load (which includes
        the connector wrench when the caller added it) and the weight (Newton–Euler)."""
        x, r, v, w = self.position(), self.rotation(), self.velocity(), self.angular_velocity()
        a = self._force / self.spec.mass + self.gravity
        jw = self.inertia_world(r)
        alpha = np.linalg.solve(jw, self._torque - np.cross(w, jw @ w))
        return BodyState(x, r, v, w, a, alpha, self._time)

    def momentum(self) -> np.ndarray:
        """Linear momentum of rear + nose [kg m/s]."""
        return self.spec.mass * self.velocity() + self.nose_spec.mass * self.nose_velocity()

    def kinetic_energy(self) -> float:
        """Kinetic energy of rear + nose [J]."""
        out = 0.0
        for spec, v, w, r in ((self.spec, self.velocity(), self.angular_velocity(),
                               self.rotation()),
                              (self.nose_spec, self.nose_velocity(),
                               self.nose_angular_velocity(), self.nose_rotation())):
            jw = r @ spec.inertia @ r.T
            out += 0.5 * spec.mass * float(v @ v) + 0.5 * float(w @ (jw @ w))
        return out

    #: scalar state of the crush element and the solver (saved and restored as is)
    _SCALARS = ("s_p", "max_load_before_bottoming", "max_uf_load_before_bottoming",
                "compression", "load", "bottomed", "_time", "_exu_time", "n_advances")

    def state_dict(self) -> dict:
        """Restart state: the exact Exudyn state of both bodies (reference configuration,
        ODE2 coordinates and velocities, solver clock), the crush element's committed plastic
        stroke and its history (load, compression, maxima, bottoming), the held loads on both
        bodies and the declared connector load, plus the rear body's pose and velocities
        (world, SI) for inspection. :meth:`load_state_dict` restores it bit for bit."""
        sd = self._mbs.systemData
        d = {"position": self.position(), "rotation": self.rotation(),
             "velocity": self.velocity(), "angular_velocity": self.angular_velocity(),
             "time": self._time, "force": self._force.copy(), "torque": self._torque.copy(),
             "nose_force": self._nose_force.copy(), "nose_torque": self._nose_torque.copy(),
             "added_force": self._added[0].copy(), "added_torque": self._added[1].copy(),
             "reference_position": self._ref_position.copy(),
             "reference_rotation": self._ref_rotation.copy(),
             "ode2": np.array(sd.GetODE2Coordinates(), dtype=np.float64),
             "ode2_t": np.array(sd.GetODE2Coordinates_t(), dtype=np.float64),
             # the load vectors Exudyn holds (rear: applied minus declared connector load at
             # the last apply; nose), restored as they are
             "exudyn_loads": np.array([self._mbs.GetLoadParameter(ld, "loadVector")
                                       for pair in self._loads for ld in pair],
                                      dtype=np.float64),
             # the element's parameters, checked on load (a restart into another element)
             "crush_force": self.crush_force, "stroke": self.stroke, "k": self.k}
        for name in self._SCALARS:
            d[name] = getattr(self, name)
        d["bottomed"] = bool(self.bottomed)
        d["n_advances"] = int(self.n_advances)
        return d

    def load_state_dict(self, d: dict) -> None:
        """Rebuild both bodies at a saved state (see :meth:`state_dict`), bit-exact.

        Notes
        -----
        As ``ExudynRigidBody.load_state_dict``: the system is rebuilt on the saved reference
        configuration, the ODE2 coordinates and velocities are set as the initial
        configuration and a fresh explicit solver is initialised at the saved Exudyn clock
        (an initialised solver does not see a changed current configuration).

        Raises
        ------
        ValueError
            If the dict belongs to an element with another crush force, stroke or stiffness
            (another scenario or time step), or its coordinate vectors have the wrong size.
        """
        for name in ("crush_force", "stroke", "k"):
            if float(d[name]) != getattr(self, name):
                raise ValueError(f"ExudynCrushableBody.load_state_dict: {name}={d[name]!r} "
                                 f"differs from this element's {getattr(self, name)!r}")
        self.reset(d["reference_position"], d["reference_rotation"], (0.0, 0.0, 0.0),
                   (0.0, 0.0, 0.0), float(d["time"]))

        def element_state():  # read by the connector's user function
            for name in self._SCALARS:
                setattr(self, name, d[name])
            self.s_p = float(d["s_p"])
            self.bottomed = bool(d["bottomed"])
            self.n_advances = int(d["n_advances"])
            self._time = float(d["time"])

        _restart_explicit(self, d["ode2"], d["ode2_t"], d["_exu_time"], "ExudynCrushableBody",
                          element_state)
        self._force = _vec3(d["force"], "force")
        self._torque = _vec3(d["torque"], "torque")
        self._nose_force = _vec3(d["nose_force"], "nose_force")
        self._nose_torque = _vec3(d["nose_torque"], "nose_torque")
        self._added = (_vec3(d["added_force"], "added_force"),
                       _vec3(d["added_torque"], "added_torque"))
        loads = np.asarray(d["exudyn_loads"], dtype=np.float64)
        if loads.shape != (4, 3):
            raise ValueError(f"ExudynCrushableBody.load_state_dict: exudyn_loads shape "
                             f"{loads.shape}: must be (4, 3)")
        for ld, vec in zip((ld for pair in self._loads for ld in pair), loads):
            self._mbs.SetLoadParameter(ld, "loadVector", vec.tolist())

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass
