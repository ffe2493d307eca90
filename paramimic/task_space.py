"""The task space A: a box of named parameters ([L21] §4.2; [WL19] §4.4).

Body parameters, physical ones and task goals all live in one box; a zero-width range is a
constraint: the parameter is fixed but still part of the policy's input.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class TaskSpace:
    names: tuple[str, ...]
    low: np.ndarray  # [d]
    high: np.ndarray  # [d]

    @classmethod
    def from_ranges(cls, ranges: Mapping[str, tuple[float, float]]) -> TaskSpace:
        names = tuple(ranges)
        low = np.array([float(ranges[n][0]) for n in names])
        high = np.array([float(ranges[n][1]) for n in names])
        if np.any(low > high):
            bad = [n for n, lo, hi in zip(names, low, high, strict=True) if lo > hi]
            raise ValueError(f"task range min > max for {bad}")
        return cls(names, low, high)

    @property
    def dim(self) -> int:
        return len(self.names)

    @property
    def width(self) -> np.ndarray:
        return self.high - self.low

    @property
    def center(self) -> np.ndarray:
        return 0.5 * (self.low + self.high)

    def base(self, shape_names: Iterable[str]) -> np.ndarray:
        """The base body's task: every shape parameter (`shape_names`) at 1.0, the base body's
        scale, clipped into its range; every other dimension at the range's centre."""
        shape = [name in set(shape_names) for name in self.names]
        return np.where(shape, np.clip(1.0, self.low, self.high), self.center)

    @property
    def free(self) -> np.ndarray:
        """[d] bool: dimensions with a non-zero range (the others are constraints)."""
        return self.width > 0

    @property
    def metric(self) -> np.ndarray:
        """diag A [d] of the distance (a − a')ᵀA(a − a') on the normalized box: 1/width² on free
        dimensions, 0 on fixed ones ([L21] Eq. 13 with A = I on normalized parameters)."""
        return np.where(self.free, 1.0 / np.where(self.free, self.width, 1.0) ** 2, 0.0)

    def normalize(self, a: np.ndarray) -> np.ndarray:
        """a mapped to the unit box: [0, 1] per free dimension, 0.5 on fixed ones: [n, d]."""
        a = np.atleast_2d(np.asarray(a, dtype=np.float64))
        x = (a - self.low) / np.where(self.free, self.width, 1.0)
        return np.where(self.free, x, 0.5)

    def scaled(self, a: np.ndarray) -> np.ndarray:
        """a mapped to [-1, 1] per free dimension, 0 on fixed ones (network inputs): [n, d]."""
        return 2.0 * self.normalize(a) - 1.0

    def ranges(self) -> dict[str, tuple[float, float]]:
        return {
            n: (float(lo), float(hi))
            for n, lo, hi in zip(self.names, self.low, self.high, strict=True)
        }

    def sample(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """n points drawn uniformly from the box: [n, d]."""
        return self.low + rng.random((n, self.dim)) * self.width

    def contains(self, a: np.ndarray, atol: float = 1e-9) -> np.ndarray:
        a = np.atleast_2d(a)
        return np.all((a >= self.low - atol) & (a <= self.high + atol), axis=-1)

    def to_dict(self, a: np.ndarray) -> dict[str, float]:
        return {n: float(v) for n, v in zip(self.names, np.asarray(a), strict=True)}

    def from_dict(self, values: Mapping[str, float]) -> np.ndarray:
        missing = set(self.names) - set(values)
        if missing:
            raise KeyError(f"task is missing parameters {sorted(missing)}")
        return np.array([float(values[n]) for n in self.names])

    def grid(self, dims: tuple[str, str], n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """An n x n grid over two named dims, the others at the box centre.

        Returns (xs [n], ys [n], points [n*n, d]) with points in row-major (y, x) order.
        """
        i, j = (self.names.index(d) for d in dims)
        xs = np.linspace(self.low[i], self.high[i], n)
        ys = np.linspace(self.low[j], self.high[j], n)
        pts = np.tile(self.center, (n * n, 1))
        yy, xx = np.meshgrid(ys, xs, indexing="ij")
        pts[:, i] = xx.ravel()
        pts[:, j] = yy.ravel()
        return xs, ys, pts
