"""What inference and training both need from the camera: the footprint seen before a push and
VisNet's pose measurement (below both layers)."""
