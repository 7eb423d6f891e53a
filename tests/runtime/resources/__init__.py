"""Tests of the Smart Resource layer."""
