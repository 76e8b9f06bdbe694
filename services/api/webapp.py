"""The web page: `web/` built by Vite into `static/`, served at /app/, with / redirecting there;
the API's docs, /docs (Swagger UI) and /redoc (ReDoc), from `static/docs/`; and the guide, the
docs site `scripts/docs` builds into `guide/`, at /guide/.

The page's key lives in the browser's sessionStorage, so the page is served with a strict
Content-Security-Policy: only this origin's own scripts, styles and API, nothing inline. The docs
pages load nothing from elsewhere either (no CDN: they work on a network without internet), and
start their viewers from files, not inline scripts; ReDoc writes its styles into <style>
elements, so their policy allows inline styles (never inline scripts).
"""

from __future__ import annotations

import html
from pathlib import Path

from fastapi import FastAPI, status
from fastapi.responses import HTMLResponse, PlainTextResponse, RedirectResponse
from starlette.responses import Response
from starlette.staticfiles import StaticFiles
from starlette.types import Receive, Scope, Send

__all__ = ["CSP", "DOCS_CSP", "GUIDE_CSP", "GUIDE_DIR", "STATIC_DIR", "mount_docs", "mount_guide",
           "mount_web"]

STATIC_DIR = Path(__file__).with_name("static")
GUIDE_DIR = Path(__file__).with_name("guide")
CSP = ("default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self' blob: data:; "
       "connect-src 'self' blob:; object-src 'none'; base-uri 'none'; frame-ancestors 'none'; "
       "form-action 'self'")
DOCS_CSP = ("default-src 'self'; script-src 'self'; style-src 'self' 'unsafe-inline'; "
            "img-src 'self' data: blob:; font-src 'self' data:; worker-src 'self' blob:; "
            "connect-src 'self'; object-src 'none'; base-uri 'none'; frame-ancestors 'none'; "
            "form-action 'self'")
# The guide is MkDocs Material's static site: its pages start the theme with small inline
# scripts, so those are allowed; everything else is this origin's (no fonts or CDN: theme.font off).
GUIDE_CSP = ("default-src 'self'; script-src 'self' 'unsafe-inline'; style-src 'self' 'unsafe-inline'; "
             "img-src 'self' data:; font-src 'self' data:; worker-src 'self' blob:; connect-src 'self'; "
             "object-src 'none'; base-uri 'none'; frame-ancestors 'none'; form-action 'self'")
GUIDE_NOT_BUILT = ("The guide has not been built here: run scripts/docs (it builds docs/ into "
                   "services/api/guide).")
NOT_BUILT = ("The web page has not been built here: run scripts/setup with node and npm installed "
             "(it runs npm ci and npm run build in web/).")


class _Page(StaticFiles):
    async def get_response(self, path: str, scope: Scope) -> Response:
        response = await super().get_response(path, scope)
        response.headers["Content-Security-Policy"] = CSP
        response.headers["X-Content-Type-Options"] = "nosniff"
        response.headers["Referrer-Policy"] = "no-referrer"
        # Vite names assets by their content hash, so they never change; index.html does.
        immutable = path.startswith("assets/")
        response.headers["Cache-Control"] = "public, max-age=31536000, immutable" if immutable else "no-cache"
        return response


def _home() -> RedirectResponse:
    # Relative, so that behind a proxy serving us under a prefix it stays under that prefix.
    return RedirectResponse("app/", status_code=status.HTTP_307_TEMPORARY_REDIRECT)


def _not_built() -> PlainTextResponse:
    return PlainTextResponse(NOT_BUILT, status_code=status.HTTP_404_NOT_FOUND)


def mount_web(app: FastAPI, directory: Path = STATIC_DIR) -> None:
    """Serve the built page from `directory` at /app/; without a build, /app/ says how to make one."""
    app.add_api_route("/", _home, methods=["GET", "HEAD"], include_in_schema=False)  # HEAD: monitors
    if (directory / "index.html").is_file():
        app.mount("/app", _Page(directory=directory, html=True), name="app")
    else:
        app.add_api_route("/app/{rest:path}", _not_built, methods=["GET"], include_in_schema=False)


# Relative URLs: under a proxy prefix the pages still load their own assets and the API's document.
_SWAGGER = """<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>{title} - Swagger UI</title>
<link rel="stylesheet" href="static/docs/swagger-ui.css">
<link rel="icon" type="image/png" href="static/docs/favicon-32x32.png">
</head><body><div id="swagger-ui"></div>
<script src="static/docs/swagger-ui-bundle.js"></script>
<script src="static/docs/swagger-init.js"></script>
</body></html>
"""
_REDOC = """<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>{title} - ReDoc</title>
<meta name="viewport" content="width=device-width, initial-scale=1">
<link rel="icon" type="image/png" href="static/docs/favicon-32x32.png">
</head><body><div id="redoc"></div>
<script src="static/docs/redoc.standalone.js"></script>
<script src="static/docs/redoc-init.js"></script>
</body></html>
"""


def _docs_page(template: str, title: str, directory: Path) -> Response:
    if not (directory / "swagger-init.js").is_file():
        return _not_built()
    return HTMLResponse(template.format(title=html.escape(title)), headers={
        "Content-Security-Policy": DOCS_CSP, "X-Content-Type-Options": "nosniff",
        "Referrer-Policy": "no-referrer", "Cache-Control": "no-cache"})


class _DocsAssets(StaticFiles):
    async def get_response(self, path: str, scope: Scope) -> Response:
        response = await super().get_response(path, scope)
        response.headers["X-Content-Type-Options"] = "nosniff"
        response.headers["Cache-Control"] = "no-cache"  # not content-hashed: revalidated
        return response


def mount_docs(app: FastAPI, directory: Path = STATIC_DIR / "docs") -> None:
    """Serve /docs and /redoc from `directory` (the web build copies their assets there).

    The app must be made with ``docs_url=None, redoc_url=None`` (FastAPI's own load a CDN).
    """
    app.add_api_route("/docs", lambda: _docs_page(_SWAGGER, app.title, directory), methods=["GET"],
                      include_in_schema=False)
    app.add_api_route("/redoc", lambda: _docs_page(_REDOC, app.title, directory), methods=["GET"],
                      include_in_schema=False)
    if directory.is_dir():
        app.mount("/static/docs", _DocsAssets(directory=directory), name="docs-assets")


class _Guide(StaticFiles):
    """The built docs site; looked for at each request, so a build made while the API runs shows."""

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if not (Path(str(self.directory)) / "index.html").is_file():
            response: Response = PlainTextResponse(GUIDE_NOT_BUILT, status_code=status.HTTP_404_NOT_FOUND)
            await response(scope, receive, send)
            return
        await super().__call__(scope, receive, send)

    async def get_response(self, path: str, scope: Scope) -> Response:
        response = await super().get_response(path, scope)
        response.headers["Content-Security-Policy"] = GUIDE_CSP
        response.headers["X-Content-Type-Options"] = "nosniff"
        response.headers["Referrer-Policy"] = "no-referrer"
        response.headers["Cache-Control"] = "no-cache"
        return response


def mount_guide(app: FastAPI, directory: Path = GUIDE_DIR) -> None:
    """Serve the docs site built in `directory` at /guide/ (without a build, it says how to make one)."""
    app.mount("/guide", _Guide(directory=directory, html=True, check_dir=False), name="guide")
