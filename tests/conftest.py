"""Shared test helpers: hypothesis strategies for PH data and waypoint sets."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from hypothesis import settings
from hypothesis import strategies as st

# CI runs the property tests with a fixed seed sequence, so a landing never depends on luck; developers
# get fresh random examples on every run (set HYPOTHESIS_PROFILE=ci to reproduce CI)
settings.register_profile("ci", derandomize=True, deadline=None)
if os.environ.get("CI") or os.environ.get("HYPOTHESIS_PROFILE") == "ci":
    settings.load_profile("ci")

#: The whole real CAM files beside the repository (../shared/data), read only by the ``slow`` whole-file tests
#: (skipped with a reason when the folder is absent, as on a clean clone).
SHARED_DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
#: Verbatim excerpts of those files kept in the repository (tests/data, see SOURCES.md there), read by the
#: default suite; tests.cam_excerpts maps their lines back to the whole files' line numbers.
EXCERPT_DATA = Path(__file__).resolve().parent / "data"

finite = st.floats(min_value=-3.0, max_value=3.0, allow_nan=False, allow_infinity=False)


@st.composite
def quaternions(draw, min_norm: float = 0.2):
    """A quaternion (4,) with norm at least ``min_norm``."""
    q = np.array(draw(st.lists(finite, min_size=4, max_size=4)))
    if np.linalg.norm(q) < min_norm:
        q = q + np.array([min_norm, 0.0, 0.0, 0.0])
    return q


@st.composite
def waypoint_sets(draw, min_size: int = 2, max_size: int = 30):
    """Random waypoint polylines with steps between 0.05 and about 2 (no near-duplicates)."""
    n = draw(st.integers(min_value=min_size, max_value=max_size))
    seed = draw(st.integers(min_value=0, max_value=2**32 - 1))
    rng = np.random.default_rng(seed)
    steps = rng.normal(size=(n - 1, 3))
    steps *= rng.uniform(0.05, 2.0, size=(n - 1, 1)) / np.linalg.norm(steps, axis=1, keepdims=True)
    return np.vstack((np.zeros(3), np.cumsum(steps, axis=0))) + rng.normal(size=3)
