"""Errors and warnings of the toolpath readers: every message names the file, the line and the field."""

from __future__ import annotations

import warnings

from planner.errors import PlannerError


class InputFileError(PlannerError):
    """A toolpath file holds data the reader cannot use.

    The message always reads ``"<source> line <n>, <field>: <problem>"``, e.g.
    ``"part.apt line 12, field 3 of GOTO: 'x1.5' is not a number"``.

    Attributes
    ----------
    source : str
        Name of the file (or of the stream) being read.
    line : int or None
        1-based line number of the offending record (None for a whole-file problem).
    field : str
        Which field of the record is wrong, in words ("field 3 of GOTO", "word X", "column z", ...);
        empty when the record as a whole is wrong.
    problem : str
        What is wrong with it.
    """

    def __init__(self, source: str, line: int | None, field: str, problem: str):
        self.source = source
        self.line = line
        self.field = field
        self.problem = problem
        where = source if line is None else f"{source} line {line}"
        if field:
            where += f", {field}"
        super().__init__(f"{where}: {problem}")

    def __reduce__(self):
        return (type(self), (self.source, self.line, self.field, self.problem))


class ReaderWarning(UserWarning):
    """A reader's warning, self-contained on one line: ``"<file> line <n>: <what>"`` (``"<file>: <what>"``
    for the whole file).

    Front ends print ``str(warning)`` as it is (the CLI as ``warning: <message>``, grouping repeats); the
    Python API keeps them as Python warnings. Built with ``ReaderWarning(source, line, problem)`` (any
    newlines in ``problem`` are folded into blanks) or, like any warning, from one message string.

    Attributes
    ----------
    source : str or None
        Name of the file.
    line : int or None
        1-based line of the record (None for a whole-file remark).
    problem : str
        What was skipped or assumed.
    """

    def __init__(self, *args):
        if len(args) == 3:
            source, line, problem = args
            self.source, self.line, self.problem = source, line, " ".join(str(problem).split())
            where = str(source) if line is None else f"{source} line {line}"
            super().__init__(f"{where}: {self.problem}")
        else:
            self.source, self.line = None, None
            self.problem = " ".join(str(args[0]).split()) if args else ""
            super().__init__(self.problem)

    def __reduce__(self):
        if self.source is not None:
            return (type(self), (self.source, self.line, self.problem))
        return (type(self), (self.problem,))


class InputFileWarning(ReaderWarning):
    """A record was skipped or interpreted under an assumption; the message names file and line."""


class WarningLimiter:
    """Issue :class:`InputFileWarning` for the first few occurrences of each kind, then one summary.

    Unknown records can repeat thousands of times in a large file; each kind is reported at its first
    ``limit`` lines and :meth:`flush` reports how many more were skipped, so nothing is dropped
    silently and the warnings registry stays small.
    """

    def __init__(self, source: str, limit: int = 5):
        self.source = source
        self.limit = limit
        self._counts: dict[str, list[int]] = {}

    def warn(self, key: str, line: int | None, message: str) -> None:
        """Warn about ``key`` at ``line`` (the message is prefixed with the file and line)."""
        seen = self._counts.setdefault(key, [0, 0])
        seen[0] += 1
        if seen[0] <= self.limit:
            warnings.warn(InputFileWarning(self.source, line, message), stacklevel=4)
        else:
            seen[1] = line or 0

    def flush(self) -> None:
        """Summarise the occurrences beyond the limit, one warning per kind."""
        for key, (count, last) in self._counts.items():
            if count > self.limit:
                warnings.warn(
                    InputFileWarning(self.source, None, f"{count - self.limit} more {key} (last at line {last}) "
                                     "not listed"),
                    stacklevel=4,
                )
        self._counts.clear()
