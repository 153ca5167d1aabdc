"""Conventions shared by every layer: parameter names and ranges, camera model, errors, config."""
