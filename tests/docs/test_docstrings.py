"""Every public class and function of the package has a docstring with a runnable example.

The examples run as doctests (``--doctest-modules`` in pyproject.toml). The
names below predate this check and still lack an example; the list may only
shrink: a new public name needs an ``Examples:`` block, and a listed name that
gains one must leave the list.
"""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[2] / "torchrl_subgoal"

#: ``module.name`` of the public classes and functions without an example yet (see above)
WITHOUT_EXAMPLE = {
    "agents.actor_critic.ActorCriticConfig",
    "agents.actor_critic.fourier_coefficients",
    "agents.ddpg.DDPGConfig",
    "agents.ddpg.mlp",
    "agents.ddpg.ClippedTD0Estimator",
    "agents.fused.run_episodes_fused",
    "agents.fused.run_four_rooms_fused",
    "agents.fused.run_pinball_fused",
    "agents.sarsa.SarsaConfig",
    "envs.fetch.FetchUnavailableError",
    "envs.fetch.require_fetch",
    "envs.fetch.human_patterns",
    "envs.four_rooms.free_cells",
    "envs.four_rooms.room_aggregation",
    "envs.four_rooms.check_subgoal",
    "envs.four_rooms.state_of",
    "envs.four_rooms.draw_map",
    "experiments.checkpoint.rng_states",
    "experiments.checkpoint.restore_rng_states",
    "experiments.paper.PaperStat",
    "experiments.paper.PaperResults",
    "experiments.plots.FigureFile",
    "experiments.plots.plot_pattern_maps",
    "experiments.recipe.fail",
    "experiments.recipe.pattern_sets",
    "experiments.recipe.pattern_config",
    "experiments.recipe.pattern_sources",
    "experiments.recipe.check_patterns",
    "experiments.recipe.method_specs",
    "experiments.recipe.chunk_patterns",
    "experiments.recipe.sweep_and_report",
    "experiments.report.ReportOutput",
    "experiments.report.render_markdown",
    "experiments.report.main",
    "experiments.store.ResultsError",
    "experiments.store.ConfigMismatchError",
    "experiments.store.DomainMismatchError",
    "experiments.store.UnknownMethodError",
    "experiments.store.CorruptChunkError",
    "experiments.store.IncompleteResultsError",
    "experiments.store.ChunkStatus",
    "experiments.store.MethodResults",
    "experiments.store.Results",
    "experiments.store.planned_chunks",
    "experiments.sweep.RunChunk",
    "experiments.sweep.ChunkFailedError",
    "experiments.sweep.CorruptChunkWarning",
    "experiments.sweep.chunk_seed",
    "methods.Method",
    "methods.paper_methods",
    "methods.random_patterns",
    "methods.shaping_parts",
    "studio.__init__.main",
    "studio.document.RequestError",
    "studio.document.file_path",
    "studio.document.Drawing",
    "studio.document.save_drawing",
    "studio.document.infer_domain",
    "studio.document.to_document",
    "studio.domains.Limit",
    "studio.domains.Domain",
    "studio.jobs.Cancelled",
    "studio.jobs.JobError",
    "studio.jobs.Job",
    "studio.server.Studio",
    "studio.server.serve",
    "studio.server.listen",
    "studio.server.main",
    "studio.training.TrySettings",
    "studio.training.Curve",
    "studio.training.TryResult",
    "subgoals.Region",
    "subgoals.Predicate",
    "subgoals.parse_predicate",
}


def _public() -> dict[str, str]:
    """``module.name`` -> docstring of every module-level public class and function."""
    found = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        if path.name.startswith("_") and path.name != "__init__.py":
            continue
        module = ".".join(path.relative_to(PACKAGE).with_suffix("").parts)
        for node in ast.parse(path.read_text()).body:
            if isinstance(node, ast.FunctionDef | ast.ClassDef) and not node.name.startswith("_"):
                found[f"{module}.{node.name}"] = ast.get_docstring(node) or ""
    return found


def test_public_names_have_runnable_examples() -> None:
    public = _public()
    lacking = {name for name, doc in public.items() if ">>>" not in doc}
    new = sorted(lacking - WITHOUT_EXAMPLE)
    assert not new, f"public names without an Examples: block (a short doctest): {new}"
    done = sorted(WITHOUT_EXAMPLE - lacking)
    assert not done, f"these now have an example or are gone: remove them from WITHOUT_EXAMPLE in {__file__}: {done}"
