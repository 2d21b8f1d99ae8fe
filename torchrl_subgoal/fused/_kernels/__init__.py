"""The compiled kernels of the paper's learners and of the fused engine (numba), next to the modules that call them.

* :mod:`.sarsa`, :mod:`.actor_critic`: the steps of :class:`~torchrl_subgoal.fused.SoftmaxSarsa` and
  :class:`~torchrl_subgoal.fused.FourierActorCritic`, called by the TorchRL loop and the fused engine alike;
* :mod:`.records`: filing finished episodes;
* :mod:`.engine`: :func:`~.engine.fused_run`, the fused engine's loop.

They build on the shared kernels of :mod:`torchrl_subgoal._kernels` (random streams, the engine's step
protocol, the region search, the shaping step). Import the module you need: this package imports none.
"""
