"""The paper's experiments: Table 2 (instructions × distance) and Table 3 (loss ablations).

Definitions only, shared by `reproduce` (which runs them) and `report` (which writes them up).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from controller.planning.latent.config import PRESETS, LossWeights


@dataclass(frozen=True)
class Experiment:
    name: str
    table: str  # "table2" or "table3"
    instructions: str
    distance: str
    zeroed: tuple[str, ...] = ()  # loss terms switched off (ablations); the rest keep the preset's weights

    def weights(self, preset: str) -> LossWeights:
        """The preset's loss weights with this experiment's ablated terms set to 0."""
        return replace(PRESETS[preset].train.weights, **dict.fromkeys(self.zeroed, 0.0))


TABLE2 = tuple(
    Experiment(f"{ins}-{dist}", "table2", ins, dist)
    for ins in ("fixed", "varied")
    for dist in ("cosine", "euclidean", "both")
)
TABLE3 = (
    Experiment("no-cons-reg", "table3", "varied", "cosine", ("cons", "reg")),
    Experiment("no-dir", "table3", "varied", "cosine", ("dir",)),
    Experiment("no-rank", "table3", "varied", "cosine", ("rank",)),
)
MAIN = "varied-cosine"  # the configuration of the targets, Figure 3 and the gallery
EXPERIMENT_SETS = {"main": ("varied-cosine",), "table2": tuple(e.name for e in TABLE2)}
EXPERIMENT_SETS["table3"] = ("varied-cosine", *(e.name for e in TABLE3))
EXPERIMENT_SETS["all"] = tuple(dict.fromkeys(EXPERIMENT_SETS["table2"] + EXPERIMENT_SETS["table3"]))
BY_NAME = {e.name: e for e in TABLE2 + TABLE3}
