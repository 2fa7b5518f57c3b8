"""The robot as CasADi graphs: forward kinematics and sensitivities (:mod:`.graphs`), the
:class:`~tolsynth.Mechanism` that owns them, inverse kinematics, the joint space and batch
evaluation over many poses."""
