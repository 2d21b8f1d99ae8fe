"""The results store: atomic chunk files, validation, loading, config.json."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from tests.experiments import toy_domain
from torchrl_subgoal.experiments import (
    Chunk,
    CorruptChunkError,
    DomainMismatchError,
    EpisodeTable,
    IncompleteResultsError,
    Sweep,
    UnknownMethodError,
    load_results,
)
from torchrl_subgoal.experiments.results import ResultsError
from torchrl_subgoal.experiments.store import ResultsStore, diff_fields

CHUNK = Chunk("HRS", 3, (("p1", 4), ("p2", 0)), seed=11)


def table(n_learners: int = 2, n_episodes: int = 4, offset: int = 0) -> EpisodeTable:
    steps = np.arange(n_learners * n_episodes).reshape(n_learners, n_episodes) + offset
    return EpisodeTable(steps, steps * 0.5, steps % 2 == 0)


def test_chunk_round_trip_keeps_identity_and_values(tmp_path: Path) -> None:
    store = ResultsStore(tmp_path)
    path = store.write_chunk(CHUNK, table())
    assert path == tmp_path / "chunks" / "HRS" / "00003.parquet"
    assert not list(path.parent.glob(".*"))  # no temporary file left
    loaded = store.read_chunk(CHUNK)
    np.testing.assert_array_equal(loaded.steps, table().steps)
    np.testing.assert_array_equal(loaded.returns, table().returns)
    np.testing.assert_array_equal(loaded.success, table().success)
    identity = json.loads(pq.read_schema(path).metadata[b"torchrl_subgoal.chunk"])
    assert identity["rows"] == 8 and identity["method"] == "HRS" and identity["index"] == 3
    assert Chunk.from_json(identity) == CHUNK
    frame = pq.read_table(path).to_pandas()  # self-describing for any Parquet reader
    assert frame["pattern"].astype(str).tolist() == ["p1"] * 4 + ["p2"] * 4
    assert frame["learning"].tolist() == [4] * 4 + [0] * 4
    assert frame["episode"].tolist() == [1, 2, 3, 4] * 2


def test_chunk_json_run_length_encodes_learners() -> None:
    chunk = Chunk("X", 0, (("a", 0), ("a", 1), ("a", 2), ("b", 0), ("a", 7)), seed=1)
    assert chunk.to_json()["learners"] == [["a", 0, 3], ["b", 0, 1], ["a", 7, 8]]
    assert Chunk.from_json(chunk.to_json()) == chunk


@pytest.mark.parametrize(
    ("damage", "reason"),
    [
        (lambda p: p.write_bytes(p.read_bytes()[:-20]), "unreadable"),
        (lambda p: p.write_bytes(b""), "unreadable"),
        (lambda p: pq.write_table(pq.read_table(p).slice(0, 6), p), "rows"),
        (lambda p: pq.write_table(pq.read_table(p).replace_schema_metadata({}), p), "no chunk identity"),
    ],
    ids=["truncated", "empty", "wrong-row-count", "no-identity"],
)
def test_damaged_chunk_files_are_detected(tmp_path: Path, damage: Callable[[Path], object], reason: str) -> None:
    store = ResultsStore(tmp_path)
    path = store.write_chunk(CHUNK, table())
    damage(path)
    status = store.check_chunk(CHUNK)
    assert status.state == "corrupt" and reason in status.reason
    with pytest.raises(CorruptChunkError, match=str(path)):
        store.read_chunk(CHUNK)


def test_chunk_of_another_identity_is_corrupt(tmp_path: Path) -> None:
    store = ResultsStore(tmp_path)
    other = Chunk("HRS", 3, (("p1", 4), ("p2", 1)), seed=11)
    store.write_chunk(other, table())
    status = store.check_chunk(CHUNK)
    assert status.state == "corrupt" and "learners" in status.reason
    assert store.check_chunk(Chunk("HRS", 9, (), 0)).state == "missing"


def test_bit_flip_in_data_is_caught_by_page_checksums(tmp_path: Path) -> None:
    store = ResultsStore(tmp_path)
    rng = np.random.default_rng(0)
    noisy = EpisodeTable(rng.integers(0, 1000, (2, 500)), rng.normal(size=(2, 500)), rng.random((2, 500)) < 0.5)
    path = store.write_chunk(CHUNK, noisy)
    data = bytearray(path.read_bytes())
    data[len(data) // 3] ^= 0xFF  # inside a data page, away from header and footer
    path.write_bytes(bytes(data))
    assert store.check_chunk(CHUNK).state == "corrupt"


def test_temp_files_are_cleaned_and_never_loaded(tmp_path: Path) -> None:
    store = ResultsStore(tmp_path)
    store.write_chunk(CHUNK, table())
    leftover = tmp_path / "chunks" / "HRS" / ".00004.parquet.x1.tmp"
    leftover.write_bytes(b"half")
    (tmp_path / ".config.json.x2.tmp").write_text("{")
    removed = store.clean_temp_files()
    assert sorted(p.name for p in removed) == [".00004.parquet.x1.tmp", ".config.json.x2.tmp"]
    assert store.chunk_path(CHUNK).exists()


def test_episode_table_validates_shapes() -> None:
    with pytest.raises(ValueError, match="2-D"):
        EpisodeTable(np.ones(3), np.ones(3), np.ones(3, bool))
    with pytest.raises(ValueError, match="returns has shape"):
        EpisodeTable(np.ones((2, 3)), np.ones((2, 4)), np.ones((2, 3), bool))
    with pytest.raises(ValueError, match="whole numbers"):
        EpisodeTable(np.full((1, 2), 1.5), np.ones((1, 2)), np.ones((1, 2), bool))
    with pytest.raises(ValueError, match="unknown metric"):
        table().metric("reward")
    assert table().metric("success").dtype == np.float64


def test_diff_fields_names_nested_paths() -> None:
    stored = {"config": {"lr": 0.1, "report": {"window": 1}}, "seed": 0, "methods": [1, 2]}
    requested = {"config": {"lr": 0.2, "report": {"window": 1}, "new": 1}, "seed": 0, "methods": [1, 3]}
    assert diff_fields(stored, requested) == ["config.lr", "config.new", "methods[1]"]


@pytest.fixture
def results_dir(tmp_path: Path) -> Path:
    Sweep(
        toy_domain.DOMAIN,
        tmp_path,
        toy_domain.toy_methods(2),
        toy_domain.run_chunk,
        toy_domain.toy_config(6),
        seed=1,
        chunk_size=3,
    ).run(workers=0, progress=False)
    return tmp_path


def test_load_results_and_frame(results_dir: Path) -> None:
    results = load_results(results_dir, domain="toy")
    assert list(results.methods) == ["HRS", "SARSA"]
    hrs = results.methods["HRS"]
    assert hrs.patterns.tolist() == ["p1", "p1", "p2", "p2"] and hrs.learnings.tolist() == [0, 1, 0, 1]
    frame = results.to_frame()
    assert list(frame.columns) == ["method", "pattern", "learning", "episode", "steps", "return", "success"]
    assert len(frame) == (4 + 4) * 6
    row = frame[(frame.method == "HRS") & (frame.pattern == "p2") & (frame.learning == 1) & (frame.episode == 6)]
    assert row["steps"].item() == hrs.table.steps[3, 5]
    assert frame.groupby("method", observed=True).size().tolist() == [24, 24]
    manifest = json.loads((results_dir / "config.json").read_text())
    assert manifest["domain"] == "toy" and manifest["seed"] == 1 and manifest["chunk_size"] == 3
    assert {"python", "torch", "torchrl", "numpy", "torchrl_subgoal"} <= set(manifest["versions"])
    assert len(manifest["chunks"]) == 4


def test_load_results_errors_name_what_is_wrong(results_dir: Path) -> None:
    with pytest.raises(UnknownMethodError, match=r"'HRX'.*'HRS', 'SARSA'"):
        load_results(results_dir, methods=["HRX"])
    with pytest.raises(DomainMismatchError, match=f"{results_dir}.*'toy'.*'pinball'"):
        load_results(results_dir, domain="pinball")
    with pytest.raises(ResultsError, match=r"config\.json not found"):
        load_results(results_dir / "chunks")
    store = ResultsStore(results_dir)
    chunk = Chunk.from_json(json.loads((results_dir / "config.json").read_text())["chunks"][1])
    store.chunk_path(chunk).unlink()
    with pytest.raises(IncompleteResultsError, match="1 chunk"):
        load_results(results_dir)
    partial = load_results(results_dir, allow_incomplete=True)
    assert partial.missing == ("HRS/00001",) and partial.methods["HRS"].table.n_learners == 3
    store.chunk_path(Chunk.from_json(json.loads((results_dir / "config.json").read_text())["chunks"][0])).write_bytes(
        b"x"
    )
    with pytest.raises(CorruptChunkError, match=r"00000\.parquet"):
        load_results(results_dir, allow_incomplete=True)
