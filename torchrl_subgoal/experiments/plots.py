"""Figures of a report: learning curves, and the subgoal patterns drawn on the domain's map.

Figures are drawn with matplotlib's object API (no pyplot), so making a report
neither needs a display nor changes the caller's matplotlib backend.

Maps come from per-domain hooks looked up by domain name in a small registry.
The built-in hooks import their environment module only when called, so a domain
whose module is missing or broken costs the report its map panel (with a note
saying why), never the whole report. Register a hook for a new domain with
:func:`register_map_hook`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from torchrl_subgoal.experiments.stats import mean_and_sem, moving_average

#: ``hook(ax, patterns, options)``: draw the map and ``patterns`` (name -> SubgoalSeries) on ``ax``.
MapHook = Callable[[Axes, Mapping[str, Any], Mapping[str, Any]], None]


@dataclass(frozen=True)
class FigureFile:
    """A written figure, or why it was not drawn.

    Examples:
        >>> FigureFile(None, "no subgoal patterns").note
        'no subgoal patterns'
    """

    path: Path | None
    note: str = ""


def _four_rooms_map(ax: Axes, patterns: Mapping[str, Any], options: Mapping[str, Any]) -> None:
    from torchrl_subgoal.envs import four_rooms
    from torchrl_subgoal.subgoals import Cell, State

    cells: dict[str, list[tuple[int, int]]] = {}
    for name, series in patterns.items():
        cells[name] = []
        for predicate in series.predicates:
            if isinstance(predicate, Cell):
                cells[name].append((predicate.row, predicate.col))
            elif isinstance(predicate, State):
                cells[name].append(four_rooms.free_cells()[predicate.state])
            else:
                raise ValueError(f"pattern {name}: a {type(predicate).__name__} is not a grid cell")
    four_rooms.draw_map(ax, cells, **options)


def _pinball_map(ax: Axes, patterns: Mapping[str, Any], options: Mapping[str, Any]) -> None:
    from torchrl_subgoal.envs import pinball
    from torchrl_subgoal.subgoals import Circle

    circles: dict[str, list[tuple[float, float, float]]] = {}
    for name, series in patterns.items():
        circles[name] = []
        for predicate in series.predicates:
            if not isinstance(predicate, Circle):
                raise ValueError(f"pattern {name}: a {type(predicate).__name__} is not a circle")
            x, y = predicate.centre[:2]
            circles[name].append((float(x), float(y), float(predicate.radius)))
    pinball.draw_map(ax, circles=circles, **options)


_MAP_HOOKS: dict[str, MapHook] = {"four_rooms": _four_rooms_map, "pinball": _pinball_map}


def register_map_hook(domain: str, hook: MapHook) -> None:
    """Use ``hook`` to draw subgoal patterns for ``domain`` (replacing any earlier one).

    Args:
        domain: the name sweeps of this domain record.
        hook: ``hook(ax, patterns, options)`` with ``patterns`` a mapping from pattern name
            to :class:`~torchrl_subgoal.subgoals.SubgoalSeries`, and ``options`` the
            ``report.map`` section of the sweep's config.

    Examples:
        >>> register_map_hook("line", lambda ax, patterns, options: ax.plot([0, 1], [0, 1]))
    """
    _MAP_HOOKS[domain] = hook


def plot_learning_curves(
    curves: Mapping[str, npt.ArrayLike],
    path: Path,
    *,
    metric: str = "steps",
    window: int = 1,
    thresholds: Sequence[float] = (),
    log_scale: bool = False,
    unit: str = "episode",
) -> FigureFile:
    """Mean ± standard error across learners, one line per method, in one PNG.

    Args:
        curves: method -> ``[n_learners, n_episodes]``.
        path: the PNG to write.
        metric: y-axis label.
        window: moving average applied to each learner before averaging (1 = none).
        thresholds: drawn as dashed horizontal lines.
        log_scale: logarithmic y axis (useful for steps that fall by orders of magnitude).
        unit: x-axis label.

    Examples:
        >>> import tempfile
        >>> out = Path(tempfile.mkdtemp()) / "curves.png"
        >>> plot_learning_curves({"A": np.ones((3, 5))}, out).path == out
        True
    """
    fig = Figure(figsize=(7, 4.2))
    ax = fig.subplots()
    for name, values in curves.items():
        smoothed = moving_average(values, window)
        mean, sem = mean_and_sem(smoothed)
        x = np.arange(window, window + mean.size)
        (line,) = ax.plot(x, mean, label=f"{name} (n={smoothed.shape[0]})", linewidth=1.2)
        ax.fill_between(x, mean - sem, mean + sem, color=line.get_color(), alpha=0.25, linewidth=0)
    for threshold in thresholds:
        ax.axhline(threshold, color="grey", linestyle="--", linewidth=0.7)
    if log_scale:
        ax.set_yscale("log")
    smoothing = f", moving average of {window}" if window > 1 else ""
    ax.set_xlabel(unit)
    ax.set_ylabel(metric)
    ax.set_title(f"{metric} per {unit}: mean ± s.e. across learners{smoothing}")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    return FigureFile(path)


def plot_pattern_maps(
    domain: str,
    patterns: Mapping[str, Any],
    path: Path,
    *,
    options: Mapping[str, Any] | None = None,
    max_panels: int = 20,
) -> FigureFile:
    """One panel per subgoal pattern, drawn on the domain's map.

    Args:
        domain: selects the map hook.
        patterns: pattern name -> its subgoals, as in a sweep's ``config["patterns"]``: a
            list of subgoal dicts (``{"cell": [4, 9]}``, ``{"circle": {"centre": [x, y],
            "radius": 0.04}}``) or a subgoal-file pattern body.
        path: the PNG to write.
        options: extra keyword arguments for the map (e.g. ``{"config": "hard"}`` for PinBall).
        max_panels: draw at most this many patterns (a note says how many were left out).

    Returns:
        The figure, or ``FigureFile(None, note)`` saying why no map was drawn.

    Examples:
        >>> import tempfile
        >>> folder = Path(tempfile.mkdtemp())
        >>> figure = plot_pattern_maps("four_rooms", {"alice": [{"cell": [4, 9]}]}, folder / "maps.png")
        >>> figure.path.name, figure.path.exists()
        ('maps.png', True)
    """
    hook = _MAP_HOOKS.get(domain)
    if hook is None:
        return FigureFile(None, f"no map is registered for domain {domain!r}")
    if not patterns:
        return FigureFile(None, "the sweep's config has no subgoal patterns to draw")
    names = list(patterns)[:max_panels]
    left_out = len(patterns) - len(names)
    try:
        from torchrl_subgoal.subgoals import SubgoalSeries

        series = {n: SubgoalSeries.from_dict(patterns[n], name=n) for n in names}
        cols = min(5, len(names))
        rows = math.ceil(len(names) / cols)
        fig = Figure(figsize=(2.6 * cols, 2.6 * rows))
        axes = fig.subplots(rows, cols, squeeze=False)
        for ax, name in zip(axes.flat, names, strict=False):
            hook(ax, {name: series[name]}, dict(options or {}))
            ax.set_title(name, fontsize=9)
            ax.set_xticks([])
            ax.set_yticks([])
        for ax in list(axes.flat)[len(names) :]:
            ax.axis("off")
        fig.tight_layout()
        path.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(path, dpi=110)
    except Exception as exc:  # a broken hook costs the map, not the report
        return FigureFile(None, f"map for domain {domain!r} skipped: {type(exc).__name__}: {exc}")
    note = f"{left_out} more pattern(s) not drawn" if left_out else ""
    return FigureFile(path, note)
