"""What every ``dgse`` command shares: consoles, the error line, the exit status, crash logs.

Every error a user can cause (:class:`~dgse.errors.DGSEError`, or a file that
cannot be read or written) is printed as one red line ``error: <message>`` and
the command exits with status :data:`EXIT_USER_ERROR`; there is no traceback.
Anything else (a bug) prints one line naming the log file that holds the
traceback (:func:`write_crash_log`) and exits with :data:`EXIT_BUG`.
"""

from __future__ import annotations

import functools
import os
import sys
import tempfile
import traceback
from collections.abc import Callable
from datetime import datetime
from pathlib import Path
from typing import Any, TypeVar

import typer
from rich.console import Console
from rich.markup import escape
from rich.text import Text

from dgse.errors import DGSEError, InputDataError

#: Exit status of every user-caused error.
EXIT_USER_ERROR = 2
#: Exit status of an unexpected error (a bug; the traceback goes to a log file).
EXIT_BUG = 1
#: Exit status after Ctrl-C (128 + SIGINT, as shells report it).
EXIT_INTERRUPTED = 130
#: Environment variable naming the directory of crash logs.
LOG_DIR_ENV = "DGSE_LOG_DIR"

console = Console(highlight=False)
err_console = Console(stderr=True, highlight=False)

F = TypeVar("F", bound=Callable[..., Any])


def print_error(message: str) -> None:
    """``error: <message>`` in red on standard error, on one line."""
    err_console.print(
        Text("error: ", style="bold red") + Text(message.replace("\n", " "), style="red"),
        soft_wrap=True,
    )


def crash_log_dir() -> Path:
    """Where crash logs go: ``$DGSE_LOG_DIR``, else ``$XDG_STATE_HOME/dgse/logs`` (``~/.local/state``)."""
    env = os.environ.get(LOG_DIR_ENV)
    if env:
        return Path(env)
    state = os.environ.get("XDG_STATE_HOME") or str(Path.home() / ".local" / "state")
    return Path(state) / "dgse" / "logs"


def write_crash_log(exc: BaseException, argv: list[str] | None = None) -> Path:
    """Write the command line, versions and ``exc``'s traceback to a new log file; return its path.

    Falls back to the system's temporary directory when the log directory cannot be written.
    """
    from dgse import __version__

    stamp = datetime.now().strftime("%Y%m%d-%H%M%S")
    text = (
        f"dgse {__version__}, Python {sys.version.split()[0]}, {sys.platform}\n"
        f"command: dgse {' '.join(argv if argv is not None else sys.argv[1:])}\n"
        f"time: {datetime.now().isoformat(timespec='seconds')}\n\n"
        + "".join(traceback.format_exception(type(exc), exc, exc.__traceback__))
    )
    for d in (crash_log_dir(), Path(tempfile.gettempdir()) / "dgse-logs"):
        try:
            d.mkdir(parents=True, exist_ok=True)
            path = d / f"crash-{stamp}-{os.getpid()}.log"
            path.write_text(text, encoding="utf-8")
            return path
        except OSError:
            continue
    raise OSError("cannot write a crash log")


def report_bug(exc: BaseException, argv: list[str] | None = None) -> None:
    """One line on standard error for an unexpected error: what it was, where its traceback is."""
    what = f"{type(exc).__name__}: {exc}".strip().rstrip(":")
    try:
        where = f"the traceback is in {write_crash_log(exc, argv)}"
    except OSError:
        where = "no log file could be written"
    print_error(f"unexpected error ({what}); this is a bug in dgse: please report it; {where}")


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


def _writable_ancestor(path: Path, what: str) -> None:
    """Raise :class:`InputDataError` unless the nearest existing ancestor of ``path`` is a writable folder."""
    parent = path.absolute().parent
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir():
        raise InputDataError(f"{what} {path}: {parent} is a file, not a folder")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise InputDataError(f"{what} {path}: cannot write into {parent} (permission denied)")


def check_output_file(path: Path | None, what: str = "output file") -> None:
    """Check before any work that ``path`` (if given) can be written as a file.

    Raises:
        InputDataError: ``path`` is a folder, or its folder cannot be made or written.
    """
    if path is None:
        return
    path = Path(path)
    if path.is_dir():
        raise InputDataError(f"{what} {path} is a folder: give a file name")
    _writable_ancestor(path, what)
    if path.exists() and not os.access(path, os.W_OK):
        raise InputDataError(f"{what} {path}: cannot overwrite it (permission denied)")


def check_output_dir(path: Path | None, what: str = "output folder") -> None:
    """Check before any work that ``path`` (if given) is, or can be made as, a writable folder.

    Raises:
        InputDataError: ``path`` is a file, or cannot be made or written.
    """
    if path is None:
        return
    path = Path(path)
    if path.exists():
        if not path.is_dir():
            raise InputDataError(f"{what} {path} is a file, not a folder: give a folder (--out DIR)")
        if not os.access(path, os.W_OK | os.X_OK):
            raise InputDataError(f"{what} {path}: cannot write into it (permission denied)")
        return
    _writable_ancestor(path, what)


def path_text(path: Path | str) -> str:
    """A path escaped for rich markup."""
    return escape(str(path))
