"""The distance D and the four training losses of paper §3.3 (eqs. 5–9).

D(a, b) is the cosine distance 1 − cos(a, b), the Euclidean distance ‖a − b‖₂, or
their sum ("both"). Every loss is averaged over the batch.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F

from controller.planning.latent.config import LossWeights


def distance(a: torch.Tensor, b: torch.Tensor, kind: str) -> torch.Tensor:
    """D over the last dimension, broadcasting the leading ones: (..., d), (..., d) → (...)."""
    if kind == "cosine":
        return 1.0 - F.cosine_similarity(a, b, dim=-1, eps=1e-8)
    if kind == "euclidean":
        return torch.linalg.vector_norm(a - b, dim=-1)
    if kind == "both":
        return 1.0 - F.cosine_similarity(a, b, dim=-1, eps=1e-8) + torch.linalg.vector_norm(a - b, dim=-1)
    raise ValueError(f"unknown distance {kind!r}; choose cosine, euclidean or both")


def directional_loss(d_next: torch.Tensor, d_now: torch.Tensor, margin: float) -> torch.Tensor:
    """L_dir = mean max(0, D(ẑ', z*) − D(z_s, z*) + m): the true action's step must approach z*."""
    return torch.relu(d_next - d_now + margin).mean()


def ranking_loss(d_all: torch.Tensor, target: torch.Tensor, temperature: float) -> torch.Tensor:
    """L_rank = CE(softmax(−D(ẑ'_i, z*)/τ), y) over all actions; d_all (B, 9), target (B,)."""
    return F.cross_entropy(-d_all / temperature, target)


def consistency_loss(delta: torch.Tensor, g_a: torch.Tensor) -> torch.Tensor:
    """L_cons = mean ‖Δ(z_s, z_a) − g_a‖²: state-specific shifts stay near the action's global shift."""
    return (delta - g_a).pow(2).sum(dim=-1).mean()


def regularisation_loss(g_a: torch.Tensor) -> torch.Tensor:
    """L_reg = mean ‖g_a‖²: keeps the global shifts from growing without bound."""
    return g_a.pow(2).sum(dim=-1).mean()


@dataclass(frozen=True)
class LossTerms:
    total: torch.Tensor
    dir: torch.Tensor
    rank: torch.Tensor
    cons: torch.Tensor
    reg: torch.Tensor

    def as_floats(self) -> dict[str, float]:
        return {k: float(getattr(self, k).detach()) for k in ("total", "dir", "rank", "cons", "reg")}


def total_loss(
    *,
    d_now: torch.Tensor,
    d_all: torch.Tensor,
    target: torch.Tensor,
    delta_true: torch.Tensor,
    g_true: torch.Tensor,
    weights: LossWeights,
    margin: float,
    temperature: float,
) -> LossTerms:
    """L_total = w_dir L_dir + w_rank L_rank + w_cons L_cons + w_reg L_reg.

    d_now (B,): D(z_s, z*); d_all (B, 9): D(z_s + Δ_i, z*) for every action; target (B,)
    the true action index; delta_true, g_true (B, d): Δ and g for the true action.
    """
    d_next = d_all.gather(1, target.unsqueeze(1)).squeeze(1)  # (B,)
    l_dir = directional_loss(d_next, d_now, margin)
    l_rank = ranking_loss(d_all, target, temperature)
    l_cons = consistency_loss(delta_true, g_true)
    l_reg = regularisation_loss(g_true)
    total = weights.dir * l_dir + weights.rank * l_rank + weights.cons * l_cons + weights.reg * l_reg
    return LossTerms(total, l_dir, l_rank, l_cons, l_reg)
