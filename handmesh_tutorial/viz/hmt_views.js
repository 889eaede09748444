/* handmesh_tutorial 3D views (handmesh_tutorial/viz/web3d.py): start each `div.hmt-view` when it
 * scrolls into view, with meshcat's viewer (three.js, MIT). The viewer comes from, in order:
 * an inline gzip+base64 copy in the page (`script.hmt-viewer-js`, Jupyter), or the site's own copy
 * next to this file (`vendor/meshcat/main.min.js`, docs). The scene comes from `data-payload`
 * (base64) or `data-src` (a file on the same site): meshcat commands, each prefixed by its length
 * (uint32, little-endian). Nothing is loaded from another host. Each view holds a static picture
 * (`img.hmt-view-picture`, drawn by matplotlib) that shows until the live view has drawn; a view
 * that cannot start (no WebGL, a page opened as a file) keeps its picture and says why. */
(function () {
  "use strict";
  if (window.hmtViews) {
    window.hmtViews.scan();
    return;
  }
  const own = document.currentScript && document.currentScript.src;
  const H = (window.hmtViews = {});
  let viewer = null;

  function bytesOf(b64) {
    const s = atob(b64.replace(/\s+/g, ""));
    const out = new Uint8Array(s.length);
    for (let i = 0; i < s.length; i++) out[i] = s.charCodeAt(i);
    return out;
  }

  async function inlineViewer() {
    const el = document.querySelector("script.hmt-viewer-js");
    if (!el) return false;
    const gz = new Blob([bytesOf(el.textContent)]).stream();
    const text = await new Response(gz.pipeThrough(new DecompressionStream("gzip"))).text();
    // a UMD bundle: hide AMD/CommonJS loaders so that it sets window.MeshCat
    new Function("define", "exports", "module", text).call(window);
    return true;
  }

  function siteViewer() {
    const src = own || (document.querySelector('script[src$="hmt_views.js"]') || {}).src;
    if (!src) return Promise.reject(new Error("no meshcat viewer in this page: display a view "
      + "from a fresh kernel (its first view carries the viewer)"));
    const url = new URL("vendor/meshcat/main.min.js", src).href;
    return new Promise((ok, fail) => {
      const s = document.createElement("script");
      s.src = url;
      s.onload = ok;
      s.onerror = () => fail(new Error("could not load " + url));
      document.head.appendChild(s);
    });
  }

  function loadViewer() {
    if (window.MeshCat) return Promise.resolve(window.MeshCat);
    if (!viewer) {
      viewer = inlineViewer().then((done) => (done ? null : siteViewer()))
        .then(() => window.MeshCat);
    }
    return viewer;
  }

  async function payload(el) {
    if (el.dataset.payload) return bytesOf(el.dataset.payload);
    const r = await fetch(new URL(el.dataset.src, document.baseURI));
    if (!r.ok) throw new Error(el.dataset.src + ": HTTP " + r.status);
    return new Uint8Array(await r.arrayBuffer());
  }

  async function start(el) {
    el.dataset.state = "loading";
    const note = el.querySelector(".hmt-view-note");
    let pane = null;
    try {
      const [MeshCat, bytes] = await Promise.all([loadViewer(), payload(el)]);
      pane = document.createElement("div");
      pane.className = "hmt-view-pane";
      pane.style.cssText = "position:absolute;inset:0;";
      el.appendChild(pane);
      const v = new MeshCat.Viewer(pane);
      const resize = v.set_3d_pane_size.bind(v);
      v.set_3d_pane_size = () => resize(pane.clientWidth, pane.clientHeight);
      v.set_3d_pane_size();
      const data = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
      for (let off = 0; off < bytes.length;) {
        const n = data.getUint32(off, true);
        v.handle_command_bytearray(bytes.slice(off + 4, off + 4 + n));
        off += 4 + n;
      }
      if (note) note.remove();
      const picture = el.querySelector(".hmt-view-picture");
      if (picture) picture.remove();
      el.dataset.state = "ready";
      el.hmtViewer = v;
    } catch (err) {
      el.dataset.state = "failed";
      if (pane) pane.remove();   // a viewer that failed half-way: the picture shows again
      const hint = location.protocol === "file:"
        ? " Pages opened as files cannot fetch a view's data: serve the site (python -m http.server -d site)."
        : "";
      if (note) {
        note.textContent = (el.querySelector(".hmt-view-picture") ? "Static picture: the" : "The")
          + " 3D view could not start here (" + String(err.message).replace(/\.$/, "") + ")." + hint;
      }
      console.warn("hmt view:", err);
    }
  }

  const watch = "IntersectionObserver" in window ? new IntersectionObserver((entries) => {
    for (const e of entries) {
      if (e.isIntersecting) {
        watch.unobserve(e.target);
        start(e.target);
      }
    }
  }, { rootMargin: "200px" }) : null;

  H.scan = function () {
    for (const el of document.querySelectorAll(".hmt-view:not([data-state])")) {
      el.dataset.state = "waiting";
      if (watch) watch.observe(el);
      else start(el);
    }
  };
  H.start = start;
  if (document.readyState === "loading") document.addEventListener("DOMContentLoaded", H.scan);
  else H.scan();
})();
