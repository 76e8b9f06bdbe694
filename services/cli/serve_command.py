"""`prism serve`: the whole service on this machine, no external servers to set up.

redis-server (job records and queue, append-only file on), SeaweedFS (S3 object storage),
Celery workers and the API, all bound to 127.0.0.1, with their data under one folder.
Keys and secrets are generated on first start and kept in DATA_DIR/credentials.json.
"""

from __future__ import annotations

import base64
import json
import os
import shlex
import shutil
import signal
import sys
import threading
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from prismcore.errors import InputError

if TYPE_CHECKING:
    from .stack import ManagedProcess

# .stack (sockets, the HTTP client) and secrets are imported when serve runs, not for every prism.

__all__ = ["ready_line", "serve", "try_line"]

DEFAULT_PORT = 8000  # the client commands' default API URL is on this port
# The sample photo's seven points (prism scan's README example): with P6 and P7 the perspective
# is fitted, so the result is the box's size within its printed ± (five points are not).
SAMPLE_POINTS = "395,293 943,331 919,761 943,331 1035,298 411,647 1009,660"


def _credentials(data_dir: Path) -> dict[str, str]:
    path = data_dir / "credentials.json"
    if path.exists():
        saved: dict[str, str] = json.loads(path.read_text())
        return saved
    import secrets

    creds = {"api_key": "k-" + secrets.token_urlsafe(24),
             # The Standard Webhooks form, which receivers' verifiers take as it is.
             "webhook_secret": "whsec_" + base64.b64encode(secrets.token_bytes(32)).decode(),
             "s3_key_id": "prism-" + secrets.token_hex(6), "s3_secret": secrets.token_urlsafe(32)}
    data_dir.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(creds, indent=2))
    path.chmod(0o600)
    return creds


def _s3_port(data_dir: Path) -> int:
    """The object store's port, the same across restarts: download links handed out before a
    restart are signed for it and must keep working for their lifetime."""
    from .stack import free_port, port_is_free

    path = data_dir / "ports.json"
    kept = json.loads(path.read_text()).get("s3") if path.exists() else None
    if isinstance(kept, int) and port_is_free(kept):
        return kept
    port = free_port()
    path.write_text(json.dumps({"s3": port}))
    return port


def _prism_command() -> str:
    """How a shell runs this very prism: `prism` when that name on PATH is it, else its path."""
    script = Path(sys.executable).parent / "prism"
    if not script.is_file():
        return f"{shlex.quote(sys.executable)} -m prism_cli"
    found = shutil.which("prism")
    if found is not None and Path(found).resolve() == script.resolve():
        return "prism"
    return shlex.quote(str(script))


def _sample_photo() -> Path | None:
    """samples/box.jpg of the source tree prism runs from (absent from a plain install)."""
    photo = Path(__file__).resolve().parents[2] / "samples" / "box.jpg"
    return photo if photo.is_file() else None


def ready_line(port: int) -> str:
    """The banner's first line (rich markup): the API and its docs, and the page a person opens
    (tests/test_docs.py waits for its "ready: API")."""
    base = f"http://127.0.0.1:{port}"
    return (f"[bold green]ready[/]: API {base} (docs at /docs); the page: {base}/app/ "
            "(log in with the API key below)")


def try_line(port: int, key: str | None, *, prism: str | None = None,
             photo: Path | None = None) -> str:
    """One command a user can paste into another shell, anywhere, as printed: the full path of
    prism when `prism` on PATH is not this one, PRISM_API_URL when the port is not the client's
    default, the key (None: PRISM_API_KEYS holds the keys, the user's shell has one) and the
    sample photo by its full path (a plain install has none: `prism sample` renders one)."""
    prism = prism or _prism_command()
    env = []
    if port != DEFAULT_PORT:
        env.append(f"PRISM_API_URL=http://127.0.0.1:{port}")
    if key is not None:
        env.append(f"PRISM_API_KEY={shlex.quote(key)}")
    submit = " ".join([*env, prism, "submit"])
    if photo is None:
        return (f"{prism} sample --out prism-sample && {submit} --spec prism-sample/job.json --wait")
    return f"{submit} {shlex.quote(str(photo))} --points '{SAMPLE_POINTS}' --width-mm 120 --wait"


def stack_env(creds: dict[str, str], redis_port: int, s3_port: int) -> dict[str, str]:
    """The PRISM_* environment the API and the workers of a local stack share."""
    return {
        "PRISM_API_KEYS": os.environ.get("PRISM_API_KEYS") or json.dumps({"local": creds["api_key"]}),
        "PRISM_WEBHOOK_SECRET": os.environ.get("PRISM_WEBHOOK_SECRET") or creds["webhook_secret"],
        "PRISM_REDIS_URL": f"redis://127.0.0.1:{redis_port}/0",
        "PRISM_S3_ENDPOINT_URL": f"http://127.0.0.1:{s3_port}",
        "PRISM_S3_ACCESS_KEY_ID": creds["s3_key_id"],
        "PRISM_S3_SECRET_ACCESS_KEY": creds["s3_secret"],
    }


def serve(
    data_dir: Annotated[Path, typer.Option(help="Where jobs, objects and keys are kept.",
                                           envvar="PRISM_SERVE_DATA_DIR")] = Path(".prism"),
    port: Annotated[int, typer.Option(help="API port on 127.0.0.1.",
                                      envvar="PRISM_SERVE_PORT")] = DEFAULT_PORT,
    workers: Annotated[int, typer.Option(help="Worker processes.", min=1)] = 2,
) -> None:
    """Run the API, workers, Redis and S3 storage locally until Ctrl-C."""
    from rich.console import Console

    from .stack import port_is_free, start_api, start_redis, start_s3, start_worker

    console = Console()
    if not port_is_free(port):
        # Checked first: the health check would otherwise reach whatever holds the port and
        # report this stack ready before its own API died on the bind.
        raise InputError(f"port {port} on 127.0.0.1 is taken (another prism serve?): stop it "
                         "or pass --port")
    data_dir = data_dir.resolve()
    creds = _credentials(data_dir)
    started: list[ManagedProcess] = []
    try:
        with console.status("starting redis-server and SeaweedFS ..."):
            redis = start_redis(data_dir / "redis")
            started.append(redis)
            s3 = start_s3(data_dir / "s3", creds["s3_key_id"], creds["s3_secret"],
                          port=_s3_port(data_dir))
            started.append(s3)
        env = stack_env(creds, redis.port, s3.port)  # type: ignore[arg-type]
        with console.status("starting the workers and the API ..."):
            started.append(start_worker(data_dir / "worker", env, concurrency=workers))
            started.append(start_api(data_dir / "api", env, port=port))
        own_key = "PRISM_API_KEYS" not in os.environ
        key = creds["api_key"] if own_key else "(from PRISM_API_KEYS)"
        hint = try_line(port, creds["api_key"] if own_key else None, photo=_sample_photo())
        console.print(ready_line(port), soft_wrap=True)
        # As printed, with no markup read into it: a path may hold brackets.
        console.print(f"  API key: {key}\n  try: {hint}\n"
                      + ("" if own_key else "       (with PRISM_API_KEY set to one of PRISM_API_KEYS)\n")
                      + f"  logs and data: {data_dir}   (Ctrl-C stops everything)",
                      soft_wrap=True, markup=False, highlight=False)
        stop = threading.Event()
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, lambda *_: stop.set())
        while not stop.wait(1.0):
            dead = [p for p in started if p.proc is not None and p.proc.poll() is not None]
            if dead:
                console.print(f"[red]{dead[0].argv[0]} stopped; see {dead[0].workdir}/server.log")
                raise typer.Exit(1)
    finally:
        for proc in reversed(started):
            proc.stop()
    console.print("stopped")
