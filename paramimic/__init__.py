"""paramimic: parametric physics-based character controllers ([WL19], [L21])."""

__version__ = "0.1.0"
