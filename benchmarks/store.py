"""Job store benchmark: what a task about one item pays to read it, in a big job.

A worker task reads its item (and the job facts it needs) several times per item; reading the
whole record of a 5000-item job each time would cost more than scanning the photo. A client
polling a big job reads a page of its items (or none). Prints the whole-job read against the
one-item read and the pages, on a real redis-server, side by side.

Run: .venv/bin/python benchmarks/store.py [--items 5000] [--runs 20]
"""

from __future__ import annotations

import argparse
import tempfile
import time
import uuid
from datetime import UTC, datetime
from pathlib import Path

import redis
from prism_common.records import FrameRecord, ItemRecord, JobRecord, State
from prism_common.store import JobStore
from rich.console import Console
from rich.table import Table

from prism_cli.stack import start_redis
from prismcore.spec import ScanSpec

POINTS = [[395, 293], [943, 331], [919, 761], [943, 331], [1035, 298], [411, 647], [1009, 660]]


def _ms(fn, runs: int) -> float:
    fn()
    start = time.perf_counter()
    for _ in range(runs):
        fn()
    return (time.perf_counter() - start) / runs * 1000


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--items", type=int, default=5000)
    parser.add_argument("--runs", type=int, default=20)
    parser.add_argument("--video", action="store_true",
                        help="every item a video with one measured frame (frames: fields of their own)")
    args = parser.parse_args()
    server = start_redis(Path(tempfile.mkdtemp()))
    try:
        store = JobStore(redis.Redis(port=server.port, decode_responses=True))
        spec = ScanSpec(image="upload:" + "0" * 32, points=POINTS, focal_px=1400,
                        scale={"kind": "pinhole", "distance_mm": 279.1},
                        frames={"every": 10} if args.video else None)
        job = JobRecord(id=uuid.uuid4().hex, tenant="bench", created_at=datetime.now(UTC),
                        items=[ItemRecord(index=i, spec=spec) for i in range(args.items)])
        store.create(job)
        if args.video:
            for i in range(args.items):
                store.put_frame(job.id, i, FrameRecord(index=0, state=State.succeeded))
        whole = _ms(lambda: store.get(job.id), args.runs)
        one = _ms(lambda: store.get_item(job.id, args.items - 1), args.runs)
        pages = {n: _ms(lambda n=n: store.get_page(job.id, 0, n), args.runs) for n in (0, 100)}
    finally:
        server.stop()
    kind = "video " if args.video else ""
    table = Table(title=f"reading a {args.items}-item {kind}job (mean of {args.runs} runs)")
    for col in ("read", "ms"):
        table.add_column(col)
    table.add_row("the whole job (JobStore.get)", f"{whole:.2f}")
    table.add_row("one item and its job's facts (JobStore.get_item)", f"{one:.2f}")
    table.add_row("ratio whole / one item", f"{whole / one:.0f}x")
    for n, ms in pages.items():
        table.add_row(f"a poll's page of {n} items (JobStore.get_page)",
                      f"{ms:.2f}  ({whole / ms:.0f}x less)")
    Console().print(table)


if __name__ == "__main__":
    main()
