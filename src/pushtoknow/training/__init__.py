"""Training: VisNet (supervised), then the filter's networks (supervised warm-up + end to end)."""
