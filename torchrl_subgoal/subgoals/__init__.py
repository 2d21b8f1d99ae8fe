"""Subgoal series: ordered subgoals, their achievement predicates and the file format.

A *subgoal series* is what a person who knows the task writes down: a few
subgoals and the order in which they should be achieved. The order is total
(a chain, ``sg_0 ≺ sg_1 ≺ …``) or partial (a DAG). Each subgoal has an
*achievement predicate* over the environment's observation.

Built-in predicates (evaluated on one observation entry, batched):

* :class:`State` — a discrete observation equals a given state index;
* :class:`Cell` — chosen observation entries equal a grid cell ``(row, col)``;
* :class:`Circle` — chosen entries lie within ``radius`` of ``centre``;
* :class:`Box` — chosen entries lie within ``centre ± margin``.

Each compiles to one region ``lo ≤ o ≤ hi`` and ``Σ w (o − c)² ≤ r²`` so
that a batch of learners, each following its own pattern, is tested in one
vectorised expression (:class:`SubgoalTables`).

Any other condition is a :class:`Condition`: a function of the batch's
TensorDict (every entry of the step: observations of any key, flags of a
dict observation, …) returning a boolean mask. A plain function given as a
subgoal is wrapped in one, and a subgoal file names one by import path
(``{call: "package.module:function"}``).

The file format (YAML, or JSON which is valid YAML) is documented in
``docs/subgoal_files.md``; :mod:`torchrl_subgoal.subgoals.files` reads, checks and
saves it (:func:`load_pattern`, :func:`load_patterns`, :func:`save_patterns`), and
every error names the file, the pattern and the field. A series itself is data:
it knows nothing of files.
"""

from torchrl_subgoal.subgoals.errors import SubgoalFileError
from torchrl_subgoal.subgoals.files import (
    FORMAT,
    MAX_FILE_BYTES,
    DomainCheck,
    file_description,
    load_pattern,
    load_patterns,
    parse_predicate,
    parse_text,
    pattern_from_data,
    patterns_from_data,
    pick_pattern,
    read_file,
    save_patterns,
)
from torchrl_subgoal.subgoals.predicates import (
    Box,
    Cell,
    Circle,
    Condition,
    Predicate,
    Region,
    State,
)
from torchrl_subgoal.subgoals.series import MAX_SUBGOALS, SubgoalSeries
from torchrl_subgoal.subgoals.tables import RegionTables, StateAggregation, SubgoalTables

__all__ = [
    "FORMAT",
    "MAX_FILE_BYTES",
    "MAX_SUBGOALS",
    "Box",
    "Cell",
    "Circle",
    "Condition",
    "DomainCheck",
    "Predicate",
    "Region",
    "RegionTables",
    "State",
    "StateAggregation",
    "SubgoalFileError",
    "SubgoalSeries",
    "SubgoalTables",
    "file_description",
    "load_pattern",
    "load_patterns",
    "parse_predicate",
    "parse_text",
    "pattern_from_data",
    "patterns_from_data",
    "pick_pattern",
    "read_file",
    "save_patterns",
]
