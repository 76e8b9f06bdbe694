"""Errors as RFC 9457 problem details (`application/problem+json`), one builder for all of them.

Every 4xx/5xx the API sends comes from :func:`problem_response`: a stable ``type`` URI per kind
of error (clients branch on it, never on wording), ``title`` (the kind, in words), ``status``,
``detail`` (one sentence quoting what was wrong), ``instance`` (the request path) and, for
invalid input, ``errors``: one entry per bad value, located by a JSON pointer (RFC 6901) into
the request body, or by the query/path ``parameter`` or ``header`` it came in.

Routes raise :class:`Problem` to choose a kind; a plain ``HTTPException`` gets its status's
default kind, so code that raises one (dependencies, middlewares) needs no change.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from fastapi import FastAPI, HTTPException, Request
from fastapi.exceptions import RequestValidationError
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.responses import JSONResponse
from starlette.routing import Match, Mount

from prismcore.spec import error_message

__all__ = ["BASE", "KINDS", "MEDIA_TYPE", "PROBLEM_SCHEMA", "PROBLEM_TYPES", "Kind", "Problem",
           "declare_problems", "install_handlers", "pointer", "problem_response", "validation_errors"]

log = logging.getLogger(__name__)

BASE = "https://prismcloud.dev/problems/"
MEDIA_TYPE = "application/problem+json"


@dataclass(frozen=True)
class Kind:
    """One kind of error: its ``type`` URI is BASE + slug."""

    slug: str
    title: str
    status: int

    @property
    def type(self) -> str:
        return BASE + self.slug


KINDS: dict[str, Kind] = {k.slug: k for k in (
    Kind("bad-request", "The request could not be read", 400),
    Kind("unauthorized", "Missing or invalid API key", 401),
    Kind("not-found", "No such resource", 404),
    Kind("method-not-allowed", "Method not allowed", 405),
    Kind("conflict", "Conflict with the resource's state", 409),
    Kind("body-too-large", "Request body too large", 413),
    Kind("unsupported-media-type", "Unsupported file type", 415),
    Kind("validation", "Invalid input", 422),
    Kind("damaged-file", "The file is damaged", 422),
    Kind("rate-limited", "Too many requests", 429),
    Kind("internal-error", "Internal error", 500),
    Kind("at-capacity", "The service is at capacity", 503),
    Kind("backend-unavailable", "A backend is unavailable", 503),
)}
_BY_STATUS = {400: "bad-request", 401: "unauthorized", 404: "not-found", 405: "method-not-allowed",
              409: "conflict", 413: "body-too-large", 415: "unsupported-media-type", 422: "validation",
              429: "rate-limited", 500: "internal-error", 503: "backend-unavailable"}


class Problem(HTTPException):
    """An HTTPException of a named kind, optionally with located `errors` and extra members."""

    def __init__(self, kind: str, detail: str, *, errors: Sequence[Mapping[str, Any]] | None = None,
                 headers: Mapping[str, str] | None = None, status: int | None = None,
                 **extensions: Any) -> None:
        self.kind = KINDS[kind]
        super().__init__(status or self.kind.status, detail, headers=dict(headers) if headers else None)
        self.errors = list(errors) if errors is not None else None
        self.extensions = extensions


def _kind_for(status: int) -> Kind | None:
    slug = _BY_STATUS.get(status)
    return KINDS[slug] if slug else None


def problem_response(status: int, detail: str, *, instance: str, kind: str | None = None,
                     errors: Sequence[Mapping[str, Any]] | None = None,
                     headers: Mapping[str, str] | None = None, **extensions: Any) -> JSONResponse:
    """The problem document of one error, as a response.

    A status without a kind of its own is ``about:blank`` with the status's phrase as title,
    as RFC 9457 (section 4.2.1) has it.
    """
    found = KINDS[kind] if kind else _kind_for(status)
    if found is not None:
        type_, title = found.type, found.title
    else:
        from http import HTTPStatus
        type_ = "about:blank"
        try:
            title = HTTPStatus(status).phrase
        except ValueError:
            title = "Error"
    body: dict[str, Any] = {"type": type_, "title": title, "status": status, "detail": detail,
                            "instance": instance}
    if errors is not None:
        body["errors"] = list(errors)
    body.update(extensions)
    return JSONResponse(body, status_code=status, headers=dict(headers) if headers else None,
                        media_type=MEDIA_TYPE)


def _instance(scope_or_request: Request | Mapping[str, Any]) -> str:
    """The request's path as the client sent it (under a --root-path, the prefix included)."""
    scope = scope_or_request.scope if isinstance(scope_or_request, Request) else scope_or_request
    return str(scope.get("path", ""))


def instance_of(scope: Mapping[str, Any]) -> str:
    """`instance` for a response built outside the exception handlers (ASGI middlewares)."""
    return _instance(scope)


# -- JSON pointers --------------------------------------------------------------------------------

def _escape(segment: str | int) -> str:
    return str(segment).replace("~", "~0").replace("/", "~1")


def pointer(segments: Iterable[str | int]) -> str:
    """The RFC 6901 pointer of a path of keys and indices ("" is the whole document)."""
    return "".join("/" + _escape(s) for s in segments)


_MISSING = object()


def _index(step: str | int) -> int | None:
    """The list index a location step names: an index, or p1..p7 of a points list."""
    if isinstance(step, str) and len(step) == 2 and step[0] == "p" and step[1].isdigit():
        return int(step[1]) - 1
    return step if isinstance(step, int) else None


def body_path(loc: Sequence[str | int], body: Any = _MISSING) -> list[str | int]:
    """Where in the body a pydantic location points, as keys and indices of the JSON sent.

    Pydantic's locations hold steps that are not in the document: the tag of a tagged union
    ("pinhole": the object's "kind", left out even where a key has its name, as a known edge's
    "edge"), a model's name in a plain union, a validator's name. With the parsed body at
    hand, a step is kept only where the document has it (or it is the last step: a missing
    field is pointed at where it belongs); a named point given as a list ([[x, y], ...]) is
    pointed at by its index; a bad key of an object (pydantic's last step "[key]") is pointed
    at as its member. Without the body, the location is taken as it is.
    """
    if body is _MISSING:
        return list(loc)
    out: list[str | int] = []
    value = body
    for i, step in enumerate(loc):
        last = i == len(loc) - 1
        if last and step == "[key]" and out:
            break  # the key before it is at fault: its member is the place
        if isinstance(value, dict):
            if not last and value.get("kind") == step:
                continue  # the tag of a tagged union (the scale's), even where a key has its name
            if str(step) in value:
                out.append(str(step))
                value = value[str(step)]
            elif last:
                out.append(str(step))
        elif isinstance(value, list):
            index = _index(step)
            if index is not None and 0 <= index < len(value):
                out.append(index)
                value = value[index]
            elif last and index is not None:
                out.append(index)
        else:
            break
    return out


def validation_errors(raw: Sequence[Mapping[str, Any]], body: Any = _MISSING) -> list[dict[str, Any]]:
    """Pydantic/FastAPI errors as problem `errors`: a `pointer` into the body, or the `parameter`
    (query, path) or `header` they concern, and `detail`."""
    out = []
    for e in raw:
        loc = list(e.get("loc", ()))
        where, rest = (loc[0], loc[1:]) if loc else ("body", [])
        message = error_message(str(e.get("msg", "invalid")))
        entry: dict[str, Any]
        if where in ("query", "path", "cookie"):
            entry = {"parameter": str(rest[0]) if rest else ""}
        elif where == "header":
            entry = {"header": str(rest[0]) if rest else ""}
        else:
            entry = {"pointer": pointer(body_path(rest, body))}
        entry["detail"] = message
        out.append(entry)
    return out


def _summary(errors: list[dict[str, Any]]) -> str:
    first = errors[0]
    place = first.get("pointer") or first.get("parameter") or first.get("header") or "the body"
    more = f" (and {len(errors) - 1} more)" if len(errors) > 1 else ""
    return f"{place}: {first['detail']}{more}"


# -- handlers -------------------------------------------------------------------------------------

_METHODS = ("GET", "HEAD", "POST", "PUT", "PATCH", "DELETE", "OPTIONS")


def _allowed(request: Request) -> list[str]:
    """Every method a route of the app answers at the request's path.

    Starlette's router answers 405 from the first route whose path matched, naming that route's
    methods only: a path served by two routes (GET and POST /v1/jobs, GET and DELETE
    /v1/stations/{id}) named one. The routes are asked again, one method at a time (mounts, the
    static files, answer any method and say their own).
    """
    routes = [route for route in request.app.router.routes if not isinstance(route, Mount)]
    path, root = request.scope.get("path", ""), request.scope.get("root_path", "")

    def answers(method: str) -> bool:
        scope = {"type": "http", "path": path, "root_path": root, "method": method, "headers": []}
        return any(route.matches(dict(scope))[0] is Match.FULL for route in routes)

    return [method for method in _METHODS if answers(method)]


async def _http_error(request: Request, exc: StarletteHTTPException) -> JSONResponse:
    detail = exc.detail if isinstance(exc.detail, str) else json.dumps(exc.detail)
    if isinstance(exc, Problem):
        return problem_response(exc.status_code, detail, instance=_instance(request), kind=exc.kind.slug,
                                errors=exc.errors, headers=exc.headers, **exc.extensions)
    headers = exc.headers
    if exc.status_code == 405 and headers and "Allow" in headers:  # the router's 405
        headers = {**headers, "Allow": ", ".join(_allowed(request)) or headers["Allow"]}
    return problem_response(exc.status_code, detail, instance=_instance(request), headers=headers)


async def _invalid(request: Request, exc: RequestValidationError) -> JSONResponse:
    # FastAPI's default echoes each bad input back, which can hold NaN (not JSON, so a 500) or
    # a whole uploaded spec: only the place and the message are sent.
    raw = list(exc.errors())
    if any(e.get("type") == "json_invalid" for e in raw):
        # Not JSON at all: nothing in it can be pointed at (the OpenAPI document says 400).
        reason = next(str((e.get("ctx") or {}).get("error", e.get("msg"))) for e in raw
                      if e.get("type") == "json_invalid")
        return problem_response(400, f"the body is not valid JSON ({reason})", instance=_instance(request))
    sent_as = _not_json(request)
    if sent_as is not None and any(tuple(e.get("loc", ()))[:1] == ("body",) and e.get("type") != "missing"
                                   for e in raw):
        # FastAPI reads a body as JSON only when its Content-Type says it is: any other type (or
        # none) reached the model as text, which "should be a valid dictionary" at "" explained
        # to nobody.
        detail = (f"the body is sent {sent_as}, which this route does not read: send the JSON with "
                  "Content-Type: application/json")
        return problem_response(415, detail, instance=_instance(request), kind="unsupported-media-type",
                                errors=[{"header": "Content-Type", "detail": detail}])
    body = exc.body if exc.body is not None else _MISSING
    errors = validation_errors(raw, body)
    if not errors:
        errors = [{"pointer": "", "detail": "invalid request"}]
    return problem_response(422, _summary(errors), instance=_instance(request), errors=errors)


def _not_json(request: Request) -> str | None:
    """How the request's body is typed ("as Content-Type 'text/plain'", "without a Content-Type")
    when not as JSON (application/json or application/*+json, which FastAPI parses), else None."""
    sent = request.headers.get("content-type", "").strip()
    if not sent:
        return "without a Content-Type"
    kind = sent.split(";", 1)[0].strip().lower()
    json = kind == "application/json" or (kind.startswith("application/") and kind.endswith("+json"))
    return None if json else f"as Content-Type {sent!r}"


async def _backend_down(request: Request, exc: Exception) -> JSONResponse:
    log.error("backend unavailable on %s %s: %r", request.method, request.url.path, exc)
    return problem_response(503, "a storage backend is unavailable; try again shortly",
                            instance=_instance(request), headers={"Retry-After": "5"})


async def _unhandled(request: Request, exc: Exception) -> JSONResponse:
    # The traceback goes to the log (Starlette's error middleware re-raises after this answer);
    # the client gets nothing of the internals.
    log.error("unhandled error on %s %s: %r", request.method, request.url.path, exc)
    return problem_response(500, "the server failed to answer this request; it has been logged",
                            instance=_instance(request))


def install_handlers(app: FastAPI, backend_errors: Iterable[type[Exception]]) -> None:
    """Answer every error of `app` as a problem document."""
    app.add_exception_handler(StarletteHTTPException, _http_error)  # type: ignore[arg-type]
    app.add_exception_handler(RequestValidationError, _invalid)  # type: ignore[arg-type]
    for error in backend_errors:
        app.add_exception_handler(error, _backend_down)
    app.add_exception_handler(Exception, _unhandled)


# -- the OpenAPI document -------------------------------------------------------------------------

PROBLEM_SCHEMA: dict[str, Any] = {
    "type": "object",
    "title": "Problem",
    "description": "An error, as RFC 9457 problem details. Branch on `type`, show `detail`.",
    "required": ["type", "title", "status", "detail", "instance"],
    "properties": {
        "type": {"type": "string", "description": "Stable URI of the kind of error: "
                 + ", ".join(f"`{k.type}` ({k.status})" for k in KINDS.values())
                 + "; `about:blank` for any other status."},
        "title": {"type": "string", "description": "The kind of error, in words."},
        "status": {"type": "integer", "description": "The HTTP status code."},
        "detail": {"type": "string", "description": "What went wrong here, in one sentence."},
        "instance": {"type": "string", "description": "The request's path."},
        "errors": {"type": "array", "description": "Invalid input: each bad value and why.",
                   "items": {"$ref": "#/components/schemas/ProblemError"}},
    },
}
PROBLEM_ERROR_SCHEMA: dict[str, Any] = {
    "type": "object",
    "title": "ProblemError",
    "required": ["detail"],
    "properties": {
        "pointer": {"type": "string", "description": "RFC 6901 JSON pointer into the request body, "
                    "e.g. /items/0/points/p3 (\"\": the whole body)."},
        "parameter": {"type": "string", "description": "The query or path parameter at fault."},
        "header": {"type": "string", "description": "The request header at fault."},
        "detail": {"type": "string"},
    },
}
_REF = {"$ref": "#/components/schemas/Problem"}
_DEFAULT_DESCRIPTIONS = {400: "The body cannot be read (not JSON, cut multipart)",
                         415: "The body is not sent as application/json",
                         404: "Not found", 405: "Method not allowed",
                         422: "Invalid input: `errors` locates each bad value",
                         500: "Internal error (nothing of it is disclosed)"}


# The problem types an error status carries unless an operation names its own (a route's
# `responses` entry with "x-problem-types": [slug, ...]).
_TYPES_BY_STATUS = {**{status: [slug] for status, slug in _BY_STATUS.items()},
                    503: ["at-capacity", "backend-unavailable"]}
PROBLEM_TYPES = "x-problem-types"


def _declare_types(response: dict[str, Any], status: int) -> None:
    """The response's problem types as URIs in `x-problem-types` and named in its description,
    so a client (and the contract test) knows which refusals an operation gives."""
    slugs = [t.removeprefix(BASE) for t in response.get(PROBLEM_TYPES, _TYPES_BY_STATUS.get(status, []))]
    if not slugs:
        return
    response[PROBLEM_TYPES] = [KINDS[slug].type for slug in slugs]
    named = ", ".join(f"`{KINDS[slug].type}`" for slug in slugs)
    description = response.get("description", "").rstrip(".")
    if "Problem type" not in description:
        response["description"] = f"{description}. Problem type: {named}." if description else \
            f"Problem type: {named}."


def declare_problems(schema: dict[str, Any]) -> dict[str, Any]:
    """Make every error response of every operation in an OpenAPI document a Problem.

    Adds the components, replaces FastAPI's HTTPValidationError answers, and adds 500 (any
    operation can fail), 422 (operations with parameters or a body) and 415 (a JSON body sent
    as another type) where not declared. Each error response lists its problem types
    (`x-problem-types`, the URIs of `type`; the status's own kind unless the route named others).
    """
    components = schema.setdefault("components", {}).setdefault("schemas", {})
    components["Problem"] = PROBLEM_SCHEMA
    components["ProblemError"] = PROBLEM_ERROR_SCHEMA
    for path_item in schema.get("paths", {}).values():
        for method, op in path_item.items():
            if method not in ("get", "put", "post", "delete", "patch", "head", "options"):
                continue
            responses = op.setdefault("responses", {})
            takes_input = bool(op.get("parameters") or op.get("requestBody"))
            takes_json = "application/json" in op.get("requestBody", {}).get("content", {})
            wanted = [500] + ([422] if takes_input else []) + ([415] if takes_json else [])
            for code in wanted:
                responses.setdefault(str(code), {"description": _DEFAULT_DESCRIPTIONS[code]})
            for code, response in responses.items():
                if code.isdigit() and int(code) >= 400:
                    response["content"] = {MEDIA_TYPE: {"schema": _REF}}
                    _declare_types(response, int(code))
    used = json.dumps(schema.get("paths", {}))
    for name in ("HTTPValidationError", "ValidationError"):
        if f"#/components/schemas/{name}" not in used:
            components.pop(name, None)
    return schema
