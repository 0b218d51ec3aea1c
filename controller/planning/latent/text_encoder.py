"""E_inst: token embedding + sinusoidal positions + a 2-layer transformer encoder (paper appendix).

Embedding width 128, 4 heads, feed-forward 256, dropout 0.1, at most 50 tokens. The
instruction embedding is the masked mean of the encoder outputs over real tokens.
"""

from __future__ import annotations

import math

import torch
from torch import nn

from controller.planning.latent.tokenizer import PAD_ID


class TextEncoder(nn.Module):
    """(B, L) token ids, [PAD] = 0 → (B, d) instruction embeddings."""

    def __init__(
        self,
        vocab_size: int,
        dim: int = 128,
        layers: int = 2,
        heads: int = 4,
        ff: int = 256,
        dropout: float = 0.1,
        max_tokens: int = 50,
    ) -> None:
        super().__init__()
        self.max_tokens = max_tokens
        self.embed = nn.Embedding(vocab_size, dim, padding_idx=PAD_ID)
        self.register_buffer("positions", _sinusoidal(max_tokens, dim), persistent=False)
        self.dropout = nn.Dropout(dropout)
        layer = nn.TransformerEncoderLayer(
            d_model=dim, nhead=heads, dim_feedforward=ff, dropout=dropout, batch_first=True
        )
        self.encoder = nn.TransformerEncoder(layer, num_layers=layers, enable_nested_tensor=False)

    def forward(self, ids: torch.Tensor) -> torch.Tensor:
        ids = ids[:, : self.max_tokens]  # (B, L)
        pad = ids.eq(PAD_ID)  # (B, L) True where padding
        x = self.embed(ids) * math.sqrt(self.embed.embedding_dim) + self.positions[: ids.shape[1]]
        x = self.encoder(self.dropout(x), src_key_padding_mask=pad)  # (B, L, d)
        keep = (~pad).unsqueeze(-1).to(x.dtype)  # (B, L, 1)
        return (x * keep).sum(dim=1) / keep.sum(dim=1).clamp(min=1.0)  # (B, d)


def _sinusoidal(length: int, dim: int) -> torch.Tensor:
    """(length, dim) fixed sine/cosine position codes (Vaswani et al.)."""
    pos = torch.arange(length, dtype=torch.float32).unsqueeze(1)
    freq = torch.exp(torch.arange(0, dim, 2, dtype=torch.float32) * (-math.log(10000.0) / dim))
    table = torch.zeros(length, dim)
    table[:, 0::2] = torch.sin(pos * freq)
    table[:, 1::2] = torch.cos(pos * freq)
    return table
