"""Behaviors (thesis §5.1): general-purpose ones and the use case's (Tables 7.5 and 7.7)."""
