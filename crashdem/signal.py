"""The one channel type used across crashdem: a uniformly or non-uniformly sampled signal with a unit.

Notes
-----
Units are SI strings (``"m/s^2"``, ``"N"``, ``"rad/s"``, ``"rad"``, ``"m"``, ``"m/s"``, ``"N*m"``).
Accelerations may be converted to ``"g"`` for display only (``G0 = 9.80665 m/s^2``, ISO 80000-3).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

G0 = 9.80665  # [m/s^2] standard gravity (ISO 80000-3)

#: units crashdem understands, with the factor that converts them to the SI unit on the right
UNIT_TO_SI: dict[str, tuple[float, str]] = {
    "m/s^2": (1.0, "m/s^2"),
    "m/s2": (1.0, "m/s^2"),
    "g": (G0, "m/s^2"),
    "G": (G0, "m/s^2"),
    "m/s": (1.0, "m/s"),
    "km/h": (1.0 / 3.6, "m/s"),
    "m": (1.0, "m"),
    "mm": (1e-3, "m"),
    "N": (1.0, "N"),
    "kN": (1e3, "N"),
    "N*m": (1.0, "N*m"),
    "Nm": (1.0, "N*m"),
    "rad/s": (1.0, "rad/s"),
    "deg/s": (np.pi / 180.0, "rad/s"),
    "rad": (1.0, "rad"),
    "deg": (np.pi / 180.0, "rad"),
    "s": (1.0, "s"),
    "J": (1.0, "J"),
    "Pa": (1.0, "Pa"),
    "kg": (1.0, "kg"),
    "1": (1.0, "1"),
}


def to_si(data: np.ndarray, unit: str) -> tuple[np.ndarray, str]:
    """Convert ``data`` given in ``unit`` to SI; raises ``ValueError`` for an unknown unit."""
    try:
        factor, si = UNIT_TO_SI[unit]
    except KeyError:
        raise ValueError(
            f"unit={unit!r}: unknown unit; known units are {sorted(UNIT_TO_SI)}"
        ) from None
    return np.asarray(data, dtype=float) * factor, si


@dataclass
class Signal:
    """A named channel: time [s], data [unit], and its metadata.

    Parameters
    ----------
    name : channel name (crashdem name, e.g. ``"rear_accel_x"``)
    t : (n,) time [s], strictly increasing
    data : (n,) samples in ``unit``
    unit : unit string (see ``UNIT_TO_SI``)
    cfc : channel frequency class the data were filtered with, or ``None`` for raw
    meta : free metadata (ISO-MME code, sensor position/direction, filter method, ...)
    """

    name: str
    t: np.ndarray
    data: np.ndarray
    unit: str
    cfc: float | None = None
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.t = np.asarray(self.t, dtype=float)
        self.data = np.asarray(self.data, dtype=float)
        if self.t.ndim != 1 or self.data.shape != self.t.shape:
            raise ValueError(
                f"Signal {self.name!r}: t and data must be 1-D of equal length, "
                f"got {self.t.shape} and {self.data.shape}"
            )

    @property
    def fs(self) -> float:
        """Sample rate [Hz] from the median sample interval."""
        if self.t.size < 2:
            raise ValueError(f"Signal {self.name!r}: fewer than 2 samples, no sample rate")
        return 1.0 / float(np.median(np.diff(self.t)))

    def to_si(self) -> "Signal":
        data, unit = to_si(self.data, self.unit)
        return Signal(self.name, self.t.copy(), data, unit, self.cfc, dict(self.meta))

    def in_g(self) -> "Signal":
        """Acceleration in g for display (input must be an acceleration)."""
        s = self.to_si()
        if s.unit != "m/s^2":
            raise ValueError(f"Signal {self.name!r}: unit {self.unit!r} is not an acceleration")
        return Signal(self.name, s.t, s.data / G0, "g", self.cfc, dict(self.meta))

    def window(self, t0: float, t1: float) -> "Signal":
        m = (self.t >= t0) & (self.t <= t1)
        return Signal(self.name, self.t[m], self.data[m], self.unit, self.cfc, dict(self.meta))

    def resample(self, t_new: np.ndarray) -> "Signal":
        """Linear interpolation onto ``t_new`` (no extrapolation: outside values raise)."""
        t_new = np.asarray(t_new, dtype=float)
        if t_new.size and (t_new[0] < self.t[0] - 1e-12 or t_new[-1] > self.t[-1] + 1e-12):
            raise ValueError(
                f"Signal {self.name!r}: resample range [{t_new[0]}, {t_new[-1]}] s outside "
                f"data range [{self.t[0]}, {self.t[-1]}] s"
            )
        return Signal(self.name, t_new, np.interp(t_new, self.t, self.data), self.unit,
                      self.cfc, dict(self.meta))
