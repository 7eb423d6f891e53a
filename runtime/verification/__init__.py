"""Verify before build: what every registered kind declares, and the check of a whole system against it.

``manifest`` holds the declaration format (imported by the plugin base classes); ``verify`` the
check itself (imported by the CLIs). This package imports neither eagerly.
"""
