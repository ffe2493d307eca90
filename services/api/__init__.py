"""The progress API (FastAPI): reads Redis only; never imports torch, mujoco or ray."""
