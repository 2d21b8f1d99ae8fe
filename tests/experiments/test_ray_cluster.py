"""The Ray backend as users run it on a cluster: a head and a second node started with ``ray start`` on this
machine (two raylets, one CPU each), a sweep pointed at it with ``RAY_ADDRESS``, one chunk's worker killed
mid-chunk every time Ray runs it, then the same command again.

Every wait polls for a state (a line in the chunks' log, the cluster's nodes) with a generous deadline;
nothing depends on timing. The nodes run in sessions of their own and are stopped by signalling those
(never ``ray stop``, which would stop every Ray instance on the machine).
"""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from tests.experiments.test_sweep import chunk_files, make_sweep
from torchrl_subgoal.experiments import load_frame
from torchrl_subgoal.experiments.backend import RAY_RETRIES

pytestmark = [pytest.mark.slow, pytest.mark.xdist_group("ray")]  # one Ray at a time under pytest-xdist

ROOT = Path(__file__).resolve().parents[2]
RAY = Path(sys.executable).with_name("ray")
DEADLINE = 600.0  # seconds any one wait may take on a busy machine
VICTIM = "HRS/00000"  # the chunk whose worker is killed


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def wait_for(what: str, condition: Callable[[], object]) -> object:
    """Poll ``condition`` until it returns something true; fail after :data:`DEADLINE` naming ``what``."""
    deadline = time.monotonic() + DEADLINE
    while not (value := condition()):
        if time.monotonic() > deadline:
            pytest.fail(f"timed out waiting for {what}")
        time.sleep(0.2)
    return value


def stop(process: subprocess.Popen[bytes]) -> None:
    """Stop a node: its whole session (``ray start --block`` and the processes it started), by its id."""
    for sig in (signal.SIGTERM, signal.SIGKILL):
        try:
            os.killpg(process.pid, sig)
        except ProcessLookupError:
            return
        try:
            process.wait(30)
            if sig == signal.SIGTERM:  # its children may outlive it: make sure
                continue
        except subprocess.TimeoutExpired:
            continue


def alive_nodes(address: str, env: dict[str, str]) -> int:
    """How many nodes of the cluster at ``address`` are alive (asked from a fresh process)."""
    script = (
        f"import ray; ray.init(address={address!r}, log_to_driver=False); print(sum(n['Alive'] for n in ray.nodes()))"
    )
    done = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=DEADLINE)
    lines = done.stdout.split()
    return int(lines[-1]) if done.returncode == 0 and lines else 0


@contextmanager
def ray_cluster(env: dict[str, str]) -> Iterator[str]:
    """A head and one more node on this machine, one CPU each; yields the head's address."""
    address = f"127.0.0.1:{free_port()}"
    temp = Path(tempfile.mkdtemp(prefix="ray", dir="/tmp"))  # short: Ray's socket paths must fit 107 bytes
    common = ["--num-cpus=1", "--block", "--disable-usage-stats", "--object-store-memory=100000000"]
    head = ["--head", f"--port={address.split(':')[1]}", "--include-dashboard=false", f"--temp-dir={temp}"]
    nodes: list[subprocess.Popen[bytes]] = []
    try:
        for number, args in enumerate([head, [f"--address={address}"]], start=1):
            with open(temp.with_name(f"{temp.name}-node{number}.log"), "wb") as log:
                agent = f"--dashboard-agent-listen-port={free_port()}"  # else a fixed default: two nodes here
                nodes.append(
                    subprocess.Popen(
                        [str(RAY), "start", *args, *common, agent],
                        env=env,
                        stdout=log,
                        stderr=subprocess.STDOUT,
                        start_new_session=True,
                    )
                )
            wait_for(f"{number} Ray node(s) at {address}", lambda n=number: alive_nodes(address, env) == n)
        yield address
    finally:
        for node in reversed(nodes):
            stop(node)
        shutil.rmtree(temp, ignore_errors=True)
        for number in (1, 2):
            temp.with_name(f"{temp.name}-node{number}.log").unlink(missing_ok=True)


def chunk_log(path: Path) -> list[tuple[str, int, str]]:
    """``(chunk, pid, node)`` per chunk start, as :mod:`tests.experiments.toy_domain` logs them (no tag)."""
    if not path.exists():
        return []
    rows = [line.split() for line in path.read_text().splitlines()]
    return [(chunk, int(pid), node) for chunk, pid, node in (row for row in rows if len(row) == 3)]


def test_a_sweep_on_a_two_node_cluster_survives_a_killed_worker(tmp_path: Path) -> None:
    results, log, gate = tmp_path / "results", tmp_path / "chunks.log", tmp_path / "gate"
    names = [chunk.name for chunk in make_sweep(tmp_path / "plan").chunks]
    assert VICTIM in names and len(names) == 12
    # RAY_AUTH_MODE: `ray start --head` turns token authentication on by itself where a token file exists
    # (~/.ray/auth_token) while a client does not send it unless told; this cluster is local and short-lived
    env = {**os.environ, "PYTHONPATH": str(ROOT), "RAY_USAGE_STATS_ENABLED": "0", "RAY_AUTH_MODE": "disabled"}
    env.pop("RAY_ADDRESS", None)
    # the chunks' settings: a cluster's workers get the environment of their node, not of the sweep
    env |= {
        "TOY_LOG": str(log),
        "TOY_GATE": str(gate),  # the victim waits at the gate (until its worker is killed); the others run through
        "TOY_FREE": ",".join(n for n in names if n != VICTIM),
    }
    command = [sys.executable, "-m", "tests.experiments.toy_domain", "sweep", str(results), "--backend", "ray"]
    with ray_cluster(env) as address:
        with open(tmp_path / "first.err", "w") as stderr:
            first = subprocess.Popen(command, env={**env, "RAY_ADDRESS": address}, cwd=ROOT, stderr=stderr)
        try:
            for attempt in range(1, RAY_RETRIES + 2):  # every run of the victim: its worker killed mid-chunk
                runs = wait_for(
                    f"run {attempt} of {VICTIM}",
                    lambda: [row for row in chunk_log(log) if row[0] == VICTIM][attempt - 1 :],  # noqa: B023
                )
                os.kill(runs[0][1], signal.SIGKILL)  # type: ignore[index]
            first.wait(DEADLINE)
        finally:
            if first.poll() is None:
                first.kill()
        err = (tmp_path / "first.err").read_text()
        assert first.returncode == 1, err[-3000:]
        errors = [line for line in err.splitlines() if line.startswith("error:")]
        assert len(errors) == 1 and err.rstrip().endswith(errors[0]), err[-3000:]
        assert errors[0].startswith(f"error: chunk {VICTIM} failed: WorkerCrashedError: ")
        assert f"(Ray ran it {RAY_RETRIES + 1} times)" in errors[0]
        assert "run the same command again" in errors[0]
        kept = chunk_files(results)
        finished = {path.removeprefix("chunks/").removesuffix(".parquet") for path in kept}
        assert finished and VICTIM not in finished  # the chunks that finished are saved
        first_run = chunk_log(log)

        gate.touch()
        second = subprocess.run(
            command, env={**env, "RAY_ADDRESS": address}, cwd=ROOT, capture_output=True, text=True, timeout=DEADLINE
        )
        assert second.returncode == 0, second.stderr[-3000:]
    rows = chunk_log(log)
    assert len({node for _, _, node in rows}) == 2  # the chunks ran on both nodes
    assert {chunk for chunk, _, _ in rows[len(first_run) :]} == set(names) - finished  # only what was missing
    files = chunk_files(results)
    assert {name: files[name] for name in kept} == kept  # the saved chunks untouched
    reference = tmp_path / "local"
    make_sweep(reference).run(workers=0, progress=False)
    assert load_frame(results).equals(load_frame(reference))
