"""PNG plots of results and signal overlays (matplotlib, Agg canvas, no pyplot state).

API
---
``plot_result(path_or_result, out_dir, channels=None, in_g=True, raw=True) -> list[Path]``
    one PNG per channel group present: ``accelerations.png`` (g, or m/s^2 with ``in_g=False``),
    ``velocities.png`` (m/s), ``displacements.png`` (m: displacement / penetration),
    ``forces.png`` (N), ``moments.png`` (N*m), ``angular.png`` (rate in deg/s and angle in deg,
    two panels), ``energy.png`` (ledger, J), ``other.png``.
``result_figures(result, channels=None, in_g=True, raw=True) -> dict[str, Figure]``
    the same figures, not saved (group name -> Figure).
``plot_overlay(signals_by_label, out_png, shade_windows=None, title=None, in_g=True) -> Path``
    several Signals (e.g. recording / baseline / refit) on one axis, with shaded time windows;
    ``overlay_figure(...) -> Figure`` returns it unsaved.
``display(signal, in_g=True) -> (t_ms, data, unit)`` the conversion used for plotting.

Display conventions: time in ms; accelerations in g (``G0 = 9.80665 m/s^2``) when ``in_g``;
angles and angular rates in degrees. Filtered channels are drawn solid, the raw trace (when
``raw=True`` and the channel is filtered) thin and translucent behind it, labelled
``"<name> (raw)"``; a failed sensor's failure time is marked by a dotted vertical line.
Every line's x/y data are exactly ``display(signal)`` of the channel.

Notes
-----
Unit conversions: ``crashdem.signal.UNIT_TO_SI`` (g = 9.80665 m/s^2, ISO 80000-3).
"""
from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from crashdem.signal import G0, Signal, UNIT_TO_SI

__all__ = [
    "GROUPS",
    "display",
    "overlay_figure",
    "plot_overlay",
    "plot_result",
    "result_figures",
]

#: channel groups by SI unit of the data, in plotting order (group -> (SI units, file stem))
GROUPS: dict[str, tuple[tuple[str, ...], str]] = {
    "accelerations": (("m/s^2",), "accelerations"),
    "velocities": (("m/s",), "velocities"),
    "displacements": (("m",), "displacements"),
    "forces": (("N",), "forces"),
    "moments": (("N*m",), "moments"),
    "angular": (("rad/s", "rad"), "angular"),
    "energy": (("J",), "energy"),
}
_DPI = 110
_FIGSIZE = (9.0, 5.0)


def _group_of(unit: str) -> str:
    si = UNIT_TO_SI.get(unit, (1.0, unit))[1]
    for name, (units, _) in GROUPS.items():
        if si in units:
            return name
    return "other"


def display(signal: Signal, in_g: bool = True) -> tuple[np.ndarray, np.ndarray, str]:
    """Time [ms] and data in the display unit: g (if ``in_g``) for accelerations, deg and
    deg/s for angles and rates, SI otherwise.

    Returns
    -------
    (t_ms, data, unit_label)
    """
    t_ms = signal.t * 1e3
    if (signal.unit in ("g", "G") and in_g) or signal.unit in ("deg", "deg/s"):
        return t_ms, signal.data, "g" if signal.unit == "G" else signal.unit  # no round trip
    if signal.unit not in UNIT_TO_SI:
        return t_ms, signal.data, signal.unit
    s = signal.to_si()
    if s.unit == "m/s^2" and in_g:
        return t_ms, s.data / G0, "g"
    if s.unit == "rad":
        return t_ms, np.degrees(s.data), "deg"
    if s.unit == "rad/s":
        return t_ms, np.degrees(s.data), "deg/s"
    return t_ms, s.data, s.unit


def _new_figure(nrows: int = 1) -> tuple[Figure, list[Any]]:
    fig = Figure(figsize=(_FIGSIZE[0], _FIGSIZE[1] * (0.7 if nrows > 1 else 1.0) * nrows),
                 dpi=_DPI, layout="constrained")
    FigureCanvasAgg(fig)
    axes = [fig.add_subplot(nrows, 1, i + 1) for i in range(nrows)]
    return fig, axes


def _draw(ax: Any, sig: Signal, raw: Signal | None, in_g: bool, color: Any = None) -> str:
    if raw is not None:
        t, y, _ = display(raw, in_g)
        line = ax.plot(t, y, lw=0.6, alpha=0.35, label=f"{sig.name} (raw)", color=color)[0]
        color = line.get_color()
    t, y, unit = display(sig, in_g)
    label = sig.name + (f" (CFC {sig.cfc:g})" if sig.cfc is not None else "")
    line = ax.plot(t, y, lw=1.2, label=label, color=color)[0]
    line.set_gid(sig.name)
    failed = sig.meta.get("failed_at")
    if failed is not None and math.isfinite(float(failed)):
        ax.axvline(float(failed) * 1e3, ls=":", color=line.get_color(),
                   label=f"{sig.name} failed")
    return unit


def _finish(ax: Any, ylabel: str, title: str | None = None) -> None:
    ax.set_xlabel("time [ms]")
    ax.set_ylabel(ylabel)
    ax.grid(True, alpha=0.3)
    if title:
        ax.set_title(title)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize="small", loc="best")


def result_figures(result: Any, channels: Sequence[str] | None = None, in_g: bool = True,
                   raw: bool = True) -> dict[str, Figure]:
    """Figures of a result, one per channel group present (see module docstring).

    Parameters
    ----------
    result : ``crashdem.results.Result``
    channels : channel names to plot (default all)
    in_g : accelerations in g
    raw : draw the raw trace behind filtered channels
    """
    names = list(result.channels()) if channels is None else list(channels)
    unknown = [n for n in names if n not in result.channels()]
    if unknown:
        raise KeyError(f"channels {unknown} not in the result; channels: {result.channels()}")
    grouped: dict[str, list[tuple[Signal, Signal | None]]] = {}
    for name in names:
        sig = result.channel(name, filtered=True)
        raw_sig = result.channel(name, filtered=False) if (raw and sig.cfc is not None) else None
        grouped.setdefault(_group_of(sig.unit), []).append((sig, raw_sig))
    title = f"{Path(str(result.path)).name} ({result.status})"
    figs: dict[str, Figure] = {}
    for group in list(GROUPS) + ["other"]:
        if group == "energy":
            ledger = result.energy()
            if not ledger:
                continue
            fig, (ax,) = _new_figure()
            for sig in ledger.values():
                _draw(ax, sig, None, in_g)
            _finish(ax, "energy [J]", f"energy ledger - {title}")
            figs[group] = fig
            continue
        items = grouped.get(group)
        if not items:
            continue
        if group == "angular":
            rates = [it for it in items if it[0].to_si().unit == "rad/s"]
            angles = [it for it in items if it[0].to_si().unit == "rad"]
            panels = [p for p in (rates, angles) if p]
            fig, axes = _new_figure(len(panels))
            for ax, panel in zip(axes, panels):
                unit = ""
                for sig, rs in panel:
                    unit = _draw(ax, sig, rs, in_g)
                _finish(ax, ("angular rate" if unit == "deg/s" else "angle") + f" [{unit}]")
            axes[0].set_title(f"angular rate and pitch - {title}")
        else:
            fig, (ax,) = _new_figure()
            units = set()
            for sig, rs in items:
                units.add(_draw(ax, sig, rs, in_g))
            _finish(ax, f"{group} [{', '.join(sorted(units))}]", f"{group} - {title}")
        figs[group] = fig
    return figs


def _save(fig: Figure, path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    return path


def plot_result(path_or_result: Any, out_dir: str | os.PathLike,
                channels: Sequence[str] | None = None, in_g: bool = True,
                raw: bool = True) -> list[Path]:
    """Write one PNG per channel group of a result into ``out_dir``.

    Parameters
    ----------
    path_or_result : HDF5 path or an open ``Result``
    out_dir : output directory (created)
    channels : channel names (default all)
    in_g : accelerations in g
    raw : draw raw traces behind filtered ones

    Returns
    -------
    paths of the PNG files written, in group order
    """
    from crashdem.results import Result, open_result

    out = Path(out_dir)
    if isinstance(path_or_result, Result):
        figs = result_figures(path_or_result, channels, in_g, raw)
    else:
        with open_result(path_or_result) as res:
            figs = result_figures(res, channels, in_g, raw)
    return [_save(fig, out / f"{GROUPS.get(g, (None, g))[1]}.png") for g, fig in figs.items()]


def _windows(shade_windows: Any) -> list[tuple[float, float, str | None]]:
    if shade_windows is None:
        return []
    items = shade_windows.items() if isinstance(shade_windows, Mapping) else \
        [(w[2] if len(w) > 2 else None, w) for w in shade_windows]
    out = []
    for label, w in items:
        t0, t1 = float(w[0]), float(w[1])
        if not t1 > t0:
            raise ValueError(f"shade window {label or ''} ({t0}, {t1}) s: end must be > start")
        out.append((t0, t1, label))
    return out


def overlay_figure(signals_by_label: Mapping[str, Signal],
                   shade_windows: Any = None, title: str | None = None,
                   in_g: bool = True) -> Figure:
    """Figure with several signals on one axis (see ``plot_overlay``)."""
    if not signals_by_label:
        raise ValueError("plot_overlay: signals_by_label is empty")
    fig, (ax,) = _new_figure()
    units = set()
    for label, sig in signals_by_label.items():
        t, y, unit = display(sig, in_g)
        units.add(unit)
        ax.plot(t, y, lw=1.2, label=label)
    if len(units) > 1:
        raise ValueError(f"plot_overlay: signals have incompatible units {sorted(units)}")
    colors = ["tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown", "tab:gray"]
    for i, (t0, t1, label) in enumerate(_windows(shade_windows)):
        ax.axvspan(t0 * 1e3, t1 * 1e3, alpha=0.15, color=colors[i % len(colors)],
                   label=label)
    _finish(ax, f"[{units.pop()}]", title)
    return fig


def plot_overlay(signals_by_label: Mapping[str, Signal], out_png: str | os.PathLike,
                 shade_windows: Any = None, title: str | None = None,
                 in_g: bool = True) -> Path:
    """Overlay signals (e.g. recording / baseline / refit) with shaded time windows.

    Parameters
    ----------
    signals_by_label : legend label -> Signal (compatible units; converted for display)
    out_png : output file
    shade_windows : None, a sequence of ``(t0, t1)`` or ``(t0, t1, label)`` [s], or a mapping
        label -> ``(t0, t1)``
    title : figure title
    in_g : accelerations in g

    Returns
    -------
    the PNG path
    """
    fig = overlay_figure(signals_by_label, shade_windows, title, in_g)
    return _save(fig, Path(out_png))
