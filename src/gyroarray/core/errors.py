"""The one exception type for bad user input.

Every problem with something the user gave (a file, a command-line value)
is raised as :class:`InputError`; the CLI prints ``str(err)`` as one line on
stderr and exits with code 2, never a traceback. ``str(err)`` is one line
whatever the file name or message holds (:func:`one_line`).
"""

from __future__ import annotations

import re

#: Control characters (C0, DEL, C1) and the Unicode line and paragraph separators.
_CONTROL = re.compile("[\x00-\x1f\x7f-\x9f\u2028\u2029]")


def one_line(text) -> str:
    """``text`` on one line: newlines, carriage returns and other control characters escaped
    as Python writes them in a string literal (``\\n``, ``\\r``, ``\\x1b`` ...)."""
    text = str(text)
    if not _CONTROL.search(text):
        return text
    return _CONTROL.sub(lambda m: repr(m.group(0))[1:-1], text)


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
    row : int, optional
        1-based data row in a file without lines (Parquet).
    """

    def __init__(self, message: str, file: str | None = None,
                 line: int | None = None, column: str | int | None = None,
                 row: int | None = None):
        self.message = message
        self.row = row
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
        if self.row is not None:
            where.append(f"row {self.row}")
        if self.column is not None:
            where.append(f"column {self.column}")
        prefix = ", ".join(where)
        return one_line(f"{prefix}: {self.message}" if prefix else self.message)

    def with_file(self, file) -> "InputError":
        """This error, located in ``file`` when it names no file yet (else itself unchanged).

        For a command that knows the user's file a deeper refusal came from
        (``except InputError as err: raise err.with_file(path) from None``).
        """
        if self.file is not None or file is None:
            return self
        return InputError(self.message, file=str(file), line=self.line, column=self.column,
                          row=self.row)
