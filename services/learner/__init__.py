"""The learner process: the training loop and checkpoints."""
