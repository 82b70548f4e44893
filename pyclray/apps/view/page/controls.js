// The mouse and the keys (three.js OrbitControls, Blender, MeshLab): left drag orbits, right or
// shift + left drag pans, the wheel dollies, r restores the scene's camera, h shows the keys.
// Motion goes to the server in fractions of the image's shown height (it keeps the camera).

// A right drag opens no context menu: the browser asks for one at the press (Linux, macOS) or at the
// release (Windows), over whatever element the pointer is on then, the image or not.
const MENU_AFTER_RELEASE_MS = 500;

export function attachControls(view, send, toggleHelp) {
  let mode = null;
  let last = null;
  let rightReleased = -Infinity;  // when the last right drag ended

  window.addEventListener("contextmenu", (event) => {
    if (event.target === view || mode !== null || performance.now() - rightReleased < MENU_AFTER_RELEASE_MS) {
      event.preventDefault();
    }
  });
  view.addEventListener("pointerdown", (event) => {
    if (event.button !== 0 && event.button !== 2) return;
    mode = event.button === 2 || event.shiftKey ? "pan" : "orbit";
    last = [event.clientX, event.clientY];
    view.setPointerCapture(event.pointerId);
    view.focus();
    event.preventDefault();
  });
  view.addEventListener("pointermove", (event) => {
    if (mode === null) return;
    const height = view.clientHeight || view.height;
    const dx = (event.clientX - last[0]) / height, dy = (event.clientY - last[1]) / height;
    last = [event.clientX, event.clientY];
    if (dx !== 0 || dy !== 0) send({ type: mode, dx, dy });
  });
  const release = (event) => {
    if (mode === null) return;
    mode = null;
    if (event.button === 2) rightReleased = performance.now();
    send({ type: "end" });  // the motion is over: the full image now
  };
  view.addEventListener("pointerup", release);
  view.addEventListener("pointercancel", release);
  view.addEventListener("wheel", (event) => {
    event.preventDefault();
    // one notch is deltaY = 100 pixels (or 3 lines); toward the user (deltaY < 0) dollies in
    const notches = event.deltaMode === 1 ? event.deltaY / 3 : event.deltaMode === 2 ? event.deltaY : event.deltaY / 100;
    send({ type: "dolly", notches: Math.max(-20, Math.min(20, notches)) });
  }, { passive: false });
  window.addEventListener("keydown", (event) => {
    if (event.ctrlKey || event.metaKey || event.altKey) return;
    // typing in the image selector picks the image whose name starts with the key: such a key is the
    // selector's. Any other (r: no image's name starts with it) is the view's, also with the focus
    // left on the selector after picking an image with the mouse (the key once did nothing there)
    if (event.target instanceof HTMLSelectElement && [...event.target.options].some(
      (option) => option.text.toLowerCase().startsWith(event.key.toLowerCase()))) return;
    if (event.key === "r" || event.key === "R") send({ type: "reset" });
    else if (event.key === "h" || event.key === "H" || event.key === "?") toggleHelp();
  });
}
