"""What inference and training both need from the camera: the footprint seen in S_0 and VisNet's
pose measurement (below both layers)."""
