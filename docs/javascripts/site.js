// Every page: opened from disk (file://), say how to serve the site. Browsers block what a page
// fetches from file:// (search's index, the 3D views' data), and links to a folder show a
// listing instead of its index.html.
(function () {
  if (location.protocol !== "file:" || document.querySelector(".hmt-file-banner")) return;
  const show = () => {
    const p = document.createElement("p");
    p.className = "hmt-file-banner";
    p.innerHTML = "You opened this page as a file: search, links between pages and the 3D views "
      + "need the site served. In the repository run <code>python -m http.server -d site</code> "
      + "(then open <code>http://localhost:8000</code>) or <code>mkdocs serve</code>.";
    document.body.insertBefore(p, document.body.firstChild);
  };
  if (document.readyState === "loading") document.addEventListener("DOMContentLoaded", show);
  else show();
})();
