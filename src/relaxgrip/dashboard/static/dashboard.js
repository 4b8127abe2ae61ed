// relaxgrip dashboard: one WebSocket, state messages in, controls out.
"use strict";
(function () {
  const WINDOW_S = 60;
  const params = new URLSearchParams(location.search);
  const token = params.get("token");
  const $ = (id) => document.getElementById(id);
  const fmt = (v, d) => (v === null || v === undefined ? "–" : Number(v).toFixed(d));
  let ws = null;
  let nextId = 1;
  const pending = new Map();
  const force = [[], [], [], []];   // t, estimate, truth, target
  const temp = [[], [], [], []];    // t, finger 0, finger 1, setpoint
  let filled = false;

  function plot(el, series, yLabel) {
    return new uPlot({
      width: 560, height: 220, series: series, scales: { x: { time: false } },
      axes: [{ label: "t (s)" }, { label: yLabel }],
    }, [[], [], [], []], el);
  }
  const forcePlot = plot($("force-plot"), [
    {}, { label: "estimate", stroke: "#2563eb", width: 2 },
    { label: "truth (twin)", stroke: "#16a34a", dash: [4, 3] },
    { label: "target", stroke: "#dc2626" }], "N");
  const tempPlot = plot($("temp-plot"), [
    {}, { label: "finger 0", stroke: "#ea580c", width: 2 },
    { label: "finger 1", stroke: "#9333ea", width: 2 },
    { label: "setpoint", stroke: "#dc2626", dash: [4, 3] }], "°C");

  function push(buf, row) {
    if (buf[0].length && row[0] < buf[0][buf[0].length - 1]) { buf.forEach((c) => (c.length = 0)); }
    row.forEach((v, i) => buf[i].push(v));
    while (buf[0].length && buf[0][0] < row[0] - WINDOW_S) buf.forEach((c) => c.shift());
  }

  function showError(msg) {
    const el = $("error");
    if (msg) { el.textContent = msg; el.hidden = false; } else { el.textContent = ""; el.hidden = true; }
  }

  function fillSelect(el, values, current) {
    if (el.options.length) return;
    values.forEach((v) => { const o = document.createElement("option"); o.value = v; o.textContent = v; el.appendChild(o); });
    if (current) el.value = current;
  }

  function onState(s) {
    $("backend").textContent = `${s.backend} (${s.backend_version}), ${s.estimator}`;
    $("phase").textContent = s.phase;
    $("mode").textContent = s.mode === null ? "setpoint" : s.mode;
    $("estimate").textContent = fmt(s.estimate_n, 3);
    $("target").textContent = fmt(s.target_n, 2);
    $("truth").textContent = fmt(s.truth_n, 3);
    $("icfn").textContent = fmt(s.icfn_n, 3);
    $("k").textContent = fmt(s.k_n, 3);
    $("tau").textContent = fmt(s.tau_s, 1);
    $("since-contact").textContent = fmt(s.since_contact_s, 1);
    $("marker").textContent = s.marker || "–";
    $("temp0").textContent = fmt(s.temps_c[0], 1);
    $("temp1").textContent = fmt(s.temps_c[1], 1);
    $("setpoint").textContent = s.setpoint_c === null ? "off" : fmt(s.setpoint_c, 1);
    $("heaters").textContent = `${s.temp_status} ${fmt(s.duty[0], 2)} / ${fmt(s.duty[1], 2)}`;
    $("recording").textContent = s.recording ? `● recording ${s.recording}` : "";
    $("record").checked = !!s.recording;
    if (!filled) {
      fillSelect($("mode-select"), s.modes, s.mode);
      fillSelect($("object-select"), s.objects.length ? ["none"].concat(s.objects) : [s.object || "none"], s.object || "none");
      $("object-form").querySelector("button").disabled = !s.objects.length;
      $("target-input").value = s.target_n;
      filled = true;
    }
    if (s.error) showError(s.error);
    if (s.rgb_jpeg) $("rgb").src = "data:image/jpeg;base64," + s.rgb_jpeg;
    if (s.ir_jpeg) $("ir").src = "data:image/jpeg;base64," + s.ir_jpeg;
    if (s.t_s !== null) {
      push(force, [s.t_s, s.estimate_n, s.truth_n, s.target_n]);
      push(temp, [s.t_s, s.temps_c[0], s.temps_c[1], s.setpoint_c]);
      forcePlot.setData(force);
      tempPlot.setData(temp);
    }
    const ev = $("events");
    ev.innerHTML = "";
    s.events.forEach((e) => { const li = document.createElement("li"); li.textContent = e; ev.appendChild(li); });
    document.body.dataset.updates = String(Number(document.body.dataset.updates || 0) + 1);
  }

  function send(op, value) {
    if (!ws || ws.readyState !== WebSocket.OPEN) { showError("not connected"); return; }
    const id = nextId++;
    pending.set(id, op);
    ws.send(JSON.stringify({ id: id, op: op, value: value }));
  }

  function onReply(r) {
    pending.delete(r.id);
    showError(r.ok ? "" : r.error);
    document.body.dataset.replies = String(Number(document.body.dataset.replies || 0) + 1);
  }

  function connect() {
    const proto = location.protocol === "https:" ? "wss:" : "ws:";
    const q = token ? "?token=" + encodeURIComponent(token) : "";
    ws = new WebSocket(`${proto}//${location.host}/ws${q}`);
    ws.onopen = () => { $("conn").textContent = "live"; $("conn").classList.remove("off"); };
    ws.onclose = () => {
      $("conn").textContent = "disconnected"; $("conn").classList.add("off");
      setTimeout(connect, 1000);
    };
    ws.onmessage = (m) => {
      const msg = JSON.parse(m.data);
      if (msg.type === "state") onState(msg); else if (msg.type === "reply") onReply(msg);
    };
  }

  $("target-form").onsubmit = (e) => { e.preventDefault(); send("target", $("target-input").value); };
  $("mode-form").onsubmit = (e) => { e.preventDefault(); send("mode", $("mode-select").value); };
  $("temp-form").onsubmit = (e) => { e.preventDefault(); send("temperature", $("temp-input").value); };
  $("object-form").onsubmit = (e) => { e.preventDefault(); send("object", $("object-select").value); };
  document.querySelectorAll("button[data-op]").forEach((b) => { b.onclick = () => send(b.dataset.op, null); });
  $("record").onchange = (e) => send("record", e.target.checked);
  connect();
})();
