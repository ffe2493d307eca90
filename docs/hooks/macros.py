"""mkdocs-macros module: the results pages' numbers, read from the benchmarks' JSON when the site
is built, never copied by hand.

A page opts in with `render_macros: true` in its front matter and then writes, e.g.,

    {% set t = result("throughput/throughput.json") %}
    {{ t.rows.a_raw_mj_step.steps_per_s | num }} steps/s
    {{ table([[name, r.steps_per_s | num] for name, r in t.rows.items()], ["row", "steps/s"]) }}
    {{ source("throughput/throughput.json", "python benchmarks/throughput.py") }}

A path is relative to `benchmarks/results/`; a missing file or key fails `mkdocs build --strict`
(the plugin's `on_error_fail`, `on_undefined: strict`), so a page cannot cite what no benchmark
wrote.
"""

from __future__ import annotations

import json
from functools import cache
from pathlib import Path

from tabulate import tabulate

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "benchmarks" / "results"


@cache
def _read(path: str):
    file = RESULTS / path
    if not file.is_file():
        raise FileNotFoundError(f"docs cite benchmarks/results/{path}, which no benchmark wrote")
    if file.suffix == ".jsonl":
        return [json.loads(x) for x in file.read_text().splitlines() if x.strip()]
    return json.loads(file.read_text())


def result(path: str):
    """A benchmark's JSON (a `.jsonl` file: its rows), parsed."""
    return _read(path)


def results(pattern: str, required: bool = True) -> dict:
    """Every JSON file matching a glob under benchmarks/results/, by its path, sorted (none: an
    error, unless not `required`)."""
    found = sorted(p.relative_to(RESULTS).as_posix() for p in RESULTS.glob(pattern))
    if not found and required:
        raise FileNotFoundError(f"docs cite benchmarks/results/{pattern}: no file matches")
    return {p: _read(p) for p in found}


def num(value, digits: int = 0) -> str:
    """1234.5 -> '1,235' (digits: places after the point)."""
    return f"{float(value):,.{digits}f}"


def ratio(value, digits: int = 2) -> str:
    """1.234 -> '1.23x'."""
    return f"{float(value):.{digits}f}x"


def pct(value, digits: int = 1) -> str:
    """A value already in percent: 12.34 -> '12.3 %'."""
    return f"{float(value):.{digits}f} %"


def pick(values: list, indices: list[int]) -> list:
    """The items of `values` at `indices` (e.g. a curve at a few of its points)."""
    return [values[i] for i in indices]


def table(rows: list, headers: list[str]) -> str:
    """A Markdown table."""
    return tabulate(rows, headers=headers, tablefmt="github", disable_numparse=True)


def source(path: str, command: str) -> str:
    """The line under a number's table: which file holds it and which command wrote it."""
    return f"*From `benchmarks/results/{path}`, written by `{command}`.*"


def define_env(env) -> None:
    for fn in (result, results, table, source):
        env.macro(fn)
    for fn in (num, ratio, pct, pick):
        env.filter(fn)
