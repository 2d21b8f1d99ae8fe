"""Fused CPU kernels (numba) for the per-step work of the shaping transform.

Each kernel does, in one pass over the learner batch, what the eager torch
code in :mod:`torchrl_subgoal.subgoals` and :mod:`torchrl_subgoal.transform`
does with a few dozen small tensor operations; at the batch sizes used here
(10^2-10^4 learners) the cost of those is dominated by per-operation overhead,
which is why the transform would otherwise cost more than the environment.
The eager code stays the reference (and the path for other devices and neural
potentials); ``tests/test_kernels.py`` checks the two agree.

Arrays are numpy views of torch tensors (no copies); batch dimensions are
flattened, per-learner scalars have a trailing singleton.
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, nogil=True, inline="always")
def _in_region(o, lo, hi, centre, weight, radius2):
    """Whether the observation ``o`` lies in one region: ``lo ≤ o ≤ hi`` and
    ``Σ w (o − c)² ≤ r²`` over the entries with ``w ≠ 0``, all in float64.

    The comparisons are written so that NaN is never inside (as in torch), ±inf
    compares as a number, and an entry the region does not read (open bounds,
    zero weight) never matters, whatever it holds but NaN. ``SubgoalTables``'s
    torch path computes the same, in the same order, so the two agree exactly.
    """
    for d in range(lo.shape[0]):
        if not (o[d] >= lo[d] and o[d] <= hi[d]):
            return False
    if radius2 < np.inf:
        s = 0.0
        for d in range(lo.shape[0]):
            w = np.float64(weight[d])
            if w != 0.0:
                diff = np.float64(o[d]) - np.float64(centre[d])
                s += w * diff * diff
        return s <= radius2
    return True


@numba.njit(cache=True, nogil=True)
def advance_regions(z, obs, pattern, lo, hi, centre, weight, radius2, succ, z_out):
    """``z_out[b]``: abstract state after observing ``obs[b]`` in ``z[b]`` (see SubgoalTables).

    Learner ``b`` follows pattern ``pattern[b]``; the region tables are per pattern
    (``[P, J, D]``), which keeps them in cache whatever the number of learners.
    See :func:`_in_region` for how an observation is compared (NaN is never inside).
    """
    n_nodes = lo.shape[1]
    for b in range(z.shape[0]):
        p = pattern[b]
        zb = z[b, 0]
        z_out[b, 0] = zb
        for j in range(n_nodes):
            if not succ[p, zb, j]:
                continue
            if _in_region(obs[b], lo[p, j], hi[p, j], centre[p, j], weight[p, j], radius2[p, j]):
                z_out[b, 0] = j + 1
                break


START_VALUE, START_ZERO, START_NONPOSITIVE = 0, 1, 2  # SubgoalPotentialTransform's start_potential


@numba.njit(cache=True, nogil=True)
def shape_step(
    z, z_next, achieved_prev, r_h, k, reward, done, terminated,
    table, shared, eta, gamma, value_gamma, lr, zero_terminal, start_mode, z_start,
    rh_out, k_out, reward_out, rh_acc_out, k_acc_out, emit_out,
):
    """Accumulate ``r_h, k``, update a tabular potential online, and shape the reward.

    ``table`` is ``[B or 1, Z]`` (``shared`` = one table for all envs); an
    empty table means the naive potential ``Φ = eta · achieved``. ``lr = 0``
    disables the update. ``start_mode`` shifts a table's potential by ``V(z_0)``
    (``START_ZERO``) or ``max(V(z_0), 0)`` (``START_NONPOSITIVE``), with
    ``z_start[b]`` the abstract state learner ``b``'s episode started in.
    ``rh_acc_out``, ``k_acc_out`` and ``emit_out`` (the
    SMDP transition's ``r_h``, ``k`` and mask) are filled when not empty.
    The update equals one SGD step of
    :class:`~torchrl_subgoal.SubgoalValueLoss` (reduction ``"sum"``): every
    TD error is computed with the table as it was, then all are applied.
    """
    n = z.shape[0]
    naive = table.shape[0] == 0
    delta = np.zeros(n)
    for b in range(n):
        kb = k[b, 0]
        emit = z_next[b, 0] != z[b, 0] or done[b, 0]
        r = r_h[b, 0]
        discount = 1.0
        if reward[b, 0] != 0.0 or emit:  # γ_v^k is needed only then
            discount = value_gamma**kb
            r += reward[b, 0] * discount
        kb += 1
        if emit and lr > 0.0 and not naive:
            row = 0 if shared else b
            v_next = 0.0 if terminated[b, 0] else table[row, z_next[b, 0]]
            delta[b] = r + discount * value_gamma * v_next - table[row, z[b, 0]]
        rh_out[b, 0] = 0.0 if emit else r
        k_out[b, 0] = 0 if emit else kb
        if emit_out.shape[0] > 0:
            rh_acc_out[b, 0] = r
            k_acc_out[b, 0] = kb
            emit_out[b, 0] = emit
    if lr > 0.0 and not naive:
        for b in range(n):
            if delta[b] != 0.0:
                table[0 if shared else b, z[b, 0]] += lr * delta[b]
    for b in range(n):
        if naive:
            phi = eta if achieved_prev[b, 0] else 0.0
            phi_next = eta if z_next[b, 0] != z[b, 0] else 0.0
        else:
            row = 0 if shared else b
            phi = table[row, z[b, 0]]
            phi_next = table[row, z_next[b, 0]]
            if start_mode != START_VALUE:  # shift Φ so that the start's potential is 0 or ≤ 0
                v0 = table[row, z_start[b, 0]]
                c = v0 if start_mode == START_ZERO else max(v0, 0.0)
                phi -= c
                phi_next -= c
        if zero_terminal and terminated[b, 0]:
            phi_next = 0.0
        reward_out[b, 0] = reward[b, 0] + gamma * phi_next - phi


@numba.njit(cache=True, nogil=True, inline="always")
def _softmax_choice(q_row, inv_temperature, u, scratch):
    """Index drawn from softmax(q_row / τ) by inverse CDF with the uniform ``u``."""
    n_actions = q_row.shape[0]
    top = q_row[0]
    for i in range(1, n_actions):
        top = max(top, q_row[i])
    total = 0.0
    for i in range(n_actions):
        scratch[i] = np.exp((q_row[i] - top) * inv_temperature)
        total += scratch[i]
    threshold = u * total
    acc = 0.0
    for i in range(n_actions - 1):
        acc += scratch[i]
        if acc > threshold:
            return i
    return n_actions - 1


@numba.njit(cache=True, nogil=True)
def softmax_sample(q, state, inv_temperature, u, action_out):
    """``action_out[b] ~ softmax(q[b, state[b]] / τ)``."""
    scratch = np.empty(q.shape[2])
    for b in range(q.shape[0]):
        action_out[b] = _softmax_choice(q[b, state[b]], inv_temperature, u[b], scratch)


@numba.njit(cache=True, nogil=True)
def sarsa_step(
    q, s, a, reward, s_next, terminated, done, s_root, u, lr, gamma, inv_temperature, action_out
):
    """One SARSA(0) step per learner: draw ``a' ~ π(·|s')``, update ``Q(s, a)``, then
    the next action — ``a'``, or a fresh draw at the reset state where the episode ended.

    ``u`` holds two uniforms per learner (``[2n]``): for ``a'`` and for the reset draw.
    """
    n = q.shape[0]
    scratch = np.empty(q.shape[2])
    for b in range(n):
        a2 = _softmax_choice(q[b, s_next[b]], inv_temperature, u[b], scratch)
        target = reward[b]
        if not terminated[b]:
            target += gamma * q[b, s_next[b], a2]
        q[b, s[b], a[b]] += lr * (target - q[b, s[b], a[b]])
        if done[b]:
            a2 = _softmax_choice(q[b, s_root[b]], inv_temperature, u[n + b], scratch)
        action_out[b] = a2


@numba.njit(cache=True, nogil=True)
def grid_step(
    state, t, action, transitions, cells, goal, max_steps, goal_reward, step_reward, reward, terminated, truncated,
    cell_out,
):
    """Deterministic grid moves for a batch: next state, step count, reward (``goal_reward``
    on reaching the goal, else ``step_reward``) and flags."""
    for b in range(state.shape[0]):
        s = transitions[state[b], action[b]]
        state[b] = s
        t[b] += 1
        term = s == goal
        terminated[b] = term
        truncated[b] = (not term) and t[b] >= max_steps
        reward[b] = goal_reward if term else step_reward
        cell_out[b, 0] = cells[s, 0]
        cell_out[b, 1] = cells[s, 1]


@numba.njit(cache=True, nogil=True)
def record_episodes(
    done, terminated, reward, t, ret, episode, steps_out, returns_out, success_out
):
    """Advance per-learner step and return counters; file finished episodes.

    Returns how many episodes were filed (those past ``steps_out.shape[1]`` are not).
    """
    filed = 0
    max_episodes = steps_out.shape[1]
    for b in range(done.shape[0]):
        t[b] += 1
        ret[b] += reward[b]
        if done[b]:
            e = episode[b]
            if e < max_episodes:
                steps_out[b, e] = t[b]
                returns_out[b, e] = ret[b]
                success_out[b, e] = terminated[b]
                filed += 1
            episode[b] = e + 1
            t[b] = 0
            ret[b] = 0.0
    return filed


@numba.njit(cache=True, nogil=True)
def grid_reset(state, t, reset, start, cells, cell_out):
    """Put the learners flagged in ``reset`` back at ``start``; write every learner's cell."""
    for b in range(state.shape[0]):
        if reset[b]:
            state[b] = start
            t[b] = 0
        cell_out[b, 0] = cells[state[b], 0]
        cell_out[b, 1] = cells[state[b], 1]


NO_SHAPING, SUBGOAL_SHAPING, LOOKUP_SHAPING = 0, 1, 2


@numba.njit(cache=True, nogil=True, inline="always")
def shaping_buffers(n):
    """Per-step outputs of the fused runs' shaping, ``z'``, ``r_h'``, ``k'`` and the shaped
    reward, and the empty arrays that tell :func:`shape_step` to skip the SMDP transition."""
    return (np.empty((n, 1), np.int64), np.empty((n, 1), np.float32), np.empty((n, 1), np.int64),
            np.empty((n, 1), np.float32), np.empty((0, 1), np.float32), np.empty((0, 1), np.int64),
            np.empty((0, 1), np.bool_))


@numba.njit(cache=True, nogil=True)
def carry_abstract_states(reset, shaping, initial_z, z, achieved, r_h, k, z_next, rh_out, k_out):
    """Each learner's abstract state for the next step: the reset one where ``reset``,
    else this step's outputs (left alone without shaping)."""
    for b in range(z.shape[0]):
        if reset[b, 0]:
            z[b, 0] = initial_z
            achieved[b, 0] = False
            r_h[b, 0] = 0.0
            k[b, 0] = 0
        elif shaping != NO_SHAPING:
            achieved[b, 0] = z_next[b, 0] != z[b, 0]
            z[b, 0] = z_next[b, 0]
            r_h[b, 0] = rh_out[b, 0]
            k[b, 0] = k_out[b, 0]


@numba.njit(cache=True, nogil=True)
def sarsa_grid_run(
    # the grid env (its state arrays are updated in place)
    state, t_env, transitions, cells, start, goal, max_steps, goal_reward, step_reward,
    # the shaping transform: which abstraction, its tables, its per-learner state and the potential
    shaping, observe_cell, pattern, lo, hi, centre, weight, radius2, succ, lookup, initial_z,
    z, achieved, r_h, k, table, shared, eta, gamma_shaping, value_gamma, value_lr, zero_terminal, start_mode,
    z_start,
    # the SARSA learners
    q, abstract_states, action, lr, gamma, inv_temperature, uniforms,
    # episode records
    t_rec, ret, episode, steps_out, returns_out, success_out,
):
    """Run steps of grid world + shaping + SARSA until every learner has its episodes.

    The same kernels, in the same order and with the same random numbers, as one
    iteration of :func:`torchrl_subgoal.agents.run_episodes` with a
    ``TransformedEnv(FourRoomsEnv, SubgoalPotentialTransform)`` and a
    :class:`~torchrl_subgoal.agents.SoftmaxSarsa`: env step, transform step,
    reset of finished learners, SARSA step, records. At most
    ``uniforms.shape[0]`` steps; returns ``(steps taken, episodes filed)``.
    """
    n = state.shape[0]
    reward = np.empty((n, 1), np.float32)
    terminated = np.empty((n, 1), np.bool_)
    truncated = np.empty((n, 1), np.bool_)
    done = np.empty((n, 1), np.bool_)
    cell = np.empty((n, 2), np.int64)
    z_next, rh_out, k_out, shaped, no_f, no_i, no_b = shaping_buffers(n)
    rows = np.empty(n, np.int64)
    rows_next = np.empty(n, np.int64)
    rows_root = np.empty(n, np.int64)
    next_action = np.empty(n, np.int64)
    max_episodes = steps_out.shape[1]
    filed_total = 0
    for step in range(uniforms.shape[0]):
        for b in range(n):
            rows[b] = state[b] * abstract_states + (z[b, 0] if abstract_states > 1 else 0)
        grid_step(state, t_env, action, transitions, cells, goal, max_steps, goal_reward, step_reward,
                  reward[:, 0], terminated[:, 0], truncated[:, 0], cell)
        for b in range(n):
            done[b, 0] = terminated[b, 0] or truncated[b, 0]
        if shaping == SUBGOAL_SHAPING:
            if observe_cell:
                advance_regions(z, cell, pattern, lo, hi, centre, weight, radius2, succ, z_next)
            else:
                advance_regions(z, state.reshape((n, 1)), pattern, lo, hi, centre, weight, radius2, succ, z_next)
        elif shaping == LOOKUP_SHAPING:
            for b in range(n):
                z_next[b, 0] = lookup[state[b]]
        if shaping == NO_SHAPING:
            shaped[:, 0] = reward[:, 0]
        else:
            shape_step(z, z_next, achieved, r_h, k, reward, done, terminated, table, shared, eta, gamma_shaping,
                       value_gamma, value_lr, zero_terminal, start_mode, z_start, rh_out, k_out, shaped, no_f, no_i,
                       no_b)
        for b in range(n):
            zn = z_next[b, 0] if shaping != NO_SHAPING else 0
            rows_next[b] = state[b] * abstract_states + (zn if abstract_states > 1 else 0)
            if done[b, 0]:  # the env and the transform reset this learner
                state[b] = start
                t_env[b] = 0
        carry_abstract_states(done, shaping, initial_z, z, achieved, r_h, k, z_next, rh_out, k_out)
        for b in range(n):
            rows_root[b] = state[b] * abstract_states + (z[b, 0] if abstract_states > 1 else 0)
        sarsa_step(q, rows, action, shaped[:, 0], rows_next, terminated[:, 0], done[:, 0], rows_root,
                   uniforms[step], lr, gamma, inv_temperature, next_action)
        filed_total += record_episodes(done[:, 0], terminated[:, 0], reward[:, 0], t_rec, ret, episode,
                                       steps_out, returns_out, success_out)
        action[:] = next_action
        if episode.min() >= max_episodes:
            return step + 1, filed_total
    return uniforms.shape[0], filed_total


@numba.njit(cache=True, nogil=True)
def first_region(z, obs, lo, hi, centre, weight, radius2, z_out):
    """``z_out[b]``: the first region (shared ``[J, D]`` tables) containing ``obs[b]``, else ``z[b]``."""
    for b in range(obs.shape[0]):
        z_out[b, 0] = z[b, 0]
        for j in range(lo.shape[0]):
            if _in_region(obs[b], lo[j], hi[j], centre[j], weight[j], radius2[j]):
                z_out[b, 0] = j
                break


@numba.njit(cache=True, nogil=True, inline="always", fastmath=True)
def _basis_exponentials(obs, low, inv_range, k, first_dim, end_dim, out):
    """``out[i] = exp(iπ c_i · s̃)`` over dimensions ``[first_dim, end_dim)``, with ``c_i``
    the base-``k`` digits of ``i`` (last dimension least significant), as (re, im) pairs."""
    for i in range(out.shape[0]):
        re, im, rem = 1.0, 0.0, i
        for d in range(end_dim - 1, first_dim - 1, -1):
            c = rem % k
            rem //= k
            x = min(max((obs[d] - low[d]) * inv_range[d], 0.0), 1.0)
            angle = np.pi * c * x
            cr, ci = np.cos(angle), np.sin(angle)
            re, im = re * cr - im * ci, re * ci + im * cr
        out[i, 0], out[i, 1] = re, im


@numba.njit(cache=True, nogil=True, inline="always", fastmath=True)
def fourier_features(obs, low, inv_range, order, half, first, second, out):
    """``out[f] = cos(π c_f · s̃)`` for every coefficient vector ``c_f ∈ {0..order}^D`` in
    lexicographic order, ``s̃ = clip((obs - low) / range, 0, 1)``.

    Computed as ``Re(A_a B_b)`` with ``f = a·M + b``: ``A`` are the complex
    exponentials of the first ``half`` dimensions, ``B`` of the others (one
    complex product per feature instead of a cosine).
    """
    _basis_exponentials(obs, low, inv_range, order + 1, 0, half, first)
    _basis_exponentials(obs, low, inv_range, order + 1, half, obs.shape[0], second)
    n_second = second.shape[0]
    for a in range(first.shape[0]):
        for b in range(n_second):
            out[a * n_second + b] = first[a, 0] * second[b, 0] - first[a, 1] * second[b, 1]


@numba.njit(cache=True, nogil=True, inline="always", fastmath=True)
def _policy(theta_b, phi, probs):
    """``probs`` ← softmax(θ φ)."""
    n_actions, n_features = theta_b.shape
    top = -np.inf
    for a in range(n_actions):
        s = 0.0
        for f in range(n_features):
            s += theta_b[a, f] * phi[f]
        probs[a] = s
        top = max(top, s)
    total = 0.0
    for a in range(n_actions):
        probs[a] = np.exp(probs[a] - top)
        total += probs[a]
    for a in range(n_actions):
        probs[a] /= total


@numba.njit(cache=True, nogil=True, inline="always", fastmath=True)
def _policy_sample(theta_b, phi, u, logits):
    """Draw from softmax(θ φ) with the uniform ``u``; ``logits`` is filled with π."""
    _policy(theta_b, phi, logits)
    n_actions = theta_b.shape[0]
    acc = 0.0
    for a in range(n_actions - 1):
        acc += logits[a]
        if acc > u:
            return a
    return n_actions - 1


@numba.njit(cache=True, nogil=True, fastmath=True)
def ac_act(theta, phi, probs, obs, low, inv_range, order, half, u, action_out):
    """Features of ``obs`` into ``phi``, the policy into ``probs`` and a first action per learner."""
    first, second, _ = _feature_scratch(order, half, obs.shape[1], 0)
    for b in range(obs.shape[0]):
        fourier_features(obs[b], low, inv_range, order, half, first, second, phi[b])
        action_out[b] = _policy_sample(theta[b], phi[b], u[b], probs[b])


@numba.njit(cache=True, nogil=True, inline="always")
def _feature_scratch(order, half, dim, n_features):
    """Scratch arrays of :func:`fourier_features` (the two halves' exponentials) and a feature vector."""
    return np.empty(((order + 1) ** half, 2)), np.empty(((order + 1) ** (dim - half), 2)), np.empty(n_features)


@numba.njit(cache=True, nogil=True, inline="always", fastmath=True)
def _policy_gradient_step(theta_b, phi_b, probs_b, a_taken, lr, scale, signal):
    """``θ += lr · scale · signal · (1[a] − π(·|s)) ⊗ φ(s)``: the actor step of both actor-critics."""
    for a in range(theta_b.shape[0]):
        g = ((1.0 if a == a_taken else 0.0) - probs_b[a]) * lr * scale * signal
        for f in range(theta_b.shape[1]):
            theta_b[a, f] += g * phi_b[f]


@numba.njit(cache=True, nogil=True, fastmath=True)
def ac_step(
    w, theta, phi, probs, action, reward, obs_next, terminated, done, obs_root, active,
    low, inv_range, order, half, u, actor_lr, critic_lr, gamma, normalize, action_out,
):
    """One-step actor-critic for every active learner.

    ``δ = r + γ V(s') (1 − terminated) − V(s)``, ``V = w·φ``; ``w += α_c δ φ(s)``;
    ``θ += α_a δ (1[a] − π(·|s)) ⊗ φ(s)``; with ``normalize`` both rates are
    divided by ``‖φ(s)‖``. ``phi`` and ``probs`` hold each learner's ``φ(s)``
    and ``π(·|s)`` (computed when its action was drawn; ``θ`` has not changed
    since) and are replaced by those of the next state (``s'``, or the reset
    state where the episode ended), from which the next action is drawn with ``u``.
    """
    n_features = theta.shape[2]
    first, second, phi_next = _feature_scratch(order, half, obs_next.shape[1], n_features)
    for b in range(w.shape[0]):
        if not active[b]:
            continue
        fourier_features(obs_next[b], low, inv_range, order, half, first, second, phi_next)
        value = 0.0
        value_next = 0.0
        norm2 = 0.0
        for f in range(n_features):
            value += w[b, f] * phi[b, f]
            value_next += w[b, f] * phi_next[f]
            norm2 += phi[b, f] * phi[b, f]
        delta = reward[b] - value
        if not terminated[b]:
            delta += gamma * value_next
        scale = 1.0 / np.sqrt(norm2) if normalize else 1.0
        _policy_gradient_step(theta[b], phi[b], probs[b], action[b], actor_lr, scale, delta)
        c = critic_lr * scale * delta
        for f in range(n_features):
            w[b, f] += c * phi[b, f]
        if done[b]:
            fourier_features(obs_root[b], low, inv_range, order, half, first, second, phi_next)
        for f in range(n_features):
            phi[b, f] = phi_next[f]
        action_out[b] = _policy_sample(theta[b], phi[b], u[b], probs[b])


@numba.njit(cache=True, nogil=True, fastmath=True)
def qac_step(
    w, theta, phi, probs, action, reward, obs_next, terminated, done, obs_root, active,
    low, inv_range, order, half, u, actor_lr, critic_lr, gamma, normalize, action_out,
):
    """One step of the Q-based actor-critic (the authors' released PinBall agent) for every active learner.

    ``w`` is ``[B, A·F]``: a linear critic ``Q(s, a) = w_a·φ(s)`` per action.
    First ``a' ~ π(·|s')`` is drawn with ``u[b]`` (the policy before this
    step's update). Then, with ``q = Q(s, a)`` before the critic's update:
    ``θ += α_a q (1[a] − π(·|s)) ⊗ φ(s)`` (``π`` with the current ``θ``) and
    ``w_a += α_c δ φ(s)``, ``δ = r + γ Q(s', a') (1 − terminated) − q``; with
    ``normalize`` both rates are divided by ``‖φ(s)‖``. Where the episode
    ended the next action is drawn at the reset state with ``u[n + b]``
    (``u`` is ``[2n]``). ``phi`` holds each learner's ``φ(s)`` and becomes
    that of the next state; ``probs`` is scratch.
    """
    n = w.shape[0]
    n_features = theta.shape[2]
    first, second, phi_next = _feature_scratch(order, half, obs_next.shape[1], n_features)
    for b in range(n):
        if not active[b]:
            continue
        fourier_features(obs_next[b], low, inv_range, order, half, first, second, phi_next)
        a_next = _policy_sample(theta[b], phi_next, u[b], probs[b])
        a_taken = action[b]
        q = 0.0
        q_next = 0.0
        norm2 = 0.0
        for f in range(n_features):
            q += w[b, a_taken * n_features + f] * phi[b, f]
            q_next += w[b, a_next * n_features + f] * phi_next[f]
            norm2 += phi[b, f] * phi[b, f]
        scale = 1.0 / np.sqrt(norm2) if normalize else 1.0
        _policy(theta[b], phi[b], probs[b])
        _policy_gradient_step(theta[b], phi[b], probs[b], a_taken, actor_lr, scale, q)
        delta = reward[b] - q
        if not terminated[b]:
            delta += gamma * q_next
        c = critic_lr * scale * delta
        for f in range(n_features):
            w[b, a_taken * n_features + f] += c * phi[b, f]
        if done[b]:
            fourier_features(obs_root[b], low, inv_range, order, half, first, second, phi_next)
            a_next = _policy_sample(theta[b], phi_next, u[n + b], probs[b])
        for f in range(n_features):
            phi[b, f] = phi_next[f]
        action_out[b] = a_next


@numba.njit(cache=True, nogil=True)
def advance_and_shape(
    z, obs, pattern, lo, hi, centre, weight, radius2, succ, achieved, r_h, k, reward, done, terminated,
    table, shared, eta, gamma, value_gamma, value_lr, zero_terminal, start_mode, z_start,
    z_out, rh_out, k_out, reward_out, rh_acc_out, k_acc_out, emit_out,
):
    """:func:`advance_regions` then :func:`shape_step`: one transform step in one call."""
    advance_regions(z, obs, pattern, lo, hi, centre, weight, radius2, succ, z_out)
    shape_step(z, z_out, achieved, r_h, k, reward, done, terminated, table, shared, eta, gamma,
               value_gamma, value_lr, zero_terminal, start_mode, z_start, rh_out, k_out, reward_out, rh_acc_out,
               k_acc_out, emit_out)
