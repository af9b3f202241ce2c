"""The command line of the benchmark scripts: ``python benchmarks/X.py COMMAND [ARGS]``."""

from __future__ import annotations

import argparse
from collections.abc import Callable, Mapping

__all__ = ["command_parser", "run_command"]


def command_parser(script: str, command: str, what: str) -> argparse.ArgumentParser:
    """The argument parser of ``python benchmarks/SCRIPT COMMAND``, described by ``what``
    (the script's module doc says more)."""
    return argparse.ArgumentParser(prog=f"{script} {command}", description=f"{what} ({script}'s module doc)")


def run_command(
    doc: str | None, commands: Mapping[str, Callable[[list[str]], object]], argv: list[str]
) -> None:
    """Run ``commands[argv[0]](argv[1:])``; without a known command print ``doc`` and the
    commands and exit (status 0 for ``-h``/``--help``, else 2)."""
    if not argv or argv[0] in ("-h", "--help") or argv[0] not in commands:
        print(doc)
        print(f"commands: {', '.join(commands)}")
        raise SystemExit(0 if argv and argv[0] in ("-h", "--help") else 2)
    commands[argv[0]](argv[1:])
