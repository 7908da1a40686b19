"""Offline RL over action chunks (paper sections 4.2, 5.3, 6): an IQL critic and the tools around it.

* ``iql``: the IQL losses as pure functions and ``IqlCritic`` (V(s), twin Q(s, a), Polyak targets).
* ``configuration_iql_critic`` / ``modeling_iql_critic``: the critic as a LeRobot-style checkpoint whose
  state encoder is the ``bbox_diffusion`` policy's own observation encoder, frozen and warm-started.
* ``critic_dataset``: LeRobotDataset with outcome labels -> chunk transitions with sparse terminal reward.
* ``diagnostics``: V/Q/A/TD grouped by outcome and phase, and the value-ordering checks.
* ``counterfactual``: snapshot and restore a ``LegoPickEnv`` mid-episode, run alternative branches from it.
* ``train_critic`` (``bboxpick-train-critic``), ``verify`` (``bboxpick-verify-critic``), ``rerank``.
"""
