"""RL core: networks, running stats, variable-Δt GAE, PPO, the rollout loop."""
