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


def test_overwrite_removes_only_the_sweeps_own_files(
    finished: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
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


def test_results_path_that_is_not_writable(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
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
    code, err = run(
        ["--episodes", "3", "--learnings", "1", "--workers", "0", "--methods", "SARSA", "--results", str(res)], capsys
    )
    assert code == 2 and "differing fields" in err and "config.episodes" in err and "overwrite" in err
    assert {p: p.stat().st_mtime_ns for p in res.rglob("*.parquet")} == before


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("{not json", "is not valid JSON"),
        ('{"format": 1, "domain": "four_rooms"}', "field 'methods' is missing or malformed"),
        ('{"format": 99}', "is not a torchrl_subgoal results file"),
        (b"\xff\xfe\x00binary", "cannot read"),
    ],
)
def test_a_corrupt_config_json(
    finished: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], content: str | bytes, message: str
) -> None:
    res = copy_of(finished, tmp_path)
    if isinstance(content, bytes):
        (res / "config.json").write_bytes(content)
    else:
        (res / "config.json").write_text(content)
    code, err = run([*QUICK, "--methods", "SARSA", "--results", str(res)], capsys)
    assert code == 2 and message in err and "config.json" in err
    assert list(res.rglob("*.parquet"))  # the chunks are still there


# -- settings -----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("flags", "message"),
    [
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
    ],
)
def test_bad_flag_values(tmp_path: Path, capsys: pytest.CaptureFixture[str], flags: list[str], message: str) -> None:
    code, err = (
        run([*flags, "--results", str(tmp_path / "r")], capsys)
        if "invalid" not in message
        else _argparse_exit(flags, tmp_path, capsys)
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
    (
        "dup.yaml",
        b"patterns:\n  p: {subgoals: [{cell: [3, 6]}]}\n  p: {subgoals: [{cell: [7, 9]}]}\n",
        "patterns: duplicate pattern name 'p' (line 3)",
    ),
    (
        "dup.json",
        b'{"patterns": {"p": {"subgoals": [{"cell": [3, 6]}]}, "p": {"subgoals": []}}}',
        "patterns: duplicate pattern name 'p'",
    ),
    (
        "dupsg.yaml",
        b"patterns:\n  p:\n    subgoals: {a: {cell: [3, 6]}, a: {cell: [7, 9]}}\n    order: []\n",
        "pattern 'p': subgoals: duplicate subgoal name 'a' (line 3)",
    ),
    (
        "state.yaml",
        b"patterns:\n  p: {subgoals: [{state: 5}]}\n",
        "pattern 'p': subgoals[0].state: a state predicate reads a scalar state index or a one-hot state but "
        "the observation 'cell' has 2 entries",
    ),
    ("alias.yaml", b"x: &a {cell: [3, 6]}\npatterns:\n  p: {subgoals: [*a]}\n", "used again through a YAML alias"),
    ("huge.yaml", b"#" * (2 << 20), "larger than 1048576 bytes"),
]


@pytest.mark.parametrize(("name", "content", "message"), SUBGOAL_FILES, ids=[f[0] for f in SUBGOAL_FILES])
def test_bad_subgoal_files(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], name: str, content: bytes, message: str
) -> None:
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


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        (["--n-boot", "0"], "--n-boot: must lie in [1, 100000], got 0"),
        (["--n-boot", "-5"], "--n-boot: must lie in [1, 100000], got -5"),
        (["--n-boot", "lots"], "invalid int value: 'lots'"),
        (["--seed", "-1"], "--seed: must be >= 0"),
    ],
)
def test_report_bad_flags(finished: Path, capsys: pytest.CaptureFixture[str], flags: list[str], message: str) -> None:
    with pytest.raises(SystemExit) as info:
        report_main([str(finished), *flags])
    err = capsys.readouterr().err.strip()
    assert info.value.code == 2 and len(err.splitlines()) == 1 and message in err


def test_report_never_overwrites_files_it_did_not_write(
    finished: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
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


@pytest.mark.parametrize(
    ("target", "message"),
    [
        ("missing", "holds no results"),
        ("a file", "is a file"),
    ],
)
def test_report_bad_results_dir(tmp_path: Path, capsys: pytest.CaptureFixture[str], target: str, message: str) -> None:
    path = tmp_path / "x"
    if target == "a file":
        path.write_text("x")
    assert report_main([str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err


def test_the_command_line_prints_no_traceback(tmp_path: Path) -> None:
    """The recipe as a user runs it: one line, exit 2."""
    (tmp_path / "f").write_text("x")
    done = subprocess.run(
        [sys.executable, str(ROOT / "recipes" / "four_rooms.py"), "--results", str(tmp_path / "f")],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 2 and done.stderr.strip().splitlines() == [
        f"error: {tmp_path / 'f'} is a file, not a results directory; choose a directory"
    ]


# -- the whole configuration, checked before the first chunk ----------------------------------------


def one_error_line(code: int, capsys: pytest.CaptureFixture[str]) -> str:
    """The one line on stderr of a recipe that refused its settings (exit 2); the notice gymnasium_robotics
    prints when the pick-and-place recipe first imports it is not the recipe's."""
    lines = [
        line for line in capsys.readouterr().err.splitlines() if line.strip() and "gymnasium-robotics==" not in line
    ]
    assert code == 2 and len(lines) == 1 and lines[0].startswith("error: "), (code, lines)
    return lines[0]


PICK_AND_PLACE = ["--preset", "tiny", "--learnings", "1", "--workers", "0", "--collector-workers", "0"]
A_METHOD_TWICE = [
    ("four_rooms", [*QUICK, "--methods", "HRS,SARSA,HRS"], "HRS"),
    ("pinball", ["--episodes", "2", "--learnings", "1", "--workers", "0", "--methods", "AC,AC"], "AC"),
    ("a2c", ["--total-frames", "256", "--workers", "0", "--methods", "HRS,HRS,A2C,A2C"], "HRS and A2C"),
    ("train", ["--algo", "dqn", "--total-frames", "256", "--workers", "0", "--methods", "DQN,NRS,DQN"], "DQN"),
    ("pick_and_place", [*PICK_AND_PLACE, "--methods", "DDPG,DDPG"], "DDPG"),
]


@pytest.mark.parametrize(("name", "flags", "twice"), A_METHOD_TWICE, ids=[m[0] for m in A_METHOD_TWICE])
def test_a_method_named_twice_is_one_line_in_every_recipe(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], name: str, flags: list[str], twice: str
) -> None:
    code = recipe(name).main([*flags, "--results", str(tmp_path / "r")])
    line = one_error_line(code, capsys)
    verb = "are" if " and " in twice else "is"
    assert line == f"error: --methods: {twice} {verb} named twice; name each method once"
    assert not (tmp_path / "r").exists()


SHAPING = [
    ('{"foo": 1}', "--shaping: unknown option 'foo'; SubgoalPotentialTransform takes observation_key"),
    ('{"zero_terminal_potential": "no"}', "--shaping: 'zero_terminal_potential' takes true or false, got \"no\""),
    ('{"start_potential": 1}', "--shaping: 'start_potential' takes a string, got 1"),
    ('{"start_potential": "high"}', "--shaping: HRS: start_potential must be one of"),
    ('{"gamma": 0.5}', "--shaping: 'gamma' is set by the recipe for every learner; leave it out"),
    ('{"backend": "fast"}', "--shaping: HRS: backend must be 'auto', 'compiled' or 'torch', got 'fast'"),
]


@pytest.mark.parametrize(("options", "message"), SHAPING, ids=[s[0] for s in SHAPING])
def test_pick_and_place_shaping_options_are_checked_before_anything_runs(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], options: str, message: str
) -> None:
    code = recipe("pick_and_place").main(
        [*PICK_AND_PLACE, "--methods", "HRS", "--shaping", options, "--results", str(tmp_path / "r")]
    )
    assert message in one_error_line(code, capsys)
    assert not (tmp_path / "r").exists()  # refused before the sweep wrote anything


def test_pick_and_place_shaping_options_that_fit_are_taken(tmp_path: Path) -> None:
    pick_and_place = recipe("pick_and_place")
    from torchrl_subgoal.experiments.cli import parse_config

    cfg = parse_config(
        pick_and_place.Config,
        [
            *PICK_AND_PLACE,
            "--methods",
            "HRS,NRS,SARSA-RS",
            "--shaping",
            '{"zero_terminal_potential": false, "backend": "torch"}',
            "--results",
            str(tmp_path / "r"),
        ],
    )
    assert pick_and_place.plan(cfg).config["shaping"] == {"zero_terminal_potential": False, "backend": "torch"}


@pytest.mark.parametrize("device", ["gpu0", "cuda:{unavailable}"])
def test_pick_and_place_device_is_checked_before_anything_runs(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], device: str
) -> None:
    import torch

    device = device.format(unavailable=torch.cuda.device_count() + 7)  # the cuda:7, on any machine
    code = recipe("pick_and_place").main(
        [*PICK_AND_PLACE, "--methods", "DDPG", "--device", device, "--results", str(tmp_path / "r")]
    )
    line = one_error_line(code, capsys)
    assert line.startswith(f"error: --device: {device}" if ":" in device else "error: --device: 'gpu0'")
    assert ("is not available on this machine" in line) == (":" in device)
    assert not (tmp_path / "r").exists()


def long_pattern_file(tmp_path: Path, length: int = 1000) -> Path:
    """A four-rooms file of one pattern of ``length`` subgoals (the loader's limit), longer than RRS can draw."""
    from torchrl_subgoal.envs.four_rooms import GOAL, START, free_cells

    cells = [list(c) for c in free_cells() if c not in (START, GOAL)]
    path = tmp_path / "long.json"
    path.write_text(
        json.dumps(
            {
                "domain": "four_rooms",
                "patterns": {"long": {"subgoals": [{"cell": cells[i % len(cells)]} for i in range(length)]}},
            }
        )
    )
    return path


def test_a_limit_of_random_patterns_applies_only_when_rrs_runs(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = long_pattern_file(tmp_path)
    hrs = ["--subgoals", str(path), "--episodes", "2", "--learnings", "1", "--workers", "0"]
    assert recipe("four_rooms").main([*hrs, "--methods", "HRS,SARSA", "--results", str(tmp_path / "hrs")]) == 0
    capsys.readouterr()
    config = json.loads((tmp_path / "hrs" / "config.json").read_text())
    assert len(config["config"]["patterns"]["long"]["subgoals"]) == 1000
    code = recipe("four_rooms").main([*hrs, "--methods", "HRS,RRS", "--results", str(tmp_path / "rrs")])
    line = one_error_line(code, capsys)
    assert line == (
        f"error: {path}: pattern 'long': has 1000 subgoals, more than the 102 candidate subgoals "
        "random patterns (RRS) of that length are drawn from"
    )
    assert not (tmp_path / "rrs").exists()


def test_pick_and_place_rrs_ranges_apply_only_when_rrs_runs(tmp_path: Path) -> None:
    """RRS draws boxes over positions and finger joints only; a pattern over the rotation is HRS's to use."""
    from torchrl_subgoal.experiments.cli import ConfigError, parse_config

    pick_and_place = recipe("pick_and_place")
    path = tmp_path / "rotation.yaml"
    path.write_text(
        "domain: pick_and_place\npatterns:\n  turned:\n    subgoals:\n"
        "      - {box: {centre: [0.0, 0.0, 0.0], margin: 0.1, dims: [11, 12, 13]}}\n"
    )
    flags = [*PICK_AND_PLACE, "--subgoals", str(path), "--results", str(tmp_path / "r")]
    sweep = pick_and_place.plan(parse_config(pick_and_place.Config, [*flags, "--methods", "HRS,NRS,DDPG"]))
    assert [s.name for s in sweep.specs] == ["HRS", "NRS", "DDPG"]
    with pytest.raises(ConfigError, match="pattern 'turned': RRS has no range to draw random centres from"):
        pick_and_place.plan(parse_config(pick_and_place.Config, [*flags, "--methods", "HRS,RRS"]))


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        (
            ["--total-frames", "1"],
            "--total-frames: 1 is less than one batch of 256 frames (--frames-per-batch); give at least 256",
        ),
        (["--total-frames", "255"], "--total-frames: 255 is less than one batch of 256 frames"),
        (["--total-frames", "64", "--frames-per-batch", "128"], "--total-frames: 64 is less than one batch of 128"),
    ],
)
def test_a2c_budget_smaller_than_one_batch(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], flags: list[str], message: str
) -> None:
    code = recipe("a2c").main([*flags, "--methods", "A2C", "--workers", "0", "--results", str(tmp_path / "r")])
    assert one_error_line(code, capsys).startswith(f"error: {message}")
    assert not (tmp_path / "r").exists()


def test_pinball_unknown_map_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code = recipe("pinball").main(
        ["--map", "moon", "--methods", "AC", "--workers", "0", "--results", str(tmp_path / "r")]
    )
    assert one_error_line(code, capsys) == (
        "error: --map: PinBall config 'moon' is neither one of ('simple', 'hard') nor an existing file"
    )
    assert not (tmp_path / "r").exists()


# -- the report while a sweep runs ---------------------------------------------------------------------


def test_the_report_refuses_a_directory_a_sweep_is_writing_into(
    finished: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    res = copy_of(finished, tmp_path)
    for name in ("report.md", "summary.json"):
        (res / name).unlink()
    with ResultsStore(res).lock():  # as the sweep holds it while it runs
        assert report_main([str(res), "--n-boot", "10"]) == 2
        err = capsys.readouterr().err.strip()
        assert err == (
            f"error: a sweep is running into {res} (it holds {res / '.lock'}), so its results are not "
            "final; wait for it to finish, or pass --allow-incomplete to report on the chunks finished "
            "so far"
        )
        assert not (res / "report.md").exists() and not (res / "summary.json").exists()
        assert report_main([str(res), "--n-boot", "10", "--allow-incomplete"]) == 0
        err = capsys.readouterr().err
        assert err.splitlines()[0] == (
            f"warning: a sweep is running into {res}; this report covers the chunks it has finished so far"
        )
        assert (res / "report.md").exists()
    assert report_main([str(res), "--n-boot", "10"]) == 0  # the sweep is over: no word about it
    assert "sweep is running" not in capsys.readouterr().err


# -- plans that cannot fit: refused before the sweep is even built --------------------------------

HUGE = str(10**12)
# (recipe, flags, the error line's start): each count large enough that no machine's memory, nor a year
# at 10^9 steps a second, holds it
CANNOT_FIT = [
    ("train", ["--learnings", HUGE], f"--learnings {HUGE}: the plan holds at least 1e+12 learners of 81 bytes"),
    ("qlearning", ["--learnings", HUGE], f"--learnings {HUGE}: the plan holds at least 1e+12 learners of 81 bytes"),
    ("four_rooms", ["--learnings", HUGE], f"--learnings {HUGE}: the plan holds at least 1e+12 learners of 81 bytes"),
    (  # its plan draws a random pattern per learning
        "pick_and_place",
        ["--preset", "tiny", "--learnings", HUGE],
        f"--learnings {HUGE}: the plan holds at least 1e+12 learners of 81 bytes",
    ),
    (  # fits before the plan (a learner each), not once it has 10 patterns x 2 methods x 10**5 episodes
        "qlearning",
        ["--learnings", str(10**8), "--methods", "Q,HRS", "--episodes", str(10**5)],
        f"--learnings {10**8}: 2,000,000,000 learners record at least",
    ),
    ("qlearning", ["--episodes", str(10**15)], f"--episodes {10**15}: one learner records 1e+15 episodes of 17 bytes"),
    ("pinball", ["--episodes", str(10**15)], f"--episodes {10**15}: one learner records 1e+15 episodes of 17 bytes"),
    ("train", ["--total-frames", str(10**30)], f"--total-frames {10**30}: one learner takes at least 1e+30 steps"),
    ("a2c", ["--total-frames", str(10**30)], f"--total-frames {10**30}: one learner takes at least 1e+30 steps"),
    ("pick_and_place", [*PICK_AND_PLACE, "--epochs", str(10**15)], f"--epochs {10**15}: one learner takes at least"),
    (
        "train",
        ["--algo", "a2c", "--seed-batch", str(10**9), "--learnings", str(10**7)],
        f"--seed-batch {10**9}: 2 chunks at once (--workers 2) of 100,000,000 learners hold at least",
    ),
    (
        "qlearning",
        ["--domain", "taxi", "--reward", "goal"],
        "--reward goal: applies to --domain four_rooms and sparse_rooms only",
    ),
]


@pytest.mark.parametrize(("name", "flags", "message"), CANNOT_FIT, ids=[f"{c[0]} {' '.join(c[1])}" for c in CANNOT_FIT])
def test_a_plan_that_cannot_fit_is_one_line_before_anything_is_built(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, name: str, flags: list[str],
    message: str,
) -> None:  # fmt: skip
    """Counts and sizes are checked before the sweep enumerates its learners (``--learnings 10**12`` grew
    to 13.7 GB there) or writes ``config.json``; a flag that does not apply to the task is refused, not ignored."""
    from torchrl_subgoal.experiments import recipe as recipe_module

    def built(*args: object, **kwargs: object) -> None:
        raise AssertionError("the sweep was built: the plan was not refused first")

    monkeypatch.setattr(recipe_module, "Sweep", built)
    code = recipe(name).main([*flags, "--results", str(tmp_path / "r")])
    line = one_error_line(code, capsys)
    assert line.startswith(f"error: {message}"), line
    assert "fit" in line or "leave it out" in line  # what would fit, or what to do
    assert not (tmp_path / "r").exists()


def test_a_ray_address_where_nothing_answers_is_one_line_before_anything_is_written(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Ray itself retries such an address for minutes (over five, with ``config.json`` already written)."""
    import socket

    with socket.socket() as sock:  # a port nothing listens on: bound, never listening
        sock.bind(("127.0.0.1", 0))
        address = f"127.0.0.1:{sock.getsockname()[1]}"
        monkeypatch.setenv("RAY_ADDRESS", address)
        code = recipe("qlearning").main(["--episodes", "2", "--backend", "ray", "--results", str(tmp_path / "r")])
    line = one_error_line(code, capsys)
    assert line.startswith(f"error: RAY_ADDRESS={address}: no Ray cluster answers there (Connection refused); ")
    assert not (tmp_path / "r").exists()
