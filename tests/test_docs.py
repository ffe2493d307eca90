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
