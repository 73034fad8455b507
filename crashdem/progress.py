"""A dependency-free progress line for long runs: simulated time, steps per second and ETA.

Written to stderr, redrawn at most ``min_interval`` seconds apart; silent when disabled or when
stderr is not a terminal and ``force`` is false (log files then get one line every ``log_every`` s).
"""
from __future__ import annotations

import sys
import time


def _fmt_duration(s: float) -> str:
    if s != s or s == float("inf"):
        return "--:--"
    s = int(round(s))
    h, rem = divmod(s, 3600)
    m, sec = divmod(rem, 60)
    return f"{h:d}:{m:02d}:{sec:02d}" if h else f"{m:02d}:{sec:02d}"


class Progress:
    """Progress of a run from simulated time ``t0`` to ``t_end`` [s]."""

    def __init__(self, t_end: float, label: str = "run", enabled: bool = True, stream=None,
                 min_interval: float = 0.25, log_every: float = 10.0, t0: float = 0.0) -> None:
        self.t_end = float(t_end)
        self.t0 = float(t0)
        self.label = label
        self.enabled = enabled
        self.stream = stream or sys.stderr
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.min_interval = min_interval if self.tty else log_every
        self.wall0 = time.perf_counter()
        self.last = -1e9
        self.steps = 0

    def update(self, t: float, steps: int) -> None:
        self.steps = steps
        if not self.enabled:
            return
        now = time.perf_counter()
        if now - self.last < self.min_interval:
            return
        self.last = now
        self.stream.write(self.line(t, now) + ("\r" if self.tty else "\n"))
        self.stream.flush()

    def line(self, t: float, now: float | None = None) -> str:
        now = time.perf_counter() if now is None else now
        wall = max(now - self.wall0, 1e-9)
        frac = min(max((t - self.t0) / max(self.t_end - self.t0, 1e-300), 0.0), 1.0)
        eta = wall * (1.0 - frac) / frac if frac > 0 else float("inf")
        width = 24
        bar = "#" * int(frac * width) + "-" * (width - int(frac * width))
        return (f"{self.label} [{bar}] {frac * 100:5.1f}%  t={t * 1e3:8.2f}/{self.t_end * 1e3:.1f} ms  "
                f"{self.steps / wall:8.0f} steps/s  ETA {_fmt_duration(eta)}")

    def close(self, t: float) -> None:
        if self.enabled:
            self.last = -1e9
            self.update(t, self.steps)
            if self.tty:
                self.stream.write("\n")
                self.stream.flush()
