"""Recipes: named presets that set every field where a paper's settings and ours part ways.

A config names one with `recipe: NAME`; the preset's fields fill in what the config does not
set (a field set in the config wins over its preset), and what neither sets keeps the library
default. Each entry carries where its value comes from, so `paramimic config show` can print
every field with its source and `docs/reproduce.md` can list the departures.

- `wl19`: [WL19] §5 and Table 2 as the paper states them, with none of our training rules.
- `l21`: [L21] §7 as the paper states it (its value network's 2x512 is `ppo.value_hidden_sizes`,
  its one PD gain for every joint `env.pd_gain`), with none of our training rules.
- `paramimic_walker`: the recipe of our walker studies (configs/walker_legs.yaml; docs/
  families.md): a fixed policy std of 0.2, γ 0.99, retargeted legs, the stall rule, 10-s
  training episodes at 300 Hz.
- `paramimic_humanoid`: the humanoid's imitation recipe (docs/humanoid.md): 300 Hz, 512-256
  networks updated in bfloat16 where the CPU has it, batches of 8,192 in 5 epochs of 1,024, a
  fixed std of 0.2, [WL19] Table 2's policy step, pipelined actors.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Setting:
    value: Any
    source: str  # the paper's section or table, or our study


def _s(value: Any, source: str) -> Setting:
    return Setting(value, source)


LOG_02 = -1.6094379  # log 0.2, as the configs write it
WL19 = "[WL19] Table 2"
OURS_OFF = "[WL19] has no such rule"
L21 = "[L21] §7"
L21_OFF = "[L21] has no such rule"
WALKER = "ours: the walker study (docs/families.md)"
HUMANOID = "ours: the humanoid study (docs/humanoid.md)"

PRESETS: dict[str, dict[str, Setting]] = {
    "wl19": {
        "env.physics_hz": _s(600, WL19),
        "env.control_hz": _s(30, WL19),
        "env.max_episode_seconds": _s(30.0, WL19 + " (maximum time horizon)"),
        "env.reward.normalize": _s(True, "[WL19] §4.3, Table 1"),
        "env.ground_fit": _s(True, "[WL19] Eq. 1"),
        "env.reward.end_effector_frame": _s("root", "[WL19] §4.1 (the root joint's coordinates)"),
        "env.reward.facing": _s("target", "[WL19] Eq. 6 (d′, the target direction)"),
        "env.retarget": _s(False, OURS_OFF),
        "env.stall_speed_ratio": _s(None, OURS_OFF),
        "env.heading_error_limit": _s(None, OURS_OFF),
        "env.deviation_limit": _s(None, OURS_OFF),
        "env.phase_sampling": _s("uniform", OURS_OFF),
        "env.horizon_growth": _s(None, OURS_OFF),
        "env.pd_gain": _s(None, "[WL19] §3.1: each joint's own gains"),
        "env.stable_pd": _s(True, "[WL19] §3.1, Eq. 3"),
        "ppo.num_steps": _s(4096, WL19 + " (T)"),
        "ppo.minibatch_size": _s(128, WL19 + " (n)"),
        "ppo.num_epochs": _s(10, WL19 + " (N)"),
        "ppo.policy_lr": _s(5e-5, WL19 + " (α_π)"),
        "ppo.value_lr": _s(1e-4, WL19 + " (α_V)"),
        "ppo.gamma": _s(0.95, WL19 + " (γ)"),
        "ppo.gae_lambda": _s(0.95, WL19 + " (λ)"),
        "ppo.clip_coef": _s(0.2, WL19 + " (ε)"),
        "ppo.hidden_sizes": _s((128, 128, 128), "[WL19] §5"),
        "ppo.value_hidden_sizes": _s(None, "[WL19] §5 (the policy's layers)"),
        "ppo.learn_std": _s(True, "[WL19] §3.2 (a Gaussian policy, its std learned)"),
        "ppo.desired_kl": _s(None, OURS_OFF),
        "curriculum.k": _s(10.0, "[WL19] §4.2, Fig. 6"),
        "curriculum.k_ramp_iterations": _s(None, "[WL19] §4.2 (k fixed)"),
        "curriculum.n_mcmc": _s(1000, WL19 + " (N_MCMC)"),
        "curriculum.p_mcmc": _s(20, WL19 + " (P_MCMC)"),
        "curriculum.marginal_lr": _s(1e-3, WL19 + " (α_V̄)"),
        "curriculum.mu_lr": _s(1e-3, WL19 + " (α_μ)"),
        "curriculum.widen": _s(None, OURS_OFF),
    },
    "l21": {
        "env.physics_hz": _s(150, L21),
        "env.control_hz": _s(30, L21),
        "env.pd_gain": _s(600.0, L21 + " (k_p = 600, k_d = 49 for every joint)"),
        "env.stable_pd": _s(True, L21 + " (linear-time stable PD)"),
        "env.deviation_limit": _s(None, L21_OFF),
        "env.phase_sampling": _s("uniform", L21_OFF),
        "env.horizon_growth": _s(None, L21_OFF),
        "env.skill.rsi": _s(0.0, L21_OFF + " (every episode starts at the clip's start)"),
        "env.skill.hold_seconds": _s(0.0, L21_OFF),
        "env.skill.time_warp": _s(True, "[L21] §4.2 (A3)"),
        "ppo.minibatch_size": _s(1024, L21),
        "ppo.policy_lr": _s(2e-4, L21),
        "ppo.value_lr": _s(1e-3, L21),
        "ppo.gamma": _s(0.95, L21),
        "ppo.gae_lambda": _s(0.95, L21),
        "ppo.clip_coef": _s(0.2, L21),
        "ppo.hidden_sizes": _s((1024, 1024, 1024, 1024), L21 + " (the policy: 4 x 1024)"),
        "ppo.value_hidden_sizes": _s((512, 512), L21 + " (the value network: 2 x 512)"),
        "ppo.learn_std": _s(True, L21 + " (PPO's Gaussian policy)"),
        "ppo.desired_kl": _s(None, L21_OFF),
        "curriculum.marginal_batch": _s(128, L21),
        "curriculum.n_mcmc": _s(1000, L21),
        "curriculum.p_mcmc": _s(5, L21 + " (MCMC every five policy updates)"),
        "curriculum.k_ramp_iterations": _s(None, L21_OFF),
        "curriculum.widen": _s(None, L21_OFF),
        "curriculum.skill.sampling": _s("curriculum", "[L21] §6"),
        "curriculum.skill.motion_parameterization": _s(True, "[L21] §5.3 (A3)"),
        "curriculum.skill.constraint_tolerance": _s(
            None, "[L21] §5.2, Eq. 10 (a constraint only lowers F)"
        ),
        "curriculum.skill.p_hidden": _s((512, 512), L21),
        "curriculum.skill.p_lr": _s(1e-3, L21),
        "curriculum.skill.p_batch": _s(128, L21),
        "curriculum.skill.p_every": _s(10, L21),
        "curriculum.skill.p_steps": _s(10, L21),
    },
    "paramimic_walker": {
        "env.physics_hz": _s(300, "ours: benchmarks/physics_rate.py (docs/physics_rate.md)"),
        "env.max_episode_seconds": _s(10.0, WALKER),
        "env.retarget": _s(True, WALKER + " (42.7 % -> 3.9 % falls)"),
        "env.stall_speed_ratio": _s(0.5, WALKER),
        "ppo.num_steps": _s(4096, WALKER),
        "ppo.minibatch_size": _s(512, WALKER),
        "ppo.num_epochs": _s(10, WALKER),
        "ppo.learn_std": _s(False, WALKER),
        "ppo.init_log_std": _s(LOG_02, WALKER + " (std 0.2)"),
        "ppo.gamma": _s(0.99, WALKER),
        "actors.num_envs": _s(16, WALKER),
    },
    "paramimic_humanoid": {
        "env.physics_hz": _s(300, HUMANOID),
        "ppo.num_steps": _s(8192, HUMANOID),
        "ppo.minibatch_size": _s(1024, HUMANOID),
        "ppo.num_epochs": _s(5, HUMANOID),
        "ppo.hidden_sizes": _s((512, 256), HUMANOID),
        "ppo.update_precision": _s("auto", HUMANOID + " (the bfloat16 screens)"),
        "ppo.learn_std": _s(False, HUMANOID + " (DeepMimic freezes it too)"),
        "ppo.init_log_std": _s(LOG_02, HUMANOID + " (std 0.2: 0.1 rad of PD target)"),
        "ppo.gamma": _s(0.95, HUMANOID + " (DeepMimic's)"),
        "ppo.policy_lr": _s(5e-5, WL19 + " (α_π)"),
        "ppo.obs_std_floor": _s(0.02, HUMANOID),
        "curriculum.k": _s(0.0, HUMANOID + " (one body)"),
        "actors.num_envs": _s(16, HUMANOID),
        "actors.mode": _s("pipelined", HUMANOID),
    },
}


def preset(name: str) -> dict[str, Setting]:
    if name not in PRESETS:
        raise ValueError(f"recipe: unknown {name!r}; known: {sorted(PRESETS)}")
    return PRESETS[name]


def overrides(name: str) -> dict[str, Any]:
    """Every field of recipe `name` as a dotted override, with `recipe` itself: the recipe's
    setting then wins even where a config sets its own (a config's field otherwise wins), as
    a run "at the paper's settings" wants."""
    return {"recipe": name} | {
        k: list(s.value) if isinstance(s.value, tuple) else s.value for k, s in preset(name).items()
    }


def flatten(data: Mapping, prefix: str = "") -> dict[str, Any]:
    """{'a': {'b': 1}} -> {'a.b': 1}: every nested mapping walked, an empty one a leaf."""
    out: dict[str, Any] = {}
    for k, v in data.items():
        key = f"{prefix}{k}"
        if isinstance(v, Mapping) and v:
            out |= flatten(v, key + ".")
        else:
            out[key] = v
    return out


def _is_set(raw: Mapping, dotted: str) -> bool:
    node: Any = raw
    for part in dotted.split("."):
        if not isinstance(node, Mapping) or part not in node:
            return False
        node = node[part]
    return True


def apply(raw: Mapping) -> dict:
    """`raw` (a config as written) with its recipe's fields filled in beneath it."""
    name = raw.get("recipe")
    if name is None:
        return dict(raw)
    if not isinstance(name, str):
        raise ValueError(f"recipe: a name, one of {sorted(PRESETS)}")
    out = _copy(raw)
    for dotted, setting in preset(name).items():
        if _is_set(raw, dotted):
            continue
        *parents, leaf = dotted.split(".")
        node = out
        for part in parents:
            child = node.get(part)
            if child is None:
                child = node[part] = {}
            elif not isinstance(child, dict):
                break  # an already-built section: leave it as the config gave it
            node = child
        else:
            node[leaf] = setting.value
    return out


def _copy(d: Mapping) -> dict:
    return {k: _copy(v) if isinstance(v, Mapping) else v for k, v in d.items()}


def sources(raw: Mapping, fields: Mapping[str, Any], descriptions: Mapping[str, str]) -> dict:
    """Where each field of a validated config (`fields`, flattened) comes from: `config` when
    `raw` sets it (or gives its section whole, as a list or scalar), the recipe's source when
    its preset does, else `default` with the field's description (which cites the paper where
    the default is the paper's)."""
    name = raw.get("recipe")
    settings = preset(name) if isinstance(name, str) else {}
    out = {}
    for dotted in fields:
        if _is_set(raw, dotted) or _covered(raw, dotted):
            out[dotted] = "config"
        elif dotted in settings:
            out[dotted] = f"recipe {name}: {settings[dotted].source}"
        else:
            note = descriptions.get(dotted)
            out[dotted] = f"default: {note}" if note else "default"
    return out


def _covered(raw: Mapping, dotted: str) -> bool:
    """Whether the config gives a parent of the field as a value rather than a section."""
    node: Any = raw
    for part in dotted.split(".")[:-1]:
        if not isinstance(node, Mapping) or part not in node:
            return False
        node = node[part]
        if not isinstance(node, Mapping):
            return True
    return False
