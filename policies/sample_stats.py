"""The two summaries every evaluation file reports: the share of episodes with a property, and the distribution
of a sample, both as JSON-ready numbers (units: those of the input)."""

from __future__ import annotations

import numpy as np


def percent(mask: np.ndarray) -> float | None:
    """Percentage of True entries; None (JSON null) for no entries."""
    return 100.0 * float(mask.mean()) if mask.size else None


def describe(values: np.ndarray) -> dict[str, float | int]:
    """Count, mean, 10/25/50/75/90th percentiles, min and max of ``values``; only the count (0) when empty."""
    if values.size == 0:
        return {"count": 0}
    q = np.percentile(values, [10, 25, 50, 75, 90])
    return {"count": int(values.size), "mean": float(values.mean()), "p10": float(q[0]), "p25": float(q[1]),
            "median": float(q[2]), "p75": float(q[3]), "p90": float(q[4]), "min": float(values.min()),
            "max": float(values.max())}
