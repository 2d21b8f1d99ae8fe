"""The domain registry: a toy domain added through it alone runs the method from a subgoal file,
and the core imports no domain module."""

from __future__ import annotations

import builtins
import importlib.util
import subprocess
import sys
from collections.abc import Callable, Mapping
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest
import torch
from torchrl.envs import TransformedEnv

from torchrl_subgoal import domains, load_patterns, registry
from torchrl_subgoal.envs import fetch
from torchrl_subgoal.experiments import Chunk, EpisodeTable, MethodSpec, Sweep
from torchrl_subgoal.experiments.paper import PaperResults
from torchrl_subgoal.experiments.recipe import chunk_patterns
from torchrl_subgoal.experiments.report import write_report
from torchrl_subgoal.fused import SARSA_PRESETS, SoftmaxSarsa, run_episodes
from torchrl_subgoal.methods import paper_methods, shaping_transform
from torchrl_subgoal.subgoals import SubgoalFileError

TUTORIAL = Path(__file__).resolve().parents[1] / "docs" / "tutorials" / "adding_a_domain.py"
CORE = (
    "torchrl_subgoal",
    "torchrl_subgoal.subgoals",
    "torchrl_subgoal.experiments",
    "torchrl_subgoal.experiments.plots",
    "torchrl_subgoal.experiments.paper",
    "torchrl_subgoal.experiments.report",
    "torchrl_subgoal.experiments.recipe",
    "torchrl_subgoal.domains",
    "torchrl_subgoal.studio.domains",
    "torchrl_subgoal.training",
)


@pytest.fixture
def corridor(monkeypatch: pytest.MonkeyPatch) -> ModuleType:
    """The docs' corridor domain, registered for this test only."""
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))
    spec = importlib.util.spec_from_file_location("adding_a_domain", TUTORIAL)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, "adding_a_domain", module)  # the spawn-free sweep below pickles nothing
    spec.loader.exec_module(module)
    return module


def test_the_core_imports_no_domain_module() -> None:
    """Importing the library, the registry and the layers that read it imports no domain plugin (nor the
    envs it would bring): a plugin is imported when its domain is first looked up."""
    code = (
        f"import importlib, sys\nfor m in {CORE!r}: importlib.import_module(m)\n"
        "print(sorted(m for m in sys.modules if m.startswith(('torchrl_subgoal.envs', 'torchrl_subgoal.domains.'))))"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, check=True)
    assert done.stdout.strip() == "[]"


def test_built_in_domains_load_on_first_use() -> None:
    assert domains.names()[:6] == [
        "acrobot",
        "four_rooms",
        "four_rooms_step",
        "mountain_car",
        "pick_and_place",
        "pinball",
    ]
    assert domains.get("fetch") is domains.get("pick_and_place")  # what its recipe's results record
    assert domains.part("four_rooms", PaperResults).time_to_threshold[50]["SARSA"].mean == 51.8
    assert domains.get("pinball").make_env(3).batch_size == torch.Size([3])


def test_a_file_naming_an_unknown_domain_is_one_line(tmp_path: Path) -> None:
    path = tmp_path / "elsewhere.yaml"
    path.write_text("domain: elsewhere\npatterns:\n  p:\n    subgoals:\n      - state: 3\n")
    with pytest.raises(
        SubgoalFileError,
        match=r"^\S*elsewhere.yaml: domain: unknown domain 'elsewhere'; "
        r"known: acrobot, four_rooms, four_rooms_step, mountain_car, pick_and_place, pinball",
    ):
        load_patterns(path)


def test_pick_and_place_without_the_fetch_extra_still_says_how_to_install(monkeypatch: pytest.MonkeyPatch) -> None:
    real_import = builtins.__import__

    def no_robotics(name: str, *args: Any, **kwargs: Any) -> Any:
        if name == "gymnasium_robotics":
            raise ImportError("No module named 'gymnasium_robotics'", name="gymnasium_robotics")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_robotics)
    domain = domains.get("pick_and_place")  # registering needs no MuJoCo, nor does checking a file
    assert load_patterns(fetch.PARTICIPANTS_FILE, domain="pick_and_place")
    assert domain.make_env is not None
    with pytest.raises(
        fetch.FetchUnavailableError, match=r"gymnasium_robotics is missing\): pip install 'torchrl_subgoal\[fetch\]'"
    ):
        domain.make_env(1)


def test_a_toy_domain_checks_its_subgoal_files(corridor: ModuleType, tmp_path: Path) -> None:
    good, bad = tmp_path / "good.yaml", tmp_path / "bad.yaml"
    good.write_text(corridor.SUBGOAL_FILE)
    bad.write_text(corridor.SUBGOAL_FILE.replace("state: 8", "state: 12"))
    assert [p.state for p in load_patterns(good)["thirds"].predicates] == [4, 8]
    with pytest.raises(
        SubgoalFileError,
        match=r"bad.yaml: pattern 'thirds': subgoals\[1\]\.state: state 12 is "
        r"not a cell short of the goal",
    ):
        load_patterns(bad)
    cell = _written(tmp_path / "cell.yaml", "domain: corridor\npatterns:\n  p:\n    subgoals:\n      - cell: [1, 2]\n")
    with pytest.raises(
        SubgoalFileError, match=r"cell.yaml: pattern 'p': subgoals\[0\]\.cell: corridor subgoals are states"
    ):
        load_patterns(cell)


def _written(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def _corridor_chunk(chunk: Chunk, config: Mapping[str, Any], progress: Callable[[int], None]) -> EpisodeTable:
    """HRS or SARSA on the corridor, made through the registry only."""
    sarsa = SARSA_PRESETS["released"]
    patterns, index = chunk_patterns(chunk, config)
    env = domains.get("corridor").make_env(chunk.n_learners)  # type: ignore[misc]
    shaping = shaping_transform(
        paper_methods("SARSA")[chunk.method],
        env.batch_size,
        gamma=sarsa.gamma,
        value_lr=sarsa.value_lr,
        patterns=patterns,
        pattern_index=index,
    )
    agent = SoftmaxSarsa(chunk.n_learners, env.observation_spec["observation"].n, 2, sarsa, seed=chunk.seed)
    records = run_episodes(
        TransformedEnv(env, shaping) if shaping is not None else env, agent, config["episodes"], progress=progress
    )
    if shaping is not None:  # HRS learned a potential over the file's subgoals
        assert shaping.potential.table.abs().sum() > 0  # type: ignore[union-attr]
    return EpisodeTable(records.steps, records.returns, records.success)


def test_the_method_runs_on_a_toy_domain_from_a_subgoal_file(corridor: ModuleType, tmp_path: Path) -> None:
    path = _written(tmp_path / "corridor.yaml", corridor.SUBGOAL_FILE)
    patterns = load_patterns(path)
    config = {
        "episodes": 6,
        "patterns": {n: s.to_dict() for n, s in patterns.items()},
        "report": {"metric": "steps", "thresholds": [100.0]},
    }
    specs = [MethodSpec("HRS", ["thirds"], 3), MethodSpec("SARSA", ["none"], 3)]
    Sweep("corridor", tmp_path / "results", specs, _corridor_chunk, config, n_episodes=6).run(workers=0, progress=False)
    report = write_report(tmp_path / "results", n_boot=20)
    assert (tmp_path / "results" / "patterns.png").read_bytes()[:4] == b"\x89PNG"  # the corridor's draw_map
    assert "no map" not in report.markdown and "skipped" not in report.markdown


def test_a_toy_domain_joins_the_fused_engine(corridor: ModuleType, tmp_path: Path) -> None:
    """The corridor's record and its five env steps are all the fused engine needs: with SARSA, shaped by
    HRS over the file's subgoals or not, its episodes, Q table and potential equal the TorchRL loop's."""
    patterns = list(load_patterns(_written(tmp_path / "corridor.yaml", corridor.SUBGOAL_FILE)).values())
    sarsa, n = SARSA_PRESETS["released"], 6
    for method in ("HRS", "SARSA"):
        results = {}
        for engine in ("torchrl", "fused"):
            env = corridor.CorridorEnv(n, max_steps=40)
            shaping = shaping_transform(
                paper_methods("SARSA")[method],
                env.batch_size,
                gamma=sarsa.gamma,
                value_lr=sarsa.value_lr,
                patterns=patterns,
                pattern_index=torch.zeros(n, dtype=torch.long),
            )
            agent = SoftmaxSarsa(n, corridor.LENGTH + 1, 2, sarsa, seed=3)
            records = run_episodes(
                TransformedEnv(env, shaping) if shaping is not None else env, agent, 8, engine=engine
            )  # type: ignore[arg-type]
            potential = shaping.potential.table.clone() if shaping is not None else None  # type: ignore[union-attr]
            results[engine] = (records, agent.q.clone(), potential)
        (a, qa, va), (b, qb, vb) = results["torchrl"], results["fused"]
        assert torch.equal(a.steps, b.steps) and torch.equal(a.returns, b.returns)
        assert (a.steps < 40).any()  # some episodes reached the goal
        last = int(a.steps.sum(1).argmax())  # the fused engine stops a learner at its last episode
        assert torch.equal(qa[last], qb[last])
        if method == "HRS":
            assert va is not None and vb is not None and torch.equal(va[last], vb[last]) and vb.abs().sum() > 0
