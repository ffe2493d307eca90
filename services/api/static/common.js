const POLL_MS = 2000;
async function getJSON(url) {
  const r = await fetch(url);
  if (!r.ok) throw new Error(url + ": " + r.status);
  return r.json();
}
const fmt = (v, d = 1) => v === null || v === undefined ? "–" :
  (typeof v === "number" ? v.toLocaleString(undefined, {maximumFractionDigits: d}) : v);
const ago = t => t ? Math.round(Date.now() / 1000 - t) + " s ago" : "–";
