"""Pluggable fusion estimators (issue 4)."""
