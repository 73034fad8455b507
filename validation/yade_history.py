"""Shared tail of the Yade scripts (run *inside* Yade by ``yade -n -j1 -x SCRIPT cfg.json``).

``validation/campaign/yade_drop.py`` (the drop campaign's Yade comparison) and
``validation/diagnosis_yade/yade_truth.py`` (Yade truth recordings of the diagnosis) both advance
their scene one step at a time, record the drop mass's history and leave Yade without its
shutdown hooks. A Yade script imports this module with::

    sys.path.insert(0, str(Path(sys.argv[0]).resolve().parents[N]))   # the repository root
    from validation.yade_history import record_history, finish

(inside Yade ``__file__`` is the ``yade`` launcher; ``sys.argv[0]`` is the script). Only numpy
and the standard library are imported here: Yade's objects (``O``) are passed in.
"""
from __future__ import annotations

import json
import math
import os
import sys
from typing import Any

import numpy as np

__all__ = ["record_history", "finish"]


def record_history(O: Any, body_id: int, t_end: float, out: str,
                   facts: dict[str, Any] | None = None) -> np.ndarray:
    """Run the scene to ``t_end`` [s] one step at a time (``O.dt`` fixed) and record the body's
    history ``(t, z, v_z, F_z)`` after every step (``F_z``: the contact force on it, 0 at t0).

    Writes ``<out>.npy`` (the history, ``n + 1`` rows) and ``<out>.json`` (``mass``, ``steps``
    and ``facts``); returns the history."""
    n = int(math.ceil(t_end / O.dt))
    hist = np.zeros((n + 1, 4))
    b = O.bodies[body_id]
    hist[0] = (O.time, b.state.pos[2], b.state.vel[2], 0.0)
    for k in range(1, n + 1):
        # O.step() runs one iteration in this thread; O.run(1, True) hands it to Yade's
        # simulation thread and polls for its end, about 40 ms a step, sleeping (same result)
        O.step()
        hist[k] = (O.time, b.state.pos[2], b.state.vel[2], O.forces.f(body_id)[2])
    np.save(out + ".npy", hist)
    with open(out + ".json", "w") as f:
        json.dump({"mass": b.state.mass, "steps": n, **(facts or {})}, f)
    return hist


def finish() -> None:
    """Tell the caller the run completed (``YADE_DONE`` on stdout) and leave Yade at once
    (its interpreter shutdown can hang in headless mode)."""
    print("YADE_DONE")
    sys.stdout.flush()
    os._exit(0)
