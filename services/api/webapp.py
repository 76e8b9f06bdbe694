"""The web page: `web/` built by Vite into `static/`, served at /app/, with / redirecting there.

The page's key lives in the browser's sessionStorage, so the page is served with a strict
Content-Security-Policy: only this origin's own scripts, styles and API, nothing inline.
"""

from __future__ import annotations

from pathlib import Path

from fastapi import FastAPI, status
from fastapi.responses import PlainTextResponse, RedirectResponse
from starlette.responses import Response
from starlette.staticfiles import StaticFiles
from starlette.types import Scope

__all__ = ["CSP", "STATIC_DIR", "mount_web"]

STATIC_DIR = Path(__file__).with_name("static")
CSP = ("default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self' blob: data:; "
       "connect-src 'self'; object-src 'none'; base-uri 'none'; frame-ancestors 'none'; "
       "form-action 'self'")
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
    app.add_api_route("/", _home, methods=["GET"], include_in_schema=False)
    if (directory / "index.html").is_file():
        app.mount("/app", _Page(directory=directory, html=True), name="app")
    else:
        app.add_api_route("/app/{rest:path}", _not_built, methods=["GET"], include_in_schema=False)
