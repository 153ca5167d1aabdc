"""Baselines: Mavrakis-style features + multi-output random forest (SPEC §3.7)."""
