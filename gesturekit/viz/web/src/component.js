// The viewer as a Streamlit component: the page speaks Streamlit's component protocol itself (window messages
// to and from the app's page). It says it is ready; each "streamlit:render" message brings the args of the
// viewer's Python side (app/display.py): data (the viewer's JSON text), audio (the speech as WAV bytes, a
// Uint8Array, or absent), hash (of both), key and height. A rerun with the same hash keeps the drawn view.

function send(type, fields) {
  window.parent.postMessage({ isStreamlitMessage: true, type, ...fields }, "*");
}

/** Serve the viewer run(data, audioElement) -> takedown from the render messages. */
export function component(run) {
  let shown = null, takedown = null, url = null;
  window.addEventListener("message", (event) => {
    const msg = event.data;
    if (!msg || msg.type !== "streamlit:render") return;
    const a = msg.args;
    document.body.dataset.key = a.key;
    const stage = document.getElementById("stage");
    const fresh = a.hash !== shown || stage.dataset.most !== String(a.height);
    stage.dataset.most = String(a.height);  // the viewer may draw less high (viewer.js: fittedHeight)
    if (fresh) stage.style.height = a.height + "px";
    send("streamlit:setFrameHeight", { height: document.body.scrollHeight });
    if (!fresh) return;  // the same viewer again: nothing to redraw
    shown = a.hash;
    if (takedown) takedown();
    const old = document.getElementById("gk-audio");
    if (old) old.remove();
    if (url) URL.revokeObjectURL(url);
    url = null;
    let audio = null;
    if (a.audio) {
      audio = document.createElement("audio");
      audio.id = "gk-audio";
      audio.preload = "auto";
      url = URL.createObjectURL(new Blob([a.audio], { type: "audio/wav" }));
      audio.src = url;
      document.body.appendChild(audio);
    }
    // the JSON text as the page got it, for tests and tools that read what is shown
    window.gkArgs = { data: a.data, audio: a.audio || null, key: a.key, hash: a.hash };
    const data = JSON.parse(a.data);
    document.getElementById("stage").style.background = data.look.background;
    takedown = run(data, audio, () => send("streamlit:setFrameHeight", { height: document.body.scrollHeight }));
  });
  send("streamlit:componentReady", { apiVersion: 1 });
}
