"""The package's layers only look down, and its rooms stay small.

Layers, from the bottom: 0 the compiled kernels' random streams and the fused engine's step
protocol; 1 predicates and subgoal series (with their files); 2 abstraction tables; 3 potentials;
4 the loss; 5 the shaping transform; 6 envs and learners; 7 the engines (TorchRL loop, fused) and
the training building blocks; 8 the domain registry; 9 domain plugins, experiments, the studio and
the package's facade; 10 the scripts in ``recipes/``, ``tools/`` and ``benchmarks/``, which may import
the package but never the reverse. Every import counts: module-level, inside functions, under
``TYPE_CHECKING``, and a module named to ``importlib.import_module``. No import circle is allowed,
between modules or between folders.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "torchrl_subgoal"
#: the script folders (not packages): each script is the module ``<folder>.<name>``
SCRIPTS = ("recipes", "tools", "benchmarks")

#: module (exact) or package (every module below it) -> layer; the longest match wins
LAYERS: dict[str, int] = {
    "torchrl_subgoal._kernels": 0,
    "torchrl_subgoal._kernels.random": 0,
    "torchrl_subgoal._kernels.steps": 0,
    "torchrl_subgoal.subgoals.errors": 1,
    "torchrl_subgoal.subgoals.predicates": 1,
    "torchrl_subgoal.subgoals.series": 1,
    "torchrl_subgoal.subgoals.files": 1,
    "torchrl_subgoal.subgoals": 2,
    "torchrl_subgoal._kernels.regions": 2,
    "torchrl_subgoal.potentials": 3,
    "torchrl_subgoal.loss": 4,
    "torchrl_subgoal.transform": 5,
    "torchrl_subgoal._kernels.shaping": 5,
    "torchrl_subgoal._kernels.segments": 5,
    "torchrl_subgoal.envs": 6,
    "torchrl_subgoal._kernels.grid": 6,
    "torchrl_subgoal.fused.module": 6,
    "torchrl_subgoal.fused.sarsa": 6,
    "torchrl_subgoal.fused.actor_critic": 6,
    "torchrl_subgoal.training.ddpg_parts": 6,
    "torchrl_subgoal.training.stack": 6,
    "torchrl_subgoal.training.subgoal_input": 6,
    "torchrl_subgoal.fused._kernels.sarsa": 6,
    "torchrl_subgoal.fused._kernels.actor_critic": 6,
    "torchrl_subgoal.fused": 7,
    "torchrl_subgoal.training": 7,
    "torchrl_subgoal.methods": 7,
    "torchrl_subgoal.registry": 8,
    "torchrl_subgoal.domains": 8,
    "torchrl_subgoal.domains.": 9,
    "torchrl_subgoal.experiments": 9,
    "torchrl_subgoal.studio": 9,
    "torchrl_subgoal.console": 9,
    "torchrl_subgoal": 9,
    **dict.fromkeys(SCRIPTS, 10),
}
#: what the core of the method never imports, whatever the layers say
NOT_IN_THE_CORE = (
    "torchrl_subgoal.registry",
    "torchrl_subgoal.domains",
    "torchrl_subgoal.fused",
    "torchrl_subgoal.training",
    "torchrl_subgoal.experiments",
    "torchrl_subgoal.studio",
    "torchrl_subgoal.envs",
)
#: the packages of compiled kernels, whose functions take their arrays one by one
KERNELS = ("torchrl_subgoal._kernels", "torchrl_subgoal.fused._kernels")
CORE = ("torchrl_subgoal.subgoals", "torchrl_subgoal.transform", "torchrl_subgoal.potentials", "torchrl_subgoal.loss")


def module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {
    module_name(path): path
    for path in sorted([*PACKAGE.rglob("*.py"), *(p for folder in SCRIPTS for p in (ROOT / folder).glob("*.py"))])
}


def layer(module: str) -> int:
    """The layer of ``module``: its exact entry, else its closest package's (a ``"pkg."`` entry covers the
    modules below ``pkg`` but not ``pkg`` itself)."""
    if module in LAYERS:
        return LAYERS[module]
    parts = module.split(".")
    for end in range(len(parts) - 1, 0, -1):
        package = ".".join(parts[:end])
        if package + "." in LAYERS:
            return LAYERS[package + "."]
        if package in LAYERS:
            return LAYERS[package]
    raise KeyError(f"{module} has no layer: add it to LAYERS in {__file__}")


def imports(path: Path) -> set[str]:
    """The package modules ``path`` imports, anywhere in it (``from pkg import name`` counts as the module
    ``pkg.name`` when there is one, else ``pkg``)."""
    found = set()
    module = module_name(path)
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:  # relative: from the module's package
                package = module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]
                base = ".".join(package[: len(package) - node.level + 1] + ([base] if base else []))
            for alias in node.names:
                found.add(f"{base}.{alias.name}" if f"{base}.{alias.name}" in MODULES else base)
        elif isinstance(node, ast.Call) and getattr(node.func, "attr", getattr(node.func, "id", "")) == "import_module":
            found |= {a.value for a in node.args if isinstance(a, ast.Constant) and isinstance(a.value, str)}
    return {name for name in found if name in MODULES or name.startswith("torchrl_subgoal.")}


def test_every_module_has_a_layer() -> None:
    assert all(layer(module) >= 0 for module in MODULES)


@pytest.mark.parametrize("module", sorted(MODULES))
def test_no_module_imports_a_higher_layer(module: str) -> None:
    higher = sorted(f"{name} (layer {layer(name)})" for name in imports(MODULES[module]) if layer(name) > layer(module))
    assert not higher, f"{module} (layer {layer(module)}) imports {higher}"


@pytest.mark.parametrize("module", sorted(m for m in MODULES if m.startswith(CORE)))
def test_the_core_imports_no_registry_domain_agent_training_experiment_or_studio(module: str) -> None:
    assert not [name for name in imports(MODULES[module]) if name.startswith(NOT_IN_THE_CORE)]


def test_the_graph_is_read() -> None:
    """The test can fail: a plugin's imports reach up to the registry, the transform's down to the loss."""
    assert "torchrl_subgoal.domains" in imports(MODULES["torchrl_subgoal.domains.four_rooms"])
    assert "torchrl_subgoal.loss" in imports(MODULES["torchrl_subgoal.transform.setup"])
    assert layer("torchrl_subgoal.domains.four_rooms") > layer("torchrl_subgoal.domains")


# ----------------------------------------------------------------- no circles

#: import circles still to break, each a set of modules (none may be added; remove one once it is gone)
KNOWN_CIRCLES: list[set[str]] = []  # none: a new circle fails the tests below


def folder(module: str) -> str:
    """The folder ``module`` lives in: a package's own name for its ``__init__``, the script folder for a
    script; a module directly in ``torchrl_subgoal`` (the facade, ``loss``, ``registry`` …) is a folder
    of its own."""
    if MODULES[module].name == "__init__.py" or "." not in module:
        return module
    parent = module.rsplit(".", 1)[0]
    return module if parent == "torchrl_subgoal" else parent


def circles(graph: dict[str, set[str]]) -> list[set[str]]:
    """The strongly connected components of more than one node (Tarjan's algorithm, iteratively)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found = []
    for start in sorted(graph):
        if start in index:
            continue
        index[start] = low[start] = len(index)
        stack.append(start)
        on_stack.add(start)
        work = [(start, iter(sorted(graph[start])))]
        while work:
            node, successors = work[-1]
            for succ in successors:
                if succ not in index:
                    index[succ] = low[succ] = len(index)
                    stack.append(succ)
                    on_stack.add(succ)
                    work.append((succ, iter(sorted(graph.get(succ, ())))))
                    break
                if succ in on_stack:
                    low[node] = min(low[node], index[succ])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    component = set()
                    while True:
                        member = stack.pop()
                        on_stack.discard(member)
                        component.add(member)
                        if member == node:
                            break
                    if len(component) > 1:
                        found.append(component)
    return found


def module_graph() -> dict[str, set[str]]:
    return {m: {n for n in imports(p) if n in MODULES and n != m} for m, p in MODULES.items()}


def folder_graph() -> dict[str, set[str]]:
    graph: dict[str, set[str]] = {folder(m): set() for m in MODULES}
    for module, imported in module_graph().items():
        graph[folder(module)] |= {folder(n) for n in imported} - {folder(module)}
    return graph


def test_no_modules_import_each_other_in_a_circle() -> None:
    new = [sorted(c) for c in circles(module_graph()) if c not in KNOWN_CIRCLES]
    assert not new, f"import circles: {new}"


def test_no_folders_import_each_other_in_a_circle() -> None:
    """``domains/`` imports ``experiments/`` (for its report part), so ``experiments/`` finds the domains
    through ``registry``, never through ``domains/``."""
    known = [{folder(m) for m in c} for c in KNOWN_CIRCLES]
    new = [sorted(c) for c in circles(folder_graph()) if c not in known]
    assert not new, f"folder import circles: {new}"


def test_circles_are_found() -> None:
    """The test can fail: a circle of three, one inside a larger component, and none in a chain."""
    assert circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [{"a", "b", "c"}]
    assert circles({"a": {"b"}, "b": {"c"}, "c": set()}) == []
    assert folder("torchrl_subgoal.experiments.plots") == "torchrl_subgoal.experiments"
    assert folder("torchrl_subgoal.loss") == "torchrl_subgoal.loss"
    assert folder("recipes.train") == "recipes"
    assert all(c <= set(MODULES) for c in KNOWN_CIRCLES)


def test_the_scripts_are_read_and_nothing_in_the_package_imports_them() -> None:
    assert {"recipes.train", "tools.engine_identity", "benchmarks.seed_batch"} <= set(MODULES)
    assert "torchrl_subgoal.recipes.train" in imports(MODULES["recipes.train"])
    package = [m for m in MODULES if m.startswith("torchrl_subgoal")]
    assert not [(m, n) for m in package for n in imports(MODULES[m]) if n.split(".")[0] in SCRIPTS]


# ----------------------------------------------------------------- small rooms


def _functions(tree: ast.AST) -> list[ast.FunctionDef | ast.AsyncFunctionDef]:
    return [node for node in ast.walk(tree) if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef)]


def _compiled(function: ast.FunctionDef | ast.AsyncFunctionDef) -> bool:
    """A numba kernel (its arguments are arrays a compiled loop passes one by one)."""
    return any("numba" in ast.unparse(d) or "implements" in ast.unparse(d) for d in function.decorator_list)


def test_no_module_is_over_800_lines() -> None:
    long = {m: n for m, p in MODULES.items() if (n := len(p.read_text().splitlines())) > 800}
    assert not long


def test_no_function_but_a_kernel_takes_more_than_12_parameters() -> None:
    """Kernels (numba-compiled, or the compiled engine's generic steps in ``KERNELS``) take their arrays one
    by one; every other function takes at most 12."""
    many = []
    for module, path in MODULES.items():
        for function in _functions(ast.parse(path.read_text())):
            args = function.args
            count = (
                len(args.posonlyargs)
                + len(args.args)
                + len(args.kwonlyargs)
                - (args.args[:1] != [] and args.args[0].arg == "self")
            )
            if count > 12 and not _compiled(function) and not module.startswith(KERNELS):
                many.append(f"{module}.{function.name}: {count}")
    assert not many


def test_the_transform_class_keeps_specs_reset_step_and_transitions() -> None:
    """The class stays what a TorchRL transform is (specs, reset, step, transitions; the shaping behind a
    backend): at most 280 lines and 8 constructor parameters."""
    tree = ast.parse(MODULES["torchrl_subgoal.transform.transform"].read_text())
    cls = next(n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == "SubgoalPotentialTransform")
    assert cls.end_lineno is not None and cls.end_lineno - cls.lineno + 1 <= 280
    init = next(n for n in cls.body if isinstance(n, ast.FunctionDef) and n.name == "__init__")
    assert len(init.args.args) - 1 + len(init.args.kwonlyargs) <= 8  # the constructor's parameters
