// Webcam capture front end (anywidget ESM, plain DOM; the Live tab, widgets/live/).
//
// While `active` is true the page holds the user's camera (getUserMedia: the browser asks
// for consent) and sends frames to the kernel as small JPEGs, at the rate the kernel keeps
// up with (at most MAX_SEND_WIDTH wide): one frame in flight, the next one only after the
// kernel's {type: "ack"} — a slow kernel makes frames drop, never queue. The next frame is
// grabbed and encoded while one is in flight, started so that it is ready by the time the ack
// comes (schedulePregrab), and sent on the ack: the rate is set by the slower of the round
// trip and the encode, not their sum, and a frame waits for the ack only as long as that
// estimate is early (the "wait" stage). Turning `active` off, or
// closing the view, stops the camera (every track of the stream).
//
// Messages to the kernel: {type: "frame", t, width, height} with the JPEG as buffer 0;
// {type: "camera", state: "on" | "off" | "error", message}. From the kernel: {type: "ack",
// kernel_ms} (the kernel's time on the frame: decode, tracking, the face's update sent).
//
// Latency, camera frame to drawn face, per stage (the last LATENCY_SAMPLES frames): "grab"
// (the video frame into a canvas and JPEG-encoded), "wait" (encoded → sent: the frame in
// flight before it was not acked yet), "kernel" (as the ack says), "transport"
// (the rest of the send → ack round trip: websocket, server, queueing), "draw" (ack → the
// second animation frame after it: the face's update reached the page before the ack, on
// the same kernel channel, so the first animation frame draws it and the second one starts
// only after that one was painted — a bound, up to one frame late), "total" (grab → draw).
//
// While frames flow, the face animates like a playing timeline: the camera announces itself
// in the playback registry (./shared/playback.js) under its face model's scene key (the
// `_scene` trait), so that model's viewports draw at draft resolution on software WebGL.
//
// Test hooks (attributes on the root): data-camera = "off" | "starting" | "on" | "error",
// data-sent, data-acked (frames), data-error (the browser's message), data-latency (JSON:
// {n, stages: {name: [median, p90] ms}}).

import { announcePlayback } from "./shared/playback.js";

const JPEG_QUALITY = 0.8;
// Frames go out at most this wide (the camera's aspect kept): FaceMesh crops the face and
// resizes it to 192 px anyway, and the weights it gives were the same at 320×240 as at
// 640×480 on the rendered take (RMSE 0.144 / 0.148); a quarter of the pixels to draw,
// encode, send and decode.
const MAX_SEND_WIDTH = 320;
const LATENCY_SAMPLES = 120;
const STAGES = ["grab", "wait", "kernel", "transport", "draw", "total"];
// until this many frames were measured, the next frame is grabbed only on the ack
const PREGRAB_AFTER = 3;

function quantile(sorted, q) {
  if (!sorted.length) return NaN;
  return sorted[Math.min(sorted.length - 1, Math.floor(q * sorted.length))];
}

function view({ model, el }) {
  el.classList.add("fwb-camera");
  el.style.cssText = "display:flex;flex-direction:column;gap:4px;font:12px sans-serif;";
  const video = document.createElement("video");
  video.muted = true;
  video.playsInline = true;
  video.style.cssText = "width:100%;max-width:320px;background:#222;border-radius:4px;transform:scaleX(-1);";
  const status = document.createElement("div");
  status.className = "fwb-camera-status";
  el.append(video, status);
  const canvas = document.createElement("canvas");
  let stream = null;
  let inFlight = false;
  let grabbing = false; // a frame is being encoded
  let ready = null; // a frame encoded while another was in flight: {buf, t, w, h, grab, encoded}
  let sent = 0;
  let acked = 0;
  let timer = null;
  let disposed = false;
  let pending = null; // {grab, encoded, sent} times (ms) of the frame in flight
  const source = `camera-${Math.random().toString(36).slice(2)}`; // this view, in the playback registry
  const latency = []; // the last frames' {stage: ms}
  let summary = null; // latencySummary() of `latency`, made once per measured frame

  const latencySummary = () => {
    const stages = {};
    for (const k of STAGES) {
      const v = latency.map((r) => r[k]).filter(Number.isFinite).sort((a, b) => a - b);
      stages[k] = [quantile(v, 0.5), quantile(v, 0.9)];
    }
    return { n: latency.length, stages };
  };

  const mark = (state, message = "") => {
    el.setAttribute("data-camera", state);
    el.setAttribute("data-sent", String(sent));
    el.setAttribute("data-acked", String(acked));
    if (message) el.setAttribute("data-error", message);
    const total = summary ? summary.stages.total[0] : NaN;
    const lat = Number.isFinite(total) ? `, camera → face ${Math.round(total)} ms` : "";
    status.textContent = state === "on" ? `camera on: ${sent} frames sent${lat}` :
      state === "error" ? `camera: ${message}` : state === "starting" ? "asking for the camera…" : "camera off";
  };

  const clearTimer = () => {
    if (timer !== null) clearTimeout(timer);
    timer = null;
  };

  const stop = () => {
    clearTimer();
    if (stream) stream.getTracks().forEach((t) => t.stop());
    stream = null;
    video.srcObject = null;
    inFlight = false;
    grabbing = false;
    ready = null;
    pending = null;
    announcePlayback(source, model.get("_scene"), false);
  };

  const send = (f) => {
    inFlight = true;
    sent += 1;
    pending = { grab: f.grab, encoded: f.encoded, sent: performance.now() };
    model.send({ type: "frame", t: f.t, width: f.w, height: f.h }, undefined, [f.buf]);
    mark("on");
    schedulePregrab();
  };

  // The next frame into a JPEG: sent at once when nothing is in flight, else kept for the ack.
  const grab = () => {
    clearTimer();
    if (!stream || disposed || grabbing || ready) return;
    if (video.readyState < 2 || !video.videoWidth) {
      timer = setTimeout(grab, 10); // the video's first frame is not there yet
      return;
    }
    const scale = Math.min(1, MAX_SEND_WIDTH / video.videoWidth);
    const w = Math.round(video.videoWidth * scale);
    const h = Math.round(video.videoHeight * scale);
    canvas.width = w;
    canvas.height = h;
    const grabbed = performance.now();
    canvas.getContext("2d").drawImage(video, 0, 0, w, h);
    grabbing = true;
    const t = performance.now() / 1000;
    const session = stream;
    canvas.toBlob(async (blob) => {
      const buf = blob && stream === session ? await blob.arrayBuffer() : null;
      grabbing = false;
      // stopped (or restarted) while the JPEG was made: drop it, and never mark a stopped camera "on"
      if (!buf || stream !== session || disposed) return;
      const f = { buf, t, w, h, grab: grabbed, encoded: performance.now() };
      if (inFlight) ready = f;
      else send(f);
    }, "image/jpeg", JPEG_QUALITY);
  };

  // While a frame is in flight, start the next one's grab so that it is encoded by the time the
  // ack comes: a short round trip (its lower quartile over the measured frames) less a long
  // encode (upper quartile) — ready before the ack about three times in four, waiting at most
  // the round trip's spread; before PREGRAB_AFTER frames are measured, grab on the ack.
  const schedulePregrab = () => {
    clearTimer();
    if (latency.length < PREGRAB_AFTER) return;
    const sorted = (f) => latency.map(f).filter(Number.isFinite).sort((a, b) => a - b);
    const trip = quantile(sorted((r) => r.kernel + r.transport), 0.25);
    const encode = quantile(sorted((r) => r.grab), 0.75);
    const lead = Math.max(0, trip - encode);
    if (Number.isFinite(lead)) timer = setTimeout(grab, lead);
  };

  const start = async () => {
    if (stream) return;
    mark("starting");
    if (!navigator.mediaDevices || !navigator.mediaDevices.getUserMedia) {
      const message = "this page cannot open a camera (getUserMedia needs a secure context: https or localhost)";
      mark("error", message);
      model.send({ type: "camera", state: "error", message });
      return;
    }
    try {
      const s = await navigator.mediaDevices.getUserMedia({ video: { width: 640, height: 480 }, audio: false });
      if (disposed || !model.get("active")) { s.getTracks().forEach((t) => t.stop()); return; }
      stream = s;
      s.getVideoTracks().forEach((tr) => tr.addEventListener("ended", () => {
        stop();
        mark("error", "the camera stopped (unplugged?)");
        model.send({ type: "camera", state: "error", message: "the camera stopped (unplugged?)" });
      }));
      video.srcObject = s;
      await video.play().catch(() => {});
      mark("on");
      model.send({ type: "camera", state: "on", message: "" });
      announcePlayback(source, model.get("_scene"), true);
      grab();
    } catch (err) {
      const message = `${err && err.name ? err.name + ": " : ""}${err && err.message ? err.message : err}`;
      mark("error", message);
      model.send({ type: "camera", state: "error", message });
    }
  };

  const onActive = () => {
    if (model.get("active")) start();
    else { stop(); mark("off"); model.send({ type: "camera", state: "off", message: "" }); }
  };
  const onMsg = (msg) => {
    if (msg && msg.type === "ack") {
      acked += 1;
      inFlight = false;
      el.setAttribute("data-acked", String(acked));
      const p = pending;
      pending = null;
      // the next frame: the one encoded meanwhile, else the one being encoded (sent when done), else grab now
      if (stream && !disposed) {
        if (ready) {
          const f = ready;
          ready = null;
          send(f);
        } else if (!grabbing) grab();
      }
      if (!p) return;
      const ack = performance.now();
      const kernel = Number(msg.kernel_ms);
      requestAnimationFrame(() => requestAnimationFrame(() => {
        if (disposed) return;
        const drawn = performance.now();
        const trip = ack - p.sent;
        latency.push({ grab: p.encoded - p.grab, wait: p.sent - p.encoded, kernel,
                       transport: Number.isFinite(kernel) ? trip - kernel : NaN,
                       draw: drawn - ack, total: drawn - p.grab });
        if (latency.length > LATENCY_SAMPLES) latency.shift();
        summary = latencySummary();
        el.setAttribute("data-latency", JSON.stringify(summary));
      }));
    }
  };
  model.on("change:active", onActive);
  model.on("msg:custom", onMsg);
  mark("off");
  if (model.get("active")) start();
  return () => {
    disposed = true;
    model.off("change:active", onActive);
    model.off("msg:custom", onMsg);
    stop();
  };
}

export default { render: view };
