"""A sweep's results file: every finished job appended as one JSON line, so an interrupted sweep can resume.

Each line is ``{"function": ..., "key": ..., "result": ...}``: the job's function (its qualified
name), the job itself as text (``repr`` of the item: an :class:`~safenav.experiments.EpisodeSpec`,
a benchmark's job dataclass; readable, and the same for the same job in every run), and the
result, pickled and base64-encoded (results such as :class:`~safenav.experiments.EpisodeOutcome`
hold numpy arrays and worlds; a pickle brings them back bit for bit, so a resumed sweep's tables
equal an uninterrupted one's). Lines are written and flushed as jobs finish: a sweep stopped
by Ctrl-C, a killed process or a lost Ray node loses only the jobs that were running.

The file is for resuming, not for exchange (the benchmarks' ``--json`` is): it loads with
:mod:`pickle`, so resume only from files you wrote yourself.
"""

from __future__ import annotations

import base64
import json
import os
import pickle
from collections.abc import Callable
from pathlib import Path
from typing import IO, Any

from safenav.errors import InvalidConfig

__all__ = ["ResultsFile", "job_name"]


def job_name(function: Callable[..., Any]) -> str:
    """The name a results file knows a function by: its qualified name (``run_spec``, ``abs``).

    Not the module: the same benchmark run as ``python -m benchmarks.NAME`` (``__main__``) and as
    ``safenav bench`` (``benchmarks.NAME``) must find its own results.
    """
    return getattr(function, "__qualname__", None) or type(function).__qualname__


class ResultsFile:
    """The finished jobs of a sweep, read from and appended to one JSON-lines file.

    Args:
        path: the file.
        resume: continue the file: its results are reused. Without it, a file that already holds
            results is an error (a new sweep must not mix with an old one, nor overwrite it).

    Raises:
        InvalidConfig: the file holds results and ``resume`` is not set, or a line (other than a
            last one cut short by an interrupted write) is not a results line.
    """

    def __init__(self, path: str | os.PathLike[str], *, resume: bool = False) -> None:
        self.path = Path(path)
        self._done: dict[tuple[str, str], Any] = {}
        self._handle: IO[str] | None = None
        if self.path.exists() and self.path.stat().st_size > 0:
            if not resume:
                raise InvalidConfig(f"results file {str(self.path)!r} already holds results; expected a new file, or "
                                    "resume=True (--resume) to continue that sweep")
            self._load()

    def __len__(self) -> int:
        return len(self._done)

    def _load(self) -> None:
        data = self.path.read_bytes()
        complete = data.rfind(b"\n") + 1
        if complete < len(data):   # the last write was cut short: that job did not finish
            with self.path.open("r+b") as handle:
                handle.truncate(complete)
        for number, line in enumerate(data[:complete].decode("utf-8").splitlines(), start=1):
            try:
                entry = json.loads(line)
                result = pickle.loads(base64.b64decode(entry["result"]))
                self._done[(entry["function"], entry["key"])] = result
            except (ValueError, KeyError, TypeError, pickle.UnpicklingError, AttributeError, ImportError) as error:
                raise InvalidConfig(f"line {number} of results file {str(self.path)!r} is not a results line "
                                    f"({type(error).__name__}: {error}); expected the file a sweep wrote") from None

    def get(self, function: str, key: str, default: Any = None) -> Any:
        """The stored result of the job ``key`` of ``function`` (see :func:`job_name`), or ``default``."""
        return self._done.get((function, key), default)

    def add(self, function: str, key: str, result: Any) -> None:
        """Append one finished job and flush it to the file."""
        if self._handle is None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._handle = self.path.open("a", encoding="utf-8")
        line = {"function": function, "key": key,
                "result": base64.b64encode(pickle.dumps(result, protocol=pickle.HIGHEST_PROTOCOL)).decode("ascii")}
        self._handle.write(json.dumps(line) + "\n")
        self._handle.flush()
        self._done[(function, key)] = result

    def close(self) -> None:
        """Close the file (it is reopened by the next :meth:`add`)."""
        if self._handle is not None:
            self._handle.close()
            self._handle = None
