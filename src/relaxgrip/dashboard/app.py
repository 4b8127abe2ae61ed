"""The dashboard's web application: one page, one WebSocket, a small API, the live state.

``GET /`` serves the page; ``/static`` its script, style and the bundled
uPlot; ``/ws`` is the WebSocket; ``GET /api/state`` the state as JSON and
``POST /api/control`` one control (``{"op": ..., "value": ...}``), for
programs.  The server pushes ``{"type": "state", ...}`` messages (the
session's state, the RGB frame with the marker drawn and the infrared frame
in false colour, as base64 JPEG) at ``broadcast_hz`` to every viewer through
a :class:`~relaxgrip.dashboard.hub.Hub`, and one at once to a viewer that
connects and after every control; a viewer sends controls
``{"id": n, "op": ..., "value": ...}`` and gets
``{"type": "reply", "id": n, "ok": ..., "error": ...}``, where ``error`` is
the one-line message of the :class:`~relaxgrip.errors.InputError` that
refused it (nothing changed).

Every request but the static files needs the access token and passes the
Host and Origin checks of :mod:`relaxgrip.dashboard.access`, on loopback too:
403, or a WebSocket closed with 1008, otherwise.  The lifespan starts the
session's loop and, on shutdown, stops it: motor stopped, heaters off.
"""

from __future__ import annotations

import asyncio
import base64
import contextlib
import json
import logging
import math
from collections.abc import AsyncIterator, Callable
from importlib import resources
from typing import Any

import cv2
from fastapi import FastAPI, Request, WebSocket, WebSocketDisconnect
from fastapi.responses import HTMLResponse, Response
from fastapi.staticfiles import StaticFiles

from relaxgrip.dashboard.access import TOKEN_HEADER, AccessGuard, check_token
from relaxgrip.dashboard.hub import Hub
from relaxgrip.dashboard.render import encode_jpeg, ir_view, rgb_view
from relaxgrip.dashboard.session import LiveSession
from relaxgrip.errors import InputError
from relaxgrip.serialize import json_safe

__all__ = ["TOKEN_HEADER", "create_app"]

#: Headers of the page: never framed (clickjacking), its URL (with the token) never sent on.
_PAGE_HEADERS = {"Content-Security-Policy": "frame-ancestors 'none'",
                 "X-Frame-Options": "DENY", "Referrer-Policy": "no-referrer",
                 "Cache-Control": "no-store"}
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
    """Apply one control; the reply's extra fields.

    ``applied`` is the number of controls the session has taken, this one
    included: a state message whose ``controls`` has reached it shows the
    control's effect (a client waits on that, not on time).
    """

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
    extra: dict[str, Any] = {"applied": session.count_control()}
    if op == "record" and result is not None:
        extra["path"] = str(result)
    return extra


def create_app(session: LiveSession, *, token: str, loopback_only: bool = True,
               broadcast_hz: float = 15.0, start_session: bool = True) -> FastAPI:
    """The dashboard application around a session.

    Parameters
    ----------
    session : LiveSession
        The live session (started by the lifespan unless ``start_session`` is false).
    token : str
        Access token every request but the static files must present
        (:func:`~relaxgrip.dashboard.access.check_token`).
    loopback_only : bool
        The server is bound to the loopback interface: requests addressed to
        any other host name are refused (DNS rebinding).
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

    async def publish_now() -> None:
        """A fresh state to every viewer at once (after a control, for a new viewer)."""
        # A failure is the periodic broadcast's to log; a control's reply is not held up.
        with contextlib.suppress(Exception):
            message = await asyncio.to_thread(frames.message)
            if hub.viewers:
                hub.publish(message)

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
                    if hub.viewers:  # the last one may have left while it was made
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
    # Checked here, not at the first request (the middleware is built then).
    app.add_middleware(AccessGuard, token=check_token(token, "access token"),
                       loopback_only=loopback_only)

    @app.get("/", response_class=HTMLResponse)
    async def page() -> Response:
        return HTMLResponse((static / "index.html").read_text(encoding="utf-8"),
                            headers=_PAGE_HEADERS)

    @app.get("/api/state")
    async def api_state() -> Response:
        state = await asyncio.to_thread(session.state)
        return Response(json.dumps(json_safe(state), allow_nan=False),
                        media_type="application/json", headers={"Cache-Control": "no-store"})

    @app.post("/api/control")
    async def api_control(request: Request) -> Response:
        reply = await _reply(session, await request.body(), with_id=False)
        await publish_now()
        return Response(json.dumps(json_safe(reply), allow_nan=False),
                        status_code=200 if reply["ok"] else 400,
                        media_type="application/json")

    @app.websocket("/ws")
    async def ws(websocket: WebSocket) -> None:
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
        await publish_now()  # the live state at once, not one cached before this viewer came
        try:
            while True:
                message = await websocket.receive()
                if message["type"] == "websocket.disconnect":
                    raise WebSocketDisconnect(message.get("code", 1000))
                if message.get("text") is None:
                    reply = _refused(None, "a control is JSON text, not a binary frame")
                else:
                    reply = await _reply(session, message["text"], with_id=True)
                    await publish_now()
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


def _refused(ident: Any, error: str) -> dict[str, Any]:
    return {"type": "reply", "id": ident, "ok": False, "error": error}


async def _reply(session: LiveSession, text: str | bytes, *, with_id: bool) -> dict[str, Any]:
    """Apply one control given as JSON text; the reply (its ``error`` one line)."""
    ident: Any = None
    try:
        request = json.loads(text)
        if not isinstance(request, dict):
            raise InputError("a control is a JSON object {id, op, value}")
        if with_id and not isinstance(request.get("id"), str | int | float | None):
            # Echoed in the reply: nested JSON could be too deep to encode.
            raise InputError("a control's id is a number, a string or null")
        ident = request.get("id") if with_id else None
        extra = await asyncio.to_thread(_control, session, str(request.get("op")),
                                        request.get("value"))
    except InputError as exc:
        return _refused(ident, str(exc).splitlines()[0])
    except (ValueError, RecursionError):  # not JSON, or nested past decoding
        return _refused(None, "a control is a JSON object {id, op, value}")
    except Exception as exc:  # a fault of ours: said, logged, the viewer kept
        _log.exception("control %r failed", ident)
        return _refused(ident, f"{type(exc).__name__}: {exc}".splitlines()[0])
    return {"type": "reply", "id": ident, "ok": True, "error": None, **extra}
