"""The service's Prometheus metrics, read from Redis when scraped (there is no state in the API).

Jobs and task durations are written by every API and worker process into Redis, so one scrape
of any API process sees the whole service.
"""

from __future__ import annotations

from collections.abc import Iterator

import redis
from prism_common.metrics import BUCKETS_S, read_task_durations
from prism_common.queue import QUEUE_FRAMES, QUEUE_SCANS, QUEUE_WEBHOOKS, queue_depth
from prism_common.store import JobStore
from prometheus_client import CollectorRegistry, generate_latest
from prometheus_client.core import GaugeMetricFamily, HistogramMetricFamily, Metric
from prometheus_client.registry import Collector
from prometheus_client.utils import floatToGoString

__all__ = ["ServiceCollector", "render_metrics"]

class ServiceCollector(Collector):
    def __init__(self, store: JobStore, client: redis.Redis) -> None:
        self._store, self._client = store, client

    def collect(self) -> Iterator[Metric]:
        jobs = GaugeMetricFamily("prism_jobs", "Jobs by state.", labels=["state"])
        for state, count in self._store.count_by_state().items():
            jobs.add_metric([state], count)
        yield jobs

        depth = GaugeMetricFamily("prism_queue_depth", "Tasks waiting in a Celery queue.",
                                  labels=["queue"])
        for queue in (QUEUE_SCANS, QUEUE_FRAMES, QUEUE_WEBHOOKS):
            depth.add_metric([queue], queue_depth(self._client, queue))
        yield depth

        durations = HistogramMetricFamily("prism_task_duration_seconds",
                                          "Run time of worker tasks.", labels=["task"])
        for task, row in read_task_durations(self._client).items():
            # The workers count a run in every bucket it fits, so the counts are cumulative.
            buckets = [(floatToGoString(bound), row.get(f"le:{bound}", 0.0)) for bound in BUCKETS_S]
            buckets.append(("+Inf", row.get("count", 0.0)))
            durations.add_metric([task], buckets, sum_value=row.get("sum", 0.0))
        yield durations


def render_metrics(store: JobStore, client: redis.Redis) -> bytes:
    """The exposition text of one scrape."""
    registry = CollectorRegistry(auto_describe=False)
    registry.register(ServiceCollector(store, client))
    return generate_latest(registry)
