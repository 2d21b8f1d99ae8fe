"""SubgoalSeries, predicates, the file format and its errors, batched evaluation."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import torch
import yaml
from tensordict import TensorDict

from torchrl_subgoal import (
    Box,
    Cell,
    Circle,
    Condition,
    State,
    StateAggregation,
    SubgoalFileError,
    SubgoalSeries,
    load_patterns,
    save_patterns,
)
from torchrl_subgoal.subgoals import Predicate, SubgoalTables, file_description, load_pattern


def write(tmp_path: Path, data: object, name: str = "subgoals.yaml") -> Path:
    path = tmp_path / name
    path.write_text(data if isinstance(data, str) else yaml.safe_dump(data))
    return path


# ----------------------------------------------------------------- order


def test_chain_successors() -> None:
    s = SubgoalSeries([Cell(1, 1), Cell(2, 2), Cell(3, 3)])
    assert s.is_chain and s.num_abstract_states == 4
    assert [s.successors(z) for z in range(4)] == [(0,), (1,), (2,), ()]


def test_partial_order_uses_covering_relation() -> None:
    # a, b before c; a before d; the transitive pair (a, c) changes nothing
    s = SubgoalSeries([Cell(1, 1)] * 4, order=[(0, 2), (1, 2), (0, 3), (0, 2)], names=["a", "b", "c", "d"])
    assert not s.is_chain
    assert s.successors(0) == (0, 1)  # sources a, b
    assert s.successors(1) == (2, 3)  # after a: c or d
    assert s.successors(2) == (2,)  # after b: c
    assert s.successors(3) == () and s.successors(4) == ()


def test_transitive_pair_is_not_a_shortcut() -> None:
    s = SubgoalSeries([Cell(1, 1)] * 3, order=[(0, 1), (1, 2), (0, 2)], names=["a", "b", "c"])
    assert s.successors(1) == (1,)  # after a only b, though a < c is stated


def test_cycle_is_an_error() -> None:
    with pytest.raises(SubgoalFileError, match="cycle"):
        SubgoalSeries([Cell(1, 1)] * 3, order=[(0, 1), (1, 2), (2, 0)], names=["a", "b", "c"])


def test_random_series_is_reproducible_and_distinct() -> None:
    cands = [Cell(r, c) for r in range(1, 4) for c in range(1, 4)]
    a = SubgoalSeries.random(cands, 3, torch.Generator().manual_seed(5))
    b = SubgoalSeries.random(cands, 3, torch.Generator().manual_seed(5))
    c = SubgoalSeries.random(cands, 3, torch.Generator().manual_seed(6))
    assert a.predicates == b.predicates and len(set(a.predicates)) == 3
    assert a.predicates != c.predicates


# ----------------------------------------------------------------- files


def test_file_round_trip(tmp_path: Path) -> None:
    patterns = {
        "chain": SubgoalSeries([Cell(3, 6), Cell(7, 9)], name="chain"),
        "dag": SubgoalSeries(
            [Circle((0.5, 0.5), 0.04), Box((0.0, 0.0, 0.0), (0.01, 0.01, 0.01), (6, 7, 8)), State(3)],
            order=[(0, 2), (1, 2)],
            names=["c", "b", "s"],
            name="dag",
        ),
    }
    path = tmp_path / "p.yaml"
    save_patterns(path, patterns)
    loaded = load_patterns(path)
    assert loaded.keys() == patterns.keys()
    for name, original in patterns.items():
        assert loaded[name].predicates == original.predicates
        states = range(original.num_abstract_states)
        assert [loaded[name].successors(z) for z in states] == [original.successors(z) for z in states]


def test_save_keeps_file_and_pattern_descriptions(tmp_path: Path) -> None:
    path = write(
        tmp_path,
        {
            "description": "whole file",
            "patterns": {
                "chain": {"description": "hallways first", "subgoals": [{"cell": [3, 6]}, {"cell": [7, 9]}]},
                "named": {
                    "description": "partial",
                    "subgoals": {"a": {"cell": [3, 6]}, "b": {"cell": [7, 9]}},
                    "order": [],
                },
                "plain": {"subgoals": [{"cell": [3, 6]}]},
            },
        },
    )
    loaded = load_patterns(path)
    assert [s.description for s in loaded.values()] == ["hallways first", "partial", None]
    again = tmp_path / "again.yaml"
    save_patterns(again, loaded, description=file_description(path))
    assert yaml.safe_load(again.read_text())["description"] == "whole file"
    assert [s.description for s in load_patterns(again).values()] == ["hallways first", "partial", None]
    assert "description" not in yaml.safe_load(again.read_text())["patterns"]["plain"]
    with pytest.raises(SubgoalFileError, match=r"pattern 'p': description: expected text, got 3"):
        load_patterns(write(tmp_path, {"patterns": {"p": {"description": 3, "subgoals": [{"cell": [3, 6]}]}}}))
    with pytest.raises(SubgoalFileError, match=r"bad\.yaml: description: expected text"):
        load_patterns(write(tmp_path, {"description": ["x"], "patterns": {"p": [{"cell": [3, 6]}]}}, "bad.yaml"))


def test_shipped_participants_file() -> None:
    from importlib.resources import files

    patterns = load_patterns(
        Path(str(files("torchrl_subgoal") / "domains" / "four_rooms" / "four_rooms_participants.yaml"))
    )
    assert len(patterns) == 10
    assert patterns["participant_7"].predicates == (Cell(3, 6), Cell(7, 9))
    assert all(len(p) == 2 and p.is_chain for p in patterns.values())


def test_json_and_box_slice(tmp_path: Path) -> None:
    path = write(
        tmp_path,
        '{"patterns": {"fetch": {"subgoals": [{"box": {"centre": [0, 0, 0], "margin": 0.01, "slice": [6, 9]}}]}}}',
        "s.json",
    )
    box = load_pattern(path).predicates[0]
    assert isinstance(box, Box) and box.box_dims == (6, 7, 8) and box.margin == (0.01,) * 3


BAD_FILES = [
    ({"patterns": {"p": {"subgoals": [{"square": [1, 2]}]}}}, "pattern 'p': subgoals[0]: give exactly one predicate"),
    ({"patterns": {"p": {"subgoals": [{"cell": [1, 2, 3]}]}}}, "subgoals[0].cell: expected [row, col]"),
    (
        {"patterns": {"p": {"subgoals": [{"circle": {"centre": [0.1, float("nan")], "radius": 0.1}}]}}},
        "subgoals[0].circle.centre[1]: expected a finite number",
    ),
    (
        {"patterns": {"p": {"subgoals": [{"circle": {"centre": [0.1, 0.2], "radius": 0.1, "dims": [0]}}]}}},
        "subgoals[0].circle.dims: has 1 entries but the centre has 2",
    ),
    (
        {"patterns": {"p": {"subgoals": [{"circle": {"centre": [0.1, 0.2], "radius": -1}}]}}},
        "circle.radius: must be positive",
    ),
    (
        {"patterns": {"p": {"subgoals": [{"box": {"centre": [0.1], "margin": [0.1, 0.2]}}]}}},
        "box.margin: has 2 entries but the centre has 1",
    ),
    (
        {
            "patterns": {
                "p": {"subgoals": {"a": {"cell": [1, 1]}, "b": {"cell": [2, 2]}}, "order": [["a", "b"], ["b", "a"]]}
            }
        },
        "pattern 'p': order: the order has a cycle",
    ),
    (
        {"patterns": {"p": {"subgoals": {"a": {"cell": [1, 1]}}, "order": [["a", "z"]]}}},
        "order[0]: unknown subgoal 'z'",
    ),
    ({"patterns": {"p": {"subgoals": {"a": {"cell": [1, 1]}}}}}, "pattern 'p': order: missing"),
    ({"patterns": {"p": {"goals": []}}}, "pattern 'p': unknown field(s) ['goals']"),
    ({"patterns": {"p": {"subgoals": []}}}, "pattern 'p': a pattern needs at least one subgoal"),
    ({"patterns": {}}, "patterns: expected a non-empty mapping"),
    (
        {"domain": "four_rooms", "patterns": {"p": {"subgoals": [{"cell": [1, 1]}, {"cell": [0, 6]}]}}},
        "pattern 'p': subgoals[1].cell: (0, 6) is a wall",
    ),
    (
        {"domain": "four_rooms", "patterns": {"p": {"subgoals": [{"cell": [13, 2]}]}}},
        "subgoals[0].cell: (13, 2) is off the 13x13 grid",
    ),
    (
        {"domain": "four_rooms", "patterns": {"p": {"subgoals": [{"circle": {"centre": [1, 1], "radius": 1}}]}}},
        "four-rooms subgoals are cells or states",
    ),
    ({"domain": "mars", "patterns": {"p": {"subgoals": [{"cell": [1, 1]}]}}}, "unknown domain 'mars'"),
    ("patterns: [unclosed", "not valid YAML/JSON"),
]


@pytest.mark.parametrize(("data", "message"), BAD_FILES)
def test_file_errors_name_file_pattern_and_field(tmp_path: Path, data: object, message: str) -> None:
    path = write(tmp_path, data)
    with pytest.raises(SubgoalFileError) as err:
        load_patterns(path)
    assert str(path) in str(err.value)
    assert message in str(err.value)


def test_unknown_pattern_names_the_available_ones(tmp_path: Path) -> None:
    path = write(tmp_path, {"patterns": {"a": [{"cell": [1, 1]}], "b": [{"cell": [2, 2]}]}})
    with pytest.raises(SubgoalFileError, match=r"no pattern 'c'; available: \['a', 'b'\]"):
        load_pattern(path, "c")
    with pytest.raises(SubgoalFileError, match="holds 2 patterns"):
        load_pattern(path)


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(SubgoalFileError, match="cannot read"):
        load_patterns(tmp_path / "nope.yaml")


# ----------------------------------------------------------------- batched evaluation


def test_tables_chain_advance_one_subgoal_per_step_in_order() -> None:
    s = SubgoalSeries([Cell(3, 6), Cell(7, 9)])
    tables = SubgoalTables([s], torch.zeros(3, dtype=torch.long), observation_size=2)
    z = torch.tensor([[0], [0], [1]])
    obs = torch.tensor([[7, 9], [3, 6], [7, 9]])  # out of order, in order, in order
    for advance in (tables.advance, tables.advance_eager):
        assert advance(z, obs).tolist() == [[0], [1], [2]]
    # once complete, nothing more happens
    assert tables.advance(torch.tensor([[2], [2], [2]]), obs).tolist() == [[2], [2], [2]]


def test_tables_each_learner_its_own_pattern() -> None:
    a = SubgoalSeries([Cell(1, 1)])
    b = SubgoalSeries([Cell(2, 2), Cell(1, 1), Cell(3, 3)])
    tables = SubgoalTables([a, b], torch.tensor([0, 1]), observation_size=2)
    assert tables.num_states == 4
    obs = torch.tensor([[1, 1], [1, 1]])
    assert tables.advance(torch.tensor([[0], [0]]), obs).tolist() == [[1], [0]]
    assert tables.advance(torch.tensor([[1], [1]]), obs).tolist() == [[1], [2]]


def test_tables_one_hot_state_predicate() -> None:
    s = SubgoalSeries([State(5)])
    tables = SubgoalTables([s], torch.zeros(2, dtype=torch.long), observation_size=16, one_hot=True)
    obs = torch.nn.functional.one_hot(torch.tensor([5, 4]), 16)
    assert tables.advance(torch.zeros(2, 1, dtype=torch.long), obs).tolist() == [[1], [0]]


def test_wrong_observation_size_names_pattern_and_field() -> None:
    s = SubgoalSeries([Circle((0.1, 0.2), 0.1, (3, 4))], name="wide", source="f.yaml")
    with pytest.raises(SubgoalFileError, match=r"f.yaml: pattern 'wide': subgoals\[0\].circle: .* has 4 entries"):
        SubgoalTables([s], torch.zeros(1, dtype=torch.long), observation_size=4)


def random_tables(seed: int, n: int = 64) -> tuple[SubgoalTables, list[SubgoalSeries], torch.Tensor]:
    g = torch.Generator().manual_seed(seed)
    patterns = []
    for p in range(4):
        preds = []
        for _ in range(3):
            kind = int(torch.randint(3, (1,), generator=g))
            c = torch.rand(3, generator=g).tolist()
            if kind == 0:
                preds.append(Circle((c[0], c[1]), 0.3))
            elif kind == 1:
                preds.append(Box(tuple(c), (0.3, 0.2, 0.4), (0, 1, 2)))
            else:
                preds.append(Circle((c[0], c[2]), 0.4, (0, 2)))
        order = None if p % 2 == 0 else [(0, 2), (1, 2)]
        patterns.append(SubgoalSeries(preds, order=order, names=["a", "b", "c"] if order else None))
    index = torch.randint(4, (n,), generator=g)
    return SubgoalTables(patterns, index, observation_size=3), patterns, index


@pytest.mark.parametrize("seed", range(5))
def test_kernel_agrees_with_eager_and_with_the_definition(seed: int) -> None:
    tables, patterns, index = random_tables(seed)
    g = torch.Generator().manual_seed(100 + seed)
    z = torch.randint(4, (64, 1), generator=g)
    obs = torch.rand(64, 3, generator=g)
    fast, eager = tables.advance(z, obs), tables.advance_eager(z, obs)
    assert torch.equal(fast, eager)
    # the definition, one learner at a time
    for b in range(64):
        series = patterns[int(index[b])]
        o = obs[b].tolist()
        expected = int(z[b])
        for j in series.successors(int(z[b])):
            pred = series.predicates[j]
            dims = pred.dims()
            if isinstance(pred, Circle):
                ok = sum((o[d] - c) ** 2 for d, c in zip(dims, pred.centre, strict=True)) <= pred.radius**2
            else:
                assert isinstance(pred, Box)
                ok = all(abs(o[d] - c) <= m for d, c, m in zip(dims, pred.centre, pred.margin, strict=True))
            if ok:
                expected = j + 1
                break
        assert int(fast[b]) == expected, (b, series, o)


def test_circle_boundary_is_inside() -> None:
    s = SubgoalSeries([Circle((0.0, 0.0), 0.5)])
    tables = SubgoalTables([s], torch.zeros(2, dtype=torch.long), observation_size=2)
    obs = torch.tensor([[0.0, 0.5], [0.0, 0.5001]])  # exactly on the boundary, just outside
    assert tables.advance(torch.zeros(2, 1, dtype=torch.long), obs).tolist() == [[1], [0]]
    assert not math.isinf(tables.radius2[0, 0])


def test_state_aggregation_lookup_and_function() -> None:
    agg = StateAggregation(torch.tensor([2, 0, 1]), num_states=3)
    z = torch.zeros(3, 1, dtype=torch.long)
    assert agg.advance(z, torch.tensor([0, 1, 2])).tolist() == [[2], [0], [1]]
    assert agg.initial(torch.tensor([2]), torch.Size([1])).tolist() == [[1]]
    halves = StateAggregation(lambda o: (o[..., 0] > 0.5).long(), num_states=2)
    assert halves.advance(torch.zeros(2, 1, dtype=torch.long), torch.tensor([[0.2], [0.7]])).tolist() == [[0], [1]]
    with pytest.raises(ValueError, match="must lie in"):
        StateAggregation(torch.tensor([0, 3]), num_states=3)


# --------------------------------------------------------------------------- conditions


def _carrying(td: TensorDict) -> torch.Tensor:
    return td["inventory"] > 0


def test_a_plain_function_is_a_subgoal() -> None:
    series = SubgoalSeries([_carrying, Cell(2, 2)])
    assert isinstance(series.predicates[0], Condition)
    assert series.predicates[0].to_dict() == {"call": "tests.test_subgoals:_carrying"}
    tables = SubgoalTables([series], torch.zeros(3, dtype=torch.long), 2, observation_key="cell")
    td = TensorDict({"inventory": torch.tensor([0, 1, 1]), "cell": torch.tensor([[2, 2], [0, 0], [2, 2]])}, [3])
    z = tables.advance(torch.zeros(3, 1, dtype=torch.long), td["cell"], td)
    assert z.tolist() == [[0], [1], [1]]  # the region of the second subgoal does not count before the first
    assert tables.advance(z, td["cell"], td).tolist() == [[0], [1], [2]]


def test_condition_reads_any_entry_and_checks_its_mask() -> None:
    series = SubgoalSeries([lambda td: td["flag"]])
    tables = SubgoalTables([series], torch.zeros(2, dtype=torch.long), 0)
    td = TensorDict({"flag": torch.tensor([[True], [False]])}, [2])
    assert tables.advance(torch.zeros(2, 1, dtype=torch.long), None, td).tolist() == [[1], [0]]
    wrong = SubgoalTables(
        [SubgoalSeries([lambda td: td["flag"][:1]], name="short")], torch.zeros(2, dtype=torch.long), 0
    )
    with pytest.raises(ValueError, match=r"returned \(1, 1\); expected a boolean mask of shape \(2,\)"):
        wrong.advance(torch.zeros(2, 1, dtype=torch.long), None, td)
    with pytest.raises(KeyError, match="failed on the step"):
        tables.advance(torch.zeros(2, 1, dtype=torch.long), None, TensorDict({}, [2]))


def test_condition_subclass_without_region() -> None:
    class Carrying(Predicate):
        kind = "carrying"

        def __call__(self, tensordict: TensorDict) -> torch.Tensor:
            return tensordict["inventory"] > 0

    series = SubgoalSeries([Carrying()])
    tables = SubgoalTables([series], torch.zeros(2, dtype=torch.long), 0)
    td = TensorDict({"inventory": torch.tensor([3, 0])}, [2])
    assert tables.advance(torch.zeros(2, 1, dtype=torch.long), None, td).tolist() == [[1], [0]]


def test_condition_by_import_path_in_a_file(tmp_path: Path) -> None:
    path = tmp_path / "conditions.yaml"
    path.write_text(
        "patterns:\n"
        "  carry_then_cell:\n"
        "    subgoals:\n"
        "      - {call: 'tests.test_subgoals:_carrying'}\n"
        "      - {call: 'tests.dict_env.at_door'}\n"
        "      - {cell: [3, 4]}\n"
    )
    series = load_pattern(path)
    first, second = series.predicates[0], series.predicates[1]
    assert isinstance(first, Condition) and first.fn is _carrying
    assert isinstance(second, Condition) and second.path == "tests.dict_env:at_door"
    save_patterns(tmp_path / "round.yaml", {"carry_then_cell": series})
    assert load_patterns(tmp_path / "round.yaml")["carry_then_cell"] == series


def test_condition_factory_with_args(tmp_path: Path) -> None:
    path = tmp_path / "factory.yaml"
    path.write_text("patterns:\n  p:\n    subgoals:\n      - {call: 'operator:itemgetter', args: {}}\n")
    series = load_pattern(path)
    assert isinstance(series.predicates[0], Condition)


@pytest.mark.parametrize(
    ("body", "message"),
    [
        ("{call: 'no_such_module_xyz:f'}", r"subgoals\[0\]\.call: cannot import module 'no_such_module_xyz'"),
        ("{call: 'operator:no_such'}", r"subgoals\[0\]\.call: module 'operator' has no attribute 'no_such'"),
        ("{call: 3}", r"subgoals\[0\]\.call: expected an import path"),
        ("{call: 'operator:truth', args: [1]}", r"args: expected a mapping"),
        ("{call: 'operator:truth', where: 1}", r"unknown field\(s\) \['where'\]"),
    ],
)
def test_condition_file_errors_name_the_field(tmp_path: Path, body: str, message: str) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text(f"patterns:\n  p:\n    subgoals:\n      - {body}\n")
    with pytest.raises(SubgoalFileError, match=message):
        load_patterns(path)


def test_a_lambda_cannot_be_written_to_a_file(tmp_path: Path) -> None:
    series = SubgoalSeries([lambda td: td["x"] > 0], name="anon")
    with pytest.raises(SubgoalFileError, match="has no import path"):
        save_patterns(tmp_path / "x.yaml", {"anon": series})


def test_a_condition_must_return_a_boolean_mask() -> None:
    """A number is not a truth value: a condition returning the passenger's index (an int) instead of
    a comparison is refused in one line naming it, not read as 'achieved wherever non-zero'."""
    from tensordict import TensorDict

    from torchrl_subgoal.subgoals import SubgoalTables

    def passenger(td):  # forgot the `== 4`
        return td["passenger"]

    tables = SubgoalTables([SubgoalSeries([passenger])], torch.zeros(2, dtype=torch.long), 1)
    td = TensorDict({"passenger": torch.tensor([4, 0])}, [2])
    with pytest.raises(ValueError, match=r"passenger.*int64 tensor; expected a boolean mask"):
        tables.advance(torch.zeros(2, 1, dtype=torch.long), None, td)
    tables = SubgoalTables([SubgoalSeries([lambda td: td["passenger"] == 4])], torch.zeros(2, dtype=torch.long), 1)
    assert tables.advance(torch.zeros(2, 1, dtype=torch.long), None, td).reshape(-1).tolist() == [1, 0]
