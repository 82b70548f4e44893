// pyclray view's page: the WebSocket to the server, the images it sends painted in order on
// #view (data-frame counts them), the image selector, the animation's clock, the error banner.
import { attachControls } from "./controls.js";

const $ = (id) => document.getElementById(id);
const view = $("view"), context = view.getContext("2d");
const socket = new WebSocket(`ws://${location.host}/ws${location.search}`);
socket.binaryType = "arraybuffer";

// what the page measured, for bench/view.py and the tests: when each input was sent, when each
// image was painted (the latest KEEP of each), the images painted, the camera shown, and the seq of
// the latest input that changes the view (a release does not): an image whose seq is at least that
// shows every input so far
const KEEP = 2000;
const stats = { sent: {}, paints: [], painted: 0, camera: "", latest: 0 };
window.pyclrayView = stats;
let seq = 0, painted = 0, last = null, playing = null, animation = null;

function send(message) {
  if (socket.readyState !== WebSocket.OPEN) return;
  if (message.type !== "painted") {
    message.seq = ++seq;
    stats.sent[seq] = performance.now();
    if (message.type !== "end") stats.latest = seq;
    delete stats.sent[seq - KEEP];
  }
  socket.send(JSON.stringify(message));
}

// images are decoded as they come and painted in the order they were sent. Every image is
// acknowledged once, painted or not (the server sends no more while two are unacknowledged), and a
// failure with one image never passes down the queue to the next ones
let queue = Promise.resolve();
function receiveImage(buffer) {
  const length = new DataView(buffer).getUint32(0);
  const header = JSON.parse(new TextDecoder().decode(new Uint8Array(buffer, 4, length)));
  const decoded = createImageBitmap(new Blob([new Uint8Array(buffer, 4 + length)], { type: header.type }));
  queue = queue
    .then(() => decoded)
    .then((bitmap) => paint(header, bitmap))
    .catch((error) => console.warn(`pyclray view: image ${header.frame} not shown:`, error))
    .then(() => send({ type: "painted", frame: header.frame }));
}

function paint(header, bitmap) {
  context.imageSmoothingEnabled = bitmap.width !== view.width;
  context.drawImage(bitmap, 0, 0, view.width, view.height);
  bitmap.close();
  painted += 1;
  view.dataset.frame = String(painted);
  stats.painted = painted;
  stats.paints.push({ time: performance.now(), seq: header.seq, width: header.width, lossless: header.lossless });
  if (stats.paints.length > 2 * KEEP) stats.paints.splice(0, KEEP);
  stats.camera = header.camera;
  last = header;
  const vector = (v) => "[" + v.map((x) => x.toFixed(3)).join(", ") + "]";
  $("info").textContent = `${header.aov} ${header.width}x${header.height}${header.lossless ? "" : " (moving)"} in ` +
    `${header.ms.toFixed(1)} ms · eye ${vector(header.eye)} · target ${vector(header.target)}`;
}

function showScene(scene) {
  $("source").textContent = scene.source;
  document.title = `pyclray view: ${scene.source}`;
  if (view.width !== scene.width || view.height !== scene.height) {
    view.width = scene.width;
    view.height = scene.height;
  }
  const select = $("aov");
  select.replaceChildren(...scene.aovs.map((name) => new Option(name, name, false, name === scene.aov)));
  select.value = scene.aov;
  animation = scene.animation;
  $("clock").hidden = animation === null;
  if (animation === null) {
    stop();
    $("time")?.remove();  // only an animated scene has a clock
    return;
  }
  const time = $("time") ?? makeSlider();
  time.max = String(animation.duration);
  time.step = String(1 / animation.fps);
  time.value = String(scene.t);
  showTime();
}

function showError(message) {
  const banner = $("error");
  banner.textContent = message;
  banner.hidden = message === "";
}

socket.addEventListener("message", (event) => {
  if (typeof event.data !== "string") {
    receiveImage(event.data);
    return;
  }
  const message = JSON.parse(event.data);
  if (message.type === "scene") showScene(message);
  else if (message.type === "error") showError(message.message);
});
socket.addEventListener("close", () => { $("info").textContent = "the server has stopped"; });

// the animation's clock: the slider, and play (a step of 1 / fps at the animation's rate)
function showTime() { $("time-value").textContent = `${Number($("time").value).toFixed(2)} s`; }
function stop() {
  if (playing !== null) clearInterval(playing);
  playing = null;
  $("play").textContent = "play";
}
function makeSlider() {
  const time = Object.assign(document.createElement("input"), { type: "range", id: "time", min: "0", value: "0" });
  time.addEventListener("input", () => {
    showTime();
    send({ type: "time", t: Number(time.value) });
  });
  $("time-value").before(time);
  return time;
}
$("play").addEventListener("click", () => {
  if (playing !== null || animation === null) {
    stop();
    return;
  }
  $("play").textContent = "pause";
  const time = $("time");
  playing = setInterval(() => {
    const next = Number(time.value) + 1 / animation.fps;
    time.value = String(next > animation.duration + 1e-9 ? 0 : next);
    showTime();
    send({ type: "time", t: Number(time.value) });
  }, 1000 / animation.fps);
});

$("aov").addEventListener("change", () => send({ type: "aov", name: $("aov").value }));

// "copy camera": the [camera] table of the view shown, for the scene file
$("copy").addEventListener("click", async () => {
  if (last === null) return;
  try {
    await navigator.clipboard.writeText(last.camera);
  } catch {
    const area = Object.assign(document.createElement("textarea"), { value: last.camera });
    document.body.append(area);
    area.select();
    document.execCommand("copy");
    area.remove();
  }
  $("copy").textContent = "copied";
  setTimeout(() => { $("copy").textContent = "copy camera"; }, 1200);
});

const toggleHelp = () => { $("help").hidden = !$("help").hidden; };
$("help-button").addEventListener("click", toggleHelp);
attachControls(view, send, toggleHelp);
