"""What the dashboard's and the box picker's FastAPI apps share: the page, its static files, error bodies.

Every refused request answers ``{"error": message, "field": name}``: a ``RequestError`` with its own
status (400 / 404 / 409), a malformed body with 422 and a message naming the field.
"""

from __future__ import annotations

from pathlib import Path

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import FileResponse, JSONResponse, Response
from fastapi.staticfiles import StaticFiles

from lerobot_bboxpick.apps.dashboard.errors import RequestError

STATIC_DIR = Path(__file__).resolve().parent / "static"


def _validation_message(error: RequestValidationError) -> tuple[str, str | None]:
    parts, field = [], None
    for item in error.errors():
        loc = [str(x) for x in item.get("loc", ()) if x != "body"]
        name = ".".join(loc) or "body"
        field = field or name
        got = f" (got {item['input']!r})" if "input" in item and not isinstance(item["input"], dict) else ""
        parts.append(f"{name}: {item.get('msg', 'invalid')}{got}")
    return "; ".join(parts) or "malformed request body", field


def install_common(app: FastAPI) -> None:
    """Add the page (``/``), ``/static``, and the JSON error handlers to ``app``."""
    app.mount("/static", StaticFiles(directory=STATIC_DIR), name="static")

    @app.get("/", include_in_schema=False)
    def index() -> FileResponse:
        return FileResponse(STATIC_DIR / "index.html", headers={"Cache-Control": "no-store"})

    @app.exception_handler(RequestError)
    async def request_error(_: Request, exc: RequestError) -> JSONResponse:
        return JSONResponse(exc.as_json(), status_code=exc.status)

    @app.exception_handler(RequestValidationError)
    async def validation_error(_: Request, exc: RequestValidationError) -> JSONResponse:
        message, field = _validation_message(exc)
        return JSONResponse({"error": message, "field": field}, status_code=422)


def jpeg_response(data: bytes | None, view: str, valid: tuple[str, ...]) -> Response:
    """The JPEG of a view, or a 404 naming the valid views."""
    if view not in valid:
        raise RequestError(
            f"view={view!r} is not known; valid views: {', '.join(valid)}", status=404, field="view"
        )
    if data is None:
        raise RequestError(f"view {view!r} has no frame yet (load a scene, or run)", status=404, field="view")
    return Response(data, media_type="image/jpeg", headers={"Cache-Control": "no-store"})
