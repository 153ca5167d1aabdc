"""Training data chosen by a push policy with the current model, and the learning-efficiency
ablation built on it (docs/DESIGN.md §7, §8; `pushtoknow collect`, `pushtoknow ablate-efficiency`).

Above `inference` (collection runs `infer_object`) and `training` (the ablation trains models),
below `evaluation` and the CLI.
"""
