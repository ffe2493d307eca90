"""The training loop of the library: [WL19] Alg. 1 with the rollouts behind a backend and the task
sampling behind a curriculum (`trainer`), and the run directory's checkpoints (`checkpoint`).
The services run it on Ray with Redis, an API and a launcher around it; benchmarks and tests
train with it directly (`SerialBackend`)."""
