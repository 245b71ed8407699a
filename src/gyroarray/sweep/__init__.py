"""Scenario files and sweeps (issue 5)."""
