"""Subgoal-based reward shaping (dynamic trajectory aggregation) for TorchRL.

Implements Okudo & Yamada, "Reward Shaping with Dynamic Trajectory
Aggregation" (IJCNN 2021): a person names a few ordered subgoals, and
:class:`SubgoalPotentialTransform` turns them into a learned potential-based
shaping reward for any TorchRL environment.
"""

from torchrl_subgoal import domains  # noqa: F401  (the registry's names; no plugin is imported)
from torchrl_subgoal.loss import SubgoalValueLoss, ValueUpdate
from torchrl_subgoal.potentials import NaivePotential, NeuralPotential, Potential, TabularPotential
from torchrl_subgoal.registry import load_pattern, load_patterns
from torchrl_subgoal.subgoals import (
    Box,
    Cell,
    Circle,
    Condition,
    State,
    StateAggregation,
    SubgoalFileError,
    SubgoalSeries,
    save_patterns,
)
from torchrl_subgoal.transform import SubgoalKeys, SubgoalPotentialTransform

__version__ = "0.1.0"

__all__ = [
    "Box",
    "Cell",
    "Circle",
    "Condition",
    "NaivePotential",
    "NeuralPotential",
    "Potential",
    "State",
    "StateAggregation",
    "SubgoalFileError",
    "SubgoalKeys",
    "SubgoalPotentialTransform",
    "SubgoalSeries",
    "SubgoalValueLoss",
    "TabularPotential",
    "ValueUpdate",
    "__version__",
    "load_pattern",
    "load_patterns",
    "save_patterns",
]
