"""Fingerprint of both reproductions at a small setting: records, learners' tables and potentials.

Runs each recipe in this process (no workers) at a small setting and, for every
chunk, keeps the episode records, the learner's final tables (SARSA's Q; the
actor-critic's ``w`` and ``θ``) and the shaping potential's table, then saves
them to an ``.npz`` file. Two checkouts agree bit for bit when their files do::

    python tools/engine_identity.py /tmp/after.npz
    PYTHONPATH=/tmp/before python tools/engine_identity.py /tmp/before.npz
    python tools/engine_identity.py --compare /tmp/before.npz /tmp/after.npz

``--engine torchrl`` runs the TorchRL loop instead of the fused engine.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib.util
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

SMALL = {
    "four_rooms": ["--learnings", "3", "--episodes", "40", "--random-patterns", "2"],
    "pinball": ["--learnings", "1", "--episodes", "2", "--random-patterns", "1", "--max-steps", "600"],
}


def _arrays(obj: Any, names: tuple[str, ...]) -> dict[str, np.ndarray]:
    out = {}
    for name in names:
        value = getattr(obj, name, None)
        if value is None:
            continue
        out[name] = np.array(value.detach().numpy() if hasattr(value, "detach") else value)
    return out


def recipe_module(domain: str) -> Any:
    """The recipe of ``domain`` in the package on the path (``torchrl_subgoal.recipes``), or, for a checkout
    from before the recipes moved into the package, its ``recipes/`` script."""
    try:
        return importlib.import_module(f"torchrl_subgoal.recipes.{domain}")
    except ModuleNotFoundError:
        import torchrl_subgoal

        script = Path(torchrl_subgoal.__file__).resolve().parents[1] / "recipes" / f"{domain}.py"
        spec = importlib.util.spec_from_file_location(f"recipe_{domain}", script)
        assert spec is not None and spec.loader is not None
        recipe = importlib.util.module_from_spec(spec)
        sys.modules[spec.name] = recipe
        spec.loader.exec_module(recipe)
        return recipe


def fingerprint(engine: str) -> dict[str, np.ndarray]:
    """Every chunk's records, tables and potential, keyed ``domain/method/chunk/name``."""
    import torch

    found: dict[str, np.ndarray] = {}
    for domain, args in SMALL.items():
        recipe = recipe_module(domain)
        run = recipe.run_episodes
        count = [0]

        def capture(
            env: Any,
            agent: Any,
            episodes: int,
            _run: Any = run,
            _domain: str = domain,
            _count: list[int] = count,
            **kwargs: Any,
        ) -> Any:
            records = _run(env, agent, episodes, **kwargs)
            key = f"{_domain}/{_count[0]}"
            _count[0] += 1
            found[f"{key}/steps"] = records.steps.numpy().copy()
            found[f"{key}/returns"] = records.returns.numpy().copy()
            found[f"{key}/success"] = records.success.numpy().copy()
            found[f"{key}/env_steps"] = np.array(records.env_steps)
            for name, value in _arrays(agent, ("q", "w", "theta")).items():
                found[f"{key}/agent.{name}"] = value
            transform = getattr(env, "transform", None)
            table = getattr(getattr(transform, "potential", None), "table", None)
            if isinstance(table, torch.Tensor):
                found[f"{key}/potential"] = table.detach().numpy().copy()
            return records

        recipe.run_episodes = capture
        plan = recipe.plan

        def no_warm_up(cfg: Any, _plan: Any = plan) -> Any:  # the fingerprint is of the sweep's chunks only
            made = _plan(cfg)
            return dataclasses.replace(made, warm_up=None) if hasattr(made, "warm_up") else made

        recipe.plan = no_warm_up
        with tempfile.TemporaryDirectory() as results:
            code = recipe.main([*args, "--workers", "0", "--engine", engine, "--results", results])
        recipe.run_episodes, recipe.plan = run, plan
        if code:
            raise SystemExit(f"{domain} recipe failed ({code})")
    return found


def compare(a: Path, b: Path) -> int:
    """Print the differing keys; 0 if the two fingerprints are identical."""
    left, right = np.load(a), np.load(b)
    keys = sorted(set(left.files) | set(right.files))
    bad = [
        k
        for k in keys
        if k not in left.files or k not in right.files or not np.array_equal(left[k], right[k], equal_nan=True)
    ]
    for k in bad:
        print(f"differs: {k}")
    print(f"{len(keys) - len(bad)} of {len(keys)} arrays identical")
    return 1 if bad else 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("out", nargs="?", help="the .npz file to write")
    parser.add_argument("--engine", default="fused", choices=["fused", "torchrl"])
    parser.add_argument("--compare", nargs=2, metavar="NPZ", help="compare two fingerprints")
    opts = parser.parse_args(argv)
    if opts.compare:
        return compare(Path(opts.compare[0]), Path(opts.compare[1]))
    if not opts.out:
        parser.error("give the .npz file to write (or --compare A B)")
    found = fingerprint(opts.engine)
    np.savez(opts.out, **found)  # type: ignore[arg-type]
    print(f"{len(found)} arrays -> {opts.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
