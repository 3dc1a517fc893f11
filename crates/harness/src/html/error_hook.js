(function () {
  var root = document.documentElement;
  function note(msg) {
    root.setAttribute("data-errors", (root.getAttribute("data-errors") || "") + msg + "\n");
  }
  window.onerror = function (msg, src, line, col) { note(msg + " at " + line + ":" + col); };
  window.addEventListener("unhandledrejection", function (e) { note("unhandled rejection: " + e.reason); });
  // Whether the page fits its window: a width wider than the window means sideways scrolling
  // (tests read these from the dumped DOM).
  window.addEventListener("load", function () {
    root.setAttribute("data-scroll-width", String(root.scrollWidth));
    root.setAttribute("data-client-width", String(root.clientWidth));
  });
})();
