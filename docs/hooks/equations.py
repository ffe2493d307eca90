"""mkdocs hook: the table of every equation of both papers and the code that holds it, read from
the citations in `paramimic/` when the site is built (so it is never out of date).

A citation is `[WL19] Eq. N` or `[L21] Eq. N` (also `Eq. N-M`); a bare `Eq. N` belongs to the
paper its innermost function or class (else its module) cites most. Each is listed under the
function, method or class it sits in (or the module, for a module docstring or a module-level
constant). The table replaces the
`<!-- equations -->` marker of a page.
"""

from __future__ import annotations

import ast
import re
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
MARK = "<!-- equations -->"
CITED = re.compile(r"(?:\[(WL19|L21)\]\s+)?Eqs?\.\s*(\d+)(?:\s*[-–]\s*(\d+))?")
PAPERS = ("WL19", "L21")


def _scopes(tree: ast.Module) -> list[tuple[int, int, str]]:
    """(first line, last line, qualified name) of every def and class."""
    out = []

    def walk(node: ast.AST, prefix: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
                name = f"{prefix}{child.name}"
                out.append((child.lineno, child.end_lineno or child.lineno, name))
                walk(child, name + ".")

    walk(tree, "")
    return out


def citations(root: Path = ROOT / "paramimic") -> dict[tuple[str, int], set[str]]:
    """(paper, equation) -> the places that cite it (`module.py: name`)."""
    found: dict[tuple[str, int], set[str]] = defaultdict(set)
    for path in sorted(root.rglob("*.py")):
        text = path.read_text()
        lines = text.splitlines()
        scopes = _scopes(ast.parse(text))
        where = path.relative_to(ROOT).as_posix()

        def cited_most(first: int, last: int, lines: list[str] = lines) -> str | None:
            span = "\n".join(lines[first - 1 : last])
            counts = {p: span.count(f"[{p}]") for p in PAPERS}
            return max(counts, key=counts.get) if any(counts.values()) else None

        for lineno, line in enumerate(lines, 1):
            for m in CITED.finditer(line):
                inner = sorted((s for s in scopes if s[0] <= lineno <= s[1]), reverse=True)
                name = inner[0][2] if inner else "(module)"
                # a bare "Eq. N": the paper its innermost citing scope (or module) cites most
                paper = (
                    m.group(1)
                    or next((p for s in inner if (p := cited_most(s[0], s[1]))), None)
                    or cited_most(1, len(lines))
                )
                if paper is None:
                    continue
                first, last = int(m.group(2)), int(m.group(3) or m.group(2))
                for eq in range(first, min(last, first + 20) + 1):
                    found[(paper, eq)].add(f"`{where}`: `{name}`")
    return found


def table() -> str:
    rows = ["| paper | equation | where |", "|---|---|---|"]
    for (paper, eq), places in sorted(citations().items()):
        rows.append(f"| [{paper}] | Eq. {eq} | {'<br>'.join(sorted(places))} |")
    return "\n".join(rows)


def on_page_markdown(markdown: str, **kwargs) -> str:
    return markdown.replace(MARK, table()) if MARK in markdown else markdown
