"""Verify before build: what every registered kind declares, and the check of a whole system against it.

The design coherence check of §3.1.5.1, extended past the XSD to each kind's ``<Param>`` and value types.

``manifest`` holds the declaration format (imported by the plugin base classes); ``verify`` the
check itself (imported by the CLIs). This package imports neither eagerly.
"""
