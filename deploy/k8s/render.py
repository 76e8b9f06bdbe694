"""Render PrismCloud's Kubernetes manifests (deploy/k8s/prismcloud.yaml) from the service's own
names: the queues the workers consume and KEDA watches come from prism_common.queue, the
probes from the API's routes.

    .venv/bin/python deploy/k8s/render.py > deploy/k8s/prismcloud.yaml   # after a change
    .venv/bin/python deploy/k8s/render.py --check                       # the file is current

What it describes: the API (a Deployment, readiness on /readyz, liveness on /healthz, and its
Service), the workers (a Deployment that KEDA scales on the length of the scans queue's Redis
list), Redis and the S3 store outside the cluster (Services of type ExternalName that the
settings name), the settings in a ConfigMap and the keys in a Secret. Edit the marked values
(image, external hosts, replicas) here, or patch the rendered file with kustomize.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import yaml
from prism_common.queue import QUEUE_FRAMES, QUEUE_SCANS, WORKER_QUEUES

OUT = Path(__file__).with_name("prismcloud.yaml")

# -- the values a site changes ---------------------------------------------------------------
IMAGE = "prismcloud:latest"  # built from the repository's Dockerfile
REDIS_HOST = "redis.internal.example"  # outside the cluster (or a Sentinel set: docs/how-to/sentinel.md)
S3_HOST = "s3.internal.example"
S3_PUBLIC_URL = "https://s3.example.com"  # where clients fetch their presigned downloads from
WORKER_CONCURRENCY = 2  # processes per worker pod (one per core requested)
WORKERS_MIN, WORKERS_MAX = 1, 64  # at least one: the watchdog and the frames queue live in workers
SCANS_PER_WORKER = 2 * WORKER_CONCURRENCY  # waiting tasks per pod before KEDA adds one
TASK_TIME_LIMIT_S, TASK_HARD_MARGIN_S = 240, 30  # the settings' defaults
# A scale-down's SIGTERM is Celery's warm shutdown: running tasks finish (at most the time
# limit and its margin) before the pod is killed.
WORKER_GRACE_S = TASK_TIME_LIMIT_S + TASK_HARD_MARGIN_S + 30

LABELS = {"app.kubernetes.io/part-of": "prismcloud"}


def _meta(name: str, component: str) -> dict[str, Any]:
    return {"name": name, "labels": {**LABELS, "app.kubernetes.io/name": name,
                                     "app.kubernetes.io/component": component}}


def _select(name: str) -> dict[str, Any]:
    return {"app.kubernetes.io/name": name}


def _env_from() -> list[dict[str, Any]]:
    return [{"configMapRef": {"name": "prism-config"}}, {"secretRef": {"name": "prism-secrets"}}]


def _security() -> dict[str, Any]:
    return {"runAsNonRoot": True, "runAsUser": 10001, "allowPrivilegeEscalation": False,
            "readOnlyRootFilesystem": True, "capabilities": {"drop": ["ALL"]}}


def external(name: str, host: str, port: int) -> dict[str, Any]:
    """A cluster name for a service that runs outside the cluster."""
    return {"apiVersion": "v1", "kind": "Service", "metadata": _meta(name, "external"),
            "spec": {"type": "ExternalName", "externalName": host,
                     "ports": [{"name": "main", "port": port, "targetPort": port}]}}


def config() -> dict[str, Any]:
    return {"apiVersion": "v1", "kind": "ConfigMap", "metadata": _meta("prism-config", "config"),
            "data": {"PRISM_S3_ENDPOINT_URL": "http://prism-s3:8333",
                     "PRISM_S3_PUBLIC_ENDPOINT_URL": S3_PUBLIC_URL,
                     "PRISM_S3_BUCKET": "prismcloud",
                     "PRISM_TASK_TIME_LIMIT_S": str(TASK_TIME_LIMIT_S),
                     "PRISM_TASK_HARD_MARGIN_S": str(TASK_HARD_MARGIN_S)}}


def secrets() -> dict[str, Any]:
    """Placeholders: create the real Secret with kubectl (docs/how-to/kubernetes.md), leave this out."""
    return {"apiVersion": "v1", "kind": "Secret", "metadata": _meta("prism-secrets", "secrets"),
            "type": "Opaque",
            "stringData": {"PRISM_API_KEYS": '{"tenant": "replace-me"}',
                           "PRISM_WEBHOOK_SECRET": "replace-me",
                           "PRISM_REDIS_URL": "redis://:replace-me@prism-redis:6379/0",
                           "PRISM_S3_ACCESS_KEY_ID": "replace-me",
                           "PRISM_S3_SECRET_ACCESS_KEY": "replace-me",
                           # KEDA reads the queue's length with it (TriggerAuthentication).
                           "REDIS_PASSWORD": "replace-me"}}


def api() -> list[dict[str, Any]]:
    name = "prism-api"
    container = {
        "name": "api", "image": IMAGE,
        "command": ["uvicorn", "prism_api.main:app", "--host", "0.0.0.0", "--port", "8000",
                    "--workers", "2", "--proxy-headers", "--forwarded-allow-ips", "*"],
        "ports": [{"name": "http", "containerPort": 8000}],
        "envFrom": _env_from(),
        # Ready when Redis and the store answer (a 503 takes the pod out of the Service);
        # alive as long as the process answers at all (a Redis outage restarts nothing).
        "readinessProbe": {"httpGet": {"path": "/readyz", "port": "http"}, "periodSeconds": 10,
                           "timeoutSeconds": 5, "failureThreshold": 3},
        "livenessProbe": {"httpGet": {"path": "/healthz", "port": "http"}, "periodSeconds": 20,
                          "timeoutSeconds": 5, "failureThreshold": 3},
        "resources": {"requests": {"cpu": "500m", "memory": "512Mi"}, "limits": {"memory": "1Gi"}},
        "securityContext": _security(),
        "volumeMounts": [{"name": "tmp", "mountPath": "/tmp"}],
    }
    deployment = {
        "apiVersion": "apps/v1", "kind": "Deployment", "metadata": _meta(name, "api"),
        "spec": {"replicas": 2, "selector": {"matchLabels": _select(name)},
                 "strategy": {"type": "RollingUpdate", "rollingUpdate": {"maxUnavailable": 0, "maxSurge": 1}},
                 "template": {"metadata": {"labels": {**LABELS, **_select(name)}},
                              "spec": {"containers": [container],
                                       "volumes": [{"name": "tmp", "emptyDir": {}}]}}}}
    service = {"apiVersion": "v1", "kind": "Service", "metadata": _meta(name, "api"),
               "spec": {"selector": _select(name),
                        "ports": [{"name": "http", "port": 80, "targetPort": "http"}]}}
    return [deployment, service]


def worker() -> dict[str, Any]:
    name = "prism-worker"
    container = {
        "name": "worker", "image": IMAGE,
        "command": ["celery", "-A", "prism_worker.app", "worker", "-Q", WORKER_QUEUES,
                    "--concurrency", str(WORKER_CONCURRENCY), "--loglevel", "info",
                    "--hostname", "worker@$(POD_NAME)", "--without-gossip", "--without-mingle"],
        "env": [{"name": "POD_NAME", "valueFrom": {"fieldRef": {"fieldPath": "metadata.name"}}}],
        "envFrom": _env_from(),
        "resources": {"requests": {"cpu": str(WORKER_CONCURRENCY), "memory": "2Gi"},
                      "limits": {"memory": "4Gi"}},
        "securityContext": _security(),
        "volumeMounts": [{"name": "tmp", "mountPath": "/tmp"}],
    }
    return {
        "apiVersion": "apps/v1", "kind": "Deployment", "metadata": _meta(name, "worker"),
        "spec": {"replicas": WORKERS_MIN, "selector": {"matchLabels": _select(name)},
                 "template": {"metadata": {"labels": {**LABELS, **_select(name)}},
                              "spec": {
                                  "terminationGracePeriodSeconds": WORKER_GRACE_S,
                                  "containers": [container],
                                  "volumes": [{"name": "tmp", "emptyDir": {"sizeLimit": "10Gi"}}]}}}}


def autoscaling() -> list[dict[str, Any]]:
    auth = {"apiVersion": "keda.sh/v1alpha1", "kind": "TriggerAuthentication",
            "metadata": _meta("prism-redis", "autoscaling"),
            "spec": {"secretTargetRef": [{"parameter": "password", "name": "prism-secrets",
                                          "key": "REDIS_PASSWORD"}]}}

    def trigger(queue: str, per_pod: int) -> dict[str, Any]:
        # kombu keeps a queue as the Redis list of its name (prism_common.queue.queue_lists).
        return {"type": "redis", "name": f"queue-{queue}",
                "metadata": {"address": "prism-redis:6379", "databaseIndex": "0", "listName": queue,
                             "listLength": str(per_pod), "activationListLength": "0"},
                "authenticationRef": {"name": "prism-redis"}}

    scaled = {"apiVersion": "keda.sh/v1alpha1", "kind": "ScaledObject",
              "metadata": _meta("prism-worker", "autoscaling"),
              "spec": {"scaleTargetRef": {"name": "prism-worker"},
                       "minReplicaCount": WORKERS_MIN, "maxReplicaCount": WORKERS_MAX,
                       "pollingInterval": 15, "cooldownPeriod": 300,
                       "triggers": [trigger(QUEUE_SCANS, SCANS_PER_WORKER), trigger(QUEUE_FRAMES, 4)]}}
    return [auth, scaled]


def manifests() -> list[dict[str, Any]]:
    return [config(), secrets(), external("prism-redis", REDIS_HOST, 6379),
            external("prism-s3", S3_HOST, 8333), *api(), worker(), *autoscaling()]


def render() -> str:
    head = "# Rendered by deploy/k8s/render.py: edit that, then render again.\n"
    return head + "---\n".join(yaml.safe_dump(m, sort_keys=False, width=100) for m in manifests())


def main(argv: list[str]) -> int:
    text = render()
    if argv[1:] == ["--check"]:
        if OUT.read_text() != text:
            print(f"{OUT} is out of date: run deploy/k8s/render.py > {OUT}", file=sys.stderr)
            return 1
        return 0
    sys.stdout.write(text)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
