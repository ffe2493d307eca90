"""Rollout actors on Ray: thin shells around paramimic.rl.rollout.RolloutWorker."""
