"""The documentation stays true to the code: generated reference tables are current, the site's nav lists every
page that exists (and nothing else), and the README keeps its one-screen shape with working links."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_generated_reference_tables_are_current():
    run = subprocess.run([sys.executable, "docs/tools/gen_reference.py", "--check"], cwd=ROOT,
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr + run.stdout


def _nav_pages() -> set[str]:
    text = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    nav = text[text.index("\nnav:"):]
    return set(re.findall(r"([\w/.-]+\.md)\s*$", nav, flags=re.M))


def test_nav_lists_every_page_and_only_existing_ones():
    pages = _nav_pages()
    on_disk = {p.relative_to(ROOT / "docs").as_posix() for p in (ROOT / "docs").rglob("*.md")}
    assert pages - on_disk == set(), "nav entries without a file"
    assert on_disk - pages == set(), "pages missing from the nav in mkdocs.yml"
    assert "results/index.md" in pages


def test_readme_one_screen_with_the_two_setup_commands_first_and_working_links():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 200
    first_block = re.search(r"```bash\n(.*?)```", text, flags=re.S).group(1).strip().splitlines()
    assert first_block == ['pip install ".[dev]"', 'pytest -n 2 -m "not slow"']
    assert ("roadload simulate --vehicle gt_rwd --road hilly --seed 1 --out out/trip.parquet && "
            "roadload plot out/trip.parquet") in text
    links = re.findall(r"\]\(((?:docs|examples)/[^)#]+)", text)
    assert links, "the README links into the docs"
    missing = [link for link in links if not (ROOT / link).exists()]
    assert missing == []


def test_every_example_takes_quick():
    examples = sorted((ROOT / "examples").glob("*.py"))
    assert len(examples) >= 4
    for path in examples:
        assert '"--quick"' in path.read_text(encoding="utf-8"), f"{path.name} has no --quick option"
