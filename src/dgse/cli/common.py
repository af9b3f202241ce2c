"""What every ``dgse`` command shares: consoles, the error line, the exit status, crash logs.

Every error a user can cause (:class:`~dgse.errors.DGSEError`, or a file that
cannot be read or written) is printed as one red line ``error: <message>`` and
the command exits with status :data:`EXIT_USER_ERROR`; there is no traceback.
Anything else (a bug) prints one line naming the log file that holds the
traceback (:func:`write_crash_log`) and exits with :data:`EXIT_BUG`.
"""

from __future__ import annotations

import contextlib
import functools
import json
import math
import os
import re
import shlex
import signal
import sys
import tempfile
import threading
import traceback
from collections.abc import Callable, Iterator, Sequence
from datetime import datetime
from pathlib import Path
from typing import Annotated, Any, TypeVar

import typer
from rich.console import Console
from rich.markup import escape
from rich.text import Text

from dgse.errors import DGSEError, InputDataError
from dgse.files import write_text

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
            write_text(path, text)
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


def parse_params(items: Sequence[str] | None, flag: str = "--param") -> dict[str, Any]:
    """``["K=3", "fusion.floor=0", "name=x"]`` -> ``{"K": 3, "fusion.floor": 0, "name": "x"}``
    (values JSON-decoded when they parse; ``inf`` and ``-inf`` are the floats, as options such
    as ``evidence.effective_readings=inf`` take them).  A dotted key sets one field of a
    settings object (:func:`dgse.options.check_options`).

    The one reading of ``-p/--param`` (estimator) and ``-P/--planner-option`` options in every command.

    Raises:
        InputDataError: an item without ``=`` or whose key is not a Python name (or dotted names).
    """
    out: dict[str, Any] = {}
    for item in items or ():
        key, sep, raw = item.partition("=")
        key = key.strip()
        if not sep or not all(part.isidentifier() for part in key.split(".")):
            raise InputDataError(
                f"{flag} needs KEY=VALUE with KEY a Python name (or dotted names), got {item!r}"
            )
        infinite = raw.strip().lower()
        if infinite in ("inf", "+inf", "-inf"):
            out[key] = -math.inf if infinite.startswith("-") else math.inf
            continue
        try:
            out[key] = json.loads(raw)
        except json.JSONDecodeError:
            out[key] = raw
    return out


#: ``--knowledge``: what an estimator is told besides its readings (dgse.belief.knowledge).
KNOWLEDGE_HELP = (
    "What the estimator is told besides the readings: map (occupancy only, the paper's setting), "
    "openings (plus the inlets and outlets), wind (plus the case's wind field and inlet speed, as from "
    "the user's own CFD). Recorded in the results."
)
KnowledgeOption = Annotated[str, typer.Option("--knowledge", metavar="LEVEL", help=KNOWLEDGE_HELP)]


#: Folder of the results of a command run without an output path.
OUTPUT_DIR = Path("dgse-out")


# -- long runs: default output, interruption, the command that resumes -------------------
def default_output(command: str, *names: str) -> Path:
    """``dgse-out/<command>-<name>-....json``, the names made safe for a file name."""
    parts = [re.sub(r"[^A-Za-z0-9._+-]+", "_", n).strip("._") or "x" for n in (command, *names)]
    return OUTPUT_DIR / ("-".join(parts) + ".json")


@contextlib.contextmanager
def sigterm_as_interrupt() -> Iterator[None]:
    """Within the block, SIGTERM (``kill``) raises ``KeyboardInterrupt`` as Ctrl-C does."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def interrupt(signum: int, frame: Any) -> None:
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, interrupt)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def _option_words(param: Any, value: Any) -> list[str]:
    if param.is_flag and param.secondary_opts:
        return [(param.opts if value else param.secondary_opts)[0]]
    name = next((o for o in param.opts if o.startswith("--")), param.opts[0])
    if param.is_flag:
        return [name] if value else []
    values = value if param.multiple else [value]
    return [w for v in values for w in (name, str(v))]


def resume_command(ctx: typer.Context, drop: Sequence[str] = ("restart",)) -> str:
    """The running command's line as a shell takes it: ``dgse <command>``, its arguments and
    every option that differs from its default (the options named in ``drop`` left out)."""
    words = ["dgse", *ctx.command_path.split()[1:]]
    options: list[str] = []
    for param in ctx.command.params:
        if param.name is None or param.name in drop or param.name not in ctx.params:
            continue
        value = ctx.params[param.name]
        if param.param_type_name == "argument":
            words += [str(v) for v in (value if isinstance(value, list | tuple) else [value])]
        elif param.param_type_name == "option" and value is not None and value != param.default:
            if getattr(param, "multiple", False) and not value:
                continue
            options += _option_words(param, value)
    return shlex.join(words + options)


def report_interrupt(kept: int, unit: str, where: Path, command: str) -> None:
    """One line on standard error after Ctrl-C: what was kept, where, how to resume."""
    plural = unit if kept == 1 else unit + "s"
    err_console.print(
        f"[yellow]interrupted: {kept} finished {plural} kept in {path_text(where)}; "
        f"resume with: {escape(command)}[/]",
        soft_wrap=True,
    )


def kept_note(journal: Path, unit: str, restart: bool) -> str:
    """The line that says where finished pieces are kept (and how many an earlier run left)."""
    from dgse.journal import count_records

    n = 0 if restart else count_records(journal)
    if n:
        return f"{n} finished {unit}{'s' * (n != 1)} of an earlier run in [cyan]{path_text(journal)}[/]"
    return f"finished {unit}s are kept in [cyan]{path_text(journal)}[/] as they finish"
