"""Workloads behind ``ckm-bench``; each prints a human table and, with --json, one JSON line last."""
