"""Stamps on generated documents: which code made the numbers, with which command, and a digest
of the files the numbers depend on, so a test can tell a stale table without re-running it.

A generated Markdown block is

    <!-- generated {"command": ..., "inputs": [...], "inputs_sha256": ..., ...} -->
    ... the table ...
    <!-- end generated -->

and a generated JSON card carries the same object under ``"stamp"``. ``inputs`` are paths
relative to the repository (files or folders); their digest covers every file under them
(``__pycache__`` and compiled files left out) by relative path and content, so a change to any
of them, and nothing else, makes the block stale (:func:`stale_blocks`).
"""
from __future__ import annotations

import hashlib
import json
import re
import subprocess
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from datetime import UTC, datetime
from pathlib import Path

__all__ = [
    "ROOT",
    "Stamp",
    "file_stamps",
    "generated_block",
    "generated_files",
    "inputs_digest",
    "make_stamp",
    "read_blocks",
    "replace_block",
    "stale_blocks",
    "stale_stamps",
    "table_main",
]

#: the repository (the parent of the package)
ROOT = Path(__file__).resolve().parent.parent

_BLOCK = re.compile(r"<!-- generated (\{.*?\}) -->\n(.*?)<!-- end generated -->", re.DOTALL)
_SKIP = ("__pycache__", ".pyc", ".so", ".egg-info")


@dataclass(frozen=True)
class Stamp:
    """Who made a generated table, and from what.

    Attributes
    ----------
    id : str
        The block's name, unique in its file.
    command : str
        The command that regenerates it (run from the repository).
    inputs : tuple of str
        Repository-relative paths the numbers depend on.
    inputs_sha256 : str
        :func:`inputs_digest` of ``inputs`` when it was made.
    version : str
        The package version.
    commit : str
        ``git rev-parse --short HEAD`` then (``"unknown"`` outside a clone), with ``+dirty`` when
        an input had uncommitted changes.
    date : str
        UTC date it was made.
    """

    id: str
    command: str
    inputs: tuple[str, ...]
    inputs_sha256: str
    version: str
    commit: str
    date: str

    def text(self) -> str:
        """One line for the reader: the code version and the command."""
        return f"fdi-sim {self.version} at commit {self.commit}, {self.date}; command: `{self.command}`"


def _files(inputs: tuple[str, ...], root: Path) -> list[Path]:
    out = []
    for rel in inputs:
        p = root / rel
        if not p.exists():
            raise FileNotFoundError(f"stamp input {rel!r} does not exist under {root}")
        for f in sorted([p] if p.is_file() else p.rglob("*")):
            if f.is_file() and not any(s in str(f) for s in _SKIP):
                out.append(f)
    return sorted(set(out))


def inputs_digest(inputs: tuple[str, ...] | list[str], root: Path = ROOT) -> str:
    """SHA-256 (first 20 hex digits) over the relative path and bytes of every file under
    ``inputs``."""
    h = hashlib.sha256()
    for f in _files(tuple(inputs), root):
        h.update(f.relative_to(root).as_posix().encode() + b"\0")
        h.update(f.read_bytes())
        h.update(b"\0")
    return h.hexdigest()[:20]


def make_stamp(block_id: str, command: str, inputs: tuple[str, ...] | list[str], root: Path = ROOT) -> Stamp:
    """The stamp for a block made now from the code under ``root``."""
    from fdi_sim import __version__

    inputs = tuple(inputs)
    try:
        commit = subprocess.run(["git", "-C", str(root), "rev-parse", "--short", "HEAD"], capture_output=True,
                                text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--", *inputs],
                               capture_output=True, text=True, check=True).stdout.strip()
        commit += "+dirty" if dirty else ""
    except (OSError, subprocess.CalledProcessError):
        commit = "unknown"
    return Stamp(block_id, command, inputs, inputs_digest(inputs, root), __version__, commit,
                 datetime.now(UTC).strftime("%Y-%m-%d"))


def generated_block(stamp: Stamp, body: str) -> str:
    """``body`` between the stamp's opening comment and the closing one, with the stamp's
    readable line under it."""
    head = json.dumps(asdict(stamp), separators=(", ", ": "))
    return f"<!-- generated {head} -->\n{body.rstrip()}\n\nStamp: {stamp.text()}\n<!-- end generated -->"


def read_blocks(text: str) -> list[tuple[Stamp, str]]:
    """Every generated block of a Markdown text: its stamp and its body."""
    out = []
    for m in _BLOCK.finditer(text):
        d = json.loads(m.group(1))
        d["inputs"] = tuple(d["inputs"])
        out.append((Stamp(**d), m.group(2)))
    return out


def replace_block(text: str, stamp: Stamp, body: str) -> str:
    """``text`` with its block named ``stamp.id`` replaced (appended when it has none)."""
    new = generated_block(stamp, body)
    for m in _BLOCK.finditer(text):
        if json.loads(m.group(1)).get("id") == stamp.id:
            return text[:m.start()] + new + text[m.end():]
    return text.rstrip() + "\n\n" + new + "\n"


def generated_files(root: Path = ROOT) -> list[Path]:
    """Every file that may hold generated blocks: ``README.md``, ``docs/*.md``, the HTML pages
    ``docs/*.html`` (the leaderboard) and the stamped JSON cards ``docs/card/*.json``."""
    return ([root / "README.md"] + sorted((root / "docs").glob("*.md")) + sorted((root / "docs").glob("*.html"))
            + sorted((root / "docs" / "card").glob("*.json")))


def file_stamps(path: Path) -> list[Stamp]:
    """The stamps of a Markdown (or HTML) file's generated blocks, or a JSON card's stamp."""
    path = Path(path)
    text = path.read_text()
    if path.suffix != ".json":
        return [s for s, _ in read_blocks(text)]
    card = json.loads(text)
    d = card.get("stamp") if isinstance(card, dict) else None
    return [] if not isinstance(d, dict) else [Stamp(**{**d, "inputs": tuple(d["inputs"])})]


def stale_stamps(path: Path, root: Path = ROOT) -> list[tuple[Stamp, str]]:
    """The stamps of ``path`` whose inputs changed since they were made, each with why."""
    out = []
    for s in file_stamps(path):
        try:
            now = inputs_digest(s.inputs, root)
        except FileNotFoundError as e:
            out.append((s, str(e)))
            continue
        if now != s.inputs_sha256:
            out.append((s, f"stale (inputs {', '.join(s.inputs)} changed since commit {s.commit})"))
    return out


def stale_blocks(path: Path, root: Path = ROOT) -> list[str]:
    """What is stale in the generated blocks of a Markdown file (or the stamp of a JSON card):
    one line per block whose inputs changed since it was made, naming the command to run."""
    return [f"{Path(path).name} [{s.id}]: {why}; run `{s.command}`" for s, why in stale_stamps(path, root)]


def table_main(md: Path, command: str, blocks: Sequence[tuple[str, Sequence[str], Callable[[], str]]],
               argv: Sequence[str]) -> int:
    """The ``main`` of a ``docs/make_*.py`` table script: each ``(block id, inputs, render)`` of
    ``blocks`` rendered and written into ``md`` with a stamp made now for ``command``; with
    ``--print`` in ``argv`` the tables are printed instead and nothing is written."""
    if "--print" in argv:
        print("\n\n".join(render() for _, _, render in blocks))
        return 0
    text = md.read_text()
    for block_id, inputs, render in blocks:
        text = replace_block(text, make_stamp(block_id, command, tuple(inputs)), render())
    md.write_text(text)
    print(f"wrote the {', '.join(b for b, _, _ in blocks)} block(s) of {md}")
    return 0
