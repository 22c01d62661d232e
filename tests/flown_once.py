"""Logs flown once per test session and shared by the pytest-xdist workers.

``make test`` runs two workers with ``--dist loadfile``: the files that read the same flown logs
(``tests/review/*``, the two Foxglove files) land on either worker, and a session fixture there
flies its logs once per worker. :func:`flown_once` flies them once for the whole session: the first
worker takes an exclusive ``fcntl`` lock on a file in the session's shared temporary folder
(``pytest-of-<user>/pytest-<n>``, the parent of each worker's base), flies, and writes an index;
the other waits on the lock and reads the index (the pytest-xdist documentation's pattern for
session-wide fixtures).
"""
from __future__ import annotations

import fcntl
import json
import os
import shutil
from pathlib import Path
from typing import Callable

import pytest


def flown_once(tmp_path_factory: pytest.TempPathFactory, name: str,
               fly: Callable[[Path], dict[str, Path]]) -> dict[str, Path]:
    """``fly(folder)``'s name -> log path, computed by one process of the session.

    Parameters
    ----------
    tmp_path_factory : pytest.TempPathFactory
        The session's factory (its base's parent is shared by the xdist workers).
    name : str
        The set of logs (a folder name).
    fly : callable
        Flies the logs into the given empty folder; returns name -> path.
    """
    base = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        base = base.parent  # .../pytest-<n>/popen-gw0 -> .../pytest-<n>, shared by the workers
    out = base / f"shared-{name}"
    with open(base / f"shared-{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes, or when the process dies
        index = out / "index.json"
        if index.exists():
            return {k: Path(v) for k, v in json.loads(index.read_text()).items()}
        if out.exists():
            shutil.rmtree(out)  # a worker that died while flying: fly again
        out.mkdir(parents=True)
        logs = fly(out)
        index.write_text(json.dumps({k: str(v) for k, v in logs.items()}))
        return logs
