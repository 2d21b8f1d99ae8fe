"""The report: files, numbers, the paper's table, map hooks, the console entry point."""

from __future__ import annotations

import json
import runpy
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from tests.experiments import toy_domain
from torchrl_subgoal import registry
from torchrl_subgoal.domains import Domain, register
from torchrl_subgoal.experiments import Sweep, load_results, stats
from torchrl_subgoal.experiments.plots import ReportMap
from torchrl_subgoal.experiments.report import ReportSpec, main, write_report

REPO = Path(__file__).resolve().parents[2]


def make_results(path: Path, domain: str, window: int = 1) -> Path:
    methods = toy_domain.toy_methods(4, ("HRS", "RRS", "SARSA", "NRS", "SARSA-RS"))
    Sweep(domain, path, methods, toy_domain.run_chunk, toy_domain.toy_config(40, window), seed=2, chunk_size=8).run(
        workers=0, progress=False
    )
    return path


@pytest.fixture(scope="module")
def four_rooms_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return make_results(tmp_path_factory.mktemp("four_rooms"), "four_rooms")


def test_report_writes_markdown_summary_and_figures_in_three_formats(four_rooms_dir: Path, tmp_path: Path) -> None:
    output = write_report(four_rooms_dir, tmp_path, n_boot=200)
    names = sorted(p.name for p in tmp_path.iterdir())
    figures = ["learning_curves", "patterns", "performance_profile"]
    assert names == sorted(["report.md", "summary.json", *(f + s for f in figures for s in (".png", ".pdf", ".svg"))])
    assert sorted(p.name for p in output.files) == names
    for figure in figures:
        assert (tmp_path / f"{figure}.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert (tmp_path / f"{figure}.pdf").read_bytes()[:5] == b"%PDF-"
        assert b"<svg" in (tmp_path / f"{figure}.svg").read_bytes()[:2000]
    markdown = (tmp_path / "report.md").read_text()
    assert markdown == output.markdown
    assert "![learning curves](learning_curves.png)" in markdown
    assert "![performance profile](performance_profile.png)" in markdown
    assert "![subgoal patterns](patterns.png)" in markdown
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary == output.summary
    assert [t["threshold"] for t in summary["time_to_threshold"]] == [500.0, 100.0]
    assert summary["asymptotic"]["window"] == [35, 40]


def test_summary_numbers_equal_the_statistics_computed_directly(four_rooms_dir: Path) -> None:
    summary = write_report(four_rooms_dir, four_rooms_dir / "out", n_boot=200).summary
    steps = load_results(four_rooms_dir).methods["NRS"].table.metric("steps")
    times = stats.time_to_threshold(steps, 100)
    cell = summary["time_to_threshold"][1]["methods"]["NRS"]
    assert cell["mean"] == pytest.approx(times.episodes.mean())
    assert cell["sd"] == pytest.approx(times.episodes.std(ddof=1))
    assert cell["not_reached"] == times.n_not_reached and cell["n"] == 8
    assert cell["iqm"] == pytest.approx(float(stats.iqm(times.episodes)))
    low, high = cell["iqm_ci"]
    assert low <= cell["iqm"] <= high
    final = summary["asymptotic"]["methods"]["NRS"]["mean"]
    assert final == pytest.approx(steps[:, 35:40].mean())
    pairs = summary["asymptotic"]["pairwise"]
    assert len(pairs) == 10 and all(0 <= p["p"] <= p["p_holm"] <= 1 for p in pairs)
    # the toy's HRS learns fastest by construction
    poi = {(p["first"], p["second"]): p["p"] for p in summary["time_to_threshold"][1]["probability_of_improvement"]}
    assert poi[("HRS", "NRS")] > 0.9


def test_report_is_reproducible(four_rooms_dir: Path, tmp_path: Path) -> None:
    one = write_report(four_rooms_dir, tmp_path / "a", n_boot=200, seed=3)
    two = write_report(four_rooms_dir, tmp_path / "b", n_boot=200, seed=3)
    assert one.summary == two.summary and one.markdown.replace("/a", "/b") == two.markdown.replace("/a", "/b")


def test_paper_numbers_sit_beside_ours(four_rooms_dir: Path, tmp_path: Path) -> None:
    markdown = write_report(four_rooms_dir, tmp_path, n_boot=100).markdown
    rows = [line for line in markdown.splitlines() if line.startswith("| 500 |")]
    assert any("| HRS |" in r and r.endswith("| 2.68 (1.86) |") for r in rows)
    assert any("| NRS |" in r and r.endswith("| 5.78 (6.39) |") for r in rows)
    assert any("| SARSA-RS |" in r and r.endswith("| — |") for r in rows)  # no paper number for it
    assert "Okudo" in markdown
    assert "| method | mean (s.d.) | IQM [CI] |\n" in markdown  # the paper tabulates no asymptote: no column


def test_domains_without_a_map_or_paper_get_notes(tmp_path: Path) -> None:
    path = make_results(tmp_path / "toy", "toy", window=3)
    markdown = write_report(path, n_boot=100).markdown
    assert not (path / "patterns.png").exists()
    assert "no map is registered for domain 'toy'" in markdown
    assert "paper" not in markdown.lower().split("## notes")[0] and "2.68" not in markdown  # no empty paper column
    assert "moving average of 3 episodes" in markdown


def test_map_hooks_are_looked_up_by_domain_and_failures_only_cost_the_map(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))  # the test's domains go with it
    drawn: list[dict[str, Any]] = []

    def hook(ax: Any, patterns: Any, options: Any) -> None:
        drawn.append({name: len(series) for name, series in patterns.items()} | dict(options))
        ax.plot([0, 1], [0, 1])

    def broken(ax: Any, patterns: Any, options: Any) -> None:
        raise ImportError("no module named envs.broken")

    register(Domain("hooked", parts=(ReportMap(hook),)))
    register(Domain("broken", parts=(ReportMap(broken),)))
    path = make_results(tmp_path / "hooked", "hooked")
    write_report(path, n_boot=50)
    assert drawn == [{"p1": 2}, {"p2": 2}] and (path / "patterns.png").exists()
    path = make_results(tmp_path / "broken", "broken")
    markdown = write_report(path, n_boot=50).markdown
    assert "map for domain 'broken' skipped: ImportError: no module named envs.broken" in markdown
    assert (path / "learning_curves.png").exists()


def test_pinball_patterns_reach_the_pinball_hook(tmp_path: Path) -> None:
    pytest.importorskip("torchrl_subgoal.envs.pinball")
    methods = toy_domain.toy_methods(1, ("HRS",))
    config = toy_domain.toy_config(12)
    config["patterns"] = {
        "p1": [
            {"circle": {"centre": [0.59, 0.65], "radius": 0.04}},
            {"circle": {"centre": [0.64, 0.32], "radius": 0.04}},
        ],
        "p2": [
            {"circle": {"centre": [0.28, 0.26], "radius": 0.04}},
            {"circle": {"centre": [0.69, 0.31], "radius": 0.04}},
        ],
    }
    config["report"]["map"] = {"config": "simple"}
    Sweep("pinball", tmp_path, methods, toy_domain.run_chunk, config).run(workers=0, progress=False)
    markdown = write_report(tmp_path, n_boot=50).markdown
    assert "![subgoal patterns](patterns.png)" in markdown, markdown


def test_a_sweep_named_after_its_recipe_draws_the_map_of_its_config_domain(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """recipes/a2c.py names its sweep a2c_four_rooms and stores ``"domain": "four_rooms"``."""
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))
    drawn: list[str] = []
    register(Domain("hooked2", parts=(ReportMap(lambda ax, patterns, options: drawn.extend(patterns)),)))
    config = toy_domain.toy_config(12) | {"domain": "hooked2"}
    Sweep("a2c_hooked2", tmp_path, toy_domain.toy_methods(1, ("HRS",)), toy_domain.run_chunk, config).run(
        workers=0, progress=False
    )
    markdown = write_report(tmp_path, n_boot=50).markdown
    assert drawn == ["p1", "p2"] and "![subgoal patterns](patterns.png)" in markdown, markdown


def test_report_spec_reads_the_config_section() -> None:
    spec = ReportSpec(thresholds=(3000, 2000), window=10, asymptotic_window=(190, 200))
    assert ReportSpec.from_config({"report": spec.to_dict()}) == spec
    assert ReportSpec.from_config({}).final_window(1000) == (990, 1000)
    with pytest.warns(UserWarning, match="moving_average"):
        ReportSpec.from_config({"report": {"moving_average": 10}})
    with pytest.raises(ValueError, match="metric"):
        ReportSpec(metric="reward")


def test_times_to_threshold_in_frames_when_the_config_gives_frames_per_column(four_rooms_dir: Path) -> None:
    """A learner recipe's column is a batch of frames: the report gives each mean time in frames too."""
    from torchrl_subgoal.experiments.report import render_markdown, summarize

    results = load_results(four_rooms_dir)
    plain = summarize(results, n_boot=50)
    assert plain["frames_per_unit"] == 0 and "mean frames" not in render_markdown(plain, None, {})
    spec = ReportSpec(thresholds=(500, 100), unit="update", frames_per_unit=256)
    assert ReportSpec.from_config({"report": spec.to_dict()}) == spec
    summary = summarize(results, spec, n_boot=50)
    markdown = render_markdown(summary, None, {})
    assert "One update is 256 frames" in markdown and "| mean frames |" in markdown
    cell = summary["time_to_threshold"][1]["methods"]["NRS"]
    assert f"| 100 | NRS | {cell['mean']:.3g} ({cell['sd']:.3g}) | {cell['mean'] * 256:.0f} |" in markdown


def test_console_entry_point_prints_tables(
    four_rooms_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main([str(four_rooms_dir), "--out", str(tmp_path), "--n-boot", "100"]) == 0
    printed = capsys.readouterr().out
    assert "## Time to threshold" in printed and "| threshold | method |" in printed
    assert (tmp_path / "report.md").exists()
    assert main([str(tmp_path)]) == 2  # not a results dir
    assert "config.json not found" in capsys.readouterr().err


@pytest.mark.slow
def test_module_entry_point_runs(four_rooms_dir: Path, tmp_path: Path) -> None:
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "torchrl_subgoal.experiments.report",
            str(four_rooms_dir),
            "--out",
            str(tmp_path),
            "--n-boot",
            "50",
        ],
        capture_output=True,
        text=True,
        cwd=REPO,
        timeout=120,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    assert "## Asymptotic performance" in done.stdout


def test_recipe_script_calls_the_report(
    four_rooms_dir: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr(sys, "argv", ["report.py", str(four_rooms_dir), "--out", str(tmp_path), "--n-boot", "50"])
    with pytest.raises(SystemExit) as exit_info:
        runpy.run_path(str(REPO / "recipes" / "report.py"), run_name="__main__")
    assert exit_info.value.code == 0
    assert "## Tests across methods" in capsys.readouterr().out


def test_learners_that_never_reach_a_threshold_count_as_n_episodes(tmp_path: Path) -> None:
    methods = toy_domain.toy_methods(2, ("HRS", "STUCK"))
    Sweep("toy", tmp_path, methods, toy_domain.run_chunk, toy_domain.toy_config(40)).run(workers=0, progress=False)
    output = write_report(tmp_path, n_boot=50)
    stuck = output.summary["time_to_threshold"][1]["methods"]["STUCK"]
    assert stuck["not_reached"] == stuck["n"] == 4
    assert stuck["mean"] == 40 and stuck["sd"] == 0
    assert output.summary["time_to_threshold"][1]["methods"]["HRS"]["not_reached"] == 0
    assert "| 100 | STUCK | 40 (0) | 4/4 |" in output.markdown


def test_the_reports_robust_statistics_are_rliables(four_rooms_dir: Path) -> None:
    """IQM, its stratified-bootstrap interval (strata: subgoal patterns, the seed the report derives) and the
    probability of improvement equal what rliable computes on the same learners."""
    import numpy as np
    from rliable import library, metrics

    summary = write_report(four_rooms_dir, four_rooms_dir / "rliable", n_boot=300, seed=4).summary
    results = load_results(four_rooms_dir)
    finals = {n: r.table.metric("steps")[:, 35:40].mean(axis=1) for n, r in results.methods.items()}
    for i, (name, res) in enumerate(results.methods.items()):
        # HRS: 4 learners of each of 2 patterns, one column per pattern; SARSA: 8 of one pseudo-pattern
        matrix = np.stack([finals[name][res.patterns == p] for p in np.unique(res.patterns)], axis=1)
        cell = summary["asymptotic"]["methods"][name]
        assert cell["iqm"] == pytest.approx(float(metrics.aggregate_iqm(matrix)))
        np.random.seed(int(np.random.SeedSequence([4, i]).generate_state(1)[0]))
        _, interval = library.get_interval_estimates(
            {name: matrix}, lambda m: np.array([metrics.aggregate_iqm(m)]), reps=300
        )
        assert cell["iqm_ci"] == pytest.approx(interval[name][:, 0].tolist())
    for pair in summary["asymptotic"]["probability_of_improvement"]:  # fewer steps is better: negated
        x, y = -finals[pair["first"]][:, None], -finals[pair["second"]][:, None]
        assert pair["p"] == pytest.approx(float(metrics.probability_of_improvement(x, y)))


def test_learning_curves_of_frames_are_drawn_against_environment_steps(tmp_path, monkeypatch) -> None:
    """x in frames when each column is a batch of frames; the paper's unit otherwise."""
    import numpy as np

    from torchrl_subgoal.experiments import plots

    drawn = []
    monkeypatch.setattr(plots, "save_figure", lambda fig, path: drawn.append(fig.axes[0]))
    curves = {"A2C": np.ones((3, 5)), "HRS": np.zeros((3, 5))}
    plots.plot_learning_curves(curves, tmp_path / "a.png", unit="update", frames_per_unit=256, n_boot=20)
    plots.plot_learning_curves(curves, tmp_path / "b.png", unit="episode", n_boot=20)
    frames, episodes = drawn
    assert frames.get_xlabel() == "frames (environment steps)" and episodes.get_xlabel() == "episode"
    assert frames.lines[0].get_xdata().tolist() == [256, 512, 768, 1024, 1280]
    assert episodes.lines[0].get_xdata().tolist() == [1, 2, 3, 4, 5]
