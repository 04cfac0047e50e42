"""The acslam exception tree.

Every error a user can cause (a bad config, a corrupt file, an invalid message) is an
:class:`AcslamError` whose message names the problem and where it is; the CLI turns it
into one line on stderr and exit code 1.
"""

from __future__ import annotations

from pathlib import Path


class AcslamError(Exception):
    """Base class of every error acslam raises on purpose."""


class AcslamWarning(UserWarning):
    """Base class of acslam's warnings: input it skipped and went on without. The CLI
    prints each as one ``acslam: warning:`` line."""


class ConfigError(AcslamError):
    """A scenario or config is invalid: names the file and the field path."""

    def __init__(self, source: str | Path | None, field: str, problem: str) -> None:
        self.source = str(source) if source is not None else "<config>"
        self.field = field
        self.problem = problem
        where = f"{self.source}: {field}" if field else self.source
        super().__init__(f"{where}: {problem}")


class DataError(AcslamError):
    """A map, dataset or log file cannot be read: names the file (and line if known)."""

    def __init__(self, path: str | Path, problem: str, line: int | None = None) -> None:
        self.path = str(path)
        self.line = line
        self.problem = problem
        where = f"{self.path}:{line}" if line is not None else self.path
        super().__init__(f"{where}: {problem}")


class MessageError(AcslamError, ValueError):
    """A robot <-> server message has an invalid field (NaN, inf, wrong shape)."""


class NoPathError(AcslamError):
    """No collision-free path exists (or start/goal have no free cell nearby)."""


class SlamError(AcslamError):
    """The optimiser failed (e.g. an indeterminant linear system); names the operation."""


class PluginError(AcslamError):
    """A plugin is unknown, registered twice, or its entry point cannot be loaded."""


class WallTimeLimitError(AcslamError):
    """Raised from the progress callback to stop a run that uses too much wall time."""


class VizError(AcslamError):
    """The live view cannot start."""


class CodecError(MessageError):
    """A payload that cannot be decoded into a valid message."""


class TransportError(AcslamError):
    """A bad endpoint, fault setting or robot id given to a distributed node."""
