"""Runs of True in a boolean frame mask (contacts, tracked frames, swapped frames, repeats).
No bpy."""
from __future__ import annotations

import numpy as np


def run_bounds(mask):
    """``(starts, stops)``: int arrays of the runs of True in the 1-D bool ``mask``, each run
    ``mask[start:stop]``, in order."""
    d = np.diff(np.concatenate([[0], np.asarray(mask, bool).astype(np.int8), [0]]))
    return np.nonzero(d == 1)[0], np.nonzero(d == -1)[0]


def runs(mask):
    """``[(start, stop), ...]`` (Python ints) of the runs of True in the 1-D bool ``mask``."""
    starts, stops = run_bounds(mask)
    return list(zip(starts.tolist(), stops.tolist()))
