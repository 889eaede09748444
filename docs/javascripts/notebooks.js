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
