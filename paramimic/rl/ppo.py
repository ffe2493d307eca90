"""The clipped PPO objective and the learner that optimizes it ([WL19] §3.2, [L21] §4.3)."""

from __future__ import annotations

import contextlib
import functools
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from paramimic.config import PPOConfig
from paramimic.rl.gae import compute_gae
from paramimic.rl.networks import ActorCritic, RunningMeanStd
from paramimic.rl.rollout import Fragment


def ppo_loss(
    new_logp: torch.Tensor,
    old_logp: torch.Tensor,
    advantages: torch.Tensor,
    values: torch.Tensor,
    returns: torch.Tensor,
    entropy: torch.Tensor,
    clip_coef: float,
    vf_coef: float,
    ent_coef: float,
) -> tuple[torch.Tensor, dict[str, float]]:
    """Clipped surrogate + value regression − entropy bonus, all over a minibatch [N].

    L = −mean(min(ρA, clip(ρ, 1−ε, 1+ε)A)) + c_v · ½ mean((V − R)²) − c_e · H,  ρ = π/π_old.
    `old_logp` is the log-prob under the policy that collected the data, so the same ratio
    also corrects data sampled one policy version behind.
    """
    ratio = torch.exp(new_logp - old_logp)
    surrogate = torch.minimum(
        ratio * advantages, torch.clamp(ratio, 1 - clip_coef, 1 + clip_coef) * advantages
    )
    policy_loss = -surrogate.mean()
    value_loss = 0.5 * (values - returns).pow(2).mean()
    loss = policy_loss + vf_coef * value_loss - ent_coef * entropy
    with torch.no_grad():
        log_ratio = new_logp - old_logp
        stats = {
            "policy_loss": float(policy_loss),
            "value_loss": float(value_loss),
            "entropy": float(entropy),
            "approx_kl": float(((ratio - 1) - log_ratio).mean()),
            "clip_fraction": float(((ratio - 1).abs() > clip_coef).float().mean()),
        }
    return loss, stats


@dataclass
class Batch:
    """Flattened training data of one iteration: N transitions."""

    obs: np.ndarray  # [N, obs_dim] raw observations
    actions: np.ndarray  # [N, A]
    logp: np.ndarray  # [N]
    values: np.ndarray  # [N]
    advantages: np.ndarray  # [N]
    returns: np.ndarray  # [N]
    tasks: np.ndarray  # [N, d] task parameters of each transition (for V̄)


LR_MIN, LR_MAX = 1e-5, 1e-2  # bounds of the adaptive policy learning rate
BF16_FLAGS = ("amx_bf16", "avx512_bf16")  # CPU flags of native bfloat16 matrix products


@functools.cache
def native_bf16() -> bool:
    """Whether this CPU multiplies bfloat16 matrices natively (Linux's /proc/cpuinfo flags)."""
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        return False
    flags = next((line.split(":", 1)[1].split() for line in text.splitlines()
                  if line.startswith("flags")), [])  # fmt: skip
    return any(f in flags for f in BF16_FLAGS) and torch.ops.mkldnn._is_mkldnn_bf16_supported()


def update_dtype(precision: str) -> torch.dtype:
    """The dtype of the update's matrix products for `PPOConfig.update_precision`."""
    if precision == "auto":
        precision = "bfloat16" if native_bf16() else "float32"
    return torch.bfloat16 if precision == "bfloat16" else torch.float32


class PPOLearner:
    """Networks, optimizers and the observation normalizer; `update` runs one PPO step."""

    def __init__(self, obs_dim: int, act_dim: int, cfg: PPOConfig, seed: int = 0) -> None:
        self.cfg = cfg
        torch.manual_seed(seed)
        self.policy = ActorCritic(
            obs_dim,
            act_dim,
            cfg.hidden_sizes,
            cfg.init_log_std,
            cfg.obs_clip,
            cfg.obs_std_floor,
            cfg.value_hidden_sizes,
        )
        self.policy.log_std.requires_grad_(cfg.learn_std)
        trained = [p for p in self.policy.policy_parameters() if p.requires_grad]
        self.policy_opt = torch.optim.Adam(trained, lr=cfg.policy_lr)
        self.value_opt = torch.optim.Adam(self.policy.value_parameters(), lr=cfg.value_lr)
        self.normalizer = RunningMeanStd(obs_dim)
        self.rng = np.random.default_rng(seed)
        self.version = 0  # policy version, +1 per update
        self.dtype = update_dtype(cfg.update_precision)

    def _precision(self) -> contextlib.AbstractContextManager:
        """bfloat16 matrix products under autocast, or nothing to change."""
        if self.dtype == torch.float32:
            return contextlib.nullcontext()
        return torch.autocast("cpu", dtype=self.dtype)

    def weights(self) -> dict[str, np.ndarray]:
        """Everything an actor needs to act, as numpy (actors do not load torch): network
        weights, log σ, the normalizer and its clip."""
        return self.policy.numpy_weights()

    def build_batch(self, fragments: list[Fragment]) -> Batch:
        """Variable time-step GAE per fragment ([L21] Eq. 9), then flatten."""
        parts = []
        for f in fragments:
            adv, ret = compute_gae(
                f.rewards,
                f.spike_rewards,
                f.values,
                f.next_values,
                f.terminated,
                f.truncated,
                f.dphi,
                self.cfg.gamma,
                self.cfg.gae_lambda,
            )
            parts.append(
                (
                    f.obs.reshape(-1, f.obs.shape[-1]),
                    f.actions.reshape(-1, f.actions.shape[-1]),
                    f.logp.ravel(),
                    f.values.ravel(),
                    adv.ravel(),
                    ret.ravel(),
                    f.tasks[f.task_index].reshape(f.task_index.size, f.tasks.shape[-1]),
                )
            )
        cols = [np.concatenate(c) for c in zip(*parts, strict=True)]
        return Batch(*cols)

    def update(self, batch: Batch) -> dict[str, float]:
        """E epochs of minibatch PPO on the batch; then fold its observations into the normalizer.

        The normalizer changes only after the update so that the ratio π/π_old starts at 1.
        """
        cfg = self.cfg
        obs = torch.as_tensor(batch.obs, dtype=torch.float32)
        actions = torch.as_tensor(batch.actions, dtype=torch.float32)
        old_logp = torch.as_tensor(batch.logp, dtype=torch.float32)
        returns = torch.as_tensor(batch.returns, dtype=torch.float32)
        adv = torch.as_tensor(batch.advantages, dtype=torch.float32)
        n = len(obs)
        mb = min(cfg.minibatch_size, n)
        sums: dict[str, float] = {}
        steps = skipped = 0
        for _ in range(cfg.num_epochs):
            order = self.rng.permutation(n)
            for start in range(0, n - mb + 1, mb):
                idx = torch.from_numpy(order[start : start + mb])
                a = adv[idx]
                a = (a - a.mean()) / (a.std() + 1e-8)  # advantage normalization per minibatch
                with self._precision():
                    mean, value = self.policy(obs[idx])
                mean, value = mean.float(), value.float()  # log-probs and losses in float32
                new_logp = self.policy.log_prob(mean, actions[idx])
                loss, stats = ppo_loss(
                    new_logp,
                    old_logp[idx],
                    a,
                    value,
                    returns[idx],
                    self.policy.entropy(),
                    cfg.clip_coef,
                    cfg.vf_coef,
                    cfg.ent_coef,
                )
                if cfg.desired_kl is not None:
                    self._adapt_lr(stats["approx_kl"], cfg.desired_kl)
                self.policy_opt.zero_grad()
                self.value_opt.zero_grad()
                loss.backward()
                gp = torch.nn.utils.clip_grad_norm_(
                    self.policy.policy_parameters(), cfg.max_grad_norm
                )
                gv = torch.nn.utils.clip_grad_norm_(
                    self.policy.value_parameters(), cfg.max_grad_norm
                )
                if not (torch.isfinite(loss) and torch.isfinite(gp) and torch.isfinite(gv)):
                    skipped += 1  # a NaN/inf step never reaches the weights
                    continue
                self.policy_opt.step()
                self.value_opt.step()
                for k, v in stats.items():
                    sums[k] = sums.get(k, 0.0) + v
                steps += 1
        if np.isfinite(batch.obs).all():
            self.normalizer.update(batch.obs)
            self.policy.set_normalizer(self.normalizer)
        self.version += 1
        metrics = {k: v / max(steps, 1) for k, v in sums.items()}
        metrics["skipped_steps"] = skipped  # minibatch steps with a non-finite loss or gradient
        metrics["update_steps"] = steps
        var_y = float(np.var(batch.returns))
        metrics["explained_variance"] = (
            float(1 - np.var(batch.returns - batch.values) / var_y) if var_y > 0 else 0.0
        )
        metrics["std"] = float(self.policy.log_std.detach().exp().mean())
        metrics["policy_lr"] = float(self.policy_opt.param_groups[0]["lr"])
        return metrics

    def _adapt_lr(self, kl: float, desired: float) -> None:
        """The adaptive step size of rsl_rl / legged_gym PPO: a minibatch whose policy already
        moved more than 2x `desired` (approx. KL to the sampling policy) shrinks the learning
        rate by 1.5, one below half of it grows it by 1.5. It lives in the optimizer's state,
        so a checkpoint keeps it."""
        for group in self.policy_opt.param_groups:
            if kl > 2.0 * desired:
                group["lr"] = max(LR_MIN, group["lr"] / 1.5)
            elif kl < 0.5 * desired:
                group["lr"] = min(LR_MAX, group["lr"] * 1.5)

    def state_dict(self) -> dict:
        return {
            "policy": self.policy.state_dict(),
            "policy_opt": self.policy_opt.state_dict(),
            "value_opt": self.value_opt.state_dict(),
            "normalizer": self.normalizer.state_dict(),
            "rng": self.rng.bit_generator.state,
            "version": self.version,
        }

    def load_state_dict(self, state: dict) -> None:
        self.policy.load_state_dict(state["policy"])
        self.policy_opt.load_state_dict(state["policy_opt"])
        self.value_opt.load_state_dict(state["value_opt"])
        self.normalizer.load_state_dict(state["normalizer"])
        self.rng.bit_generator.state = state["rng"]
        self.version = int(state["version"])


CONSTANT = 1e-10  # an observation variance this small: the input never changed


def adopt_controller(
    learner: PPOLearner,
    source: dict,
    observations: np.ndarray,
    inserted: np.ndarray | None = None,
    source_observations: np.ndarray | None = None,
) -> np.ndarray:
    """Warm start from `source`, a `PPOLearner.state_dict()` (or a shipped controller's, with
    the policy only) of the same observation layout but for the inputs `inserted` (indices in
    this learner's observation that the source has not: task dims it did not observe): its π,
    V and normalizer. Inputs that were constant in the source's experience (normalizer variance
    ≈ 0; for a controller without its normalizer's statistics, constant over
    `source_observations`, resets of the source's own config: task dims it trained with fixed,
    and what follows from them, such as a body's own target speed)
    but vary in `observations` (resets of the new task space), and the inserted ones, start
    ignored: their first-layer weights in π and V are zero, so every new task first gets the
    source's actions and values, and their normalizer statistics become those of
    `observations`, so they enter as well-scaled inputs instead of a constant's z-scores
    clipped at ±obs_clip. Returns those input indices."""
    obs_dim = observations.shape[1]
    inserted = np.asarray([] if inserted is None else inserted, dtype=int)
    kept = np.setdiff1d(np.arange(obs_dim), inserted)
    policy = {k: v.clone() for k, v in source["policy"].items()}
    if len(inserted):  # widen the first layers and the normalization buffers
        for key in ("pi.0.weight", "v.0.weight"):
            w = policy[key]
            policy[key] = w.new_zeros((w.shape[0], obs_dim))
            policy[key][:, torch.from_numpy(kept)] = w
        for key, fill in (("obs_mean", 0.0), ("obs_std", 1.0)):
            old = policy[key]
            policy[key] = old.new_full((obs_dim,), fill)
            policy[key][torch.from_numpy(kept)] = old
    learner.policy.load_state_dict(policy)
    stats = source.get("normalizer")
    mean, var = np.zeros(obs_dim), np.zeros(obs_dim)
    if stats is not None:
        mean[kept], var[kept] = stats["mean"], stats["var"]
        learner.normalizer.count = float(stats["count"])
        constant = var < CONSTANT
    else:  # a controller: the policy's normalization; constant where its resets are
        if source_observations is None:
            raise ValueError("a source without normalizer statistics needs source_observations")
        mean[kept] = policy["obs_mean"].double().numpy()[kept]
        var[kept] = policy["obs_std"].double().numpy()[kept] ** 2
        learner.normalizer.count = float(len(observations))
        constant = np.zeros(obs_dim, dtype=bool)
        constant[kept] = source_observations.var(axis=0) < CONSTANT
    sample_var = observations.var(axis=0)
    constant[inserted] = True
    new = np.isin(np.arange(obs_dim), inserted)
    dims = np.flatnonzero(constant & ((sample_var > CONSTANT) | new))
    learner.normalizer.mean, learner.normalizer.var = mean, var
    with torch.no_grad():
        for net in (learner.policy.pi, learner.policy.v):
            net[0].weight[:, torch.from_numpy(dims)] = 0.0
    learner.normalizer.mean[dims] = observations.mean(axis=0)[dims]
    learner.normalizer.var[dims] = sample_var[dims]
    learner.policy.set_normalizer(learner.normalizer)
    return dims
