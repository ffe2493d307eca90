async function tick() {
  const runs = await getJSON("/runs?limit=100");
  const rows = await Promise.all(runs.map(async r => {
    let p = {};
    try { p = await getJSON(`/runs/${r.run_id}/progress`); } catch (e) {}
    return `<tr data-run="${r.run_id}"><td><a href="/ui/runs/${r.run_id}">${r.run_id}</a></td>
      <td class="${r.status}">${r.status}</td><td>${r.character}</td><td>${r.name}</td>
      <td>${fmt(r.env_steps, 0)} / ${fmt(r.total_steps, 0)}</td><td>${fmt(p.steps_per_second, 0)}</td>
      <td>${fmt(p.mean_return)}</td><td>${fmt(p.fall_percent)}</td><td>${ago(r.updated_at)}</td></tr>`;
  }));
  document.getElementById("runs").innerHTML = rows.join("") ||
    '<tr><td colspan="9" class="muted">no runs yet: paramimic train CONFIG</td></tr>';
}
tick(); setInterval(() => tick().catch(console.error), POLL_MS);
