"""The exception hierarchy of fdi-sim.

Every error the package raises on purpose derives from :class:`FdiSimError`, and also from
the matching built-in, so ``except ValueError`` still works where a caller expects it.
Messages are built from fields, so tests and the CLI can read the parts.
"""
from __future__ import annotations


class FdiSimError(Exception):
    """Base of every deliberate fdi-sim error."""


class ScenarioError(FdiSimError, ValueError):
    """A scenario file (or object) is invalid.

    Parameters
    ----------
    source : str
        The file path, or ``"<scenario>"`` for an object built in Python.
    key : str
        The dotted key path of the offending entry (``"initial.vc_kts"``), or ``""``.
    problem : str
        What is wrong.
    fix : str
        What to write instead.
    """

    def __init__(self, source: str, key: str, problem: str, fix: str = "") -> None:
        self.source, self.key, self.problem, self.fix = source, key, problem, fix
        where = f"{source}: {key}" if key else source
        msg = f"{where}: {problem}"
        if fix:
            msg += f" Fix: {fix}"
        super().__init__(msg)


class TrimError(FdiSimError, RuntimeError):
    """An operating point could not be trimmed.

    Parameters
    ----------
    aircraft : str
        Aircraft id (``"f16"``, ``"DHC6"``).
    point : str
        Human-readable operating point (without the aircraft id: ``"h=5000 ft VC=150 kt"``).
    reason : str
        Why the trim failed (residual, limit hit, JSBSim's message).
    fix : str, optional
        What to change in the operating point.
    source : str, optional
        The scenario file the point came from ("" when built in Python).
    key : str, optional
        The scenario key of the point (``"initial"``), or "".
    """

    def __init__(self, aircraft: str, point: str, reason: str, fix: str = "", source: str = "", key: str = "") -> None:
        self.aircraft, self.point, self.reason, self.fix = aircraft, point, reason, fix
        self.source, self.key = source, key
        where = "".join(f"{part}: " for part in (source, key) if part)
        msg = f"{where}cannot trim {aircraft} at {point}: {reason}"
        if fix:
            msg += f" Fix: {fix}"
        super().__init__(msg)

    def with_source(self, source: str, key: str = "initial") -> "TrimError":
        """The same error, located in a scenario file: the message starts with ``"source: key: "``."""
        return TrimError(self.aircraft, self.point, self.reason, self.fix, str(source), key)

    def __reduce__(self) -> tuple:  # pickle (study workers) rebuilds from the fields, not the message
        return (TrimError, (self.aircraft, self.point, self.reason, self.fix, self.source, self.key))


class SimulationDiverged(FdiSimError, RuntimeError):
    """The simulation left the physically meaningful region.

    Parameters
    ----------
    t_s : float
        Simulated time of the divergence [s].
    reason : str
        Which signal and which limit.
    """

    def __init__(self, t_s: float, reason: str) -> None:
        self.t_s, self.reason = t_s, reason
        super().__init__(f"diverged at t = {t_s:.3f} s: {reason}")


class LogError(FdiSimError, ValueError):
    """A flight log cannot be read or written.

    Parameters
    ----------
    path : str
        The log path.
    problem : str
        What is wrong and, where possible, what to do.
    """

    def __init__(self, path: str, problem: str) -> None:
        self.path, self.problem = str(path), problem
        super().__init__(f"{path}: {problem}")


class DesignError(FdiSimError, ValueError):
    """A detector or linear-model design cannot be done with the given inputs.

    Use for: window order too short, rank-deficient covariance, unobservable pair,
    undetectable fault, infeasible LMI. The message says what to change.
    """


class RegistryError(FdiSimError, KeyError):
    """Unknown or duplicate plugin id."""

    def __str__(self) -> str:  # KeyError quotes its argument; keep the message readable
        return str(self.args[0]) if self.args else ""


class CacheError(FdiSimError, OSError):
    """The folder for fdi-sim's built JSBSim models cannot be used, nor a temporary one.

    The message names the folder, the environment variable that chose it and the fix.
    """


class StudyError(ScenarioError):
    """A study file, its results folder or its cluster is unusable (what, where, and the fix).

    Same fields as :class:`ScenarioError`; ``source`` is the study file or the results folder.
    """


class ReviewError(FdiSimError, ValueError):
    """A log cannot be reviewed, two logs cannot be compared, or the report cannot be written.

    Parameters
    ----------
    source : str
        The log path (or the report path).
    problem : str
        What is wrong or missing.
    fix : str, optional
        What to do instead.
    """

    def __init__(self, source: str, problem: str, fix: str = "") -> None:
        self.source, self.problem, self.fix = str(source), problem, fix
        msg = f"{source}: {problem}"
        if fix:
            msg += f". Fix: {fix}"
        super().__init__(msg)

    def __reduce__(self) -> tuple:
        return (ReviewError, (self.source, self.problem, self.fix))
