"""The dashboard server with Starlette's TestClient: state stream, controls, tokens, viewers."""

from __future__ import annotations

import base64
import json
import threading
import time
from typing import Any

import cv2
import numpy as np
import pytest

pytest.importorskip("fastapi")

from fastapi.testclient import TestClient
from starlette.websockets import WebSocketDisconnect

from relaxgrip.backend import Command
from relaxgrip.clock import WallClock
from relaxgrip.dashboard.app import TOKEN_HEADER, create_app
from relaxgrip.dashboard.session import LiveSession

TOKEN = "test-token-0123"
#: Where the test server says it is: a loopback address (the Host check refuses others).
BASE = "http://127.0.0.1:8000"


class Client(TestClient):
    """Starlette's test client, its WebSockets addressed to :data:`BASE` as its requests are
    (Starlette's own say ``Host: testserver``)."""

    def websocket_connect(self, url: str, subprotocols: Any = None, **kwargs: Any) -> Any:
        headers = {k.lower(): v for k, v in (kwargs.get("headers") or {}).items()}
        headers.setdefault("host", BASE.removeprefix("http://"))
        for name, value in self.headers.items():
            headers.setdefault(name.lower(), value)
        kwargs["headers"] = headers
        return super().websocket_connect(url, subprotocols, **kwargs)


def serve(session: LiveSession, **kwargs: Any) -> Client:
    """A test client of the dashboard around ``session``, its requests carrying the token."""
    return Client(create_app(session, token=TOKEN, **kwargs), base_url=BASE,
                  headers={TOKEN_HEADER: TOKEN})


class Spy:
    """A backend that records its commands and can be made to fail."""

    def __init__(self, inner, fail_after: int | None = None) -> None:
        self.inner = inner
        self.fail_after = fail_after
        self.observed = 0
        self.commands: list[Command] = []
        self.closed = False

    @property
    def info(self):
        return self.inner.info

    def reset(self, seed=None):
        return self.inner.reset(seed)

    def observe(self):
        self.observed += 1
        if self.fail_after is not None and self.observed > self.fail_after:
            raise OSError("camera unplugged")
        return self.inner.observe()

    def act(self, command: Command) -> None:
        self.commands.append(command)
        self.inner.act(command)

    def close(self) -> None:
        self.closed = True
        self.inner.close()


def _state(ws: Any, pred: Any = lambda s: True, max_messages: int = 200) -> Any:
    for _ in range(max_messages):
        msg = ws.receive_json()
        if msg["type"] == "state" and pred(msg):
            return msg
    raise AssertionError("no matching state message")


def _after(ws: Any, reply: Any) -> Any:
    """The first state message that shows the control ``reply`` answered (waits on state)."""
    assert reply["ok"], reply
    return _state(ws, lambda s: s["controls"] >= reply["applied"])


def _control(ws: Any, op: str, value: Any = None, ident: int = 1) -> Any:
    ws.send_json({"id": ident, "op": op, "value": value})
    for _ in range(200):
        msg = ws.receive_json()
        if msg["type"] == "reply" and msg["id"] == ident:
            return msg
    raise AssertionError("no reply")


def _decode(b64: str) -> Any:
    data = np.frombuffer(base64.b64decode(b64), dtype=np.uint8)
    return cv2.imdecode(data, cv2.IMREAD_COLOR)


@pytest.fixture
def served(make_session):
    session = make_session()
    spy = Spy(session.backend)
    session.backend = spy
    with serve(session) as client:
        yield client, session, spy
    # lifespan shut down:
    assert not session.alive
    assert spy.closed
    assert spy.commands[-1] == Command()  # motor stopped, heaters off


def test_state_messages_carry_the_live_view(served) -> None:
    client, _, _ = served
    page = client.get("/")
    assert page.status_code == 200
    assert "relaxgrip" in page.text
    assert client.get("/static/uPlot.iife.min.js").status_code == 200
    with client.websocket_connect("/ws") as ws:
        s = _state(ws, lambda s: s["rgb_jpeg"] is not None and s["ir_jpeg"] is not None
                   and s["marker"] == "tracking")
    assert s["phase"] == "done"
    assert s["backend"] == "twin"
    assert s["estimator"] == "observer"
    assert s["truth_n"] == pytest.approx(0.0, abs=1e-6)  # the twin's truth, shown
    assert s["mode"] == "stiff"
    assert s["setpoint_c"] is None
    assert all(20.0 < t < 35.0 for t in s["temps_c"])
    assert "hammer" in s["objects"]
    assert s["object"] == "force_ball"
    rgb, ir = _decode(s["rgb_jpeg"]), _decode(s["ir_jpeg"])
    assert rgb.shape == (480, 640, 3)
    assert ir.shape == (384, 512, 3)
    # The marker is drawn: the ArUco border colour (green) and the axes are on the frame.
    green = (rgb[:, :, 1] > 200) & (rgb[:, :, 0] < 60) & (rgb[:, :, 2] < 60)
    assert green.sum() > 20


def test_a_state_message_that_fails_is_logged_and_the_next_ones_go_out(
        make_session, monkeypatch, caplog) -> None:
    """The broadcast task had ended on the first exception, silently: the page froze."""
    from relaxgrip.dashboard import app as app_module

    calls = {"n": 0}
    original = app_module._Frames.message

    def flaky(self: Any) -> Any:
        calls["n"] += 1
        if calls["n"] <= 3:
            raise RuntimeError("a frame the encoder could not take")
        return original(self)

    monkeypatch.setattr(app_module._Frames, "message", flaky)
    session = make_session()
    with serve(session) as client, client.websocket_connect("/ws") as ws:
        assert _state(ws, lambda s: True)["type"] == "state"
    failed = [r for r in caplog.records if "state message failed" in r.getMessage()]
    assert len(failed) == 1  # once per streak of failures, not per message


def test_controls_change_the_loop_and_bad_values_change_nothing(served) -> None:
    client, session, _ = served
    with client.websocket_connect("/ws") as ws:
        three = _control(ws, "target", 3, 1)
        bad = _control(ws, "target", 12.5, 2)
        assert not bad["ok"]
        assert bad["error"] == "target force 12.5 N is outside (0, 10] N"
        assert "applied" not in bad
        assert not _control(ws, "target", "abc", 3)["ok"]
        assert _after(ws, three)["target_n"] == 3.0
        s = _after(ws, _control(ws, "mode", "medium", 4))
        assert s["mode"] == "medium"
        assert s["setpoint_c"] == 40.0
        lava = _control(ws, "mode", "lava", 5)
        assert not lava["ok"]
        assert "unknown stiffness mode 'lava'" in lava["error"]
        hot = _control(ws, "temperature", 95, 6)
        assert not hot["ok"]
        assert "\n" not in hot["error"]
        assert _state(ws)["setpoint_c"] == 40.0
        s = _after(ws, _control(ws, "temperature", 45, 7))
        assert s["mode"] is None
        assert s["setpoint_c"] == 45.0
        assert not _control(ws, "object", "anvil", 8)["ok"]
        assert _after(ws, _control(ws, "object", "hammer", 9))["object"] == "hammer"
        assert "nothing to release" in _control(ws, "release", None, 10)["error"]
        assert "nothing to hold" in _control(ws, "hold", None, 11)["error"]
        assert "unknown control" in _control(ws, "explode", None, 12)["error"]
        s = _after(ws, _control(ws, "close", None, 13))
        assert s["phase"] in ("open", "close", "hold")
        assert s["target_n"] == 3.0
        again = _control(ws, "close", None, 14)
        assert not again["ok"]
        assert "release first" in again["error"]
        assert not _control(ws, "object", "glass", 15)["ok"]  # not while grasping
        rec = _control(ws, "record", True, 16)
        assert rec["ok"]
        assert rec["path"].endswith(".mcap")
        assert _after(ws, rec)["recording"] == rec["path"]
        periods = session.periods
        _state(ws, lambda s: s["periods"] > periods + 10)  # a few periods recorded
        assert _control(ws, "record", False, 17)["ok"]
        s = _after(ws, _control(ws, "stop", None, 18))
        assert s["phase"] == "stopped"
        assert s["recording"] is None
        assert s["duty"] == [0.0, 0.0]
        assert s["temp_status"] == "off"  # the loop's, not the last one before the stop
    from relaxgrip.recording import read_session

    assert read_session(session.record_dir / rec["path"].split("/")[-1])["backend"]["name"] \
        == "twin"


def _refused_ws(client: Client, path: str, **headers: str) -> int:
    """The close code of a WebSocket the server refuses before its handshake completes."""
    with pytest.raises(WebSocketDisconnect) as info, \
            client.websocket_connect(path, headers=headers) as ws:
        ws.receive_json()
    return int(info.value.code)


def test_the_token_is_required_for_the_page_the_api_and_the_websocket(make_session) -> None:
    """Without a valid token: 403 (HTTP), 1008 (WebSocket), and nothing changed."""
    session = make_session()
    token = TOKEN
    with Client(create_app(session, token=token), base_url=BASE) as client:
        for bad in ("", "?token=wrong-token-0123", "?token="):
            assert client.get(f"/{bad}").status_code == 403
            assert client.get(f"/api/state{bad}").status_code == 403
            assert _refused_ws(client, f"/ws{bad}") == 1008
        wrong = {TOKEN_HEADER: "wrong-token-0123"}
        assert client.get("/", headers=wrong).status_code == 403
        assert client.get("/", headers={"Authorization": "token nope-nope-nope"}
                          ).status_code == 403
        control = json.dumps({"op": "target", "value": 2.5})
        for headers in ({}, wrong, {"Authorization": "Bearer " + token}):
            assert client.post("/api/control", content=control,
                               headers=headers).status_code == 403
        assert _refused_ws(client, "/ws", **wrong) == 1008
        assert session.state()["target_n"] == 5.0  # nothing changed
        # The token in the query, in the header, or as "Authorization: token ...":
        assert client.get(f"/?token={token}").status_code == 200
        assert client.get("/", headers={TOKEN_HEADER: token}).status_code == 200
        reply = client.post("/api/control", content=control,
                            headers={"Authorization": f"token {token}"})
        assert reply.status_code == 200, reply.text
        assert reply.json()["ok"]
        state = client.get(f"/api/state?token={token}").json()
        assert state["target_n"] == 2.5
        assert state["backend"] == "twin"
        with client.websocket_connect(f"/ws?token={token}") as ws:
            assert _state(ws)["backend"] == "twin"
        with client.websocket_connect("/ws", headers={TOKEN_HEADER: token}) as ws:
            assert _state(ws)["target_n"] == 2.5
        # The static files hold no state: served without the token.
        assert client.get("/static/dashboard.js").status_code == 200
        refused = client.post("/api/control", content='{"op": "target", "value": 50}',
                              headers={TOKEN_HEADER: token})
        assert refused.status_code == 400
        assert refused.json()["error"] == "target force 50.0 N is outside (0, 10] N"


def test_other_hosts_and_other_origins_are_refused_even_with_the_token(make_session) -> None:
    """DNS rebinding (a foreign Host) and a foreign page (its Origin) change nothing."""
    session = make_session()
    with serve(session) as client:
        for host in ("evil.example", "127.0.0.1.evil.example", "localhost.evil.example"):
            assert client.get("/", headers={"Host": host}).status_code == 403
            assert client.get("/static/dashboard.js", headers={"Host": host}
                              ).status_code == 403
            assert _refused_ws(client, "/ws", Host=host) == 1008
        for host in ("localhost:8000", "127.0.0.1", "[::1]:8000", "127.0.0.2:80"):
            assert client.get("/", headers={"Host": host}).status_code == 200, host
        control = json.dumps({"op": "temperature", "value": 60})
        for origin in ("http://evil.example", "null", "http://127.0.0.1:9999",
                       "https://127.0.0.1:8000.evil.example", "file://"):
            assert _refused_ws(client, "/ws", Origin=origin) == 1008
            assert client.post("/api/control", content=control,
                               headers={"Origin": origin}).status_code == 403
            assert client.get("/api/state", headers={"Origin": origin}).status_code == 403
        assert session.state()["setpoint_c"] != 60.0
        with client.websocket_connect("/ws", headers={"Origin": BASE}) as ws:
            assert _control(ws, "temperature", 45)["ok"]  # the dashboard's own page
    # Bound for remote access, any host name may be used (the token protects it).
    with serve(make_session(), loopback_only=False) as client:
        assert client.get("/", headers={"Host": "rig-1.lab:8000"}).status_code == 200
        assert client.get("/", headers={"Host": "rig-1.lab:8000",
                                        TOKEN_HEADER: "wrong-token-0123"}).status_code == 403
        assert _refused_ws(client, "/ws", Host="rig-1.lab:8000",
                           Origin="http://evil.example") == 1008


def test_a_bad_token_is_refused_when_the_app_is_made(make_session) -> None:
    from relaxgrip.errors import InputError

    session = make_session()
    for token in ("", "short", "has space in it", "x" * 300):
        with pytest.raises(InputError, match="access token must be 8-256 characters"):
            create_app(session, token=token)


def test_four_viewers_each_get_at_least_10_updates_per_second(served) -> None:
    client, _, _ = served
    window_s = 2.0
    counts: list[int] = []
    times: list[list[float]] = []
    lock = threading.Lock()
    sockets = [client.websocket_connect("/ws") for _ in range(4)]
    conns = [s.__enter__() for s in sockets]
    try:
        for ws in conns:
            _state(ws)  # connected and streaming

        def watch(ws) -> None:
            seen: list[float] = []
            t0 = time.monotonic()
            while time.monotonic() - t0 < window_s:
                msg = ws.receive_json()
                if msg["type"] == "state":
                    seen.append(msg["t_s"])
            with lock:
                counts.append(len(seen))
                times.append(seen)

        threads = [threading.Thread(target=watch, args=(ws,)) for ws in conns]
        for t in threads:
            t.start()
        for t in threads:
            t.join(10.0)
    finally:
        for s in sockets:
            s.__exit__(None, None, None)
    assert len(counts) == 4
    rates = [n / window_s for n in counts]
    print(f"updates per second, 4 viewers: {[round(r, 1) for r in rates]}")
    assert min(rates) >= 10.0
    for seen in times:  # live: the loop time advances between messages
        assert seen[-1] - seen[0] > 1.0


def test_loop_death_stops_motor_and_heaters_and_shows_the_error(make_session) -> None:
    session = make_session()
    spy = Spy(session.backend, fail_after=20)
    session.backend = spy
    session.set_mode("compliant")  # heaters on while it runs
    with serve(session) as client, client.websocket_connect("/ws") as ws:
        s = _state(ws, lambda s: s["error"] is not None)
        assert s["error"] == "control loop stopped: OSError: camera unplugged"
        assert not s["alive"]
        assert spy.commands[-1] == Command()
        assert any(c.heater_duty != (0.0, 0.0) for c in spy.commands)
        assert "camera unplugged" in _control(ws, "close")["error"]


def test_a_dead_loop_does_not_show_the_heaters_on(make_session) -> None:
    # The loop's last command switched the heaters off: the page must not read them on.
    session = make_session()
    session.backend = Spy(session.backend, fail_after=20)
    session.set_mode("compliant")  # heating at full duty when the loop dies
    with serve(session) as client, client.websocket_connect("/ws") as ws:
        s = _state(ws, lambda s: s["error"] is not None)
        assert s["duty"] == [0.0, 0.0]
        assert s["phase"] == "stopped"
        assert s["setpoint_c"] is None or np.isnan(s["setpoint_c"])


def test_session_refuses_bad_construction() -> None:
    from relaxgrip.errors import InputError

    with pytest.raises(InputError, match="control rate"):
        LiveSession(None, None, WallClock(), rate_hz=0.0)  # type: ignore[arg-type]


def test_emulated_mcu_watchdog_does_not_see_the_start_up(tmp_path) -> None:
    """The web server starts between the session's reset and its loop: longer than the
    MCU's 200 ms watchdog. The emulator's virtual time carries on from the reset."""
    from relaxgrip.dashboard.session import open_session

    session = open_session("emulator", clock=WallClock(), record_dir=tmp_path)
    try:
        time.sleep(0.5)
        session.start()
        deadline = time.monotonic() + 10.0
        while session.periods < 15 and session.alive and time.monotonic() < deadline:
            time.sleep(0.05)
        assert session.error is None
        assert session.alive
        assert session.periods >= 15
    finally:
        session.close()


def test_rearm_runs_in_the_loop_before_the_first_period(make_session) -> None:
    session = make_session()
    calls: list[tuple[str, int]] = []
    spy = Spy(session.backend)
    session.backend = spy
    session._rearm = lambda: calls.append((threading.current_thread().name, spy.observed))
    session.start()
    try:
        deadline = time.monotonic() + 10.0
        while session.periods < 3 and time.monotonic() < deadline:
            time.sleep(0.02)
    finally:
        session.close()
    assert calls == [("relaxgrip-loop", 0)]


def test_malformed_controls_get_a_reply_and_keep_the_viewer(served) -> None:
    client, session, _ = served

    def reply(ws: Any) -> Any:
        for _ in range(200):
            msg = ws.receive_json()
            if msg["type"] == "reply":
                return msg
        raise AssertionError("no reply")

    with client.websocket_connect("/ws") as ws:
        ws.send_text('{"id": 1, "op": "target", "value": 1' + "0" * 400 + "}")
        assert "target needs a number" in reply(ws)["error"]
        ws.send_text('{"id": 2, "op": "target", "value": 1' + "0" * 5000 + "}")
        assert reply(ws)["error"] == "a control is a JSON object {id, op, value}"
        ws.send_text("[" * 100_000)
        assert reply(ws)["error"] == "a control is a JSON object {id, op, value}"
        ws.send_bytes(b'{"id": 3, "op": "stop"}')
        assert reply(ws)["error"] == "a control is JSON text, not a binary frame"
        # An id nested too deep to encode in the reply: refused before it acts.
        ws.send_text('{"id": %s, "op": "target", "value": 6}' % ("[" * 800 + "]" * 800))
        assert reply(ws) == {"type": "reply", "id": None, "ok": False,
                             "error": "a control's id is a number, a string or null"}
        assert _state(ws)["target_n"] != 6.0
        for value in ("false", 0, None):
            assert "record needs true or false" in _control(ws, "record", value, 4)["error"]
        assert _state(ws)["recording"] is None
        # JSON true is no number: Python's float(True) would have set a 1 N target.
        assert _control(ws, "target", True, 6)["error"] == "target needs a number, got True"
        assert _state(ws)["target_n"] != 1.0
        assert _control(ws, "target", 4, 5)["ok"]  # the same viewer, still served
    assert session.alive


def test_a_session_runs_the_models_and_observer_it_is_given(make_session, tmp_path) -> None:
    """``--models`` and ``--observer``: a lab's own estimator on its own gripper."""
    import shutil

    from relaxgrip.errors import InputError
    from relaxgrip.learning.observer import default_observer_dir, load_observer, set_band_scale
    from relaxgrip.learning.training import default_models_dir

    directory = tmp_path / "observer"
    shutil.copytree(default_observer_dir(), directory)
    set_band_scale(directory, 0.5, {"method": "a test's"})
    session = make_session(estimator="observer", models_dir=default_models_dir(),
                           observer_dir=directory)
    try:
        assert session.controller.estimator.model.band_scale == 0.5
        assert load_observer(default_observer_dir()).band_scale != 0.5
    finally:
        session.close()
    with pytest.raises(InputError, match="not an observer model directory"):
        make_session(observer_dir=tmp_path / "none")


def test_a_disk_too_full_to_start_a_recording_refuses_it_in_one_line(make_session,
                                                                     monkeypatch) -> None:
    """Room for the MCAP header and not for the channels and first records: the Record
    control is refused with one line (the page shows it), and the grasp goes on."""
    pytest.importorskip("mcap")
    from relaxgrip.errors import InputError
    from tests.recording.test_bad_input import filling_disk

    filling_disk(monkeypatch, 3_000)
    session = make_session()
    session.start()
    try:
        with pytest.raises(InputError) as info:
            session.set_recording(True)
        message = str(info.value)
        assert message.startswith("cannot record to ")
        assert "No space left on device" in message
        assert "\n" not in message
        assert session.state()["recording"] is None
        periods = session.periods
        time.sleep(0.3)
        assert session.alive
        assert session.periods > periods
    finally:
        session.close()


def test_a_full_disk_stops_the_recording_not_the_loop(make_session, monkeypatch) -> None:
    """The recording ends sealed and says why on the page; the grasp goes on, and the next
    recording (another file) starts clean."""
    pytest.importorskip("mcap")
    from relaxgrip.recording.reader import iter_messages
    from tests.recording.test_bad_input import filling_disk

    filling_disk(monkeypatch, 1_500_000)
    session = make_session()
    session.start()
    try:
        path = session.set_recording(True)
        deadline = time.monotonic() + 60.0
        while session.record_error is None and time.monotonic() < deadline:
            time.sleep(0.05)
        assert session.record_error is not None, "the recording never filled the disk"
        assert session.record_error.startswith(f"recording {path} stopped: No space left on "
                                               "device; the recording stops, sealed at its "
                                               "last complete chunk (")
        periods = session.periods
        state = session.state()
        assert state["recording"] is None
        assert state["error"] == session.record_error
        time.sleep(0.3)
        assert session.alive
        assert session.periods > periods
        assert sum(1 for _ in iter_messages(path)) > 10  # sealed: complete, read strictly
        assert session.set_recording(True) != path
        assert session.record_error is None
        assert session.state()["error"] is None
    finally:
        session.close()


def test_a_new_viewer_gets_the_live_state_not_one_cached_when_the_last_left(served) -> None:
    """The broadcast stops with nobody watching: the hub's last message went stale."""
    client, session, _ = served
    with client.websocket_connect("/ws") as ws:
        first = _state(ws)
    periods = session.periods
    deadline = time.monotonic() + 30.0
    while session.periods < periods + 45:  # the loop runs on, 1.5 s of it, unwatched
        assert time.monotonic() < deadline
        time.sleep(0.02)
    now_s = session.state()["t_s"]
    assert now_s > first["t_s"] + 1.0
    with client.websocket_connect("/ws") as ws:
        again = ws.receive_json()  # the very first message
    assert again["type"] == "state"
    assert again["t_s"] >= now_s
