"""The linear actor-critics over a Fourier basis (the paper's PinBall learners)."""

from __future__ import annotations

import numba
import numpy as np

from torchrl_subgoal._kernels.random import _exp_shifted, _inverse_cdf, uniform

# --------------------------------------------------------------------------- linear actor-critics
#
# ``fastmath`` lets LLVM vectorise these loops (about 30% of a PinBall learner-step). The
# per-learner steps (:func:`_ac_learner`, :func:`_qac_learner`) are compiled once, not
# inlined, and called by both the batch kernels (the TorchRL loop) and the fused engine, so
# the two run the same machine code and agree bit for bit (``tests/fused/test_engine.py``).
# Numba's on-disk cache of a compiled caller is keyed on its own file only: after editing
# this file, delete the ``__pycache__/*.nb[ic]`` of ``engine.py`` next to it (or touch that file).


@numba.njit(cache=True, nogil=True, inline="always", fastmath=True)
def _dot(x, y):
    """``Σ x[f] y[f]`` over ``x``'s length, as four interleaved partial sums."""
    n = x.shape[0]
    s0 = s1 = s2 = s3 = 0.0
    f = 0
    while f + 4 <= n:
        s0 += x[f] * y[f]
        s1 += x[f + 1] * y[f + 1]
        s2 += x[f + 2] * y[f + 2]
        s3 += x[f + 3] * y[f + 3]
        f += 4
    while f < n:
        s0 += x[f] * y[f]
        f += 1
    return (s0 + s1) + (s2 + s3)


@numba.njit(cache=True, nogil=True, inline="always", fastmath=True)
def _basis_exponentials(trig, k, first_dim, end_dim, out):
    """``out[:, i] = exp(iπ c_i · s̃)`` over dimensions ``[first_dim, end_dim)``, with ``c_i``
    the base-``k`` digits of ``i`` (last dimension least significant), as rows (re, im).

    Built from the last dimension up, each product ``(exponentials of the later dimensions)
    × trig[d, c]``, in place: the products of :func:`fourier_features`' definition in the
    same order, without recomputing a dimension's cosines for every entry.
    """
    out[0, 0], out[1, 0] = 1.0, 0.0
    size = 1
    for d in range(end_dim - 1, first_dim - 1, -1):
        for c in range(k - 1, -1, -1):  # c = 0 last: it overwrites the entries it reads
            cr, ci = trig[d, c, 0], trig[d, c, 1]
            for j in range(size):
                re, im = out[0, j], out[1, j]
                out[0, c * size + j], out[1, c * size + j] = re * cr - im * ci, re * ci + im * cr
        size *= k


@numba.njit(cache=True, nogil=True, inline="always", fastmath=True)
def fourier_features(obs, low, inv_range, order, half, scratch, out):
    """``out[f] = cos(π c_f · s̃)`` for every coefficient vector ``c_f ∈ {0..order}^D`` in
    lexicographic order, ``s̃ = clip((obs - low) / range, 0, 1)``.

    Computed as ``Re(A_a B_b)`` with ``f = a·M + b``: ``A`` are the complex
    exponentials of the first ``half`` dimensions, ``B`` of the others (one
    complex product per feature instead of a cosine); each is a product of the
    per-dimension ``exp(iπ c s̃_d)``, the powers of ``exp(iπ s̃_d)`` (one cosine
    and one sine per dimension; equal to ``cos(π c s̃_d)`` and ``sin(π c s̃_d)``
    within a few units in the last place).
    ``scratch`` is :func:`_feature_scratch`'s.
    """
    first, second, trig = scratch
    k = order + 1
    for d in range(obs.shape[0]):  # exp(iπ c s̃_d) = exp(iπ s̃_d)^c: two trigonometric calls per dimension
        x = min(max((obs[d] - low[d]) * inv_range[d], 0.0), 1.0)
        cr, ci = np.cos(np.pi * x), np.sin(np.pi * x)
        trig[d, 0, 0], trig[d, 0, 1] = 1.0, 0.0
        for c in range(1, k):
            re, im = trig[d, c - 1, 0], trig[d, c - 1, 1]
            trig[d, c, 0], trig[d, c, 1] = re * cr - im * ci, re * ci + im * cr
    _basis_exponentials(trig, k, 0, half, first)
    _basis_exponentials(trig, k, half, obs.shape[0], second)
    n_second = second.shape[1]
    second_re, second_im = second[0], second[1]  # rows: the loop below reads contiguous entries
    for a in range(first.shape[1]):
        first_re, first_im = first[0, a], first[1, a]
        out_a = out[a * n_second : (a + 1) * n_second]
        for b in range(n_second):
            out_a[b] = first_re * second_re[b] - first_im * second_im[b]


@numba.njit(cache=True, nogil=True, inline="always", fastmath=True)
def _policy(theta_b, phi, probs):
    """``probs`` ← softmax(θ φ)."""
    n_actions = theta_b.shape[0]
    top = -np.inf
    for a in range(n_actions):
        s = _dot(theta_b[a], phi)
        probs[a] = s
        top = max(top, s)
    total = _exp_shifted(probs, top, 1.0, probs)
    for a in range(n_actions):
        probs[a] /= total


@numba.njit(cache=True, nogil=True, inline="always", fastmath=True)
def _policy_sample(theta_b, phi, u, logits):
    """Draw from softmax(θ φ) with the uniform ``u``; ``logits`` is filled with π."""
    _policy(theta_b, phi, logits)
    return _inverse_cdf(logits, u)


@numba.njit(cache=True, nogil=True, fastmath=True)
def ac_act(theta, phi, probs, obs, low, inv_range, order, half, streams, action_out):
    """Features of ``obs`` into ``phi``, the policy into ``probs`` and a first action per learner
    (drawn from its stream; an empty ``streams`` draws nothing and leaves ``action_out`` alone)."""
    scratch, _ = _feature_scratch(order, half, obs.shape[1], 0)
    for b in range(obs.shape[0]):
        fourier_features(obs[b], low, inv_range, order, half, scratch, phi[b])
        if streams.shape[0] > 0:
            action_out[b] = _policy_sample(theta[b], phi[b], uniform(streams, b), probs[b])
        else:
            _policy(theta[b], phi[b], probs[b])


@numba.njit(cache=True, nogil=True, inline="always", fastmath=True)
def _feature_scratch(order, half, dim, n_features):
    """Scratch arrays of :func:`fourier_features` (the two halves' exponentials and the per-dimension
    ones) and a feature vector."""
    scratch = (
        np.empty((2, (order + 1) ** half)),
        np.empty((2, (order + 1) ** (dim - half))),
        np.empty((dim, order + 1, 2)),
    )
    return scratch, np.empty(n_features)


@numba.njit(cache=True, nogil=True, inline="always", fastmath=True)
def _policy_gradient_step(theta_b, phi_b, probs_b, a_taken, lr, scale, signal):
    """``θ += lr · scale · signal · (1[a] − π(·|s)) ⊗ φ(s)``: the actor step of both actor-critics."""
    for a in range(theta_b.shape[0]):
        g = ((1.0 if a == a_taken else 0.0) - probs_b[a]) * lr * scale * signal
        for f in range(theta_b.shape[1]):
            theta_b[a, f] += g * phi_b[f]


@numba.njit(cache=True, nogil=True, fastmath=True)
def _ac_learner(
    b,
    w,
    theta,
    phi,
    probs,
    a_taken,
    reward,
    obs_next,
    terminated,
    done,
    obs_root,
    low,
    inv_range,
    order,
    half,
    streams,
    actor_lr,
    critic_lr,
    gamma,
    normalize,
    scratch,
    phi_next,
):
    """:func:`ac_step` for learner ``b``; returns its next action."""
    n_features = theta.shape[2]
    fourier_features(obs_next, low, inv_range, order, half, scratch, phi_next)
    value = _dot(w[b], phi[b])
    value_next = _dot(w[b], phi_next)
    norm2 = _dot(phi[b], phi[b])
    delta = reward - value
    if not terminated:
        delta += gamma * value_next
    scale = 1.0 / np.sqrt(norm2) if normalize else 1.0
    _policy_gradient_step(theta[b], phi[b], probs[b], a_taken, actor_lr, scale, delta)
    c = critic_lr * scale * delta
    for f in range(n_features):
        w[b, f] += c * phi[b, f]
    if done:
        fourier_features(obs_root, low, inv_range, order, half, scratch, phi_next)
    for f in range(n_features):
        phi[b, f] = phi_next[f]
    return _policy_sample(theta[b], phi[b], uniform(streams, b), probs[b])


@numba.njit(cache=True, nogil=True, fastmath=True)
def ac_step(
    w,
    theta,
    phi,
    probs,
    action,
    reward,
    obs_next,
    terminated,
    done,
    obs_root,
    low,
    inv_range,
    order,
    half,
    streams,
    actor_lr,
    critic_lr,
    gamma,
    normalize,
    action_out,
):
    """One-step actor-critic for every learner.

    ``δ = r + γ V(s') (1 − terminated) − V(s)``, ``V = w·φ``; ``w += α_c δ φ(s)``;
    ``θ += α_a δ (1[a] − π(·|s)) ⊗ φ(s)``; with ``normalize`` both rates are
    divided by ``‖φ(s)‖``. ``phi`` and ``probs`` hold each learner's ``φ(s)``
    and ``π(·|s)`` (computed when its action was drawn; ``θ`` has not changed
    since) and are replaced by those of the next state (``s'``, or the reset
    state where the episode ended), from which the next action is drawn with
    one uniform of the learner's stream.
    """
    scratch, phi_next = _feature_scratch(order, half, obs_next.shape[1], theta.shape[2])
    for b in range(w.shape[0]):
        action_out[b] = _ac_learner(
            b,
            w,
            theta,
            phi,
            probs,
            action[b],
            reward[b],
            obs_next[b],
            terminated[b],
            done[b],
            obs_root[b],
            low,
            inv_range,
            order,
            half,
            streams,
            actor_lr,
            critic_lr,
            gamma,
            normalize,
            scratch,
            phi_next,
        )


@numba.njit(cache=True, nogil=True, fastmath=True)
def _qac_learner(
    b,
    w,
    theta,
    phi,
    probs,
    a_taken,
    reward,
    obs_next,
    terminated,
    done,
    obs_root,
    low,
    inv_range,
    order,
    half,
    streams,
    actor_lr,
    critic_lr,
    gamma,
    normalize,
    scratch,
    phi_next,
):
    """:func:`qac_step` for learner ``b``; returns its next action."""
    n_features = theta.shape[2]
    fourier_features(obs_next, low, inv_range, order, half, scratch, phi_next)
    a_next = _policy_sample(theta[b], phi_next, uniform(streams, b), probs[b])
    q = _dot(w[b, a_taken * n_features : (a_taken + 1) * n_features], phi[b])
    q_next = _dot(w[b, a_next * n_features : (a_next + 1) * n_features], phi_next)
    norm2 = _dot(phi[b], phi[b])
    scale = 1.0 / np.sqrt(norm2) if normalize else 1.0
    _policy(theta[b], phi[b], probs[b])
    _policy_gradient_step(theta[b], phi[b], probs[b], a_taken, actor_lr, scale, q)
    delta = reward - q
    if not terminated:
        delta += gamma * q_next
    c = critic_lr * scale * delta
    first = np.uint64(a_taken * n_features)  # an unsigned index: no negative-index test, so the loop vectorises
    for f in range(n_features):
        w[b, first + np.uint64(f)] += c * phi[b, f]
    if done:
        fourier_features(obs_root, low, inv_range, order, half, scratch, phi_next)
        a_next = _policy_sample(theta[b], phi_next, uniform(streams, b), probs[b])
    for f in range(n_features):
        phi[b, f] = phi_next[f]
    return a_next


@numba.njit(cache=True, nogil=True, fastmath=True)
def qac_step(
    w,
    theta,
    phi,
    probs,
    action,
    reward,
    obs_next,
    terminated,
    done,
    obs_root,
    low,
    inv_range,
    order,
    half,
    streams,
    actor_lr,
    critic_lr,
    gamma,
    normalize,
    action_out,
):
    """One step of the Q-based actor-critic (the authors' released PinBall agent) for every learner.

    ``w`` is ``[B, A·F]``: a linear critic ``Q(s, a) = w_a·φ(s)`` per action.
    First ``a' ~ π(·|s')`` is drawn from the learner's stream (the policy
    before this step's update). Then, with ``q = Q(s, a)`` before the critic's
    update: ``θ += α_a q (1[a] − π(·|s)) ⊗ φ(s)`` (``π`` with the current
    ``θ``) and ``w_a += α_c δ φ(s)``, ``δ = r + γ Q(s', a') (1 − terminated) − q``;
    with ``normalize`` both rates are divided by ``‖φ(s)‖``. Where the episode
    ended the next action is drawn at the reset state with one more uniform.
    ``phi`` holds each learner's ``φ(s)`` and becomes that of the next state;
    ``probs`` is scratch.
    """
    scratch, phi_next = _feature_scratch(order, half, obs_next.shape[1], theta.shape[2])
    for b in range(w.shape[0]):
        action_out[b] = _qac_learner(
            b,
            w,
            theta,
            phi,
            probs,
            action[b],
            reward[b],
            obs_next[b],
            terminated[b],
            done[b],
            obs_root[b],
            low,
            inv_range,
            order,
            half,
            streams,
            actor_lr,
            critic_lr,
            gamma,
            normalize,
            scratch,
            phi_next,
        )


@numba.njit(cache=True, nogil=True, inline="always")
def ac_learner_step(learner, b, a, reward, obs_next, terminated, done, obs_root, scratch, phi_next):
    """Learner ``b``'s step of an :class:`~torchrl_subgoal.fused.actor_critic.ActorCriticKernelState`
    (:func:`_qac_learner` or :func:`_ac_learner`, by its critic); returns its next action."""
    L = learner
    if L.q_critic:
        return _qac_learner(
            b,
            L.w,
            L.theta,
            L.phi,
            L.probs,
            a,
            reward,
            obs_next,
            terminated,
            done,
            obs_root,
            L.low,
            L.inv_range,
            L.order,
            L.half,
            L.streams,
            L.actor_lr,
            L.critic_lr,
            L.gamma,
            L.normalize,
            scratch,
            phi_next,
        )
    return _ac_learner(
        b,
        L.w,
        L.theta,
        L.phi,
        L.probs,
        a,
        reward,
        obs_next,
        terminated,
        done,
        obs_root,
        L.low,
        L.inv_range,
        L.order,
        L.half,
        L.streams,
        L.actor_lr,
        L.critic_lr,
        L.gamma,
        L.normalize,
        scratch,
        phi_next,
    )
