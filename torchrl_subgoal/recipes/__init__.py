"""The recipes the ``torchrl-subgoal`` command runs, one module each (the repository's ``recipes/``
scripts run the same ``main``):

* :mod:`~torchrl_subgoal.recipes.train`: ``torchrl-subgoal train``, any TorchRL learner (A2C, PPO,
  DQN, DDPG) with subgoal shaping on a registered domain, against the unshaped one;
* :mod:`~torchrl_subgoal.recipes.four_rooms`: ``torchrl-subgoal reproduce four-rooms``, SARSA against
  the paper's baselines;
* :mod:`~torchrl_subgoal.recipes.pinball`: ``torchrl-subgoal reproduce pinball``, the actor-critic;
* :mod:`~torchrl_subgoal.recipes.pick_and_place`: ``torchrl-subgoal reproduce pick-and-place``, DDPG on
  MuJoCo's Fetch (the ``fetch`` extra).

Each is a settings dataclass (every field a flag), a ``plan`` turning the settings into a sweep, and
``main(argv, prog)``; the experiment engine (:mod:`torchrl_subgoal.experiments`) does the rest.
"""

#: ``torchrl-subgoal reproduce NAME``: the module of each paper reproduction
REPRODUCTIONS = {"four-rooms": "four_rooms", "pinball": "pinball", "pick-and-place": "pick_and_place"}

__all__ = ["REPRODUCTIONS"]
