"""Deterministic grid moves (the four-rooms env)."""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, nogil=True, inline="always")
def grid_step_one(grid, b, a):
    """Learner ``b``'s move ``a`` in a grid env (a :class:`~torchrl_subgoal.envs.four_rooms.GridKernelState`,
    updated in place): ``(next state, reward as float32, terminated, done)``."""
    s = grid.transitions[grid.state[b], a]
    grid.state[b] = s
    grid.t[b] += 1
    terminated = s == grid.goal
    done = terminated or grid.t[b] >= grid.max_steps
    return s, np.float32(grid.goal_reward if terminated else grid.step_reward), terminated, done


@numba.njit(cache=True, nogil=True, inline="always")
def grid_reset_one(grid, b):
    """Put learner ``b`` of a grid env back at the start."""
    grid.state[b] = grid.start
    grid.t[b] = 0


@numba.njit(cache=True, nogil=True)
def grid_step(grid, action, reward, terminated, truncated, cell_out):
    """Deterministic grid moves for a batch (:func:`grid_step_one` per learner): next state, step
    count, reward (``goal_reward`` on reaching the goal, else ``step_reward``), flags and cells."""
    for b in range(grid.state.shape[0]):
        s, r, term, done = grid_step_one(grid, b, action[b])
        terminated[b] = term
        truncated[b] = done and not term
        reward[b] = r
        cell_out[b, 0] = grid.cells[s, 0]
        cell_out[b, 1] = grid.cells[s, 1]


@numba.njit(cache=True, nogil=True)
def grid_reset(grid, reset, cell_out):
    """Put the learners flagged in ``reset`` back at the start; write every learner's cell."""
    for b in range(grid.state.shape[0]):
        if reset[b]:
            grid_reset_one(grid, b)
        cell_out[b, 0] = grid.cells[grid.state[b], 0]
        cell_out[b, 1] = grid.cells[grid.state[b], 1]
