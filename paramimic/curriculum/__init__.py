"""The curriculum: task space, marginal value V̄, adaptive MCMC sampling ([WL19] §4.2)."""

from paramimic.curriculum.marginal_value import MarginalValue
from paramimic.curriculum.mcmc import AdaptiveSampler, metropolis_hastings, surrogate_log_density
from paramimic.curriculum.task_space import TaskSpace

__all__ = [
    "AdaptiveSampler",
    "MarginalValue",
    "TaskSpace",
    "metropolis_hastings",
    "surrogate_log_density",
]
