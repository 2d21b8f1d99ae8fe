"""A new built-in domain is its folder under ``torchrl_subgoal/domains/`` and one entry point, nothing else.

The test adds a domain the way a built-in one is added: one file, ``domains/line/__init__.py`` (a
folder added to the ``torchrl_subgoal.domains`` package for this test only), declared by one entry
point (the line a built-in domain adds to ``pyproject.toml``; here the installed metadata that line
becomes). Every layer then finds it by name: the registry, the subgoal files, the report, the studio.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

import torchrl_subgoal.domains
from torchrl_subgoal import load_patterns, registry
from torchrl_subgoal.experiments.plots import ReportMap
from torchrl_subgoal.studio.domains import default_domains
from torchrl_subgoal.subgoals import SubgoalFileError

PLUGIN = '''"""A line of ten cells: the whole of a new domain."""

from torchrl_subgoal import domains
from torchrl_subgoal.envs import FourRoomsEnv
from torchrl_subgoal.experiments.plots import ReportMap
from torchrl_subgoal.studio.domains import StudioDomain
from torchrl_subgoal.subgoals import Predicate, State


def check_subgoal(predicate: Predicate) -> str | None:
    if not isinstance(predicate, State):
        return f"line subgoals are states, not {predicate.kind}"
    return None if 0 <= predicate.state < 10 else f"state {predicate.state} is off the line"


def geometry(config: str) -> dict:
    return {"kind": "grid", "rows": [" " * 10], "wall": "w", "start": [0, 0], "goal": [0, 9], "hallways": []}


DOMAIN = domains.register(
    domains.Domain(
        "line",
        "A line",
        make_env=FourRoomsEnv,
        check_subgoal=check_subgoal,
        parts=(ReportMap(lambda ax, patterns, options: None), StudioDomain(geometry, recipe="python line.py")),
    )
)
'''
ENTRY_POINT = "[torchrl_subgoal.domains]\nline = torchrl_subgoal.domains.line\n"


@pytest.fixture
def line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """The new domain's files under ``tmp_path``: its folder, and the entry point declaring it."""
    folder = tmp_path / "domains" / "line"
    folder.mkdir(parents=True)
    (folder / "__init__.py").write_text(PLUGIN)
    metadata = tmp_path / "entry_point" / "torchrl_subgoal_line-0.dist-info"
    metadata.mkdir(parents=True)
    (metadata / "METADATA").write_text("Metadata-Version: 2.1\nName: torchrl-subgoal-line\nVersion: 0\n")
    (metadata / "entry_points.txt").write_text(ENTRY_POINT)
    monkeypatch.setattr(torchrl_subgoal.domains, "__path__", [*torchrl_subgoal.domains.__path__, str(folder.parent)])
    monkeypatch.syspath_prepend(str(metadata.parent))
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))
    yield tmp_path
    sys.modules.pop("torchrl_subgoal.domains.line", None)


def test_a_new_domain_needs_its_folder_and_one_entry_point(line: Path) -> None:
    files = sorted(str(p.relative_to(line)) for p in line.rglob("*") if p.is_file())
    assert files == [
        "domains/line/__init__.py",  # the plugin: env, subgoal check, each layer's part
        "entry_point/torchrl_subgoal_line-0.dist-info/METADATA",  # the entry point, as installed
        "entry_point/torchrl_subgoal_line-0.dist-info/entry_points.txt",
    ]
    assert "line" in registry.names()
    assert registry.get("line").title == "A line"  # imported on first use, from its folder
    assert registry.get("line").make_env(2).batch_size == (2,)


def test_every_layer_finds_the_new_domain_by_name(line: Path) -> None:
    good, bad = line / "good.yaml", line / "bad.yaml"
    good.write_text("domain: line\npatterns:\n  p:\n    subgoals:\n      - state: 3\n")
    bad.write_text("domain: line\npatterns:\n  p:\n    subgoals:\n      - state: 12\n")
    assert load_patterns(good)["p"].predicates[0].state == 3
    with pytest.raises(
        SubgoalFileError, match=r"bad.yaml: pattern 'p': subgoals\[0\]\.state: state 12 is off the line"
    ):
        load_patterns(bad)
    assert isinstance(registry.part("line", ReportMap), ReportMap)  # the report's map
    studio = default_domains()["line"]  # the studio's menu
    assert (studio.title, studio.check_subgoal is not None) == ("A line", True)


def test_the_built_in_domains_are_folders_declared_by_entry_points() -> None:
    """Each built-in plugin is ``domains/<name>/`` (one entry point per domain name it registers)."""
    package = Path(torchrl_subgoal.domains.__file__).parent
    folders = sorted(p.name for p in package.iterdir() if (p / "__init__.py").is_file())
    declared = registry._plugins()
    assert folders == sorted({module.rsplit(".", 1)[1] for module in declared.values()})
    assert not [p.name for p in package.glob("*.py") if p.name != "__init__.py"]  # no plugin outside a folder
