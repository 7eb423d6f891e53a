"""Localization (thesis §6.2.1): laser/odometry simulator, Algorithm 3's reliability filter, an AMCL-like MCL."""
