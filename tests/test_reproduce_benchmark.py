"""benchmarks/reproduce.py (paper against us, row by row): one short run of a [WL19] row at the
paper's settings and one of an [L21] row, each evaluated as the row measures it, and the table
written from their JSON, through the benchmark's own code (budgets and evaluation shrunk)."""

import json
import shutil

import pytest

from paramimic.training import checkpoint


def test_a_row_at_the_papers_settings_is_kept_and_tabled(benchmark_module, tmp_path, monkeypatch):
    bench = benchmark_module("reproduce")
    monkeypatch.setattr(bench, "OUT", tmp_path / "results")
    monkeypatch.setattr(bench, "RUNS", tmp_path / "runs")
    monkeypatch.setattr(bench, "EVAL", {"bodies": 3, "seconds": 1.0, "grid": 2})
    docs = tmp_path / "reproduce.md"
    shutil.copy(bench.DOCS, docs)
    monkeypatch.setattr(bench, "DOCS", docs)

    # [WL19] Table 4, RN off, at [WL19]'s settings: the variant's switch beside the recipe's
    # two iterations: the sampler draws by V̄ from the second on
    out = bench.run_one("wl19_table4", "paper", "quadruped_no_rn", 0, 8192, threads=1)
    assert out["overrides"]["recipe"] == "wl19"
    assert out["overrides"]["env.reward.normalize"] is False
    assert out["env_steps"] >= 8192
    report = out["report"]
    assert 0.0 <= report["fall_percent"] <= 100.0
    assert "coefficient_of_variation" in report["grid_uniformity"]
    run_dir = tmp_path / "runs" / "wl19_table4" / "paper" / "quadruped_no_rn_s0"
    used = checkpoint.load(checkpoint.resolve(run_dir))["config"]
    assert used["env"]["physics_hz"] == 600  # [WL19] Table 2, where quadruped.yaml says 300
    assert used["env"]["reward"]["normalize"] is False
    assert used["ppo"]["minibatch_size"] == 128
    kept = bench.result_path("wl19_table4", "paper", "quadruped_no_rn", 0, 8192)
    assert json.loads(kept.read_text())["report"] == report
    # how narrowly [WL19] Eq. 10 drew at the run's end (uniform while μ ≤ 0, as this early)
    sampling = report["sampling"]
    assert 0.0 < sampling["effective_share"] <= 1.0 and 0.0 <= sampling["low_mass"] <= 1.0
    assert report["range_width"] == 1.0  # the paper's ranges from the start: no `widen`
    # its training time is its log's, the gap between its two iterations
    trained = out["train_seconds"]
    assert trained == bench.trained_seconds(run_dir, out["env_steps"]) and trained > 0
    assert bench.trained_seconds(run_dir, out["env_steps"] + 1) is None  # never logged there
    with (run_dir / "metrics.jsonl").open("a") as log:  # a row torn by a kill, cut on resume
        log.write('{"iteration": 3, "env_st')
    assert bench.trained_seconds(run_dir, out["env_steps"]) == trained
    # a run kept without them gets them back from its run directory's checkpoint, and the time
    # of a run kept by an older version after a resume (its last session's) from its whole log
    bare = json.loads(kept.read_text()) | {"train_seconds": trained / 10}
    del bare["report"]["sampling"], bare["report"]["range_width"]
    kept.write_text(json.dumps(bare))
    assert bench.backfill() == [kept]
    assert json.loads(kept.read_text())["report"]["sampling"] == sampling
    assert json.loads(kept.read_text())["report"]["range_width"] == 1.0
    assert json.loads(kept.read_text())["train_seconds"] == trained
    assert bench.backfill() == []  # nothing left to add
    # where it falls: its bodies again from its checkpoint, the same falls as its report
    where = bench.rn_falls("paper")["quadruped_no_rn"]["seeds"]["0"]
    assert where["falls"] == where["kept_falls"] == report["fall_percent"]
    assert len(where["falls_by_third"]) == 3 and len(where["velocity_scale_edges"]) == 4
    assert json.loads((tmp_path / "results" / "rn_falls.json").read_text())["paper"]
    monkeypatch.setattr(bench, "_falls_by_scale", None)  # measured at these steps: kept
    assert bench.rn_falls("paper")["quadruped_no_rn"]["seeds"]["0"] == where

    # [L21] Table 2's A1 in our arm: the explored range of the elites
    a1 = bench.run_one("l21_table2", "ours", "A1", 0, 4096, threads=1)
    assert a1["overrides"] == {"curriculum.skill.motion_parameterization": False}
    assert 0.0 <= a1["report"]["explored_ratio"] <= 1.0
    assert set(a1["report"]["ranges"]) == {"gravity", "jump_height"}
    fit = a1["report"]["elite_mean_fitness"]  # [L21] Eq. 10 of the elites, π0's at least
    assert fit is not None and 0.0 < fit <= 1.0 + 0.1  # F plus w_constraint · r_constraint
    kept_a1 = bench.result_path("l21_table2", "ours", "A1", 0, 4096)
    bare = json.loads(kept_a1.read_text())
    del bare["report"]["elite_mean_fitness"]
    kept_a1.write_text(json.dumps(bare))
    assert bench.backfill() == [kept_a1]
    assert json.loads(kept_a1.read_text())["report"]["elite_mean_fitness"] == fit

    body = bench.table()
    line = next(x for x in body.splitlines() if "quadruped_no_rn" in x)
    cells = [c.strip() for c in line.strip("|").split("|")]
    assert cells[3].startswith(f"{report['task_achievement']:.1f} task")  # the paper's settings
    assert cells[4] == "not run yet"  # ours: not run
    assert "gravity" in next(x for x in body.splitlines() if "| A1 " in x)
    written = docs.read_text()
    assert body in written and "<!-- /rows -->" in written
    summary = json.loads((tmp_path / "results" / "reproduce.json").read_text())
    assert (
        summary["header"][3] == "paper's settings"
        and len(summary["rows"]) == len(body.splitlines()) - 2
    )
    kept_falls = summary["variants"]["wl19_table4"]["paper"]["quadruped_no_rn"]
    assert kept_falls["seeds"] == [0]
    assert kept_falls["mean"]["falls"] == report["fall_percent"]
    assert summary["variants"]["l21_table2"]["ours"]["A1"]["per_seed"]["explored_ratio"] == [
        a1["report"]["explored_ratio"]
    ]
    assert "ours" not in summary["variants"]["wl19_table4"]  # no run of ours: no summary


def test_what_a_run_costs_in_each_arm_is_timed_and_in_the_budget_column(
    benchmark_module, tmp_path, monkeypatch
):
    bench = benchmark_module("reproduce")
    monkeypatch.setattr(bench, "OUT", tmp_path / "results")
    docs = tmp_path / "reproduce.md"
    shutil.copy(bench.DOCS, docs)
    monkeypatch.setattr(bench, "DOCS", docs)

    out = bench.cost(["wl19_fig6"], iterations=1)["wl19_fig6"]
    paper, ours = out["paper"], out["ours"]
    # the paper arm ran [WL19] Table 2's settings, ours walker_legs.yaml's
    assert (paper["physics_hz"], paper["minibatch_size"]) == (600, 128)
    assert (ours["physics_hz"], ours["minibatch_size"]) == (300, 512)
    for arm in (paper, ours):
        assert arm["env_steps"] >= 4096 and arm["seconds"] > 0
        assert arm["hours_per_run"] == arm["seconds_per_1k_steps"] * 2_000_000 / 1000 / 3600
    assert json.loads((tmp_path / "results" / "cost.json").read_text())["wl19_fig6"] == out

    line = next(x for x in bench.table().splitlines() if "| k10 " in x)
    budget = line.strip("|").split("|")[-1].strip()
    assert budget == (
        f"2M per run: {paper['hours_per_run']:.1f} / {ours['hours_per_run']:.1f} h (paper's / ours)"
    )
    table4 = next(x for x in bench.table().splitlines() if "biped_lower_rn" in x)
    # not timed: no hours; our arm's budget with its base stage
    assert table4.strip("|").split("|")[-1].strip() == "paper's 2M, ours 2M base + 8M per run"
    assert bench.total_hours(json.loads((tmp_path / "results" / "cost.json").read_text())) is None


def test_the_whole_table_is_costed_with_base_stages_once_per_seed_and_the_curricula(
    benchmark_module,
):
    bench = benchmark_module("reproduce")
    rate = {"seconds_per_1k_steps": 1.0}  # one second per 1,000 env steps in every row and arm
    costs = {row: {"paper": rate, "ours": rate} for row in bench.ROWS}
    # the paper's arm: Table 4 4 x 2M, Fig. 6 4 x 2M, Table 2 3 x 2M, §7.3 5 x 1.5M = 29.5M;
    # ours: Table 4 2 x 8M (biped) + 2 x 2M (quadruped) + two base stages of 2M, Fig. 6 8M,
    # Table 2 6M, §7.3 7.5M = 45.5M; each on three seeds
    assert bench.total_hours(costs) == pytest.approx(
        {"paper": 3 * 29_500 / 3600, "ours": 3 * 45_500 / 3600}
    )
    costs["l21_table2"]["paper"] = {"seconds_per_1k_steps": 2.0}  # one arm of one row slower
    budget = bench._curricula_budget([[], []], costs)
    assert budget == "1.5M per run: 0.8 / 0.4 h (paper's / ours, at Table 2's rates)"


def test_fig6_falls_are_ranked_against_how_widely_each_run_sampled(
    benchmark_module, tmp_path, monkeypatch
):
    bench = benchmark_module("reproduce")
    monkeypatch.setattr(bench, "OUT", tmp_path)
    kept = [("k5", 0, 2.0, 0.8), ("k10", 0, 5.0, 0.3), ("k20", 0, 9.0, 0.05), ("k0", 0, 30.0, 1.0)]
    for variant, seed, falls, share in kept[:2]:
        report = {"fall_percent": falls, "sampling": {"effective_share": share, "low_mass": 0.5}}
        bench.result_path("wl19_fig6", "ours", variant, seed, 1000).write_text(
            json.dumps({"seed": seed, "report": report})
        )
    assert bench.falls_against_sampling("ours") is None  # two runs: no rank correlation yet
    for variant, seed, falls, share in kept[2:]:
        report = {"fall_percent": falls, "sampling": {"effective_share": share, "low_mass": 0.5}}
        bench.result_path("wl19_fig6", "ours", variant, seed, 1000).write_text(
            json.dumps({"seed": seed, "report": report})
        )
    # k = 0 draws uniformly by definition: left out, so the three adaptive runs rank exactly
    got = bench.falls_against_sampling("ours")
    assert got["runs"] == 3 and got["spearman"] == -1.0
    assert bench.falls_against_sampling("paper") is None


def test_our_arm_starts_from_a_base_stage_its_variants_share(
    benchmark_module, tmp_path, monkeypatch
):
    """[WL19] Table 4 in our arm: the x0.5 family warm started from a base-body run of the same
    seed, trained once and shared by RN on and off (budgets shrunk)."""
    bench = benchmark_module("reproduce")
    monkeypatch.setattr(bench, "OUT", tmp_path / "results")
    monkeypatch.setattr(bench, "RUNS", tmp_path / "runs")
    monkeypatch.setattr(bench, "EVAL", {"bodies": 2, "seconds": 0.5, "grid": 2})
    row = dict(bench.ROWS["wl19_table4"])
    row["base"] = {"configs/quadruped_x0.5.yaml": ("configs/quadruped_base.yaml", 4096)}
    monkeypatch.setitem(bench.ROWS, "wl19_table4", row)

    off = bench.run_one("wl19_table4", "ours", "quadruped_no_rn", 0, 4096, threads=1)
    base = tmp_path / "runs" / "wl19_table4" / "ours" / "base_quadruped_base_s0"
    assert off["config"] == "configs/quadruped_x0.5.yaml"
    assert off["base"] == {"config": "configs/quadruped_base.yaml", "env_steps": 4096}
    assert off["overrides"]["train.init_from"] == str(base)
    assert off["overrides"]["env.reward.normalize"] is False
    trained = checkpoint.load(checkpoint.resolve(base))
    assert trained["progress"]["env_steps"] >= 4096
    assert trained["config"]["shape_scale"] == 0.0  # the base body
    family = tmp_path / "runs" / "wl19_table4" / "ours" / "quadruped_no_rn_s0"
    used = checkpoint.load(checkpoint.resolve(family))["config"]
    assert used["shape_scale"] == 0.5 and used["train"]["init_from"] == str(base)
    assert used["ppo"]["minibatch_size"] == 512  # ours: no paper recipe (128) over the config

    stamp = checkpoint.resolve(base).stat().st_mtime_ns
    on = bench.run_one("wl19_table4", "ours", "quadruped_rn", 0, 4096, threads=1)
    assert on["overrides"]["train.init_from"] == str(base)
    assert checkpoint.resolve(base).stat().st_mtime_ns == stamp  # not trained again
    assert bench.variant_spec("wl19_table4", "paper", "quadruped_rn") == (
        "configs/quadruped.yaml",
        {"env.reward.normalize": True},
        2_000_000,
        None,
    )


def test_a_family_run_keeps_the_share_of_its_ranges_it_trained_on(
    benchmark_module, tmp_path, monkeypatch
):
    """Our biped grows its range from the base body (`widen`); the evaluation draws from all of
    it, so a kept run says how far the training range had grown."""
    from paramimic.config import load_config
    from paramimic.curriculum.adaptive import AdaptiveCurriculum

    bench = benchmark_module("reproduce")
    monkeypatch.setattr(bench, "OUT", tmp_path / "results")
    monkeypatch.setattr(bench, "RUNS", tmp_path / "runs")
    grown = AdaptiveCurriculum.from_config(load_config(bench.ROOT / "configs/biped_x0.5.yaml"))
    assert bench._family_state(grown)["range_width"] == 0.05  # widen.start
    grown.width = 0.6
    assert bench._family_state(grown)["range_width"] == 0.6
    whole = AdaptiveCurriculum.from_config(load_config(bench.ROOT / "configs/quadruped_x0.5.yaml"))
    assert bench._family_state(whole)["range_width"] == 1.0

    def kept(seed: int, width: float | None) -> dict:
        grid = {"coefficient_of_variation": 0.5}
        report = {"fall_percent": 50.0, "task_achievement": 40.0, "worst_decile_return": 20.0,
                  "grid_uniformity": grid, "mean_length_seconds": 20.0,
                  "mean_forward_speed": 1.0, "range_width": width}  # fmt: skip
        return {"seed": seed, "report": report}

    cell = bench._cell("wl19_table4", [kept(0, 0.6), kept(1, 1.0)])
    assert cell.endswith("falls 50.0 / 50.0; trained on 60 / 100 % of the ranges)")
    assert "trained on" not in bench._cell("wl19_table4", [kept(0, 1.0), kept(1, 1.0)])
    assert "trained on" not in bench._cell("wl19_table4", [kept(0, None)])  # kept before it

    # a budget raised later: its runs supersede those kept at the old one, which stay apart
    bench.OUT.mkdir()
    for seed, steps, width in ((0, 4_000_000, 0.5), (1, 4_000_000, 0.6), (0, 8_000_000, 0.9)):
        path = bench.result_path("wl19_table4", "ours", "biped_lower_rn", seed, steps)
        path.write_text(json.dumps(kept(seed, width) | {"env_steps": steps + 100}))
    assert [r["seed"] for r in bench._results("wl19_table4", "ours", "biped_lower_rn")] == [0]
    summary = bench._kept_summary(
        "wl19_table4", bench._by_budget("wl19_table4", "ours", "biped_lower_rn")
    )
    assert summary["per_seed"]["range_width"] == [0.9]
    assert summary["earlier"]["4000k"]["per_seed"]["range_width"] == [0.5, 0.6]
    assert bench._short_of_budget("wl19_table4", "ours", ["biped_lower_rn"]) == ""
    (bench.OUT / "wl19_table4_ours_biped_lower_rn_s0_8000k.json").unlink()  # 4M kept only
    assert bench._short_of_budget("wl19_table4", "ours", ["biped_lower_rn"]) == "at 4M of 8M"
    # a claim compares variants at one budget, each on three seeds
    for variant in ("biped_lower_rn", "biped_lower_no_rn"):
        for seed in (0, 1, 2):
            path = bench.result_path("wl19_table4", "ours", variant, seed, 4_000_000)
            path.write_text(json.dumps(kept(seed, 0.5)))
    verdict, text = bench._claim_rn("ours", "biped_lower")
    assert verdict == "disagrees" and text.endswith("; at 4M of 8M")  # equal: RN raises nothing
    fallen = kept(2, 0.5)
    fallen["report"] |= {"fall_percent": 100.0, "mean_length_seconds": 1.0}
    path = bench.result_path("wl19_table4", "ours", "biped_lower_rn", 2, 4_000_000)
    path.write_text(json.dumps(fallen))
    assert bench._claim_rn("ours", "biped_lower")[0] == "disagrees"  # RN off still walks
    for variant in ("biped_lower_rn", "biped_lower_no_rn"):
        for seed in (0, 1, 2):
            path = bench.result_path("wl19_table4", "ours", variant, seed, 4_000_000)
            path.write_text(json.dumps(fallen | {"seed": seed}))
    verdict, text = bench._claim_rn("ours", "biped_lower")
    assert verdict == "cannot say" and text.startswith(
        "every body falls with RN and without, after 1.0 and 1.0 s on the mean; task 40.0 vs 40.0"
    )
    path = bench.result_path("wl19_table4", "ours", "biped_lower_rn", 0, 8_000_000)
    path.write_text(json.dumps(kept(0, 1.0)))
    assert bench._claim_rn("ours", "biped_lower") == ("not run yet", "")  # 8M against 4M: no
    path = bench.result_path("wl19_table4", "ours", "quadruped_rn", 0, 2_000_000)
    path.write_text(json.dumps(kept(0, 1.0)))
    assert "earlier" not in bench._kept_summary(
        "wl19_table4", bench._by_budget("wl19_table4", "ours", "quadruped_rn")
    )
    for path in bench.OUT.iterdir():
        path.unlink()

    # kept before the width was, its run directory gone: the config says it where it can
    for variant in ("quadruped_rn", "biped_lower_rn"):
        old = {"row": "wl19_table4", "arm": "ours", "variant": variant, "seed": 0,
               "env_steps": 2000, "report": {"sampling": {"effective_share": 0.1}}}  # fmt: skip
        bench.result_path("wl19_table4", "ours", variant, 0, 2000).write_text(json.dumps(old))
    quadruped = bench.result_path("wl19_table4", "ours", "quadruped_rn", 0, 2000)
    assert bench.backfill() == [quadruped]  # never widened: the whole range throughout
    assert json.loads(quadruped.read_text())["report"]["range_width"] == 1.0
    biped = bench.result_path("wl19_table4", "ours", "biped_lower_rn", 0, 2000)
    assert "range_width" not in json.loads(biped.read_text())["report"]  # only its run knew


def test_rn_scales_spread_wider_over_the_papers_ranges_than_over_our_halved_ones(
    benchmark_module,
):
    """What RN corrects in each arm of [WL19] Table 4: its scales over bodies drawn from the
    arm's ranges; the paper's full ranges spread them further apart than our halved ones."""
    bench = benchmark_module("reproduce")
    found = bench.scales(bodies=60)
    assert set(found) == {"biped_lower", "quadruped"}
    for body, arms in found.items():
        for arm in ("paper", "ours"):
            for name in ("velocity", "direction", "energy"):
                s = arms[arm][name]
                assert 0.0 < s["p5"] <= s["p95"] and s["ratio"] >= 1.0, (body, arm, name)
        for name in ("velocity", "energy"):
            assert arms["paper"][name]["ratio"] > arms["ours"][name]["ratio"], (body, name)


def test_claims_are_judged_per_arm_once_every_variant_has_run_on_three_seeds(
    benchmark_module, tmp_path, monkeypatch
):
    bench = benchmark_module("reproduce")
    monkeypatch.setattr(bench, "RESULTS", tmp_path)
    monkeypatch.setattr(bench, "OUT", tmp_path / "reproduce")
    bench.OUT.mkdir()

    def keep(variant: str, seed: int, low_gravity: float) -> None:
        er, ranges = 0.3 - low_gravity / 4, {"gravity": [low_gravity, 1.6]}
        report = {"explored_ratio": er, "ranges": ranges}
        bench.result_path("l21_table2", "ours", variant, seed, 1000).write_text(
            json.dumps({"seed": seed, "report": report})
        )

    lowest = {"A1": 0.6, "A2": 0.4, "A3": 0.2}
    for seed in (0, 1):
        for variant, g in lowest.items():
            keep(variant, seed, g)
    assert bench._claim_ablation("ours") == ("not run yet", "")  # two seeds
    for variant, g in lowest.items():
        keep(variant, 2, g)
    verdict, text = bench._claim_ablation("ours")
    assert verdict == "agrees" and text == (
        "ER 0.15 / 0.20 / 0.25; gravity [0.60, 1.60] / [0.40, 1.60] / [0.20, 1.60] (A1 / A2 / A3);"
        " in that order on seeds 0, 1, 2 of 0, 1, 2"
    )
    keep("A3", 2, 0.5)  # one seed of A3 below its A2: the mean still agrees, not every seed
    verdict, text = bench._claim_ablation("ours")
    assert verdict == "agrees" and text.endswith("in that order on seeds 0, 1 of 0, 1, 2")
    keep("A3", 2, 1.0)  # one seed of A3 that explored less turns the mean around
    assert bench._claim_ablation("ours")[0] == "disagrees"
    assert bench._claim_ablation("paper") == ("not run yet", "")
    bare = {"seed": 0, "report": {"explored_ratio": 0.0, "ranges": {"gravity": None}}}
    assert bench._cell("l21_table2", [bare]) == "ER 0.00 (0.00); no elites (seeds 0)"

    # §7.3 at the paper's settings: read from benchmarks/curriculum.py --recipe l21's JSON
    def run(sampling: str, seed: int) -> dict:
        er = 0.5 if sampling == "uniform" else 0.2
        curve = [{"episodes": 0, "explored_ratio": 0.0}, {"episodes": 100, "explored_ratio": er}]
        return {"sampling": sampling, "seed": seed, "steps": 1000, "curve": curve}

    (tmp_path / "curriculum").mkdir()
    runs = [run(s, seed) for s in bench.CURRICULA for seed in (0, 1, 2)]
    (tmp_path / "curriculum" / "curriculum_l21.json").write_text(json.dumps({"runs": runs}))
    verdict, text = bench._claim_curricula("paper")
    assert verdict == "disagrees" and "uniform 0.50" in text and "curriculum 0.20" in text
    assert bench._claim_curricula("ours") == ("not run yet", "")
    rows = [r for r in bench.claims() if r[0] == "[L21] §7.3"]
    assert rows[0][2].startswith("disagrees: ER at N = 100") and rows[0][3] == "not run yet"


def test_all_leaves_what_is_kept_and_costs_what_is_left(benchmark_module, tmp_path, monkeypatch):
    """`reproduce.py all --dry-run`: every run of every row and §7.3 curriculum not kept yet, on
    the claims' seeds, with its hours at cost.json's rates (a base stage not trained yet adds
    its own, once per seed)."""
    bench = benchmark_module("reproduce")
    monkeypatch.setattr(bench, "OUT", tmp_path / "reproduce")
    monkeypatch.setattr(bench, "RUNS", tmp_path / "runs")
    curriculum = bench.curriculum_benchmark()
    monkeypatch.setattr(curriculum, "RESULTS", tmp_path / "curriculum")
    bench.OUT.mkdir()
    (tmp_path / "curriculum" / "runs").mkdir(parents=True)
    for row in bench.ROWS:  # our arm kept, but for one biped seed, RN off
        for variant in bench.ROWS[row]["variants"]:
            for seed in bench.SEEDS:
                steps = bench.variant_spec(row, "ours", variant)[2]
                if (row, variant, seed) != ("wl19_table4", "biped_lower_no_rn", 1):
                    bench.result_path(row, "ours", variant, seed, steps).write_text("{}")
    for sampling in bench.CURRICULA:
        for seed in bench.SEEDS:
            if (sampling, seed) != ("mastering", 2):
                curriculum.kept_run(sampling, seed, bench.CURRICULA_STEPS).write_text("{}")

    assert bench.pending(["ours"]) == [
        ("wl19_table4 ours biped_lower_no_rn seed 1", None),  # no cost.json: hours unknown
        ("§7.3 ours mastering seed 2", None),
    ]
    rate = {"seconds_per_1k_steps": 1.8}  # 1 h per 2M env steps
    costs = {row: {"paper": rate, "ours": rate} for row in bench.ROWS}
    (bench.OUT / "cost.json").write_text(json.dumps(costs))
    # the biped's family stage (8M) and its base stage (2M), which nothing has trained yet
    assert bench.pending(["ours"]) == [
        ("wl19_table4 ours biped_lower_no_rn seed 1", pytest.approx(5.0)),
        ("§7.3 ours mastering seed 2", pytest.approx(0.75)),
    ]
    # stopped at 3M of the family stage, its base stage done: what is left of it only
    run_dir = bench.RUNS / "wl19_table4" / "ours" / "biped_lower_no_rn_s1"
    checkpoint.save(run_dir, {"progress": {"env_steps": 3_000_000}}, 1)
    base = bench.base_dir("wl19_table4", "ours", "configs/biped_base.yaml", 1)
    checkpoint.save(base, {"progress": {"env_steps": 2_000_000}}, 1)
    assert bench.pending(["ours"])[0][1] == pytest.approx(2.5)
    left = bench.pending(["paper"])  # nothing of the paper's arm is kept: every run, no bases
    runs = sum(len(spec["variants"]) for spec in bench.ROWS.values()) + len(bench.CURRICULA)
    assert len(left) == 3 * runs
    assert sum(h for _, h in left) == pytest.approx(3 * (11 * 1.0 + 5 * 0.75))
    assert bench._curricula_command("paper", 2)[-2:] == ["--recipe", "l21"]
    assert "--recipe" not in bench._curricula_command("ours", 2)
