"""Schemathesis hooks for tests/service/test_schemathesis.py, loaded by the `st` command it runs
(SCHEMATHESIS_HOOKS names this file; the test's environment gives the references below).

A generated job names files by reference: `upload:` and 32 hex digits that no upload of the
tenant has, so every generated job would be refused for a missing file and none would reach the
worker. What a reference points at is data, not schema: just before each call, the references
of a generated job are swapped for real uploads of the kind the item needs (a video for an item
with frames, the sample photo otherwise; distinct photos for distinct views), and its
webhook_url, which the operator's allow-list decides, for the test's receiver. The rest of the
body is Schemathesis' own. Schemathesis validates the body again after the hook, so a case is
judged positive or negative by what was sent.
"""

from __future__ import annotations

import json
import os
import re
import sys
from typing import Any

import schemathesis

# Schemathesis' coverage phase describes the station.json schema's nested strategies by parsing
# lambdas' sources, and CPython 3.11's parser fails ("AST constructor recursion depth mismatch")
# when that starts near the default recursion limit.
sys.setrecursionlimit(max(sys.getrecursionlimit(), 10_000))

PHOTO = os.environ.get("PRISM_FUZZ_PHOTO", "")
VIDEO = os.environ.get("PRISM_FUZZ_VIDEO", "")
VIEWS: list[str] = json.loads(os.environ.get("PRISM_FUZZ_VIEWS", "[]"))
WEBHOOK = os.environ.get("PRISM_FUZZ_WEBHOOK", "")


def ground(body: Any) -> None:
    """Swap a job body's references (and webhook_url) for real ones, in place."""
    if not isinstance(body, dict):
        return
    if isinstance(body.get("webhook_url"), str):
        body["webhook_url"] = WEBHOOK
    for item in body.get("items") or []:
        if not isinstance(item, dict):
            continue
        video = any(item.get(name) is not None for name in ("frames", "frame_points", "points_frame"))
        if isinstance(item.get("image"), str):
            item["image"] = VIDEO if video else PHOTO
        if isinstance(item.get("side_image"), str):
            item["side_image"] = VIEWS[0]  # another photo of the part than the front's
        views = item.get("views")
        if isinstance(views, list):
            for k, view in enumerate(views):
                if isinstance(view, dict) and isinstance(view.get("image"), str):
                    view["image"] = VIEWS[k % len(VIEWS)]
            # with views, an image given must be the first view's
            if isinstance(item.get("image"), str) and views and isinstance(views[0], dict):
                item["image"] = views[0].get("image", item["image"])


@schemathesis.hook
def before_call(context: Any, case: Any, kwargs: dict[str, Any]) -> None:
    if case.method == "POST" and case.path == "/v1/jobs":
        ground(case.body)


# What a job the schema allows may still be refused for (422), by the words of the refusal: the
# files it names, numbers compared with numbers, and the rules ScanSpec's schema leaves to its
# validators (prismcore.spec_fields.scan_spec_rules says why). Any other refusal of a schema-valid
# job is a rule the document could state and does not: a failure.
BEYOND_THE_SCHEMA = {
    "a point, hint or region outside the photo": r"is outside the \d+x\d+ image",
    "points too close together": r"closer than [\d.]+ px",
    "points that mark no face": r"cannot tell which face",
    "frames past the video's end": r"past the video's end",
    "a station the tenant does not have": r"no station '",
    "a region's corners out of order": r"with X0 < X1 and Y0 < Y1",
    "frame_points' keys against frames.indices": r"frame_points measures exactly frames",
    "a time range ending before it starts": r"must be after start_s",
    "a shooting distance without a focal length": r"a shooting distance needs focal_px",
    "side_face left or top with side_image": r"side_face '(left|top)' is for one photo",
    "frames with side_image": r"a video is measured in single-photo mode",
    "points_frame's needs": r"points_frame (is for a video|names the frame)|tracking from points_frame",
    "fit 'frames' without frames": r"fit is for a video's frames",
    "fit 'joint''s frame_points and options": r'fit "joint"',
}


@schemathesis.check
def refused_jobs_break_a_rule_beyond_the_schema(ctx: Any, response: Any, case: Any) -> bool | None:
    if case.method != "POST" or case.path != "/v1/jobs" or response.status_code != 422:
        return None
    if case.meta is None or not case.meta.generation.mode.is_positive:
        return None
    problem = response.json()
    details = [e.get("detail", "") for e in problem.get("errors") or [problem]]
    unstated = [d for d in details if not any(re.search(p, d) for p in BEYOND_THE_SCHEMA.values())]
    if unstated:
        raise AssertionError("a job the schema allows was refused for a rule it could state: "
                             + " | ".join(unstated))
    return True
