async function tick() {
  const runs = await getJSON("/runs?limit=100");
  const rows = await Promise.all(runs.map(async r => {
    let p = {};
    try { p = await getJSON(`/runs/${encodeURIComponent(r.run_id)}/progress`); } catch (e) {}
    const id = esc(r.run_id);
    return `<tr data-run="${id}"><td><a href="/ui/runs/${encodeURIComponent(r.run_id)}">${id}</a></td>
      <td class="${esc(r.status)}">${esc(r.status)}</td><td>${esc(r.character)}</td><td>${esc(r.name)}</td>
      <td>${fmt(r.env_steps, 0)} / ${fmt(r.total_steps, 0)}</td><td>${fmt(p.steps_per_second, 0)}</td>
      <td>${fmt(p.mean_return)}</td><td>${fmt(p.fall_percent)}</td><td>${ago(r.updated_at)}</td></tr>`;
  }));
  document.getElementById("runs").innerHTML = rows.join("") ||
    '<tr><td colspan="9" class="muted">no runs yet: paramimic train CONFIG</td></tr>';
}
tick(); setInterval(() => tick().catch(console.error), POLL_MS);
