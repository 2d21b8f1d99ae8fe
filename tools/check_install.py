"""Install check: the package as a user gets it, from a built wheel, in clean venvs outside the repository.

Builds the wheel from the working tree (tracked and new files, in a temporary copy), then

* **core**: a venv with torch and the wheel alone (no extra): numba, pandas, matplotlib, scipy,
  tyro and rliable must be absent; ``import torchrl_subgoal`` works and the README's "Use it on
  your env" snippet shapes a small TorchRL env of its own behind a collector (the transform
  steps in torch) and trains the potential;
* **full**: a venv with the wheel's ``experiments`` and ``tensorboard`` extras: ``torchrl-subgoal
  train --algo ppo --domain four_rooms_step ... --logger tensorboard`` and ``torchrl-subgoal
  report`` run from a directory outside the repository, exit 0, and write TensorBoard event
  files, the report and its figures.

Each venv installs torch==2.13.0 first (the CPU build), as the Makefile does. The venvs are kept
(``--venvs DIR``, default ``$TMPDIR/torchrl_subgoal-install-check``) and reused by the next run,
which reinstalls the wheel; ``--fresh`` starts them over. ``make test`` runs this.

    python tools/check_install.py
    python tools/check_install.py --fresh --venvs /tmp/check
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TORCH = "torch==2.13.0"
#: what the core install must not bring
NOT_IN_CORE = ("numba", "pandas", "pyarrow", "matplotlib", "scipy", "statsmodels", "tyro", "rliable")

#: run by the core venv's Python: the README's snippet on a small env of its own (no numba, no package envs)
CORE_SCRIPT = r'''
import importlib.util, sys
from pathlib import Path

absent = [m for m in sys.argv[2].split(",") if importlib.util.find_spec(m) is not None]
assert not absent, f"the core install brought {absent}"

import torch
from tensordict import TensorDict
from torchrl.collectors import Collector
from torchrl.data import Categorical, Composite, Unbounded
from torchrl.envs import EnvBase

import torchrl_subgoal
from torchrl_subgoal import State, SubgoalSeries, save_patterns


class Corridor(EnvBase):
    """Cells 0..5 of a corridor: action 1 steps right, 0 left; -1 per step, the last cell ends it."""

    def __init__(self, n):
        super().__init__(batch_size=torch.Size([n]))
        self.observation_spec = Composite(observation=Categorical(6, shape=(n,), dtype=torch.long), shape=(n,))
        self.action_spec = Categorical(2, shape=(n,), dtype=torch.long)
        self.reward_spec = Unbounded(shape=(n, 1))
        self.pos = torch.zeros(n, dtype=torch.long)

    def _reset(self, td=None, **kwargs):
        reset = td.get("_reset", None) if td is not None else None
        self.pos.masked_fill_(torch.ones_like(self.pos, dtype=torch.bool) if reset is None else reset.reshape(-1), 0)
        false = torch.zeros(*self.batch_size, 1, dtype=torch.bool)
        observation = {"observation": self.pos.clone(), "done": false, "terminated": false.clone()}
        return TensorDict(observation, self.batch_size)

    def _step(self, td):
        self.pos = (self.pos + 2 * td["action"] - 1).clamp(0, 5)
        done = (self.pos == 5).unsqueeze(-1)
        reward = torch.full((*self.batch_size, 1), -1.0)
        return TensorDict(
            {"observation": self.pos.clone(), "reward": reward, "done": done, "terminated": done.clone()},
            self.batch_size,
        )

    def _set_seed(self, seed):
        torch.manual_seed(seed)


readme = Path(sys.argv[1]).read_text()
start = readme.index("## Use it on your env")
begin = readme.index("```python\n", start) + len("```python\n")
code = readme[begin : readme.index("```", begin)]
save_patterns("my_subgoals.yaml", {"alice": SubgoalSeries([State(1), State(3)], name="alice")})
namespace = {"base_env": Corridor(4)}
exec(compile(code, "README.md", "exec"), namespace)
shaping, env, potential = namespace["shaping"], namespace["env"], namespace["potential"]
initial = potential.table.detach().clone()
torch.manual_seed(0)
collector = Collector(env, None, frames_per_batch=200, total_frames=600)
shaped = []
for data in collector:
    shaped.append(not torch.equal(data["next", "reward"], data["next", "env_reward"]))
collector.shutdown()
assert any(shaped), "the README snippet shaped no reward"
assert not torch.equal(potential.table.detach(), initial), "the potential did not learn"
print(f"core: torchrl_subgoal {torchrl_subgoal.__version__} from {Path(torchrl_subgoal.__file__).parent}; "
      f"README snippet shaped {sum(shaped)} of {len(shaped)} batches; potential {potential.table.flatten().tolist()}")
'''

ONE_PATTERN = """format: torchrl_subgoal/v1
domain: four_rooms
observation_key: cell
patterns:
  hallways: {subgoals: [{cell: [6, 2]}, {cell: [10, 6]}]}
"""


def run(command: list[str], **kwargs: object) -> subprocess.CompletedProcess[str]:
    """Run ``command`` with no ``PYTHONPATH`` (so the venv imports its installed package), failing loudly."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    env.setdefault("MPLBACKEND", "Agg")
    print("+", " ".join(arg if len(arg) < 200 else arg[:40].strip() + " ..." for arg in command), flush=True)
    done = subprocess.run(command, env=env, text=True, capture_output=True, **kwargs)  # type: ignore[call-overload]
    if done.returncode != 0:
        sys.stderr.write(done.stdout[-4000:] + done.stderr[-4000:])
        raise SystemExit(f"failed ({done.returncode}): {' '.join(command)}")
    return done


def build_wheel(out: Path) -> Path:
    """The wheel of the working tree's tracked and new files, built in a copy (no stale build/ of the tree)."""
    listed = subprocess.run(
        ["git", "-C", str(ROOT), "ls-files", "-co", "--exclude-standard"], capture_output=True, text=True, check=True
    ).stdout.split("\n")
    with tempfile.TemporaryDirectory() as copy:
        for name in filter(None, listed):
            source = ROOT / name
            if source.is_file():
                (Path(copy) / name).parent.mkdir(parents=True, exist_ok=True)
                shutil.copy2(source, Path(copy) / name)
        run(
            [sys.executable, "-m", "pip", "wheel", "--quiet", "--no-deps", copy, "-w", str(out)]  # as a user builds it
        )
    (wheel,) = out.glob("torchrl_subgoal-*.whl")
    return wheel


def venv(path: Path, fresh: bool) -> Path:
    """A venv at ``path`` with torch installed (made once, kept for the next run); its Python."""
    if fresh and path.exists():
        shutil.rmtree(path)
    python = path / "bin" / "python"
    if not python.exists():
        run([sys.executable, "-m", "venv", str(path)])
        run([str(python), "-m", "pip", "install", "--quiet", TORCH])
    return python


def size(path: Path) -> str:
    return subprocess.run(["du", "-sh", str(path)], capture_output=True, text=True).stdout.split()[0]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--venvs", type=Path, default=Path(tempfile.gettempdir()) / "torchrl_subgoal-install-check")
    parser.add_argument("--fresh", action="store_true", help="make the venvs anew")
    opts = parser.parse_args(argv)
    venvs = opts.venvs.resolve()
    if venvs.is_relative_to(ROOT):
        parser.error(f"--venvs {venvs} is inside the repository; the check installs outside it")
    start = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        wheel = build_wheel(Path(tmp) / "wheel")
        print(f"built {wheel.name}", flush=True)

        core = venv(venvs / "core", opts.fresh)
        run([str(core), "-m", "pip", "install", "--quiet", "--force-reinstall", "--no-deps", str(wheel)])
        run([str(core), "-m", "pip", "install", "--quiet", str(wheel)])
        work = Path(tmp) / "core"
        work.mkdir()
        done = run([str(core), "-c", CORE_SCRIPT, str(ROOT / "README.md"), ",".join(NOT_IN_CORE)], cwd=work)
        print(done.stdout.strip())

        full = venv(venvs / "full", opts.fresh)
        run([str(full), "-m", "pip", "install", "--quiet", "--force-reinstall", "--no-deps", str(wheel)])
        run([str(full), "-m", "pip", "install", "--quiet", f"{wheel}[experiments,tensorboard]"])
        command = str(full.parent / "torchrl-subgoal")
        work = Path(tmp) / "full"
        work.mkdir()
        (work / "one_pattern.yaml").write_text(ONE_PATTERN)
        run([command, "--help"], cwd=work)
        train = [command, "train", "--algo", "ppo", "--domain", "four_rooms_step", "--methods", "PPO,HRS"]
        train += ["--subgoals", "one_pattern.yaml", "--total-frames", "512", "--workers", "0"]
        run([*train, "--results", "results/ppo", "--logger", "tensorboard"], cwd=work)
        events = sorted((work / "results" / "ppo" / "logs").glob("*/events.out.tfevents.*"))
        if len(events) != 2:
            raise SystemExit(f"expected a TensorBoard event file per learner (2), found {len(events)}")
        run([command, "report", "results/ppo", "--out", "report", "--n-boot", "200"], cwd=work)
        written = sorted(p.name for p in (work / "report").iterdir())
        for name in ("report.md", "summary.json", "learning_curves.png", "learning_curves.pdf", "learning_curves.svg"):
            if name not in written:
                raise SystemExit(f"torchrl-subgoal report wrote no {name} (wrote {written})")
        print(f"full: torchrl-subgoal train wrote {len(events)} TensorBoard event files; report wrote {written}")
    print(
        f"install check passed in {time.perf_counter() - start:.0f} s; venvs (kept for the next run): "
        f"core {size(venvs / 'core')}, full {size(venvs / 'full')} in {venvs}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
