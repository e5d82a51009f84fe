"""The OpenAPI docs page at ``/docs``, served with its Swagger UI assets from the service itself.

FastAPI's default page loads Swagger UI's script and style from a CDN, which a cell's network (or CI's) does not
reach. The assets come from the ``swagger-ui-bundle-v2`` package instead (Swagger UI 5, which renders the
OpenAPI 3.1 schema FastAPI writes) and are served under ``/docs/assets/``; only the files the page uses are served.
"""

from __future__ import annotations

import importlib
from pathlib import Path

from fastapi import FastAPI, HTTPException
from fastapi.openapi.docs import get_swagger_ui_html
from fastapi.responses import FileResponse, HTMLResponse

#: Where the page loads its assets from (same origin).
ASSETS = "/docs/assets"
#: The asset files served, with their media types.
FILES = {"swagger-ui-bundle.js": "text/javascript; charset=utf-8", "swagger-ui.css": "text/css; charset=utf-8",
         "favicon-32x32.png": "image/png"}


def swagger_ui_dir() -> Path:
    """The folder of the packaged Swagger UI (``swagger_ui_bundle.swagger_ui_path``)."""
    try:
        bundle = importlib.import_module("swagger_ui_bundle")  # (untyped: only its folder is used)
    except ImportError:  # pragma: no cover - a broken install
        raise RuntimeError("the docs page needs the package swagger-ui-bundle-v2 (pip install swagger-ui-bundle-v2)"
                           ) from None
    return Path(str(bundle.swagger_ui_path))


def add_docs(app: FastAPI, openapi_url: str = "/openapi.json") -> None:
    """Add ``GET /docs`` and ``GET /docs/assets/{name}`` to ``app`` (created with ``docs_url=None``)."""
    folder = swagger_ui_dir()
    missing = [name for name in FILES if not (folder / name).is_file()]
    if missing:
        raise RuntimeError(f"the packaged Swagger UI in {folder} lacks {', '.join(missing)}")

    @app.get("/docs", include_in_schema=False)
    def docs() -> HTMLResponse:
        return get_swagger_ui_html(openapi_url=openapi_url, title=f"{app.title} - API docs",
                                   swagger_js_url=f"{ASSETS}/swagger-ui-bundle.js",
                                   swagger_css_url=f"{ASSETS}/swagger-ui.css",
                                   swagger_favicon_url=f"{ASSETS}/favicon-32x32.png")

    @app.get(ASSETS + "/{name}", include_in_schema=False)
    def asset(name: str) -> FileResponse:
        if name not in FILES:  # a fixed list: no name from a request reaches the file system
            raise HTTPException(404, f"no docs asset {name}")
        return FileResponse(folder / name, media_type=FILES[name],
                            headers={"Cache-Control": "public, max-age=86400"})
