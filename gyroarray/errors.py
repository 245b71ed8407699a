"""The one exception type for bad user input.

Every problem with something the user gave (a file, a command-line value)
is raised as :class:`InputError`; the CLI prints ``str(err)`` as one line on
stderr and exits with code 2, never a traceback.
"""

from __future__ import annotations


class InputError(ValueError):
    """Bad user input, located as precisely as possible.

    Parameters
    ----------
    message : str
        What is wrong, in words a user understands.
    file : str, optional
        The file the problem is in (as the user named it).
    line : int, optional
        1-based line number in that file.
    column : str or int, optional
        Column name (CSV) or 1-based column number, or a TOML key path.
    """

    def __init__(self, message: str, file: str | None = None,
                 line: int | None = None, column: str | int | None = None):
        self.message = message
        self.file = None if file is None else str(file)
        self.line = line
        self.column = column
        super().__init__(self.__str__())

    def __str__(self) -> str:
        where = []
        if self.file is not None:
            where.append(self.file)
        if self.line is not None:
            where.append(f"line {self.line}")
        if self.column is not None:
            where.append(f"column {self.column}")
        prefix = ", ".join(where)
        return f"{prefix}: {self.message}" if prefix else self.message
