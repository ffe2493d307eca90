const RUN = decodeURIComponent(location.pathname.split("/").pop());
const CURVES = [["mean_return", "mean return"], ["fall_percent", "fall %"], ["mean_length", "episode length (steps)"], ["steps_per_second", "steps/s"], ["std", "policy std"], ["approx_kl", "KL per update"], ["explained_variance", "explained variance"]];
let since = 0, history = [];
const CONFIG = {displayModeBar: false, responsive: true};
const layout = (title, extra = {}) => Object.assign({title: {text: title, font: {size: 13}},
  margin: {l: 50, r: 10, t: 30, b: 35}, xaxis: {title: {text: "env steps"}},
  legend: {orientation: "h", y: -0.18}}, extra);
for (const [key] of CURVES) {
  const div = document.createElement("div");
  div.id = "curve-" + key; div.className = "plot";
  document.getElementById("curves").appendChild(div);
}
function token() {
  const t = document.getElementById("token").value;
  if (t) sessionStorage.setItem("paramimic-token", t);
  return t || sessionStorage.getItem("paramimic-token") || "";
}
document.getElementById("token").value = sessionStorage.getItem("paramimic-token") || "";
async function control(method, path, body) {
  const r = await fetch(`/runs/${RUN}${path}`, {method, headers: Object.assign(
    {"Authorization": "Bearer " + token()}, body ? {"Content-Type": "application/json"} : {}),
    body: body ? JSON.stringify(body) : undefined});
  const said = await r.json().catch(() => ({}));
  document.getElementById("said").textContent = r.ok ? "requested: " + JSON.stringify(said.requested)
    : `${r.status}: ${said.detail || ""}`;
}
document.getElementById("pause").onclick = () => control("POST", "/pause");
document.getElementById("resume").onclick = () => control("POST", "/resume");
document.getElementById("setk").onclick = () =>
  control("PUT", "/curriculum/k", {k: Number(document.getElementById("k").value)});

function curves() {
  document.getElementById("curves").style.display = "";
  const x = history.map(h => h.env_steps);
  for (const [key, title] of CURVES) {
    const y = history.map(h => h[key] === undefined ? null : h[key]);
    Plotly.react("curve-" + key, [{x, y, mode: "lines", name: title}], layout(title), CONFIG);
  }
}
let PARAMS = {};  // name -> the run's task parameter (GET /runs/{run})
const label = name => PARAMS[name] && PARAMS[name].unit ? `${name} (${PARAMS[name].unit})` : name;
async function parameters() {
  const run = await getJSON(`/runs/${RUN}`);
  PARAMS = Object.fromEntries(run.parameters.map(p => [p.name, p]));
}
function parameterTable(achieved) {
  const rows = Object.values(PARAMS).map(p => {
    const what = p.measure ? p.measure + (p.axis ? ` about ${p.axis}` : "") +
      (p.body ? ` of ${p.body}` : "") : p.kind;
    const reward = p.reward ? (p.reward === "spike" ? `spike at ${p.event}` : "continuous") : "";
    const a = (achieved || {})[p.name];
    return `<tr data-name="${esc(p.name)}"><td><b>${esc(p.name)}</b></td>` +
      `<td>${fmt(p.range[0], 3)} – ${fmt(p.range[1], 3)}</td><td class="unit">${esc(p.unit)}</td>` +
      `<td>${esc(what)}${p.constraint ? " (constraint)" : ""}</td><td>${esc(reward)}</td>` +
      `<td>${a ? `${fmt(a.mean, 3)} [${fmt(a.min, 3)}, ${fmt(a.max, 3)}]` : ""}</td></tr>`;
  });
  document.getElementById("parameters").innerHTML = "<tr><th>name</th><th>range</th><th>unit</th>" +
    "<th>meaning</th><th>task reward</th><th>latest a′ mean [min, max]</th></tr>" + rows.join("");
}
function column(rows, names, name) {
  const i = names.indexOf(name);
  return rows.map(r => r[i]);
}
async function wl19(c) {
  const g = await getJSON(`/runs/${RUN}/curriculum/marginal-value`);
  if (!g.available) return;
  const batches = await getJSON(`/runs/${RUN}/curriculum/samples?limit=20`);
  const tasks = batches.flatMap(b => b.tasks), names = batches.length ? batches[0].names : [];
  Plotly.react("task-map", [
    {type: "heatmap", x: g.xs, y: g.ys, z: g.values, colorscale: "Viridis",
     colorbar: {title: {text: "V̄"}}, name: "V̄"},
    {type: "contour", x: g.xs, y: g.ys, z: g.values, showscale: false, name: "μ",
     contours: {coloring: "none", start: g.mu, end: g.mu, size: 1}, line: {color: "white", width: 2}},
    {type: "scatter", mode: "markers", x: column(tasks, names, g.dims[0]),
     y: column(tasks, names, g.dims[1]), marker: {color: "red", size: 5}, name: "samples (S)"},
  ], layout(`V̄ over ${g.dims.join(" × ")}: μ = ${fmt(g.mu, 2)}, k = ${fmt(c.k, 2)}`,
     {xaxis: {title: {text: label(g.dims[0])}}, yaxis: {title: {text: label(g.dims[1])}}}), CONFIG);
}
async function l21(c) {
  const [e, d] = await Promise.all([getJSON(`/runs/${RUN}/curriculum/elites?limit=5000&spread=true`),
                                    getJSON(`/runs/${RUN}/curriculum/density`)]);
  const traces = [];
  if (d.available) {
    traces.push({type: "contour", x: d.xs, y: d.ys, z: d.values, colorscale: "Blues",
      opacity: 0.4, showscale: false, name: "density", contours: {coloring: "heatmap"}});
    for (const [level, name, color] of [[d.visited, "A_h (D)", "green"],
                                        [d.surrounding, "A_s (D')", "orange"]]) {
      traces.push({type: "contour", x: d.xs, y: d.ys, z: d.values, showscale: false, name,
        contours: {coloring: "none", start: level, end: level, size: 1},
        line: {color, width: 2}});
    }
  }
  const dims = d.available ? d.dims : e.names.slice(0, 2);
  traces.push({type: "scatter", mode: "markers", name: "elites",
    x: e.items.map(i => i.params[dims[0]]), y: e.items.map(i => i.params[dims[1]]),
    marker: {color: e.items.map(i => i.fitness), colorscale: "Viridis", showscale: true,
             colorbar: {title: {text: "fitness"}, x: 1.12}, size: 7}});
  Plotly.react("task-map", traces, layout(`${e.total} elites: phase ${c.phase}, stage ${c.stage}`,
    {xaxis: {title: {text: label(dims[0])}}, yaxis: {title: {text: label(dims[1])}}}), CONFIG);
  const h = c.history || [];
  Plotly.react("er", [{x: h.map(p => p.episodes), y: h.map(p => p.explored_ratio),
    mode: "lines+markers", name: "ER"}], layout("explored ratio ER over episodes N",
    {xaxis: {title: {text: "episodes N"}}}), CONFIG);
}
async function events() {
  const items = await getJSON(`/runs/${RUN}/events?limit=200`);
  const box = document.getElementById("events");
  box.innerHTML = items.slice().reverse().map(e => `<div data-type="${esc(e.type)}">
    ${new Date(e.time * 1000).toLocaleTimeString()} <b>${esc(e.type)}</b> ${esc(e.message)}</div>`).join("");
}
async function tick() {
  const p = await getJSON(`/runs/${RUN}/progress`);
  document.getElementById("title").textContent = RUN;
  const last = history.length ? history[history.length - 1] : {};
  document.getElementById("status").innerHTML = `<span class="${esc(p.status)}" id="run-status">
    ${esc(p.status)}</span> · iteration <span id="iteration">${p.iteration}</span> ·
    ${fmt(p.env_steps, 0)} / ${fmt(p.total_steps, 0)} env steps · ${fmt(p.steps_per_second, 0)}
    steps/s · actors ${fmt(p.actors, 0)} on ${fmt(p.nodes, 0)} node(s) · restarts
    ${fmt(last.actor_restarts || 0, 0)} · updated ${ago(p.updated_at)}`;
  const h = await getJSON(`/runs/${RUN}/history?since=${since}&limit=10000`);
  if (h.items.length) { history.push(...h.items); since = h.next_since; curves(); }
  if (!Object.keys(PARAMS).length) { await parameters(); parameterTable(); }
  try {
    const c = await getJSON(`/runs/${RUN}/curriculum`);
    parameterTable(c.achieved);
    document.getElementById("curriculum").textContent = c.phase ?
      `[L21] phase ${c.phase}, stage ${c.stage}, ER ${fmt(c.explored_ratio, 3)}, ` +
      `${c.elites} elites, P_θ loss ${fmt(c.motion_loss, 4)}` :
      `[WL19] k = ${fmt(c.k, 2)}, μ = ${fmt(c.mu, 2)}, ${c.refills} refills of S, ` +
      `${c.episodes} episodes`;
    await (c.phase ? l21(c) : wl19(c));
  } catch (e) { document.getElementById("curriculum").textContent = "no curriculum yet"; }
  await events();
  document.body.dataset.updated = Date.now();
}
tick().catch(console.error);
setInterval(() => tick().catch(console.error), POLL_MS);
