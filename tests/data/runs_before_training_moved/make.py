"""How this folder was written, at commit 171d3ab (before the training loop moved into
paramimic/training/): `git worktree add /tmp/old 171d3ab; PYTHONPATH=/tmp/old python make.py DIR
CONFIGS_JSON` with the CONFIGS of tests/test_behaviour_unchanged.py (P_θ 16-16 to keep the file
small): two iterations of each, the curriculum in the sampler service with its state in an
embedded Redis (password "compat"), the run directory and the Redis data beside it."""

import json
import shutil
import sys
from pathlib import Path

import redis as redis_lib
import torch
import yaml
from services.learner.trainer import SerialBackend, Trainer

from paramimic.config import ExperimentConfig
from paramimic.envs.skill_env import clip_setup
from services.launch.redis_server import EmbeddedRedis
from services.sampler.service import SamplerService

CONFIGS = json.loads(sys.argv[2])
out = Path(sys.argv[1])
for name, data in CONFIGS.items():
    torch.manual_seed(0)
    cfg = ExperimentConfig.model_validate(data | {"name": name})
    run = out / name
    shutil.rmtree(run, ignore_errors=True)
    with EmbeddedRedis(run / "redis", password="compat") as server:
        clip = None if cfg.env.clip is None else clip_setup(cfg)
        config = cfg.model_dump(mode="json")
        sampler = SamplerService(config, server.url, f"compat-{name}", clip=clip)
        trainer = Trainer(cfg, run, sampler)
        backend = SerialBackend(cfg, trainer.obs_dim, trainer.act_dim, trainer.curriculum)
        trainer.train(backend, total_steps=2 * 256)
        r = redis_lib.Redis.from_url(server.url)
        print(name, trainer.progress, sorted(k.decode() for k in r.keys("*")))
        r.bgrewriteaof()
    (run / "config.yaml").write_text(yaml.safe_dump(cfg.model_dump(mode="json")))
    for p in (run / "checkpoints").glob("ckpt_*"):
        p.unlink()
