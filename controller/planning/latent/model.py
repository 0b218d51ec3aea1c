"""The latent dynamics model of paper §3.2: encoders, fusion, f_θ, global action embeddings.

    z_s  = fuse(concat(E_img(x), E_inst(instr)))          (B, d)
    z_a  = concat(E_X[x], E_Z[z])                          (9, 32)
    Δ    = f_θ(concat(z_s, z_a))                           MLP 160 → 128 → 128 → 128
    ẑ'   = z_s + Δ
    g_a  = g_X[x] + g_Z[z]                                 (training only)
    z*   = fuse(concat(mean_i E_img(goal_i), E_inst(instr)))

Planning scores every action by D(ẑ'_a, z*) and picks the smallest.

With `conditioning="film"` E_img(x | E_inst(instr)) is FiLM-modulated by the instruction, and
the goal mean is taken over goal images each encoded under an instruction naming its own
centred target ("the named target is centred", whichever it is); `presence_head` adds
p(named target in view) = σ(MLP(z_s)).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from controller.planning.actions import NUM_ACTIONS
from controller.planning.latent.config import SHIFT_INIT_STD, ModelConfig
from controller.planning.latent.image_encoder import ImageEncoder
from controller.planning.latent.text_encoder import TextEncoder

# (9,) axis indices of every joint action, in Action.index order (index = 3·x + z).
ACTION_X = torch.arange(NUM_ACTIONS) // 3
ACTION_Z = torch.arange(NUM_ACTIONS) % 3


def distance(a: torch.Tensor, b: torch.Tensor, kind: str) -> torch.Tensor:
    """D over the last dimension, broadcasting the leading ones: (..., d), (..., d) → (...)."""
    if kind == "cosine":
        return 1.0 - F.cosine_similarity(a, b, dim=-1, eps=1e-8)
    if kind == "euclidean":
        return torch.linalg.vector_norm(a - b, dim=-1)
    if kind == "both":
        return 1.0 - F.cosine_similarity(a, b, dim=-1, eps=1e-8) + torch.linalg.vector_norm(a - b, dim=-1)
    raise ValueError(f"unknown distance {kind!r}; choose cosine, euclidean or both")


class LatentDynamicsModel(nn.Module):
    def __init__(self, config: ModelConfig, shift_init_std: float = SHIFT_INIT_STD) -> None:
        """`shift_init_std`: the spread of the global shifts g_X, g_Z at initialisation (a training
        choice, `TrainConfig.shift_init_std`; the same random draws whatever it is)."""
        super().__init__()
        self.config = config
        d = config.latent_dim
        self.image_encoder = ImageEncoder(
            d,
            config.base_width,
            config.coord_channels,
            config.pooling,
            config.image_size,
            condition_dim=d if config.conditioning == "film" else 0,
        )
        self.text_encoder = TextEncoder(
            config.vocab_size,
            d,
            config.text_layers,
            config.text_heads,
            config.text_ff,
            config.text_dropout,
            config.max_tokens,
        )
        self.fuse = nn.Linear(2 * d, d)  # concat(E_img, E_inst) → z_s
        if config.fusion == "gated":  # + (A·E_img) ⊙ (B·E_inst)
            self.fuse_img = nn.Linear(d, d, bias=False)
            self.fuse_text = nn.Linear(d, d)
        self.action_x = nn.Embedding(3, config.action_dim)  # E_act, X axis
        self.action_z = nn.Embedding(3, config.action_dim)  # E_act, Z axis
        h = config.dynamics_hidden
        self.dynamics = nn.Sequential(  # f_θ
            nn.Linear(d + 2 * config.action_dim, h),
            nn.ReLU(),
            nn.Dropout(config.dynamics_dropout),
            nn.Linear(h, h),
            nn.ReLU(),
            nn.Dropout(config.dynamics_dropout),
            nn.Linear(h, d),
        )
        self.presence: nn.Module | None = None
        if config.presence_head:  # z_s → logit of "the named target is in view"
            self.presence = nn.Sequential(nn.Linear(d, 64), nn.ReLU(), nn.Linear(64, 1))
        self.global_x = nn.Parameter(torch.zeros(3, d))  # g_X
        self.global_z = nn.Parameter(torch.zeros(3, d))  # g_Z
        nn.init.normal_(self.global_x, std=shift_init_std)
        nn.init.normal_(self.global_z, std=shift_init_std)
        self.register_buffer("action_x_index", ACTION_X.clone(), persistent=False)
        self.register_buffer("action_z_index", ACTION_Z.clone(), persistent=False)

    # --- encoders -----------------------------------------------------------------------------
    @property
    def device(self) -> torch.device:
        """Where the weights live (training may run on a GPU; data and results stay on the CPU)."""
        return next(self.parameters()).device

    @property
    def conditioned(self) -> bool:
        """Whether E_img takes the instruction (FiLM), so an image embedding depends on the words."""
        return self.config.conditioning == "film"

    def encode_images(self, images: torch.Tensor, text_emb: torch.Tensor | None = None) -> torch.Tensor:
        """(B, 3, S, S) in [0, 1] (+ (B, d) E_inst when FiLM-conditioned) → (B, d) E_img."""
        return self.image_encoder(images, text_emb if self.conditioned else None)

    def presence_logits(self, z_s: torch.Tensor) -> torch.Tensor:
        """(B, d) z_s → (B,) logits of "the named target is in view" (needs `presence_head`)."""
        if self.presence is None:
            raise ValueError("this model has no presence head")
        return self.presence(z_s).squeeze(-1)

    def encode_text(self, ids: torch.Tensor) -> torch.Tensor:
        """(B, L) token ids → (B, d) E_inst."""
        return self.text_encoder(ids)

    def fuse_state(self, img_emb: torch.Tensor, text_emb: torch.Tensor) -> torch.Tensor:
        """(B, d), (B, d) → (B, d) z_s (also used for the goal prototype z*)."""
        z = self.fuse(torch.cat([img_emb, text_emb], dim=-1))
        if self.config.fusion == "gated":
            z = z + self.fuse_img(img_emb) * self.fuse_text(text_emb)
        return z

    def action_embeddings(self) -> torch.Tensor:
        """(9, 32) z_a of every joint action."""
        return torch.cat([self.action_x(self.action_x_index), self.action_z(self.action_z_index)], dim=-1)

    def global_shifts(self) -> torch.Tensor:
        """(9, d) g_a = g_X[x] + g_Z[z] of every joint action."""
        return self.global_x[self.action_x_index] + self.global_z[self.action_z_index]

    # --- dynamics -----------------------------------------------------------------------------
    def deltas(self, z_s: torch.Tensor) -> torch.Tensor:
        """(B, d) → (B, 9, d): Δ_θ(z_s, z_a) for every action, all in one batch."""
        b, d = z_s.shape
        z_a = self.action_embeddings()  # (9, 32)
        pairs = torch.cat(
            [z_s.unsqueeze(1).expand(b, NUM_ACTIONS, d), z_a.unsqueeze(0).expand(b, -1, -1)], dim=-1
        )  # (B, 9, d + 32)
        return self.dynamics(pairs)  # (B, 9, d)

    def score(self, z_s: torch.Tensor, z_goal: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Distances of every predicted next state to the goal.

        z_s (B, d), z_goal (B, d) → (d_all (B, 9) = D(z_s + Δ_a, z*), deltas (B, 9, d)).
        """
        deltas = self.deltas(z_s)
        z_next = z_s.unsqueeze(1) + deltas  # (B, 9, d)
        return distance(z_next, z_goal.unsqueeze(1), self.config.distance), deltas

    def forward(
        self, images: torch.Tensor, ids: torch.Tensor, goal_image_embedding: torch.Tensor
    ) -> torch.Tensor:
        """Planning in one call: (B, 3, S, S), (B, L), (d,) → (B, 9) distances to the goal."""
        text = self.encode_text(ids)
        z_s = self.fuse_state(self.encode_images(images, text), text)
        z_goal = self.fuse_state(goal_image_embedding.expand_as(text), text)
        return self.score(z_s, z_goal)[0]
