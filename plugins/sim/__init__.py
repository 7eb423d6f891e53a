"""The simulated laboratory of thesis §7.1: a pybullet world built from the Environment model,
the mobile manipulator (Turtlebot role) and the humanoid (Nao role), their sensors, and the
devices the ``hardware.sim`` backend serves channels from, and the world server that holds one
world for every process of a run (``server``, ``render``, ``client``, ``session``). See
docs/simulation.md.

(pybullet prints its build time on standard error when imported; standard output stays clean
for ``--json`` outputs.)"""
