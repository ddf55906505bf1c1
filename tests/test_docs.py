"""Every relative link and picture in the README and docs/ points at a file that exists and, for a
Markdown file, at a heading that exists (GitHub's anchor rules)."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = sorted([ROOT / "README.md", ROOT / "benchmarks" / "README.md", *(ROOT / "docs").glob("*.md")])

INLINE = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")
REFDEF = re.compile(r"^\[([^\]]+)\]:\s*(\S+)", re.M)
REFUSE = re.compile(r"\[[^\]]+\]\[([^\]]+)\]")


def _prose(text: str) -> str:
    """The text without fenced code blocks (a '# comment' there is no heading)."""
    out, fenced = [], False
    for line in text.split("\n"):
        if line.lstrip().startswith("```"):
            fenced = not fenced
            continue
        if not fenced:
            out.append(line)
    return "\n".join(out)


def slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = re.sub(r"`([^`]*)`", r"\1", heading.strip()).lower()
    return "".join(c for c in text if c.isalnum() or c in "-_ ").replace(" ", "-")


def anchors(path: Path) -> set[str]:
    seen: dict[str, int] = {}
    out = set()
    for line in _prose(path.read_text(encoding="utf-8")).split("\n"):
        m = re.match(r"#{1,6}\s+(.*)", line)
        if not m:
            continue
        base = slug(m.group(1))
        n = seen.get(base, 0)
        seen[base] = n + 1
        out.add(base if n == 0 else f"{base}-{n}")
    return out


def test_slug_follows_github():
    assert slug("6.13 Adopted: small clusters take their next class") == \
        "613-adopted-small-clusters-take-their-next-class"
    assert slug("5. Evaluation: metrics, folds, reports") == "5-evaluation-metrics-folds-reports"
    assert slug("Quick start (`lidarfx demo`)") == "quick-start-lidarfx-demo"


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_resolve(page: Path):
    text = _prose(page.read_text(encoding="utf-8"))
    refs = dict(REFDEF.findall(text))
    targets = INLINE.findall(text) + list(refs.values())
    for label in REFUSE.findall(text):
        assert label in refs, f"{page.name}: reference [{label}] has no definition"
    bad = []
    for target in targets:
        if re.match(r"[a-z]+:", target):  # http:, https:, mailto:
            continue
        file, _, frag = target.partition("#")
        dest = (page.parent / file).resolve() if file else page
        if not dest.exists():
            bad.append(f"{target} (no file)")
        elif frag and dest.suffix == ".md" and frag not in anchors(dest):
            bad.append(f"{target} (no heading)")
    assert not bad, f"{page.name}: broken links: {bad}"
