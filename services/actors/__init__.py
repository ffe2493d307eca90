"""Rollout actors on Ray (Part 2): thin shells around paramimic.rl.rollout.RolloutWorker."""
