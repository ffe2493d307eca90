"""Families that learn: what makes one controller work on most bodies of walker_legs.

Each variant is a set of config overrides on configs/walker_legs.yaml, trained with the serial
trainer (one torch thread, so two runs share the 2 cores) and evaluated with the deterministic
policy on 300 shapes drawn with a seed no training run uses (EVAL_SEED) plus a 7x7 grid of the
two leg lengths, 10 s episodes. Runs are resumable: `run` continues from the run dir's latest
checkpoint (runs/study/<variant>_s<seed>), so an interrupted study loses at most 10 iterations.

    python benchmarks/family_study.py run std_frozen --seed 0 --steps 2000000
    python benchmarks/family_study.py queue std_frozen,kl_adaptive --seeds 0 --steps 2000000
    python benchmarks/family_study.py merge   # the table and benchmarks/results/study_curves.png
    python benchmarks/family_study.py probe base_legs --seed 0   # a run's controller on the family
    python benchmarks/family_study.py fragility biped_base_heading0.8_std0.1  # base -> family
    python benchmarks/family_study.py sensitivity biped_base_heading0.8_std0.1  # one part at a time
    python benchmarks/family_study.py fit-offsets   # how far Eq. 1 moves a body's first pose
    python benchmarks/family_study.py reference   # the pose bell of every body on its reference
    python benchmarks/family_study.py headings biped_base --seed 0   # where a 3D body turned
    python benchmarks/family_study.py stopped k0 --seed 0   # a stopped screen's training curve

Each run writes benchmarks/results/study_<variant>_s<seed>_<M>M.json (evaluation, config,
the training curve); `merge` writes study.json: per variant and budget, mean and spread over
seeds of falls, mean return, worst-decile return, forward speed and the final policy std.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import time
import warnings
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results"
RUNS = ROOT / "runs" / "study"
sys.path.insert(0, str(ROOT / "benchmarks"))
EVAL_SEED = 2024  # never a training seed
EVAL_EPISODES = 300
CONFIG = "configs/walker_legs.yaml"
# Every variant states the knobs the study varies, so that it means the same whatever the
# config ships (configs/walker_legs.yaml now carries the winner, `retarget_stall`); a variant that
# does not name env.retarget, the stall rule or the normalizer's floor runs without them
# (`variant_config`), as it was measured (configs/biped_lower.yaml ships the floor).
UNNAMED = {"env.retarget": False, "env.stall_speed_ratio": None, "ppo.obs_std_floor": 0.0}
# the learned policy std of the first walker_legs recipe
LEARNED = {"ppo.learn_std": True, "ppo.init_log_std": -1.0}
FROZEN = {"ppo.learn_std": False, "ppo.init_log_std": math.log(0.2)}
STD01 = {"ppo.learn_std": False, "ppo.init_log_std": math.log(0.1)}
STD005 = {"ppo.learn_std": False, "ppo.init_log_std": math.log(0.05)}
G95 = {"ppo.gamma": 0.95}  # [WL19] Table 2
G99 = {"ppo.gamma": 0.99}
TABLE2 = {"ppo.policy_lr": 5e-5, "ppo.value_lr": 1e-4, "ppo.minibatch_size": 128}
K0 = {"curriculum.k": 0.0}
BASE_LEGS = "runs/study/base_legs_s{seed}"
PRODUCT = {"env.reward.combine": "product"}
RETARGET = {"env.retarget": True}
STALL = {"env.stall_speed_ratio": 0.5}
HEADING = {"env.heading_error_limit": 0.8}
FLOOR = {"ppo.obs_std_floor": 0.02}
# the walker study's widening ranges were promoted on falls alone (WidenConfig.promote_on)
WIDEN_FALLS = {"curriculum.widen": {"promote_on": "falls"}}
BIPED_BASE_RUN = "runs/study/biped_base_heading0.8_std0.1_s{seed}"  # the base biped, 2M steps
BIPED_FLOOR_RUN = "runs/study/biped_base_heading0.8_std0.1_floor_s{seed}"  # 2M steps
QUADRUPED_BASE_RUN = "runs/study/quadruped_base_stall_s{seed}"  # the base quadruped, 2M steps
# a range grown from the base body in steps of 5 % of each range (the base controller, warm
# started, falls on 57 % of bodies whose height alone varies by +-2.5 %: `fragility`)
SLOW_WIDEN = {"curriculum.widen": {"start": 0.05, "step": 0.05, "promote_on": "falls"}}
# the same steps judged at the range's edge by the deterministic policy (WidenConfig `edge`)
EDGE_WIDEN = {
    "curriculum.widen": {
        "start": 0.05,
        "step": 0.05,
        "promote_on": "edge",
        "window": 16,
        "promote_below": 0.25,
        "check_every": 10,
    }
}
VARIANTS: dict[str, dict] = {
    # PPO as first shipped (learned std from e^-1, gamma 0.95), the rule fixes in
    "learned_std": LEARNED | G95,
    "k0": LEARNED | G95 | K0,
    "kl_adaptive": LEARNED | G95 | {"ppo.desired_kl": 0.01},
    "table2_steps": LEARNED | G95 | TABLE2,
    "std_frozen": FROZEN | G95,
    "std_frozen_k0": FROZEN | G95 | K0,
    "std_frozen_kl_adaptive": FROZEN | G95 | {"ppo.desired_kl": 0.01},
    "std_frozen_table2": FROZEN | G95 | TABLE2,
    "std_0.1": STD01 | G95,
    "std_frozen_batch16k": FROZEN | G95 | {"ppo.num_steps": 16384, "ppo.minibatch_size": 2048},
    # the base body alone (legs fixed at 1.0, the family's env layout): the warm start's source
    "base_legs": FROZEN
    | G95
    | {"task.left_leg_length": [1.0, 1.0], "task.right_leg_length": [1.0, 1.0]},
    # the family from the base body's controller (run base_legs with the same seed first)
    "warm_std_frozen": FROZEN | G95 | {"train.init_from": BASE_LEGS},
    # the range grows from the base body as it is mastered (curriculum.widen), k = 10 inside it
    "widen_std_frozen": FROZEN | G95 | WIDEN_FALLS,
    "warm_widen_std_frozen": FROZEN | G95 | WIDEN_FALLS | {"train.init_from": BASE_LEGS},
    # the best recipe without retargeting and its uniform-sampling twin
    "std_frozen_gamma99": FROZEN | G99,
    "std_frozen_gamma99_k0": FROZEN | G99 | K0,
    "std_frozen_gamma99_widen": FROZEN | G99 | WIDEN_FALLS,
    # every surviving recipe stands more than it walks (0.2 m/s): the COM-velocity term
    # (w4, 1 of the walker's 14) weighed 4x, alone and with the widening range
    "std_frozen_gamma99_vel4": FROZEN | G99 | {"env.reward.w_com_velocity": 4.0},
    "std_frozen_gamma99_vel4_widen": FROZEN
    | G99
    | WIDEN_FALLS
    | {"env.reward.w_com_velocity": 4.0},
    # standing still stops paying: the episode ends below half the target speed (2 s average)
    "std_frozen_gamma99_stall": FROZEN | G99 | {"env.stall_speed_ratio": 0.5},
    "std_frozen_gamma99_stall_widen": FROZEN | G99 | WIDEN_FALLS | {"env.stall_speed_ratio": 0.5},
    # the bells multiplied, not added (env.reward.combine): standing still stops paying half
    # of a walking step (the sum's end-effector, direction and torque bells)
    # (measured with the stall rule, which walker_legs.yaml shipped by then and variant_config
    # did not yet switch off for variants that do not name it: STALL keeps what they measured)
    "product": FROZEN | G99 | PRODUCT | STALL,
    "product_g95": FROZEN | G95 | PRODUCT | STALL,
    # every leg follows the base leg's hip-to-ankle path scaled by the shortest leg
    # (env.retarget): a reference that bodies with legs of unequal length can follow; with the
    # stall rule, the winner: what configs/walker_legs.yaml ships (`_k0`: uniform sampling)
    "retarget": FROZEN | G99 | RETARGET,
    "retarget_stall": FROZEN | G99 | RETARGET | STALL,
    "retarget_stall_k0": FROZEN | G99 | RETARGET | STALL | K0,
    # the winning recipe on the [WL19] §5.3 3D characters (the other target rows)
    "biped_base": FROZEN | G99,
    # the base biped turns away from its target and falls after it (`headings biped_base`: 16 of
    # 20 episodes fell after facing 1.0-3.1 rad off): the episode ends beyond the limit
    "biped_base_heading0.5": FROZEN | G99 | {"env.heading_error_limit": 0.5},
    "biped_base_heading0.8": FROZEN | G99 | HEADING,
    # its failing seed runs 1.44 m/s for a 1 m/s target: the COM-velocity bell weighed 4x
    "biped_base_heading0.8_vel4": FROZEN | G99 | HEADING | {"env.reward.w_com_velocity": 4.0},
    # half the exploration noise: a 3D body balances in roll as well as pitch
    "biped_base_heading0.8_std0.1": STD01 | G99 | HEADING,
    "biped_x0.5": FROZEN | G99,
    "biped_x0.5_std0.1": STD01 | G99 | HEADING,
    # its seeds stalled at a training return of ~22 (the base body's: 115 at 1.4M): the family
    # with uniform sampling, and with only the global scales varying (every body symmetric)
    "biped_x0.5_std0.1_k0": STD01 | G99 | HEADING | K0,
    "biped_x0.5_std0.1_global": STD01 | G99 | HEADING,
    # symmetric bodies learn faster (global: 34 at 0.6M against 20): the legs retargeted
    "biped_x0.5_std0.1_retarget": STD01 | G99 | HEADING | RETARGET,
    # the family grown from the base body, warm started from the base biped
    "biped_x0.5_std0.1_warm_widen": STD01
    | G99
    | HEADING
    | SLOW_WIDEN
    | {"train.init_from": BIPED_BASE_RUN},
    # its updates move the policy far: approx. KL 0.1-0.2 per update by 1.3M, 0.54 at 10M (std 0.1
    # makes a small step of the mean a large KL): a 4x smaller policy step
    "biped_x0.5_std0.1_lr5e-5": STD01 | G99 | HEADING | {"ppo.policy_lr": 5e-5},
    # its training episodes fall with the policy's noise (85 %; the base body's 40 % at 2M,
    # 79 % with std 0.2): half of it again
    "biped_x0.5_std0.05": STD005 | G99 | HEADING,
    # warm started, promoted below 50 % training falls, the range grew to 0.2 by 2M; its
    # controller then falls on 2.5 % of x0.05 bodies (the base body's: 67.5 %), 72.5 % of x0.25
    # ones (`fragility`): a range grown faster, below 70 % training falls (the base body's own
    # training episodes fell 40 % with the policy's noise, its held-out ones 2 %)
    "biped_x0.5_std0.1_warm_widen0.7": STD01
    | G99
    | HEADING
    | {"curriculum.widen": SLOW_WIDEN["curriculum.widen"] | {"promote_below": 0.7}}
    | {"train.init_from": BIPED_BASE_RUN},
    # the base biped's gait is a knife edge in the body's height (`fragility`: 57.5 % falls at
    # +-2.5 %): the recipe on bodies jittered that much (x0.05), from scratch
    "biped_x0.05_std0.1": STD01 | G99 | HEADING,
    # its training return stayed at 38 by 2M (the base body's: 176): the same bodies, the
    # policy blind to them (env.observe_shape false: its shape inputs are the base body's)
    "biped_x0.05_std0.1_blind": STD01 | G99 | HEADING | {"env.observe_shape": False},
    # blind to the shape it learned faster (62 against 38 at 1.23M; the base body: 104): the
    # x0.5 family blind; and without the [WL19] Eq. 1 ground fit of the initial posture, which
    # moves an x0.5 body's joints up to 0.5 rad off its reference (0.05 at x0.05), a jerk at
    # the first step when the servos pull them back
    "biped_x0.5_std0.1_blind": STD01 | G99 | HEADING | {"env.observe_shape": False},
    "biped_x0.5_std0.1_nofit": STD01 | G99 | HEADING | {"env.ground_fit": False},
    # the base gait hinges on the torso (`sensitivity`: 90-100 % falls with the torso 2 % shorter
    # or taller): its height in the root frame, held by a stiff ball joint, varied by 0.2-0.7 mm
    # in the base body's training, so 2 % moved that input 5-17 sigma: the normalizer's std
    # floored at 2 cm / 0.02 rad (ppo.obs_std_floor), on the base body and the x0.5 family
    "biped_base_heading0.8_std0.1_floor": STD01 | G99 | HEADING | FLOOR,
    "biped_x0.5_std0.1_floor": STD01 | G99 | HEADING | FLOOR,
    # the floored base controller falls on 15 % of x0.05 bodies (without the floor: 67.5 %): the
    # x0.5 family from it, legs retargeted (what is left of its fragility is one-sided legs)
    "biped_x0.5_std0.1_floor_warm": STD01
    | G99
    | HEADING
    | FLOOR
    | RETARGET
    | {"train.init_from": BIPED_FLOOR_RUN},
    # what made the quadruped family from its base controller meet its target: a small step
    "biped_x0.5_std0.1_floor_warm_kl": STD01
    | G99
    | HEADING
    | FLOOR
    | RETARGET
    | {"train.init_from": BIPED_FLOOR_RUN, "ppo.desired_kl": 0.01},
    # the same, the range grown from the base body (the unfloored base's widening reached 20 % of
    # the ranges by 2M with the full step, where its near family was learned: `fragility`)
    "biped_x0.5_std0.1_floor_warm_widen_kl": STD01
    | G99
    | HEADING
    | FLOOR
    | RETARGET
    | SLOW_WIDEN
    | {"train.init_from": BIPED_FLOOR_RUN, "ppo.desired_kl": 0.01},
    # its range grew by 5 % per 0.04-0.6M steps (20 % at 1.3M), promoted below 50 % training falls
    # where the base body's own training episodes fell 40 % with the policy's noise: below 60 %
    # (with the full step, below 70 % collapsed the controller: `_warm_widen0.7`)
    "biped_x0.5_std0.1_floor_warm_widen0.6_kl": STD01
    | G99
    | HEADING
    | FLOOR
    | RETARGET
    | {"curriculum.widen": SLOW_WIDEN["curriculum.widen"] | {"promote_below": 0.6}}
    | {"train.init_from": BIPED_FLOOR_RUN, "ppo.desired_kl": 0.01},
    # the range judged by ADR's boundary test instead: every 10 iterations, the mean action on 16
    # bodies at the range's edge; it grows 5 % when fewer than 25 % of them fell
    "biped_x0.5_std0.1_floor_warm_edge_kl": STD01
    | G99
    | HEADING
    | FLOOR
    | RETARGET
    | EDGE_WIDEN
    | {"train.init_from": BIPED_FLOOR_RUN, "ppo.desired_kl": 0.01},
    "quadruped_x0.5": FROZEN | G99,
    # its seed 0 stood at 10M (16.7 % falls at 0.11 m/s) and turned in place (`headings
    # quadruped_x0.5`: 12 of 20 episodes faced more than 1.2 rad off): the biped's recipe, and
    # that with the walker's stall rule
    "quadruped_x0.5_retarget": FROZEN | G99 | RETARGET,
    # retargeted, it stands steadier (5-11 % falls at 2M) but still at 0.17-0.18 m/s: with the
    # stall rule that made walker_legs walk once it joined the retargeted reference
    "quadruped_x0.5_retarget_stall": FROZEN | G99 | RETARGET | STALL,
    # with the stall rule its training return stayed at ~45 to 1M (episodes end at the stall
    # window): can the base quadruped walk at all with this reference and reward?
    "quadruped_base_stall": FROZEN | G99 | STALL,
    # it walks (training return 213 at 0.94M, 0 % held-out falls at 2M): the x0.5 family from its
    # controller, legs retargeted, the stall rule kept
    "quadruped_x0.5_warm_stall": FROZEN
    | G99
    | RETARGET
    | STALL
    | {"train.init_from": QUADRUPED_BASE_RUN},
    # its held-out falls grew from 3M to 5M (22 -> 30 %) while the updates' approx. KL climbed
    # (0.25 -> 0.8) with 72-77 % of samples clipped: smaller policy steps, [WL19] Table 2's
    # policy step size or rsl_rl's KL-adapted one
    "quadruped_x0.5_warm_stall_lr5e-5": FROZEN
    | G99
    | RETARGET
    | STALL
    | {"train.init_from": QUADRUPED_BASE_RUN, "ppo.policy_lr": 5e-5},
    "quadruped_x0.5_warm_stall_kl": FROZEN
    | G99
    | RETARGET
    | STALL
    | {"train.init_from": QUADRUPED_BASE_RUN, "ppo.desired_kl": 0.01},
    "quadruped_x0.5_std0.1_heading": STD01 | G99 | HEADING,
    "quadruped_x0.5_std0.1_heading_stall": STD01 | G99 | HEADING | STALL,
}
# variants whose bodies vary only by the global scales b_g (symmetric bodies)
GLOBAL_ONLY = frozenset({"biped_x0.5_std0.1_global"})
# variants on another config: (config, shape scale s: every shape range shrunk toward the base
# body, lo' = 1 - s(1 - lo), hi' = 1 + s(hi - 1); s = 0 is the base body alone)
OTHER_CONFIGS: dict[str, tuple[str, float]] = {
    "biped_base": ("configs/biped_lower.yaml", 0.0),
    "biped_base_heading0.5": ("configs/biped_lower.yaml", 0.0),
    "biped_base_heading0.8": ("configs/biped_lower.yaml", 0.0),
    "biped_base_heading0.8_vel4": ("configs/biped_lower.yaml", 0.0),
    "biped_base_heading0.8_std0.1": ("configs/biped_lower.yaml", 0.0),
    "biped_x0.5": ("configs/biped_lower.yaml", 0.5),
    "quadruped_x0.5": ("configs/quadruped.yaml", 0.5),
    "quadruped_x0.5_std0.1_heading": ("configs/quadruped.yaml", 0.5),
    "quadruped_x0.5_std0.1_heading_stall": ("configs/quadruped.yaml", 0.5),
    "biped_x0.5_std0.1": ("configs/biped_lower.yaml", 0.5),
    "biped_x0.5_std0.1_k0": ("configs/biped_lower.yaml", 0.5),
    "biped_x0.5_std0.1_global": ("configs/biped_lower.yaml", 0.5),
    "biped_x0.5_std0.1_retarget": ("configs/biped_lower.yaml", 0.5),
    "quadruped_x0.5_retarget": ("configs/quadruped.yaml", 0.5),
    "quadruped_x0.5_retarget_stall": ("configs/quadruped.yaml", 0.5),
    "quadruped_base_stall": ("configs/quadruped.yaml", 0.0),
    "quadruped_x0.5_warm_stall": ("configs/quadruped.yaml", 0.5),
    "quadruped_x0.5_warm_stall_lr5e-5": ("configs/quadruped.yaml", 0.5),
    "quadruped_x0.5_warm_stall_kl": ("configs/quadruped.yaml", 0.5),
    "biped_x0.5_std0.1_warm_widen": ("configs/biped_lower.yaml", 0.5),
    "biped_x0.5_std0.1_lr5e-5": ("configs/biped_lower.yaml", 0.5),
    "biped_x0.5_std0.05": ("configs/biped_lower.yaml", 0.5),
    "biped_x0.05_std0.1": ("configs/biped_lower.yaml", 0.05),
    "biped_x0.05_std0.1_blind": ("configs/biped_lower.yaml", 0.05),
    "biped_x0.5_std0.1_blind": ("configs/biped_lower.yaml", 0.5),
    "biped_x0.5_std0.1_nofit": ("configs/biped_lower.yaml", 0.5),
    "biped_base_heading0.8_std0.1_floor": ("configs/biped_lower.yaml", 0.0),
    "biped_x0.5_std0.1_floor": ("configs/biped_lower.yaml", 0.5),
    "biped_x0.5_std0.1_floor_warm": ("configs/biped_lower.yaml", 0.5),
    "biped_x0.5_std0.1_floor_warm_kl": ("configs/biped_lower.yaml", 0.5),
    "biped_x0.5_std0.1_floor_warm_widen_kl": ("configs/biped_lower.yaml", 0.5),
    "biped_x0.5_std0.1_floor_warm_widen0.6_kl": ("configs/biped_lower.yaml", 0.5),
    "biped_x0.5_std0.1_floor_warm_edge_kl": ("configs/biped_lower.yaml", 0.5),
    "biped_x0.5_std0.1_warm_widen0.7": ("configs/biped_lower.yaml", 0.5),
}


def variant_config(variant: str, seed: int) -> tuple[str, dict]:
    """The config file and the overrides of a variant (the shape ranges of other configs' ones)."""
    config, scale = OTHER_CONFIGS.get(variant, (CONFIG, 1.0))
    overrides = {
        k: ROOT / v.format(seed=seed) if k == "train.init_from" else v
        for k, v in (UNNAMED | VARIANTS[variant]).items()
    }
    if scale != 1.0:
        from normalization import shrunk_shape_ranges

        character = Path(config).stem
        overrides |= shrunk_shape_ranges(character, scale)
    if variant in GLOBAL_ONLY:  # the parts' own scales b_l stay at the base body's
        overrides |= {k: [1.0, 1.0] for k in overrides if k.startswith("task.")
                      and not k.startswith("task.global_")}  # fmt: skip
    return config, overrides


# what a result file keeps of each training iteration (metrics.jsonl)
CURVE_KEYS = ("env_steps", "mean_return", "fall_percent", "mean_length", "std", "approx_kl",
              "clip_fraction", "policy_lr", "range_width", "edge_fall_percent")  # fmt: skip


def _report_path(variant: str, seed: int, steps: int) -> Path:
    return RESULTS / f"study_{variant}_s{seed}_{steps / 1e6:g}M.json"


def run(variant: str, seed: int, steps: int) -> dict:
    """Train (or continue) one variant and seed to `steps` env steps, then evaluate."""
    warnings.filterwarnings("ignore")
    from paramimic.config import load_config
    from paramimic.evaluation import evaluate_config
    from paramimic.training import checkpoint
    from paramimic.training.trainer import SerialBackend, Trainer

    run_dir = RUNS / f"{variant}_s{seed}"
    config, variant_overrides = variant_config(variant, seed)
    overrides = variant_overrides | {
        "train.run_dir": str(run_dir),
        "train.seed": seed,
        "train.torch_threads": 1,
    }
    cfg = load_config(ROOT / config, overrides)
    run_dir.mkdir(parents=True, exist_ok=True)
    trainer = Trainer(cfg, run_dir)
    latest = checkpoint.checkpoint_dir(run_dir) / checkpoint.LATEST
    if latest.exists():
        trainer.load_state_dict(checkpoint.load(latest))
    backend = SerialBackend(cfg, trainer.obs_dim, trainer.act_dim, trainer.curriculum)
    t0 = time.perf_counter()
    trainer.train(backend, steps)
    backend.close()
    report = evaluate_config(trainer.learner.policy, cfg, EVAL_EPISODES, EVAL_SEED, 7, seconds=10.0)
    curve = [json.loads(line) for line in (run_dir / "metrics.jsonl").read_text().splitlines()]
    report |= {
        "variant": variant,
        "overrides": VARIANTS[variant],
        "config": config,
        "seed": seed,
        "env_steps": trainer.progress.env_steps,
        "seconds_this_session": time.perf_counter() - t0,
        "final_std": float(np.exp(trainer.learner.policy.log_std.detach().numpy()).mean()),
        "curve": [{k: m[k] for k in CURVE_KEYS if k in m} for m in curve],
    }
    RESULTS.mkdir(parents=True, exist_ok=True)
    _report_path(variant, seed, steps).write_text(json.dumps(report, indent=2))
    return report


def _run_state(variant: str, seed: int) -> tuple[dict, dict]:
    """A study run's latest checkpoint and its config's env section."""
    from paramimic.config import ExperimentConfig
    from paramimic.training import checkpoint

    state = checkpoint.load(RUNS / f"{variant}_s{seed}")
    return state, ExperimentConfig.model_validate(state["config"]).env.model_dump()


def _adopted(state: dict, cfg):
    """The checkpoint's controller warm started on `cfg`'s family as `train.init_from` does
    (adopt_controller: inputs constant in its training start ignored)."""
    import torch

    from paramimic.config import ExperimentConfig
    from paramimic.rl.ppo import PPOLearner, adopt_controller
    from paramimic.training.trainer import reset_observations

    source = ExperimentConfig.model_validate(state["config"])
    learner = PPOLearner(state["obs_dim"], state["act_dim"], source.ppo)
    adopt_controller(learner, state["learner"], reset_observations(cfg))
    torch.set_num_threads(1)
    return learner.policy


def probe(variant: str, seed: int, episodes: int = 100) -> dict:
    """A study run's controller (its latest checkpoint) on the whole family of CONFIG: e.g. how
    far the base body's controller (`base_legs`) carries, blind to the shape as a warm start
    begins. Writes study_probe_<variant>_s<seed>.json."""
    warnings.filterwarnings("ignore")
    from paramimic.config import load_config
    from paramimic.evaluation import evaluate_config

    state, env = _run_state(variant, seed)
    cfg = load_config(ROOT / CONFIG, {"env": env})
    policy = _adopted(state, cfg)
    report = evaluate_config(policy, cfg, episodes, EVAL_SEED, 7, seconds=10.0)
    report |= {"variant": variant, "seed": seed, "family": CONFIG}
    (RESULTS / f"study_probe_{variant}_s{seed}.json").write_text(json.dumps(report, indent=2))
    return report


# (shape scale, shape parameters that vary: a prefix of their names, "" for all of them)
FRAGILITY_FAMILIES = (
    (0.05, ""), (0.25, ""), (0.5, ""),
    (0.05, "global_"), (0.05, "global_z"), (0.02, "global_z"), (0.05, "hip_"), (0.05, "torso_"),
    (0.05, "thigh_"), (0.05, "shin_"), (0.05, "foot_"),
)  # fmt: skip


def fragility(variant: str, seed: int, episodes: int = 40) -> dict:
    """How far a run's controller (warm started as `train.init_from` does, which changes
    nothing for a controller trained on varying shapes) carries into its config's family:
    falls and return on random bodies of the shape ranges shrunk by s, with all shape
    parameters varying or only one group. Writes study_fragility_<variant>_s<seed>_<M>M.json
    (M: the checkpoint's env steps)."""
    warnings.filterwarnings("ignore")
    from normalization import shrunk_shape_ranges

    from paramimic.config import load_config
    from paramimic.envs import env_for

    config = variant_config(variant, seed)[0]
    state, env = _run_state(variant, seed)
    rows = []
    for scale, prefix in FRAGILITY_FAMILIES:
        ranges = shrunk_shape_ranges(Path(config).stem, scale)
        ranges = {k: r if k.startswith(f"task.{prefix}") else [1.0, 1.0] for k, r in ranges.items()}
        cfg = load_config(ROOT / config, {"env": env} | ranges)
        policy = _adopted(state, cfg)
        env_cfg = cfg.env.for_evaluation(10.0)
        space = env_for(cfg, env_cfg).task_space
        tasks = space.sample(np.random.default_rng(EVAL_SEED), episodes)
        summary = _on_bodies(policy, cfg, env_cfg, tasks)
        rows.append({"shape_scale": scale, "varying": prefix or "all"} | summary)
        print(f"shape scale {scale:g}, varying {prefix or 'all'}: falls "
              f"{summary['fall_percent']:.1f} %, return {summary['mean_return']:.0f}")  # fmt: skip
    return _controller_report("fragility", variant, seed, state, episodes, {"families": rows})


def _episodes_on(policy, cfg, env_cfg, tasks: np.ndarray) -> list:
    """The deterministic controller, one episode per task of `cfg`'s env, as `run`'s
    evaluation runs them (8 at a time, EVAL_SEED): EpisodeResults in the tasks' order."""
    from paramimic.envs import env_for
    from paramimic.evaluation import deterministic, run_episodes

    return run_episodes(
        deterministic(policy), lambda: env_for(cfg, env_cfg), tasks, 8,
        EVAL_SEED,
    )  # fmt: skip


def _on_bodies(policy, cfg, env_cfg, tasks: np.ndarray) -> dict:
    """`_episodes_on`, summarized (`summarize`'s dict)."""
    from paramimic.evaluation import summarize

    return summarize(_episodes_on(policy, cfg, env_cfg, tasks))


RIM_BINS = ((0, 2), (3, 4), (5, 6), (7, 99))  # parameters beyond the range's width


def rim(variant: str, seed: int) -> dict:
    """Where a grown family's controller falls: the held-out evaluation of `run` (the same 300
    bodies and seeds, so the same falls) split by how many shape parameters of a body lie
    beyond the width the run's range reached (curriculum.widen; one width for all 27 of the
    biped's, so nearly every held-out body has some). Writes
    study_rim_<variant>_s<seed>_<M>M.json."""
    warnings.filterwarnings("ignore")
    from paramimic.config import ExperimentConfig
    from paramimic.envs import env_for
    from paramimic.evaluation import summarize

    state, _ = _run_state(variant, seed)
    cfg = ExperimentConfig.model_validate(state["config"])
    width = float(state["curriculum"]["core"]["width"])
    env_cfg = cfg.env.for_evaluation(10.0)
    space = env_for(cfg, env_cfg).task_space
    tasks = space.sample(np.random.default_rng(EVAL_SEED), EVAL_EPISODES)
    results = _episodes_on(_adopted(state, cfg), cfg, env_cfg, tasks)
    free = space.free
    offset = np.abs(tasks - space.center)[:, free] / (0.5 * space.width[free])
    beyond = (offset > width).sum(axis=1)
    rets = np.array([r.ret for r in results])
    worst = np.argsort(rets)[: len(rets) // 10]
    groups = []
    for lo, hi in RIM_BINS:
        mask = (beyond >= lo) & (beyond <= hi)
        chosen = [r for r, m in zip(results, mask, strict=True) if m]
        row = {"beyond": [lo, hi], "bodies": int(mask.sum()),
               "worst_decile_share": float(np.mean(mask[worst]))}  # fmt: skip
        groups.append(row | (summarize(chosen) if chosen else {}))
        falls = f"{groups[-1]['fall_percent']:.1f} %" if chosen else "-"
        print(f"{lo}-{hi} of {free.sum()} parameters beyond the range's {100 * width:.0f} %: "
              f"{row['bodies']} bodies, falls {falls}, "
              f"{100 * row['worst_decile_share']:.0f} % of the worst decile")  # fmt: skip
    overall = summarize(results)
    print(f"all: falls {overall['fall_percent']:.1f} % (the run's report: the same bodies)")
    return _controller_report(
        "rim", variant, seed, state, EVAL_EPISODES,
        {"range_width": width, "all": overall, "groups": groups,
         "parameters_beyond": beyond.tolist(), "fell": [r.fell for r in results]},
    )  # fmt: skip


# the reports of a run's controller measured elsewhere (study_<kind>_...), which `merge` skips
CONTROLLER_KINDS = ("fragility", "rim", "sensitivity")


def _controller_report(
    kind: str, variant: str, seed: int, state: dict, episodes: int, rows: dict
) -> dict:
    """benchmarks/results/study_<kind>_<variant>_s<seed>_<M>M.json (M: the checkpoint's env
    steps) of a run's controller measured on other bodies, `episodes` per body or family."""
    assert kind in CONTROLLER_KINDS, kind
    steps = int(state["progress"]["env_steps"])
    report = {"variant": variant, "seed": seed, "config": variant_config(variant, seed)[0],
              "env_steps": steps, "episodes": episodes} | rows  # fmt: skip
    name = f"study_{kind}_{variant}_s{seed}_{round(steps / 1e6):g}M.json"
    (RESULTS / name).write_text(json.dumps(report, indent=2))
    return report


# one shape parameter moved at a time (the others at the base body's 1.0): which part of the
# body a controller's gait hinges on
SENSITIVITY_PARAMETERS = ("global_x", "global_z", "hip_z", "torso_z", "thigh_r_z", "shin_r_z",
                          "foot_r_z")  # fmt: skip
SENSITIVITY_VALUES = (0.98, 1.02)


def sensitivity(variant: str, seed: int, episodes: int = 10) -> dict:
    """A run's controller (as `fragility` adopts it) on bodies that differ from the base body
    in one shape parameter by 2 %: falls and forward speed per parameter and value, the base
    body first. Writes study_sensitivity_<variant>_s<seed>_<M>M.json."""
    warnings.filterwarnings("ignore")
    from normalization import shrunk_shape_ranges

    from paramimic.config import load_config
    from paramimic.envs import env_for
    from paramimic.rl.ppo import CONSTANT

    config = variant_config(variant, seed)[0]
    state, env = _run_state(variant, seed)
    # ranges wide enough to hold every value moved (x0.2: global 0.9-1.1, parts 0.94-1.04)
    cfg = load_config(ROOT / config, {"env": env} | shrunk_shape_ranges(Path(config).stem, 0.2))
    policy = _adopted(state, cfg)
    env_cfg = cfg.env.for_evaluation(10.0)
    probe_env = env_for(cfg, env_cfg)
    names = list(probe_env.task_space.names)
    # the inputs that varied least in the run's training (its normalizer's std; inputs that never
    # varied, such as the fixed shape parameters, aside), and how far each body moves them at
    # its first step, in those standard deviations (the same reset seed: the same phase)
    layout = probe_env.observation_layout()
    inputs = [f"{segment}[{i}]" for segment, size in layout for i in range(size)]
    std = np.sqrt(np.asarray(state["learner"]["normalizer"]["var"], dtype=float))
    least = [k for k in np.argsort(std) if std[k] ** 2 > CONSTANT][:5]
    first = {}
    cases = [("base", 1.0)] + [(p, v) for p in SENSITIVITY_PARAMETERS for v in SENSITIVITY_VALUES]
    rows = []
    for name, value in cases:
        task = np.array([1.0 if n != name else value for n in names])
        task[names.index("target_velocity")] = cfg.task["target_velocity"][0]
        first[name, value] = probe_env.reset(seed=EVAL_SEED, options={"task": task})[0][least]
        shift = (first[name, value] - first["base", 1.0]) / std[least]
        summary = _on_bodies(policy, cfg, env_cfg, np.repeat(task[None], episodes, axis=0))
        moved = {inputs[k]: float(x) for k, x in zip(least, shift, strict=True)}
        rows.append(
            {"parameter": name, "value": value} | summary | {"least_varied_shift_sigma": moved}
        )
        print(f"{name} {value:g}: falls {summary['fall_percent']:.0f} %, speed "
              f"{summary['mean_forward_speed']:.2f} m/s")  # fmt: skip
    extra = {"bodies": rows, "least_varied_inputs": {inputs[k]: float(std[k]) for k in least}}
    return _controller_report("sensitivity", variant, seed, state, episodes, extra)


def stopped(variant: str, seed: int) -> dict:
    """A run stopped before its budget and not evaluated (a screen that lost): its training
    curve as it stands, benchmarks/results/study_<variant>_s<seed>_stopped.json, for the
    record and the curves figure. (`run` continues it and writes the evaluated report.)"""
    run_dir = RUNS / f"{variant}_s{seed}"
    curve = [json.loads(line) for line in (run_dir / "metrics.jsonl").read_text().splitlines()]
    tail = curve[-10:]
    report = {
        "variant": variant,
        "overrides": VARIANTS[variant],
        "config": variant_config(variant, seed)[0],
        "seed": seed,
        "env_steps": curve[-1]["env_steps"],
        "evaluated": False,
        "last_10_iterations": {
            k: float(np.mean([m[k] for m in tail])) for k in ("mean_return", "fall_percent")
        },
        "curve": [{k: m[k] for k in CURVE_KEYS if k in m} for m in curve],
    }
    (RESULTS / f"study_{variant}_s{seed}_stopped.json").write_text(json.dumps(report, indent=2))
    return report


def _spread(values: list[float]) -> dict:
    a = np.array(values, dtype=float)
    return {"mean": float(a.mean()), "min": float(a.min()), "max": float(a.max()), "n": len(a)}


def merge() -> dict:
    groups: dict[tuple[str, float], list[dict]] = {}
    for path in sorted(RESULTS.glob("study_*_s*_*M.json")):
        if path.name.startswith(tuple(f"study_{k}_" for k in ("probe", *CONTROLLER_KINDS))):
            continue  # evaluations of a run's controller elsewhere, not runs
        r = json.loads(path.read_text())
        millions = float(path.stem.rsplit("_", 1)[1].removesuffix("M"))  # the run's budget
        groups.setdefault((r["variant"], millions), []).append(r)
    table = {}
    for (variant, millions), runs in sorted(groups.items()):
        table[f"{variant}@{millions:g}M"] = {
            "seeds": [r["seed"] for r in runs],
            "config": runs[0]["config"],
            "overrides": VARIANTS.get(variant, runs[0]["overrides"]),
            "fall_percent": _spread([r["fall_percent"] for r in runs]),
            "mean_return": _spread([r["mean_return"] for r in runs]),
            "worst_decile_return": _spread([r["worst_decile_return"] for r in runs]),
            "worst_decile_over_mean": _spread(
                [r["worst_decile_return"] / max(r["mean_return"], 1e-9) for r in runs]
            ),
            "forward_speed": _spread([r["mean_forward_speed"] for r in runs]),
            "final_std": _spread([r["final_std"] for r in runs]),
            "grid_fall_percent": _spread(
                [100 * float(np.mean(r["grid"]["fall"])) for r in runs if "grid" in r]
            ),
        }
    (RESULTS / "study.json").write_text(json.dumps(table, indent=2))
    curves = dict(groups)  # the figures also draw the stopped screens' curves
    for path in sorted(RESULTS.glob("study_*_s*_stopped.json")):
        r = json.loads(path.read_text())
        if not any(v == r["variant"] for v, _ in groups):
            curves.setdefault((r["variant"], 0), []).append(r)
    _plot(curves)
    for name, row in table.items():
        f, w = row["fall_percent"], row["worst_decile_return"]
        print(
            f"{name:34s} seeds {row['seeds']}  falls {f['mean']:5.1f} % [{f['min']:.1f}-"
            f"{f['max']:.1f}]  return {row['mean_return']['mean']:6.1f}  worst decile "
            f"{w['mean']:5.1f}  speed {row['forward_speed']['mean']:.2f}  "
            f"std {row['final_std']['mean']:.2f}"
        )
    return table


# the training curves the study draws, per figure: its main steps on walker_legs, and the 3D rows
STD_PANEL = ("std", "policy std")
WIDTH_PANEL = ("range_width", "share of the shape ranges in use (curriculum.widen)")
CURVES = {
    "study_curves.png": (
        "walker_legs (each leg 0.7-1.3x): training curves per variant and seed",
        (
            "learned_std",
            "std_frozen",
            "std_frozen_gamma99",
            "std_frozen_gamma99_stall_widen",
            "retarget",
            "retarget_stall",
            "retarget_stall_k0",
        ),
        STD_PANEL,
    ),
    "study_curves_3d.png": (
        "biped_lower (base body, x0.5 ranges) and quadruped (x0.5): training curves per seed",
        (
            "biped_base_heading0.8",
            "biped_base_heading0.8_std0.1",
            "biped_x0.5_std0.1",
            "quadruped_x0.5",
            "quadruped_x0.5_std0.1_heading",
            "quadruped_x0.5_std0.1_heading_stall",
        ),
        STD_PANEL,
    ),
    "study_curves_biped_x0.5.png": (
        "biped_lower at x0.5 ranges: the recipe and its screens, training curves per seed",
        (
            "biped_x0.5_std0.1",
            "biped_x0.5_std0.1_global",
            "biped_x0.5_std0.1_retarget",
            "biped_x0.5_std0.1_lr5e-5",
            "biped_x0.5_std0.05",
            "biped_x0.5_std0.1_blind",
            "biped_x0.5_std0.1_nofit",
            "biped_x0.5_std0.1_warm_widen",
            "biped_x0.5_std0.1_warm_widen0.7",
            "biped_x0.5_std0.1_floor",
            "biped_x0.5_std0.1_floor_warm",
            "biped_x0.5_std0.1_floor_warm_kl",
            "biped_x0.5_std0.1_floor_warm_widen_kl",
            "biped_x0.5_std0.1_floor_warm_widen0.6_kl",
            "biped_x0.5_std0.1_floor_warm_edge_kl",
        ),
        WIDTH_PANEL,
    ),
    "study_curves_quadruped.png": (
        "quadruped: the x0.5 family from scratch, the base body and the family from its "
        "controller, training curves per seed",
        (
            "quadruped_x0.5",
            "quadruped_x0.5_retarget",
            "quadruped_x0.5_retarget_stall",
            "quadruped_base_stall",
            "quadruped_x0.5_warm_stall",
            "quadruped_x0.5_warm_stall_lr5e-5",
            "quadruped_x0.5_warm_stall_kl",
        ),
        ("mean_length", "training episode length (control steps, 30 per s)"),
    ),
}


def _plot(groups: dict) -> None:
    for name, (title, variants, panel) in CURVES.items():
        _plot_curves(groups, variants, title, panel, RESULTS / name)


def _plot_curves(
    groups: dict, variants: tuple[str, ...], title: str, panel: tuple[str, str], path: Path
) -> None:
    """Training falls, return and `panel` (a curve key, its title) per variant and seed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(15, 4.6))
    colors = plt.get_cmap("tab20").colors  # up to 20 variants a figure, each its own colour
    variants = [v for v in variants if any(v == g for g, _ in groups)]
    for i, variant in enumerate(variants):
        # per seed its longest run (a longer run's curve holds the shorter's)
        longest = {}
        for _, g in sorted((m, g) for (v, m), g in groups.items() if v == variant):
            longest |= {r["seed"]: r for r in g}
        runs = [longest[seed] for seed in sorted(longest)]
        for j, r in enumerate(runs):
            x = [m["env_steps"] / 1e6 for m in r["curve"]]
            for ax, key in zip(axes, ("fall_percent", "mean_return", panel[0]), strict=True):
                y = np.array([m.get(key, np.nan) for m in r["curve"]], dtype=float)
                if key != panel[0] and len(y) >= 10:  # noisy episodes: a moving average of 10
                    y = np.convolve(y, np.ones(10) / 10, mode="valid")
                ax.plot(x[len(x) - len(y) :], y, color=colors[i % len(colors)], alpha=0.8,
                        label=variant if j == 0 else None)  # fmt: skip
    for ax, label in zip(axes, ("training falls (%)", "training return", panel[1]), strict=True):
        ax.set_title(label)
        ax.set_xlabel("env steps (M)")
    # below the panels, where it hides no curve: one entry per variant
    handles, labels = axes[0].get_legend_handles_labels()
    columns = min(len(labels), 5) or 1
    fig.legend(handles, labels, loc="lower center", ncol=columns, fontsize=7, frameon=False)
    fig.suptitle(title)
    fig.tight_layout(rect=(0, 0.04 + 0.05 * -(-len(labels) // columns), 1, 1))
    fig.savefig(path, dpi=90)
    plt.close(fig)


def headings(variant: str, seed: int, episodes: int = 20) -> dict:
    """A study run's controller (latest checkpoint) on its own config's env, whole episodes
    from random initial states: per episode whether and when it fell and the largest angle
    between its facing direction and the target direction. Writes
    study_headings_<variant>_s<seed>.json."""
    warnings.filterwarnings("ignore")
    from paramimic.config import ExperimentConfig
    from paramimic.envs import env_for
    from paramimic.evaluation import deterministic
    from paramimic.rl.networks import ActorCritic
    from paramimic.training import checkpoint

    state = checkpoint.load(RUNS / f"{variant}_s{seed}")
    cfg = ExperimentConfig.model_validate(state["config"])
    policy = ActorCritic(state["obs_dim"], state["act_dim"], cfg.ppo.hidden_sizes, 0.0)
    policy.load_state_dict(state["learner"]["policy"])
    act = deterministic(policy)
    env = env_for(cfg, cfg.env.for_evaluation(10.0))
    rows = []
    for i in range(episodes):
        obs, _ = env.reset(seed=EVAL_SEED + i)
        worst = 0.0
        while True:
            obs, _, terminated, truncated, info = env.step(act(obs[None])[0])
            worst = max(worst, env.unwrapped.heading_error() or 0.0)
            if terminated or truncated:
                break
        rows.append(
            {"fell": bool(info["fell"]), "seconds": env.sim_time, "max_heading_error": worst}
        )
    fallen = [r for r in rows if r["fell"]]
    report = {
        "variant": variant,
        "seed": seed,
        "episodes": rows,
        "max_heading_error_fallen": [r["max_heading_error"] for r in fallen],
        "max_heading_error_standing": [r["max_heading_error"] for r in rows if not r["fell"]],
    }
    (RESULTS / f"study_headings_{variant}_s{seed}.json").write_text(json.dumps(report, indent=2))
    return report


def fit_offsets(resets: int = 10) -> dict:
    """How far [WL19] Eq. 1's ground fit moves a biped_lower body's initial posture off its
    reference pose (init_noise 0): per shape scale, the largest joint offset (rad) of each
    reset. Writes study_fit_offsets.json."""
    warnings.filterwarnings("ignore")
    from normalization import shrunk_shape_ranges

    from paramimic.config import load_config
    from paramimic.envs import env_for

    rows = []
    for scale in (0.0, 0.05, 0.5):
        overrides = shrunk_shape_ranges("biped_lower", scale) | {"env.init_noise": 0.0}
        cfg = load_config(ROOT / "configs/biped_lower.yaml", overrides)
        env = env_for(cfg).unwrapped
        offsets = []
        for i in range(resets):
            env.reset(seed=i)
            c = env.character
            reference = np.clip(env.motion.pose(env._phase), c.ctrl_low, c.ctrl_high)
            offsets.append(float(np.abs(reference - env.data.qpos[c.qpos_idx]).max()))
        rows.append({"shape_scale": scale, "max_joint_offset_rad": offsets})
        print(f"shape scale {scale:g}: largest joint offset from the reference "
              f"{max(offsets):.3f} rad (mean over resets {np.mean(offsets):.3f})")  # fmt: skip
    report = {"config": "configs/biped_lower.yaml", "resets": resets, "scales": rows}
    (RESULTS / "study_fit_offsets.json").write_text(json.dumps(report, indent=2))
    return report


REFERENCE_BODIES = ((1.0, 1.0), (0.8, 0.8), (1.2, 1.2), (0.8, 1.2), (1.2, 0.8), (0.7, 1.3))


def reference(resets: int = 10, steps: int = 10) -> dict:
    """How well each body can follow its reference at all: the servos' PD targets on the
    reference pose (zero action) for `steps` control steps from `resets` resets, the mean [WL19]
    pose bell (Eq. 5), with and without env.retarget. Writes study_reference_pose.json."""
    from paramimic.config import load_config
    from paramimic.envs import env_for

    rows = []
    for left, right in REFERENCE_BODIES:
        row = {"left_leg_length": left, "right_leg_length": right}
        for retarget in (False, True):
            cfg = load_config(ROOT / CONFIG, {"env.retarget": retarget})
            env = env_for(cfg)
            task = {"left_leg_length": left, "right_leg_length": right, "target_velocity": 1.0}
            bells = []
            for seed in range(resets):
                env.reset(seed=seed, options={"task": task})
                for _ in range(steps):
                    bells.append(env.step(np.zeros(env.action_space.shape))[4]["reward_terms"])
            key = "retargeted" if retarget else "reference"
            row[f"pose_bell_{key}"] = float(np.mean([b["pose"] for b in bells]))
        rows.append(row)
    report = {"resets": resets, "steps": steps, "config": CONFIG, "bodies": rows}
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "study_reference_pose.json").write_text(json.dumps(report, indent=2))
    return report


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument(
        "command",
        choices=[
            "run",
            "queue",
            "merge",
            "probe",
            "fragility",
            "sensitivity",
            "fit-offsets",
            "reference",
            "headings",
            "stopped",
            "rim",
        ],  # fmt: skip
    )
    ap.add_argument("variants", nargs="?", default="std_frozen_gamma99", help="comma-separated")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--seeds", default="0", help="comma-separated, for `queue`")
    ap.add_argument("--steps", type=int, default=2_000_000)
    ap.add_argument("--parallel", type=int, default=2)
    args = ap.parse_args()
    for v in args.variants.split(","):
        if v not in VARIANTS:
            raise SystemExit(f"unknown variant {v!r}; variants: {sorted(VARIANTS)}")
    if args.command == "merge":
        merge()
    elif args.command == "headings":
        r = headings(args.variants, args.seed)
        for row in r["episodes"]:
            print(f"{'fell' if row['fell'] else 'up  '} at {row['seconds']:5.2f} s, largest "
                  f"heading error {row['max_heading_error']:.2f} rad")  # fmt: skip
    elif args.command == "reference":
        for row in reference()["bodies"]:
            print(f"legs {row['left_leg_length']}/{row['right_leg_length']}: pose bell "
                  f"{row['pose_bell_reference']:.3f} on the reference, "
                  f"{row['pose_bell_retargeted']:.3f} retargeted")  # fmt: skip
    elif args.command == "probe":
        r = probe(args.variants, args.seed)
        print(f"{args.variants} s{args.seed} on {CONFIG}: falls {r['fall_percent']:.1f} %")
        for y, row in zip(r["grid"]["y"], r["grid"]["returns"], strict=True):
            print(f"{y:4.2f}", " ".join(f"{v:5.0f}" for v in row))
    elif args.command == "fit-offsets":
        fit_offsets()
    elif args.command == "fragility":
        fragility(args.variants, args.seed)
    elif args.command == "sensitivity":
        sensitivity(args.variants, args.seed)
    elif args.command == "rim":
        rim(args.variants, args.seed)
    elif args.command == "stopped":
        r = stopped(args.variants, args.seed)
        last = r["last_10_iterations"]
        print(f"{args.variants} s{args.seed} stopped at {r['env_steps']:,} steps: training "
              f"return {last['mean_return']:.1f}, falls {last['fall_percent']:.0f} % (last 10 "
              "iterations)")  # fmt: skip
    elif args.command == "run":
        r = run(args.variants, args.seed, args.steps)
        print(f"{args.variants} s{args.seed}: falls {r['fall_percent']:.1f} %")
    else:  # every (variant, seed) without a report at this budget, `parallel` at a time
        jobs = [
            (v, int(s))
            for s in args.seeds.split(",")
            for v in args.variants.split(",")
            if not _report_path(v, int(s), args.steps).exists()
        ]

        def sub(job: tuple[str, int]) -> int:
            v, s = job
            cmd = [sys.executable, __file__, "run", v, "--seed", str(s), "--steps", str(args.steps)]
            return subprocess.call(cmd)

        with ThreadPoolExecutor(args.parallel) as pool:
            codes = list(pool.map(sub, jobs))
        merge()
        if any(codes):
            raise SystemExit(f"{sum(1 for c in codes if c)} runs failed")


if __name__ == "__main__":
    main()
