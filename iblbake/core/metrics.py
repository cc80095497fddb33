"""Error metrics shared by tests, benchmarks and the accuracy study."""

from __future__ import annotations

import math

import numpy as np



def relative_rmse(a, b):
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return float(math.sqrt(np.mean((a - b) ** 2)) / max(math.sqrt(np.mean(b ** 2)), 1e-300))
