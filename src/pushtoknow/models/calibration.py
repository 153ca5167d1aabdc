"""How much of a push's evidence the parameter belief keeps (calibrated on whole push sequences).

A learned model's errors persist over a push and across pushes of the same object, so the
filter's posterior after a push is overconfident and, for what the pushes barely reveal, biased.
After each push the belief is therefore moved only part of the way from the push's prior
N(m₀, P₀) to the filter's posterior N(m₁, P₁), per direction of a parameter basis in which the
physics separates (normalised parameters, `common.params`):

    e₁ ∝ log μ·m   (the force's scale: what quasi-static pushes reveal)
    e₂ ⊥ e₁ in the (log m, log μ) plane   (what only dynamic content separates)
    e₃ = c_x, e₄ = c_y, e₅ = log I_z

With y = Rᵀ-coordinates in that basis and w ∈ [0, 1] per direction:
    y = y₀ + w ⊙ (y₁ − y₀),   var = var₁ + (1 − w) ⊙ (var₀ − var₁)   (marginals in the basis),
and the correlations of the posterior are kept. w = 1 is the filter's posterior, w = 0 the
push's prior. `training.calibrate` chooses w on validation objects' push sequences.

Pushes of one profile share part of their model error (the same model, outline and object),
so a second push of a profile tells less than the first: the n-th keeps w·g_r(n) of its
evidence (`evidence_discount`), with r the correlation of two such pushes' errors per
direction, chosen with w. r = 0: the pushes' errors are independent and every push keeps w.
"""

from __future__ import annotations

import numpy as np
import torch

from pushtoknow.common.params import PARAM_NAMES, space_scale
from pushtoknow.filters.tensor_shapes import expect_shape

DIRECTIONS: tuple[str, ...] = ("log_mu_m", "m_vs_mu", "com_x", "com_y", "log_inertia")


def evidence_basis() -> torch.Tensor:
    """(K, K) orthonormal rows e₁…e₅ (see the module docstring), in normalised coordinates."""
    scale = space_scale()
    i, j = PARAM_NAMES.index("mass"), PARAM_NAMES.index("friction")
    basis = np.zeros((len(PARAM_NAMES), len(PARAM_NAMES)))
    # log μm = s_m z_m + s_μ z_μ + const in normalised coordinates z
    basis[0, [i, j]] = scale[[i, j]] / np.hypot(scale[i], scale[j])
    basis[1, [i, j]] = np.array([scale[j], -scale[i]]) / np.hypot(scale[i], scale[j])
    for row, name in zip((2, 3, 4), ("com_x", "com_y", "inertia"), strict=True):
        basis[row, PARAM_NAMES.index(name)] = 1.0
    return torch.as_tensor(basis, dtype=torch.float32)


def check_correlations(values) -> None:
    """Raise ValueError unless every evidence correlation r (an iterable of floats) lies in
    [0, 1) (r = 1 would make a profile's later pushes worthless and g undefined)."""
    values = list(values)
    if not all(0.0 <= r < 1.0 for r in values):
        raise ValueError(f"evidence correlations must lie in [0, 1), got {values}")


def evidence_discount(nth: torch.Tensor, correlation: torch.Tensor) -> torch.Tensor:
    """g_r(n) (..., K): the share of the first push's evidence that the n-th push of a profile
    adds when the errors of any two of the profile's pushes correlate by r (each reads a
    direction as θ + b + εₙ, b common to the pushes, r = var b / (var b + var εₙ)).

    n such readings carry n / (1 + (n − 1) r) times one reading's information (1ᵀΣ⁻¹1 for
    Σ = (1 − r) I + r 11ᵀ), so the n-th adds g_r(n) = (1 − r) / ((1 + (n − 1) r)(1 + (n − 2) r))
    of the first's: g(1) = 1, g_0 ≡ 1, and however many pushes are made a profile keeps at most
    1/r pushes' evidence. Applied push by push through `keep_evidence` this is an approximation:
    the variance follows the information, but the mean weights a profile's n-th push by
    g_r(n) where the exact estimate would weight its pushes equally.
    nth (...,) ≥ 1 (a push's count among its profile's, itself included); correlation (K,)
    r ∈ [0, 1) per direction.
    """
    if bool((nth < 1).any()):
        raise ValueError(f"a push's count among its profile's starts at 1, got {nth.min()}")
    check_correlations(correlation.flatten().tolist())
    n = nth.to(correlation.dtype).unsqueeze(-1)
    r = correlation
    return (1.0 - r) / ((1.0 + (n - 1.0) * r) * (1.0 + (n - 2.0) * r))


def keep_evidence(
    mean0: torch.Tensor,
    cov0: torch.Tensor,
    mean1: torch.Tensor,
    cov1: torch.Tensor,
    weights: torch.Tensor,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Belief after a push keeping `weights` (K,) of its evidence per basis direction.

    mean0, mean1: (B, K) the push's prior and the filter's posterior; cov0, cov1: (B, K, K);
    weights (K,) for every row, or (B, K) per row.
    Returns mean (B, K), cov (B, K, K), symmetric positive semi-definite by construction.
    """
    k = len(PARAM_NAMES)
    b = expect_shape(mean0, "mean0", [("B", None), ("K", k)]).shape[0]
    expect_shape(cov0, "cov0", [("B", b), ("K", k), ("K", k)])
    expect_shape(mean1, "mean1", [("B", b), ("K", k)])
    expect_shape(cov1, "cov1", [("B", b), ("K", k), ("K", k)])
    if weights.dim() == 1:
        expect_shape(weights, "weights", [("K", k)])
    else:
        expect_shape(weights, "weights", [("B", b), ("K", k)])
    r = evidence_basis().to(mean0)
    w = weights.to(mean0)
    y0, y1 = mean0 @ r.T, mean1 @ r.T
    c0, c1 = r @ cov0 @ r.T, r @ cov1 @ r.T
    var0 = torch.diagonal(c0, dim1=-2, dim2=-1).clamp_min(1e-12)
    var1 = torch.diagonal(c1, dim1=-2, dim2=-1).clamp_min(1e-12)
    y = y0 + w * (y1 - y0)
    var = var1 + (1.0 - w) * (var0 - var1)
    corr = c1 / torch.sqrt(var1.unsqueeze(-1) * var1.unsqueeze(-2))
    std = var.clamp_min(1e-12).sqrt()
    c = corr * std.unsqueeze(-1) * std.unsqueeze(-2)
    cov = r.T @ c @ r
    return y @ r, 0.5 * (cov + cov.transpose(-1, -2))
