"""The dashboard's web application: one page, one WebSocket, a broadcast of the live state.

``GET /`` serves the page; ``/static`` its script, style and the bundled
uPlot; ``/ws`` is the WebSocket.  The server pushes ``{"type": "state", ...}``
messages (the session's state, the RGB frame with the marker drawn and the
infrared frame in false colour, as base64 JPEG) at ``broadcast_hz`` to every
viewer through a :class:`~relaxgrip.dashboard.hub.Hub`; a viewer sends
controls ``{"id": n, "op": ..., "value": ...}`` and gets
``{"type": "reply", "id": n, "ok": ..., "error": ...}``, where ``error`` is
the one-line message of the :class:`~relaxgrip.errors.InputError` that
refused it (nothing changed).

With an access token, the page and the WebSocket need it as the ``token``
query parameter or the ``X-Relaxgrip-Token`` header, else 403.  The lifespan
starts the session's loop and, on shutdown, stops it: motor stopped, heaters
off.
"""

from __future__ import annotations

import asyncio
import base64
import contextlib
import json
import logging
import math
import secrets
from collections.abc import AsyncIterator, Callable
from importlib import resources
from typing import Any

import cv2
from fastapi import FastAPI, Request, WebSocket, WebSocketDisconnect
from fastapi.responses import HTMLResponse, Response
from fastapi.staticfiles import StaticFiles

from relaxgrip.dashboard.hub import Hub
from relaxgrip.dashboard.render import encode_jpeg, ir_view, rgb_view
from relaxgrip.dashboard.session import LiveSession
from relaxgrip.errors import InputError
from relaxgrip.serialize import json_safe

__all__ = ["TOKEN_HEADER", "create_app"]

TOKEN_HEADER = "x-relaxgrip-token"
_log = logging.getLogger(__name__)


def _b64(data: bytes) -> str:
    return base64.b64encode(data).decode("ascii")


class _Frames:
    """JPEGs of the latest frames, encoded once per new frame whoever watches."""

    def __init__(self, session: LiveSession, rgb_quality: int = 70) -> None:
        self.session = session
        self.rgb_quality = rgb_quality
        self._rgb: tuple[int, str | None] = (-2, None)
        self._ir: tuple[int, str | None] = (-2, None)

    def message(self) -> str:
        """The state message (JSON text)."""
        frames = self.session.frames()
        state = self.session.state()
        rig = self.session.controller.rig
        if frames.rgb_seq != self._rgb[0]:
            jpeg = None if frames.rgb is None else _b64(encode_jpeg(
                rgb_view(frames.rgb, frames.marker, rig), self.rgb_quality))
            self._rgb = (frames.rgb_seq, jpeg)
        if frames.ir_seq != self._ir[0]:
            jpeg = None if frames.ir is None else _b64(encode_jpeg(
                ir_view(frames.ir, rig, frames.aperture_m, beam_temps_c=frames.beam_temps_c)))
            self._ir = (frames.ir_seq, jpeg)
        state.update(type="state", rgb_jpeg=self._rgb[1], ir_jpeg=self._ir[1])
        return json.dumps(json_safe(state), allow_nan=False)


def _control(session: LiveSession, op: str, value: Any) -> dict[str, Any]:
    """Apply one control; the reply's extra fields."""

    def number() -> float:
        if isinstance(value, bool):  # float(True) is 1.0: a 1 N target, a 1 °C setpoint
            raise InputError(f"{op} needs a number, got {value!r}")
        try:
            out = float(value)
        except (TypeError, ValueError, OverflowError):
            raise InputError(f"{op} needs a number, got {str(value)[:40]!r}") from None
        if not math.isfinite(out):
            raise InputError(f"{op} needs a finite number, got {value!r}")
        return out

    def flag() -> bool:
        if not isinstance(value, bool):
            raise InputError(f"{op} needs true or false, got {str(value)[:40]!r}")
        return value

    actions: dict[str, Callable[[], Any]] = {
        "target": lambda: session.set_target(number()),
        "mode": lambda: session.set_mode(str(value)),
        "temperature": lambda: session.set_temperature(number()),
        "object": lambda: session.set_object(str(value)),
        "close": session.close_grasp,
        "hold": session.hold,
        "lift": session.lift,
        "release": session.release,
        "stop": session.stop,
        "record": lambda: session.set_recording(flag()),
    }
    if op not in actions:
        raise InputError(f"unknown control {op!r}; known: {', '.join(actions)}")
    result = actions[op]()
    return {"path": str(result)} if op == "record" and result is not None else {}


def create_app(session: LiveSession, *, token: str | None = None,
               broadcast_hz: float = 15.0, start_session: bool = True) -> FastAPI:
    """The dashboard application around a session.

    Parameters
    ----------
    session : LiveSession
        The live session (started by the lifespan unless ``start_session`` is false).
    token : str, optional
        Access token the page and the WebSocket must present; ``None``: none
        (for a server bound to the loopback interface only).
    broadcast_hz : float
        State messages per second to each viewer.
    start_session : bool
        Start the session's loop at startup (it is always closed at shutdown).

    Returns
    -------
    FastAPI
    """
    if not (math.isfinite(broadcast_hz) and broadcast_hz > 0):
        raise InputError(f"broadcast rate must be > 0 Hz, got {broadcast_hz}")
    hub = Hub()
    frames = _Frames(session)
    static = resources.files("relaxgrip.dashboard") / "static"

    async def broadcast() -> None:
        period = 1.0 / broadcast_hz
        loop = asyncio.get_running_loop()
        t_next = loop.time()
        failing = False
        while True:
            if hub.viewers:
                try:
                    message = await asyncio.to_thread(frames.message)
                except Exception:  # a fault of ours: logged once, the viewers still served
                    if not failing:
                        _log.exception("the dashboard's state message failed")
                    failing = True
                else:
                    failing = False
                    hub.publish(message)
            t_next += period
            t_next = max(t_next, loop.time())
            await asyncio.sleep(t_next - loop.time())

    @contextlib.asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        cv2.setNumThreads(1)
        if start_session:
            session.start()
        task = asyncio.create_task(broadcast())
        try:
            yield
        finally:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task
            await asyncio.to_thread(session.close)

    app = FastAPI(title="relaxgrip dashboard", lifespan=lifespan, docs_url=None,
                  redoc_url=None, openapi_url=None)
    app.state.hub = hub
    app.state.session = session

    def allowed(query: str | None, header: str | None) -> bool:
        if token is None:
            return True
        given = query if query is not None else header
        return given is not None and secrets.compare_digest(given.encode(), token.encode())

    @app.get("/", response_class=HTMLResponse)
    async def page(request: Request) -> Response:
        if not allowed(request.query_params.get("token"), request.headers.get(TOKEN_HEADER)):
            return Response("403: this dashboard needs its access token (?token=...)\n",
                            status_code=403, media_type="text/plain")
        return HTMLResponse((static / "index.html").read_text(encoding="utf-8"))

    @app.websocket("/ws")
    async def ws(websocket: WebSocket) -> None:
        if not allowed(websocket.query_params.get("token"), websocket.headers.get(TOKEN_HEADER)):
            await websocket.close(code=1008)  # before accept: the handshake gets 403
            return
        await websocket.accept()
        box = hub.subscribe()
        send_lock = asyncio.Lock()

        async def send(text: str) -> None:
            async with send_lock:
                await websocket.send_text(text)

        async def pump() -> None:
            while True:
                await send(await box.get())

        sender = asyncio.create_task(pump())
        try:
            while True:
                ident: Any = None
                try:
                    message = await websocket.receive()
                    if message["type"] == "websocket.disconnect":
                        raise WebSocketDisconnect(message.get("code", 1000))
                    if message.get("text") is None:
                        raise InputError("a control is JSON text, not a binary frame")
                    request = json.loads(message["text"])
                    if not isinstance(request, dict):
                        raise InputError("a control is a JSON object {id, op, value}")
                    if not isinstance(request.get("id"), str | int | float | None):
                        # Echoed in the reply: nested JSON could be too deep to encode.
                        raise InputError("a control's id is a number, a string or null")
                    ident = request.get("id")
                    extra = await asyncio.to_thread(_control, session, str(request.get("op")),
                                                    request.get("value"))
                    reply: dict[str, Any] = {"type": "reply", "id": ident, "ok": True,
                                             "error": None, **extra}
                except InputError as exc:
                    reply = {"type": "reply", "id": ident, "ok": False,
                             "error": str(exc).splitlines()[0]}
                except (ValueError, RecursionError):  # not JSON, or nested past decoding
                    reply = {"type": "reply", "id": None, "ok": False,
                             "error": "a control is a JSON object {id, op, value}"}
                except WebSocketDisconnect:
                    raise
                except Exception as exc:  # a fault of ours: said, logged, the viewer kept
                    _log.exception("control %r failed", ident)
                    reply = {"type": "reply", "id": ident, "ok": False,
                             "error": f"{type(exc).__name__}: {exc}".splitlines()[0]}
                await send(json.dumps(json_safe(reply), allow_nan=False))
        except WebSocketDisconnect:
            pass
        finally:
            hub.unsubscribe(box)
            sender.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await sender

    app.mount("/static", StaticFiles(directory=str(static)), name="static")
    return app
