"""The Control Kernel Middleware runtime: kernel, networking, Smart Resources, missions (issues B–E)."""
