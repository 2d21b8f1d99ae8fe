"""Sweeps: chunk planning, resume after SIGKILL, corruption, config checks, backends."""

from __future__ import annotations

import multiprocessing
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from tests.experiments import toy_domain
from torchrl_subgoal.experiments import (
    Chunk,
    ChunkFailedError,
    ConfigMismatchError,
    CorruptChunkWarning,
    DomainMismatchError,
    EpisodeTable,
    MethodSpec,
    ResultsError,
    Sweep,
    UnknownMethodError,
    load_frame,
    plan_chunks,
    select_methods,
)
from torchrl_subgoal.experiments.store import ResultsStore

REPO = Path(__file__).resolve().parents[2]


def make_sweep(path: Path, **overrides: object) -> Sweep:
    kwargs: dict[str, object] = {
        "domain": toy_domain.DOMAIN,
        "results_dir": path,
        "methods": toy_domain.toy_methods(3),
        "run_chunk": toy_domain.run_chunk,
        "config": toy_domain.toy_config(30),
        "seed": 7,
        "chunk_size": 1,
        "n_episodes": 30,
    }
    kwargs.update(overrides)
    return Sweep(**kwargs)  # type: ignore[arg-type]


@pytest.fixture(scope="module")
def reference(tmp_path_factory: pytest.TempPathFactory) -> pd.DataFrame:
    """An uninterrupted in-process run of the sweep the CLI of toy_domain runs."""
    path = tmp_path_factory.mktemp("reference")
    make_sweep(path).run(workers=0, progress=False)
    return load_frame(path)


def chunk_files(path: Path) -> dict[str, tuple[int, int]]:
    """Finished chunk files -> (inode, mtime_ns)."""
    return {
        str(f.relative_to(path)): (f.stat().st_ino, f.stat().st_mtime_ns)
        for f in sorted((path / "chunks").glob("*/*.parquet"))
    }


# -- planning -------------------------------------------------------------------------------


def test_plan_chunks_never_mixes_methods_and_respects_size() -> None:
    methods = [MethodSpec("HRS", ["a", "b", "c"], 3), MethodSpec("SARSA", ["none"], 5)]
    chunks = plan_chunks(methods, seed=0, chunk_size=4)
    assert [(c.method, c.index, c.n_learners) for c in chunks] == [
        ("HRS", 0, 4),
        ("HRS", 1, 4),
        ("HRS", 2, 1),
        ("SARSA", 0, 4),
        ("SARSA", 1, 1),
    ]
    assert chunks[0].learners == (("a", 0), ("a", 1), ("a", 2), ("b", 0))  # may mix patterns
    learners = [(c.method, *lrn) for c in chunks for lrn in c.learners]
    assert len(learners) == len(set(learners)) == 14


def test_chunk_seeds_depend_only_on_seed_method_and_index() -> None:
    hrs, sarsa = MethodSpec("HRS", ["a"], 4), MethodSpec("SARSA", ["none"], 4)
    one = {(c.method, c.index): c.seed for c in plan_chunks([hrs, sarsa], seed=3, chunk_size=2)}
    other = {(c.method, c.index): c.seed for c in plan_chunks([sarsa, hrs], seed=3, chunk_size=2)}
    assert one == other
    assert len(set(one.values())) == len(one)
    moved = {(c.method, c.index): c.seed for c in plan_chunks([hrs, sarsa], seed=4, chunk_size=2)}
    assert set(moved.values()).isdisjoint(one.values())
    assert all(0 <= s < 2**63 for s in one.values())


def test_method_spec_validation_and_selection() -> None:
    with pytest.raises(ValueError, match="HRS/x"):
        MethodSpec("HRS/x", ["a"], 1)
    with pytest.raises(ValueError, match="twice"):
        MethodSpec("HRS", ["a", "a"], 1)
    specs = toy_domain.toy_methods(1)
    assert [m.name for m in select_methods(specs, ["SARSA", "HRS"])] == ["SARSA", "HRS"]
    with pytest.raises(UnknownMethodError, match=r"'HRX'.*HRS"):
        select_methods(specs, ["HRX"])


# -- resume ---------------------------------------------------------------------------------


@pytest.mark.slow
def test_sigkill_then_resume_recomputes_nothing_finished(
    tmp_path: Path, reference: pd.DataFrame, monkeypatch: pytest.MonkeyPatch
) -> None:
    results, log = tmp_path / "results", tmp_path / "log.txt"
    # three chunks finish, the others wait for a gate that never opens: killed at a known point
    env = {
        **os.environ,
        "TOY_LOG": str(log),
        "TOY_TAG": "first",
        "TOY_GATE": str(tmp_path / "never"),
        "TOY_FREE": "HRS/00000,HRS/00001,HRS/00002",
    }
    process = subprocess.Popen(
        [sys.executable, "-m", "tests.experiments.toy_domain", "sweep", str(results), "--workers", "2"],
        cwd=REPO,
        env=env,
    )
    deadline = time.monotonic() + 120
    while not (results / "chunks").exists() or len(chunk_files(results)) < 3:
        assert process.poll() is None, "the sweep ended before it could be killed"
        assert time.monotonic() < deadline, "no chunk was written in time"
        time.sleep(0.05)
    os.kill(process.pid, signal.SIGKILL)
    process.wait()
    before = chunk_files(results)
    assert len(before) == 3
    (results / "chunks" / "HRS" / ".00005.parquet.half.tmp").write_bytes(b"PAR1 half a file")

    monkeypatch.setenv("TOY_TAG", "resume")
    monkeypatch.setenv("TOY_LOG", str(log))
    resumed = make_sweep(results).run(workers=0, progress=False)  # the pool ran above; keep it light

    after = chunk_files(results)
    assert len(after) == 12
    assert {k: after[k] for k in before} == before  # same inode and mtime: not rewritten
    rerun = {line.split()[1] for line in log.read_text().splitlines() if line.startswith("resume")}
    done_before = {k.removeprefix("chunks/").removesuffix(".parquet") for k in before}
    assert rerun.isdisjoint(done_before)
    assert rerun | done_before == {c.name for c in make_sweep(results).chunks}
    assert not list(results.rglob("*.tmp"))
    pd.testing.assert_frame_equal(resumed.to_frame(), reference)


@pytest.mark.slow
def test_ctrl_c_stops_the_workers_and_resume_completes(
    tmp_path: Path, reference: pd.DataFrame, monkeypatch: pytest.MonkeyPatch
) -> None:
    # two chunks finish; the others wait for a gate that only opens after the test, so the
    # sweep cannot end before the interrupt however slow or busy the machine is
    monkeypatch.setenv("TOY_GATE", str(tmp_path / "never"))
    monkeypatch.setenv("TOY_FREE", "HRS/00000,HRS/00001")

    def interrupt_after_two_chunks() -> None:
        while len(chunk_files(tmp_path)) < 2:
            time.sleep(0.05)
        os.kill(os.getpid(), signal.SIGINT)

    threading.Thread(target=interrupt_after_two_chunks, daemon=True).start()
    # Ctrl-C raises KeyboardInterrupt, whatever a test runner (pytest-xdist's workers) set
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(KeyboardInterrupt):
            make_sweep(tmp_path).run(workers=2, progress=False)
    finally:
        signal.signal(signal.SIGINT, previous)
    assert not multiprocessing.active_children()  # the pool's workers were stopped
    before = chunk_files(tmp_path)
    assert len(before) == 2
    monkeypatch.delenv("TOY_GATE")
    resumed = make_sweep(tmp_path).run(workers=0, progress=False)
    assert {k: chunk_files(tmp_path)[k] for k in before} == before
    pd.testing.assert_frame_equal(resumed.to_frame(), reference)


def test_second_run_of_a_finished_sweep_computes_nothing(tmp_path: Path) -> None:
    make_sweep(tmp_path).run(workers=0, progress=False)
    files = chunk_files(tmp_path)
    make_sweep(tmp_path, run_chunk=_must_not_run).run(workers=0, progress=False)
    assert chunk_files(tmp_path) == files


def _must_not_run(chunk: Chunk, config: object, progress: object) -> EpisodeTable:
    raise AssertionError(f"{chunk.name} was recomputed")


def test_failed_chunk_keeps_finished_ones_and_resume_completes(
    tmp_path: Path, reference: pd.DataFrame, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("TOY_FAIL", "HRS/00002")
    with pytest.raises(ChunkFailedError, match="HRS/00002"):
        make_sweep(tmp_path).run(workers=0, progress=False)
    assert len(chunk_files(tmp_path)) == 2  # HRS/00000 and HRS/00001 were saved
    monkeypatch.delenv("TOY_FAIL")
    pd.testing.assert_frame_equal(make_sweep(tmp_path).run(workers=0).to_frame(), reference)


# -- corruption and mismatches --------------------------------------------------------------


def test_corrupt_chunks_are_reported_by_name_and_recomputed(tmp_path: Path, reference: pd.DataFrame) -> None:
    sweep = make_sweep(tmp_path)
    sweep.run(workers=0, progress=False)
    store = ResultsStore(tmp_path)
    truncated, foreign = sweep.chunks[1], sweep.chunks[7]
    data = store.chunk_path(truncated).read_bytes()
    store.chunk_path(truncated).write_bytes(data[: len(data) // 2])
    shutil.copy(store.chunk_path(sweep.chunks[0]), store.chunk_path(foreign))  # wrong identity
    with pytest.warns(CorruptChunkWarning) as caught:
        results = sweep.run(workers=0, progress=False)
    messages = " ".join(str(w.message) for w in caught)
    assert str(store.chunk_path(truncated)) in messages and "unreadable" in messages
    assert str(store.chunk_path(foreign)) in messages and "identity" in messages
    assert store.chunk_path(truncated).with_suffix(".parquet.corrupt").exists()
    pd.testing.assert_frame_equal(results.to_frame(), reference)


def test_different_config_into_same_dir_is_an_error_naming_fields(tmp_path: Path) -> None:
    make_sweep(tmp_path).run(workers=0, progress=False)
    config = toy_domain.toy_config(30)
    config["report"]["window"] = 10
    with pytest.raises(ConfigMismatchError) as info:
        make_sweep(tmp_path, config=config, seed=8).run(workers=0, progress=False)
    message = str(info.value)
    assert str(tmp_path) in message and "config.report.window" in message and "seed" in message
    with pytest.raises(ConfigMismatchError, match="methods"):
        make_sweep(tmp_path, methods=toy_domain.toy_methods(2)).run(workers=0, progress=False)
    # overwrite discards the old experiment and runs the new one
    results = make_sweep(tmp_path, config=config, seed=8, overwrite=True).run(workers=0, progress=False)
    assert results.config["report"]["window"] == 10


def test_results_dir_of_another_domain_is_refused(tmp_path: Path) -> None:
    make_sweep(tmp_path).run(workers=0, progress=False)
    with pytest.raises(DomainMismatchError, match=f"{tmp_path}.*'toy'.*'pinball'"):
        make_sweep(tmp_path, domain="pinball").run(workers=0, progress=False)
    with pytest.raises(DomainMismatchError, match="'toy'"):
        load_frame(tmp_path, domain="four_rooms")


def test_bad_tables_and_unpicklable_functions_are_clear_errors(tmp_path: Path) -> None:
    def wrong_rows(chunk: Chunk, config: object, progress: object) -> EpisodeTable:
        return EpisodeTable(np.ones((2, 30)), np.ones((2, 30)), np.ones((2, 30), bool))

    with pytest.raises(ValueError, match="2 rows for HRS/00000"):
        make_sweep(tmp_path / "a", run_chunk=wrong_rows).run(workers=0, progress=False)
    with pytest.raises(TypeError, match="picklable"):
        make_sweep(tmp_path / "b", run_chunk=wrong_rows).run(workers=2, progress=False)
    with pytest.raises(ValueError, match="backend"):
        make_sweep(tmp_path / "c").run(backend="dask", workers=0)  # type: ignore[arg-type]


def test_another_process_holding_the_dir_is_an_error(tmp_path: Path) -> None:
    store = ResultsStore(tmp_path)
    with store.lock(), pytest.raises(ResultsError, match="another process"):
        make_sweep(tmp_path).run(workers=0, progress=False)


# -- Ray --------------------------------------------------------------------------------------


@pytest.mark.slow
@pytest.mark.xdist_group("ray")  # one Ray instance at a time under pytest-xdist
def test_ray_backend_matches_local(tmp_path: Path) -> None:
    ray = pytest.importorskip("ray")
    ray.init(address="local", num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        results = make_sweep(tmp_path, chunk_size=4).run(backend="ray", progress=True)
    finally:
        ray.shutdown()
    local = make_sweep(tmp_path / "local", chunk_size=4).run(workers=0, progress=False)
    pd.testing.assert_frame_equal(results.to_frame(), local.to_frame())
    assert len(chunk_files(tmp_path)) == 4


# -- what a sweep may touch ------------------------------------------------------------------


def test_a_directory_that_is_not_ours_is_refused_before_anything_is_written(tmp_path: Path) -> None:
    (tmp_path / "notes.txt").write_text("mine\n")
    with pytest.raises(ResultsError, match=r"is not empty \(notes\.txt\) and is not a results directory"):
        make_sweep(tmp_path, overwrite=True).run(workers=0, progress=False)
    assert [p.name for p in tmp_path.iterdir()] == ["notes.txt"]


def test_overwrite_removes_only_files_the_store_can_identify(tmp_path: Path) -> None:
    make_sweep(tmp_path).run(workers=0, progress=False)
    mine = [
        tmp_path / "chunks" / "HRS" / "keep.txt",
        tmp_path / "chunks" / "other" / "data.csv",
        tmp_path / "chunks" / "HRS" / "00000.parquet.bak",
        tmp_path / "notes.md",
    ]
    for path in mine:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text("mine\n")
    removed = ResultsStore(tmp_path).clear()
    assert len(removed) == 1 + 12 and all(p.exists() for p in mine)
    assert not (tmp_path / "chunks" / "SARSA").exists()  # emptied, so removed


def test_an_experiment_without_finished_chunks_is_replaced_without_overwrite(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("TOY_FAIL", "HRS/00000")
    with pytest.raises(ChunkFailedError, match=r"toy failure in HRS/00000\. No chunk was finished; fix the cause"):
        make_sweep(tmp_path).run(workers=0, progress=False)
    monkeypatch.delenv("TOY_FAIL")
    results = make_sweep(tmp_path, seed=8).run(workers=0, progress=False)  # a different experiment
    assert results.manifest["seed"] == 8


def test_a_warm_up_runs_once_before_pending_chunks_and_says_so(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """What compiles the kernels runs before the first chunk, between two lines on stderr; not at all when
    nothing is left to run; and a warm-up that fails leaves the chunks to run (and fail) on their own."""
    calls: list[int] = []
    make_sweep(tmp_path / "a", warm_up=lambda: calls.append(1)).run(workers=0, progress=False)
    err = capsys.readouterr().err
    assert calls == [1] and "compiling the engine's numba kernels" in err and "engine ready in" in err
    make_sweep(tmp_path / "a", warm_up=lambda: calls.append(1)).run(workers=0, progress=False)
    assert calls == [1] and "compiling" not in capsys.readouterr().err  # all chunks done: no warm-up

    def broken() -> None:
        raise RuntimeError("no compiler here")

    make_sweep(tmp_path / "b", warm_up=broken).run(workers=0, progress=False)
    assert "engine ready" not in capsys.readouterr().err and load_frame(tmp_path / "b").shape[0] > 0


def test_runtime_settings_reach_the_chunks_but_not_the_experiment(tmp_path: Path) -> None:
    """``runtime`` (a recipe's logger) is handed to ``run_chunk`` with the config and recorded, but a resumed
    sweep may change it; ``provenance`` is recorded when the sweep starts."""
    import json

    sweep = make_sweep(tmp_path, runtime={"logger": "csv"}, provenance={"command": "x --flag"})
    sweep.run(workers=0, progress=False)
    manifest = json.loads((tmp_path / "config.json").read_text())
    assert manifest["runtime"] == {"logger": "csv"} and manifest["provenance"] == {"command": "x --flag"}
    make_sweep(tmp_path, runtime={"logger": "tensorboard"}).run(workers=0, progress=False)  # no mismatch
