const POLL_MS = 2000;
// every string from the server goes into HTML through this: a task parameter or an event
// message is text, never markup
const esc = v => String(v).replace(/[&<>"']/g, ch => ({"&": "&amp;", "<": "&lt;", ">": "&gt;",
                                                      '"': "&quot;", "'": "&#39;"})[ch]);
async function getJSON(url) {
  const r = await fetch(url);
  if (!r.ok) throw new Error(url + ": " + r.status);
  return r.json();
}
const fmt = (v, d = 1) => v === null || v === undefined ? "–" :
  (typeof v === "number" ? v.toLocaleString(undefined, {maximumFractionDigits: d}) : v);
const ago = t => t ? Math.round(Date.now() / 1000 - t) + " s ago" : "–";
