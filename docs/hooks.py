"""MkDocs hook: the reference pages that are read from the code, written at build time.

Nothing here is copied by hand from the code: the command line comes from the typer app, the
HTTP API from the app's OpenAPI document, the job spec from its JSON schema (what `prism schema`
prints), report.json from its model's schema (`prism schema --report`), the configuration from
the settings class (its fields, defaults and the comments above them), the problem types from
`prism_api.problems.KINDS`. Each page is added to the build as a
generated file, so `mkdocs build --strict` fails on a broken link in any of them.
"""

from __future__ import annotations

import ast
import io
import json
import logging
import tokenize
from pathlib import Path
from typing import Any

from mkdocs.structure.files import File, Files

log = logging.getLogger("mkdocs.hooks.prism")
ROOT = Path(__file__).resolve().parents[1]


def _cell(text: object) -> str:
    """Text fit for one Markdown table cell."""
    return " ".join(str(text).split()).replace("|", "\\|")


# -- the command line ----------------------------------------------------------------------------

def cli_page() -> str:
    import typer.main

    from prism_cli.main import cli

    group = typer.main.get_command(cli)
    out = ["# Command line", "",
           "Every `prism` command and option, read from the program itself when this site was built "
           "(`prism COMMAND --help` prints the same). Exit codes: [Exit codes](exit-codes.md).", ""]
    root = group.context_class(group, info_name="prism")
    out += [f"- [`prism {name}`](#prism-{name}): {_cell(cmd.get_short_help_str(limit=100))}"
            for name, cmd in group.commands.items() if not cmd.hidden]
    out.append("")
    for name, cmd in group.commands.items():
        if not cmd.hidden:
            out += _command(cmd, f"prism {name}", root)
    return "\n".join(out) + "\n"


def _command(cmd: Any, path: str, parent: Any) -> list[str]:
    ctx = cmd.context_class(cmd, info_name=path.split()[-1], parent=parent)
    slug = path.replace(" ", "-")
    usage = " ".join([path, *cmd.collect_usage_pieces(ctx)])
    out = [f"## `{path}` {{#{slug}}}", "", (cmd.help or "").strip(), "", "```text", usage, "```", ""]
    records = [p.get_help_record(ctx) for p in cmd.params]
    records = [r for r in records if r]
    if records:
        out += ["| option | meaning |", "|---|---|"]
        out += [f"| `{_cell(flag)}` | {_cell(help_text)} |" for flag, help_text in records]
        out.append("")
    for name, sub in getattr(cmd, "commands", {}).items():  # a command group: its commands
        if not sub.hidden:
            out += _command(sub, f"{path} {name}", ctx)
    return out


# -- JSON schemas (the job spec, the API's models) -------------------------------------------------

def _type(schema: dict[str, Any], anchor: str = "") -> str:
    if "$ref" in schema:
        name = schema["$ref"].rsplit("/", 1)[1]
        return f"[{name}](#{anchor}{name.lower()})"
    if "anyOf" in schema or "oneOf" in schema:
        parts = [_type(s, anchor) for s in schema.get("anyOf", schema.get("oneOf", []))]
        return " or ".join(dict.fromkeys(parts))
    if "const" in schema:
        return f"`{json.dumps(schema['const'])}`"
    if "enum" in schema:
        return " or ".join(f"`{json.dumps(v)}`" for v in schema["enum"])
    kind = schema.get("type", "any")
    if kind == "array":
        if "prefixItems" in schema:
            return "[" + ", ".join(_type(s, anchor) for s in schema["prefixItems"]) + "]"
        return f"array of {_type(schema.get('items', {}), anchor)}"
    if kind == "object" and isinstance(schema.get("additionalProperties"), dict):
        return f"object of {_type(schema['additionalProperties'], anchor)}"
    return "null" if kind == "null" else str(kind)


def _limits(schema: dict[str, Any]) -> str:
    notes = []
    for key, word in (("minimum", ">="), ("exclusiveMinimum", ">"), ("maximum", "<="),
                      ("exclusiveMaximum", "<"), ("minItems", "items >="), ("maxItems", "items <="),
                      ("minLength", "length >="), ("maxLength", "length <=")):
        for s in [schema, *schema.get("anyOf", [])]:
            if key in s:
                notes.append(f"{word} {s[key]:g}" if isinstance(s[key], float) else f"{word} {s[key]}")
    if "default" in schema:
        notes.append(f"default `{json.dumps(schema['default'])}`")
    return "; ".join(dict.fromkeys(notes))


def schema_table(schema: dict[str, Any], anchor: str = "") -> list[str]:
    props = schema.get("properties", {})
    if not props:
        return [_cell(schema.get("description", "")), ""]
    required = set(schema.get("required", []))
    out = [_cell(schema.get("description", "")), "", "| field | type | meaning |", "|---|---|---|"]
    for name, sub in props.items():
        meaning = " ".join(filter(None, [sub.get("description", ""), _limits(sub)]))
        flag = " (required)" if name in required else ""
        out.append(f"| `{name}`{flag} | {_cell(_type(sub, anchor))} | {_cell(meaning)} |")
    return [*out, ""]


def job_spec_page() -> str:
    from prismcore import ScanSpec

    schema = ScanSpec.model_json_schema()
    return _schema_page(
        "# Job spec",
           "A scan as JSON: the file `prism scan --spec FILE` reads, and each item of a job sent to "
           "`POST /v1/jobs` (there `image` is a reference: `upload:ID`, `s3://bucket/key` or an "
           "allowed `https` URL). This page is the JSON Schema `prism schema` prints, as tables; "
           "every length and scale is bounded, and a value outside its range is refused at once "
           "(exit 2, or HTTP 422 naming the field). `prism schema` prints the schema itself.",
        "ScanSpec", schema)


def _schema_page(title: str, intro: str, top: str, schema: dict[str, Any]) -> str:
    """A JSON Schema as a page: its title, its intro, the top model's table, then each $defs'."""
    out = [title, "", intro, "", f"## {top} {{#{top.lower()}}}", "", *schema_table(schema)]
    for name, sub in schema.get("$defs", {}).items():
        out += [f"## {name} {{#{name.lower()}}}", "", *schema_table(sub)]
    return "\n".join(out) + "\n"


def report_page() -> str:
    from prismcore.report import report_schema

    schema = report_schema()
    return _schema_page(
        "# report.json",
           "One photo's (or video frame's, or station photo's) measurement, as `prismcore.report.ScanReport` "
           "holds it: the engine builds it, and the overlay, the glb model, the service's item result and "
           "`prism scan`'s summary read it. A field is in the file when the measurement's mode sets it "
           "(found points add `points_source` and `auto_points`, a video frame `frame`, a station "
           "`scale_source`, `points_source`, `station` and `engine_dimensions`); a field set to null "
           "says the value is unknown. Its JSON Schema (draft 2020-12) is "
           "[report.schema.json](report.schema.json) (`prism schema --report` prints it); this page is "
           "that schema as tables, and [Output files](outputs.md#reportjson) says what the fields mean.",
        "ScanReport", schema)


# -- the HTTP API ----------------------------------------------------------------------------------

def http_api_page() -> str:
    from prism_api.main import create_app

    doc = create_app().openapi()
    out = ["# HTTP API", "",
           "Every operation of the API, from its OpenAPI document (`/openapi.json` on a running "
           "service, which also serves it as pages at `/docs` and `/redoc`). Every `/v1` call "
           "carries `X-API-Key`; errors are [problem details](problems.md).", ""]
    for path, ops in doc["paths"].items():
        for method, op in ops.items():
            title = f"{method.upper()} {path}"
            lead = f"**{op.get('summary', '')}.** {op.get('description', '')}".strip()
            out += [f"## `{title}`", "", lead, ""]
            params = op.get("parameters", [])
            if params:
                out += ["| parameter | in | type | meaning |", "|---|---|---|---|"]
                for p in params:
                    req = " (required)" if p.get("required") else ""
                    meaning = " ".join(filter(None, [p.get("description", ""), _limits(p.get("schema", {}))]))
                    out.append(f"| `{p['name']}`{req} | {p['in']} | "
                               f"{_cell(_type(p.get('schema', {}), 'schema-'))} | {_cell(meaning)} |")
                out.append("")
            body = op.get("requestBody", {}).get("content", {})
            for media, content in body.items():
                out += [f"Body (`{media}`): {_type(content.get('schema', {}), 'schema-')}", ""]
            out += ["| status | meaning |", "|---|---|"]
            for code, answer in sorted(op.get("responses", {}).items()):
                schemas = [_type(c.get("schema", {}), "schema-") for c in answer.get("content", {}).values()
                           if c.get("schema")]
                what = answer.get("description", "") + (f" ({', '.join(schemas)})" if schemas else "")
                out.append(f"| {code} | {_cell(what)} |")
            out.append("")
    out += ["## Schemas", ""]
    for name, schema in doc.get("components", {}).get("schemas", {}).items():
        out += [f"### {name} {{#schema-{name.lower()}}}", "", *schema_table(schema, "schema-")]
    return "\n".join(out) + "\n"


# -- the configuration -----------------------------------------------------------------------------

# What an operator needs to know beyond the class's own comments (field name: meaning). A name
# here that the class does not have fails the build.
SETTING_NOTES = {
    "api_keys": "Who may call: JSON `{\"tenant\": \"key\", ...}`. Required.",
    "webhook_secret": "The webhook signing key: `whsec_` + base64 (Standard Webhooks), or any other "
                      "string, whose UTF-8 bytes are the key ([webhooks](../how-to/webhooks.md)). Required.",
    "redis_url": "The broker and the job records.",
    "redis_sentinels": "`host:port,host:port`: Redis behind Sentinel ([how-to](../how-to/sentinel.md)); "
                       "`PRISM_REDIS_URL` then gives only the primary's password and database.",
    "redis_sentinel_master": "The name the sentinels monitor the primary under.",
    "s3_endpoint_url": "Any S3-compatible endpoint (none: AWS S3).",
    "s3_bucket": "The service's bucket (created if missing).",
    "s3_region": "The bucket's region.",
    "s3_access_key_id": "S3 credentials (none: boto3's usual chain, `AWS_*` variables and so on).",
    "s3_secret_access_key": "S3 credentials (none: boto3's usual chain).",
    "readable_buckets": "Buckets that `s3://bucket/key` inputs may name.",
    "fetch_allowed_hosts": "Hosts that `https` inputs may name (public addresses only; redirects "
                           "checked again).",
    "fetch_allow_private": "Tests only: lets allow-listed input hosts resolve to loopback.",
    "webhook_allowed_hosts": "Hosts webhooks may be sent to ([webhooks](../how-to/webhooks.md)).",
    "webhook_allow_http": "`http://` webhook URLs too (otherwise `https` only): a receiver on a network "
                          "you trust.",
    "webhook_allow_private": "Webhook hosts may resolve to loopback or private addresses (a receiver on "
                             "this machine or the LAN).",
    "fetch_max_bytes": "The largest input fetched from an `https` URL.",
    "fetch_ca_bundle": "A CA bundle for `https` inputs (none: the system's).",
    "upload_max_bytes": "The largest upload, refused while it streams (413).",
    "presign_ttl_s": "The lifetime of download links, in seconds.",
    "max_items_per_job": "The most items one job may have.",
    "max_pixels": "The largest image, in pixels.",
    "tiles_per_face": "Row tiles each face is scanned in, in parallel.",
    "queue_retry_after_s": "The `Retry-After` of a 503 from a full queue.",
    "watchdog_interval_s": "How often the watchdog sweeps (0: off).",
    "job_stall_restarts": "Restarts without progress before a stalled job fails with the reason.",
}


def _field_comments(source: str, class_name: str) -> dict[str, str]:
    """Each field's comment: the comment lines just above it and the one at its line's end."""
    tree = ast.parse(source)
    cls = next(n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == class_name)
    comments: dict[int, str] = {}
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type == tokenize.COMMENT:
            comments[tok.start[0]] = tok.string.lstrip("#").strip()
    lines = source.splitlines()
    out: dict[str, str] = {}
    for node in cls.body:
        if isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            above, row = [], node.lineno - 1
            while row >= 1 and lines[row - 1].strip().startswith("#"):
                above.insert(0, comments.get(row, ""))
                row -= 1
            text = " ".join([*above, comments.get(node.end_lineno or node.lineno, "")]).strip()
            out[node.target.id] = text
    return out


def configuration_page() -> str:
    from prism_common.settings import Settings
    from pydantic_core import PydanticUndefined

    source = (ROOT / "services" / "common" / "settings.py").read_text()
    comments = _field_comments(source, "Settings")
    unknown = set(SETTING_NOTES) - set(Settings.model_fields)
    if unknown:
        raise ValueError(f"docs/hooks.py SETTING_NOTES names no setting: {sorted(unknown)}")
    out = ["# Configuration", "",
           "The service (API and workers) reads its settings from environment variables, one "
           "`PRISM_<NAME>` per field of one settings class (`prism_common.settings.Settings`); this "
           "table is read from that class when the site is built. Lists and objects are JSON "
           "(`PRISM_DEFAULT_FORMATS='[\"csv\",\"ply\"]'`). `prism serve` sets the required ones "
           "itself.", "",
           "| variable | default | meaning |", "|---|---|---|"]
    for name, field in Settings.model_fields.items():
        if field.default_factory is not None:
            default: Any = field.default_factory()  # type: ignore[call-arg]
        else:
            default = field.default
        shown = ("required" if default is PydanticUndefined
                 else "none" if default is None else f"`{json.dumps(default)}`")
        meaning = SETTING_NOTES.get(name) or field.description or comments.get(name, "")
        out.append(f"| `PRISM_{name.upper()}` | {_cell(shown)} | {_cell(meaning)} |")
    return "\n".join(out) + "\n"


# -- problem types ---------------------------------------------------------------------------------

PROBLEM_WHEN = {
    "bad-request": "The body cannot be read: not JSON, a cut multipart body, the client left.",
    "unauthorized": "No `X-API-Key`, or a wrong one.",
    "not-found": "No such job, upload, item, frame or route (another tenant's answers the same).",
    "method-not-allowed": "The route has no such method.",
    "conflict": "An `Idempotency-Key` reused with another body; cancelling a finished job.",
    "body-too-large": "Over `PRISM_REQUEST_MAX_BYTES`, an upload over `PRISM_UPLOAD_MAX_BYTES`, or a "
                      "station's calibration photos over `PRISM_STATION_MAX_BYTES`.",
    "unsupported-media-type": "An upload that is neither a photo nor a video (`detected_type` says "
                              "what it is).",
    "validation": "Invalid input: `errors` locates each bad value.",
    "damaged-file": "An upload that is a photo or a video but damaged (a truncated JPEG, say).",
    "rate-limited": "The key's rate limit, or the address's refused-key budget (`Retry-After`).",
    "internal-error": "A fault of the service; nothing of it is disclosed, it is logged.",
    "at-capacity": "The scans queue is full: no job was created; or `PRISM_STATION_CALIBRATIONS_AT_ONCE` "
                   "stations are being calibrated: no station was created; or `PRISM_UPLOADS_AT_ONCE` "
                   "uploads are being taken: nothing was stored (`Retry-After`).",
    "backend-unavailable": "Redis, the object store or the job queue does not answer (`Retry-After`).",
}


def problems_page() -> str:
    from prism_api.problems import BASE, KINDS

    missing = set(KINDS) - set(PROBLEM_WHEN)
    if missing:
        raise ValueError(f"docs/hooks.py PROBLEM_WHEN lacks problem types {sorted(missing)}")
    out = ["# Problem types", "",
           "Every error the API answers is an RFC 9457 problem, `Content-Type: "
           "application/problem+json`: `{\"type\", \"title\", \"status\", \"detail\", \"instance\"}`. "
           "`detail` is one sentence quoting the bad value; invalid input adds `errors`, one "
           "`{\"pointer\": \"/items/0/points/p3\", \"detail\"}` per bad value (a JSON pointer into the "
           "body as sent; a query or path value gets `parameter`, a header `header`). Branch on "
           "`type`, which is stable; the wording of `detail` may change.", "",
           f"| `type` (`{BASE}...`) | status | title | when |", "|---|---|---|---|"]
    for slug, kind in KINDS.items():
        when = _cell(PROBLEM_WHEN.get(slug, ""))
        out.append(f"| `{slug}` | {kind.status} | {_cell(kind.title)} | {when} |")
    out += ["", "Any other status carries `type` `about:blank`. `Retry-After` comes with 429 and 503, "
            "`WWW-Authenticate` with 401."]
    return "\n".join(out) + "\n"


GENERATED = {
    "reference/cli.md": cli_page,
    "reference/http-api.md": http_api_page,
    "reference/job-spec.md": job_spec_page,
    "reference/report.md": report_page,
    "reference/configuration.md": configuration_page,
    "reference/problems.md": problems_page,
}


def on_files(files: Files, config: Any) -> Files:
    for uri, make in GENERATED.items():
        files.append(File.generated(config, uri, content=make()))
    return files
