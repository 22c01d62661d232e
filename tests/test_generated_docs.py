"""Numbers in README.md and docs/ come from scripts, stamped, and a stale table fails here.

A generated table sits in a block whose stamp holds the digest of the files its numbers depend
on (:mod:`fdi_sim.stamp`); the check recomputes the digest (cheap: nothing is re-run). Every
other table says what it is on the line above it: ``<!-- table: reference -->`` (no measured
number) or ``<!-- table: result, unstamped; regenerate: ... -->`` (a measured table not yet
generated with a stamp: refused by the test below).
"""
from __future__ import annotations

import json
import re
import shutil
from pathlib import Path


from fdi_sim.stamp import (
    generated_files,
    inputs_digest,
    make_stamp,
    read_blocks,
    replace_block,
    stale_blocks,
)

ROOT = Path(__file__).resolve().parents[1]
DOCS = [p for p in generated_files(ROOT) if p.suffix == ".md"]
CARDS = [p for p in generated_files(ROOT) if p.suffix == ".json"]
MARKER = re.compile(r"^<!-- table: (reference|result, unstamped; regenerate: .+) -->$")


def _tables(path: Path) -> list[tuple[int, str | None, bool]]:
    """Each table of a Markdown file: (line number, its marker or None, inside a generated block)."""
    out, fenced, in_block, prev = [], False, False, ""
    lines = path.read_text().splitlines()
    for i, line in enumerate(lines):
        if line.startswith("```"):
            fenced = not fenced
        if line.startswith("<!-- generated "):
            in_block = True
        elif line.startswith("<!-- end generated -->"):
            in_block = False
        if not fenced and line.startswith("|") and not prev.startswith("|"):
            m = MARKER.match(prev)
            out.append((i + 1, m.group(1) if m else None, in_block))
        prev = line
    return out


def test_every_generated_block_is_fresh():
    stale = [s for p in DOCS + CARDS for s in stale_blocks(p)]
    assert not stale, "\n".join(stale)


def test_every_table_is_generated_or_says_what_it_is():
    bare = [f"{p.relative_to(ROOT)}:{n}" for p in DOCS for n, marker, gen in _tables(p) if marker is None and not gen]
    assert not bare, f"tables with neither a generated block nor a marker line above them: {bare}"


def test_every_result_table_and_card_is_generated_with_a_stamp():
    unstamped = [f"{p.relative_to(ROOT)}:{n} ({m.split('regenerate: ')[1]})" for p in DOCS
                 for n, m, gen in _tables(p) if m and m.startswith("result")]
    cards = [str(c.relative_to(ROOT)) for c in CARDS
             if not isinstance(json.loads(c.read_text()), dict) or not isinstance(json.loads(c.read_text()).get("stamp"), dict)]
    assert not unstamped and not cards, f"unstamped result tables: {unstamped}; cards without a stamp: {cards}"


def test_the_freshness_check_can_fail(tmp_path):
    """A block made from two files: fresh; one input changed: stale, naming the command; a stamp
    whose digest was altered: stale; a missing input: named."""
    (tmp_path / "src").mkdir()
    (tmp_path / "src" / "a.py").write_text("X = 1\n")
    (tmp_path / "make.py").write_text("print('table')\n")
    stamp = make_stamp("t", "python make.py", ("src", "make.py"), root=tmp_path)
    doc = tmp_path / "doc.md"
    doc.write_text(replace_block("# A doc\n", stamp, "| a |\n|---|\n| 1 |"))
    assert stale_blocks(doc, root=tmp_path) == []
    assert read_blocks(doc.read_text())[0][0] == stamp
    assert _tables(doc) == [(4, None, True)]

    (tmp_path / "src" / "a.py").write_text("X = 2\n")
    msg = stale_blocks(doc, root=tmp_path)
    assert len(msg) == 1 and "stale" in msg[0] and "python make.py" in msg[0]

    (tmp_path / "src" / "a.py").write_text("X = 1\n")
    assert stale_blocks(doc, root=tmp_path) == []
    doc.write_text(doc.read_text().replace(stamp.inputs_sha256, "0" * 20))
    assert "stale" in stale_blocks(doc, root=tmp_path)[0]

    shutil.rmtree(tmp_path / "src")
    assert "does not exist" in stale_blocks(doc, root=tmp_path)[0]


def test_a_digest_covers_content_and_names(tmp_path):
    (tmp_path / "a.txt").write_text("1")
    d = inputs_digest(("a.txt",), root=tmp_path)
    (tmp_path / "a.txt").write_text("2")
    assert inputs_digest(("a.txt",), root=tmp_path) != d
    (tmp_path / "a.txt").rename(tmp_path / "b.txt")
    (tmp_path / "b.txt").write_text("1")
    assert inputs_digest(("b.txt",), root=tmp_path) != d


def test_a_table_script_writes_its_stamped_block_or_prints_it(tmp_path, capsys):
    """fdi_sim.stamp.table_main, the main of the docs/make_*.py table scripts: --print writes
    nothing; otherwise the block is written with a stamp the freshness check accepts."""
    from fdi_sim.stamp import table_main

    doc = tmp_path / "doc.md"
    doc.write_text("# A doc\n")
    blocks = [("t", ("fdi_sim/stamp.py",), lambda: "| a |\n|---|\n| 1 |")]
    assert table_main(doc, "python make.py", blocks, ["--print"]) == 0
    assert doc.read_text() == "# A doc\n" and "| 1 |" in capsys.readouterr().out
    assert table_main(doc, "python make.py", blocks, []) == 0
    (stamp, body), = read_blocks(doc.read_text())
    assert stamp.id == "t" and "| 1 |" in body and stale_blocks(doc) == []
