"""Figures of a report: learning curves, performance profiles, and the subgoal patterns drawn on the domain's map.

Figures are drawn with matplotlib's object API (no pyplot), so making a report
neither needs a display nor changes the caller's matplotlib backend; each is
written as PNG (for the Markdown report), PDF and SVG (for a paper). The
uncertainty bands are stratified-bootstrap intervals computed by rliable
(:mod:`~torchrl_subgoal.experiments.stats`).

Maps are drawn by the :class:`ReportMap` part of the domain registered under the
sweep's domain name (:mod:`torchrl_subgoal.domains`). A domain plugin is imported
only when its map is drawn, so a domain whose module is missing or broken costs
the report its map panel (with a note saying why), never the whole report.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
import numpy.typing as npt
from matplotlib.figure import Figure

from torchrl_subgoal import registry
from torchrl_subgoal.experiments.stats import curve_band, moving_average, performance_profile

T = TypeVar("T")

#: ``draw_map(ax, patterns, options)``: draw the map and ``patterns`` (name -> SubgoalSeries) on a
#: matplotlib ``Axes``; ``options`` is the ``report.map`` section of a sweep's config.
MapHook = Callable[[Any, Mapping[str, Any], Mapping[str, Any]], None]


@dataclass(frozen=True)
class ReportMap:
    """A domain's map in reports: the part of its registration the report's pattern maps are drawn by.

    Args:
        draw: ``draw(ax, patterns, options)``, the map and the patterns on a matplotlib ``Axes``.

    Examples:
        >>> from torchrl_subgoal import registry
        >>> isinstance(registry.get("four_rooms").part(ReportMap), ReportMap)
        True
    """

    draw: MapHook


def numbered_subgoals(patterns: Mapping[str, Any], kind: type[T]) -> Iterator[tuple[str, str, int, T]]:
    """Every subgoal of every pattern, for a map hook: ``(pattern name, its colour, subgoal number from 1,
    subgoal)``, one colour of matplotlib's cycle per pattern (``"C0"``, ``"C1"``…).

    Raises:
        ValueError: a subgoal is not a ``kind``; the message names the pattern.

    Examples:
        >>> from torchrl_subgoal import Cell, SubgoalSeries
        >>> [(name, colour, number, cell.row) for name, colour, number, cell in
        ...  numbered_subgoals({"alice": SubgoalSeries([Cell(4, 9)])}, Cell)]
        [('alice', 'C0', 1, 4)]
    """
    for k, (name, series) in enumerate(patterns.items()):
        for i, predicate in enumerate(series.predicates):
            if not isinstance(predicate, kind):
                raise ValueError(f"pattern {name}: a {type(predicate).__name__} is not a {kind.__name__.lower()}")
            yield name, f"C{k % 10}", i + 1, predicate


#: The formats every figure is written in, beside each other: the PNG the report shows, then PDF and SVG.
FORMATS = (".png", ".pdf", ".svg")


@dataclass(frozen=True)
class FigureFile:
    """A written figure (its PNG; the PDF and SVG beside it), or why it was not drawn.

    Examples:
        >>> FigureFile(None, "no subgoal patterns").note
        'no subgoal patterns'
        >>> [p.name for p in FigureFile(Path("curves.png")).paths]
        ['curves.png', 'curves.pdf', 'curves.svg']
    """

    path: Path | None
    note: str = ""

    @property
    def paths(self) -> tuple[Path, ...]:
        """Every file of the figure, one per format."""
        return () if self.path is None else tuple(self.path.with_suffix(f) for f in FORMATS)


def save_figure(fig: Figure, path: Path, dpi: int = 150) -> FigureFile:
    """Write ``fig`` as ``path`` (a PNG) and as PDF and SVG beside it.

    Examples:
        >>> import tempfile
        >>> fig = Figure()
        >>> _ = fig.subplots().plot([0, 1], [0, 1])
        >>> [p.exists() for p in save_figure(fig, Path(tempfile.mkdtemp()) / "line.png").paths]
        [True, True, True]
    """
    path.parent.mkdir(parents=True, exist_ok=True)
    for suffix in FORMATS:
        fig.savefig(path.with_suffix(suffix), dpi=dpi, metadata={"Date": None} if suffix == ".svg" else None)
    return FigureFile(path)


def plot_learning_curves(
    curves: Mapping[str, npt.ArrayLike],
    path: Path,
    *,
    metric: str = "steps",
    window: int = 1,
    thresholds: Sequence[float] = (),
    log_scale: bool = False,
    unit: str = "episode",
    frames_per_unit: int = 0,
    strata: Mapping[str, npt.ArrayLike] | None = None,
    n_boot: int = 500,
    seed: int = 0,
) -> FigureFile:
    """The mean across learners with its 95% stratified-bootstrap band (at up to 100 points), one line per method
    (PNG, PDF, SVG).

    Args:
        curves: method -> ``[n_learners, n_columns]``.
        path: the PNG to write.
        metric: y-axis label.
        window: moving average applied to each learner before averaging (1 = none).
        thresholds: drawn as dashed horizontal lines.
        log_scale: logarithmic y axis (useful for steps that fall by orders of magnitude).
        unit: what a column is (the x axis when ``frames_per_unit`` is 0: the paper's episodes or epochs).
        frames_per_unit: env frames per column; when set, the x axis is frames (environment steps).
        strata: method -> each learner's subgoal pattern, the bootstrap's strata.
        n_boot: bootstrap samples of the band.
        seed: the bootstrap's seed.

    Examples:
        >>> import tempfile
        >>> out = Path(tempfile.mkdtemp()) / "curves.png"
        >>> plot_learning_curves({"A": np.ones((3, 5))}, out, n_boot=50).path == out
        True
    """
    fig = Figure(figsize=(7, 4.2))
    ax = fig.subplots()
    for k, (name, values) in enumerate(curves.items()):
        smoothed = moving_average(values, window)
        band_seed = int(np.random.SeedSequence([seed, k]).generate_state(1)[0])
        columns, _, band = curve_band(smoothed, (strata or {}).get(name), n_boot=n_boot, seed=band_seed)
        scale = frames_per_unit or 1
        x = (np.arange(smoothed.shape[1]) + window) * scale
        (line,) = ax.plot(x, smoothed.mean(axis=0), label=f"{name} (n={smoothed.shape[0]})", linewidth=1.2)
        ax.fill_between((columns + window) * scale, band[0], band[1], color=line.get_color(), alpha=0.25, linewidth=0)
    for threshold in thresholds:
        ax.axhline(threshold, color="grey", linestyle="--", linewidth=0.7)
    if log_scale:
        ax.set_yscale("log")
    smoothing = f", moving average of {window} {unit}s" if window > 1 else ""
    ax.set_xlabel("frames (environment steps)" if frames_per_unit else unit)
    ax.set_ylabel(metric)
    ax.set_title(f"{metric} per {unit}: mean and 95% bootstrap CI across learners{smoothing}", fontsize=10)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return save_figure(fig, path)


def plot_performance_profile(
    scores: Mapping[str, npt.ArrayLike],
    path: Path,
    *,
    label: str,
    lower_is_better: bool,
    strata: Mapping[str, npt.ArrayLike] | None = None,
    log_scale: bool = False,
    n_boot: int = 500,
    seed: int = 0,
) -> FigureFile:
    """Performance profiles (rliable's score distributions): for each method, the fraction of learners whose
    score is better than τ, over τ, with 95% stratified-bootstrap bands (PNG, PDF, SVG).

    Args:
        scores: method -> one score per learner (e.g. its asymptotic performance).
        path: the PNG to write.
        label: what a score is (the x axis).
        lower_is_better: whether a learner does better below τ.
        strata: method -> each learner's subgoal pattern.
        log_scale: τ on a logarithmic axis (positive scores, such as steps).
        n_boot: bootstrap samples.
        seed: the bootstrap's seed.

    Examples:
        >>> import tempfile
        >>> out = Path(tempfile.mkdtemp()) / "profile.png"
        >>> plot_performance_profile({"A": [3.0, 5.0, 9.0]}, out, label="steps", lower_is_better=True).path == out
        True
    """
    values = {name: np.asarray(x, dtype=np.float64).ravel() for name, x in scores.items()}
    pooled = np.concatenate(list(values.values()))
    low, high = float(pooled.min()), float(pooled.max())
    high = high if high > low else low + 1.0
    log_scale = log_scale and low > 0
    taus = np.geomspace(low, high, 101) if log_scale else np.linspace(low, high, 101)
    profiles = performance_profile(
        values, dict(strata or {}), taus, lower_is_better=lower_is_better, n_boot=n_boot, seed=seed
    )
    fig = Figure(figsize=(6, 4))
    ax = fig.subplots()
    for name, (profile, band) in profiles.items():
        (line,) = ax.plot(taus, profile, label=f"{name} (n={values[name].size})", linewidth=1.2)
        ax.fill_between(taus, band[0], band[1], color=line.get_color(), alpha=0.2, linewidth=0)
    if log_scale:
        ax.set_xscale("log")
    ax.set_xlabel(f"τ ({label})")
    ax.set_ylabel(f"fraction of learners {'below' if lower_is_better else 'above'} τ")
    ax.set_ylim(-0.02, 1.02)
    ax.set_title("performance profile: 95% bootstrap CI (rliable)", fontsize=10)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return save_figure(fig, path)


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
        domain: the registered domain whose ``draw_map`` draws the map.
        patterns: pattern name -> its subgoals, as in a sweep's ``config["patterns"]``: a
            list of subgoal dicts (``{"cell": [4, 9]}``, ``{"circle": {"centre": [x, y],
            "radius": 0.04}}``) or a subgoal-file pattern body.
        path: the PNG to write (the PDF and SVG beside it).
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
    try:
        registered = registry.find(domain)
    except Exception as exc:  # a broken domain module costs the map, not the report
        return FigureFile(None, f"map for domain {domain!r} skipped: {type(exc).__name__}: {exc}")
    drawing = registered.part(ReportMap) if registered is not None else None
    if drawing is None:
        return FigureFile(None, f"no map is registered for domain {domain!r}")
    if not patterns:
        return FigureFile(None, "the sweep's config has no subgoal patterns to draw")
    names = list(patterns)[:max_panels]
    left_out = len(patterns) - len(names)
    try:
        from torchrl_subgoal.subgoals import pattern_from_data

        series = {n: pattern_from_data(patterns[n], name=n) for n in names}
        cols = min(5, len(names))
        rows = math.ceil(len(names) / cols)
        fig = Figure(figsize=(2.6 * cols, 2.6 * rows))
        axes = fig.subplots(rows, cols, squeeze=False)
        for ax, name in zip(axes.flat, names, strict=False):
            drawing.draw(ax, {name: series[name]}, dict(options or {}))
            ax.set_title(name, fontsize=9)
            ax.set_xticks([])
            ax.set_yticks([])
        for ax in list(axes.flat)[len(names) :]:
            ax.axis("off")
        fig.tight_layout()
        save_figure(fig, path, dpi=110)
    except Exception as exc:  # a broken hook costs the map, not the report
        return FigureFile(None, f"map for domain {domain!r} skipped: {type(exc).__name__}: {exc}")
    note = f"{left_out} more pattern(s) not drawn" if left_out else ""
    return FigureFile(path, note)
