"""Property tests: the compiled (numba) and the reference (torch) paths agree on every input.

Random observations, rewards and dones, including NaN, ±inf, float64 values one ulp
either side of a region's bound or a circle's rim, float32 and integer observations,
chains and partial orders, and random batch shapes. Hypothesis runs derandomized, so
CI sees the same examples every time (no timing: ``deadline=None``).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from torchrl_subgoal import (
    Box,
    Cell,
    Circle,
    SubgoalPotentialTransform,
    SubgoalSeries,
    TabularPotential,
)
from torchrl_subgoal.potentials import ACHIEVED, INDEX
from torchrl_subgoal.subgoals import Predicate, StateAggregation, SubgoalTables
from torchrl_subgoal.subgoals.tables import _in_regions
from torchrl_subgoal.transform import RETURN, STEPS, SubgoalKeys
from torchrl_subgoal.transform.keys import StepInputs

D = 3  # observation entries
PROPERTY = settings(
    max_examples=150,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)

coords = st.sampled_from([-1.0, 0.0, 0.1, 0.3, 1 / 3, 0.5, 2.0, 7.0])
predicates: st.SearchStrategy[Predicate] = st.one_of(
    st.builds(lambda r, c: Cell(r, c, (0, 2)), st.integers(0, 3), st.integers(0, 3)),
    st.builds(
        lambda c, r, d: Circle(tuple(c), r, d),
        st.lists(coords, min_size=2, max_size=2),
        st.sampled_from([0.04, 0.1, 0.5, 1.0]),
        st.sampled_from([(0, 1), (1, 2), (2, 0)]),
    ),
    st.builds(
        lambda c, m, d: Box((c,), (m,), (d,)), coords, st.sampled_from([0.0, 0.04, 1 / 6, 1.0]), st.integers(0, D - 1)
    ),
)


@st.composite
def patterns(draw: st.DrawFn) -> list[SubgoalSeries]:
    out = []
    for p in range(draw(st.integers(1, 3))):
        preds = draw(st.lists(predicates, min_size=1, max_size=4))
        n = len(preds)
        pairs = [(a, b) for a in range(n) for b in range(a + 1, n)]
        order = draw(st.none() | st.lists(st.sampled_from(pairs), unique=True)) if pairs else None
        out.append(SubgoalSeries(preds, order=order, name=f"p{p}"))
    return out


def near(values: list[float]) -> list[float]:
    """Each value, as float32 and float64, and one float64 ulp either side of it."""
    out = []
    for v in values:
        v32 = float(np.float32(v)) if abs(v) < 3e38 else v
        out += [v, v32, math.nextafter(v32, math.inf), math.nextafter(v32, -math.inf)]
    return out


def interesting_values(series: list[SubgoalSeries]) -> list[float]:
    """Region bounds, circle rims and the values that break comparisons."""
    values: list[float] = [math.nan, math.inf, -math.inf, 0.0, -0.0, 1e300]
    for s in series:
        for pred in s.predicates:
            if isinstance(pred, Cell):
                values += [pred.row, pred.col]
            elif isinstance(pred, Circle):
                values += [c + sign * pred.radius for c in pred.centre for sign in (-1, 0, 1)]
                values += [c + pred.radius / math.sqrt(2) for c in pred.centre]
            elif isinstance(pred, Box):
                values += [c + sign * m for c, m in zip(pred.centre, pred.margin, strict=True) for sign in (-1, 0, 1)]
    return near(values)


@st.composite
def batch(draw: st.DrawFn) -> tuple[list[SubgoalSeries], torch.Size, torch.Tensor, torch.Tensor, torch.Tensor]:
    series = draw(patterns())
    shape = torch.Size(draw(st.lists(st.integers(1, 4), min_size=1, max_size=2)))
    n = shape.numel()
    index = torch.tensor(draw(st.lists(st.integers(0, len(series) - 1), min_size=n, max_size=n))).reshape(shape)
    z = torch.tensor([draw(st.integers(0, len(series[int(i)]))) for i in index.reshape(-1)]).reshape(*shape, 1)
    dtype = draw(st.sampled_from([torch.float64, torch.float32, torch.int64]))
    pool = interesting_values(series)
    if dtype == torch.int64:
        pool = [float(int(v)) for v in pool if math.isfinite(v) and abs(v) < 1e9]
    values = draw(st.lists(st.sampled_from(pool) | st.floats(-3, 8), min_size=n * D, max_size=n * D))
    obs = torch.tensor(values, dtype=torch.float64).to(dtype).reshape(*shape, D)
    return series, shape, index, z, obs


@PROPERTY
@given(batch())
def test_region_tests_agree(case: tuple) -> None:
    series, _, index, z, obs = case
    tables = SubgoalTables(series, index, D)
    assert torch.equal(tables.advance(z, obs), tables.advance_eager(z, obs))


@PROPERTY
@given(batch())
def test_first_region_agrees_with_torch(case: tuple) -> None:
    """``StateAggregation.from_regions`` (kernel only) against the torch region test."""
    series, _, _, z, obs = case
    regions = [pred for s in series for pred in s.predicates]
    agg = StateAggregation.from_regions(regions, D)
    if int(z.max()) >= len(regions):  # not an abstract state of this aggregation: refused, never read
        with pytest.raises(ValueError, match="abstract states must lie in"):
            agg.advance(z, obs)
        z = z.clamp(max=len(regions) - 1)
    compiled = [p.region(D) for p in regions]
    stack = {k: torch.stack([getattr(r, k) for r in compiled]) for k in ("lo", "hi", "centre", "weight")}
    radius2 = torch.tensor([r.radius2 for r in compiled], dtype=torch.float32)
    flat = obs.reshape(-1, 1, D).to(torch.float64)
    inside = _in_regions(flat, stack["lo"], stack["hi"], stack["centre"], stack["weight"], radius2, True)
    first = torch.where(inside.any(-1), inside.long().argmax(-1), z.reshape(-1))
    assert torch.equal(agg.advance(z, obs).reshape(-1), first)
    assert torch.equal(agg.advance_eager(z, obs).reshape(-1), first)


rewards = st.sampled_from([0.0, 1.0, -1.0, 0.5, 1e-3, math.nan, math.inf, -math.inf]) | st.floats(-10, 10)


def one_step(
    t: SubgoalPotentialTransform,
    current: dict[str, torch.Tensor],
    obs: torch.Tensor,
    reward: torch.Tensor,
    done: torch.Tensor,
    terminated: torch.Tensor,
    shape: torch.Size,
    obs_before: torch.Tensor | None = None,
) -> dict:
    """One step of ``t`` (set up for a batch of ``shape``, learning online) from the entries ``current``."""
    n = shape.numel()
    setup = t._batch(shape, torch.arange(n).reshape(*shape, 1), n, obs, online=True)
    if t.keys.learner in t._settings.kept:  # a backend's step reads every kept entry
        current.setdefault(t.keys.learner, setup.learner)
    step = StepInputs(obs, reward, reward, done, terminated, None, obs_before)
    return setup.backend.step(setup, current, step, True)


@PROPERTY
@given(batch(), st.data())
def test_shaping_paths_agree(case: tuple, data: st.DataObject) -> None:
    """One transform step through the compiled kernels and through torch operations only:
    the same abstract states, accumulators, shaped rewards and trained tables, or the
    same error for a NaN/inf reward or a NaN observation; with or without the monotone lift and the
    within-segment term (read at the step's starting observation, another row's)."""
    series, shape, index, z, obs = case
    monotone, interpolate = data.draw(st.booleans()), data.draw(st.booleans())
    obs_before = obs.reshape(-1, obs.shape[-1]).roll(1, 0).reshape(obs.shape)
    n = shape.numel()
    r = torch.tensor(data.draw(st.lists(rewards, min_size=n, max_size=n)), dtype=torch.float32).reshape(*shape, 1)
    done = torch.tensor(data.draw(st.lists(st.booleans(), min_size=n, max_size=n))).reshape(*shape, 1)
    terminated = done & torch.tensor(data.draw(st.lists(st.booleans(), min_size=n, max_size=n))).reshape(*shape, 1)
    k = torch.tensor(data.draw(st.lists(st.integers(0, 50), min_size=n, max_size=n))).reshape(*shape, 1)
    r_h = torch.tensor(data.draw(st.lists(st.floats(-5, 5), min_size=n, max_size=n)), dtype=torch.float32).reshape(
        *shape, 1
    )
    states = max(len(s) for s in series) + 1
    table = torch.randn(*shape, states, generator=torch.Generator().manual_seed(data.draw(st.integers(0, 99))))
    outcomes = []
    for backend in ("compiled", "torch"):
        potential = TabularPotential(states, batch_shape=shape, monotone=monotone, interpolate=interpolate)
        with torch.no_grad():
            potential.table.copy_(table)
        t = SubgoalPotentialTransform(
            [series[int(i)] for i in index.reshape(-1)],
            potential,
            gamma=0.9,
            value_update=0.5,
            keys=SubgoalKeys(transitions="smdp"),
        ).use_backend(backend)  # type: ignore[arg-type]
        current = {INDEX: z.clone(), RETURN: r_h.clone(), STEPS: k.clone(), ACHIEVED: torch.zeros_like(done)}
        try:
            out = one_step(t, current, obs, r.clone(), done, terminated, shape, obs_before)
        except ValueError as exc:
            outcomes.append(("error", str(exc), potential.table.detach().clone()))
            continue
        outcomes.append(("ok", out, potential.table.detach().clone()))
    (kind_f, out_f, table_f), (kind_e, out_e, table_e) = outcomes
    assert kind_f == kind_e
    bad_reward = not bool(torch.isfinite(r).all())
    bad_obs = obs.is_floating_point() and bool(torch.isnan(obs).any())
    assert (kind_f == "error") == (bad_reward or bad_obs)
    if kind_f == "error":
        assert out_f == out_e
        assert torch.equal(table_f, table) and torch.equal(table_e, table)  # nothing was updated
        return
    assert torch.equal(out_f[INDEX], out_e[INDEX])
    assert torch.equal(out_f[STEPS], out_e[STEPS])
    assert torch.equal(out_f["transition"]["mask"], out_e["transition"]["mask"])
    for key in (RETURN, "reward"):
        torch.testing.assert_close(out_f[key], out_e[key], rtol=1e-5, atol=1e-5)
    torch.testing.assert_close(table_f, table_e, rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("eager", [False, True])
@pytest.mark.parametrize(
    ("reward", "obs", "message"),
    [
        (math.nan, 0.5, r"'reward' is NaN or infinite at index \(1, 0\) \(value nan\)"),
        (math.inf, 0.5, "'reward' is NaN or infinite"),
        (1.0, math.nan, r"'observation' is NaN at index \(1, 1\)"),
    ],
)
def test_nan_is_an_error_on_both_paths(eager: bool, reward: float, obs: float, message: str) -> None:
    """A NaN reward would make the table NaN for good; the transform refuses it."""
    series = [SubgoalSeries([Circle((0.5, 0.5), 0.1)])]
    potential = TabularPotential(2, batch_shape=(2,))
    t = SubgoalPotentialTransform(series, potential, gamma=0.9, value_update=0.5).use_backend(
        "torch" if eager else "compiled"
    )
    observation = torch.tensor([[0.5, 0.5], [0.5, obs]])
    rewards = torch.tensor([[0.0], [reward]])
    current = {
        INDEX: torch.zeros(2, 1, dtype=torch.long),
        RETURN: torch.zeros(2, 1),
        STEPS: torch.zeros(2, 1, dtype=torch.long),
    }
    false = torch.zeros(2, 1, dtype=torch.bool)
    with pytest.raises(ValueError, match=message):
        one_step(t, current, observation, rewards, false, false, torch.Size([2]))
    assert torch.equal(potential.table.detach(), torch.zeros(2, 2))


def test_infinite_observations_compare_as_numbers() -> None:
    """``inf`` is outside every bounded region and harmless in an entry a region does not read."""
    series = [SubgoalSeries([Circle((0.5, 0.5), 0.1)])]
    tables = SubgoalTables(series, torch.zeros(3, dtype=torch.long), 3)
    obs = torch.tensor([[0.5, 0.5, math.inf], [math.inf, 0.5, 0.0], [0.5, 0.5, -math.inf]], dtype=torch.float64)
    z = torch.zeros(3, 1, dtype=torch.long)
    assert tables.advance(z, obs).reshape(-1).tolist() == [1, 0, 1]
    assert torch.equal(tables.advance(z, obs), tables.advance_eager(z, obs))


@PROPERTY
@given(st.data())
def test_the_shaping_kernel_mirrors_the_torch_reference(data: st.DataObject) -> None:
    """``_kernels.shaping.shape_step`` against the torch functions of ``transform.shaping`` and one
    ``ValueUpdate.step`` of ``SubgoalValueLoss`` (reduction "sum"): the SMDP return, the online update (a table per
    row, one shared table, or a table per group of rows), the start level, a monotone table and the terminal
    potential."""
    from torchrl_subgoal import SubgoalValueLoss, ValueUpdate
    from torchrl_subgoal._kernels.shaping import shape_step
    from torchrl_subgoal.transform.setup import PotentialKernelState
    from torchrl_subgoal.transform.shaping import (
        START_MODES,
        accumulate,
        ancestral_max,
        closes,
        restart,
        shaped_reward,
        start_level,
    )
    from torchrl_subgoal.transform.transitions import transition

    n, states = data.draw(st.integers(1, 6)), data.draw(st.integers(2, 4))
    shared, zero_terminal = data.draw(st.booleans()), data.draw(st.booleans())
    # a table per row (group 1), or consecutive rows sharing one (envs_per_table = group)
    group = 1 if shared else data.draw(st.sampled_from([g for g in range(1, n + 1) if n % g == 0]))
    tables = 1 if shared else n // group
    start, lr = data.draw(st.sampled_from(sorted(START_MODES))), data.draw(st.sampled_from([0.0, 0.25, 1.0]))
    gamma, value_gamma = data.draw(st.sampled_from([0.9, 0.99, 1.0])), data.draw(st.sampled_from([0.5, 0.95]))
    expectile, bootstrap = data.draw(st.sampled_from([0.5, 0.9, 0.3])), data.draw(st.booleans())
    col = (n, 1)
    ancestors = None
    if data.draw(st.booleans()):  # a monotone table: each row's series a chain or a diamond-like random order
        ancestors = torch.eye(states, dtype=torch.bool).repeat(n, 1, 1)
        for row in range(n):
            for zz in range(1, states):
                before = data.draw(st.lists(st.integers(0, zz - 1), min_size=1, max_size=zz))
                ancestors[row, zz, before] = True
                ancestors[row, zz] |= ancestors[row, before].any(0)  # what comes before those comes before zz

    def ints(high: int) -> torch.Tensor:
        return torch.tensor(data.draw(st.lists(st.integers(0, high), min_size=n, max_size=n))).reshape(col)

    def floats() -> torch.Tensor:
        return torch.tensor(data.draw(st.lists(st.floats(-5, 5, width=32), min_size=n, max_size=n))).reshape(col)

    z, z_next, k, r_h, reward = ints(states - 1), ints(states - 1), ints(40), floats(), floats()
    done = ints(1).bool()
    terminated = done & ints(1).bool()
    table = torch.tensor(
        data.draw(
            st.lists(
                st.floats(-3, 3, width=32),
                min_size=tables * states,
                max_size=tables * states,
            )
        )
    ).reshape(-1, states)
    # the compiled step
    kernel_table = table.numpy().copy()
    outputs = [
        np.empty(col, np.float32),
        np.empty(col, np.int64),
        np.empty(col, np.float32),
        np.empty(col, np.float32),
        np.empty(col, np.int64),
        np.empty(col, np.bool_),
    ]
    potential = PotentialKernelState(
        kernel_table,
        0.0,
        gamma,
        value_gamma,
        lr,
        zero_terminal,
        START_MODES[start],
        expectile,
        bootstrap,
        *(() if ancestors is None else (ancestors.numpy(),)),
    )
    shape_step(
        potential,
        n if shared else (group if group > 1 else 0),
        z.numpy(),
        z_next.numpy(),
        z.numpy(),
        r_h.numpy(),
        k.numpy(),
        reward.numpy(),
        done.numpy(),
        terminated.numpy(),
        np.zeros(col, np.int64),
        *outputs,
    )
    # the torch reference
    v = TabularPotential(states, () if shared else (tables,), envs_per_table=group)
    with torch.no_grad():
        v.table.copy_(table[0] if shared else table)
    r_acc, k_acc = accumulate(r_h, k, reward, value_gamma)
    closed = closes(z, z_next, done)
    learner = {} if shared else {"subgoal_learner": torch.arange(n).reshape(col)}
    if lr:
        loss = SubgoalValueLoss(v, expectile=expectile, bootstrap_truncated=bootstrap).make_value_estimator(
            gamma=value_gamma
        )
        ValueUpdate(lr, loss).step(  # the torch reference of the kernels' update: one SGD step
            transition(
                torch.Size([n]),
                {INDEX: z, **learner},
                {INDEX: z_next, **learner},
                r_acc,
                k_acc,
                closed,
                done,
                terminated,
                z_next != z,
            )
        )
    rows = torch.zeros(n, dtype=torch.long) if shared else torch.arange(n) // group
    values = v.table.detach().reshape(-1, states)[rows]
    if ancestors is not None:
        values = ancestral_max(values, ancestors)
    level = start_level(values[:, :1], start)  # z_0 = 0: every subgoal series starts there
    phi, phi_next = values.gather(1, z), values.gather(1, z_next)
    if level is not None:
        phi, phi_next = phi - level, phi_next - level
    shaped = shaped_reward(reward, phi, phi_next, terminated, gamma, zero_terminal)
    rh_out, k_out = restart(r_acc, k_acc, closed)
    torch.testing.assert_close(
        torch.from_numpy(kernel_table), v.table.detach().reshape(-1, states), rtol=1e-5, atol=1e-4
    )
    torch.testing.assert_close(torch.from_numpy(outputs[2]), shaped, rtol=1e-5, atol=1e-4)
    torch.testing.assert_close(torch.from_numpy(outputs[0]), rh_out, rtol=1e-5, atol=1e-4)
    assert torch.equal(torch.from_numpy(outputs[1]), k_out) and torch.equal(torch.from_numpy(outputs[5]), closed)
    torch.testing.assert_close(torch.from_numpy(outputs[3]), r_acc, rtol=1e-5, atol=1e-4)


@PROPERTY
@given(batch(), st.data())
def test_conditions_advance_alike_compiled_and_in_torch(case: tuple, data: st.DataObject) -> None:
    """Subgoals of regions and conditions (functions of the step's TensorDict): the compiled region search,
    called with each condition's mask, and the torch one reach the same abstract states."""
    from tensordict import TensorDict

    from torchrl_subgoal import Condition

    series, shape, index, z, obs = case
    n = shape.numel()
    flags = [Condition(lambda td, c=c: td[f"flag{c}"], name=f"flag{c}") for c in range(3)]
    mixed = [
        SubgoalSeries(
            [flags[data.draw(st.integers(0, 2))] if data.draw(st.booleans()) else p for p in s.predicates],
            order=s.order,
            name=s.name,
        )
        for s in series
    ]
    td = TensorDict(
        {
            f"flag{c}": torch.tensor(data.draw(st.lists(st.booleans(), min_size=n, max_size=n))).reshape(shape)
            for c in range(3)
        },
        batch_size=shape,
    )
    tables = SubgoalTables(mixed, index, D)
    observation = obs if tables.uses_regions else None
    assert torch.equal(tables.advance(z, observation, td), tables.advance_eager(z, observation, td))


@PROPERTY
@given(
    st.integers(1, 6).flatmap(
        lambda n: st.tuples(
            st.lists(st.floats(-50, 50, allow_nan=False), min_size=n, max_size=n),
            st.lists(st.lists(st.booleans(), min_size=n, max_size=n), min_size=n, max_size=n),
        )
    )
)
def test_ancestral_max_lifts_each_state_to_what_comes_before_it(case: tuple) -> None:
    """Entry ``z`` becomes the largest value among ``z`` and its ancestors: never lower than before,
    never below an ancestor's lifted value, and applying it again changes nothing."""
    from torchrl_subgoal.transform.shaping import ancestral_max

    entries, before = case
    n = len(entries)
    ancestors = torch.tensor(before).tril(-1) | torch.eye(n, dtype=torch.bool)  # a order in which a < z
    for z in range(n):  # closed under "comes before"
        for a in range(z):
            if ancestors[z, a]:
                ancestors[z] |= ancestors[a]
    values = torch.tensor([entries], dtype=torch.float64)
    out = ancestral_max(values, ancestors[None])
    for z in range(n):
        assert out[0, z] == max(entries[a] for a in range(n) if ancestors[z, a])
        assert all(out[0, z] >= out[0, a] for a in range(n) if ancestors[z, a])
    assert (out >= values).all()
    assert torch.equal(ancestral_max(out, ancestors[None]), out)


@PROPERTY
@given(batch(), st.data())
def test_the_within_segment_term_lies_between_zero_and_the_step_to_a_next_subgoal(
    case: tuple, data: st.DataObject
) -> None:
    """``segment_term`` is never negative, never more than the largest step up to a subgoal that counts from
    ``z``, and the whole step where the observation is inside that subgoal's region (finite observations)."""
    from torchrl_subgoal.transform.segments import segment_term

    series, shape, index, z, obs = case
    obs = torch.nan_to_num(obs.to(torch.float64), nan=0.0, posinf=1e6, neginf=-1e6)
    tables = SubgoalTables(series, index, D)
    n = tables.num_states
    rows = shape.numel()
    values = torch.tensor(data.draw(st.lists(st.floats(-5, 5), min_size=rows * n, max_size=rows * n))).view(rows, n)
    term = segment_term(tables, values.float(), z, obs).reshape(-1)
    flat_z = z.reshape(-1)
    counts = tables.succ[torch.arange(rows), flat_z]  # [rows, J]
    reached = values.float()[:, (torch.arange(counts.shape[1]) + 1).clamp(max=n - 1)]
    step_up = (reached - values.float().gather(1, flat_z.unsqueeze(1))).clamp(min=0.0)
    bound = torch.where(counts, step_up, torch.zeros_like(step_up)).amax(-1)
    assert (term >= 0).all() and (term <= bound + 1e-5).all()
    inside = tables.inside(obs) & counts
    whole = torch.where(inside, step_up, torch.zeros_like(step_up)).amax(-1)
    assert (term >= whole - 1e-5).all()
