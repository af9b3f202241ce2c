"""What every ``dgse`` command shares: consoles, the error line, the exit status, crash logs.

Every error a user can cause (:class:`~dgse.errors.DGSEError`, a file that
cannot be read or written, or a command line that does not parse) is printed
as one red line ``error: <message>`` and the command exits with status
:data:`EXIT_USER_ERROR`; there is no traceback.  A message that names a
Python argument names the command's option instead (:func:`error_message`).
Anything else (a bug) prints one line naming the log file that holds the
traceback (:func:`write_crash_log`) and exits with :data:`EXIT_BUG`.

Ctrl-C (or SIGTERM inside :func:`interruptible`) ends every command with one
yellow line, ``interrupted: <what was kept and how to resume>``, and status
:data:`EXIT_INTERRUPTED` (:func:`user_errors`, :func:`interruptible`).

Help is click's plain text, wrapped to the terminal and never cut
(:class:`HelpGroup` lists each command's whole summary).
"""

from __future__ import annotations

import contextlib
import functools
import inspect
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
from typer.core import TyperGroup

from dgse.errors import DGSEError, InputDataError
from dgse.files import write_text

try:  # the copy of click that recent typer releases carry
    from typer._click import exceptions as _click_exceptions
    from typer._click import globals as _click_globals
    from typer._click import types as _click_types
except ImportError:  # older typer runs on the click package
    from click import exceptions as _click_exceptions  # type: ignore[no-redef]
    from click import globals as _click_globals  # type: ignore[no-redef]
    from click import types as _click_types  # type: ignore[no-redef]

#: click's errors of a command line that does not parse, and of the help a bare group shows.
UsageError = _click_exceptions.UsageError
ClickException = _click_exceptions.ClickException
NoArgsIsHelpError: type[Exception] | None = getattr(_click_exceptions, "NoArgsIsHelpError", None)

#: The value type of a repeatable option of three words ``SIDE START END`` (an opening):
#: typer cannot declare a list of tuples, so such an option is ``list[tuple]`` with this
#: ``click_type`` and each use of it gives one ``(str, float, float)``.
OPENING_ARGS = _click_types.Tuple([str, float, float])

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


#: A file written under a temporary name beside its target and renamed over it:
#: ``x.npz.part``, ``x.npz.<pid>.<thread>.part``, ``x.journal.jsonl.tmp``.
_TEMPORARY = re.compile(r"^(?P<target>.+?)(?:\.\d+\.\d+)?\.(?:part|tmp)$")


def os_error_message(e: OSError) -> str:
    """``<file>: <reason>``; a temporary file that stands for a target is named as that target."""
    if not (e.filename and e.strerror):
        return str(e)
    name = str(e.filename)
    m = _TEMPORARY.match(name)
    if m:
        return f"cannot write {m.group('target')}: {e.strerror}"
    return f"{name}: {e.strerror}"


def option_spellings(command: Any) -> dict[str, str]:
    """Each option of a click ``command`` by how the command line spells it: ``{"restart": "--restart"}``."""
    out: dict[str, str] = {}
    for p in command.params:
        if p.param_type_name == "option" and p.name:
            longs = [o for o in p.opts if o.startswith("--")]
            out[p.name] = (longs or p.opts)[0]
    return out


def error_message(e: DGSEError) -> str:
    """``e``'s message, the arguments it names spelled as the running command's options.

    A library message such as ``start afresh with restart=True`` reads ``start afresh
    with --restart`` in ``dgse search`` (:meth:`~dgse.errors.DGSEError.spelled`; the
    command's parameter must carry the library argument's name).
    """
    ctx = _click_globals.get_current_context(silent=True)
    if ctx is None or not e.names:
        return str(e)
    return e.spelled(option_spellings(ctx.command))


def usage_error_message(e: Any) -> str:
    """A command line that does not parse, on one line, with where its options are listed."""
    message = " ".join(e.format_message().split()).rstrip(".")
    if e.ctx is not None:
        message += f" (see {e.ctx.command_path} --help)"
    return message


# -- Ctrl-C ------------------------------------------------------------------------------
#: What a command that keeps nothing says after Ctrl-C.
NOTHING_KEPT = "nothing was kept; run the command again to start over"


def print_interrupted(note: str) -> None:
    """One yellow line on standard error after Ctrl-C: ``interrupted: <note>``."""
    err_console.print(Text(f"interrupted: {' '.join(note.split())}", style="yellow"), soft_wrap=True)


def resume_note(kept: int, unit: str, where: Path | str, command: str) -> str:
    """``3 finished episodes kept in out.journal.jsonl; resume with: dgse search ...``."""
    plural = unit if kept == 1 else unit + "s"
    return f"{kept} finished {plural} kept in {where}; resume with: {command}"


@contextlib.contextmanager
def interruptible(note: Callable[[], str], sigterm: bool = True) -> Iterator[None]:
    """Within the block Ctrl-C (and SIGTERM, ``kill``, when ``sigterm``) ends the command: the
    line ``interrupted: <note()>`` (what was kept, how to resume) and exit status 130."""
    try:
        with sigterm_as_interrupt() if sigterm else contextlib.nullcontext():
            yield
    except KeyboardInterrupt:
        print_interrupted(note())
        raise typer.Exit(EXIT_INTERRUPTED) from None


def user_errors(fn: F) -> F:
    """The one rule of every command: a user-caused error is the error line and exit status 2;
    Ctrl-C outside :func:`interruptible` is the line :data:`NOTHING_KEPT` and exit status 130."""

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except DGSEError as e:
            print_error(error_message(e))
            raise typer.Exit(EXIT_USER_ERROR) from None
        except OSError as e:
            print_error(os_error_message(e))
            raise typer.Exit(EXIT_USER_ERROR) from None
        except KeyboardInterrupt:
            print_interrupted(NOTHING_KEPT)
            raise typer.Exit(EXIT_INTERRUPTED) from None

    wrapper.user_errors = True  # type: ignore[attr-defined]
    return wrapper  # type: ignore[return-value]


# -- help ----------------------------------------------------------------------------------
def command_summary(command: Any) -> str:
    """A command's line in its group's help: its ``short_help``, else its help's first paragraph."""
    if command.short_help:
        return command.short_help
    text = inspect.cleandoc(command.help or "")
    return " ".join(text.split("\n\n", 1)[0].split())


class HelpGroup(TyperGroup):
    """A command group whose help lists every command's whole summary, wrapped, never cut."""

    def format_commands(self, ctx: Any, formatter: Any) -> None:
        rows = []
        for name in self.list_commands(ctx):
            command = self.get_command(ctx, name)
            if command is not None and not command.hidden:
                rows.append((name, command_summary(command)))
        if rows:
            with formatter.section("Commands"):
                formatter.write_dl(rows)


def new_app(name: str, help: str) -> typer.Typer:
    """A typer app with the project's settings: no completion, ``-h``, no pretty tracebacks,
    plain help (click's: wrapped to the terminal, where rich's panels cut long names)."""
    return typer.Typer(
        name=name,
        help=help,
        cls=HelpGroup,
        no_args_is_help=True,
        add_completion=False,
        pretty_exceptions_enable=False,
        rich_markup_mode=None,
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
#: ``-p/--param KEY=VALUE`` (repeatable): estimator options, read by :func:`parse_params`.
ParamOption = Annotated[
    list[str] | None,
    typer.Option(
        "--param",
        "-p",
        metavar="KEY=VALUE",
        help="Estimator argument KEY=VALUE (VALUE as JSON, else a string); repeatable.",
    ),
]
#: ``--threads N``: PyTorch's CPU threads (None: PyTorch's default).
THREADS_HELP = "PyTorch CPU threads (1 is often fastest on busy, shared cores)."
ThreadsOption = Annotated[int | None, typer.Option("--threads", help=THREADS_HELP)]
#: ``--progress/--no-progress``: a progress bar while the command works.
ProgressOption = Annotated[bool, typer.Option("--progress/--no-progress", help="Show a progress bar.")]
#: ``--engine/-e``: the physics engine that solves flow and gas (a registered name).
EngineOption = Annotated[str, typer.Option("--engine", "-e", help="Physics engine (see `dgse engines`).")]
#: ``--method/-m``: a named method (:mod:`dgse.presets`) or a registered estimator (None: the
#: default method of the knowledge level).
MethodOption = Annotated[
    str | None,
    typer.Option(
        "--method",
        "-m",
        help="Method (default: dgse-phys): a named method runs its estimator and planner with "
        "the options it was measured with; any registered estimator runs with its defaults.",
    ),
]
#: The search protocol's options (:data:`dgse.presets.PROTOCOL` gives the defaults): the
#: simulated robot of ``dgse search``, ``dgse demo`` and ``dgse ros sim`` and the node of
#: ``dgse ros run`` read them alike.
SpeedOption = Annotated[float, typer.Option("--speed", help="Robot speed, m/s.")]
DwellOption = Annotated[float, typer.Option("--dwell", help="Time at a goal for one reading, s.")]
TimeLimitOption = Annotated[float, typer.Option("--time-limit", help="Time limit of a search, s.")]
MinStartDistanceOption = Annotated[
    float,
    typer.Option(
        "--min-start-distance",
        help="Least path length from a drawn start to the source, m (a start inside the "
        "2 m success radius would make a trial trivial).",
    ),
]
FramesOption = Annotated[
    bool, typer.Option("--frames/--steady", help="Read a case's time-varying frames when it has them.")
]
SampleRateOption = Annotated[
    float | None,
    typer.Option(
        "--sample-rate",
        metavar="HZ",
        help="Also read every 1/HZ s while driving to a goal (default: only at the goals, as the paper).",
    ),
]


def option_bundle(name: str, bundle: Callable[..., Any]) -> Callable[[F], F]:
    """Give a command the options of ``bundle`` in place of its parameter ``name``.

    ``bundle`` (a function or a dataclass) declares options that several commands share, once:
    its parameters (typer-annotated, each with a default) stand on the command line where
    ``name`` stands in the command's signature, and the command receives ``bundle(**those
    options)`` as ``name``.
    """
    bundled = list(inspect.signature(bundle, eval_str=True).parameters.values())

    def decorate(fn: F) -> F:
        sig = inspect.signature(fn, eval_str=True)
        if name not in sig.parameters:
            raise TypeError(f"{fn.__name__} has no parameter {name!r}")
        params = [q for p in sig.parameters.values() for q in (bundled if p.name == name else [p])]

        @functools.wraps(fn)
        def wrapper(*args: Any, **kwargs: Any) -> Any:
            kwargs[name] = bundle(**{p.name: kwargs.pop(p.name, p.default) for p in bundled})
            return fn(*args, **kwargs)

        wrapper.__signature__ = sig.replace(parameters=params)  # type: ignore[attr-defined]
        return wrapper  # type: ignore[return-value]

    return decorate


def journal_output(what: str, default: str, kept: str) -> Any:
    """The ``-o/--out/--json`` option of a command that keeps its finished ``kept`` (say,
    ``"episodes"``) in a journal beside its JSON file of ``what`` (default path ``default``)."""
    return typer.Option(
        "--out",
        "-o",
        "--json",
        help=f"{what} as JSON (default: {default}).  Finished {kept} are kept as they finish in "
        "<name>.journal.jsonl beside it; the same command again resumes an interrupted run.",
    )


def restart_option(kept: str) -> Any:
    """The ``--restart`` option of a command that keeps its finished ``kept`` in a journal."""
    return typer.Option("--restart", help=f"Discard the {kept} kept from an earlier run into the same file.")


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
    words: list[str] = []
    for v in values:  # an option of several values (``--size MIN MAX``) takes them as words
        words += [name, *(str(x) for x in (v if isinstance(v, list | tuple) else [v]))]
    return words


def resume_command(ctx: typer.Context, drop: Sequence[str] = ("restart",), add: Sequence[str] = ()) -> str:
    """The running command's line as a shell takes it: ``dgse <command>``, its arguments and
    every option that differs from its default (the options named in ``drop`` left out, the
    words of ``add`` appended)."""
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
    return shlex.join(words + options + list(add))


def kept_note(journal: Path, unit: str, n: int) -> str:
    """The line that says where finished pieces are kept (and how many, ``n``, an earlier run left)."""
    if n:
        return f"{n} finished {unit}{'s' * (n != 1)} of an earlier run in [cyan]{path_text(journal)}[/]"
    return f"finished {unit}s are kept in [cyan]{path_text(journal)}[/] as they finish"
