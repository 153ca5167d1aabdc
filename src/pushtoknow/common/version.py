"""The package version (pyproject's), written into datasets and checkpoints."""

__version__ = "0.1.0"
