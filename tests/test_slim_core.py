"""The core without the experiment stack: with numba, scipy, pandas, pyarrow, statsmodels, matplotlib, tyro
and rliable absent, ``import torchrl_subgoal`` works, the README's snippet shapes an env of its own behind a
collector (the transform stepping in torch), and ``use_backend("compiled")`` says what is missing.

``make install-check`` makes the same check in a venv that never had them (tools/check_install.py); this
one hides them from a fresh interpreter of the dev venv (``sys.modules[name] = None``), in seconds."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from tests.tools import load_tool as tool

ROOT = Path(__file__).resolve().parents[1]
HIDE = "import sys\nfor name in {names!r}:\n    sys.modules[name] = None\n"


def run_hidden(code: str, *args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    hidden = tool("check_install").NOT_IN_CORE
    return subprocess.run(
        [sys.executable, "-c", HIDE.format(names=hidden) + code, *args],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=cwd,
    )


def test_the_readme_snippet_runs_without_the_experiment_stack(tmp_path: Path) -> None:
    check = tool("check_install")
    done = run_hidden(check.CORE_SCRIPT, str(ROOT / "README.md"), ",".join(check.NOT_IN_CORE), cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "README snippet shaped" in done.stdout


def test_without_numba_auto_steps_in_torch_and_compiled_says_why(tmp_path: Path) -> None:
    code = """
import torch
from tensordict import TensorDict
from torchrl.data import Categorical, Composite, Unbounded
from torchrl.envs import EnvBase, TransformedEnv
from torchrl_subgoal import State, SubgoalPotentialTransform, SubgoalSeries, TabularPotential
from torchrl_subgoal._kernels import NUMBA

class Walk(EnvBase):
    def __init__(self):
        super().__init__(batch_size=torch.Size([2]))
        self.observation_spec = Composite(observation=Categorical(4, shape=(2,), dtype=torch.long), shape=(2,))
        self.action_spec = Categorical(2, shape=(2,), dtype=torch.long)
        self.reward_spec = Unbounded(shape=(2, 1))
    def _reset(self, td=None, **kwargs):
        false = torch.zeros(2, 1, dtype=torch.bool)
        self.pos = torch.zeros(2, dtype=torch.long)
        return TensorDict({"observation": self.pos.clone(), "done": false, "terminated": false}, [2])
    def _step(self, td):
        self.pos = (self.pos + 1).clamp(max=3)
        done = (self.pos == 3).unsqueeze(-1)
        return TensorDict({"observation": self.pos.clone(), "reward": torch.ones(2, 1), "done": done,
                           "terminated": done.clone()}, [2])
    def _set_seed(self, seed):
        pass

def shaped(backend):
    transform = SubgoalPotentialTransform(SubgoalSeries([State(1), State(2)]), TabularPotential(3), gamma=0.9,
                                          observation_key="observation", value_update=0.5)
    return TransformedEnv(Walk(), transform.use_backend(backend))

assert not NUMBA
rollout = shaped("auto").rollout(3)
print("shaped", rollout["next", "reward"][0].flatten().tolist(), rollout["next", "env_reward"][0].flatten().tolist())
try:
    shaped("compiled").reset()
except TypeError as exc:
    print(exc)
"""
    done = run_hidden(code, cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "numba is not installed (pip install numba)" in done.stdout
    assert "shaped [" in done.stdout and "[1.0, 1.0, 1.0]" in done.stdout  # the env reward kept beside the shaped
