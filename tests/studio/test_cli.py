"""``torchrl-subgoal studio`` / ``python -m torchrl_subgoal.studio``: serve, ports, bad options."""

from __future__ import annotations

import json
import signal
import socket
import subprocess
import sys
import urllib.error
import urllib.request
from pathlib import Path

import pytest
from flask import Flask

from torchrl_subgoal.console import main as console
from torchrl_subgoal.studio.server import DEFAULT_PORT, listen, main

BIN = Path(sys.executable).parent


def test_serves_on_loopback_and_stops_on_ctrl_c(tmp_path: Path) -> None:
    proc = subprocess.Popen(
        [sys.executable, "-m", "torchrl_subgoal.studio", "--port", "0", "--folder", str(tmp_path / "files")],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline()  # the address, once it listens (nothing if it failed)
        assert line.startswith("Subgoal studio at http://127.0.0.1:"), (line, proc.stderr and proc.stderr.read())
        url = line.split()[3]
        base, _, query = url.partition("?")
        token = query.removeprefix("token=")
        assert query.startswith("token=") and len(token) >= 32  # a per-launch token, printed with the address
        api = urllib.request.Request(f"{base}api/domains", headers={"X-Studio-Token": token})
        with urllib.request.urlopen(api, timeout=60) as response:
            assert [d["name"] for d in json.load(response)] == [
                "four_rooms",
                "pinball",
                "pick_and_place",
                "point_maze_umaze",
                "point_maze_medium",
                "mountain_car",
            ]
        with urllib.request.urlopen(url, timeout=60) as response:
            assert "<title>Subgoal studio" in response.read().decode()
        for without in (f"{base}api/domains", base, f"{base}api/files?token=wrong"):
            with pytest.raises(urllib.error.HTTPError) as refused:
                urllib.request.urlopen(without, timeout=60)
            assert refused.value.code == 403 and b"token is missing or wrong" in refused.value.read()
        assert (tmp_path / "files").is_dir()
    finally:
        proc.send_signal(signal.SIGINT)
        assert proc.wait(120) == 0


def test_a_taken_default_port_falls_back_to_a_free_one(app: Flask) -> None:
    blocker = socket.socket()
    try:
        blocker.bind(("127.0.0.1", DEFAULT_PORT))
        blocker.listen()
    except OSError:
        pass  # something else holds it already: the same situation
    try:
        server = listen(app, "127.0.0.1", None)
        assert server.port not in (0, DEFAULT_PORT)
        server.server_close()
    finally:
        blocker.close()


def test_a_taken_given_port_is_a_clear_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with socket.socket() as blocker:
        blocker.bind(("127.0.0.1", 0))
        blocker.listen()
        port = blocker.getsockname()[1]
        assert main(["--port", str(port), "--folder", str(tmp_path)]) == 2
    assert f"error: --host 127.0.0.1 --port {port}: cannot listen" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--pinball-map", "mine={bad}"], "error: {bad}, line 2: 'target' expects 3 number(s), got 2"),
        (["--pinball-map", "simple={good}"], "error: PinBall map name 'simple' is taken"),
        (["--max-jobs", "0"], "error: --max-jobs: must be >= 1"),
    ],
)
def test_bad_options(tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], message: str) -> None:
    from torchrl_subgoal.envs.pinball import _DATA_DIR

    bad, good = tmp_path / "bad.cfg", tmp_path / "good.cfg"
    bad.write_text("ball 0.02\ntarget 0.9 0.2\n")
    good.write_text((_DATA_DIR / "simple.cfg").read_text())
    argv = [a.format(bad=bad, good=good) for a in argv]
    assert main([*argv, "--folder", str(tmp_path / "files")]) == 2
    assert message.format(bad=bad) in capsys.readouterr().err


def test_console_script_dispatches(capsys: pytest.CaptureFixture[str]) -> None:
    assert console(["nope"]) == 2
    assert "unknown command 'nope'" in capsys.readouterr().err
    assert console([]) == 2
    with pytest.raises(SystemExit) as exit_:
        console(["studio", "--help"])
    assert exit_.value.code == 0 and "--pinball-map" in capsys.readouterr().out
    installed = subprocess.run([str(BIN / "torchrl-subgoal"), "--help"], capture_output=True, text=True, timeout=300)
    assert installed.returncode == 0 and "studio     draw subgoal series" in installed.stdout
