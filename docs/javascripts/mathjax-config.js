// One MathJax 3 configuration for every page: concept pages and API docstrings (math wrapped by
// pymdownx.arithmatex in <span/div class="arithmatex">) and notebook pages (Markdown cells rendered
// by nbconvert, math left as $...$ / $$...$$ inside .jp-RenderedMarkdown). MathJax itself is
// served from assets/mathjax/ (fetched by tools/mkdocs_hooks.py), never from a CDN.
const notebookPage = document.querySelector(".jupyter-wrapper") !== null;

window.MathJax = {
  tex: {
    inlineMath: [["$", "$"], ["\\(", "\\)"]],
    displayMath: [["$$", "$$"], ["\\[", "\\]"]],
    processEscapes: true,
    processEnvironments: true,
    tags: "ams",
  },
  // Material loads extra_javascript at the end of <body>, so the page is already parsed here.
  options: notebookPage
    ? {
        // notebook pages: Markdown cells (and Markdown outputs); not code, text outputs or site chrome
        ignoreHtmlClass: "md-header|md-tabs|md-sidebar|md-footer|jp-OutputArea|jp-CodeCell|tex2jax_ignore",
        processHtmlClass: "jp-RenderedMarkdown|arithmatex|tex2jax_process",
      }
    : {
        // concept and API pages: only what pymdownx.arithmatex marked as math
        ignoreHtmlClass: ".*|",
        processHtmlClass: "arithmatex",
      },
};

// Material's instant navigation (if switched on) swaps page content without a reload.
if (typeof document$ !== "undefined") {
  document$.subscribe(() => {
    if (window.MathJax && MathJax.typesetPromise) {
      MathJax.startup.output.clearCache();
      MathJax.typesetClear();
      MathJax.texReset();
      MathJax.typesetPromise();
    }
  });
}
