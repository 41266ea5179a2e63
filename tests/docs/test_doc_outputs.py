"""The check of the pages' stored outputs (.ci/doc_commands.py): a block's printed text must equal its ```output
block, ``...`` being the only wildcard; a differing number fails and names the line; --update rewrites stale outputs;
the guides keep their printed results as checked output blocks."""

from __future__ import annotations

import importlib.util
import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SPEC = importlib.util.spec_from_file_location("doc_commands", ROOT / ".ci" / "doc_commands.py")
doc_commands = importlib.util.module_from_spec(SPEC)
sys.modules["doc_commands"] = doc_commands
SPEC.loader.exec_module(doc_commands)

PAGE = '''# A page

```python
x = 0.1 + 0.2
print(f"sum {x:.3f}")
print("took 12.3 s")
```

```output
sum 0.300
took ... s
```

```bash
echo "rows: 3"
```

```output
rows: 3
```

```python
print("not checked")
```
'''


def test_matching_outputs_pass_and_ellipsis_is_the_only_wildcard(tmp_path):
    page = tmp_path / "page.md"
    page.write_text(PAGE)
    ran, checked, failures = doc_commands.run_page(page, tmp_path, python=True, update=False)
    assert (ran, checked, failures) == (3, 2, [])
    assert doc_commands.matches("a ... b", "a 1\n2 b") and not doc_commands.matches("sum 0.300", "sum 0.301")
    assert not doc_commands.matches("rows: 3", "rows: 3\nrows: 4")


def test_a_changed_number_fails_with_the_line_and_update_rewrites_it(tmp_path):
    page = tmp_path / "page.md"
    page.write_text(PAGE.replace("sum 0.300", "sum 0.311"))
    ran, checked, failures = doc_commands.run_page(page, tmp_path, python=True, update=False)
    assert checked == 2 and len(failures) == 1
    assert "page.md:3" in failures[0] and "stored:  sum 0.311" in failures[0] and "printed: sum 0.300" in failures[0]
    doc_commands.run_page(page, tmp_path, python=True, update=True)
    text = page.read_text()
    assert "sum 0.300\ntook 12.3 s\n```" in text and "rows: 3" in text      # the stale block rewritten, others kept
    assert doc_commands.run_page(page, tmp_path, python=True, update=False)[2] == []


def test_a_failing_block_stops_the_page(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("```python\nraise ValueError('boom')\n```\n\n```bash\necho after\n```\n")
    ran, checked, failures = doc_commands.run_page(page, tmp_path, python=True, update=False)
    assert ran == 1 and len(failures) == 1 and "ValueError: boom" in failures[0]


@pytest.mark.parametrize("guide, at_least", [("estimators.md", 3), ("mpc.md", 3), ("rl.md", 3)])
def test_the_guides_store_their_printed_results_as_checked_output_blocks(guide, at_least):
    text = (ROOT / "docs" / "guides" / guide).read_text(encoding="utf-8")
    blocks = doc_commands.page_blocks(text, python=True)
    assert sum(b.expected is not None for b in blocks) >= at_least
    assert not re.search(r"^On \d{4}-\d\d-\d\d this printed", text, flags=re.M)   # no unchecked printed results
