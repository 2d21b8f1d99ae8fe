"""Bad inputs to the recipes and the report, as a new user makes them: each is one line
on stderr naming the problem (and the fix), exit code 2, and nothing of the user's is lost.

docs/reliability.md lists the same cases; keep the two in step.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests.recipes.test_recipes import ROOT, recipe
from torchrl_subgoal.experiments.report import main as report_main
from torchrl_subgoal.experiments.store import ResultsStore

QUICK = ["--episodes", "2", "--learnings", "1", "--workers", "0"]


def run(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    """The four-rooms recipe's exit code and its stderr (which must be one line on failure)."""
    code = recipe("four_rooms").main(args)
    err = capsys.readouterr().err
    if code != 0:
        lines = [line for line in err.splitlines() if line.strip()]
        assert len(lines) == 1 and lines[0].startswith("error: "), err
    return code, err


@pytest.fixture(scope="module")
def finished(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A results directory of a finished quick sweep (SARSA only)."""
    path = tmp_path_factory.mktemp("finished") / "res"
    assert recipe("four_rooms").main([*QUICK, "--methods", "SARSA", "--results", str(path)]) == 0
    return path


def copy_of(finished: Path, tmp_path: Path) -> Path:
    target = tmp_path / "res"
    shutil.copytree(finished, target)
    return target


# -- the results directory --------------------------------------------------------------------


def test_a_directory_that_is_not_a_results_directory_is_refused_and_left_alone(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The issue's example: data.csv under chunks/ and a report.md of the user's own."""
    res = tmp_path / "u"
    (res / "chunks" / "mine").mkdir(parents=True)
    (res / "chunks" / "mine" / "data.csv").write_text("x\n")
    (res / "report.md").write_text("my notes\n")
    code, err = run([*QUICK, "--methods", "HRS", "--results", str(res)], capsys)
    assert code == 2 and "is not empty" in err and "not a results directory" in err
    assert (res / "chunks" / "mine" / "data.csv").read_text() == "x\n"
    assert (res / "report.md").read_text() == "my notes\n"
    assert sorted(p.name for p in res.iterdir()) == ["chunks", "report.md"]  # not even a lock file


def test_overwrite_removes_only_the_sweeps_own_files(finished: Path, tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    res = copy_of(finished, tmp_path)
    (res / "chunks" / "SARSA" / "notes.txt").write_text("mine\n")
    (res / "chunks" / "mine").mkdir()
    (res / "chunks" / "mine" / "data.csv").write_text("x\n")
    code, _ = run([*QUICK, "--methods", "HRS", "--overwrite", "--results", str(res)], capsys)
    assert code == 0
    assert (res / "chunks" / "SARSA" / "notes.txt").read_text() == "mine\n"
    assert (res / "chunks" / "mine" / "data.csv").read_text() == "x\n"
    assert not list((res / "chunks" / "SARSA").glob("*.parquet"))
    assert list((res / "chunks" / "HRS").glob("*.parquet"))


@pytest.mark.parametrize("kind", ["file", "under a file"])
def test_results_path_that_is_a_file(tmp_path: Path, capsys: pytest.CaptureFixture[str], kind: str) -> None:
    (tmp_path / "f").write_text("keep me\n")
    path = tmp_path / "f" if kind == "file" else tmp_path / "f" / "sub"
    code, err = run([*QUICK, "--results", str(path)], capsys)
    assert code == 2 and str(tmp_path / "f") in err
    assert (tmp_path / "f").read_text() == "keep me\n"


def test_results_path_that_is_not_writable(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                           monkeypatch: pytest.MonkeyPatch) -> None:
    parent = tmp_path / "ro"
    parent.mkdir()
    if os.geteuid() == 0:  # root writes anywhere: make the directory creation fail as it would
        real_mkdir = Path.mkdir

        def denied(self: Path, *args: object, **kwargs: object) -> None:
            if self.parent == parent:
                raise PermissionError(13, "Permission denied", str(self))
            real_mkdir(self, *args, **kwargs)  # type: ignore[arg-type]

        monkeypatch.setattr(Path, "mkdir", denied)
    else:
        parent.chmod(0o500)
    code, err = run([*QUICK, "--results", str(parent / "res")], capsys)
    assert code == 2 and "cannot write the results directory" in err and "Permission denied" in err


def test_a_concurrent_run_is_refused(finished: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    res = copy_of(finished, tmp_path)
    with ResultsStore(res).lock():
        code, err = run([*QUICK, "--methods", "SARSA", "--results", str(res)], capsys)
    assert code == 2 and "another process is running a sweep" in err


def test_a_different_experiment_names_the_fields_and_the_fix(
    finished: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    res = copy_of(finished, tmp_path)
    before = {p: p.stat().st_mtime_ns for p in res.rglob("*.parquet")}
    code, err = run(["--episodes", "3", "--learnings", "1", "--workers", "0", "--methods", "SARSA",
                     "--results", str(res)], capsys)
    assert code == 2 and "differing fields" in err and "config.episodes" in err and "overwrite" in err
    assert {p: p.stat().st_mtime_ns for p in res.rglob("*.parquet")} == before


@pytest.mark.parametrize(("content", "message"), [
    ("{not json", "is not valid JSON"),
    ('{"format": 1, "domain": "four_rooms"}', "field 'methods' is missing or malformed"),
    ('{"format": 99}', "is not a torchrl_subgoal results file"),
    (b"\xff\xfe\x00binary", "cannot read"),
])
def test_a_corrupt_config_json(finished: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
                               content: str | bytes, message: str) -> None:
    res = copy_of(finished, tmp_path)
    if isinstance(content, bytes):
        (res / "config.json").write_bytes(content)
    else:
        (res / "config.json").write_text(content)
    code, err = run([*QUICK, "--methods", "SARSA", "--results", str(res)], capsys)
    assert code == 2 and message in err and "config.json" in err
    assert list(res.rglob("*.parquet"))  # the chunks are still there


# -- settings -----------------------------------------------------------------------------------


@pytest.mark.parametrize(("flags", "message"), [
    (["--episodes", "0"], "--episodes: must be >= 1"),
    (["--episodes", "many"], "--episodes: invalid int value: 'many'"),
    (["--eta", "inf"], "--eta: must be a finite number, got inf"),
    (["--eta", "nan"], "--eta: must be a finite number, got nan"),
    (["--seed", "-1"], "--seed: must be >= 0, got -1"),
    (["--methods", ","], "--methods: give at least one method"),
    (["--methods", "HRS,XYZ"], "--methods: unknown method(s) ['XYZ']"),
    (["--workers", "-1"], "--workers: must be >= 0"),
    (["--chunk-size", "0"], "--chunk-size: must be >= 1"),
    (["--backend", "slurm"], "--backend: invalid choice: 'slurm'"),
])
def test_bad_flag_values(tmp_path: Path, capsys: pytest.CaptureFixture[str], flags: list[str],
                         message: str) -> None:
    code, err = (
        run([*flags, "--results", str(tmp_path / "r")], capsys)
        if "invalid" not in message else _argparse_exit(flags, tmp_path, capsys)
    )
    assert code == 2 and message in err
    assert not (tmp_path / "r").exists()


def _argparse_exit(flags: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    with pytest.raises(SystemExit) as info:
        recipe("four_rooms").main([*flags, "--results", str(tmp_path / "r")])
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1, err
    return int(info.value.code or 0), err


# -- subgoal files --------------------------------------------------------------------------------


SUBGOAL_FILES: list[tuple[str, bytes, str]] = [
    ("binary.yaml", b"\x89PNG\r\n\x1a\n\x00\x00", "not a text file (byte 0x89 at offset 0 is not UTF-8)"),
    ("dup.yaml", b"patterns:\n  p: {subgoals: [{cell: [3, 6]}]}\n  p: {subgoals: [{cell: [7, 9]}]}\n",
     "patterns: duplicate pattern name 'p' (line 3)"),
    ("dup.json", b'{"patterns": {"p": {"subgoals": [{"cell": [3, 6]}]}, "p": {"subgoals": []}}}',
     "patterns: duplicate pattern name 'p'"),
    ("dupsg.yaml", b"patterns:\n  p:\n    subgoals: {a: {cell: [3, 6]}, a: {cell: [7, 9]}}\n    order: []\n",
     "pattern 'p': subgoals: duplicate subgoal name 'a' (line 3)"),
    ("state.yaml", b"patterns:\n  p: {subgoals: [{state: 5}]}\n",
     "pattern 'p': subgoals[0].state: a state predicate reads a scalar state index or a one-hot state but "
     "the observation 'cell' has 2 entries"),
    ("alias.yaml", b"x: &a {cell: [3, 6]}\npatterns:\n  p: {subgoals: [*a]}\n", "used again through a YAML alias"),
    ("huge.yaml", b"#" * (2 << 20), "larger than 1048576 bytes"),
]


@pytest.mark.parametrize(("name", "content", "message"), SUBGOAL_FILES, ids=[f[0] for f in SUBGOAL_FILES])
def test_bad_subgoal_files(tmp_path: Path, capsys: pytest.CaptureFixture[str], name: str, content: bytes,
                           message: str) -> None:
    path = tmp_path / name
    path.write_bytes(content)
    code, err = run([*QUICK, "--subgoals", str(path), "--results", str(tmp_path / "r")], capsys)
    assert code == 2 and f"error: {path}: " in err and message in err
    assert not (tmp_path / "r").exists()  # refused before anything was written


# -- a failing chunk ---------------------------------------------------------------------------------


def error_line(capsys: pytest.CaptureFixture[str]) -> str:
    """The one error line after a sweep's progress bar."""
    errors = [line for line in capsys.readouterr().err.splitlines() if line.startswith("error:")]
    assert len(errors) == 1, errors
    return errors[0]


def test_a_failing_chunk_names_the_subgoal_file_and_gives_the_right_advice(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    four_rooms = recipe("four_rooms")
    real = four_rooms.run_chunk

    def broken(chunk, config, progress):  # type: ignore[no-untyped-def]
        if chunk.method == "HRS":  # as if a pattern of the file broke the chunk
            from torchrl_subgoal.experiments.recipe import chunk_patterns
            from torchrl_subgoal.subgoals import SubgoalTables

            series, _ = chunk_patterns(chunk, config)
            SubgoalTables(series, __import__("torch").zeros(1, dtype=__import__("torch").long), 1)
        return real(chunk, config, progress)

    monkeypatch.setattr(four_rooms, "run_chunk", broken)
    res = tmp_path / "res"
    code = four_rooms.main([*QUICK, "--methods", "SARSA,HRS", "--results", str(res)])
    err = error_line(capsys)
    assert code == 1
    assert "chunk HRS/00000 failed" in err and "four_rooms_participants.yaml: pattern 'participant_1'" in err
    assert "1 finished chunk(s) are saved" in err and "run the same command again" in err
    monkeypatch.setattr(four_rooms, "run_chunk", real)
    assert four_rooms.main([*QUICK, "--methods", "SARSA,HRS", "--results", str(res)]) == 0  # as advised


def test_a_failing_first_chunk_needs_no_overwrite_after_the_fix(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    four_rooms = recipe("four_rooms")
    real = four_rooms.run_chunk

    def broken(chunk, config, progress):  # type: ignore[no-untyped-def]
        raise RuntimeError("something in the env\nover two lines")

    monkeypatch.setattr(four_rooms, "run_chunk", broken)
    res = tmp_path / "res"
    assert four_rooms.main([*QUICK, "--methods", "HRS", "--results", str(res)]) == 1
    err = error_line(capsys)
    assert "something in the env over two lines" in err and "No chunk was finished" in err
    monkeypatch.setattr(four_rooms, "run_chunk", real)
    # the fix changed a setting: nothing was finished, so no --overwrite is needed
    assert four_rooms.main([*QUICK, "--methods", "HRS", "--eta", "2", "--results", str(res)]) == 0


# -- the report --------------------------------------------------------------------------------------


@pytest.mark.parametrize(("flags", "message"), [
    (["--n-boot", "0"], "--n-boot: must lie in [1, 100000], got 0"),
    (["--n-boot", "-5"], "--n-boot: must lie in [1, 100000], got -5"),
    (["--n-boot", "lots"], "invalid int value: 'lots'"),
    (["--seed", "-1"], "--seed: must be >= 0"),
])
def test_report_bad_flags(finished: Path, capsys: pytest.CaptureFixture[str], flags: list[str],
                          message: str) -> None:
    with pytest.raises(SystemExit) as info:
        report_main([str(finished), *flags])
    err = capsys.readouterr().err.strip()
    assert info.value.code == 2 and len(err.splitlines()) == 1 and message in err


def test_report_never_overwrites_files_it_did_not_write(finished: Path, tmp_path: Path,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "paper"
    out.mkdir()
    (out / "summary.json").write_text('{"mine": 1}\n')
    assert report_main([str(finished), "--out", str(out), "--n-boot", "10"]) == 2
    err = capsys.readouterr().err.strip()
    assert "summary.json exists and was not written by a report" in err
    assert json.loads((out / "summary.json").read_text()) == {"mine": 1}
    fresh = tmp_path / "fresh"
    assert report_main([str(finished), "--out", str(fresh), "--n-boot", "10"]) == 0
    assert report_main([str(finished), "--out", str(fresh), "--n-boot", "10"]) == 0  # its own: replaced


@pytest.mark.parametrize(("target", "message"), [
    ("missing", "holds no results"),
    ("a file", "is a file"),
])
def test_report_bad_results_dir(tmp_path: Path, capsys: pytest.CaptureFixture[str], target: str,
                                message: str) -> None:
    path = tmp_path / "x"
    if target == "a file":
        path.write_text("x")
    assert report_main([str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err


def test_the_command_line_prints_no_traceback(tmp_path: Path) -> None:
    """The recipe as a user runs it: one line, exit 2."""
    (tmp_path / "f").write_text("x")
    done = subprocess.run([sys.executable, str(ROOT / "recipes" / "four_rooms.py"), "--results",
                           str(tmp_path / "f")], capture_output=True, text=True, timeout=300)
    assert done.returncode == 2 and done.stderr.strip().splitlines() == [
        f"error: {tmp_path / 'f'} is a file, not a results directory; choose a directory"
    ]
