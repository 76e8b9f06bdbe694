"""The service on five hosts (network namespaces on this machine: API, two workers, Redis, the
object store; the test is a sixth, the client): a batch of jobs across them, then one fault at a
time with jobs streaming in, each audited for lost and duplicated jobs (client.audit). Run with
`scripts/test-cluster`. The figures of each fault are printed at the end ("cluster faults").
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import pytest
import redis

from .client import Api, Hooks, Load, Oracle, audit, item, png, scene, store_of, wait_final
from .cluster import HOOK_PORT, HOSTS, SETTINGS, Cluster
from .conftest import FAULT_LINES
from .netns import Network, cannot_make_namespaces, inside


@dataclass
class Ctx:
    cluster: Cluster
    net: Network
    api: Api
    hooks: Hooks
    items: list[dict]
    oracle: Oracle


# Issue 14 allows a skip only where the machine cannot make namespaces, that is without root.
# As root (CI) the test runs, and a root machine that cannot build the network fails it.
pytestmark = pytest.mark.skipif(os.geteuid() != 0, reason="network namespaces need root: "
                                "run scripts/test-cluster as root")


@pytest.fixture(scope="module")
def ctx(tmp_path_factory) -> Iterator[Ctx]:
    if (why := cannot_make_namespaces()) is not None:
        pytest.fail(why)
    net = Network(f"pcl{os.getpid()}", HOSTS)
    try:
        net.create()
        # The test is the client host from here to the end of the module: every socket it opens
        # (and every thread it starts) is in the client's namespace.
        with inside(net.ns("client")):
            cluster = Cluster(net, tmp_path_factory.mktemp("cluster"))
            hooks = api = None
            try:
                cluster.start()
                api = Api(cluster.api_url)
                hooks = Hooks(net.addr("client"), HOOK_PORT)
                # Scenes measured within 0.5 % of the true box here, under one grey level, a JPEG
                # re-encode and a 0.1 px shift, and with OpenCV's and numpy's AVX2/AVX-512 paths
                # off; scene 1 measured 54.9 mm for 60 with numpy 2.4 / OpenCV 5.1 (8.5 % off).
                scenes = [scene(5), scene(6)]
                photos = [png(s.image) for s in scenes]
                items = [item(api.upload(p), s) for p, s in zip(photos, scenes, strict=True)]
                yield Ctx(cluster, net, api, hooks, items, Oracle.of(items, photos))
            finally:
                if hooks is not None:
                    hooks.close()
                if api is not None:
                    api.http.close()
                cluster.stop()
    finally:
        net.remove()
    assert not net.leftovers()


def _run(ctx: Ctx, figures, name: str, inject: Callable[[], None], heal: Callable[[], None] | None,
         hold: float, *, after: float = 3.0) -> None:
    """Jobs stream in (one every 2.5 s, under what the two workers take here, so the recovery
    time is the fault's, not a backlog's); `inject` the fault once some are in flight, `hold` s
    later `heal` it (None: the fault is for good, e.g. a dead host, and ends when injected),
    keep submitting `after` s, then wait for every acknowledged job and audit them."""
    load = Load(ctx.api, f"{name}-{os.urandom(3).hex()}", ctx.items, ctx.cluster.hook_url,
                interval=2.5).start()
    try:
        # A submit may take as long as the client's patience for a busy or restarting API (Api.call
        # retries for 120 s), so wait that long for the first one, not a margin of our own.
        deadline = time.monotonic() + 180
        while (in_flight := sum(ctx.api.job(job_id)["state"] not in ("succeeded", "failed")
                                for job_id, _ in list(load.acked.values()))) < 1:
            if load.error is not None:  # a refused submit: say why, not "nothing in flight"
                raise load.error
            assert time.monotonic() < deadline, (
                f"no job in flight after 180 s ({len(load.acked)} acknowledged)\n" + ctx.cluster.logs())
            time.sleep(0.2)
        restarts = ctx.cluster.restarts
        inject()
        ended = time.monotonic()
        if heal is not None:
            time.sleep(hold)
            heal()
            ended = time.monotonic()
        else:
            time.sleep(hold)
        time.sleep(after)
    finally:
        load.stop()
    ids = [job_id for job_id, _ in load.acked.values()]
    final, seen = wait_final(ctx.api, ids, timeout=300)
    # Webhooks follow the final state; one whose delivery task a killed worker had taken comes
    # back when the broker hands the unacknowledged task out again, up to the visibility timeout
    # later (90 s here: it came after the 60 s this waited once, and was counted as never told).
    deadline = time.monotonic() + int(SETTINGS["VISIBILITY_TIMEOUT_S"]) + 30
    while any(j not in ctx.hooks.told for j in final) and time.monotonic() < deadline:
        time.sleep(0.5)
    client = redis.Redis(host=ctx.net.addr("redis"), port=6379, decode_responses=True, socket_timeout=10)
    result = audit(ctx.api, load, final, ctx.hooks, store_of(ctx.cluster.store_url), ctx.oracle, client)
    client.close()
    before = [job_id for job_id, at in load.acked.values() if at <= ended]
    recovery = max([seen[j] - ended for j in before if j in seen] + [0.0])
    took = sorted(seen[j] - at for j, at in load.acked.values() if j in seen) or [0.0]
    line = (f"{name}: jobs {result.jobs} ({in_flight} in flight at the fault), lost {len(result.lost)}, "
            f"duplicated {len(result.duplicated)}, failed {len(result.failed)}, recovery {recovery:.1f} s "
            f"(job time median {took[len(took) // 2]:.1f} s, slowest {took[-1]:.1f} s); "
            f"workers restarted by their supervisor {ctx.cluster.restarts - restarts}")
    FAULT_LINES.append(line)
    print("\n" + line)
    figures.update({"faults survived": 0 if result.problems else 1,
                    "jobs submitted": result.jobs, "jobs lost": len(result.lost),
                    "jobs duplicated": len(result.duplicated),
                    "jobs succeeded": result.jobs - len(result.failed) - len(result.lost)})
    assert in_flight > 0, "the fault met no job in flight"
    assert not result.problems, "\n".join(result.problems[:20]) + "\n" + ctx.cluster.logs()


def test_a_batch_runs_across_the_hosts(ctx, figures):
    load = Load(ctx.api, f"batch-{os.urandom(3).hex()}", ctx.items, ctx.cluster.hook_url, interval=0,
                count=16)
    load.start().stop(wait=True)
    ids = [job_id for job_id, _ in load.acked.values()]
    started = time.monotonic()
    final, _ = wait_final(ctx.api, ids, timeout=180)
    deadline = time.monotonic() + 60
    while any(j not in ctx.hooks.told for j in final) and time.monotonic() < deadline:
        time.sleep(0.5)
    client = redis.Redis(host=ctx.net.addr("redis"), port=6379, decode_responses=True)
    result = audit(ctx.api, load, final, ctx.hooks, store_of(ctx.cluster.store_url), ctx.oracle, client)
    client.close()
    line = (f"batch: jobs {result.jobs}, lost {len(result.lost)}, duplicated {len(result.duplicated)}, "
            f"failed {len(result.failed)}, all final {time.monotonic() - started:.1f} s after submits ended")
    FAULT_LINES.append(line)
    figures.update({"jobs submitted": result.jobs, "jobs succeeded": result.jobs - len(result.failed)})
    assert result.jobs >= 10 and not result.problems, "\n".join(result.problems[:20])
    for host, worker in ctx.cluster.workers.items():  # the work was shared by both hosts
        assert "succeeded in" in worker.log, f"{host} ran nothing:\n{worker.log[-2000:]}"


def test_a_worker_host_cut_off_for_30_s(ctx, figures):
    _run(ctx, figures, "worker host w1 link down 30 s", lambda: ctx.net.link("w1", up=False),
         lambda: ctx.net.link("w1", up=True), hold=30)


def test_the_store_unreachable_from_one_worker_host(ctx, figures):
    _run(ctx, figures, "store unreachable from w2 for 30 s (packets dropped)",
         lambda: ctx.net.drop_toward("w2", "store", dropped=True),
         lambda: ctx.net.drop_toward("w2", "store", dropped=False), hold=30)


def test_a_worker_host_killed(ctx, figures):
    worker = ctx.cluster.workers["w1"]
    ctx.cluster.down.add("w1")  # a dead host: its supervisor died with it
    try:
        _run(ctx, figures, "worker host w1 SIGKILLed (stays down)", worker.kill, None, hold=5)
    finally:
        ctx.cluster.start_worker("w1")
        ctx.cluster.down.discard("w1")


def test_the_redis_host_restarted(ctx, figures):
    def restart() -> None:
        ctx.cluster.start_redis()

    _run(ctx, figures, "redis-server SIGKILLed, back after 5 s (AOF everysec)",
         ctx.cluster.redis.kill, restart, hold=5)


def test_the_api_host_restarted(ctx, figures):
    _run(ctx, figures, "API SIGKILLed, back after 2 s", ctx.cluster.api.kill, ctx.cluster.start_api, hold=2)
