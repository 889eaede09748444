"""MkDocs hooks: serve MathJax from the site itself and give notebook pages our one math config.

MathJax 3 (Apache-2.0, https://www.mathjax.org) is not committed. The pinned npm package
``mathjax@3.2.2`` is fetched once into ``.cache/mathjax-3.2.2/`` (gitignored) the first time the
docs are built, checked against the registry's sha512 integrity, and copied into
``site/assets/mathjax/`` after every build. No page loads anything from a CDN.

Notebook pages rendered by mkdocs-jupyter carry nbconvert's MathJax 2 block (an empty
``<script src="">`` and a ``text/x-mathjax-config`` script); we strip it so that every page,
concept, API or notebook, is typeset by the same MathJax 3 with the configuration in
``docs/javascripts/mathjax-config.js`` (``$...$`` inline enabled).

Notebook pages also get: ipywidgets outputs as static, labelled HTML (the widget manager would come
from a CDN and cannot run without a kernel anyway; a tqdm bar becomes its last line of text),
Markdown pipe tables printed as text turned into HTML tables, a table of contents whose links
reach their headings (mkdocs-jupyter's contents drop inline code from a heading's id, its
headings keep it), code cells and prompts kept out of the search index (previews of notebook
hits showed raw code and the copy buttons' "Copied!"), and a lighter page: the 0.6 MB of
Jupyter CSS that nbconvert inlines into every notebook page becomes one cached file for the
whole site, and the figures (base64 PNG, 0.7-1.7 MB a page) become image files next to the page,
loaded lazily.

3D views (``handmesh_tutorial.viz.web3d``): the build copies meshcat's viewer (MIT, from the
installed ``meshcat``) to ``site/javascripts/vendor/meshcat/`` and the views' loader to
``site/javascripts/hmt_views.js`` (listed in ``extra_javascript``), once for the whole site; the
copy of the viewer that a notebook's first view carries inline is removed from notebook pages,
and an explorer's widget (``handmesh_tutorial.viz.explore``) shows its strip of frames.
"""

from __future__ import annotations

import base64
import hashlib
import html
import io
import json
import logging
import re
import shutil
import subprocess
import tarfile
import tempfile
import urllib.request
from pathlib import Path

log = logging.getLogger("mkdocs.hooks.handmesh")

ROOT = Path(__file__).resolve().parents[1]
MATHJAX_VERSION = "3.2.2"
#: ``npm view mathjax@3.2.2 dist.integrity``
MATHJAX_INTEGRITY = (
    "sha512-Bt+SSVU8eBG27zChVewOicYs7Xsdt40qm4+UpHyX7k0/O9NliPc+x77k1/FEsPsjKPZGJvtRZM1vO+geW0OhGw=="
)
MATHJAX_TARBALL = f"https://registry.npmjs.org/mathjax/-/mathjax-{MATHJAX_VERSION}.tgz"
MATHJAX_CACHE = ROOT / ".cache" / f"mathjax-{MATHJAX_VERSION}"
#: What the site needs of the package's ``es5/`` folder: the combined TeX/MathML -> CommonHTML
#: component and what it loads on demand (fonts, TeX extensions, menu, accessibility).
MATHJAX_KEEP = (
    "tex-mml-chtml.js",
    "a11y/",
    "adaptors/",
    "input/",
    "output/chtml/",
    "sre/",
    "ui/",
)
SITE_SUBDIR = "assets/mathjax"


def _integrity_ok(data: bytes) -> bool:
    algo, _, expected = MATHJAX_INTEGRITY.partition("-")
    return base64.b64encode(hashlib.new(algo, data).digest()).decode() == expected


def _download_tarball() -> bytes:
    """The pinned tarball: through ``npm pack`` when npm is installed, else straight from the registry."""
    npm = shutil.which("npm")
    if npm:
        with tempfile.TemporaryDirectory() as tmp:
            proc = subprocess.run(
                [npm, "pack", f"mathjax@{MATHJAX_VERSION}", "--pack-destination", tmp, "--silent"],
                capture_output=True,
                text=True,
                check=False,
            )
            tgz = Path(tmp) / f"mathjax-{MATHJAX_VERSION}.tgz"
            if proc.returncode == 0 and tgz.exists():
                return tgz.read_bytes()
            log.warning("npm pack mathjax@%s failed (%s); downloading the tarball", MATHJAX_VERSION,
                        proc.stderr.strip()[-200:])
    with urllib.request.urlopen(MATHJAX_TARBALL, timeout=120) as response:  # noqa: S310 (pinned https)
        return response.read()


def ensure_mathjax(cache: Path = MATHJAX_CACHE) -> Path:
    """Fetch and unpack the pinned MathJax once; returns the folder holding ``es5/`` and ``LICENSE``."""
    if (cache / "es5" / "tex-mml-chtml.js").is_file():
        return cache
    log.info("fetching mathjax@%s (Apache-2.0) into %s", MATHJAX_VERSION, cache)
    try:
        data = _download_tarball()
    except OSError as exc:  # no network: say what to do instead of a half-working site
        raise RuntimeError(
            f"could not fetch mathjax@{MATHJAX_VERSION} from the npm registry ({exc}); the docs serve "
            f"MathJax from the site itself. Put the package's files in {cache} (es5/ and LICENSE) "
            "or retry with network access."
        ) from exc
    if not _integrity_ok(data):
        raise RuntimeError(f"mathjax-{MATHJAX_VERSION}.tgz does not match {MATHJAX_INTEGRITY}")
    cache.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".tmp-mathjax-{MATHJAX_VERSION}-", dir=cache.parent))
    try:
        with tarfile.open(fileobj=io.BytesIO(data), mode="r:gz") as tar:
            members = []
            for m in tar.getmembers():
                name = m.name.removeprefix("package/")
                if not m.isfile() or ".." in Path(name).parts:
                    continue
                if name in ("LICENSE", "package.json") or (
                    name.startswith("es5/") and name[4:].startswith(MATHJAX_KEEP)
                ):
                    m.name = name
                    members.append(m)
            try:
                tar.extractall(tmp, members=members, filter="data")
            except TypeError:  # Python without extraction filters; members are checked above
                tar.extractall(tmp, members=members)
        tmp.rename(cache)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return cache


def on_config(config, **kwargs):
    ensure_mathjax()
    return config


def on_post_build(config, **kwargs):
    src = ensure_mathjax()
    dest = Path(config["site_dir"]) / SITE_SUBDIR
    shutil.rmtree(dest, ignore_errors=True)
    shutil.copytree(src / "es5", dest)
    shutil.copy2(src / "LICENSE", dest / "LICENSE")
    copy_view_scripts(Path(config["site_dir"]))


def copy_view_scripts(site: Path) -> None:
    """The 3D views' loader and meshcat's viewer (with its licences), served by the site."""
    import importlib.util

    # the notebooks extra; found, not imported (its server side needs ZeroMQ)
    spec = importlib.util.find_spec("meshcat")
    if spec is None or spec.origin is None:
        raise RuntimeError("the 3D views need meshcat's viewer: pip install -e '.[notebooks]'")
    package = Path(spec.origin).parent
    dist = package / "viewer" / "dist"
    vendor = site / "javascripts" / "vendor" / "meshcat"
    vendor.mkdir(parents=True, exist_ok=True)
    for name in ("main.min.js", "main.min.js.LICENSE.txt", "main.min.js.THIRD_PARTY_LICENSES.json"):
        shutil.copy2(dist / name, vendor / name)
    licence = package / "viewer" / "LICENSE"
    if licence.is_file():
        shutil.copy2(licence, vendor / "LICENSE")
    shutil.copy2(ROOT / "handmesh_tutorial" / "viz" / "hmt_views.js",
                 site / "javascripts" / "hmt_views.js")


# nbconvert's MathJax 2 block as mkdocs-jupyter writes it into every notebook page.
_NB_MATHJAX2 = re.compile(r"<!-- Load mathjax -->.*?<!-- End of mathjax configuration -->", re.S)


# mkdocs-jupyter's loader of the ipywidgets HTML manager (from unpkg.com) and the saved widget state
_WIDGET_LOADER = re.compile(
    r"<script>\s*\(function\(\) \{\s*function addWidgetsRenderer\(\).*?\}\(\)\);\s*</script>", re.S
)
_WIDGET_STATE = re.compile(
    r'<script type="application/vnd\.jupyter\.widget-state\+json">\s*(.*?)\s*</script>', re.S
)
_WIDGET_VIEW = re.compile(
    r'<script type="text/javascript">\s*var element = document\.getElementById\([^)]*\);\s*</script>\s*'
    r'<script type="application/vnd\.jupyter\.widget-view\+json">\s*(\{.*?\})\s*</script>',
    re.S,
)
_TAGS = re.compile(r"<[^>]+>")


def _widget_text(model_id: str, state: dict) -> str | None:
    """The final text of a tqdm progress bar widget (HBox: HTML, progress, HTML), else None."""
    box = state.get(model_id, {})
    if box.get("model_name") != "HBoxModel":
        return None
    kids = [state.get(str(c).removeprefix("IPY_MODEL_"), {}) for c in box["state"].get("children", [])]
    names = [k.get("model_name") for k in kids]
    if len(kids) != 3 or names[0] != "HTMLModel" or names[2] != "HTMLModel" or not str(
        names[1]
    ).endswith("ProgressModel"):
        return None
    left, bar, right = (k.get("state", {}) for k in kids)
    total, value = bar.get("max") or 0, bar.get("value") or 0
    filled = int(round(10 * value / total)) if total else 0
    text = f"{left.get('value', '')}|{'█' * filled}{' ' * (10 - filled)}| {right.get('value', '')}"
    return html.unescape(_TAGS.sub("", text)).replace("\xa0", " ").strip()


def _static_widgets(output: str, src: str) -> str:
    """Replace ipywidgets views (which need a live kernel or a CDN script) by static, labelled HTML."""
    match = _WIDGET_STATE.search(output)
    try:
        state = json.loads(match.group(1)).get("state", {}) if match else {}
    except json.JSONDecodeError:
        state = {}

    def view(m: re.Match) -> str:
        try:
            model_id = json.loads(m.group(1)).get("model_id", "")
        except json.JSONDecodeError:
            model_id = ""
        fallback = json.loads(m.group(1)).get("hmt_fallback") if model_id else None
        if isinstance(fallback, str):  # hmt.viz.explore: its strip of frames
            return fallback
        text = _widget_text(model_id, state)
        if text is not None:  # a tqdm bar: its last state as one line of text
            return f'<pre class="hmt-widget-progress">{html.escape(text)}</pre>'
        kind = state.get(model_id, {}).get("model_name", "widget").removesuffix("Model")
        return (
            '<div class="admonition info hmt-widget-fallback"><p class="admonition-title">'
            f"Interactive widget (ipywidgets {html.escape(kind)})</p><p>This output is a live control: "
            "it works when you run the notebook in Jupyter, not on this static page. The static "
            "figure that follows in the notebook shows the same view.</p></div>"
        )

    output, n = _WIDGET_VIEW.subn(view, output)
    output = _WIDGET_LOADER.sub("", output)
    output = _WIDGET_STATE.sub("", output)
    if n:
        log.debug("%s: %d widget views made static", src, n)
    return output


# a text output (stream or text/plain) as nbconvert writes it
_TEXT_OUTPUT = re.compile(r'(<div class="jp-RenderedText[^"]*"[^>]*>\s*)<pre>(.*?)</pre>', re.S)
_TABLE_RULE = re.compile(r"^\|(\s*:?-{3,}:?\s*\|)+\s*$")


def _pipe_tables(output: str) -> str:
    """Turn Markdown pipe tables printed as text (``print(table)``) into HTML tables.

    The notebook keeps its text output (readable in Jupyter's monospace); the site shows a table.
    Lines around a table stay text; ANSI-coloured outputs (``<span>`` inside) are left alone.
    """
    import markdown  # a dependency of mkdocs

    def convert(m: re.Match) -> str:
        body = m.group(2)
        if "|" not in body or "<span" in body:
            return m.group(0)
        lines = html.unescape(body).split("\n")
        if not any(_TABLE_RULE.match(ln.strip()) for ln in lines):
            return m.group(0)
        parts, text, i = [], [], 0
        while i < len(lines):
            if (lines[i].lstrip().startswith("|") and i + 1 < len(lines)
                    and _TABLE_RULE.match(lines[i + 1].strip())):
                j = i + 2
                while j < len(lines) and lines[j].lstrip().startswith("|"):
                    j += 1
                if text:
                    parts.append("<pre>" + html.escape("\n".join(text)) + "</pre>")
                    text = []
                table = markdown.markdown("\n".join(ln.strip() for ln in lines[i:j]),
                                          extensions=["tables"])
                # a class of its own: Material's table:not([class]) style is for prose tables
                table = table.replace("<table>", '<table class="hmt-data">', 1)
                parts.append(f'<div class="hmt-table">{table}</div>')
                i = j
            else:
                text.append(lines[i])
                i += 1
        while text and not text[-1].strip():
            text.pop()
        if text:
            parts.append("<pre>" + html.escape("\n".join(text)) + "</pre>")
        return m.group(1) + "".join(parts)

    return _TEXT_OUTPUT.sub(convert, output)


# the copy of meshcat's viewer that the first 3D view of a kernel carries (the site has its own)
# (nbconvert may reorder the attributes)
_INLINE_VIEWER = re.compile(r'<script\b[^>]*\bclass="hmt-viewer-js"[^>]*>[^<]*</script>')


def _strip_inline_viewer(output: str) -> str:
    return _INLINE_VIEWER.sub("", output)


# nbconvert's permalink inside a heading ("¶")
_ANCHOR_LINK = re.compile(r'<a class="anchor-link"[^>]*>.*?</a>', re.S)
# headings of a rendered notebook: level, id, inner HTML
_HEADING = re.compile(r"<h([1-6])\b[^>]*?\bid=\"([^\"]+)\"[^>]*>(.*?)</h\1>", re.S)


def _fix_toc(toc, content: str) -> int:
    """Point the table of contents at the headings' real ids; returns how many links changed.

    mkdocs-jupyter builds the contents from a Markdown copy of the notebook, whose ids drop inline
    code (``### `pred.json`: what ...`` -> ``what-...``), while the rendered headings keep it
    (``predjson-what-...``): such contents links were dead. Each contents entry takes the first
    heading, after the previous entry's, whose id is its id or ends with ``-`` + its id.
    """
    headings = [(m.group(2), m.group(3)) for m in _HEADING.finditer(content)]
    ids = [h[0] for h in headings]
    fixed, start = 0, 0

    def walk(items):
        nonlocal fixed, start
        for item in items:
            for k in range(start, len(ids)):
                if ids[k] == item.id or ids[k].endswith("-" + item.id):
                    if ids[k] != item.id:
                        item.id = ids[k]
                        # the title lost the code too (": what ..."): the heading's own text
                        text = _ANCHOR_LINK.sub("", headings[k][1])
                        item.title = html.unescape(_TAGS.sub("", text)).strip() or item.title
                        fixed += 1
                    start = k + 1
                    break
            walk(item.children)

    walk(toc)
    return fixed


# what Material's search must not index on a notebook page: the code of code cells (with their
# copy buttons, "Copied!") and the In/Out prompts; the Markdown and the outputs stay searchable
_SEARCH_NOISE = re.compile(
    r'<div class="(?:jp-CodeMirrorEditor jp-Editor jp-InputArea-editor|jp-InputPrompt'
    r'|jp-OutputPrompt)\b'
)


def _exclude_code_from_search(content: str) -> str:
    """Mark code cells and prompts ``data-search-exclude`` (Material's search skips them and
    strips the attribute from the page)."""
    return _SEARCH_NOISE.sub(lambda m: m.group(0).replace("<div ", "<div data-search-exclude ", 1),
                             content)


def on_page_content(html_content, page, config, files, **kwargs):
    if page.file.src_uri.endswith(".ipynb"):
        if page.toc is not None and (n := _fix_toc(page.toc, html_content)):
            log.debug("%s: %d contents links pointed at their headings", page.file.src_uri, n)
        html_content = _exclude_code_from_search(html_content)
    return html_content


# nbconvert's inline CSS (Jupyter's and Pygments'): the same blocks on every notebook page
_BIG_STYLE = re.compile(r"<style\b[^>]*>([^<]{2000,})</style>")
_DATA_IMG = re.compile(r'(<img\b[^>]*?)\ssrc="data:image/(png|jpeg|gif);base64,([A-Za-z0-9+/=\s]+)"')


def _site_root(page) -> str:
    """Relative URL from a page to the site's root (``../../`` for ``notebooks/x/``)."""
    return "../" * page.url.count("/") if page.url else ""


def _lighten(output: str, page, site_dir: Path) -> str:
    """Move nbconvert's big inline CSS blocks to shared files and base64 figures to files.

    CSS: ``assets/notebook-css/<sha1>.css`` (content-addressed: one file for every page that
    has the block). Figures: ``<page folder>/figures/<sha1>.<ext>`` (a figure shown twice is one
    file), with ``loading="lazy"``. Both are relative links, so the pages work under any prefix
    and from ``file://``.
    """
    css_dir = site_dir / "assets" / "notebook-css"

    def css(m: re.Match) -> str:
        body = m.group(1)
        name = hashlib.sha1(body.encode()).hexdigest()[:16] + ".css"
        if not (css_dir / name).is_file():
            css_dir.mkdir(parents=True, exist_ok=True)
            (css_dir / name).write_text(body, encoding="utf-8")
        return f'<link rel="stylesheet" href="{_site_root(page)}assets/notebook-css/{name}">'

    page_dir = Path(page.file.abs_dest_path).parent

    def figure(m: re.Match) -> str:
        data = base64.b64decode(re.sub(r"\s+", "", m.group(3)))
        ext = {"jpeg": "jpg"}.get(m.group(2), m.group(2))
        name = f"{hashlib.sha1(data).hexdigest()[:16]}.{ext}"
        target = page_dir / "figures" / name
        if not target.is_file():
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_bytes(data)
        lazy = "" if "loading=" in m.group(1) else ' loading="lazy"'
        return f'{m.group(1)}{lazy} src="figures/{name}"'

    output = _BIG_STYLE.sub(css, output)
    return _DATA_IMG.sub(figure, output)


def on_post_page(output, page, config, **kwargs):
    if page.file.src_uri.endswith(".ipynb"):
        output = _strip_inline_viewer(output)
        output, n = _NB_MATHJAX2.subn("", output, count=1)
        if n != 1:
            log.warning("%s: no nbconvert MathJax block found to replace", page.file.src_uri)
        output = _static_widgets(output, page.file.src_uri)
        output = _pipe_tables(output)
        output = _lighten(output, page, Path(config["site_dir"]))
    return output
