(function () {
  "use strict";
  var data = JSON.parse(document.getElementById("viewer-data").textContent);
  var root = document.documentElement;
  var KINDS = ["reference", "render", "diff"];
  var NAMES = { reference: "reference", render: "render", diff: "difference" };
  var ZOOMS = [1, 2, 4, 8, 16];
  var sel = document.getElementById("cfg");
  var img = document.getElementById("view");
  var stage = document.getElementById("stage");
  var status = document.getElementById("status");
  var pixel = document.getElementById("pixel");
  var zoomLabel = document.getElementById("zoom-label");
  var kindButtons = {};
  KINDS.forEach(function (k) { kindButtons[k] = document.getElementById("show-" + k); });
  var soloButton = document.getElementById("solo");
  var state = { i: 0, kind: "render", zoom: 1, solo: false };

  // Reads the view from the address fragment; returns whether it named an image kind.
  function parseHash() {
    var asked = false;
    var h = (location.hash || "").replace(/^#/, "");
    h.split("&").forEach(function (part) {
      var eq = part.indexOf("=");
      if (eq < 0) return;
      var key = part.slice(0, eq), value;
      try { value = decodeURIComponent(part.slice(eq + 1)); } catch (e) { return; }
      if (key === "flip" || key === "view") {
        if (value === "difference") value = "diff";
        if (KINDS.indexOf(value) >= 0) { state.kind = value; asked = true; }
      } else if (key === "config") {
        for (var j = 0; j < data.length; j++) {
          if (data[j].id === value) { state.i = j; return; }
        }
        var n = parseInt(value, 10);
        if (String(n) === value && n >= 0 && n < data.length) state.i = n;
      } else if (key === "solo") {
        state.solo = value === "1";
      } else if (key === "zoom") {
        var z = parseInt(value, 10);
        if (ZOOMS.indexOf(z) >= 0) state.zoom = z;
      }
    });
    return asked;
  }

  function writeHash() {
    var h = "#flip=" + state.kind + "&zoom=" + state.zoom + "&config=" +
      encodeURIComponent(data[state.i].id).replace(/%2F/g, "/").replace(/%3A/g, ":") +
      (state.solo ? "&solo=1" : "");
    try { history.replaceState(null, "", h); } catch (e) { /* file:// may refuse; the view still works */ }
  }

  function show() {
    var e = data[state.i];
    var path = e[state.kind];
    KINDS.forEach(function (k) {
      var b = kindButtons[k];
      b.setAttribute("aria-pressed", k === state.kind ? "true" : "false");
      b.disabled = !e[k];
      b.title = e[k] ? e[k] : "no " + NAMES[k] + " image for this configuration";
    });
    sel.value = String(state.i);
    zoomLabel.textContent = state.zoom + "x";
    document.getElementById("zoom-out").disabled = state.zoom === ZOOMS[0];
    document.getElementById("zoom-in").disabled = state.zoom === ZOOMS[ZOOMS.length - 1];
    root.classList.toggle("solo", state.solo);
    soloButton.setAttribute("aria-pressed", state.solo ? "true" : "false");
    root.setAttribute("data-view", state.kind);
    root.setAttribute("data-zoom", String(state.zoom));
    if (!path) {
      img.hidden = true;
      img.removeAttribute("src");
      img.setAttribute("data-kind", "none");
      status.className = "status warn";
      status.textContent = "No " + NAMES[state.kind] + " image for " + e.id +
        (state.kind === "render" ? "." : " (no reference render for its scene and size, or it was not written).");
      return;
    }
    img.hidden = false;
    if (img.getAttribute("src") !== path) img.setAttribute("src", path);
    img.setAttribute("data-kind", state.kind);
    img.alt = NAMES[state.kind] + " of " + e.id;
    img.style.width = (e.width * state.zoom) + "px";
    img.style.height = (e.height * state.zoom) + "px";
    status.className = "status";
    status.textContent = NAMES[state.kind] + ": " + path + " (" + e.width + "x" + e.height + ", zoom " + state.zoom + "x)";
  }

  function update() { show(); writeHash(); }

  function flip(kind) {
    if (!data[state.i][kind]) return;
    state.kind = kind;
    update();
  }

  // Zooms to `z`, keeping the image point under (cx, cy) of the stage where it was.
  function zoomTo(z, cx, cy) {
    if (z === state.zoom) return;
    if (cx === undefined) { cx = stage.clientWidth / 2; cy = stage.clientHeight / 2; }
    var fx = (stage.scrollLeft + cx) / state.zoom, fy = (stage.scrollTop + cy) / state.zoom;
    state.zoom = z;
    update();
    stage.scrollLeft = fx * z - cx;
    stage.scrollTop = fy * z - cy;
  }

  function step(dir, cx, cy) {
    var k = ZOOMS.indexOf(state.zoom) + dir;
    if (k >= 0 && k < ZOOMS.length) zoomTo(ZOOMS[k], cx, cy);
  }

  function select(i) {
    if (i < 0 || i >= data.length) return;
    state.i = i;
    // Keep the kind when the new configuration has it; else fall back to its render.
    if (!data[i][state.kind]) state.kind = data[i].render ? "render" : (data[i].reference ? "reference" : state.kind);
    update();
  }

  var askedKind = parseHash();
  // Without a kind in the address, start on one the first configuration has.
  if (!askedKind && !data[state.i][state.kind]) {
    state.kind = data[state.i].reference ? "reference" : (data[state.i].diff ? "diff" : state.kind);
  }
  KINDS.forEach(function (k) {
    kindButtons[k].addEventListener("click", function () { flip(k); });
  });
  sel.addEventListener("change", function () { select(parseInt(sel.value, 10)); });
  document.getElementById("zoom-in").addEventListener("click", function () { step(1); });
  document.getElementById("zoom-out").addEventListener("click", function () { step(-1); });
  soloButton.addEventListener("click", function () { state.solo = !state.solo; update(); });
  stage.addEventListener("wheel", function (ev) {
    ev.preventDefault();
    var r = stage.getBoundingClientRect();
    step(ev.deltaY < 0 ? 1 : -1, ev.clientX - r.left, ev.clientY - r.top);
  }, { passive: false });
  img.addEventListener("mousemove", function (ev) {
    var x = Math.floor(ev.offsetX / state.zoom), y = Math.floor(ev.offsetY / state.zoom);
    pixel.textContent = "pixel (" + x + ", " + y + ")";
  });
  img.addEventListener("mouseleave", function () { pixel.textContent = ""; });
  img.addEventListener("load", function () { img.setAttribute("data-loaded", img.getAttribute("src")); });
  img.addEventListener("error", function () {
    status.className = "status warn";
    status.textContent = "Could not load " + img.getAttribute("src") + " (file missing from the run folder?).";
    root.setAttribute("data-broken-image", img.getAttribute("src") || "");
  });
  document.addEventListener("keydown", function (ev) {
    if (ev.ctrlKey || ev.metaKey || ev.altKey) return;
    var t = ev.target && ev.target.tagName;
    if (t === "INPUT" || t === "TEXTAREA") return;
    var handled = true;
    switch (ev.key) {
      case "1": flip("reference"); break;
      case "2": flip("render"); break;
      case "3": flip("diff"); break;
      case "+": case "=": step(1); break;
      case "-": case "_": step(-1); break;
      case "[": select(state.i - 1); break;
      case "]": select(state.i + 1); break;
      case "f": state.solo = !state.solo; update(); break;
      default: handled = false;
    }
    if (handled) ev.preventDefault();
  });
  show();
  root.setAttribute("data-ready", "1");
})();
