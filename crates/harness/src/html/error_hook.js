(function () {
  var root = document.documentElement;
  function note(msg) {
    root.setAttribute("data-errors", (root.getAttribute("data-errors") || "") + msg + "\n");
  }
  window.onerror = function (msg, src, line, col) { note(msg + " at " + line + ":" + col); };
  window.addEventListener("unhandledrejection", function (e) { note("unhandled rejection: " + e.reason); });
})();
