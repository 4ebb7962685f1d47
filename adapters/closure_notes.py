"""The note an engine adapter gives on redundant loop-closure equations.

A closure model has redundant rows of its own (a planar revolute closed by a 3-D point: one, a
spatial revolute by two: ``SpanningTree.redundant_closure_equations``), but an overconstrained
mechanism (Bennett's 4R, Bricard's 6R, parallel revolutes drawn in space) makes more of them
dependent.  The adapters may not use the harness's rank analysis, so each counts with its engine's
own closure Jacobian at the start; :func:`redundancy_notes` turns that Jacobian into the count and
the note, the same for every engine.
"""

from __future__ import annotations

import numpy as np


def redundancy_notes(jacobian: np.ndarray, of_model: int, rank_rtol: float) -> list[str]:
    """The note counting the redundant rows of a closure Jacobian, shape (rows, coordinates), at
    the start: its rank by the singular values above ``rank_rtol`` · σ_max, the mechanism's share
    the rows beyond the rank less the closure model's own ``of_model``.  None when no row is
    redundant.  At a singular position the rank drops further and the count includes it."""
    rows = jacobian.shape[0]
    if rows == 0:
        return []
    sigma = np.linalg.svd(jacobian, compute_uv=False)
    rank = int(np.count_nonzero(sigma > rank_rtol * sigma[0])) if sigma[0] > 0.0 else 0
    redundant = rows - rank
    if redundant == 0:
        return []
    return [f"{redundant} redundant closure equation(s) of {rows} (rank {rank} at the start): "
            f"{redundant - of_model} of the mechanism, {of_model} of the closure model"]
