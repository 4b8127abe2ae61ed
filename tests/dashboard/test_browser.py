"""The dashboard in a real browser (Chromium, Playwright): the operator's page works, a
foreign page cannot reach it, and the README screenshot can be made.

The screenshot goes to the test's temporary folder; to refresh the README's
image, run ``RELAXGRIP_SCREENSHOT=docs/dashboard.png python3 -m pytest
tests/dashboard/test_browser.py``.
"""

from __future__ import annotations

import contextlib
import json
import os
import threading
import time
import urllib.request
from collections.abc import Iterator
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any

import pytest

from tests.dashboard.conftest import TOKEN, dashboard_process, free_port

CHROMIUM = Path("/usr/lib/chromium/chromium")
ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
        "--disable-component-update", "--disable-sync", "--no-first-run"]

pytestmark = pytest.mark.skipif(
    not CHROMIUM.exists(),
    reason=f"no Chromium at {CHROMIUM} (apt-get install chromium): browser test skipped")


@pytest.fixture
def server(tmp_path):
    """The dashboard on a free loopback port: the operator's URL (with the token) and the port."""
    with dashboard_process(tmp_path) as (_, port):
        yield f"http://127.0.0.1:{port}/?token={TOKEN}", port


def _number(page: Any, selector: str) -> float:
    text = page.text_content(selector) or ""
    try:
        return float(text)
    except ValueError:
        return float("nan")


def test_grasp_at_3n_mode_switch_and_range_error(server, tmp_path) -> None:
    server, _ = server
    screenshot = Path(os.environ.get("RELAXGRIP_SCREENSHOT") or tmp_path / "dashboard.png")
    sync_api = pytest.importorskip("playwright.sync_api")
    with sync_api.sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=str(CHROMIUM), args=ARGS)
        try:
            page = browser.new_page(viewport={"width": 1280, "height": 1000})
            page.goto(server)
            page.wait_for_function("document.getElementById('conn').textContent === 'live'")
            page.wait_for_function("document.getElementById('phase').textContent === 'done'")
            page.wait_for_function("Number(document.body.dataset.updates || 0) > 5")
            page.fill("#target-input", "3")
            page.click("#target-set")
            page.wait_for_function("document.getElementById('target').textContent === '3.00'")
            assert page.is_hidden("#error")
            page.click("#btn-close")
            page.wait_for_function("document.getElementById('phase').textContent === 'hold'",
                                   timeout=40_000)
            # Settled: the estimate within ±0.3 N of 3 N over two seconds of updates.
            settled: list[float] = []
            t0 = time.monotonic()
            while time.monotonic() - t0 < 25 and len(settled) < 10:
                est = _number(page, "#estimate")
                settled = [*settled, est] if abs(est - 3.0) <= 0.3 else []
                time.sleep(0.2)
            assert len(settled) >= 10, f"estimate did not settle near 3 N: {settled}"
            assert abs(_number(page, "#truth") - 3.0) < 1.0  # the twin's truth shown too
            page.select_option("#mode-select", "medium")
            page.click("#mode-set")
            page.wait_for_function("document.getElementById('mode').textContent === 'medium'")
            page.wait_for_function("document.getElementById('setpoint').textContent === '40.0'")
            assert page.is_hidden("#error")
            page.fill("#target-input", "15")
            page.click("#target-set")
            page.wait_for_selector("#error:not([hidden])")
            assert page.text_content("#error") == "target force 15.0 N is outside (0, 10] N"
            assert page.text_content("#target") == "3.00"  # unchanged
            time.sleep(1.0)  # a second of plot after the switch
            screenshot.parent.mkdir(parents=True, exist_ok=True)
            page.screenshot(path=str(screenshot), full_page=True)
            assert screenshot.stat().st_size > 10_000  # a rendered page, not an empty image
            print(f"estimate {settled[-1]:.3f} N; screenshot {screenshot}")
        finally:
            browser.close()


#: A page of another origin that tries every way a web page has to reach the dashboard:
#: WebSockets with and without the token, cross-site fetches and a form post.  Each
#: WebSocket attempt reports whether it opened or got a message; the fetches cannot see
#: their answers (no CORS), so whether they changed anything is read from the dashboard.
_FOREIGN_PAGE = """<!DOCTYPE html><html><body><form id="f" method="post" target="sink"
enctype="text/plain"><input name='{"op":"close","value":null,"x":"' value='"}'></form>
<iframe name="sink"></iframe><script>
const base = "127.0.0.1:%(port)d", token = "%(token)s";
const results = [];
function tryWs(name, url, ops) {
  return new Promise((done) => {
    const r = { name: name, opened: false, messages: 0 };
    let ws;
    try { ws = new WebSocket(url); }
    catch (e) { r.error = String(e); results.push(r); done(); return; }
    ws.onopen = () => { r.opened = true;
      ops.forEach((op, i) => ws.send(JSON.stringify({ id: i, op: op[0], value: op[1] }))); };
    ws.onmessage = () => { r.messages += 1; };
    ws.onclose = (e) => { r.code = e.code; results.push(r); done(); };
    setTimeout(() => { try { ws.close(); } catch (e) {} }, 3000);
  });
}
function tryFetch(name, url, init) {
  // An opaque answer (no-cors) is one the page cannot read: what it did shows in the state.
  return fetch(url, init).then((resp) => { results.push({ name: name,
      readable: resp.type !== "opaque", status: resp.status }); },
    (e) => { results.push({ name: name, readable: false, error: String(e) }); });
}
(async () => {
  const hot = [["temperature", 65], ["mode", "compliant"], ["target", 9.5], ["close", null],
               ["record", true]];
  await tryWs("ws without token", `ws://${base}/ws`, hot);
  await tryWs("ws with the token", `ws://${base}/ws?token=${token}`, hot);
  await tryFetch("post control, no-cors, token in the query",
                 `http://${base}/api/control?token=${token}`,
                 { method: "POST", mode: "no-cors", body: '{"op": "temperature", "value": 65}' });
  await tryFetch("post control, cors, token header", `http://${base}/api/control`,
                 { method: "POST", headers: { "X-Relaxgrip-Token": token },
                   body: '{"op": "target", "value": 9.5}' });
  await tryFetch("read state, cors", `http://${base}/api/state?token=${token}`, {});
  const form = document.getElementById("f");
  form.action = `http://${base}/api/control?token=${token}`;
  form.submit();
  await new Promise((r) => setTimeout(r, 1500));
  results.push({ name: "form post of close" });
  document.title = "done";
})();
</script></body></html>"""


@contextlib.contextmanager
def _foreign_site(port: int) -> Iterator[str]:
    """A web server of another origin (another port) serving :data:`_FOREIGN_PAGE`."""
    page = (_FOREIGN_PAGE % {"port": port, "token": TOKEN}).encode()

    class Handler(BaseHTTPRequestHandler):
        def do_GET(self) -> None:
            self.send_response(200)
            self.send_header("Content-Type", "text/html")
            self.send_header("Content-Length", str(len(page)))
            self.end_headers()
            self.wfile.write(page)

        def log_message(self, *args: Any) -> None:
            pass

    httpd = ThreadingHTTPServer(("127.0.0.1", free_port()), Handler)
    thread = threading.Thread(target=httpd.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{httpd.server_address[1]}/"
    finally:
        httpd.shutdown()
        httpd.server_close()


def _state(port: int) -> Any:
    request = urllib.request.Request(f"http://127.0.0.1:{port}/api/state",
                                     headers={"X-Relaxgrip-Token": TOKEN})
    with urllib.request.urlopen(request, timeout=10) as r:
        return json.loads(r.read())


def test_a_page_of_another_origin_cannot_connect_or_command_and_the_operator_can(
        server) -> None:
    """Even knowing the token, a foreign page (another origin, or a rebound host name) gets
    no WebSocket open and no control taken; the operator's page then connects and commands."""
    url, port = server
    sync_api = pytest.importorskip("playwright.sync_api")
    before = _state(port)
    with sync_api.sync_playwright() as pw, _foreign_site(port) as foreign:
        # evil.test resolves to the loopback: a DNS rebinding attack's second answer.
        browser = pw.chromium.launch(executable_path=str(CHROMIUM), args=[
            *ARGS, "--host-resolver-rules=MAP evil.test 127.0.0.1"])
        try:
            page = browser.new_page()
            page.goto(foreign)
            page.wait_for_function("document.title === 'done'", timeout=30_000)
            attempts = page.evaluate("results")
            rebound = browser.new_page()
            answer = rebound.goto(f"http://evil.test:{port}/?token={TOKEN}")
            assert answer is not None
            attempts.append({"name": "rebound host name", "served": answer.status != 403})
            rebound.close()
            succeeded = [a for a in attempts
                         if a.get("opened") or a.get("messages") or a.get("readable")
                         or a.get("served")]
            after = _state(port)
            changed = {k: (before[k], after[k]) for k in
                       ("target_n", "setpoint_c", "mode", "phase", "recording", "controls")
                       if before[k] != after[k]}
            print(f"cross-origin attempts: {len(attempts)}, succeeded: {len(succeeded)}, "
                  f"state changed: {changed or 'nothing'}")
            assert len(attempts) == 7
            assert succeeded == []
            assert changed == {}
            assert after["controls"] == 0
            # The operator's page, same browser: connects and commands.
            operator = browser.new_page()
            operator.goto(url)
            # The first state fills the form: typed into before it, the value is replaced.
            operator.wait_for_function("Number(document.body.dataset.updates || 0) > 0")
            operator.fill("#target-input", "4")
            operator.click("#target-set")
            operator.wait_for_function(
                "document.getElementById('target').textContent === '4.00'")
            assert _state(port)["controls"] == 1
        finally:
            browser.close()
