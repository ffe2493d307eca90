"""The kNN proxy of [L21] §5.3 (Eq. 14): a motion trace for parameter a interpolated from its
k nearest elites, weighted by fitness and distance, used until P_θ's regression loss is low."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from paramimic.curriculum.elite_set import EliteSet


def knn_weights(
    params: np.ndarray, fitness: np.ndarray, a: np.ndarray, weights: np.ndarray, sigma: float
) -> np.ndarray:
    """w_k = F_k exp(−(a_k − a)ᵀA(a_k − a) / σ_k²) (Eq. 14), normalized to sum 1: [k]."""
    d2 = ((np.asarray(params) - a) ** 2 * weights).sum(axis=-1)
    w = np.asarray(fitness) * np.exp(-d2 / sigma**2)
    return w / w.sum()


def knn_proxy(
    elites: EliteSet,
    trace_of: Callable[[str], np.ndarray],
    a: np.ndarray,
    k: int = 5,
    sigma: float = 0.28,
) -> np.ndarray | None:
    """Σ w_k trace_k over the k elites nearest to a ([L21]: k = 5, σ_k = 0.28); traces are
    {(d_t, τ_t)} arrays of one shape. None while the elite set is empty."""
    a = np.asarray(a, np.float64)
    nearest = elites.nearest(a, k)
    if len(nearest) == 0:
        return None
    w = knn_weights(elites.params[nearest], elites.fitness[nearest], a, elites.weights, sigma)
    traces = np.stack([trace_of(elites.keys[s]) for s in nearest])
    return np.tensordot(w, traces, axes=1)
