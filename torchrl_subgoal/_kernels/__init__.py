"""Compiled CPU kernels (numba), one module per concern.

Each kernel does, in one pass over the learner batch, what the eager torch code
does with a few dozen small tensor operations; at the batch sizes used here
(10^2-10^4 learners) the cost of those is dominated by per-operation overhead.
The torch code stays the reference (and the path for other devices and neural
potentials); the tests check the two agree.

* :mod:`.random`: every learner's counter-based random stream, and draws from it;
* :mod:`.steps`: the fused engine's per-record steps (``env_step``, ``learner_step``, …)
  and :func:`~.steps.implements`, with which an env's or a learner's record joins the engine;
* :mod:`.regions`: the region search of subgoal predicates and region aggregations;
* :mod:`.shaping`: the shaping transform's step (the SMDP return, the online update, the shaped reward);
* :mod:`.grid`: the four-rooms env.

The paper's two learners' kernels, filing finished episodes and the fused engine's loop live with the
learners, in :mod:`torchrl_subgoal.fused._kernels`.

Arrays are numpy views of torch tensors (no copies); batch dimensions are
flattened, per-learner scalars have a trailing singleton. Import the module you
need (``from torchrl_subgoal._kernels import shaping``): this package imports none.

numba is optional (the ``fast`` and ``experiments`` extras): without it, :data:`NUMBA` is false, the
shaping transform's ``backend="auto"`` steps in torch and nothing here is imported.
"""

from importlib.util import find_spec

#: Whether numba is installed, so that the compiled kernels can be imported.
NUMBA = find_spec("numba") is not None
