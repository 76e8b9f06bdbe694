"""`prism serve`: the whole service on this machine, no external servers to set up.

redis-server (job records and queue, append-only file on), SeaweedFS (S3 object storage),
Celery workers and the API, all bound to 127.0.0.1, with their data under one folder.
Keys and secrets are generated on first start and kept in DATA_DIR/credentials.json.
"""

from __future__ import annotations

import base64
import json
import os
import secrets
import signal
import threading
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console

from prismcore import InputError

from .stack import ManagedProcess, free_port, port_is_free, start_api, start_redis, start_s3, start_worker

__all__ = ["serve"]


def _credentials(data_dir: Path) -> dict[str, str]:
    path = data_dir / "credentials.json"
    if path.exists():
        saved: dict[str, str] = json.loads(path.read_text())
        return saved
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
    path = data_dir / "ports.json"
    kept = json.loads(path.read_text()).get("s3") if path.exists() else None
    if isinstance(kept, int) and port_is_free(kept):
        return kept
    port = free_port()
    path.write_text(json.dumps({"s3": port}))
    return port


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
    port: Annotated[int, typer.Option(help="API port on 127.0.0.1.", envvar="PRISM_SERVE_PORT")] = 8000,
    workers: Annotated[int, typer.Option(help="Worker processes.", min=1)] = 2,
) -> None:
    """Run the API, workers, Redis and S3 storage locally until Ctrl-C."""
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
        key = creds["api_key"] if "PRISM_API_KEYS" not in os.environ else "(from PRISM_API_KEYS)"
        console.print(f"[bold green]ready[/]: API http://127.0.0.1:{port} (docs at /docs)\n"
                      f"  API key: {key}\n"
                      f"  try: PRISM_API_KEY={key} prism submit samples/box.jpg --points "
                      f"'395,293 943,331 919,761 943,331 1035,298' --width-mm 120 --wait\n"
                      f"  logs and data: {data_dir}   (Ctrl-C stops everything)", soft_wrap=True)
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
