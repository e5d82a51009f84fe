"""Type stub of the compiled grid search (planner/cam/_spin_search.c)."""

import numpy as np

def grid_search(
    q: np.ndarray, valid: np.ndarray, node: np.ndarray, dt: np.ndarray, dX: np.ndarray, spin: np.ndarray,
    inv_v: np.ndarray, free: int, K: int, weights: tuple[float, float, float, float, float], D: np.ndarray,
    back: np.ndarray,
) -> None: ...
