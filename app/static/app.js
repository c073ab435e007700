// Shared helpers of the review pages: the API token, authorised fetches, small DOM helpers.
// Plain JavaScript, no build step, no network access beyond this server.
"use strict";

const SBSC = (() => {
  // One login per browser: the token is sent once (POST /api/session), then the server's
  // HttpOnly session cookie signs in every tab and the 3D scene until logout or expiry.
  // The token itself is never stored; only the signed-in user is remembered per tab.
  function token() { return null; }
  function forget() { sessionStorage.removeItem("sbsc_user"); }
  async function logout() {
    try { await fetch("/api/session", { method: "DELETE" }); } catch { /* gone anyway */ }
    forget(); location.href = "/index.html";
  }
  // To the login page, coming back here afterwards; never resolves (the page is going away).
  function toLogin() {
    forget();
    location.href = "/index.html?next=" + encodeURIComponent(location.pathname + location.search);
    return new Promise(() => {});
  }
  function user() { try { return JSON.parse(sessionStorage.getItem("sbsc_user") || "null"); } catch { return null; } }

  class ApiError extends Error {
    constructor(status, detail, body) { super(detail); this.status = status; this.body = body; }
  }

  async function api(path, { method = "GET", body, raw = false } = {}) {
    const headers = {};
    const opts = { method, headers, credentials: "same-origin" };
    if (body !== undefined) { headers["Content-Type"] = "application/json"; opts.body = JSON.stringify(body); }
    const res = await fetch(path, opts);
    if (res.status === 401 && !path.endsWith("/api/me")) return toLogin();
    if (!res.ok) {
      let data = null;
      try { data = await res.json(); } catch { /* not JSON */ }
      throw new ApiError(res.status, (data && data.detail) || res.statusText, data);
    }
    return raw ? res : res.json();
  }

  // Images and downloads need the Authorization header too: fetch them as blobs.
  async function blobUrl(path) {
    const res = await api(path, { raw: true });
    return URL.createObjectURL(await res.blob());
  }

  async function download(path, fallbackName) {
    const res = await api(path, { raw: true });
    const cd = res.headers.get("Content-Disposition") || "";
    const m = cd.match(/filename="([^"]+)"/);
    const url = URL.createObjectURL(await res.blob());
    const a = el("a", { href: url, download: m ? m[1] : fallbackName });
    document.body.appendChild(a); a.click(); a.remove();
    setTimeout(() => URL.revokeObjectURL(url), 10000);
  }

  // Upload one file as multipart field "file" with progress callbacks (XHR has upload progress).
  function upload(path, file, onProgress) {
    return new Promise((resolve, reject) => {
      const xhr = new XMLHttpRequest();
      xhr.open("POST", path);
      xhr.upload.onprogress = (e) => { if (e.lengthComputable) onProgress(e.loaded / e.total); };
      xhr.onload = () => {
        let data = null;
        try { data = JSON.parse(xhr.responseText); } catch { /* not JSON */ }
        if (xhr.status >= 200 && xhr.status < 300) resolve(data);
        else reject(new ApiError(xhr.status, (data && data.detail) || xhr.statusText, data));
      };
      xhr.onerror = () => reject(new ApiError(0, "network error during upload"));
      const form = new FormData();
      form.append("file", file, file.name);
      xhr.send(form);
    });
  }

  function el(tag, attrs = {}, ...children) {
    const e = document.createElement(tag);
    for (const [k, v] of Object.entries(attrs)) {
      if (k === "class") e.className = v;
      else if (k === "text") e.textContent = v;
      else if (k.startsWith("on")) e.addEventListener(k.slice(2), v);
      else if (v !== null && v !== undefined && v !== false) e.setAttribute(k, v === true ? "" : v);
    }
    for (const c of children.flat()) if (c !== null && c !== undefined) e.append(c);
    return e;
  }

  function param(name) { return new URLSearchParams(location.search).get(name); }

  function toast(msg, kind = "info") {
    let box = document.getElementById("toast");
    if (!box) { box = el("div", { id: "toast", role: "status", "aria-live": "polite" }); document.body.append(box); }
    box.textContent = msg; box.className = "toast " + kind + " show";
    clearTimeout(box._t); box._t = setTimeout(() => box.classList.remove("show"), 4000);
  }

  // Every page but the login page: require a session and fill in the header.
  async function guard() {
    let me = user();
    if (!me) {
      try { me = await api("/api/me"); } catch (e) { if (e.status === 401) return toLogin(); throw e; }
      sessionStorage.setItem("sbsc_user", JSON.stringify(me));
    }
    const who = document.getElementById("who");
    if (who) who.replaceChildren(el("span", { text: `${me.name} (${me.role})` }), " ",
                                 el("button", { class: "link", onclick: logout, text: "Log out" }));
    return me;
  }

  async function login(t) {
    const res = await fetch("/api/session", { method: "POST", headers: { "Authorization": "Bearer " + t.trim() } });
    let data = null;
    try { data = await res.json(); } catch { /* not JSON */ }
    if (!res.ok) throw new ApiError(res.status, (data && data.detail) || res.statusText, data);
    const me = { id: data.id, name: data.name, role: data.role };
    sessionStorage.setItem("sbsc_user", JSON.stringify(me));
    return me;
  }
  // Whether this browser has a session (a tab opened after the login elsewhere).
  async function signedIn() {
    if (user()) return true;
    const res = await fetch("/api/me", { credentials: "same-origin" });
    if (!res.ok) return false;
    sessionStorage.setItem("sbsc_user", JSON.stringify(await res.json()));
    return true;
  }

  function fmtBytes(n) {
    const u = ["B", "KB", "MB", "GB", "TB"]; let i = 0;
    while (n >= 1024 && i < u.length - 1) { n /= 1024; i++; }
    return `${n.toFixed(i ? 1 : 0)} ${u[i]}`;
  }
  function fmtTime(iso) { return iso ? new Date(iso).toLocaleString() : ""; }

  return { api, blobUrl, download, upload, el, param, toast, guard, login, logout, token, user, signedIn,
           fmtBytes, fmtTime, ApiError };
})();
