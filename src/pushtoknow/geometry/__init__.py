"""Image-space geometry: push affordances from S_0, action maps, differentiable mask warping."""
