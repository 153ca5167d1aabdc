"""Command-line interface `pushtoknow`."""
