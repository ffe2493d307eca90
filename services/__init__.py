"""Runtime shells around the paramimic library: CLI, learner, actors, sampler, API."""
