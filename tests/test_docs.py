"""The README stays a short page, and its table of shipped configs says what the configs say."""

import re
from pathlib import Path

from paramimic.config import load_config

ROOT = Path(__file__).resolve().parent.parent


def _millions(text: str) -> float:
    return float(text.strip().rstrip("M"))


def test_the_readme_is_short_and_lists_every_shipped_config_with_its_budget():
    readme = (ROOT / "README.md").read_text()
    assert len(readme.splitlines()) <= 250
    table = readme.split("## Shipped configs", 1)[1].split("\n\n", 2)[1]
    listed: dict[str, float] = {}
    for row in table.splitlines()[2:]:
        cells = [c.strip() for c in row.strip("|").split("|")]
        names = re.findall(r"`([a-z0-9_.]+)\.yaml`", cells[0])
        if "..." in cells[0]:  # `a.yaml` ... `d.yaml`: the run of names between them
            first, last = names
            stem = first.rstrip("abcdefgh")
            names = [f"{stem}{c}" for c in "abcd"]
            assert names[-1] == last
        steps = [_millions(s) for s in cells[2].replace("each", "").split(",")]
        steps = steps * len(names) if len(steps) == 1 else steps
        assert len(steps) == len(names), row
        listed |= dict(zip(names, steps, strict=True))
    shipped = {p.stem for p in (ROOT / "configs").glob("*.yaml")}
    assert set(listed) == shipped
    for name, millions in listed.items():
        total = load_config(ROOT / "configs" / f"{name}.yaml").train.total_steps / 1e6
        digits = 1 if millions != round(millions) else 0
        assert round(total, digits) == millions, name


def _macros():
    import importlib.util

    spec = importlib.util.spec_from_file_location("macros", ROOT / "docs" / "hooks" / "macros.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_every_results_page_renders_its_numbers_from_the_benchmarks_json():
    """A results page opts in to the macros and cites a file in benchmarks/results/ that exists;
    the helpers refuse a file no benchmark wrote (which fails `mkdocs build --strict`)."""
    import pytest

    macros = _macros()
    for page in sorted((ROOT / "docs" / "results").glob("*.md")):
        if page.name == "index.md":
            continue
        text = page.read_text()
        assert text.startswith("---\nrender_macros: true\n---\n"), page.name
        cited = re.findall(r'(results?)\("([^"]+)"(, required=false)?\)', text)
        assert cited, f"{page.name} reads no benchmark JSON"
        for kind, path, optional in cited:
            if kind == "result":
                assert macros.result(path) is not None, path
            else:
                assert macros.results(path, required=not optional) is not None, path
    with pytest.raises(FileNotFoundError, match="benchmarks/results/nothing/here.json"):
        macros.result("nothing/here.json")
    assert macros.results("nothing/*.json", required=False) == {}
    assert macros.num(1234.56) == "1,235" and macros.num(0.5, 2) == "0.50"
    assert macros.ratio(1.234) == "1.23x" and macros.pct(12.34) == "12.3 %"
    assert macros.pick([10, 11, 12, 13], [0, 3]) == [10, 13]
    table = macros.table([["a", "1"]], ["name", "value"]).splitlines()
    assert table[0].split("|")[1].strip() == "name" and table[2].split("|")[2].strip() == "1"
