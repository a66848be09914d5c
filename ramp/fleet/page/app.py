"""The page's web side (Starlette): the page, its files, the fleet as JSON, and commands.

The page polls `GET /api/fleet`; `POST /api/stop_all`, `/api/robot/{id}/pause`, `/resume` and
`/mission` publish instant actions and orders through the supervisor. Served on loopback: a
supervisor's machine opens it in its own browser.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from starlette.applications import Starlette
from starlette.requests import Request
from starlette.responses import FileResponse, JSONResponse, Response
from starlette.routing import Mount, Route
from starlette.staticfiles import StaticFiles

from ramp.fleet.page.supervisor import FleetSupervisor


def static_dir() -> Path:
    return Path(str(resources.files("ramp.fleet.page").joinpath("static")))


def create_app(supervisor: FleetSupervisor) -> Starlette:
    async def page(request: Request) -> Response:
        return FileResponse(static_dir() / "index.html")

    async def fleet(request: Request) -> Response:
        return JSONResponse(supervisor.snapshot(), headers={"Cache-Control": "no-store"})

    async def stop_all(request: Request) -> Response:
        return JSONResponse({"ok": True, "sent": supervisor.stop_all()})

    async def robot(request: Request) -> Response:
        """`pause`, `resume` or `mission` for one robot."""
        what = request.path_params["what"]
        key = f"{request.path_params['manufacturer']}/{request.path_params['serial']}"
        if what == "mission":
            why = supervisor.mission(key)
            return JSONResponse({"ok": why is None, "error": why},
                                status_code=200 if why is None else 409)
        if what not in ("pause", "resume"):
            return JSONResponse({"ok": False, "error": f"no command {what}"}, status_code=404)
        ok = supervisor.pause(key, what == "pause")
        return JSONResponse({"ok": ok}, status_code=200 if ok else 404)

    return Starlette(routes=[
        Route("/", page),
        Route("/api/fleet", fleet),
        Route("/api/stop_all", stop_all, methods=["POST"]),
        Route("/api/robot/{manufacturer}/{serial}/{what}", robot, methods=["POST"]),
        Mount("/static", StaticFiles(directory=static_dir()), name="static"),
    ])
