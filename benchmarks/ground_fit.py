"""Cost and outcome of ground-contact fitting ([WL19] Eq. 1) at reset.

For each config, N resets with the fit on and off: milliseconds per reset, the share of fits that
fell back to the vertical lift, and the mean Eq. 1 objective of fit vs lift. Writes
benchmarks/results/ground_fit/ground_fit.json.

    python benchmarks/ground_fit.py [--resets 100]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

import paramimic.envs.core as env_core
from paramimic.characters.ground_fit import fit_ground_contact
from paramimic.config import load_config
from paramimic.envs import ParamEnv

ROOT = Path(__file__).resolve().parent.parent
CONFIGS = ("walker_legs", "biped_lower", "quadruped")


def measure(name: str, resets: int) -> dict:
    cfg = load_config(ROOT / "configs" / f"{name}.yaml")
    fits = []

    def recording(*args, **kwargs):
        fit = fit_ground_contact(*args, **kwargs)
        fits.append(fit)
        return fit

    env_core.fit_ground_contact = recording
    out = {}
    try:
        for on in (True, False):
            env = ParamEnv(cfg.character, cfg.task, cfg.env.model_copy(update={"ground_fit": on}))
            env.reset(seed=0)  # compile caches warm for the base body
            fits.clear()
            t0 = time.perf_counter()
            for seed in range(1, resets + 1):
                env.reset(seed=seed)
            out["ms_per_reset_fit" if on else "ms_per_reset_lift"] = (
                1000 * (time.perf_counter() - t0) / resets
            )
            if on:
                out["fits"] = len(fits)
                out["fallback_share"] = float(np.mean([f.method == "lift" for f in fits]))
    finally:
        env_core.fit_ground_contact = fit_ground_contact
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--resets", type=int, default=100)
    args = ap.parse_args()
    report = {name: measure(name, args.resets) for name in CONFIGS}
    path = ROOT / "benchmarks" / "results" / "ground_fit" / "ground_fit.json"
    path.write_text(json.dumps(report, indent=2))
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
