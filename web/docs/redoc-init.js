// Starts ReDoc on /redoc from a file, not an inline script: the page's CSP allows no inline code.
window.addEventListener("load", () => {
  Redoc.init("openapi.json", {}, document.getElementById("redoc"));
});
