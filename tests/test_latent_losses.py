"""The distance D and the four losses of paper §3.3 on hand-computed cases."""

import math

import pytest
import torch

from controller.planning.latent.config import LossWeights
from controller.training.losses import (
    consistency_loss,
    directional_loss,
    distance,
    ranking_loss,
    regularisation_loss,
    total_loss,
)


def test_distances_on_hand_computed_vectors() -> None:
    a, b = torch.tensor([3.0, 4.0]), torch.tensor([4.0, 3.0])
    # cos = 24 / 25 → cosine distance 0.04; ‖a − b‖ = √2
    assert float(distance(a, b, "cosine")) == pytest.approx(0.04, abs=1e-6)
    assert float(distance(a, b, "euclidean")) == pytest.approx(math.sqrt(2), abs=1e-6)
    assert float(distance(a, b, "both")) == pytest.approx(0.04 + math.sqrt(2), abs=1e-6)
    # opposite vectors: cosine distance 2
    assert float(distance(a, -a, "cosine")) == pytest.approx(2.0, abs=1e-6)
    with pytest.raises(ValueError, match="unknown distance"):
        distance(a, b, "manhattan")


def test_distance_broadcasts_over_actions() -> None:
    z_next = torch.tensor([[[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0]]])  # (1, 3, 2)
    goal = torch.tensor([[1.0, 0.0]]).unsqueeze(1)  # (1, 1, 2)
    assert distance(z_next, goal, "cosine")[0].tolist() == pytest.approx([0.0, 1.0, 2.0], abs=1e-6)


def test_directional_hinge() -> None:
    d_next = torch.tensor([0.5, 0.2, 1.0])
    d_now = torch.tensor([1.0, 0.25, 0.5])
    # per sample: max(0, 0.5 − 1 + 0.1) = 0; max(0, 0.2 − 0.25 + 0.1) = 0.05; max(0, 1 − 0.5 + 0.1) = 0.6
    assert float(directional_loss(d_next, d_now, 0.1)) == pytest.approx((0.0 + 0.05 + 0.6) / 3, abs=1e-6)


def test_ranking_loss_is_cross_entropy_of_negative_distances() -> None:
    d = torch.tensor([[0.0, math.log(2.0), math.log(4.0)]])
    # softmax(−d) ∝ (1, 1/2, 1/4) → p(0) = 4/7
    assert float(ranking_loss(d, torch.tensor([0]), 1.0)) == pytest.approx(-math.log(4 / 7), abs=1e-6)
    # temperature 0.5 doubles the logits: ∝ (1, 1/4, 1/16) → p(2) = 1/21
    assert float(ranking_loss(d, torch.tensor([2]), 0.5)) == pytest.approx(-math.log(1 / 21), abs=1e-5)


def test_consistency_and_regularisation() -> None:
    delta = torch.tensor([[1.0, 2.0], [0.0, 0.0]])
    g = torch.tensor([[1.0, 0.0], [3.0, 4.0]])
    assert float(consistency_loss(delta, g)) == pytest.approx((4.0 + 25.0) / 2)
    assert float(regularisation_loss(g)) == pytest.approx((1.0 + 25.0) / 2)


def test_total_is_the_weighted_sum_and_zero_weight_removes_a_term() -> None:
    args = dict(
        d_now=torch.tensor([1.0]),
        d_all=torch.tensor([[0.5, 2.0]]),
        target=torch.tensor([0]),
        delta_true=torch.tensor([[1.0, 0.0]]),
        g_true=torch.tensor([[0.0, 2.0]]),
        margin=0.1,
        temperature=1.0,
    )
    full = total_loss(weights=LossWeights(), **args)
    expected_rank = -math.log(math.exp(-0.5) / (math.exp(-0.5) + math.exp(-2.0)))
    assert float(full.dir) == pytest.approx(0.0)  # 0.5 − 1 + 0.1 < 0
    assert float(full.rank) == pytest.approx(expected_rank, abs=1e-6)
    assert float(full.cons) == pytest.approx(5.0)
    assert float(full.reg) == pytest.approx(4.0)
    assert float(full.total) == pytest.approx(expected_rank + 9.0, abs=1e-6)
    weighted = total_loss(weights=LossWeights(dir=2.0, rank=0.0, cons=0.5, reg=0.0), **args)
    assert float(weighted.total) == pytest.approx(2.5, abs=1e-6)


def test_loss_weights_parse() -> None:
    assert LossWeights.parse("dir=0,rank=2") == LossWeights(dir=0.0, rank=2.0, cons=1.0, reg=1.0)
    with pytest.raises(ValueError, match="bad loss weight"):
        LossWeights.parse("speed=1")
    with pytest.raises(ValueError, match="not a number"):
        LossWeights.parse("dir=abc")
