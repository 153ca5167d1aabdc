"""Metrics and evaluation protocols (SPEC §3.7)."""
