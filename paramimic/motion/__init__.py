"""Reference motions: procedural keyframes now; clips, displacement and time warp in [L21]."""

from paramimic.motion.procedural import REFERENCE_MOTIONS, SinusoidalMotion

__all__ = ["REFERENCE_MOTIONS", "SinusoidalMotion"]
