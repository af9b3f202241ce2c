"""What every ``dgse`` command shares: consoles, the error line, the exit status.

Every error a user can cause (:class:`~dgse.errors.DGSEError`, or a file that
cannot be read or written) is printed as one red line ``error: <message>`` and
the command exits with status :data:`EXIT_USER_ERROR`; there is no traceback.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import typer
from rich.console import Console
from rich.markup import escape
from rich.text import Text

from dgse.errors import DGSEError

#: Exit status of every user-caused error.
EXIT_USER_ERROR = 2

console = Console(highlight=False)
err_console = Console(stderr=True, highlight=False)

F = TypeVar("F", bound=Callable[..., Any])


def print_error(message: str) -> None:
    """``error: <message>`` in red on standard error, on one line."""
    err_console.print(
        Text("error: ", style="bold red") + Text(message.replace("\n", " "), style="red"),
        soft_wrap=True,
    )


def os_error_message(e: OSError) -> str:
    return f"{e.filename}: {e.strerror}" if e.filename and e.strerror else str(e)


def user_errors(fn: F) -> F:
    """Turn a user-caused error raised by a command into the error line and exit status 2."""

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except DGSEError as e:
            print_error(str(e))
            raise typer.Exit(EXIT_USER_ERROR) from None
        except OSError as e:
            print_error(os_error_message(e))
            raise typer.Exit(EXIT_USER_ERROR) from None

    return wrapper  # type: ignore[return-value]


def new_app(name: str, help: str) -> typer.Typer:
    """A typer app with the project's settings (no completion, ``-h``, no pretty tracebacks)."""
    return typer.Typer(
        name=name,
        help=help,
        no_args_is_help=True,
        add_completion=False,
        pretty_exceptions_enable=False,
        context_settings={"help_option_names": ["-h", "--help"]},
    )


def path_text(path: Path | str) -> str:
    """A path escaped for rich markup."""
    return escape(str(path))
