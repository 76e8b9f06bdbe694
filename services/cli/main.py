"""Entry point of the `prism` command: wires the sub-commands and the error policy.

Exit codes: 0 the command succeeded (a job waited for: every item of it); 1 it ran but what
it waited for did not succeed (a job that failed, was cancelled or completed_with_failures:
some item failed while others succeeded; a wait that timed out, `prism serve` losing a server, a station
`prism station verify` found not verified, Ctrl-C);
2 bad input or usage, or an API that refused the request (4xx); 3 the API could not be reached
or could not answer (5xx, or still busy after the retries): the request may be right, try again
later. One line on stderr, never a traceback.
"""

from __future__ import annotations

import sys

import typer
from typer.exceptions import TyperException

from prismcore import InputError

from .calibrate_command import calibrate
from .client_commands import (
    cancel,
    download,
    jobs,
    results,
    station_delete,
    station_list,
    station_upload,
    status,
    submit,
    wait,
)
from .errors import ApiError, WaitTimeoutError
from .sample_command import sample
from .scan_command import scan
from .schema_command import schema
from .serve_command import serve
from .station_command import board, station_app
from .station_verify import verify

__all__ = ["app", "main"]

# Plain click help (rich_markup_mode=None): typer's rich help imports rich's markdown, syntax and
# traceback modules, ~70 ms of CPU that `prism --help` (<= 200 ms) cannot afford.
cli = typer.Typer(add_completion=False, no_args_is_help=True, pretty_exceptions_enable=False,
                  rich_markup_mode=None,
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
cli.command()(board)
station_app.command("upload")(station_upload)
station_app.command("list")(station_list)
station_app.command("delete")(station_delete)
station_app.command("verify")(verify)
cli.add_typer(station_app, name="station")


def main(argv: list[str] | None = None) -> int:
    """Run the CLI; return the exit code (0 ok, 1 failed or cancelled, 2 bad input or usage,
    3 the API unreachable or failing)."""
    try:
        # Not standalone: click then *returns* the code of a `typer.Exit` (a failed job's 1,
        # --help's 0) instead of exiting, and raises its usage errors for the one-line policy.
        code = cli(args=argv, standalone_mode=False)
    except WaitTimeoutError as exc:  # the job may still succeed; this wait did not see it
        print(f"prism: error: {exc}", file=sys.stderr)
        return 1
    except ApiError as exc:
        print(f"prism: error: {exc}", file=sys.stderr)
        return 3 if exc.unavailable else 2
    except InputError as exc:
        print(f"prism: error: {exc}", file=sys.stderr)
        return 2
    except TyperException as exc:  # typer's own (vendored click) usage errors
        message = exc.format_message() if hasattr(exc, "format_message") else str(exc)
        if message:  # empty when the usage text was just shown
            print(f"prism: error: {message}", file=sys.stderr)
        return 2
    except OSError as exc:  # a file named on the command line that cannot be read or written
        where = f" {str(exc.filename)!r}" if exc.filename else ""
        print(f"prism: error: {exc.strerror or exc}{where}", file=sys.stderr)
        return 2
    except typer.Abort:
        print("prism: aborted", file=sys.stderr)
        return 1
    # The commands return None; an int is the code of a typer.Exit raised inside one.
    return code if isinstance(code, int) else 0


def app() -> None:
    """Console-script entry point."""
    sys.exit(main())
