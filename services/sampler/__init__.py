"""The sampler service: the curriculum ([WL19] adaptive sampling) as a Ray actor, state in Redis."""
