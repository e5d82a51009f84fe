"""The methods of a path: ``OPTIONS`` answered with every method the path's routes take (``Allow``), and a 405 (a
method the path does not take) with the same ``Allow``. The framework's own answer names the methods of the first
route matching the path only (``OPTIONS /v1/jobs/{id}`` said ``allow: GET`` although ``DELETE`` works)."""

from __future__ import annotations

from starlette.routing import Match

#: Methods every path takes besides its routes' own.
ALWAYS = ("OPTIONS",)
#: The methods asked about.
METHODS = ("GET", "HEAD", "POST", "PUT", "PATCH", "DELETE")


def allowed(app, scope) -> list[str]:
    """The methods the routes of ``scope``'s path take (and OPTIONS), sorted; [] for a path no route has. Each method
    is asked of the app's routes as the router itself asks (a full match), whatever their nesting."""
    methods = [m for m in METHODS if any(route.matches({**scope, "method": m})[0] is Match.FULL
                                         for route in app.router.routes)]
    return sorted(set(methods) | set(ALWAYS)) if methods else []


class Methods:
    """ASGI middleware: ``OPTIONS`` on a known path is 204 with ``Allow``; a 405 gets the path's whole ``Allow``."""

    def __init__(self, app):
        self.app = app

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        if scope["method"] == "OPTIONS":
            methods = allowed(scope["app"], scope)
            if methods:
                await send({"type": "http.response.start", "status": 204,
                            "headers": [(b"allow", ", ".join(methods).encode())]})
                await send({"type": "http.response.body", "body": b""})
                return
            return await self.app(scope, receive, send)

        async def sent(message):
            if message["type"] == "http.response.start" and message["status"] == 405:
                headers = [(k, v) for k, v in message.get("headers", []) if k.lower() != b"allow"]
                headers.append((b"allow", ", ".join(allowed(scope["app"], scope)).encode()))
                message = {**message, "headers": headers}
            await send(message)

        await self.app(scope, receive, sent)
