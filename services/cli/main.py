"""Entry point of the `prism` command: wires the sub-commands and the error policy.

Bad input exits with code 2 and one line on stderr, never a traceback.
"""

from __future__ import annotations

import sys

import click
import typer

from prismcore import InputError

from .sample_command import sample
from .scan_command import scan
from .schema_command import schema

__all__ = ["app", "main"]

cli = typer.Typer(add_completion=False, no_args_is_help=True, pretty_exceptions_enable=False,
                  help="PrismCloud: measured 3D point clouds of box-shaped parts from photos.")
cli.command()(scan)
cli.command()(sample)
cli.command()(schema)


def main(argv: list[str] | None = None) -> int:
    """Run the CLI; return the exit code (0 ok, 2 bad input or usage)."""
    try:
        cli(args=argv, standalone_mode=False)
    except InputError as exc:
        print(f"prism: error: {exc}", file=sys.stderr)
        return 2
    except click.UsageError as exc:
        print(f"prism: error: {exc.format_message()}", file=sys.stderr)
        return 2
    except click.Abort:
        print("prism: aborted", file=sys.stderr)
        return 1
    except click.exceptions.Exit as exc:
        return exc.exit_code
    return 0


def app() -> None:
    """Console-script entry point."""
    sys.exit(main())
