"""deploy/k8s/prismcloud.yaml: current with its renderer, valid against the Kubernetes API
schemas (kubernetes-validate's bundled ones, strict: an unknown field fails), and saying what
the service needs (probes on the API's routes, the workers' queues, settings that exist).

KEDA's resources are checked against a schema written here by hand from KEDA's CRDs
(keda.sh/v1alpha1 ScaledObject and TriggerAuthentication: the fields used and their types,
nothing else allowed), not the CRDs themselves.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import jsonschema
import kubernetes_validate
import pytest
import yaml
from prism_common.queue import QUEUE_SCANS, WORKER_QUEUES
from prism_common.settings import Settings

ROOT = Path(__file__).resolve().parents[2]
MANIFESTS = ROOT / "deploy" / "k8s" / "prismcloud.yaml"
KUBERNETES = "1.30"  # the oldest minor still supported by its upstream when this was written

_STRINGS = {"type": "object", "additionalProperties": {"type": "string"}}
_INT32 = {"type": "integer", "minimum": 0, "maximum": 2**31 - 1}
_META = {"type": "object", "required": ["name"], "properties": {"name": {"type": "string"}}}
KEDA = {
    "ScaledObject": {
        "type": "object", "additionalProperties": False,
        "required": ["apiVersion", "kind", "metadata", "spec"],
        "properties": {
            "apiVersion": {"const": "keda.sh/v1alpha1"}, "kind": {"const": "ScaledObject"},
            "metadata": _META,
            "spec": {
                "type": "object", "additionalProperties": False, "required": ["scaleTargetRef", "triggers"],
                "properties": {
                    "scaleTargetRef": {"type": "object", "additionalProperties": False, "required": ["name"],
                                       "properties": {"apiVersion": {"type": "string"},
                                                      "kind": {"type": "string"},
                                                      "name": {"type": "string"},
                                                      "envSourceContainerName": {"type": "string"}}},
                    "pollingInterval": _INT32, "cooldownPeriod": _INT32, "idleReplicaCount": _INT32,
                    "minReplicaCount": _INT32, "maxReplicaCount": _INT32,
                    "triggers": {"type": "array", "minItems": 1, "items": {
                        "type": "object", "additionalProperties": False, "required": ["type", "metadata"],
                        "properties": {"type": {"type": "string"}, "name": {"type": "string"},
                                       "metadata": _STRINGS, "metricType": {"type": "string"},
                                       "useCachedMetrics": {"type": "boolean"},
                                       "authenticationRef": {
                                           "type": "object", "additionalProperties": False,
                                           "required": ["name"],
                                           "properties": {"name": {"type": "string"},
                                                          "kind": {"type": "string"}}}}}}}}}},
    "TriggerAuthentication": {
        "type": "object", "additionalProperties": False,
        "required": ["apiVersion", "kind", "metadata", "spec"],
        "properties": {
            "apiVersion": {"const": "keda.sh/v1alpha1"}, "kind": {"const": "TriggerAuthentication"},
            "metadata": _META,
            "spec": {"type": "object", "additionalProperties": False, "properties": {
                "secretTargetRef": {"type": "array", "items": {
                    "type": "object", "additionalProperties": False,
                    "required": ["parameter", "name", "key"],
                    "properties": {"parameter": {"type": "string"}, "name": {"type": "string"},
                                   "key": {"type": "string"}}}}}}}},
}


def _docs() -> list[dict]:
    return list(yaml.safe_load_all(MANIFESTS.read_text()))


def _by(kind: str, name: str) -> dict:
    [doc] = [d for d in _docs() if d["kind"] == kind and d["metadata"]["name"] == name]
    return doc


def test_the_file_is_what_the_renderer_makes():
    spec = importlib.util.spec_from_file_location("k8s_render", ROOT / "deploy" / "k8s" / "render.py")
    assert spec and spec.loader
    render = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(render)
    assert MANIFESTS.read_text() == render.render(), "run deploy/k8s/render.py > deploy/k8s/prismcloud.yaml"


@pytest.mark.parametrize("doc", _docs(), ids=lambda d: f"{d['kind']}/{d['metadata']['name']}")
def test_every_resource_is_valid(doc):
    if doc["apiVersion"].startswith("keda.sh/"):
        jsonschema.validate(doc, KEDA[doc["kind"]])
    else:
        kubernetes_validate.validate(doc, KUBERNETES, strict=True)


def test_the_validators_refuse_a_wrong_field():  # the checks above can fail
    api = _by("Deployment", "prism-api")
    api["spec"]["template"]["spec"]["containers"][0]["readinessprobe"] = {}
    with pytest.raises(kubernetes_validate.ValidationError):
        kubernetes_validate.validate(api, KUBERNETES, strict=True)
    scaled = _by("ScaledObject", "prism-worker")
    scaled["spec"]["triggers"][0]["metadata"]["listLength"] = 4
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(scaled, KEDA["ScaledObject"])


def test_probes_queues_and_settings_are_the_service_s(monkeypatch):
    from prism_api.routes.health import router

    routes = {getattr(r, "path", None) for r in router.routes}
    api = _by("Deployment", "prism-api")["spec"]["template"]["spec"]["containers"][0]
    assert api["readinessProbe"]["httpGet"]["path"] == "/readyz" in routes
    assert api["livenessProbe"]["httpGet"]["path"] == "/healthz" in routes

    worker = _by("Deployment", "prism-worker")["spec"]["template"]["spec"]["containers"][0]
    assert worker["command"][worker["command"].index("-Q") + 1] == WORKER_QUEUES
    scaled = _by("ScaledObject", "prism-worker")
    assert scaled["spec"]["scaleTargetRef"]["name"] == "prism-worker"
    triggers = {t["metadata"]["listName"] for t in scaled["spec"]["triggers"]}
    assert QUEUE_SCANS in triggers and triggers <= set(WORKER_QUEUES.split(","))
    assert scaled["spec"]["minReplicaCount"] >= 1  # the watchdog runs in the workers

    env = {**_by("ConfigMap", "prism-config")["data"], **_by("Secret", "prism-secrets")["stringData"]}
    fields = {f"PRISM_{name.upper()}" for name in Settings.model_fields}
    assert {k for k in env if k.startswith("PRISM_")} <= fields
    for name, value in env.items():
        monkeypatch.setenv(name, value)
    settings = Settings()  # type: ignore[call-arg]  # the pods' environment parses
    assert settings.s3_endpoint_url == "http://prism-s3:8333"
    external = {d["metadata"]["name"] for d in _docs()
                if d["kind"] == "Service" and d["spec"].get("type") == "ExternalName"}
    assert external == {"prism-redis", "prism-s3"}
    assert "prism-redis" in settings.redis_url
