"""The elite set E of [L21] §5.2: every episode in it is the best within its neighbourhood.

A new episode (a, F) above the fitness threshold enters only if it beats every neighbour within
(a − a')ᵀA(a − a') < r² (Eq. 13) and then replaces them; otherwise it is dismissed. Neighbourhood
and k-nearest queries run on a scipy k-d tree over √A·a. scipy's tree is static, so inserts go to
a small brute-force tail and deletes to a mask; the tree is rebuilt from the live points when
the tail or the dead entries grow past a bound. Queries merge both parts, so they stay exact.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree


@dataclass
class Offer:
    """What happened to one offered episode."""

    accepted: bool
    replaced: list[str] = field(default_factory=list)  # keys of the neighbours it replaced
    # [L21] §6.1: it counts towards the exploration rate if accepted and its fitness beats every
    # replaced neighbour's by more than the improvement margin (a new region always counts)
    improved: bool = False


@dataclass(frozen=True)
class EliteRule:
    """Who enters: fitness above `threshold` and above every neighbour within `radius` (Eq.
    13, §5.2); an entry beating what it replaced by more than `improvement` counts towards the
    exploration rate (§6.1)."""

    radius: float = 0.1
    threshold: float = 0.1
    improvement: float = 0.02


class EliteSet:
    def __init__(
        self, dim: int, weights=None, rule: EliteRule = EliteRule(), rebuild_every: int = 256
    ) -> None:
        self.dim = dim
        self.weights = (
            np.ones(dim) if weights is None else np.asarray(weights, np.float64)
        )  # diag A
        if self.weights.shape != (dim,) or np.any(self.weights < 0):
            raise ValueError("weights must be the non-negative diagonal of A, one per dimension")
        self.rule = rule
        self.rebuild_every = rebuild_every
        self._params = np.empty((0, dim))  # a per slot (with spare capacity)
        self._fitness = np.empty(0)
        self._alive = np.empty(0, bool)
        self.keys: list[str] = []  # one per slot
        self.tree: cKDTree | None = None
        self.n_tree = 0  # slots [0, n_tree) are in the tree, the rest are the tail

    # --- queries --------------------------------------------------------------------------------

    @property
    def params(self) -> np.ndarray:
        return self._params[: len(self.keys)]

    @property
    def fitness(self) -> np.ndarray:
        return self._fitness[: len(self.keys)]

    @property
    def alive(self) -> np.ndarray:
        return self._alive[: len(self.keys)]

    def __len__(self) -> int:
        return int(self.alive.sum())

    def _scaled(self, a: np.ndarray) -> np.ndarray:
        return np.asarray(a, np.float64) * np.sqrt(self.weights)

    def _dist2(self, slots: np.ndarray, a: np.ndarray) -> np.ndarray:
        diff = self.params[slots] - a
        return (diff * diff * self.weights).sum(axis=-1)

    def neighbours(self, a: np.ndarray, radius: float | None = None) -> np.ndarray:
        """Live slots with (a − a')ᵀA(a − a') < r² (Eq. 13), sorted."""
        r = self.rule.radius if radius is None else radius
        a = np.asarray(a, np.float64)
        found = []
        if self.tree is not None:
            found.extend(self.tree.query_ball_point(self._scaled(a), r))
        found.extend(range(self.n_tree, len(self.keys)))
        slots = np.array(sorted(s for s in found if self.alive[s]), dtype=np.int64)
        if len(slots) == 0:
            return slots
        return slots[self._dist2(slots, a) < r * r]  # strict, and exact for the tail

    def distance(self, slots: np.ndarray, a: np.ndarray) -> np.ndarray:
        """√((a − a')ᵀA(a − a')) from `a` to the elites in `slots`: [len(slots)]."""
        return np.sqrt(self._dist2(np.asarray(slots, np.int64), np.asarray(a, np.float64)))

    def nearest(self, a: np.ndarray, k: int, among: np.ndarray | None = None) -> np.ndarray:
        """The k live slots nearest to `a` in the A-metric, nearest first (only those in
        `among` if given)."""
        a = np.asarray(a, np.float64)
        if among is not None:
            slots = np.asarray(among, np.int64)
            slots = slots[self.alive[slots]]
            return slots[np.argsort(self._dist2(slots, a), kind="stable")[:k]]
        candidates = list(range(self.n_tree, len(self.keys)))
        if self.tree is not None:
            dead = self.n_tree - int(self.alive[: self.n_tree].sum())
            kk = min(self.n_tree, k + dead)  # enough to hold k live ones
            _, idx = self.tree.query(self._scaled(a), k=kk)
            candidates.extend(np.atleast_1d(idx).tolist())
        slots = np.array([s for s in candidates if self.alive[s]], dtype=np.int64)
        if len(slots) == 0:
            return slots
        order = np.argsort(self._dist2(slots, a), kind="stable")
        return slots[order[:k]]

    def within_box(self, low: np.ndarray | None, high: np.ndarray | None) -> np.ndarray:
        """Live slots with low <= a <= high (None: unbounded on that side)."""
        low = np.full(self.dim, -np.inf) if low is None else low
        high = np.full(self.dim, np.inf) if high is None else high
        inside = np.all((self.params >= low) & (self.params <= high), axis=1) & self.alive
        return np.flatnonzero(inside)

    def live(self) -> np.ndarray:
        return np.flatnonzero(self.alive)

    # --- the elite rule -------------------------------------------------------------------------

    def offer(self, a: np.ndarray, fitness: float, key: str) -> Offer:
        """[L21] §5.2: enter if F > threshold and F > F' of every neighbour; replace them."""
        a = np.asarray(a, np.float64).reshape(self.dim)
        if not fitness > self.rule.threshold:
            return Offer(False)
        near = self.neighbours(a)
        if len(near) and not np.all(fitness > self.fitness[near]):
            return Offer(False)
        margin = self.rule.improvement
        improved = not len(near) or bool(np.all(fitness - self.fitness[near] > margin))
        replaced = [self.keys[s] for s in near]
        self.alive[near] = False
        self._insert(a, fitness, key)
        return Offer(True, replaced, improved)

    def _insert(self, a: np.ndarray, fitness: float, key: str) -> None:
        n = len(self.keys)
        if n == len(self._params):  # grow by doubling: amortised O(1) inserts
            cap = max(16, 2 * n)
            self._params = np.resize(self._params, (cap, self.dim))
            self._fitness = np.resize(self._fitness, cap)
            self._alive = np.resize(self._alive, cap)
        self._params[n], self._fitness[n], self._alive[n] = a, fitness, True
        self.keys.append(key)
        tail = len(self.keys) - self.n_tree
        dead = len(self.keys) - len(self)
        if tail > self.rebuild_every or dead > max(self.rebuild_every, len(self)):
            self._rebuild()

    def _rebuild(self) -> None:
        """Compact to the live entries and put them all in a new tree."""
        keep = self.live()
        self._params, self._fitness = self.params[keep], self.fitness[keep]
        self.keys = [self.keys[s] for s in keep]
        self._alive = np.ones(len(keep), bool)
        self.n_tree = len(keep)
        self.tree = cKDTree(self._scaled(self.params)) if len(keep) else None

    # --- state ----------------------------------------------------------------------------------

    def to_state(self) -> dict:
        keep = self.live()
        return {
            "params": self.params[keep].tolist(),
            "fitness": self.fitness[keep].tolist(),
            "keys": [self.keys[s] for s in keep],
        }

    def from_state(self, state: dict) -> None:
        self._params = np.asarray(state["params"], np.float64).reshape(-1, self.dim)
        self._fitness = np.asarray(state["fitness"], np.float64)
        self.keys = list(state["keys"])
        self._alive = np.ones(len(self.keys), bool)
        self.n_tree = 0
        self._rebuild()
