"""The Control Kernel Middleware runtime: kernel, networking, Smart Resources, missions (issues B–E)."""

from . import simtime as _simtime

# A process started by a run on a scaled clock (ckm-run --time-scale: its partitions, the world
# server) takes the run's clock before anything reads the time.
_simtime.install()
