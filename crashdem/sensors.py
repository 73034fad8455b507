"""Virtual instrumentation: accelerometers, gyroscopes, pitch angle, point kinematics, body
force and boundary load cells, sampled at an exact acquisition rate from the DEM steps.

API
---
``BodyState(position, rotation, velocity, angular_velocity, acceleration, angular_acceleration,
force=None, torque=None)`` -- rigid-body state at one DEM instant (world frame, SI; ``rotation``
maps body to world; ``acceleration`` is the total CG acceleration *including* gravity).

``BoundaryContacts(points, forces)`` -- per-contact points (n, 3) [m] and the forces (n, 3) [N]
exerted *by the particles on* one boundary body (world frame);
``BoundaryContacts.from_contacts(sim.contacts(), body_index)`` builds it from the engine.

Sensors (frozen, keyword-only dataclasses; every one has ``name``, ``full_scale``,
``failure_factor``, ``dynamics``, ``iso_code``, ``cfc``):

* ``Accelerometer(name, body, position=(0,0,0), axis=(1,0,0), full_scale=inf, ...)`` specific
  force ``(a_P - g) . (R axis)`` [m/s^2] at a mount ``position`` (body frame, from the CG);
* ``Gyroscope(name, body, axis=PITCH_AXIS, ...)`` body angular rate ``omega . (R axis)`` [rad/s];
* ``PitchAngle(name, body, method="exact"|"integrated", initial="exact"|"zero", ...)`` [rad];
* ``PointKinematics(name, body, quantity="position"|"velocity"|"acceleration", point=(0,0,0),
  axis=(0,0,1), frame="world"|"body", relative=False)`` [m, m/s, m/s^2];
* ``BodyForce(name, body, quantity="force"|"torque", axis=(0,0,1), frame="world")`` [N, N*m];
* ``LoadCell(name, boundary, center, normal=(0,0,1), radius=None | half_size=(a, b),
  u_axis=None, plane_tolerance=inf, ...)`` normal force of the contacts in its footprint [N];
* ``MountDynamics(natural_frequency, damping_ratio)`` optional second-order sensor/mount response;
  ``MountDynamics.apply(signal)`` applies it to a stored channel (diagnosis hypothesis).

``SensorSet(sensors, fs=12500.0, t0=0.0, gravity=(0, 0, -9.81), sampling="box")``:

* ``record(t, bodies: Mapping[str, BodyState], contacts: Mapping[str, BoundaryContacts] | None)``
  once per DEM step (t strictly increasing);
* ``signals() -> dict[str, Signal]`` all samples so far (raw, SI; ``Signal.cfc`` is None and
  ``meta["cfc_class"]`` is the class the channel should be filtered with);
* ``drain() -> dict[str, (t, data)]`` the samples produced since the previous ``drain()`` (for the
  incremental HDF5 writer); ``channel_info() -> dict[str, dict]`` per-channel metadata;
* ``names``, ``units``, ``n_samples``;
* picklable: store it with the engine checkpoint and pass the restored set to
  ``crashdem.results.ResultWriter.resume``.

Construction from a body spec / scenario: ``sensors_for_body(spec.sensors, body, cfc=...,
accel_full_scale=..., failure_factor=..., dynamics=...)`` (accelerometers and gyros of the
``bodies.SensorMount`` list, plus exact and integrated pitch and CG velocity/displacement
channels); ``sensor_set_from_scenario(scenario, spec.sensors, body, load_cells=...)`` (sample
rate, CFC, full scale and the ``physics.sensor_dynamics`` switch of the scenario).

Helpers: ``j211_axis("x"|"y"|"z")`` (J211 axis in crashdem body axes), ``integrate_signal``
(cumulative trapezoid of a sampled channel, e.g. the lab's pitch angle from the gyro),
``pitch_from_rotation(R, up)``.

Conventions
-----------
crashdem body axes: x forward (nose), y to the left, z up (right-handed), so the world frame of
a level body is the DEM frame (z up, gravity -z). SAE J211 / ISO-MME axes are x forward, y right,
z down; the mapping is a rotation of pi about x: ``x_J = x``, ``y_J = -y``, ``z_J = -z``
(``j211_axis``). Pitch is positive nose-up in both conventions: it is a positive rotation about
J211 +y (right), i.e. about crashdem -y, hence the default gyro axis ``PITCH_AXIS = (0, -1, 0)``.
The exact pitch angle is the elevation of the body x axis above the horizontal plane
(``asin(x_body . up)``, computed with ``atan2``), which equals the pitch of a yaw-pitch-roll
(z-y-x) Tait-Bryan decomposition. The integrated pitch is the time integral of the body pitch
rate; the two agree exactly for planar (pitch-only) motion and differ in general 3-D motion,
because Euler-angle rates are not body rates.

Signal pipeline, per channel, at every DEM step (DEM rate, continuous-time model of the sensor):
ideal value -> [integration, integrated pitch only] -> [mount dynamics, optional] -> failure
check -> full-scale clipping -> acquisition (sampling at ``t_k = t0 + k/fs``).

Acquisition: the DEM step ``dt`` in general does not divide ``T = 1/fs``. Between two DEM
instants each channel is reconstructed as the straight line through its two values.

* ``sampling="linear"``: sample k is that line evaluated at ``t_k`` (point sampling). Error for a
  smooth channel y: ``|e| <= dt^2/8 max|y''|`` (linear interpolation); no anti-aliasing: content
  of the DEM signal above fs/2 (contact chatter at the DEM step scale) folds into the band.
* ``sampling="box"`` (default): sample k is the mean of the reconstruction over the centred window
  ``[t_k - T/2, t_k + T/2]`` (an ideal integrate-and-dump anti-aliasing filter, zero phase).
  Its transfer function is ``sinc(f/fs)``: -0.09 dB at 1000 Hz and -0.25 dB at 1650 Hz for
  fs = 12.5 kHz, inside the J211 CFC 1000 corridor (+0.5/-1 dB at F_H, +0.5/-4 dB at F_N), and
  it suppresses DEM-step chatter by averaging T/dt steps. Compared with the exact window mean of
  a smooth y, the error is bounded by ``dt^2/12 (1 + 2 dt/T) max|y''|`` (each of the at most
  T/dt + 2 whole or partial steps in the window contributes at most the trapezoid-rule error of
  a whole step, dt^3/12 max|y''|); compared with the point value y(t_k)
  there is the filter's own bias ``T^2/24 y''(t_k)``. Sample k is emitted once the DEM has passed
  ``t_k + T/2``.

Leapfrog accelerations: the engine's force F_n is computed from the state at t_n and held over
the step, ``v_{n+1/2} - v_{n-1/2} = dt F_n/m``; F_n/m is therefore the *mean* acceleration over
``[t_{n-1/2}, t_{n+1/2}]`` and is attributed to t_n. The linear reconstruction between the
(t_n, a_n) points has the same integral as the piecewise-constant one up to half a step at each
end, so a box-sampled acceleration integrates (sum of samples x T) to the velocity change over the
windows to within ``dt * max|a_{n+1} - a_n|`` per window edge; point sampling has no such
property when the step force is noisy.

Full scale and failure: values are clipped to ``[-full_scale, +full_scale]`` at the DEM rate (the
transducer saturates before the acquisition filter), so a box-sampled value never exceeds the full
scale. With ``failure_factor = X`` the channel is marked failed at the first DEM instant where
``|value| > X * full_scale`` (the reference glider test lost its 250 g front accelerometers); every
sample whose support extends past the last DEM instant before the failure is NaN, and the Signal
carries ``meta["failed_at"]`` [s] and ``meta["valid_until"]`` [s].

Mount dynamics: ``y'' + 2 zeta wn y' + wn^2 y = wn^2 u`` (``model="lowpass"``, seismic
transducer) or ``... = 2 zeta wn u' + wn^2 u`` (``model="mount"``, transmissibility of a resonant
mount), unit static gain, integrated exactly for a piecewise-linear input (first-order-hold
discretisation by the matrix exponential of the augmented system), started at rest in static
equilibrium with the first input value.

Load cells: a footprint (disc of ``radius``, or rectangle ``|u| <= a, |v| <= b`` half-open as
``-a <= u < a``, ``-b <= v < b`` so that adjacent tiles partition the plane) on the boundary plane
through ``center`` with unit ``normal`` (pointing into the particle side, as ``soil.Plane``). The
reading is ``-sum(f_i . n)`` over contacts whose points lie in the footprint (and within
``plane_tolerance`` of the plane): positive in compression, i.e. when the particles push on the
boundary.

Notes
-----
Rigid-body point kinematics ``a_P = a + alpha x r + omega x (omega x r)``, ``v_P = v + omega x r``
(e.g. Shabana, Dynamics of Multibody Systems, ch. 2). Specific force ``f = R^T (a_P - g)``
(accelerometer principle, e.g. Titterton & Weston, Strapdown Inertial Navigation, ch. 4).
Sampling rate 12.5 kHz, 250 g front accelerometers and eight floor load cells: Varriale (2019),
ch. 2. J211 axes and sign convention: SAE J211-1 / ISO-MME (anchors.md section 3).
First-order-hold discretisation: Franklin, Powell & Workman, Digital Control of Dynamic Systems,
section 6.3.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np
from scipy.linalg import expm

from crashdem.signal import Signal

__all__ = [
    "Accelerometer",
    "BodyForce",
    "BodyState",
    "BoundaryContacts",
    "Gyroscope",
    "LoadCell",
    "MountDynamics",
    "dynamics_from_scenario",
    "PITCH_AXIS",
    "PitchAngle",
    "PointKinematics",
    "SAMPLING_MODES",
    "SensorSet",
    "integrate_signal",
    "j211_axis",
    "pitch_from_rotation",
    "sensor_set_from_scenario",
    "sensors_for_body",
]

#: body pitch axis in crashdem body axes: positive rate = nose-up (J211 +y, right)
PITCH_AXIS = (0.0, -1.0, 0.0)
#: acquisition modes (see module docstring)
SAMPLING_MODES = ("box", "linear")
#: default acquisition rate of the reference tests [Hz] (Varriale 2019, ch. 2)
DEFAULT_FS = 12500.0
#: tolerance on the unit length of a user-given direction before normalisation [1]
_UNIT_TOL = 1e-6

#: relative step change below which a mount-dynamics transition matrix is reused [1]
_DT_RTOL = 1e-9
#: mount-dynamics models (``MountDynamics.model``)
MOUNT_MODELS = ("lowpass", "mount")

_J211_AXES = {"x": (1.0, 0.0, 0.0), "y": (0.0, -1.0, 0.0), "z": (0.0, 0.0, -1.0)}


def j211_axis(axis: str) -> tuple[float, float, float]:
    """Direction of a SAE J211 / ISO-MME body axis expressed in crashdem body axes.

    Parameters
    ----------
    axis : "x" (forward), "y" (right) or "z" (down), J211 convention

    Returns
    -------
    unit vector in crashdem body axes (x forward, y left, z up)

    Notes
    -----
    SAE J211-1 sign convention (x forward, y right, z down); crashdem = J211 rotated by pi about x.
    """
    key = axis.lower()
    if key not in _J211_AXES:
        raise ValueError(f"axis={axis!r}: must be one of 'x', 'y', 'z' (J211 body axes)")
    return _J211_AXES[key]


def _vec3(owner: str, fname: str, value: Any, unit: str = "", normalise: bool = False
          ) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{owner}.{fname}={value!r}: must be 3 finite numbers"
                         + (f" [{unit}]" if unit else ""))
    if normalise:
        n = float(np.linalg.norm(arr))
        if n < _UNIT_TOL:
            raise ValueError(f"{owner}.{fname}={value!r}: must be a non-zero direction")
        arr = arr / n
    return arr


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    # explicit 3-vector cross product (np.cross has a large per-call overhead)
    return np.array((a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                     a[0] * b[1] - a[1] * b[0]))


# --------------------------------------------------------------------------------------------
# inputs from the run loop
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class BodyState:
    """Rigid-body state at one DEM instant (world frame, SI).

    Parameters
    ----------
    position : (3,) CG position [m]
    rotation : (3, 3) rotation matrix, body -> world [1]
    velocity : (3,) CG velocity [m/s]
    angular_velocity : (3,) angular velocity, world frame [rad/s]
    acceleration : (3,) CG acceleration, total (including gravity: free fall gives ``g``) [m/s^2]
    angular_acceleration : (3,) angular acceleration, world frame [rad/s^2]
    force : (3,) optional contact force on the body (without gravity), world frame [N]
    torque : (3,) optional contact torque about the CG, world frame [N*m]
    """

    position: np.ndarray
    rotation: np.ndarray
    velocity: np.ndarray = field(default_factory=lambda: np.zeros(3))
    angular_velocity: np.ndarray = field(default_factory=lambda: np.zeros(3))
    acceleration: np.ndarray = field(default_factory=lambda: np.zeros(3))
    angular_acceleration: np.ndarray = field(default_factory=lambda: np.zeros(3))
    force: np.ndarray | None = None
    torque: np.ndarray | None = None

    def __post_init__(self) -> None:
        for name in ("position", "velocity", "angular_velocity", "acceleration",
                     "angular_acceleration", "force", "torque"):
            value = getattr(self, name)
            if value is None:
                continue
            arr = np.asarray(value, dtype=float)
            if arr.shape != (3,):
                raise ValueError(f"BodyState.{name}: shape {arr.shape}, must be (3,)")
            object.__setattr__(self, name, arr)
        rot = np.asarray(self.rotation, dtype=float)
        if rot.shape != (3, 3):
            raise ValueError(f"BodyState.rotation: shape {rot.shape}, must be (3, 3)")
        object.__setattr__(self, "rotation", rot)


@dataclass(frozen=True)
class BoundaryContacts:
    """Per-contact forces on one boundary body (world frame).

    Parameters
    ----------
    points : (n, 3) contact points [m]
    forces : (n, 3) force exerted *by the particles on the boundary* at each point [N]
        (the negative of the force on the particle)
    """

    points: np.ndarray
    forces: np.ndarray

    def __post_init__(self) -> None:
        p = np.asarray(self.points, dtype=float).reshape(-1, 3) if np.size(self.points) else \
            np.zeros((0, 3))
        f = np.asarray(self.forces, dtype=float).reshape(-1, 3) if np.size(self.forces) else \
            np.zeros((0, 3))
        if p.shape != f.shape:
            raise ValueError(f"BoundaryContacts: points {p.shape} and forces {f.shape} must both "
                             "be (n, 3)")
        object.__setattr__(self, "points", p)
        object.__setattr__(self, "forces", f)

    @classmethod
    def from_contacts(cls, contacts: Mapping[str, np.ndarray], body: int) -> "BoundaryContacts":
        """The contacts of boundary body ``body`` from ``soil.Simulation.contacts()``.

        Parameters
        ----------
        contacts : dict with ``body`` (n,), ``normal`` (n, 3, from the wall to the particle),
            ``fn`` (n,, compression > 0) [N], ``fs`` (n, 3, shear force on the particle) [N],
            ``point`` (n, 3) [m] (the ``soil.Simulation.contacts()`` layout)
        body : index of the boundary body in the simulation's ``boundaries`` list

        Notes
        -----
        Force on the boundary = -(force on the particle) = -(fn * normal + fs) (Newton's third
        law).
        """
        m = np.asarray(contacts["body"]) == body
        f_particle = (np.asarray(contacts["fn"], dtype=float)[m, None]
                      * np.asarray(contacts["normal"], dtype=float)[m]
                      + np.asarray(contacts["fs"], dtype=float)[m])
        return cls(np.asarray(contacts["point"], dtype=float)[m], -f_particle)


# --------------------------------------------------------------------------------------------
# sensor definitions
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class MountDynamics:
    """Second-order transducer/mount response.

    Parameters
    ----------
    natural_frequency : undamped natural frequency fn [Hz], > 0
    damping_ratio : zeta [1], in [0, 10]
    model : ``"lowpass"`` (default): seismic transducer ``wn^2 / (s^2 + 2 zeta wn s + wn^2)``;
        ``"mount"``: base-excitation transmissibility of an accelerometer on a resonant mount,
        ``(2 zeta wn s + wn^2) / (s^2 + 2 zeta wn s + wn^2)`` (the sensor mass's absolute
        acceleration)

    Notes
    -----
    Both have unit static gain and the same resonance; they differ in the damping's role and in
    the high-frequency roll-off (-40 dB/decade for the low-pass, -20 dB/decade for the mount).
    Harris' Shock and Vibration Handbook, ch. 12 (seismic transducer); Thomson & Dahl, *Theory
    of Vibration with Applications*, section 3.5 (transmissibility).
    """

    natural_frequency: float  # [Hz], > 0
    damping_ratio: float  # [1], in [0, 10]
    model: str = "lowpass"  # "lowpass" or "mount"

    def __post_init__(self) -> None:
        if not (math.isfinite(self.natural_frequency) and self.natural_frequency > 0):
            raise ValueError(f"MountDynamics.natural_frequency={self.natural_frequency!r}: "
                             "must be > 0 [Hz]")
        if not (math.isfinite(self.damping_ratio) and 0.0 <= self.damping_ratio <= 10.0):
            raise ValueError(f"MountDynamics.damping_ratio={self.damping_ratio!r}: "
                             "must be in [0, 10] [1]")
        if self.model not in MOUNT_MODELS:
            raise ValueError(f"MountDynamics.model={self.model!r}: must be one of {MOUNT_MODELS}")

    def foh_matrix(self, h: float) -> np.ndarray:
        """Exact first-order-hold transition over a step ``h`` [s].

        Returns E (2, 4): ``y_{n+1} = E[:, :2] y_n + E[:, 2] u_n + E[:, 3] (u_{n+1} - u_n)/h``
        with state ``y = (output, d output/dt)``.

        Notes
        -----
        Matrix exponential of the augmented system (x, u, du/dt) (Franklin, Powell & Workman,
        Digital Control of Dynamic Systems, 6.3).
        """
        wn = 2.0 * math.pi * self.natural_frequency
        z = self.damping_ratio
        m = np.zeros((4, 4))
        m[0, 1] = 1.0
        m[1, 0] = -wn * wn
        m[1, 1] = -2.0 * z * wn
        m[1, 2] = wn * wn
        if self.model == "mount":  # numerator 2 zeta wn s: the input rate drives the damper
            m[1, 3] = 2.0 * z * wn
        m[2, 3] = 1.0
        return expm(m * h)[:2, :]

    def apply(self, signal: Signal) -> Signal:
        """The response of this transducer to a sampled channel (post-hoc sensor dynamics).

        The input is taken as piecewise linear between samples (exact first-order hold, any
        sample spacing); the transducer starts at rest in equilibrium with the first sample.
        Used by the diagnosis to test a mount resonance on a stored channel without re-running.

        Parameters
        ----------
        signal : input channel (any unit; NaN samples propagate)

        Returns
        -------
        Signal with the same time base and unit, ``meta["dynamics"]`` added

        Notes
        -----
        Same discretisation as the DEM-rate model of ``SensorSet`` (first-order hold, Franklin,
        Powell & Workman 6.3).
        """
        t, u = signal.t, signal.data
        y = np.empty_like(u)
        if u.size:
            state = np.array((u[0], 0.0))
            y[0] = u[0]
            h_prev, e = None, None
            for k in range(1, u.size):
                h = t[k] - t[k - 1]
                if h_prev is None or abs(h - h_prev) > _DT_RTOL * h:
                    e = self.foh_matrix(h)
                    h_prev = h
                state = e[:, :2] @ state + e[:, 2] * u[k - 1] + e[:, 3] * (u[k] - u[k - 1]) / h
                y[k] = state[0]
        meta = dict(signal.meta)
        meta["dynamics"] = {"natural_frequency": self.natural_frequency,
                            "damping_ratio": self.damping_ratio, "model": self.model}
        return Signal(signal.name, t.copy(), y, signal.unit, signal.cfc, meta)


@dataclass(frozen=True, kw_only=True)
class _Sensor:
    """Fields common to every sensor (see the module docstring)."""

    name: str
    full_scale: float = math.inf  # [channel unit], > 0; clipping range +-full_scale
    failure_factor: float | None = None  # channel fails when |value| > factor * full_scale; > 1
    dynamics: MountDynamics | None = None
    iso_code: str | None = None  # 16-character ISO/TS 13499 channel code
    cfc: float | None = None  # channel frequency class for the filtered channel [Hz]

    unit = "1"
    kind = "sensor"

    def _check_common(self) -> None:
        cls = type(self).__name__
        if not isinstance(self.name, str) or not self.name or "/" in self.name:
            raise ValueError(f"{cls}.name={self.name!r}: must be a non-empty string without '/'")
        if not (self.full_scale > 0):
            raise ValueError(f"{cls}.full_scale={self.full_scale!r}: must be > 0 [{self.unit}]")
        if self.failure_factor is not None:
            if not (math.isfinite(self.failure_factor) and self.failure_factor >= 1.0):
                raise ValueError(f"{cls}.failure_factor={self.failure_factor!r}: must be >= 1 "
                                 "or None [1]")
            if not math.isfinite(self.full_scale):
                raise ValueError(f"{cls}.failure_factor={self.failure_factor!r}: needs a finite "
                                 f"full_scale (got {self.full_scale!r})")
        if self.iso_code is not None:
            code = self.iso_code
            if not (isinstance(code, str) and len(code) == 16 and code.isalnum()
                    and code.upper() == code):
                raise ValueError(f"{cls}.iso_code={code!r}: must be 16 upper-case letters/digits "
                                 "(ISO/TS 13499 channel code)")
            try:
                from crashdem.isomme import ChannelCode
            except ImportError:  # pragma: no cover - isomme is part of the package
                ChannelCode = None
            if ChannelCode is not None:
                try:
                    ChannelCode.parse(code)
                except ValueError as exc:
                    raise ValueError(f"{cls}.iso_code={code!r}: {exc}") from None
        if self.cfc is not None and not (math.isfinite(self.cfc) and self.cfc > 0):
            raise ValueError(f"{cls}.cfc={self.cfc!r}: must be > 0 [Hz] or None")

    def info(self) -> dict[str, Any]:
        """Channel metadata stored with the samples (JSON-serialisable)."""
        out: dict[str, Any] = {"kind": self.kind, "unit": self.unit,
                               "full_scale": float(self.full_scale)}
        if self.failure_factor is not None:
            out["failure_factor"] = float(self.failure_factor)
        if self.dynamics is not None:
            out["dynamics"] = {"natural_frequency": self.dynamics.natural_frequency,
                               "damping_ratio": self.dynamics.damping_ratio,
                               "model": self.dynamics.model}
        if self.iso_code is not None:
            out["iso_code"] = self.iso_code
        if self.cfc is not None:
            out["cfc_class"] = float(self.cfc)
        return out

    # ideal instantaneous value; overridden
    def _measure(self, bodies: Mapping[str, BodyState],
                 contacts: Mapping[str, BoundaryContacts], gravity: np.ndarray,
                 up: np.ndarray) -> float:  # pragma: no cover - abstract
        raise NotImplementedError


def _measure_accelerometers(group: Sequence["Accelerometer"], bodies, contacts, gravity, up
                            ) -> np.ndarray:
    """Vectorised ``Accelerometer._measure`` for the accelerometers of one body."""
    st = _body(bodies, group[0].name, group[0].body)
    rot = st.rotation
    r_b = np.array([s._r for s in group])
    e_b = np.array([s._e for s in group])
    w, al = st.angular_velocity, st.angular_acceleration
    # alpha x r + omega x (omega x r) = K r, K = skew(alpha) + skew(omega)^2
    k = np.array([[0.0, -al[2], al[1]], [al[2], 0.0, -al[0]], [-al[1], al[0], 0.0]])
    k += np.outer(w, w) - (w @ w) * np.eye(3)
    a_p = st.acceleration - gravity + (r_b @ rot.T) @ k.T
    return np.einsum("ij,ij->i", a_p, e_b @ rot.T)


def _measure_load_cells(group: Sequence["LoadCell"], bodies, contacts, gravity, up
                        ) -> np.ndarray:
    """Vectorised ``LoadCell._measure`` for the load cells of one boundary."""
    c = contacts.get(group[0].boundary)
    if c is None or c.points.shape[0] == 0:
        return np.zeros(len(group))
    pts, frc = c.points, c.forces
    n_ = np.array([s._n for s in group])
    u_ = np.array([s._u for s in group])
    v_ = np.array([s._v for s in group])
    c_ = np.array([s._c for s in group])
    pu = pts @ u_.T - np.einsum("ij,ij->i", c_, u_)  # (m, cells) in-plane coordinates [m]
    pv = pts @ v_.T - np.einsum("ij,ij->i", c_, v_)
    disc = np.array([s.radius is not None for s in group])
    rad = np.array([s.radius if s.radius is not None else 0.0 for s in group])
    ha = np.array([s.half_size[0] if s.half_size is not None else 0.0 for s in group])
    hb = np.array([s.half_size[1] if s.half_size is not None else 0.0 for s in group])
    mask = np.where(disc, pu * pu + pv * pv < rad * rad,
                    (pu >= -ha) & (pu < ha) & (pv >= -hb) & (pv < hb))
    tol = np.array([s.plane_tolerance for s in group])
    if np.isfinite(tol).any():
        dist = pts @ n_.T - np.einsum("ij,ij->i", c_, n_)
        mask &= np.abs(dist) <= tol
    return -np.einsum("ij,ij->j", frc @ n_.T, mask)


def _body(bodies: Mapping[str, BodyState], sensor: str, body: str) -> BodyState:
    try:
        return bodies[body]
    except KeyError:
        raise KeyError(f"sensor {sensor!r}: body {body!r} not in the recorded states "
                       f"{sorted(bodies)}") from None


@dataclass(frozen=True, kw_only=True)
class Accelerometer(_Sensor):
    """Uniaxial accelerometer: specific force along a body axis at a mount point.

    Parameters
    ----------
    body : name of the body it is mounted on
    position : (3,) mount point in body axes, relative to the CG [m]
    axis : (3,) sensitive axis in body axes (normalised) [1]
    full_scale : clipping range [m/s^2] (e.g. ``250 * G0``)

    Notes
    -----
    ``f = (a + alpha x r + omega x (omega x r) - g) . (R axis)``, ``r = R position``
    (rigid-body kinematics; accelerometer measures specific force).
    """

    body: str
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    axis: tuple[float, float, float] = (1.0, 0.0, 0.0)
    unit = "m/s^2"
    kind = "accelerometer"

    def __post_init__(self) -> None:
        self._check_common()
        object.__setattr__(self, "_r", _vec3("Accelerometer", "position", self.position, "m"))
        object.__setattr__(self, "_e", _vec3("Accelerometer", "axis", self.axis,
                                             normalise=True))

    def info(self) -> dict[str, Any]:
        out = super().info()
        out.update(body=self.body, position=[float(c) for c in self._r],
                   direction=[float(c) for c in self._e], frame="body")
        return out

    def _measure(self, bodies, contacts, gravity, up):
        s = _body(bodies, self.name, self.body)
        rot = s.rotation
        r_w = rot @ self._r
        w = s.angular_velocity
        a_p = s.acceleration + _cross(s.angular_acceleration, r_w) + _cross(w, _cross(w, r_w))
        return float((a_p - gravity) @ (rot @ self._e))


@dataclass(frozen=True, kw_only=True)
class Gyroscope(_Sensor):
    """Angular-rate sensor about a body axis.

    Parameters
    ----------
    body : body name
    axis : (3,) sensitive axis in body axes (default ``PITCH_AXIS``: positive = nose-up) [1]
    full_scale : clipping range [rad/s]

    Notes
    -----
    ``q = omega . (R axis)`` (rigid-body kinematics).
    """

    body: str
    axis: tuple[float, float, float] = PITCH_AXIS
    unit = "rad/s"
    kind = "gyroscope"

    def __post_init__(self) -> None:
        self._check_common()
        object.__setattr__(self, "_e", _vec3("Gyroscope", "axis", self.axis, normalise=True))

    def info(self) -> dict[str, Any]:
        out = super().info()
        out.update(body=self.body, direction=[float(c) for c in self._e], frame="body")
        return out

    def _measure(self, bodies, contacts, gravity, up):
        s = _body(bodies, self.name, self.body)
        return float(s.angular_velocity @ (s.rotation @ self._e))


def pitch_from_rotation(rotation: np.ndarray, up: Sequence[float] = (0.0, 0.0, 1.0)) -> float:
    """Pitch angle [rad], positive nose-up: elevation of the body x axis above the horizontal.

    Parameters
    ----------
    rotation : (3, 3) body -> world rotation matrix
    up : (3,) unit vertical (opposite to gravity)

    Notes
    -----
    ``theta = atan2(x_b . up, |x_b - (x_b . up) up|)`` = pitch of the z-y-x Tait-Bryan angles.
    """
    nose = np.asarray(rotation, dtype=float)[:, 0]
    upv = np.asarray(up, dtype=float)
    s = float(nose @ upv)
    horiz = nose - s * upv
    return math.atan2(s, math.sqrt(float(horiz @ horiz)))


@dataclass(frozen=True, kw_only=True)
class PitchAngle(_Sensor):
    """Pitch angle, positive nose-up [rad].

    Parameters
    ----------
    body : body name
    method : "exact" (from the rotation matrix, ``pitch_from_rotation``) or "integrated"
        (trapezoidal time integral, at the DEM rate, of the body rate about ``axis``)
    initial : for "integrated": start from the exact angle at the first record ("exact") or
        from 0 ("zero", as a lab integrating a gyro from the start of the record does)
    axis : (3,) body pitch axis for "integrated" (default ``PITCH_AXIS``) [1]

    Notes
    -----
    Exact = integrated for planar pitch-only motion; they differ in 3-D (Euler-angle rates are
    not body rates). For the lab procedure on a sampled (filtered) gyro channel use
    ``integrate_signal``.
    """

    body: str
    method: str = "exact"
    initial: str = "exact"
    axis: tuple[float, float, float] = PITCH_AXIS
    unit = "rad"
    kind = "pitch_angle"

    def __post_init__(self) -> None:
        self._check_common()
        if self.method not in ("exact", "integrated"):
            raise ValueError(f"PitchAngle.method={self.method!r}: must be 'exact' or "
                             "'integrated'")
        if self.initial not in ("exact", "zero"):
            raise ValueError(f"PitchAngle.initial={self.initial!r}: must be 'exact' or 'zero'")
        object.__setattr__(self, "_e", _vec3("PitchAngle", "axis", self.axis, normalise=True))

    def info(self) -> dict[str, Any]:
        out = super().info()
        out.update(body=self.body, method=self.method, initial=self.initial,
                   direction=[float(c) for c in self._e], frame="body")
        return out

    def _measure(self, bodies, contacts, gravity, up):
        s = _body(bodies, self.name, self.body)
        if self.method == "exact":
            return pitch_from_rotation(s.rotation, up)
        return float(s.angular_velocity @ (s.rotation @ self._e))  # rate; integrated by the set

    def _initial(self, bodies, up) -> float:
        if self.initial == "zero":
            return 0.0
        return pitch_from_rotation(_body(bodies, self.name, self.body).rotation, up)


_KIN_UNITS = {"position": "m", "velocity": "m/s", "acceleration": "m/s^2"}


@dataclass(frozen=True, kw_only=True)
class PointKinematics(_Sensor):
    """Position, velocity or (absolute) acceleration of a body point along an axis.

    Parameters
    ----------
    body : body name
    quantity : "position" [m], "velocity" [m/s] or "acceleration" [m/s^2] (total, gravity
        included: this is kinematics, not an accelerometer)
    point : (3,) point in body axes relative to the CG [m]
    axis : (3,) direction, in world axes (``frame="world"``) or body axes (``frame="body"``)
    relative : subtract the value at the first record (displacement from the start)

    Notes
    -----
    ``x_P = x + R r``, ``v_P = v + omega x R r``, ``a_P = a + alpha x R r + omega x (omega x R r)``.
    """

    body: str
    quantity: str = "position"
    point: tuple[float, float, float] = (0.0, 0.0, 0.0)
    axis: tuple[float, float, float] = (0.0, 0.0, 1.0)
    frame: str = "world"
    relative: bool = False
    kind = "kinematics"

    @property
    def unit(self) -> str:  # type: ignore[override]
        return _KIN_UNITS[self.quantity]

    def __post_init__(self) -> None:
        if self.quantity not in _KIN_UNITS:
            raise ValueError(f"PointKinematics.quantity={self.quantity!r}: must be one of "
                             f"{sorted(_KIN_UNITS)}")
        if self.frame not in ("world", "body"):
            raise ValueError(f"PointKinematics.frame={self.frame!r}: must be 'world' or 'body'")
        self._check_common()
        object.__setattr__(self, "_r", _vec3("PointKinematics", "point", self.point, "m"))
        object.__setattr__(self, "_e", _vec3("PointKinematics", "axis", self.axis,
                                             normalise=True))

    def info(self) -> dict[str, Any]:
        out = super().info()
        out.update(body=self.body, quantity=self.quantity, position=[float(c) for c in self._r],
                   direction=[float(c) for c in self._e], frame=self.frame,
                   relative=bool(self.relative))
        return out

    def _measure(self, bodies, contacts, gravity, up):
        s = _body(bodies, self.name, self.body)
        rot = s.rotation
        r_w = rot @ self._r
        if self.quantity == "position":
            vec = s.position + r_w
        elif self.quantity == "velocity":
            vec = s.velocity + _cross(s.angular_velocity, r_w)
        else:
            w = s.angular_velocity
            vec = (s.acceleration + _cross(s.angular_acceleration, r_w)
                   + _cross(w, _cross(w, r_w)))
        e = self._e if self.frame == "world" else rot @ self._e
        return float(vec @ e)


@dataclass(frozen=True, kw_only=True)
class BodyForce(_Sensor):
    """Contact force or torque on a body (``BodyState.force`` / ``.torque``) along an axis.

    Parameters
    ----------
    body : body name
    quantity : "force" [N] or "torque" [N*m] (about the CG)
    axis : (3,) direction in world (``frame="world"``) or body (``frame="body"``) axes
    """

    body: str
    quantity: str = "force"
    axis: tuple[float, float, float] = (0.0, 0.0, 1.0)
    frame: str = "world"
    kind = "body_force"

    @property
    def unit(self) -> str:  # type: ignore[override]
        return "N" if self.quantity == "force" else "N*m"

    def __post_init__(self) -> None:
        if self.quantity not in ("force", "torque"):
            raise ValueError(f"BodyForce.quantity={self.quantity!r}: must be 'force' or 'torque'")
        if self.frame not in ("world", "body"):
            raise ValueError(f"BodyForce.frame={self.frame!r}: must be 'world' or 'body'")
        self._check_common()
        object.__setattr__(self, "_e", _vec3("BodyForce", "axis", self.axis, normalise=True))

    def info(self) -> dict[str, Any]:
        out = super().info()
        out.update(body=self.body, quantity=self.quantity,
                   direction=[float(c) for c in self._e], frame=self.frame)
        return out

    def _measure(self, bodies, contacts, gravity, up):
        s = _body(bodies, self.name, self.body)
        vec = s.force if self.quantity == "force" else s.torque
        if vec is None:
            raise ValueError(f"sensor {self.name!r}: BodyState of {self.body!r} has no "
                             f"{self.quantity}")
        e = self._e if self.frame == "world" else s.rotation @ self._e
        return float(vec @ e)


@dataclass(frozen=True, kw_only=True)
class LoadCell(_Sensor):
    """Normal force of the particle contacts inside a footprint of a boundary plane.

    Parameters
    ----------
    boundary : name of the boundary body whose ``BoundaryContacts`` are passed to ``record``
    center : (3,) footprint centre, on the boundary plane, world frame [m]
    normal : (3,) plane normal pointing into the particle side [1]
    radius : disc footprint radius [m] (give either ``radius`` or ``half_size``)
    half_size : (a, b) rectangle half sizes along ``u_axis`` and ``normal x u_axis`` [m]
    u_axis : (3,) in-plane direction of the rectangle's first side (projected on the plane);
        default: world x projected on the plane (world y if x is normal to it)
    plane_tolerance : contacts farther than this from the plane are ignored [m] (default inf)
    full_scale : clipping range [N] (the reference tank cells: 2000 kg, i.e. 19.6 kN)

    Notes
    -----
    Reading ``-sum(f_i . n)`` over contacts in the footprint; positive in compression.
    Rectangles are half-open (``-a <= u < a``) so that adjacent tiles partition the plane.
    """

    boundary: str
    center: tuple[float, float, float] = (0.0, 0.0, 0.0)
    normal: tuple[float, float, float] = (0.0, 0.0, 1.0)
    radius: float | None = None
    half_size: tuple[float, float] | None = None
    u_axis: tuple[float, float, float] | None = None
    plane_tolerance: float = math.inf
    unit = "N"
    kind = "load_cell"

    def __post_init__(self) -> None:
        self._check_common()
        c = _vec3("LoadCell", "center", self.center, "m")
        n = _vec3("LoadCell", "normal", self.normal, normalise=True)
        if (self.radius is None) == (self.half_size is None):
            raise ValueError(f"LoadCell {self.name!r}: give exactly one of radius="
                             f"{self.radius!r} and half_size={self.half_size!r}")
        if self.radius is not None and not (math.isfinite(self.radius) and self.radius > 0):
            raise ValueError(f"LoadCell.radius={self.radius!r}: must be > 0 [m]")
        if self.half_size is not None:
            hs = np.asarray(self.half_size, dtype=float)
            if hs.shape != (2,) or not np.all(np.isfinite(hs)) or np.any(hs <= 0):
                raise ValueError(f"LoadCell.half_size={self.half_size!r}: must be two values "
                                 "> 0 [m]")
        if not (self.plane_tolerance > 0):
            raise ValueError(f"LoadCell.plane_tolerance={self.plane_tolerance!r}: must be > 0 [m]")
        if self.u_axis is not None:
            u = _vec3("LoadCell", "u_axis", self.u_axis)
        else:
            u = np.array((1.0, 0.0, 0.0)) if abs(n[0]) < 0.9 else np.array((0.0, 1.0, 0.0))
        u = u - (u @ n) * n
        if np.linalg.norm(u) < _UNIT_TOL:
            raise ValueError(f"LoadCell.u_axis={self.u_axis!r}: must not be parallel to the "
                             f"normal {tuple(n)}")
        u = u / np.linalg.norm(u)
        object.__setattr__(self, "_c", c)
        object.__setattr__(self, "_n", n)
        object.__setattr__(self, "_u", u)
        object.__setattr__(self, "_v", _cross(n, u))

    def info(self) -> dict[str, Any]:
        out = super().info()
        out.update(boundary=self.boundary, position=[float(x) for x in self._c],
                   direction=[float(x) for x in self._n], frame="world",
                   u_axis=[float(x) for x in self._u])
        if self.radius is not None:
            out["footprint"] = {"shape": "disc", "radius": float(self.radius)}
        else:
            out["footprint"] = {"shape": "rectangle",
                                "half_size": [float(x) for x in self.half_size]}
        return out

    def inside(self, points: np.ndarray) -> np.ndarray:
        """Boolean mask of the points (n, 3) [m] that lie in the footprint."""
        d = np.asarray(points, dtype=float).reshape(-1, 3) - self._c
        s = d @ self._n
        pu = d @ self._u
        pv = d @ self._v
        if self.radius is not None:
            m = pu * pu + pv * pv < self.radius * self.radius
        else:
            a, b = self.half_size
            m = (pu >= -a) & (pu < a) & (pv >= -b) & (pv < b)
        if math.isfinite(self.plane_tolerance):
            m &= np.abs(s) <= self.plane_tolerance
        return m

    def _measure(self, bodies, contacts, gravity, up):
        c = contacts.get(self.boundary)
        if c is None or c.points.shape[0] == 0:
            return 0.0
        m = self.inside(c.points)
        return float(-(c.forces[m] @ self._n).sum())


# --------------------------------------------------------------------------------------------
# the set: DEM-rate processing and acquisition
# --------------------------------------------------------------------------------------------
class SensorSet:
    """All sensors of a run, fed once per DEM step, sampled at exactly ``t0 + k/fs``.

    Parameters
    ----------
    sensors : sequence of sensors (unique names)
    fs : acquisition rate [Hz], > 0 (default 12500, the reference tests)
    t0 : time origin of the sample grid [s]
    gravity : (3,) gravity vector [m/s^2] (defines "up" for the pitch angle)
    sampling : "box" (window mean, default) or "linear" (point interpolation)

    Notes
    -----
    Pipeline, sampling rules and their error bounds: module docstring.
    """

    def __init__(self, sensors: Sequence[_Sensor], fs: float = DEFAULT_FS, t0: float = 0.0,
                 gravity: Sequence[float] = (0.0, 0.0, -9.81), sampling: str = "box") -> None:
        sensors = list(sensors)
        if not sensors:
            raise ValueError("SensorSet.sensors=[]: give at least one sensor")
        names = [s.name for s in sensors]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ValueError(f"SensorSet.sensors: duplicate names {dup}")
        if not (math.isfinite(fs) and fs > 0):
            raise ValueError(f"SensorSet.fs={fs!r}: must be > 0 [Hz]")
        if not math.isfinite(t0):
            raise ValueError(f"SensorSet.t0={t0!r}: must be finite [s]")
        if sampling not in SAMPLING_MODES:
            raise ValueError(f"SensorSet.sampling={sampling!r}: must be one of {SAMPLING_MODES}")
        self.sensors = sensors
        self.fs = float(fs)
        self.t0 = float(t0)
        self.sampling = sampling
        self.gravity = _vec3("SensorSet", "gravity", gravity, "m/s^2")
        gn = float(np.linalg.norm(self.gravity))
        self.up = -self.gravity / gn if gn > 0 else np.array((0.0, 0.0, 1.0))
        n = len(sensors)
        self._fullscale = np.array([s.full_scale for s in sensors], dtype=float)
        self._fail_limit = np.array(
            [s.full_scale * s.failure_factor if s.failure_factor is not None else math.inf
             for s in sensors])
        self._integrated = np.array([isinstance(s, PitchAngle) and s.method == "integrated"
                                     for s in sensors])
        self._relative = np.array([isinstance(s, PointKinematics) and s.relative
                                   for s in sensors])
        self._dyn_idx = np.array([i for i, s in enumerate(sensors) if s.dynamics is not None],
                                 dtype=int)
        self._dyn_state = np.zeros((self._dyn_idx.size, 2))
        self._dyn_h: float | None = None
        self._dyn_e = np.zeros((self._dyn_idx.size, 2, 4))
        # measurement groups: accelerometers per body and load cells per boundary are
        # evaluated with array operations; every other sensor alone
        groups: dict[tuple[str, str], list[int]] = {}
        singles: list[int] = []
        for i, sen in enumerate(sensors):
            if type(sen) is Accelerometer:
                groups.setdefault(("acc", sen.body), []).append(i)
            elif type(sen) is LoadCell:
                groups.setdefault(("cell", sen.boundary), []).append(i)
            else:
                singles.append(i)
        self._groups = [(_measure_accelerometers if kind == "acc" else _measure_load_cells,
                         np.array(idx, dtype=int), [sensors[i] for i in idx])
                        for (kind, _), idx in groups.items()]
        self._singles = singles
        self._failed_at = np.full(n, math.inf)
        self._valid_until = np.full(n, math.inf)
        # DEM-rate history (last instant)
        self._t_prev: float | None = None
        self._u_prev = np.zeros(n)  # input of the dynamics (ideal, integrated) at t_prev
        self._y_prev = np.zeros(n)  # processed (clipped) value at t_prev
        self._integral = np.zeros(n)
        self._offset = np.zeros(n)
        # acquisition
        self._k_next = 0  # next sample index (linear) / next window edge index (box)
        self._acc: np.ndarray | None = None  # integral since the last window edge (box)
        self._t_samples: list[float] = []
        self._samples: list[np.ndarray] = []
        self._drained = 0

    # ---------------------------------------------------------------------------------------
    @property
    def names(self) -> list[str]:
        """Channel names, in sensor order."""
        return [s.name for s in self.sensors]

    @property
    def units(self) -> dict[str, str]:
        """Channel unit by name (SI)."""
        return {s.name: s.unit for s in self.sensors}

    @property
    def n_samples(self) -> int:
        """Number of acquired samples so far."""
        return len(self._t_samples)

    def channel_info(self) -> dict[str, dict[str, Any]]:
        """Per-channel metadata (kind, unit, body/boundary, position, direction, full scale,
        ISO code, CFC class, sampling), JSON-serialisable; failure times once known."""
        out = {}
        for i, s in enumerate(self.sensors):
            meta = s.info()
            meta["sample_rate"] = self.fs
            meta["t0"] = self.t0
            meta["sampling"] = self.sampling
            if math.isfinite(self._failed_at[i]):
                meta["failed_at"] = float(self._failed_at[i])
                meta["valid_until"] = float(self._valid_until[i])
            out[s.name] = meta
        return out

    # ---------------------------------------------------------------------------------------
    def _dyn_matrices(self, h: float) -> np.ndarray:
        # DEM steps recovered as t_n - t_{n-1} differ from dt by round-off (~1e-12 relative);
        # reusing the transition matrices within _DT_RTOL changes the response by O(_DT_RTOL)
        if self._dyn_h is None or abs(self._dyn_h - h) > _DT_RTOL * h:
            for j, i in enumerate(self._dyn_idx):
                self._dyn_e[j] = self.sensors[i].dynamics.foh_matrix(h)
            self._dyn_h = h
        return self._dyn_e

    def _measure(self, bodies: Mapping[str, BodyState],
                 contacts: Mapping[str, BoundaryContacts]) -> np.ndarray:
        g, up = self.gravity, self.up
        u = np.empty(len(self.sensors))
        for fn, idx, group in self._groups:
            u[idx] = fn(group, bodies, contacts, g, up)
        for i in self._singles:
            u[i] = self.sensors[i]._measure(bodies, contacts, g, up)
        return u

    def record(self, t: float, bodies: Mapping[str, BodyState],
               contacts: Mapping[str, BoundaryContacts] | None = None) -> None:
        """Feed the state at one DEM instant.

        Parameters
        ----------
        t : simulation time [s], strictly greater than the previous call's
        bodies : body name -> ``BodyState``
        contacts : boundary name -> ``BoundaryContacts`` (load cells); a missing boundary
            reads 0 N
        """
        t = float(t)
        if self._t_prev is not None and not t > self._t_prev:
            raise ValueError(f"SensorSet.record: t={t!r} s must be > previous t="
                             f"{self._t_prev!r} s")
        contacts = {} if contacts is None else contacts
        up = self.up
        u = self._measure(bodies, contacts)
        first = self._t_prev is None
        if first:
            for i in np.flatnonzero(self._integrated):
                self._integral[i] = self.sensors[i]._initial(bodies, up)
            self._offset = np.where(self._relative, u, 0.0)
        else:
            h = t - self._t_prev
            if self._integrated.any():
                rate_prev = self._rate_prev
                self._integral = np.where(self._integrated,
                                          self._integral + 0.5 * h * (rate_prev + u),
                                          self._integral)
        self._rate_prev = u.copy()
        u = np.where(self._integrated, self._integral, u) - self._offset
        # mount dynamics (exact FOH), state = (output, rate)
        y = u.copy()
        if self._dyn_idx.size:
            ui = u[self._dyn_idx]
            if first:
                self._dyn_state[:, 0] = ui
                self._dyn_state[:, 1] = 0.0
            else:
                h = t - self._t_prev
                e = self._dyn_matrices(h)
                up_i = self._u_prev[self._dyn_idx]
                self._dyn_state = (np.einsum("jab,jb->ja", e[:, :, :2], self._dyn_state)
                                   + e[:, :, 2] * up_i[:, None]
                                   + e[:, :, 3] * ((ui - up_i) / h)[:, None])
            y[self._dyn_idx] = self._dyn_state[:, 0]
        # failure and clipping
        newly = (np.abs(y) > self._fail_limit) & ~np.isfinite(self._failed_at)
        if newly.any():
            self._failed_at[newly] = t
            self._valid_until[newly] = self._t_prev if self._t_prev is not None else -math.inf
        y = np.clip(y, -self._fullscale, self._fullscale)
        if self.sampling == "linear":
            self._acquire_linear(t, y, first)
        else:
            self._acquire_box(t, y, first)
        self._t_prev = t
        self._u_prev = u
        self._y_prev = y

    def _emit(self, k: int, value: np.ndarray, support_end: float) -> None:
        tk = self.t0 + k / self.fs
        # the window mean of clipped values can exceed the range by round-off only
        value = np.clip(value, -self._fullscale, self._fullscale)
        bad = support_end > self._valid_until
        if bad.any():
            value = np.where(bad, np.nan, value)
        self._t_samples.append(tk)
        self._samples.append(value)

    def _acquire_linear(self, t: float, y: np.ndarray, first: bool) -> None:
        fs, t0 = self.fs, self.t0
        if first:
            k = math.ceil((t - t0) * fs)
            while t0 + (k - 1) / fs >= t:
                k -= 1
            while t0 + k / fs < t:
                k += 1
            self._k_next = k
            if t0 + k / fs == t:
                self._emit(k, y.copy(), t)
                self._k_next = k + 1
            return
        tp, yp = self._t_prev, self._y_prev
        h = t - tp
        k = self._k_next
        while True:
            tk = t0 + k / fs
            if tk > t:
                break
            w = (tk - tp) / h
            self._emit(k, yp + w * (y - yp), tk)
            k += 1
        self._k_next = k

    def _acquire_box(self, t: float, y: np.ndarray, first: bool) -> None:
        # window k = [b_k, b_{k+1}], edge b_j = t0 + (j - 1/2)/fs
        fs, t0 = self.fs, self.t0

        def edge(j: int) -> float:
            return t0 + (j - 0.5) / fs

        if first:
            j = math.ceil((t - t0) * fs + 0.5)
            while edge(j - 1) >= t:
                j -= 1
            while edge(j) < t:
                j += 1
            if edge(j) == t:
                self._acc = np.zeros_like(y)
                j += 1
            self._k_next = j
            return
        tp, yp = self._t_prev, self._y_prev
        h = t - tp
        s, ys = tp, yp
        j = self._k_next
        while True:
            b = edge(j)
            if b > t:
                break
            yb = yp + ((b - tp) / h) * (y - yp)
            piece = (b - s) * 0.5 * (ys + yb)
            if self._acc is not None:
                self._emit(j - 1, (self._acc + piece) * fs, b)
            self._acc = np.zeros_like(y)
            s, ys = b, yb
            j += 1
        self._k_next = j
        if self._acc is not None:
            self._acc = self._acc + (t - s) * 0.5 * (ys + y)

    # ---------------------------------------------------------------------------------------
    def _signal(self, i: int, t: np.ndarray, data: np.ndarray, info: dict[str, Any]) -> Signal:
        s = self.sensors[i]
        return Signal(s.name, t, data, s.unit, None, info)

    def signals(self) -> dict[str, Signal]:
        """All samples so far, one raw ``Signal`` per channel (SI units)."""
        t = np.array(self._t_samples, dtype=float)
        data = np.array(self._samples, dtype=float).reshape(len(self._t_samples),
                                                            len(self.sensors))
        info = self.channel_info()
        return {s.name: self._signal(i, t, data[:, i].copy(), info[s.name])
                for i, s in enumerate(self.sensors)}

    def drain(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Samples produced since the previous ``drain()``: name -> (t [s], data [unit])."""
        lo = self._drained
        hi = len(self._t_samples)
        self._drained = hi
        t = np.array(self._t_samples[lo:hi], dtype=float)
        data = np.array(self._samples[lo:hi], dtype=float).reshape(hi - lo, len(self.sensors))
        return {s.name: (t, data[:, i].copy()) for i, s in enumerate(self.sensors)}


def sensors_for_body(mounts: Sequence[Any], body: str, *, cfc: float | None = None,
                     accel_full_scale: float | None = None,
                     failure_factor: float | None = None,
                     dynamics: MountDynamics | None = None, pitch: bool = True,
                     cg_kinematics: bool = True) -> list[_Sensor]:
    """Sensors for the mounts of a rigid-body spec (``bodies.SensorMount``-like objects).

    Parameters
    ----------
    mounts : objects with ``name``, ``position`` (body frame from the CG) [m], ``axis``,
        ``kind`` ("accelerometer" or "gyro") and ``full_scale`` [m/s^2 or rad/s]
    body : body name used in ``SensorSet.record``
    cfc : CFC class of every channel's filtered version [Hz] (None: stored raw only)
    accel_full_scale : range [m/s^2] of the body's main accelerometers (those with the largest
        own range, or an infinite one); mounts with a smaller own range keep it (e.g. the drop
        mass's 50 g lateral accelerometer next to its 200 g ones). None: every mount keeps its own
    failure_factor : failure factor of every accelerometer (None: no failure model)
    dynamics : mount dynamics of every accelerometer (None: ideal)
    pitch : add ``pitch_angle`` (exact, from R) and ``pitch_angle_integrated`` (gyro-style)
    cg_kinematics : add ``cg_velocity_x/z`` [m/s] and ``cg_displacement_x/z`` (from the first
        record) [m], world axes

    Returns
    -------
    list of sensors (channel names = mount names; ISO codes from ``crashdem.isomme`` are
    attached by the result writer for the well-known names)
    """
    out: list[_Sensor] = []
    acc_ranges = [float(m.full_scale) for m in mounts if m.kind == "accelerometer"]
    main_range = max(acc_ranges) if acc_ranges else math.inf
    for m in mounts:
        fs_m = float(m.full_scale)
        if m.kind == "accelerometer":
            if accel_full_scale is not None and fs_m == main_range:
                fs_m = float(accel_full_scale)
            ff = failure_factor if math.isfinite(fs_m) else None
            out.append(Accelerometer(name=m.name, body=body, position=tuple(m.position),
                                     axis=tuple(m.axis), full_scale=fs_m, failure_factor=ff,
                                     dynamics=dynamics, cfc=cfc))
        elif m.kind == "gyro":
            out.append(Gyroscope(name=m.name, body=body, axis=tuple(m.axis), full_scale=fs_m,
                                 cfc=cfc))
        else:
            raise ValueError(f"sensor mount {m.name!r}: kind={m.kind!r} must be "
                             "'accelerometer' or 'gyro'")
    if pitch:
        out.append(PitchAngle(name="pitch_angle", body=body, cfc=cfc))
        out.append(PitchAngle(name="pitch_angle_integrated", body=body, method="integrated",
                              cfc=cfc))
    if cg_kinematics:
        for ax, e in (("x", (1.0, 0.0, 0.0)), ("z", (0.0, 0.0, 1.0))):
            out.append(PointKinematics(name=f"cg_velocity_{ax}", body=body, quantity="velocity",
                                       axis=e))
            out.append(PointKinematics(name=f"cg_displacement_{ax}", body=body, axis=e,
                                       relative=True))
    return out


def dynamics_from_scenario(scenario: Any) -> tuple[float | None, MountDynamics | None]:
    """``(cfc, dynamics)`` of the accelerometer channels a scenario asks for: the
    instrumentation CFC and no sensor model, unless ``physics.sensor_dynamics`` is on (then its
    ``MountDynamics`` -- natural frequency, damping ratio, model -- and, when set, its CFC
    class). ``scenario`` needs ``get("dotted.key")``."""
    cfc = scenario.get("instrumentation.cfc")
    if not scenario.get("physics.sensor_dynamics.enabled"):
        return cfc, None
    dyn = MountDynamics(
        natural_frequency=float(scenario.get("physics.sensor_dynamics.natural_frequency")),
        damping_ratio=float(scenario.get("physics.sensor_dynamics.damping_ratio")),
        model=str(scenario.get("physics.sensor_dynamics.model") or "lowpass"))
    cfc_dyn = scenario.get("physics.sensor_dynamics.cfc")
    return (cfc if cfc_dyn is None else cfc_dyn), dyn


def sensor_set_from_scenario(scenario: Any, mounts: Sequence[Any], body: str = "impactor",
                             load_cells: Sequence[LoadCell] = (),
                             gravity: Sequence[float] = (0.0, 0.0, -9.81),
                             t0: float = 0.0, sampling: str = "box") -> SensorSet:
    """The ``SensorSet`` a scenario asks for.

    Uses ``instrumentation.sample_rate``, ``instrumentation.cfc``,
    ``instrumentation.accel_full_scale_g`` (range of the main accelerometers, see
    ``sensors_for_body``; a glider scenario sets 250) and, when
    ``physics.sensor_dynamics.enabled``, its ``natural_frequency``, ``damping_ratio`` and ``cfc``
    (replacing the instrumentation CFC when set). ``scenario`` needs ``get("dotted.key")`` (``crashdem.scenario.Scenario``).

    Parameters
    ----------
    scenario : the scenario
    mounts : the body's sensor mounts (``RigidBodySpec.sensors``)
    body : body name used in ``record``
    load_cells : boundary load cells to add (e.g. the eight floor cells of the tank)
    gravity : (3,) [m/s^2]
    t0 : origin of the sample grid [s]
    sampling : "box" or "linear"
    """
    from crashdem.signal import G0

    fs = float(scenario.get("instrumentation.sample_rate"))
    cfc, dyn = dynamics_from_scenario(scenario)
    sensors = sensors_for_body(
        mounts, body, cfc=None if cfc is None else float(cfc),
        accel_full_scale=float(scenario.get("instrumentation.accel_full_scale_g")) * G0,
        dynamics=dyn)
    return SensorSet(sensors + list(load_cells), fs=fs, t0=t0, gravity=gravity,
                     sampling=sampling)


def integrate_signal(signal: Signal, initial: float = 0.0, name: str | None = None,
                     unit: str | None = None) -> Signal:
    """Cumulative trapezoidal integral of a sampled channel (e.g. pitch angle from a gyro).

    Parameters
    ----------
    signal : channel to integrate (SI units are assumed for the default output unit)
    initial : value at the first sample [integrated unit]
    name : output channel name (default ``signal.name + "_integral"``)
    unit : output unit (default: "rad" for "rad/s", "m/s" for "m/s^2", "m" for "m/s")

    Notes
    -----
    Composite trapezoidal rule (second-order accurate); NaN samples propagate.
    """
    default_units = {"rad/s": "rad", "m/s^2": "m/s", "m/s": "m", "N": "N*s"}
    if unit is None:
        if signal.unit not in default_units:
            raise ValueError(f"integrate_signal: unit of {signal.name!r} is {signal.unit!r}; "
                             f"give unit= (known: {sorted(default_units)})")
        unit = default_units[signal.unit]
    t, x = signal.t, signal.data
    out = np.empty_like(x)
    if x.size:
        out[0] = initial
        out[1:] = initial + np.cumsum(0.5 * np.diff(t) * (x[1:] + x[:-1]))
    meta = dict(signal.meta)
    meta["integrated_from"] = signal.name
    return Signal(name or f"{signal.name}_integral", t.copy(), out, unit, signal.cfc, meta)

