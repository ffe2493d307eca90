"""The launcher: starts (or joins) Redis, Ray, the sampler, the actors, the learner and the API."""
