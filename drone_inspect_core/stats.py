"""Confidence intervals for the figures the benchmarks report.

- `wilson_interval(successes, n)`: the Wilson score interval of a rate (recall,
  false-positive rate, kind accuracy, success rate); unlike the normal ("Wald")
  interval it stays inside [0, 1] and is honest at rates near 0 or 1 on small samples.
- `quantile_interval(values, q)`: a distribution-free interval for a quantile (the
  median or p95 of a centre error): the order statistics whose ranks bound `n·q` by
  ±z·sqrt(n·q·(1−q)) (the binomial count of values below the true quantile).
- `Rate`: a count, its total, the rate and its interval, as one JSON-able value.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

Z_95 = 1.959964
"""The two-sided 95 % normal quantile."""


def wilson_interval(successes: int, n: int, z: float = Z_95) -> tuple[float, float]:
    """The Wilson score interval of a success rate (95 % by default); (0, 1) when n is 0."""
    if not 0 <= successes <= n:
        raise ValueError(f"need 0 <= successes <= n, got {successes} of {n}")
    if n == 0:
        return 0.0, 1.0
    p = successes / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    low = 0.0 if successes == 0 else max(0.0, centre - half)
    return low, 1.0 if successes == n else min(1.0, centre + half)


def quantile_interval(values: Sequence[float], q: float, z: float = Z_95) -> tuple[float, float]:
    """An approximate 95 % interval for the `q` quantile of the distribution `values` came from.

    NaN bounds when there are no values; the whole range when there are too few to say more.
    """
    if not 0.0 < q < 1.0:
        raise ValueError(f"q must be in (0, 1), got {q}")
    x = np.sort(np.asarray(values, dtype=float))
    n = len(x)
    if n == 0:
        return float("nan"), float("nan")
    spread = z * math.sqrt(n * q * (1 - q))
    lo = max(0, math.floor(n * q - spread) - 1)  # 0-based ranks of the bounding order statistics
    hi = min(n - 1, math.ceil(n * q + spread))
    return float(x[lo]), float(x[hi])


@dataclass(frozen=True)
class Rate:
    """`hits` of `n`, with its 95 % Wilson interval (rate NaN when n is 0)."""

    hits: int
    n: int

    @property
    def value(self) -> float:
        return self.hits / self.n if self.n else float("nan")

    @property
    def interval(self) -> tuple[float, float]:
        return wilson_interval(self.hits, self.n)

    def as_dict(self) -> dict[str, Any]:
        low, high = self.interval
        rate = self.value if self.n else None
        return {"hits": self.hits, "n": self.n, "rate": rate, "ci95": [low, high]}

    def describe(self, percent: bool = True) -> str:
        """'98.9 % (97.9–99.4 %, 1010/1021)'."""
        if not self.n:
            return "n/a (no samples)"
        low, high = self.interval
        scale, unit = (100.0, " %") if percent else (1.0, "")
        interval = f"{low * scale:.2f}–{high * scale:.2f}{unit}"
        return f"{self.value * scale:.2f}{unit} ({interval}, {self.hits}/{self.n})"
