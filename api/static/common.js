// Shared by both pages: API calls with the token the user typed (kept in sessionStorage).
const TOKEN_KEY = "thermcap-token";
function headers() {
  const t = sessionStorage.getItem(TOKEN_KEY);
  return t ? { Authorization: "Bearer " + t } : {};
}
async function api(path) {
  const r = await fetch(path, { headers: headers() });
  if (r.status === 401) {
    const t = prompt("This thermcap server needs a token (read scope):");
    if (t) { sessionStorage.setItem(TOKEN_KEY, t); return api(path); }
  }
  if (!r.ok) throw new Error((await r.json()).error || r.statusText);
  return r;
}
async function blobUrl(path) { return URL.createObjectURL(await (await api(path)).blob()); }
function esc(s) { return String(s ?? "").replace(/[&<>"']/g, c => ({"&":"&amp;","<":"&lt;",">":"&gt;",'"':"&quot;","'":"&#39;"}[c])); }
function fmtBytes(n) { const u = ["B","kB","MB","GB","TB"]; let i = 0; while (n >= 1000 && i < 4) { n /= 1000; i++; } return n.toFixed(i ? 1 : 0) + " " + u[i]; }
