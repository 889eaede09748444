"""Open every page of the built docs site in headless Chromium and fail on what a reader would see broken.

Usage: ``python tools/docs_check.py [--site site] [--out build/docs-check]`` (``make docs-check``
builds the site first). The site is served on 127.0.0.1 by a local HTTP server (nothing else is
reached: a request to another host is itself a failure), each page is loaded through the Chrome
DevTools Protocol, MathJax is awaited, and the rendered page is checked for

- raw TeX left in the text (``\\(``, ``\\[``, ``$$``, ``$...\\cmd...$``, ``\\begin{``) or MathJax
  errors (``mjx-merror``),
- raw mermaid source (a ``.mermaid`` block or a ``language-mermaid`` code block),
- visible Sphinx roles (``:func:``, ``:class:`` ...) or literal ``!!! note`` admonitions,
- console errors, uncaught exceptions, failed requests and requests to other hosts,
- images that fail to load,
- 3D views (``div.hmt-view``, ``handmesh_tutorial.viz.web3d``) that do not draw: each is scrolled
  into view and must show its WebGL canvas (WebGL by SwiftShader, no GPU needed) in place of its
  static picture; a screenshot of each view goes to ``--out``. With ``--no-webgl`` Chromium runs
  without WebGL and each view must instead keep its static picture, loaded and visible.

Before the browser, every link of every page is read from the HTML files (no browser needed,
``--links-only`` stops there): a link to a page of the site that does not exist, or to an anchor
(``#id``) that the target page (the same page for ``#id`` alone) does not hold, is a dead link.

Screenshots (the top of the home page, an API page, a concept page and notebook pages, plus the
first formula of pages with math) go to ``--out``; ``report.json`` there lists every page checked.
Needs Debian's ``chromium`` (``apt-get install -y chromium``) and ``websocket-client``.
"""

from __future__ import annotations

import argparse
import base64
import contextlib
import functools
import html.parser
import http.server
import json
import os
import shutil
import signal
import socketserver
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from urllib.parse import unquote, urljoin, urlparse

CHROMIUM_FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    # WebGL for the 3D views without a GPU (SwiftShader, software)
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--hide-scrollbars",
    "--window-size=1400,1000",
]

#: Pages whose screenshots are saved (site-relative paths); every page is checked regardless.
SCREENSHOT_PAGES = (
    "index.html",
    "concepts/metrics/index.html",
    "notebooks/00_quickstart/index.html",
    "api/spiral/index.html",
    "notebooks/03_cylinder_collision/index.html",
    "notebooks/07_multi_path_decoder/index.html",
    "notebooks/08_training/index.html",
    "notebooks/learning_path/index.html",
    "concepts/3d_views/index.html",
)

# Scrolls each 3D view into view (they start lazily), waits until each has started or failed;
# returns the problems and each view's box (for a screenshot).
VIEWS_PROBE = r"""
(async () => {
  const views = [...document.querySelectorAll(".hmt-view")];
  const problems = [];
  const boxes = [];
  for (const [i, el] of views.entries()) {
    el.scrollIntoView({block: "center"});
    const t0 = Date.now();
    while (!["ready", "failed"].includes(el.dataset.state) && Date.now() - t0 < 30000)
      await new Promise(r => setTimeout(r, 100));
    await new Promise(r => setTimeout(r, 300));   // a few frames drawn
    const canvas = el.querySelector("canvas");
    if (el.dataset.state !== "ready")
      problems.push(`3D view ${i + 1} did not start (${el.dataset.state || "never seen"}): `
                    + (el.textContent || "").slice(0, 160));
    else if (!canvas || canvas.width < 50 || canvas.height < 50)
      problems.push(`3D view ${i + 1} has no canvas`);
    const r = el.getBoundingClientRect();
    boxes.push({x: r.left, y: r.top + window.scrollY, width: r.width, height: r.height});
  }
  window.scrollTo(0, 0);
  return {problems, boxes};
})()
"""

# --no-webgl: each 3D view must fail to start and keep its static picture, loaded and visible.
VIEWS_PICTURE_PROBE = r"""
(async () => {
  const views = [...document.querySelectorAll(".hmt-view")];
  const problems = [];
  const boxes = [];
  for (const [i, el] of views.entries()) {
    el.scrollIntoView({block: "center"});
    const t0 = Date.now();
    while (!["ready", "failed"].includes(el.dataset.state) && Date.now() - t0 < 30000)
      await new Promise(r => setTimeout(r, 100));
    const img = el.querySelector("img.hmt-view-picture");
    if (img) { img.loading = "eager"; await img.decode().catch(() => null); }
    const r = el.getBoundingClientRect();
    const ir = img && img.getBoundingClientRect();
    if (el.dataset.state === "ready")
      problems.push(`3D view ${i + 1} started although WebGL is off`);
    else if (!img || !img.complete || img.naturalWidth === 0)
      problems.push(`3D view ${i + 1} shows no static picture`);
    else if (ir.width < 0.5 * r.width && ir.height < 0.5 * r.height)
      problems.push(`3D view ${i + 1}: its picture is ${ir.width}x${ir.height} in a ${r.width}x${r.height} box`);
    boxes.push({x: r.left, y: r.top + window.scrollY, width: r.width, height: r.height});
  }
  window.scrollTo(0, 0);
  return {problems, boxes};
})()
"""

# Runs inside each page once MathJax has finished; returns the problems a reader would see.
PAGE_PROBE = r"""
(async () => {
  const problems = [];
  const root = document.querySelector("article") || document.body;
  // .clipboard-copy-txt: the hidden plain-text copy of a notebook cell (what the copy button copies)
  const SKIP = "pre, code, script, style, textarea, mjx-container, .MathJax, .highlight, svg, " +
    ".clipboard-copy-txt";
  const walker = document.createTreeWalker(root, NodeFilter.SHOW_TEXT, {
    acceptNode: (n) => (n.parentElement && n.parentElement.closest(SKIP))
      ? NodeFilter.FILTER_REJECT : NodeFilter.FILTER_ACCEPT,
  });
  let text = "";
  for (let n = walker.nextNode(); n; n = walker.nextNode()) text += n.nodeValue + "\u0001";
  const near = (i) => text.slice(Math.max(0, i - 30), i + 70).replace(/\u0001/g, " ");
  const rules = [
    ["raw TeX", /\\\(|\\\)|\\\[|\\\]|\$\$|\\begin\{|\$[^$\u0001]{0,80}\\[A-Za-z]+[^$\u0001]{0,80}\$/g],
    // the role's backticks become a <code> element (skipped here, hence the \u0001 separator)
    ["Sphinx role", /:(mod|class|func|meth|attr|data|obj|exc|ref):(?=[`\u0001]|$)/gm],
    ["literal admonition", /^\s*!!!\s+\w+/gm],
    ["raw mermaid", /\b(flowchart|graph) (LR|TD|TB|RL)\b/g],
  ];
  for (const [kind, re] of rules) {
    let m; let count = 0;
    while ((m = re.exec(text)) !== null && count < 5) { problems.push(kind + ": ..." + near(m.index) + "..."); count++; }
  }
  for (const e of document.querySelectorAll("mjx-merror, .MathJax_Error"))
    problems.push("MathJax error: " + (e.getAttribute("data-mjx-error") || e.textContent).slice(0, 120));
  for (const e of document.querySelectorAll("pre.mermaid, code.language-mermaid, div.mermaid"))
    if (!(e.shadowRoot && e.shadowRoot.querySelector("svg")) && !e.querySelector("svg"))
      problems.push("raw mermaid block: " + e.textContent.slice(0, 60));
  // a mermaid fence whose renderer did not run is left as a code block (class removed)
  const MERMAID = /^\s*(flowchart|graph|sequenceDiagram|classDiagram|stateDiagram|erDiagram|gantt|pie)\b/;
  for (const e of root.querySelectorAll("pre"))
    if (MERMAID.test(e.textContent)) problems.push("raw mermaid source: " + e.textContent.slice(0, 60));
  const images = [...document.querySelectorAll("img")];
  // lazily loaded figures (tools/mkdocs_hooks.py) are fetched now, as a reader scrolling would
  for (const img of images) img.loading = "eager";
  await Promise.all(images.map((img) => img.decode().catch(() => null)));
  for (const img of images)
    if (!img.complete || img.naturalWidth === 0)
      problems.push("image failed to load: " + (img.currentSrc || img.src).slice(0, 120));
  return {
    problems,
    title: document.title,
    math: document.querySelectorAll("mjx-container").length,
    images: images.length,
    width: document.documentElement.scrollWidth,
  };
})()
"""


class _Quiet(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *args):
        pass


@contextlib.contextmanager
def serve(site: Path):
    handler = functools.partial(_Quiet, directory=str(site))
    socketserver.TCPServer.allow_reuse_address = True
    with socketserver.ThreadingTCPServer(("127.0.0.1", 0), handler) as httpd:
        thread = threading.Thread(target=httpd.serve_forever, daemon=True)
        thread.start()
        try:
            yield f"http://127.0.0.1:{httpd.server_address[1]}/"
        finally:
            httpd.shutdown()


def find_chromium() -> str:
    for name in ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable"):
        path = shutil.which(name)
        if path:
            return path
    sys.exit(
        "docs-check needs headless Chromium: install Debian's package with\n"
        "    sudo apt-get install -y chromium\n"
        "(make docs-check does this itself when run as root)."
    )


class Browser:
    """Chromium driven over the DevTools protocol: one tab, events collected per page."""

    def __init__(self, chromium: str, profile: Path, no_webgl: bool = False):
        import websocket  # websocket-client (a jupyter_server dependency, listed in the docs extra)

        flags = CHROMIUM_FLAGS + (["--disable-webgl", "--disable-3d-apis"] if no_webgl else [])
        self.proc = subprocess.Popen(
            [chromium, *flags, f"--user-data-dir={profile}", "--remote-debugging-port=0",
             "about:blank"],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            start_new_session=True,  # its own process group: close() stops its helpers too
        )
        port_file = profile / "DevToolsActivePort"
        deadline = time.time() + 60
        while not port_file.exists() or len(port_file.read_text().splitlines()) < 2:
            if time.time() > deadline or self.proc.poll() is not None:
                raise RuntimeError("Chromium did not start (no DevToolsActivePort)")
            time.sleep(0.1)
        port = port_file.read_text().splitlines()[0]
        import urllib.request

        for _ in range(100):
            with contextlib.suppress(OSError):
                targets = json.load(urllib.request.urlopen(f"http://127.0.0.1:{port}/json", timeout=5))
                pages = [t for t in targets if t.get("type") == "page"]
                if pages:
                    break
            time.sleep(0.1)
        self.ws = websocket.create_connection(pages[0]["webSocketDebuggerUrl"], timeout=120,
                                              suppress_origin=True)
        self._id = 0
        self.events: list[dict] = []
        for domain in ("Page", "Runtime", "Log", "Network"):
            self.call(f"{domain}.enable")
        self.call("Emulation.setDeviceMetricsOverride", width=1400, height=1000,
                  deviceScaleFactor=1, mobile=False)

    def call(self, method: str, **params):
        self._id += 1
        my_id = self._id
        self.ws.send(json.dumps({"id": my_id, "method": method, "params": params}))
        while True:
            msg = json.loads(self.ws.recv())
            if msg.get("id") == my_id:
                if "error" in msg:
                    raise RuntimeError(f"{method}: {msg['error']}")
                return msg.get("result", {})
            if "method" in msg:
                self.events.append(msg)

    def wait_event(self, name: str, timeout: float = 60.0):
        deadline = time.time() + timeout
        for i, e in enumerate(self.events):
            if e["method"] == name:
                return self.events.pop(i)
        while time.time() < deadline:
            msg = json.loads(self.ws.recv())
            if "method" in msg:
                if msg["method"] == name:
                    return msg
                self.events.append(msg)
        raise TimeoutError(name)

    def evaluate(self, expression: str, await_promise: bool = False):
        result = self.call("Runtime.evaluate", expression=expression, returnByValue=True,
                           awaitPromise=await_promise)
        if "exceptionDetails" in result:
            raise RuntimeError(result["exceptionDetails"].get("text", "evaluate failed"))
        return result["result"].get("value")

    def screenshot(self, path: Path, clip: dict | None = None):
        params = {"format": "png"}
        if clip:
            params.update(clip=clip | {"scale": 1}, captureBeyondViewport=True)
        data = self.call("Page.captureScreenshot", **params)["data"]
        path.write_bytes(base64.b64decode(data))

    def close(self):
        with contextlib.suppress(Exception):
            self.ws.close()
        # Chromium's helper processes (zygote, renderers, crash handler) outlive the main one and
        # kept writing to the profile while it was being removed ("Directory not empty"): stop
        # the whole process group.
        with contextlib.suppress(ProcessLookupError):
            os.killpg(self.proc.pid, signal.SIGTERM)
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(self.proc.pid, signal.SIGKILL)
            self.proc.wait(timeout=10)


def event_problems(events: list[dict], base: str) -> list[str]:
    out = []
    host = urlparse(base).netloc
    for e in events:
        m, p = e["method"], e.get("params", {})
        if m == "Runtime.consoleAPICalled" and p.get("type") in ("error", "assert"):
            args = " ".join(str(a.get("value", a.get("description", ""))) for a in p.get("args", []))
            out.append(f"console error: {args[:200]}")
        elif m == "Runtime.exceptionThrown":
            d = p.get("exceptionDetails", {})
            out.append(f"uncaught exception: {d.get('exception', {}).get('description', d.get('text'))}"[:240])
        elif m == "Log.entryAdded" and p.get("entry", {}).get("level") == "error":
            entry = p["entry"]
            out.append(f"console error: {entry.get('text', '')} {entry.get('url', '')}"[:240])
        elif m == "Network.loadingFailed" and not p.get("canceled"):
            out.append(f"request failed: {p.get('errorText')}")
        elif m == "Network.requestWillBeSent":
            url = p.get("request", {}).get("url", "")
            if url.startswith("http") and urlparse(url).netloc != host:
                out.append(f"request to another host (not offline-safe): {url[:160]}")
    return out


class _Links(html.parser.HTMLParser):
    """The ids (``id=``, ``<a name=>``) and the ``<a href>`` targets of one HTML page."""

    def __init__(self):
        super().__init__(convert_charrefs=True)
        self.ids: set[str] = set()
        self.hrefs: list[str] = []

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if a.get("id"):
            self.ids.add(a["id"])
        if tag == "a" and a.get("name"):
            self.ids.add(a["name"])
        if tag == "a" and a.get("href"):
            self.hrefs.append(a["href"])


def _page_links(path: Path) -> _Links:
    parser = _Links()
    parser.feed(path.read_text(encoding="utf-8", errors="replace"))
    return parser


def check_links(site: Path) -> dict[str, list[str]]:
    """Dead links of a built site, read from its HTML files: ``{page: [problem, ...]}``.

    A link is dead when it points inside the site (relative, or absolute without a host) to a
    file that does not exist (a folder counts when it holds ``index.html``), or carries an anchor
    ``#id`` that the target HTML page does not hold (``#id`` alone: the page itself). Links to
    other hosts, ``mailto:`` and a bare ``#`` are not checked. Pages under ``assets/`` and
    ``search/`` are skipped; every other ``.html`` file is read.

    Args:
        site: the built site's folder (``mkdocs build`` writes ``site/``).

    Returns:
        Only the pages with dead links, each with its problems (``href -> why``).
    """
    site = site.resolve()
    pages = sorted(p for p in site.rglob("*.html")
                   if p.relative_to(site).parts[0] not in ("assets", "search"))
    parsed: dict[Path, _Links] = {}

    def links(path: Path) -> _Links:
        if path not in parsed:
            parsed[path] = _page_links(path)
        return parsed[path]

    dead: dict[str, list[str]] = {}
    for page in pages:
        rel = page.relative_to(site).as_posix()
        base = "http://site.invalid/" + rel
        for href in links(page).hrefs:
            url = urlparse(urljoin(base, href))
            if url.scheme not in ("http", "https") or url.netloc != "site.invalid":
                continue                                 # another host, mailto:, javascript:
            target = site / unquote(url.path).lstrip("/")
            if target.is_dir() or url.path.endswith("/"):
                target = target / "index.html"
            problem = None
            if not target.is_file():
                problem = f"{href} -> no such file: {target.relative_to(site).as_posix()}"
            elif url.fragment and target.suffix == ".html":
                if unquote(url.fragment) not in links(target).ids:
                    where = "this page" if target == page else target.relative_to(site).as_posix()
                    problem = f"{href} -> no id {unquote(url.fragment)!r} in {where}"
            if problem and problem not in dead.get(rel, []):
                dead.setdefault(rel, []).append(problem)
    return dead


def site_pages(site: Path) -> list[str]:
    pages = sorted(str(p.relative_to(site)) for p in site.rglob("index.html"))
    return [p for p in pages if not p.startswith(("assets/", "search/"))]


def check_site(site: Path, out: Path, pages: list[str] | None = None,
               no_webgl: bool = False) -> dict:
    out.mkdir(parents=True, exist_ok=True)
    chromium = find_chromium()
    pages = pages or site_pages(site)
    report: dict = {"site": str(site), "pages": {}, "screenshots": []}
    # ignore_cleanup_errors: a helper process that still writes to the profile as it is removed
    # must not fail a check whose pages all passed
    with serve(site) as base, tempfile.TemporaryDirectory(prefix="docs-check-profile-",
                                                          ignore_cleanup_errors=True) as prof:
        browser = Browser(chromium, Path(prof), no_webgl=no_webgl)
        try:
            for rel in pages:
                url = base + rel
                browser.events.clear()
                t0 = time.time()
                browser.call("Page.navigate", url=url)
                browser.wait_event("Page.loadEventFired", timeout=120)
                # MathJax typesets after load; wait for it (pages without it resolve at once)
                browser.evaluate(
                    "(window.MathJax && MathJax.startup && MathJax.startup.promise) "
                    "? MathJax.startup.promise.then(() => true) : Promise.resolve(false)",
                    await_promise=True,
                )
                browser.evaluate("new Promise(r => setTimeout(r, 200))", await_promise=True)
                probe = browser.evaluate(PAGE_PROBE, await_promise=True)
                views = {"problems": [], "boxes": []}
                if browser.evaluate("document.querySelectorAll('.hmt-view').length"):
                    views = browser.evaluate(VIEWS_PICTURE_PROBE if no_webgl else VIEWS_PROBE,
                                             await_promise=True)
                browser.call("Runtime.evaluate", expression="0")  # flush queued events
                events = event_problems(browser.events, base)
                if no_webgl:   # three.js says so when it finds no WebGL: expected here
                    events = [e for e in events if "Error creating WebGL context" not in e]
                problems = probe["problems"] + views["problems"] + events
                entry = {
                    "title": probe["title"],
                    "math": probe["math"],
                    "images": probe["images"],
                    "seconds": round(time.time() - t0, 2),
                    "problems": problems,
                    "views": len(views["boxes"]),
                }
                stem = rel.removesuffix("index.html").strip("/").replace("/", "__") or "home"
                for k, box in enumerate(views["boxes"]):
                    vshot = out / f"{stem}__view{k + 1}.png"
                    browser.screenshot(vshot, clip=box)
                    report["screenshots"].append(str(vshot))
                if rel in SCREENSHOT_PAGES:
                    stem = rel.removesuffix("index.html").strip("/").replace("/", "__") or "home"
                    shot = out / f"{stem}.png"
                    browser.screenshot(shot)
                    entry["screenshot"] = str(shot)
                    report["screenshots"].append(str(shot))
                    if probe["math"]:
                        box = browser.evaluate(
                            "(() => { const r = document.querySelector('mjx-container[display=\"true\"], "
                            "mjx-container').getBoundingClientRect(); return {x: 0, y: Math.max(0, "
                            "r.top + window.scrollY - 250), width: 1400, height: 600}; })()"
                        )
                        mshot = out / f"{stem}__math.png"
                        browser.screenshot(mshot, clip=box)
                        report["screenshots"].append(str(mshot))
                report["pages"][rel] = entry
                flag = "FAIL" if problems else "ok  "
                print(f"{flag} {rel}  ({entry['math']} formulas, {entry['images']} images, "
                      f"{entry['views']} 3D views, {entry['seconds']} s)", flush=True)
                for p in problems[:12]:
                    print(f"       {p}", flush=True)
        finally:
            browser.close()
    (out / "report.json").write_text(json.dumps(report, indent=1))
    return report


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--site", type=Path, default=Path("site"))
    ap.add_argument("--out", type=Path, default=Path("build/docs-check"))
    ap.add_argument("--no-webgl", action="store_true",
                    help="Chromium without WebGL: every 3D view must show its static picture")
    ap.add_argument("--links-only", action="store_true",
                    help="check the links and anchors of the HTML files only (no browser)")
    ap.add_argument("pages", nargs="*", help="site-relative pages (default: every page)")
    args = ap.parse_args(argv)
    if not (args.site / "index.html").exists():
        sys.exit(f"{args.site}/index.html not found: build the site first (mkdocs build --strict)")
    t0 = time.time()
    dead = check_links(args.site)
    for page, problems in dead.items():
        print(f"DEAD {page}", flush=True)
        for p in problems[:12]:
            print(f"       {p}", flush=True)
    n_dead = sum(len(p) for p in dead.values())
    print(f"links: {n_dead} dead links or anchors on {len(dead)} pages ({time.time() - t0:.0f} s)")
    if args.links_only:
        return 1 if dead else 0
    report = check_site(args.site, args.out, args.pages or None, no_webgl=args.no_webgl)
    report["dead_links"] = dead
    (args.out / "report.json").write_text(json.dumps(report, indent=1))
    bad = {p: e["problems"] for p, e in report["pages"].items() if e["problems"]}
    bad.update({p: v for p, v in dead.items() if p not in bad})
    n = len(report["pages"])
    formulas = sum(e["math"] for e in report["pages"].values())
    print(f"\ndocs-check: {n} pages, {formulas} formulas typeset, {len(bad)} with problems "
          f"({time.time() - t0:.0f} s)")
    print("screenshots:")
    for s in report["screenshots"]:
        print(f"  {s}")
    print(f"report: {args.out / 'report.json'}")
    return 1 if bad else 0


if __name__ == "__main__":
    os.environ.setdefault("PYTHONUNBUFFERED", "1")
    sys.exit(main())
