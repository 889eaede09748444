// Notebook pages: click a figure to see it at full size in an overlay; click again (or Esc) to close.
document.addEventListener("click", (event) => {
  const img = event.target.closest(".jupyter-wrapper .jp-OutputArea-output img");
  const open = document.querySelector(".hmt-lightbox");
  if (open) {
    open.remove();
    return;
  }
  if (!img) return;
  const box = document.createElement("div");
  box.className = "hmt-lightbox";
  const big = document.createElement("img");
  big.src = img.src;
  big.alt = img.alt || "figure at full size";
  box.appendChild(big);
  document.body.appendChild(box);
});
document.addEventListener("keydown", (event) => {
  if (event.key === "Escape") document.querySelector(".hmt-lightbox")?.remove();
});

// Wide output tables scroll inside their cell: fade the right edge while more lies to the right.
function hmtMarkOverflow() {
  for (const el of document.querySelectorAll(
    ".jupyter-wrapper .md-typeset__scrollwrap, .jupyter-wrapper .hmt-table")) {
    const update = () => el.classList.toggle("hmt-more-right",
      el.scrollLeft + el.clientWidth < el.scrollWidth - 2);
    if (!el.dataset.hmtOverflow) {
      el.dataset.hmtOverflow = "1";
      el.addEventListener("scroll", update, { passive: true });
    }
    update();
  }
}
window.addEventListener("load", hmtMarkOverflow);
window.addEventListener("resize", hmtMarkOverflow);
