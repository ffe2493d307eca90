"""The progress API (Part 3): FastAPI over Redis."""
