// The play page: sliders for every task parameter, buttons, arrow keys, and a readout of
// /state twice a second. Frames come as an MJPEG stream (<img src="/stream">).
let state = null;

async function post(path, body) {
  const r = await fetch(path, {method: "POST", headers: {"Content-Type": "application/json"},
                               body: JSON.stringify(body || {})});
  const data = await r.json();
  document.getElementById("said").textContent = r.ok ? "" : `${r.status}: ${data.detail}`;
  if (r.ok) state = data;
  return data;
}

function sliders(s) {
  const box = document.getElementById("sliders");
  for (const [name, [lo, hi]] of Object.entries(s.ranges)) {
    if (hi <= lo) continue;  // fixed in this run's task space
    const kind = s.shape_params.includes(name) ? "body" : "goal";
    const label = document.createElement("label");
    const unit = (s.units || {})[name] || "";
    label.innerHTML = `${esc(name)} <span class="muted">(${kind})</span> = ` +
      `<b id="value-${esc(name)}">${s.task[name].toFixed(2)}</b> <span class="muted">${esc(unit)}</span>`;
    const input = document.createElement("input");
    Object.assign(input, {type: "range", id: "slider-" + name, min: lo, max: hi,
                          step: (hi - lo) / 100, value: s.task[name]});
    input.addEventListener("input", () => {
      document.getElementById("value-" + name).textContent = Number(input.value).toFixed(2);
    });
    input.addEventListener("change", () => {  // [L21] goals wait for "perform"
      if (s.kind === "family" || kind === "body") {
        post("/task", {values: {[name]: Number(input.value)}});
      }
    });
    box.append(label, input);
  }
}

function values() {
  const out = {};
  for (const input of document.querySelectorAll("#sliders input")) {
    out[input.id.slice("slider-".length)] = Number(input.value);
  }
  return out;
}

function readout(s) {
  const terms = Object.entries(s.reward_terms).map(([k, v]) => `  ${k}: ${v.toFixed(3)}`);
  document.getElementById("readout").textContent = [
    `speed ${s.speed.toFixed(2)} m/s   real-time factor ${s.real_time_factor.toFixed(2)}`,
    `V̄ ${s.vbar === null ? "–" : s.vbar.toFixed(2)}   μ ${s.mu === null ? "–" : s.mu.toFixed(2)}`,
    `hip height ${s.body.hip_height.toFixed(3)} m   mass ${s.body.mass.toFixed(2)} kg`,
    `frame ${s.frame}   sim time ${s.sim_time.toFixed(1)} s ${s.fallen ? "(fallen)" : ""}`,
    "reward terms:", ...terms].join("\n");
  document.getElementById("pause").textContent = s.paused ? "resume" : "pause";
  document.getElementById("follow").textContent = s.follow ? "camera: following" : "camera: fixed";
}

async function main() {
  state = await (await fetch("/state")).json();
  document.getElementById("title").textContent =
    `paramimic play: ${state.run} (${state.character}, ${state.kind})`;
  sliders(state);
  const perform = document.getElementById("perform");
  perform.hidden = state.kind !== "skill";
  perform.onclick = () => post("/perform", {values: values()});
  document.getElementById("reset").onclick = () => post("/reset");
  document.getElementById("pause").onclick = () => post("/pause", {on: !state.paused});
  document.getElementById("follow").onclick = () => post("/follow", {on: !state.follow});
  if (state.goals.includes("target_direction")) {
    document.getElementById("hint").textContent = "← → steer";
    document.addEventListener("keydown", e => {
      if (e.key === "ArrowLeft") post("/steer", {delta: 0.15});
      if (e.key === "ArrowRight") post("/steer", {delta: -0.15});
    });
  }
  setInterval(async () => { state = await (await fetch("/state")).json(); readout(state); }, 500);
}
main();
