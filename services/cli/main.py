"""Entry point of the `prism` command: wires the sub-commands and the error policy.

Bad input exits with code 2 and one line on stderr, never a traceback.
"""

from __future__ import annotations

import sys

import typer
from typer.exceptions import TyperException

from prismcore import InputError

from .calibrate_command import calibrate
from .client import ApiError
from .client_commands import cancel, download, jobs, results, status, submit, wait
from .sample_command import sample
from .scan_command import scan
from .schema_command import schema
from .serve_command import serve

__all__ = ["app", "main"]

cli = typer.Typer(add_completion=False, no_args_is_help=True, pretty_exceptions_enable=False,
                  help="PrismCloud: measured 3D point clouds of box-shaped parts from photos.")
cli.command()(scan)
cli.command()(calibrate)
cli.command()(sample)
cli.command()(schema)
cli.command()(submit)
cli.command()(status)
cli.command()(wait)
cli.command()(download)
cli.command()(results)
cli.command()(jobs)
cli.command()(cancel)
cli.command()(serve)


def main(argv: list[str] | None = None) -> int:
    """Run the CLI; return the exit code (0 ok, 2 bad input or usage)."""
    try:
        cli(args=argv, standalone_mode=False)
    except (InputError, ApiError) as exc:
        print(f"prism: error: {exc}", file=sys.stderr)
        return 2
    except TyperException as exc:  # typer's own (vendored click) usage errors
        message = exc.format_message() if hasattr(exc, "format_message") else str(exc)
        if message:  # empty when the usage text was just shown
            print(f"prism: error: {message}", file=sys.stderr)
        return 2
    except typer.Abort:
        print("prism: aborted", file=sys.stderr)
        return 1
    except typer.Exit as exc:
        return exc.exit_code
    return 0


def app() -> None:
    """Console-script entry point."""
    sys.exit(main())
