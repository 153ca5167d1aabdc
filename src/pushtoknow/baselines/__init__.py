"""Baselines: Mavrakis-style features + multi-output random forest (docs/DESIGN.md §9)."""
