"""The benchmark's error (kept in its package: it is raised only here and by the commands above it)."""
from __future__ import annotations

from fdi_sim.errors import ScenarioError


class BenchError(ScenarioError):
    """A benchmark suite, its results folder, a scores file or an export folder is unusable.

    Same fields as :class:`fdi_sim.errors.ScenarioError`: ``source`` is the file or folder, ``key`` the
    suite key or the option (``--scores``), with the fix; the command line exits 2 on it.
    """
