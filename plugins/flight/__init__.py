"""Flying robots: the ``flight`` interface's service kind (docs/interfaces.md, issue M)."""
