"""Type stub of the compiled member rule (planner/curves/_hermite_member.c)."""

import numpy as np

_Rule = tuple[np.ndarray, ...]  # (w, Ms, Mw) of ph_quintic._energy_matrices

def least_energy_members(
    X: np.ndarray, root_scale: np.ndarray, out: np.ndarray, screen_factor: float, tie: float, axis_fallback: float,
    axis_fade: float, equal: float, screen: _Rule, screen_lo: _Rule, full: _Rule, full_lo: _Rule,
) -> None: ...
