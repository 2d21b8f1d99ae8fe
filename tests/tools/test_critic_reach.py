"""tools/critic_reach.py: an actor-critic's values beside the returns that followed."""

from __future__ import annotations

import pytest

from tests.tools import load_tool

tool = load_tool("critic_reach")


@pytest.mark.parametrize("algo", ["a2c", "ppo"])
def test_a_short_run_prints_each_learners_values_and_returns(algo: str, capsys: pytest.CaptureFixture[str]) -> None:
    frames = 4096 if algo == "ppo" else 512  # one PPO batch; two A2C batches
    assert tool.main(["--algo", algo, "--frames", str(frames), "--learners", "2", "--reward-scale", "1"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == f"{algo}, reward scale 1.0, {frames} frames per learner"
    assert [line.split(":")[0] for line in lines[1:]] == ["learner 0", "learner 1"]
    # rewards of -1 over 200-step episodes: every return lies in [-(1 - 0.99**200) / 0.01, -1]
    low = float(lines[1].split("returns mean ")[1].split(" [")[1].split(",")[0])
    assert -86.7 <= low <= -1.0


def test_on_pinball_only_the_episodes_that_ended_are_compared(capsys: pytest.CaptureFixture[str]) -> None:
    """PinBall's episodes outlast a short rollout: a learner none of whose episodes ended says so instead of
    comparing values with the truncated returns."""
    args = ["--algo", "a2c", "--domain", "pinball", "--frames", "512", "--learners", "1", "--steps", "5"]
    assert tool.main(args) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == "a2c, reward scale 0.0001, 512 frames per learner"
    assert lines[1] == "learner 0: no episode ended within 5 steps; give more --steps or --frames"
