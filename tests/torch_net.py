"""PyTorch definition of C, the tests' independent reference; its state-dict names match :func:`numpy_forward`."""

from __future__ import annotations

import torch
from torch import nn

from terrapref.learning.network import ClassifierConfig

_ACT = {"relu": nn.ReLU, "tanh": nn.Tanh, "elu": nn.ELU}


class UtilityClassifier(nn.Module):
    """C: U (B, m, k) -> logits (B, m)."""

    def __init__(self, config: ClassifierConfig) -> None:
        super().__init__()
        self.config = config
        self.compress = nn.Linear(config.n_features, 1) if config.compress else None
        dims = [config.width_in] + [config.hidden] * config.depth + [config.m]
        self.layers = nn.ModuleList(nn.Linear(a, b) for a, b in zip(dims[:-1], dims[1:]))
        self.act = _ACT[config.activation]()

    def forward(self, U: torch.Tensor) -> torch.Tensor:
        if self.config.ignore:
            U = U.clone()
            U[..., list(self.config.ignore)] = 0.0
        if self.compress is not None:
            per_row = self.compress(U)  # (B, m, 1)
            scores, h = per_row[..., 0], per_row.flatten(1)
        else:
            scores = h = U.flatten(1)
        for layer in self.layers[:-1]:
            h = self.act(layer(h))
        logits = self.layers[-1](h)
        return logits + scores if self.config.skip else logits
