"""Behaviors (thesis §5.1) over the standard service interfaces (docs/interfaces.md): general ones (timer,
emit, wait-input), navigation goals, manipulation, perception, approach, docking, recovery."""
