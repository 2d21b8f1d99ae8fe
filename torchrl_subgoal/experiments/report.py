"""The report of a results directory: ``report.md``, ``summary.json`` and figures (PNG, PDF and SVG).

Usage::

    torchrl-subgoal report RESULTS_DIR [--out DIR]
    python -m torchrl_subgoal.experiments.report RESULTS_DIR [--out DIR]

What it computes (per method; see :mod:`~torchrl_subgoal.experiments.stats`):

* time to threshold for every threshold of the sweep's ``config["report"]``, on a
  moving average when ``window > 1``; learners that never cross a threshold count as
  ``n_episodes`` and the report says how many there were;
* asymptotic performance: the mean over the configured final window;
* a one-way ANOVA across methods and pairwise Welch t-tests with Holm-Bonferroni
  correction, for each of these measures (as the paper does);
* beyond the paper, computed by rliable (Agarwal et al. 2021): the interquartile mean
  (IQM) with a stratified-bootstrap confidence interval (strata = subgoal patterns), the
  probability of improvement between every pair of methods, and performance profiles of
  the asymptotic performance;
* learning curves (mean and 95% stratified-bootstrap band; x in frames for the learner
  recipes, else the paper's episodes or epochs) and the subgoal patterns on the domain's map;
* the paper's numbers beside ours where :mod:`~torchrl_subgoal.experiments.paper` has them
  (no paper column where it has none).
"""

from __future__ import annotations

import json
import math
import os
import sys
import time
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from itertools import combinations
from pathlib import Path
from typing import Any

import numpy as np

from torchrl_subgoal.experiments import stats
from torchrl_subgoal.experiments.cli import OneLineParser
from torchrl_subgoal.experiments.paper import PaperResults, paper_results
from torchrl_subgoal.experiments.plots import (
    FORMATS,
    plot_learning_curves,
    plot_pattern_maps,
    plot_performance_profile,
)
from torchrl_subgoal.experiments.results import (
    METRICS,
    IncompleteResultsError,
    Results,
    ResultsError,
    SweepRunningError,
)
from torchrl_subgoal.experiments.store import LOCK_FILE, ResultsStore, load_results

SUMMARY_FILE = "summary.json"
REPORT_FILE = "report.md"
CURVES_FILE = "learning_curves.png"
PROFILE_FILE = "performance_profile.png"
PATTERNS_FILE = "patterns.png"
#: Largest ``--n-boot``: the bootstrap holds ``n_boot x learners`` indices in memory.
MAX_BOOT = 100_000
#: Most bootstrap samples of the figures' bands (each costs a pass over the curves' points).
BAND_BOOT = 500


@dataclass(frozen=True)
class ReportSpec:
    """The ``"report"`` section of a sweep's config: what the report measures.

    Args:
        metric: per-episode metric: ``"steps"``, ``"return"`` or ``"success"``.
        lower_is_better: direction of improvement of ``metric``.
        thresholds: levels for time to threshold.
        window: moving-average window for time to threshold and curves (1 = none;
            the paper uses 10 for PinBall).
        asymptotic_window: ``[start, stop]`` slice of 0-based episodes (``[990, 1000]``
            = the last 10 of 1000); default the last 10 episodes.
        log_scale: logarithmic y axis for the curves (default: for ``"steps"``).
        map: extra keyword arguments for the domain's map hook, e.g. ``{"config": "hard"}``.
        unit: what a column of the tables is, for labels: ``"episode"``, or ``"epoch"`` when a
            recipe records one row per training epoch (pick-and-place), ``"update"`` per collected batch.
        frames_per_unit: env frames per column (a learner recipe's frames per batch); when set, times
            to threshold are also given in frames (0: not).

    Examples:
        >>> spec = ReportSpec(thresholds=(500, 300, 100, 50), asymptotic_window=(990, 1000))
        >>> ReportSpec.from_config({"report": spec.to_dict()}) == spec
        True
    """

    metric: str = "steps"
    lower_is_better: bool = True
    thresholds: tuple[float, ...] = ()
    window: int = 1
    asymptotic_window: tuple[int, int] | None = None
    log_scale: bool | None = None
    map: Mapping[str, Any] = field(default_factory=dict)
    unit: str = "episode"
    frames_per_unit: int = 0

    def __post_init__(self) -> None:
        if self.metric not in METRICS:
            raise ValueError(f"report.metric {self.metric!r} is not one of {METRICS}")
        if self.window < 1:
            raise ValueError("report.window must be >= 1")
        object.__setattr__(self, "thresholds", tuple(float(t) for t in self.thresholds))
        if self.asymptotic_window is not None:
            start, stop = (int(v) for v in self.asymptotic_window)
            object.__setattr__(self, "asymptotic_window", (start, stop))

    @classmethod
    def from_config(cls, config: Mapping[str, Any]) -> ReportSpec:
        """Read ``config["report"]`` (all keys optional; unknown keys are warned about)."""
        section = dict(config.get("report") or {})
        known = {f for f in cls.__dataclass_fields__}
        unknown = sorted(set(section) - known)
        if unknown:
            warnings.warn(f"ignoring unknown report keys {unknown}; known: {sorted(known)}", stacklevel=2)
        return cls(**{k: v for k, v in section.items() if k in known})

    def to_dict(self) -> dict[str, Any]:
        """The JSON section to put under ``config["report"]``."""
        return {
            "metric": self.metric,
            "lower_is_better": self.lower_is_better,
            "thresholds": list(self.thresholds),
            "window": self.window,
            "asymptotic_window": list(self.asymptotic_window) if self.asymptotic_window else None,
            "log_scale": self.log_scale,
            "map": dict(self.map),
            "unit": self.unit,
            "frames_per_unit": self.frames_per_unit,
        }

    def final_window(self, n_episodes: int) -> tuple[int, int]:
        """The asymptotic window, defaulting to the last 10 episodes."""
        return self.asymptotic_window or (max(0, n_episodes - 10), n_episodes)


@dataclass(frozen=True)
class ReportOutput:
    """What :func:`write_report` produced.

    Examples:
        >>> output = ReportOutput("# Report", {"domain": "four_rooms"}, ())
        >>> output.summary["domain"], output.files
        ('four_rooms', ())
    """

    markdown: str
    summary: dict[str, Any]
    files: tuple[Path, ...]


# -- numbers -------------------------------------------------------------------------------


def _clean(value: float | None) -> float | None:
    return None if value is None or not math.isfinite(value) else float(value)


def _measure(
    scores: Mapping[str, np.ndarray],
    strata: Mapping[str, np.ndarray],
    *,
    lower_is_better: bool,
    n_boot: int,
    confidence: float,
    seed: int,
) -> dict[str, Any]:
    """Descriptives, IQM + CI, ANOVA, Holm-corrected pairwise tests and P(improvement)."""
    methods: dict[str, Any] = {}
    for i, (name, x) in enumerate(scores.items()):
        boot_seed = int(np.random.SeedSequence([seed, i]).generate_state(1)[0])
        low, high = stats.stratified_bootstrap_ci(x, strata[name], n_boot=n_boot, confidence=confidence, seed=boot_seed)
        methods[name] = {
            "n": int(x.size),
            "mean": _clean(float(x.mean())),
            "sd": _clean(float(x.std(ddof=1))) if x.size > 1 else None,
            "iqm": _clean(float(stats.iqm(x))),
            "iqm_ci": [_clean(low), _clean(high)],
        }
    test = stats.anova(scores)
    pairwise = [
        {
            "first": r.first,
            "second": r.second,
            "t": _clean(r.statistic),
            "p": _clean(r.pvalue),
            "p_holm": _clean(r.pvalue_adjusted),
            "significant": r.reject,
        }
        for r in stats.pairwise_tests(scores)
    ]
    improvement = [
        {
            "first": a,
            "second": b,
            "p": stats.probability_of_improvement(scores[a], scores[b], lower_is_better=lower_is_better),
        }
        for a, b in combinations(scores, 2)
    ]
    return {
        "lower_is_better": lower_is_better,
        "methods": methods,
        "anova": {"F": _clean(test.statistic), "p": _clean(test.pvalue)},
        "pairwise": pairwise,
        "probability_of_improvement": improvement,
    }


def summarize(
    results: Results,
    spec: ReportSpec | None = None,
    *,
    n_boot: int = 2000,
    confidence: float = 0.95,
    seed: int = 0,
) -> dict[str, Any]:
    """All the report's numbers as JSON-ready data (what ``summary.json`` holds).

    Args:
        results: loaded results (:func:`~torchrl_subgoal.experiments.load_results`).
        spec: what to measure; default read from the sweep's config.
        n_boot: bootstrap samples for the IQM intervals.
        confidence: coverage of the intervals.
        seed: bootstrap seed; the summary is reproducible given it.

    Examples:
        >>> summary = summarize(load_results("results/four_rooms"))  # doctest: +SKIP
        >>> summary["asymptotic"]["methods"]["HRS"]["mean"]  # doctest: +SKIP
    """
    spec = spec or ReportSpec.from_config(results.config)
    if not results.methods:
        raise ResultsError(f"{results.root}: no finished chunks to report on")
    curves = {name: res.table.metric(spec.metric) for name, res in results.methods.items()}
    strata = {name: res.patterns for name, res in results.methods.items()}
    n_episodes = {c.shape[1] for c in curves.values()}
    if len(n_episodes) != 1:
        raise ResultsError(f"{results.root}: methods differ in episodes per learner {sorted(n_episodes)}")
    n = n_episodes.pop()
    thresholds = []
    for k, threshold in enumerate(spec.thresholds):
        times = {
            name: stats.time_to_threshold(c, threshold, window=spec.window, lower_is_better=spec.lower_is_better)
            for name, c in curves.items()
        }
        scores = {name: t.episodes.astype(np.float64) for name, t in times.items()}
        entry = _measure(scores, strata, lower_is_better=True, n_boot=n_boot, confidence=confidence, seed=seed + 1 + k)
        for name, t in times.items():
            entry["methods"][name]["not_reached"] = t.n_not_reached
        thresholds.append({"threshold": threshold, **entry})
    final = spec.final_window(n)
    asymptotic = {name: stats.asymptotic_performance(c, final) for name, c in curves.items()}
    return {
        "domain": results.domain,
        "results_dir": str(results.root),
        "metric": spec.metric,
        "lower_is_better": spec.lower_is_better,
        "n_episodes": n,
        "unit": spec.unit,
        "frames_per_unit": spec.frames_per_unit,
        "window": spec.window,
        "methods": {
            name: {"learners": int(res.table.n_learners), "patterns": sorted(set(res.patterns.tolist()))}
            for name, res in results.methods.items()
        },
        "incomplete": list(results.missing),
        "time_to_threshold": thresholds,
        "asymptotic": {
            "window": list(final),
            **_measure(
                asymptotic,
                strata,
                lower_is_better=spec.lower_is_better,
                n_boot=n_boot,
                confidence=confidence,
                seed=seed,
            ),
        },
        "bootstrap": {
            "n_boot": n_boot,
            "confidence": confidence,
            "seed": seed,
            "strata": "subgoal pattern of each learner (one stratum unless every pattern has as many, >= 2)",
            "interval": "percentile",
            "library": "rliable",
        },
        "tests": {"anova": "one-way (scipy f_oneway)", "pairwise": "Welch t-test, Holm-Bonferroni"},
    }


# -- Markdown ------------------------------------------------------------------------------


def _num(value: float | None, digits: int = 3) -> str:
    if value is None:
        return "—"
    return f"{value:.{digits}g}" if abs(value) < 10**digits else f"{value:.0f}"


def _pvalue(value: float | None) -> str:
    return "—" if value is None else (f"{value:.2e}" if value < 1e-3 else f"{value:.3f}")


def _table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines)


def _ci(cell: Mapping[str, Any]) -> str:
    low, high = cell["iqm_ci"]
    return f"{_num(cell['iqm'])} [{_num(low)}, {_num(high)}]"


def _tests_markdown(measures: Sequence[tuple[str, Mapping[str, Any]]]) -> list[str]:
    out = ["## Tests across methods", ""]
    out.append(
        _table(
            ["measure", "ANOVA F", "p"],
            [[label, _num(m["anova"]["F"]), _pvalue(m["anova"]["p"])] for label, m in measures],
        )
    )
    pairs = [(p["first"], p["second"]) for p in measures[0][1]["pairwise"]]
    if pairs:
        out += ["", "Pairwise Welch t-tests, Holm-Bonferroni adjusted p (`*` = significant at 0.05):", ""]
        rows = []
        for i, (a, b) in enumerate(pairs):
            cells = []
            for _, m in measures:
                p = m["pairwise"][i]
                cells.append(_pvalue(p["p_holm"]) + (" *" if p["significant"] else ""))
            rows.append([f"{a} vs {b}", *cells])
        out.append(_table(["pair", *[label for label, _ in measures]], rows))
        out += ["", "Probability of improvement P(first better than second), ties count ½:", ""]
        rows = [
            [f"{a} vs {b}", *[_num(m["probability_of_improvement"][i]["p"], 2) for _, m in measures]]
            for i, (a, b) in enumerate(pairs)
        ]
        out.append(_table(["pair", *[label for label, _ in measures]], rows))
    return out


def render_markdown(
    summary: Mapping[str, Any],
    paper: PaperResults | None,
    figures: Mapping[str, str],
    notes: Sequence[str] = (),
) -> str:
    """The Markdown report for a :func:`summarize` result.

    Args:
        summary: the numbers.
        paper: the paper's numbers for the domain, shown beside ours (or None).
        figures: caption -> relative image path.
        notes: extra lines for the notes section (e.g. why a figure is missing).

    Examples:
        >>> from torchrl_subgoal.experiments.results import EpisodeTable, MethodResults, Results
        >>> table = EpisodeTable(np.array([[9, 5, 3], [8, 4, 2]]), np.zeros((2, 3)), np.ones((2, 3), bool))
        >>> method = MethodResults("HRS", np.array(["alice", "alice"]), np.array([0, 1]), table)
        >>> summary = summarize(Results(Path("results/demo"), "four_rooms", {}, {"HRS": method}), n_boot=100)
        >>> markdown = render_markdown(summary, None, {})
        >>> markdown.splitlines()[0], "| HRS | 5.17 (0.707) |" in markdown
        ('# Report: four_rooms', True)
    """
    metric, window = summary["metric"], summary["window"]
    direction = "falls below" if summary["lower_is_better"] else "rises above"
    unit = summary["unit"]
    level = f"{metric} per {unit}" + (f" (moving average of {window} {unit}s)" if window > 1 else "")
    out = [f"# Report: {summary['domain']}", ""]
    out.append(f"Results: `{summary['results_dir']}`, {summary['n_episodes']} {unit}s per learner.")
    out.append("")
    out.append(
        _table(
            ["method", "learners", "patterns"],
            [[m, str(v["learners"]), str(len(v["patterns"]))] for m, v in summary["methods"].items()],
        )
    )
    if summary["incomplete"]:
        out += ["", f"**Incomplete:** {len(summary['incomplete'])} chunk(s) not computed yet."]
    measures: list[tuple[str, Mapping[str, Any]]] = []
    if summary["time_to_threshold"]:
        out += ["", "## Time to threshold", ""]
        out.append(
            f"{unit.capitalize()}s until {level} first {direction} the threshold. Learners that never "
            f"do count as {summary['n_episodes']} (column *not reached*)."
        )
        frames = summary.get("frames_per_unit") or 0
        if frames:
            out.append(f"One {unit} is {frames} frames; *mean frames* = mean {unit}s x {frames}.")
        with_paper = paper is not None and bool(paper.time_to_threshold)
        if paper is not None and with_paper:
            shown = f"moving average of {paper.window}" if paper.window > 1 else "no moving average"
            out.append(f"Paper: Okudo & Yamada (2021), {shown}, mean (s.d.).")
        out.append("")
        rows = []
        for entry in summary["time_to_threshold"]:
            threshold = entry["threshold"]
            measures.append((f"time to {_num(threshold)}", entry))
            paper_row = paper.time_to_threshold.get(threshold, {}) if paper else {}
            for name, cell in entry["methods"].items():
                ref = paper_row.get(name)
                rows.append(
                    [
                        _num(threshold),
                        name,
                        f"{_num(cell['mean'])} ({_num(cell['sd'])})",
                        *([f"{cell['mean'] * frames:.0f}" if cell["mean"] is not None else "—"] if frames else []),
                        f"{cell['not_reached']}/{cell['n']}",
                        _ci(cell),
                        *([f"{_num(ref.mean)} ({_num(ref.sd)})" if ref else "—"] if with_paper else []),
                    ]
                )
        header = [
            "threshold",
            "method",
            "mean (s.d.)",
            *(["mean frames"] if frames else []),
            "not reached",
            "IQM [CI]",
            *(["paper mean (s.d.)"] if with_paper else []),
        ]
        out.append(_table(header, rows))
    asym = summary["asymptotic"]
    start, stop = asym["window"]
    out += ["", "## Asymptotic performance", ""]
    out.append(f"Mean {metric} per learner over {unit}s {start + 1} to {stop}.")
    if paper is not None and paper.asymptotic_window:
        a, b = paper.asymptotic_window
        out.append(f"Paper: Okudo & Yamada (2021), mean over {a} to {b}.")
    out.append("")
    paper_asymptotic = paper.asymptotic if paper is not None else {}
    rows = [
        [
            name,
            f"{_num(cell['mean'])} ({_num(cell['sd'])})",
            _ci(cell),
            *([_num(paper_asymptotic[name]) if name in paper_asymptotic else "—"] if paper_asymptotic else []),
        ]
        for name, cell in asym["methods"].items()
    ]
    out.append(_table(["method", "mean (s.d.)", "IQM [CI]", *(["paper mean"] if paper_asymptotic else [])], rows))
    measures.append(("asymptotic", asym))
    out += ["", *_tests_markdown(measures)]
    if figures:
        out += ["", "## Figures", ""]
        out += [f"![{caption}]({path})\n" for caption, path in figures.items()]
    boot = summary["bootstrap"]
    out += ["", "## Notes", ""]
    out += [
        f"- IQM: mean of the middle 50% of learners; CI: {boot['confidence']:.0%} percentile interval "
        "of a bootstrap stratified by subgoal pattern (one stratum where the patterns' learners are single "
        f"or uneven; {boot['n_boot']} samples, seed {boot['seed']}), computed by rliable after Agarwal et al. "
        "(2021), *Deep RL at the Edge of the Statistical Precipice*.",
        "- Probability of improvement: P(X better than Y) over random learner pairs, ties ½ "
        f"(rliable; Agarwal et al. 2021). For times to threshold, fewer {unit}s is better.",
        "- Curves: the mean across learners and its 95% stratified-bootstrap band (rliable). Performance "
        "profile: the fraction of learners whose asymptotic performance is better than τ (rliable's score "
        "distributions), with its band.",
        "- Tests: one-way ANOVA, pairwise Welch t-tests with Holm-Bonferroni correction "
        "(Okudo & Yamada 2021 use ANOVA with Holm-corrected pairwise tests).",
    ]
    if paper is not None:
        out += [f"- Paper: {paper.source}"] + [f"- Paper: {n}" for n in paper.notes]
    out += [f"- {n}" for n in notes]
    return "\n".join(out) + "\n"


# -- files ---------------------------------------------------------------------------------


def write_report(
    results_dir: str | os.PathLike[str],
    out_dir: str | os.PathLike[str] | None = None,
    *,
    n_boot: int = 2000,
    seed: int = 0,
    allow_incomplete: bool = False,
) -> ReportOutput:
    """Write ``report.md``, ``summary.json`` and the figures (PNG, PDF, SVG) for a results directory.

    Args:
        results_dir: a directory written by a sweep.
        out_dir: where to write (default: ``results_dir``).
        n_boot: bootstrap samples for the IQM intervals.
        seed: bootstrap seed.
        allow_incomplete: report on the finished chunks of an unfinished sweep, or of one still
            running; without it, a sweep holding the directory's lock is a :class:`SweepRunningError`.

    Examples:
        >>> out = write_report("results/four_rooms")  # doctest: +SKIP
        >>> print(out.markdown)  # doctest: +SKIP
    """
    if n_boot < 1:
        raise ValueError(f"n_boot must be >= 1, got {n_boot}")
    if not allow_incomplete and ResultsStore(results_dir).sweep_running():
        raise SweepRunningError(
            f"a sweep is running into {results_dir} (it holds {Path(results_dir) / LOCK_FILE}), so its results "
            "are not final; wait for it to finish, or pass --allow-incomplete to report on the chunks finished so far"
        )
    results = load_results(results_dir, allow_incomplete=allow_incomplete)
    spec = ReportSpec.from_config(results.config)
    out = Path(out_dir) if out_dir is not None else results.root
    _check_output_dir(out)
    summary = summarize(results, spec, n_boot=n_boot, seed=seed)
    paper = paper_results(results.domain)
    notes: list[str] = []
    figures: dict[str, str] = {}
    files: list[Path] = []
    log_scale = spec.log_scale if spec.log_scale is not None else spec.metric == "steps"
    strata = {name: res.patterns for name, res in results.methods.items()}
    curves = plot_learning_curves(
        {name: res.table.metric(spec.metric) for name, res in results.methods.items()},
        out / CURVES_FILE,
        metric=spec.metric,
        window=spec.window,
        thresholds=spec.thresholds,
        log_scale=log_scale,
        unit=spec.unit,
        frames_per_unit=spec.frames_per_unit,
        strata=strata,
        n_boot=min(n_boot, BAND_BOOT),
        seed=seed,
    )
    start, stop = summary["asymptotic"]["window"]
    finals = {
        name: stats.asymptotic_performance(res.table.metric(spec.metric), (start, stop))
        for name, res in results.methods.items()
    }
    profile = plot_performance_profile(
        finals,
        out / PROFILE_FILE,
        label=f"mean {spec.metric} per {spec.unit}, {spec.unit}s {start + 1} to {stop}",
        lower_is_better=spec.lower_is_better,
        strata=strata,
        log_scale=log_scale,
        n_boot=min(n_boot, BAND_BOOT),
        seed=seed,
    )
    maps = plot_pattern_maps(  # a sweep named after its recipe (a2c_four_rooms) names its map's domain
        str(results.config.get("domain", results.domain)),
        results.config.get("patterns") or {},
        out / PATTERNS_FILE,
        options=spec.map,
    )
    for caption, figure in (("learning curves", curves), ("performance profile", profile), ("subgoal patterns", maps)):
        if figure.path is not None:
            figures[caption] = figure.path.name
            files += figure.paths
        if figure.note:
            notes.append(f"{caption}: {figure.note}")
    markdown = render_markdown(summary, paper, figures, notes)
    (out / REPORT_FILE).write_text(markdown)
    (out / SUMMARY_FILE).write_text(json.dumps(summary, indent=2, allow_nan=False) + "\n")
    files += [out / REPORT_FILE, out / SUMMARY_FILE]
    return ReportOutput(markdown, summary, tuple(files))


REPORT_FILES = (
    REPORT_FILE,
    SUMMARY_FILE,
    *(Path(figure).with_suffix(f).name for figure in (CURVES_FILE, PROFILE_FILE, PATTERNS_FILE) for f in FORMATS),
)


def _is_report_dir(out: Path) -> bool:
    """Whether ``out`` holds a results directory's ``config.json`` or a summary this module wrote."""
    try:
        if ResultsStore(out).read_manifest() is not None:
            return True
        summary = json.loads((out / SUMMARY_FILE).read_text(encoding="utf-8"))
    except (OSError, ValueError, ResultsError):
        return False
    return isinstance(summary, dict) and {"results_dir", "bootstrap", "asymptotic"} <= set(summary)


def _check_output_dir(out: Path) -> None:
    """Create ``out``; refuse to replace report-named files that a report did not write there."""
    if out.exists() and not out.is_dir():
        raise ResultsError(f"{out} is a file, not a directory; choose another output directory")
    existing = [out / name for name in REPORT_FILES if (out / name).exists()]
    if existing and not _is_report_dir(out):
        raise ResultsError(
            f"{existing[0]} exists and was not written by a report of torchrl_subgoal; choose another "
            "output directory (or move it away)"
        )
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ResultsError(f"cannot create the output directory {out} ({exc.strerror or exc})") from exc


def main(argv: Sequence[str] | None = None) -> int:
    """Console entry point: ``torchrl-subgoal report RESULTS_DIR [--out DIR]`` (also ``torchrl-subgoal-report``).

    Examples:
        >>> import tempfile
        >>> main([tempfile.mkdtemp()])  # an empty directory: a one-line error on stderr
        2
    """
    parser = OneLineParser(
        prog="torchrl-subgoal report",
        description="Write report.md, summary.json and plots for a sweep's results directory.",
    )
    parser.add_argument("results_dir", type=Path)
    parser.add_argument("--out", type=Path, default=None, help="output directory (default: RESULTS_DIR)")
    parser.add_argument("--n-boot", type=int, default=2000, help=f"bootstrap samples, 1 to {MAX_BOOT} (default 2000)")
    parser.add_argument("--seed", type=int, default=0, help="bootstrap seed (default 0)")
    parser.add_argument("--allow-incomplete", action="store_true", help="report on an unfinished sweep's chunks")
    args = parser.parse_args(argv)
    if not 1 <= args.n_boot <= MAX_BOOT:
        parser.error(f"--n-boot: must lie in [1, {MAX_BOOT}], got {args.n_boot}")
    if args.seed < 0:
        parser.error(f"--seed: must be >= 0, got {args.seed}")
    start = time.perf_counter()
    if args.allow_incomplete and ResultsStore(args.results_dir).sweep_running():
        print(
            f"warning: a sweep is running into {args.results_dir}; this report covers the chunks it has "
            "finished so far",
            file=sys.stderr,
        )
    try:
        output = write_report(
            args.results_dir,
            args.out,
            n_boot=args.n_boot,
            seed=args.seed,
            allow_incomplete=args.allow_incomplete,
        )
    except ResultsError as exc:
        hint = " (or pass --allow-incomplete)" if isinstance(exc, IncompleteResultsError) else ""
        print(f"error: {exc}{hint}", file=sys.stderr)
        return 2
    except OSError as exc:  # e.g. the output directory is not writable
        print(f"error: cannot write the report: {exc}", file=sys.stderr)
        return 2
    print(output.markdown)
    written = ", ".join(str(p) for p in output.files)
    print(f"wrote {written} in {time.perf_counter() - start:.1f} s", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
