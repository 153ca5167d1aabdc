"""Training data chosen by a push policy with the current model, and the learning-efficiency
ablation built on it (SPEC §3.5, §3.6; `pushtoknow collect`, `pushtoknow ablate-efficiency`).

Above `inference` (collection runs `infer_object`) and `training` (the ablation trains models),
below `evaluation` and the CLI.
"""
