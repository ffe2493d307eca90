"""benchmarks/curriculum.py ([L21] Fig. 8): a short run of two §7.3 curricula (those with a phase
clock) through its own code: a change of the library's types breaks a test, not a study."""

import pytest

from paramimic.training import checkpoint


# alternating at [L21] §7's settings (the paper arm of §7.3 in benchmarks/reproduce.py)
@pytest.mark.parametrize(("sampling", "recipe"), [("mastering", None), ("alternating", "l21")])
def test_a_short_run_records_er_against_episodes_and_its_elites(
    benchmark_module, tmp_path, sampling, recipe
):
    bench = benchmark_module("curriculum")
    run_dir = tmp_path / sampling
    out = bench.run("configs/walker_jump.yaml", sampling, 8192, 0, run_dir, recipe=recipe)
    assert out["sampling"] == sampling and out["steps"] == 8192 and out["recipe"] == recipe
    used = checkpoint.load(checkpoint.resolve(run_dir))["config"]
    assert (used["recipe"], used["env"]["physics_hz"] == 150) == (recipe, recipe == "l21")
    curve = out["curve"]
    iterations = [p["iteration"] for p in curve]
    assert len(curve) >= 2 and iterations == sorted(set(iterations))
    episodes = [p["episodes"] for p in curve]
    assert episodes == sorted(episodes) and episodes[-1] > 0
    assert all(0.0 <= p["explored_ratio"] <= 1.0 for p in curve)
    assert curve[-1]["env_steps"] >= 8192
    assert set(out["elites"]) == {"names", "params", "fitness", "ranges"}
    # ER at common episode counts, per curriculum, over the two kinds of run
    both = bench.compare([out, out | {"sampling": "uniform"}])
    assert set(both["explored_ratio"]) == {sampling, "uniform"}
