"""DEM <-> Exudyn co-simulation of one rigid body: the DEM owns the time loop.

Time alignment (leapfrog staggering)
------------------------------------
The DEM integrates particles by leapfrog: at the start of step n the force ``F_n`` (computed
on the configuration at ``t_n``) drives ``v_{n-1/2} -> v_{n+1/2}``, then
``x_{n+1} = x_n + h v_{n+1/2}``; a coupled boundary body drifts at its set velocity. The
Exudyn clock is kept **half a DEM step behind** the DEM clock: its state lives at
``t_{n-1/2}``. One exchange covers a window of ``m`` DEM steps starting at ``t_n``:

1. kick: the body velocity for the window is ``v_e + (m+1)/2 h a_n`` (``a_n`` from ``F_n``
   and the weight; ``omega`` likewise from the Newton–Euler equations): the mean of the
   predicted leapfrog velocities ``v_{n+1/2} ... v_{n+m-1/2}`` under ``F_n``; for ``m = 1``
   exactly ``v_{n+1/2}``;
2. the DEM runs ``m`` steps (the body drifts at that constant velocity) and the forces that
   drove them, ``F_n ... F_{n+m-1}``, are averaged;
3. Exudyn advances over ``[t_{n-1/2}, t_{n+m-1/2}]``, an interval centred on the mean time
   of the averaged forces, with the mean wrench held (RK44);
4. the DEM body is put at ``x_e + (h/2) v_e``, ``R = expm(skew(w_e) h/2) R_e``.

For ``m = 1`` this *is* leapfrog (``x_e(t_{n+1/2}) + h/2 v_{n+1/2} = x_n + h v_{n+1/2}``), so
a coupled sphere follows the same trajectory as a DEM particle to round-off, instead of the
one-step lag of a naive staggering (anchors §5 item 5). For ``m > 1`` the time-averaged
wrench is exchanged (/work/shared/reference/exudyn_coupling.md) and the DEM sees the body on
a constant-velocity prediction between exchanges.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from . import _kernels as _k

#: relative mismatch tolerated between the model gravity and the DEM gravity: both are
#: user inputs copied from the same scenario; anything above round-off is a set-up error.
GRAVITY_MATCH_RTOL = 1e-12


def rotation_increment(w, dt: float) -> np.ndarray:
    """``expm(skew(w) dt)`` by Rodrigues' formula (3x3).

    Notes
    -----
    Rodrigues: ``exp(K) = I + sin(a)/a K + (1 - cos a)/a^2 K^2`` with ``a = |w| dt``.
    """
    return _k.rotation_increment(np.asarray(w, dtype=np.float64), float(dt))


@dataclass
class EnergyLedger:
    """Energy accounts of the coupled system [J], all relative to the start of the run.

    Attributes
    ----------
    body_kinetic : float
        Body translational + rotational kinetic energy at the DEM time, with the synchronised
        velocities ``v_{n-1/2} + (h/2) a_n`` (as ``sim.energy()`` does for particles) [J].
    body_kinetic_0 : float
        Its value at the start [J].
    body_potential : float
        ``-m g . (x - x_0)`` of the body [J].
    body_interface_work : float
        Work of the contact wrench on the body, ``sum H (F . (v_a + v_b)/2 + T . (w_a + w_b)/2)``
        over exchanges [J] (exact for a held load on the translational part).
    soil : dict
        ``sim.energy()`` at the last refresh [J]; ``soil_0`` at the start.
    soil_interface_work : float
        Work done by the coupled body on the particles as counted by the DEM
        (``BoundaryBody.work``) [J].
    """

    body_kinetic: float = 0.0
    body_potential: float = 0.0
    body_interface_work: float = 0.0
    soil: dict = field(default_factory=dict)
    soil_interface_work: float = 0.0
    body_kinetic_0: float = 0.0
    soil_0: dict = field(default_factory=dict)

    @property
    def soil_mechanical(self) -> float:
        """Soil kinetic + elastic + dissipated - gravity work - work of all boundaries
        (``sim.energy()["total"]``); constant for an exact DEM balance [J]."""
        return _soil_total(self.soil)

    @property
    def interface_mismatch(self) -> float:
        """``W_on_body + W_by_body_on_soil``: zero for a lossless interface [J]."""
        return self.body_interface_work + self.soil_interface_work

    @property
    def residual(self) -> float:
        """Change of the total energy of body + soil since the start [J]."""
        # the soil total subtracts the work of every boundary; the coupled body's share is
        # internal to the coupled system, so it is added back
        return (self.body_kinetic - self.body_kinetic_0 + self.body_potential
                + _soil_total(self.soil) - _soil_total(self.soil_0)
                + self.soil_interface_work)

    @property
    def scale(self) -> float:
        """Energy scale for a relative closure: initial body kinetic energy plus the
        magnitudes of the body potential change and of the soil gravity work [J]."""
        return (self.body_kinetic_0 + abs(self.body_potential)
                + abs(self.soil.get("work_gravity", 0.0) - self.soil_0.get("work_gravity", 0.0)))

    @property
    def relative_residual(self) -> float:
        """``|residual| / scale`` [-]."""
        s = self.scale
        return abs(self.residual) / s if s > 0.0 else 0.0


def _soil_total(e: dict) -> float:
    """Soil energy content (kinetic + elastic + dissipated) minus the work fed in from outside
    (gravity and all boundaries) [J]: ``sim.energy()["total"]``, constant for an exact DEM
    energy balance."""
    return float(e["total"])


class CoSimulation:
    """Two-way coupling of one ``soil.BoundaryBody`` (motion="coupled") with an Exudyn body.

    Parameters
    ----------
    sim : soil.Simulation
        The DEM; owns the time loop. Its time step ``h = sim.dt`` is used.
    body_index : int
        Index of the coupled body in ``sim.boundaries``.
    model : bodies.ExudynRigidBody
        The rigid body; its current state is taken as the state at ``sim.time``. It is
        rebuilt here on the staggered clock (``model.time = sim.time - h/2``).
    exchange_every : int
        Number ``m`` of DEM steps per Exudyn step (sub-cycling), >= 1.

    Notes
    -----
    Weight: if ``model.gravity_in_exudyn`` is False, the coupling adds ``m g`` to the force;
    the DEM never applies gravity to boundary bodies. ``model.gravity`` must equal
    ``sim.gravity``. Staggering: see the module docstring.
    """

    def __init__(self, sim, body_index: int, model, exchange_every: int = 1):
        m = int(exchange_every)
        if m < 1 or m != exchange_every:
            raise ValueError(
                f"CoSimulation.exchange_every={exchange_every!r}: must be an integer >= 1")
        boundaries = sim.boundaries
        if not 0 <= body_index < len(boundaries):
            raise ValueError(
                f"CoSimulation.body_index={body_index!r}: must be in [0, {len(boundaries) - 1}]")
        body = boundaries[body_index]
        if body.motion != "coupled":
            raise ValueError(
                f"CoSimulation: sim.boundaries[{body_index}].motion={body.motion!r}: must be "
                "'coupled'")
        if body.reference_point is not None and np.any(np.asarray(body.reference_point) != 0.0):
            raise ValueError(
                f"CoSimulation: sim.boundaries[{body_index}].reference_point="
                f"{body.reference_point!r}: must be None (the body origin = the CG)")
        g_sim = np.asarray(sim.gravity, dtype=np.float64)
        g_mod = np.asarray(model.gravity, dtype=np.float64)
        if np.max(np.abs(g_sim - g_mod)) > GRAVITY_MATCH_RTOL * max(np.linalg.norm(g_sim), 1.0):
            raise ValueError(
                f"CoSimulation: model.gravity={g_mod.tolist()} differs from sim.gravity="
                f"{g_sim.tolist()} [m/s^2]")
        self.sim = sim
        self.body_index = int(body_index)
        self.body = body
        self.model = model
        self._mass = float(model.spec.mass)
        self._gravity = np.asarray(model.gravity, dtype=np.float64)
        self._j = np.ascontiguousarray(model.spec.inertia, dtype=np.float64)
        self._j_inv = np.linalg.inv(self._j)
        self.exchange_every = m
        self.h = float(sim.dt)
        self._extra_force = np.zeros(3) if model.gravity_in_exudyn else model.weight()
        # start state: the model's state is v(t_0) at the DEM time. As the DEM does for its
        # particles (velocity-Verlet start), the staggered Exudyn state is the half step
        # back: v_{-1/2} = v_0 - (h/2) a_0 with a_0 from the DEM wrench at t_0 (+ weight),
        # and x_e(t_{-1/2}) = x_0 - (h/2) v_{-1/2}, so that x_e + (h/2) v_e = x_0.
        st = model.state()
        if abs(st.time - sim.time) > 1e-9 * max(1.0, abs(sim.time)) + 0.5 * self.h * 1e-6:
            raise ValueError(
                f"CoSimulation: model.time={st.time!r} must equal sim.time={sim.time!r} [s]")
        half = 0.5 * self.h
        a0, alpha0, _ = self._newton_euler(np.asarray(body.force, dtype=np.float64),
                                           np.asarray(body.torque, dtype=np.float64))
        v_half = st.velocity - half * a0
        w_half = st.angular_velocity - half * alpha0
        model.reset(st.position - half * v_half,
                    rotation_increment(w_half, -half) @ st.rotation,
                    v_half, w_half, time=sim.time - half)
        self._place_and_kick()
        self.exchanges = 0
        self.wall_time = {"dem": 0.0, "exchange": 0.0}
        self.stop_reason = None
        # energy accounts
        self._x0 = np.array(body.position)
        ke0 = self.body_kinetic_energy()
        self.ledger = EnergyLedger(body_kinetic=ke0, body_kinetic_0=ke0,
                                   soil=dict(sim.energy()), soil_0=dict(sim.energy()),
                                   soil_interface_work=0.0)
        self._soil_work_0 = float(getattr(body, "work", 0.0))
        self._momentum_0 = self.model.spec.mass * v_half
        self._impulse_0 = np.array(body.impulse)
        self._angular_impulse_0 = np.array(body.angular_impulse)
        self.last_force = np.zeros(3)
        self.last_torque = np.zeros(3)
        self.in_contact = False
        self.had_contact = False

    # ------------------------------------------------------------------ exchange
    def _place_and_kick(self) -> None:
        """Put the DEM body at t_n from the Exudyn state at t_{n-1/2} and give it the window
        velocity for the next exchange (steps 4 and 1 of the module docstring).

        The wrench that drives the first step of the next window, ``F_n``, is the one the DEM
        computed at the end of its last step (``body.force``, ``body.torque``).
        """
        model = self.model
        x, r, v, w = model.position(), model.rotation(), model.velocity(), model.angular_velocity()
        a, alpha = _k.newton_euler(np.asarray(self.body.force, dtype=np.float64),
                                   np.asarray(self.body.torque, dtype=np.float64), self._mass,
                                   self._gravity, r, self._j_inv, self._j, w)
        half = 0.5 * self.h
        kick = 0.5 * (self.exchange_every + 1) * self.h
        self._v_e, self._w_e = v, w
        self.body.set_kinematics(x + half * v, _k.rotation_increment(w, half) @ r,
                                 v + kick * a, w + kick * alpha)

    def _newton_euler(self, force, torque):
        """Accelerations of the body under the DEM wrench (plus weight) at the Exudyn state.

        Returns ``a``, ``alpha`` and the current angular velocity ``w`` (world frame).

        Notes
        -----
        ``a = F/m + g``, ``alpha = J_w^-1 (T - omega x J_w omega)`` (Newton–Euler).
        """
        model = self.model
        w = model.angular_velocity()
        a, alpha = _k.newton_euler(np.asarray(force, dtype=np.float64),
                                   np.asarray(torque, dtype=np.float64), self._mass,
                                   self._gravity, model.rotation(), self._j_inv, self._j, w)
        return a, alpha, w

    def exchange(self) -> None:
        """One exchange: run ``m`` DEM steps with the body at its window velocity, advance
        Exudyn with the mean wrench, put the DEM body at the new Exudyn pose with the next
        window velocity."""
        m = self.exchange_every
        h = self.h
        body, model, sim = self.body, self.model, self.sim
        if sim.dt != h:
            raise ValueError(
                f"CoSimulation: sim.dt={sim.dt!r} changed from {h!r} [s]; the staggered clock "
                "needs a constant step (build a new CoSimulation after set_dt)")
        tic = time.perf_counter()
        # 2. the DEM window (the kick, step 1, was given at the end of the last exchange)
        f_sum = np.zeros(3)
        t_sum = np.zeros(3)
        for _ in range(m):
            f_sum += body.force
            t_sum += body.torque
            sim.step(1)
        toc = time.perf_counter()
        # 3. Exudyn over the staggered macro step with the mean wrench
        f = f_sum / m
        tq = t_sum / m
        v_b, w_b = self._v_e, self._w_e
        t0 = model.time
        model.apply(f + self._extra_force, tq)
        model.advance(t0, t0 + m * h)
        # 4. + 1. new pose and next window velocity for the DEM
        self._place_and_kick()
        v_a, w_a = self._v_e, self._w_e
        self.ledger.body_interface_work += m * h * (
            f @ (0.5 * (v_a + v_b)) + tq @ (0.5 * (w_a + w_b)))
        self.last_force, self.last_torque = f, tq
        self.in_contact = bool(np.any(f != 0.0) or np.any(tq != 0.0))
        self.had_contact = self.had_contact or self.in_contact
        self.exchanges += 1
        self.wall_time["dem"] += toc - tic
        self.wall_time["exchange"] += time.perf_counter() - toc

    def body_kinetic_energy(self) -> float:
        """Body kinetic energy at the DEM time ``t_n`` with the synchronised velocities
        ``v_n = v_{n-1/2} + (h/2) a_n`` (as ``sim.energy()`` does for particles) [J]."""
        a_n, alpha_n, w = self._newton_euler(self.body.force, self.body.torque)
        v = self.model.velocity() + 0.5 * self.h * a_n
        w = w + 0.5 * self.h * alpha_n
        jw = self.model.inertia_world()
        return 0.5 * self.model.spec.mass * float(v @ v) + 0.5 * float(w @ (jw @ w))

    def update_ledger(self) -> EnergyLedger:
        """Refresh the energy ledger from the current DEM and Exudyn states."""
        led = self.ledger
        led.body_kinetic = self.body_kinetic_energy()
        g = np.asarray(self.sim.gravity, dtype=np.float64)
        led.body_potential = -self.model.spec.mass * float(g @ (self.body.position - self._x0))
        led.soil = dict(self.sim.energy())
        led.soil_interface_work = float(getattr(self.body, "work", 0.0)) - self._soil_work_0
        return led

    # ------------------------------------------------------------------ loop
    def run(self, t_end: float, on_step=None, stop_on_rebound: bool = False,
            rest_speed: float | None = None, ledger_every: int = 100):
        """Advance the coupled system to ``t_end`` (or until a stop criterion fires).

        Parameters
        ----------
        t_end : float
            End time [s] (DEM clock); the run stops at the first exchange reaching it.
        on_step : callable, optional
            ``on_step(t, sim, model)`` after every exchange (virtual sensors); ``t`` is the
            DEM time; ``model.time`` is ``t - h/2`` (leapfrog staggering).
        stop_on_rebound : bool
            Stop once the body has touched the soil and is now out of contact and moving
            away from it (``v . F_last_contact > 0``).
        rest_speed : float, optional
            Stop once the body has touched the soil and its CG speed is below this [m/s].
        ledger_every : int
            Refresh the energy ledger every this many exchanges (``sim.energy()`` costs about
            a DEM step); it is always refreshed at the end. The interface work on the body is
            accumulated at every exchange regardless.

        Returns
        -------
        EnergyLedger
            The final ledger; ``self.stop_reason`` says why the loop ended.
        """
        if int(ledger_every) < 1:
            raise ValueError(f"CoSimulation.run.ledger_every={ledger_every!r}: must be >= 1")
        if on_step is not None and not callable(on_step):
            raise ValueError(f"CoSimulation.run.on_step={on_step!r}: must be callable or None")
        if rest_speed is not None and not rest_speed > 0.0:
            raise ValueError(f"CoSimulation.run.rest_speed={rest_speed!r}: must be > 0 [m/s]")
        hm = self.exchange_every * self.h
        self.stop_reason = None
        last_contact_force = np.zeros(3)
        k = 0
        while self.sim.time + 0.5 * hm <= t_end:
            self.exchange()
            k += 1
            if k % ledger_every == 0:
                self.update_ledger()
            if on_step is not None:
                on_step(self.sim.time, self.sim, self.model)
            if self.in_contact:
                last_contact_force = self.last_force.copy()
            if self.had_contact and not self.in_contact and stop_on_rebound:
                if float(self.model.velocity() @ last_contact_force) > 0.0:
                    self.stop_reason = "rebound"
                    break
            if self.had_contact and rest_speed is not None:
                if np.linalg.norm(self.model.velocity()) < rest_speed:
                    self.stop_reason = "rest"
                    break
        else:
            self.stop_reason = "time"
        self.update_ledger()
        return self.ledger

    # ------------------------------------------------------------------ restart
    _STATE_KEYS = ("exchanges", "had_contact", "in_contact", "last_force", "last_torque",
                   "_x0", "_soil_work_0", "_momentum_0", "_impulse_0", "_angular_impulse_0",
                   "_v_e", "_w_e")

    def state_dict(self) -> dict:
        """Restart state of the coupling (the Exudyn model's state included; the DEM's own
        state comes from ``sim.state_dict()``)."""
        d = {k: (np.array(getattr(self, k)) if isinstance(getattr(self, k), np.ndarray)
                 else getattr(self, k)) for k in self._STATE_KEYS}
        d["model"] = self.model.state_dict()
        d["exchange_every"] = self.exchange_every
        d["h"] = self.h
        led = self.ledger
        d["ledger"] = {"body_kinetic": led.body_kinetic, "body_potential": led.body_potential,
                       "body_interface_work": led.body_interface_work, "soil": dict(led.soil),
                       "soil_interface_work": led.soil_interface_work,
                       "body_kinetic_0": led.body_kinetic_0, "soil_0": dict(led.soil_0)}
        return d

    @classmethod
    def from_state_dict(cls, sim, body_index: int, model, d: dict) -> "CoSimulation":
        """Resume a coupling from :meth:`state_dict` with a DEM restored from its own
        ``state_dict`` (the body's pose and window velocity come from the DEM state).

        Notes
        -----
        The DEM restart is bit-exact; the Exudyn body is rebuilt on its saved reference
        configuration with its exact ODE2 coordinates, velocities and solver clock (see
        ``ExudynRigidBody.load_state_dict``), so the resumed coupling is bit-identical to an
        uninterrupted one (same thread count).
        """
        if float(sim.dt) != float(d["h"]):
            raise ValueError(f"CoSimulation.from_state_dict: sim.dt={sim.dt!r} differs from the "
                             f"saved step {d['h']!r} [s]")
        self = cls.__new__(cls)
        self.sim = sim
        self.body_index = int(body_index)
        self.body = sim.boundaries[body_index]
        if self.body.motion != "coupled":
            raise ValueError(
                f"CoSimulation.from_state_dict: sim.boundaries[{body_index}].motion="
                f"{self.body.motion!r}: must be 'coupled'")
        self.model = model
        self._mass = float(model.spec.mass)
        self._gravity = np.asarray(model.gravity, dtype=np.float64)
        self._j = np.ascontiguousarray(model.spec.inertia, dtype=np.float64)
        self._j_inv = np.linalg.inv(self._j)
        self.exchange_every = int(d["exchange_every"])
        self.h = float(d["h"])
        self._extra_force = np.zeros(3) if model.gravity_in_exudyn else model.weight()
        model.load_state_dict(d["model"])
        for k in self._STATE_KEYS:
            v = d[k]
            setattr(self, k, np.array(v) if isinstance(v, np.ndarray) else v)
        self.ledger = EnergyLedger(**{k: (dict(v) if isinstance(v, dict) else v)
                                      for k, v in d["ledger"].items()})
        self.wall_time = {"dem": 0.0, "exchange": 0.0}
        self.stop_reason = None
        return self

    # ------------------------------------------------------------------ diagnostics
    def momentum_balance(self) -> dict:
        """Body momentum change vs the contact impulse and the weight impulse since the start.

        Returns
        -------
        dict
            ``delta_p`` (Exudyn body momentum change) [N s], ``impulse`` (DEM-accumulated
            contact impulse on the body) [N s], ``gravity_impulse`` [N s] and ``error``
            ``delta_p - impulse - gravity_impulse`` [N s].
        """
        mass = self.model.spec.mass
        dp = mass * self.model.velocity() - self._momentum_0
        j = np.array(self.body.impulse) - self._impulse_0
        t_elapsed = self.exchanges * self.exchange_every * self.h
        jg = mass * np.asarray(self.sim.gravity, dtype=np.float64) * t_elapsed
        return {"delta_p": dp, "impulse": j, "gravity_impulse": jg, "error": dp - j - jg}

    def body_state(self):
        """Body state synchronised with the DEM clock: the pose at ``sim.time`` (as used by
        the DEM), half-step velocities (as DEM particles), accelerations from the last wrench.

        Returns
        -------
        bodies.BodyState
        """
        st = self.model.state()
        return st._replace(position=np.array(self.body.position),
                           rotation=np.array(self.body.rotation), time=self.sim.time)

    @property
    def overhead_fraction(self) -> float:
        """Exudyn exchange wall time / DEM wall time so far [-]."""
        dem = self.wall_time["dem"]
        return self.wall_time["exchange"] / dem if dem > 0.0 else float("nan")
