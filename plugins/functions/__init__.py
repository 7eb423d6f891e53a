"""Adaptation functions and Function-element processing plugins (§3.1.2.1)."""
