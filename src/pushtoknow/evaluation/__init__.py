"""Metrics and evaluation protocols (docs/DESIGN.md §9)."""
