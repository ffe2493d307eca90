"""The sampler service (Part 3): paramimic.curriculum behind a named Ray actor, state in Redis."""
