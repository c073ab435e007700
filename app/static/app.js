// Shared helpers of the review pages: the API token, authorised fetches, small DOM helpers.
// Plain JavaScript, no build step, no network access beyond this server.
"use strict";

const SBSC = (() => {
  const KEY = "sbsc_token";

  function token() { return sessionStorage.getItem(KEY); }
  function setToken(t) { sessionStorage.setItem(KEY, t); }
  function logout() { sessionStorage.removeItem(KEY); sessionStorage.removeItem("sbsc_user"); location.href = "/index.html"; }
  // To the login page, coming back here afterwards; never resolves (the page is going away).
  function toLogin() {
    sessionStorage.removeItem(KEY); sessionStorage.removeItem("sbsc_user");
    location.href = "/index.html?next=" + encodeURIComponent(location.pathname + location.search);
    return new Promise(() => {});
  }
  function user() { try { return JSON.parse(sessionStorage.getItem("sbsc_user") || "null"); } catch { return null; } }

  class ApiError extends Error {
    constructor(status, detail, body) { super(detail); this.status = status; this.body = body; }
  }

  async function api(path, { method = "GET", body, raw = false } = {}) {
    const headers = { "Authorization": "Bearer " + (token() || "") };
    const opts = { method, headers };
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
      xhr.setRequestHeader("Authorization", "Bearer " + token());
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

  // Every page but the login page: require a token and fill in the header.
  async function guard() {
    if (!token()) return toLogin();
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
    setToken(t.trim());
    try {
      const me = await api("/api/me");
      sessionStorage.setItem("sbsc_user", JSON.stringify(me));
      return me;
    } catch (e) { sessionStorage.removeItem(KEY); throw e; }
  }

  function fmtBytes(n) {
    const u = ["B", "KB", "MB", "GB", "TB"]; let i = 0;
    while (n >= 1024 && i < u.length - 1) { n /= 1024; i++; }
    return `${n.toFixed(i ? 1 : 0)} ${u[i]}`;
  }
  function fmtTime(iso) { return iso ? new Date(iso).toLocaleString() : ""; }

  return { api, blobUrl, download, upload, el, param, toast, guard, login, logout, token, user,
           fmtBytes, fmtTime, ApiError };
})();
