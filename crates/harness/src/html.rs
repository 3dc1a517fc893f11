//! `report.html`: one self-contained page per run folder (inline CSS and JavaScript, no
//! network) with the summary tables of [`summary_markdown`], the SVG plots of `plots/`
//! inlined, and an image viewer that flips between the reference, a configuration's render
//! and its difference heatmap at a shared pixel zoom. Images stay files in `images/` and are
//! referenced by relative path, so the page works wherever the run folder is copied.
//!
//! The viewer honours a URL fragment at load: `#flip=reference|render|diff`, `config=ID` (a
//! configuration id or its index) and `zoom=1..16`, e.g. `report.html#flip=diff&zoom=4`.

use std::fmt::Write as _;
use std::path::Path;

use serde::Serialize;

use crate::bench::slug;
use crate::report::summary_markdown;
use crate::results::{Results, Row};

/// Largest plot file that is inlined; larger ones are linked as images.
const PLOT_CAP_BYTES: u64 = 16 << 20;

/// Escapes `s` for HTML text and attribute values (`&`, `<`, `>`, `"`, `'`).
pub fn escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

/// A relative file path as a URL path: bytes outside `A-Za-z0-9-._~/` percent-encoded.
fn url_path(p: &str) -> String {
    let mut out = String::with_capacity(p.len());
    for b in p.bytes() {
        if b.is_ascii_alphanumeric() || b"-._~/".contains(&b) {
            out.push(b as char);
        } else {
            let _ = write!(out, "%{b:02X}");
        }
    }
    out
}

/// Inline Markdown of the summary: `` `code` ``, `**bold**`; everything else escaped text.
/// An unmatched backtick or `**` stays literal.
fn inline(s: &str) -> String {
    let mut out = String::new();
    let mut rest = s;
    let mut bold = false;
    loop {
        let tick = rest.find('`');
        let star = rest.find("**");
        match (tick, star) {
            (Some(t), s2) if s2.is_none_or(|s2| t < s2) => {
                if let Some(end) = rest[t + 1..].find('`') {
                    out.push_str(&escape(&rest[..t]));
                    let _ = write!(out, "<code>{}</code>", escape(&rest[t + 1..t + 1 + end]));
                    rest = &rest[t + 2 + end..];
                } else {
                    out.push_str(&escape(&rest[..=t]));
                    rest = &rest[t + 1..];
                }
            }
            (_, Some(st)) => {
                let closes = bold || rest[st + 2..].contains("**");
                out.push_str(&escape(&rest[..st]));
                if closes {
                    out.push_str(if bold { "</strong>" } else { "<strong>" });
                    bold = !bold;
                } else {
                    out.push_str("**");
                }
                rest = &rest[st + 2..];
            }
            _ => {
                out.push_str(&escape(rest));
                break;
            }
        }
    }
    if bold {
        out.push_str("</strong>");
    }
    out
}

/// The cells of a pipe-table line (`| a | b |`), trimmed.
fn cells(line: &str) -> Vec<&str> {
    let t = line.trim();
    let t = t.strip_prefix('|').unwrap_or(t);
    let t = t.strip_suffix('|').unwrap_or(t);
    t.split('|').map(str::trim).collect()
}

fn is_separator(line: &str) -> bool {
    let t = line.trim();
    t.starts_with('|') && t.contains('-') && t.chars().all(|c| "|-: ".contains(c))
}

/// Whether a table cell reads as a number (right-aligned).
fn numeric(cell: &str) -> bool {
    let c = cell.trim_start_matches('-');
    c.starts_with(|ch: char| ch.is_ascii_digit()) || cell == "n/a"
}

/// Open block while converting Markdown.
#[derive(PartialEq)]
enum Block {
    None,
    Paragraph,
    List,
    Table,
}

/// Converts the Markdown subset [`summary_markdown`] writes (ATX headings, paragraphs, `- `
/// bullet lists, pipe tables, inline code and bold) to HTML, escaping all text. Returns the
/// HTML and the `(id, text)` of every `##` heading for a table of contents.
pub fn markdown_to_html(md: &str) -> (String, Vec<(String, String)>) {
    let mut out = String::new();
    let mut toc = Vec::new();
    let mut block = Block::None;
    let mut table_head = false;
    let mut sections = 0usize;
    let close = |block: &mut Block, out: &mut String| {
        out.push_str(match block {
            Block::None => "",
            Block::Paragraph => "</p>\n",
            Block::List => "</ul>\n",
            Block::Table => "</tbody></table></div>\n",
        });
        *block = Block::None;
    };
    for line in md.lines() {
        let t = line.trim_end();
        let hashes = t.chars().take_while(|&c| c == '#').count();
        if t.trim().is_empty() {
            close(&mut block, &mut out);
        } else if (1..=6).contains(&hashes) && t[hashes..].starts_with(' ') {
            close(&mut block, &mut out);
            let text = t[hashes..].trim();
            if hashes == 2 {
                sections += 1;
                let id = format!("section-{sections}");
                let _ = writeln!(out, "<h2 id=\"{id}\">{}</h2>", inline(text));
                toc.push((id, text.replace('`', "")));
            } else {
                let _ = writeln!(out, "<h{hashes}>{}</h{hashes}>", inline(text));
            }
        } else if let Some(item) = t.strip_prefix("- ") {
            if block != Block::List {
                close(&mut block, &mut out);
                out.push_str("<ul>\n");
                block = Block::List;
            }
            let _ = writeln!(out, "<li>{}</li>", inline(item));
        } else if t.trim_start().starts_with('|') {
            if block != Block::Table {
                close(&mut block, &mut out);
                out.push_str("<div class=\"table-wrap\"><table>\n");
                block = Block::Table;
                table_head = true;
            }
            if is_separator(t) {
                continue;
            }
            if table_head {
                out.push_str("<thead><tr>");
                for c in cells(t) {
                    let _ = write!(out, "<th>{}</th>", inline(c));
                }
                out.push_str("</tr></thead><tbody>\n");
                table_head = false;
            } else {
                out.push_str("<tr>");
                for c in cells(t) {
                    if numeric(c) {
                        let _ = write!(out, "<td class=\"num\">{}</td>", inline(c));
                    } else {
                        let _ = write!(out, "<td>{}</td>", inline(c));
                    }
                }
                out.push_str("</tr>\n");
            }
        } else {
            if block == Block::Paragraph {
                out.push('\n');
            } else {
                close(&mut block, &mut out);
                out.push_str("<p>");
                block = Block::Paragraph;
            }
            out.push_str(&inline(t.trim()));
        }
    }
    if block == Block::Table && table_head {
        // A table with a header line only: its <tbody> was never opened.
        out.push_str("<tbody>");
    }
    close(&mut block, &mut out);
    (out, toc)
}

const SVG_TAGS: &[&str] = &[
    "svg", "g", "rect", "circle", "ellipse", "line", "polyline", "polygon", "path", "text",
    "tspan", "title", "desc",
];

const SVG_ATTRIBUTES: &[&str] = &[
    "width",
    "height",
    "viewBox",
    "xmlns",
    "version",
    "x",
    "y",
    "x1",
    "y1",
    "x2",
    "y2",
    "cx",
    "cy",
    "r",
    "rx",
    "ry",
    "dx",
    "dy",
    "d",
    "points",
    "fill",
    "stroke",
    "stroke-width",
    "stroke-linecap",
    "stroke-linejoin",
    "stroke-dasharray",
    "opacity",
    "fill-opacity",
    "stroke-opacity",
    "font-family",
    "font-size",
    "font-weight",
    "font-style",
    "text-anchor",
    "dominant-baseline",
    "transform",
];

/// Whether `svg` is plain drawing markup safe to inline in the page: one `<svg>` element
/// (an XML declaration before it is allowed) of drawing elements and presentation attributes
/// only, so no script, event handler, link, style or external reference can come in with a
/// file someone put into `plots/`.
fn svg_is_plain(svg: &str) -> bool {
    let mut s = svg.trim();
    if let Some(rest) = s.strip_prefix("<?xml") {
        match rest.find("?>") {
            Some(end) => s = rest[end + 2..].trim_start(),
            None => return false,
        }
    }
    if !s.starts_with("<svg") || !s.ends_with("</svg>") {
        return false;
    }
    let mut depth = 0usize;
    let mut rest = s;
    while let Some(open) = rest.find('<') {
        let Some(close) = rest[open..].find('>') else {
            return false;
        };
        let tag = &rest[open + 1..open + close];
        rest = &rest[open + close + 1..];
        if let Some(name) = tag.strip_prefix('/') {
            if !SVG_TAGS.contains(&name.trim()) || depth == 0 {
                return false;
            }
            depth -= 1;
            if depth == 0 && !rest.trim().is_empty() {
                return false;
            }
            continue;
        }
        let (body, self_closing) = match tag.strip_suffix('/') {
            Some(b) => (b, true),
            None => (tag, false),
        };
        let name_end = body
            .find(|c: char| c.is_ascii_whitespace())
            .unwrap_or(body.len());
        if !SVG_TAGS.contains(&&body[..name_end]) || !attributes_are_plain(&body[name_end..]) {
            return false;
        }
        if !self_closing {
            depth += 1;
        }
    }
    depth == 0
}

/// Whether an attribute list holds only `name="value"` pairs of [`SVG_ATTRIBUTES`] with
/// values free of `url(` and `javascript:`.
fn attributes_are_plain(mut s: &str) -> bool {
    loop {
        s = s.trim_start();
        if s.is_empty() {
            return true;
        }
        let Some(eq) = s.find('=') else {
            return false;
        };
        let name = s[..eq].trim();
        if !SVG_ATTRIBUTES.contains(&name) {
            return false;
        }
        let v = s[eq + 1..].trim_start();
        let Some(quote) = v.chars().next().filter(|&c| c == '"' || c == '\'') else {
            return false;
        };
        let Some(end) = v[1..].find(quote) else {
            return false;
        };
        let value = v[1..1 + end].to_ascii_lowercase();
        if value.contains("url(") || value.contains("javascript:") {
            return false;
        }
        s = &v[end + 2..];
    }
}

/// Plots in `dir/plots/`: `(file name, inline SVG or None)`, ordered time-vs-error,
/// step histograms, memory, threads, then others, each by name. A file that cannot be read,
/// is too large or is not plain SVG (see [`svg_is_plain`]) gets `None` and is shown as an
/// `<img>` instead (which cannot run scripts).
fn plots(dir: &Path) -> Vec<(String, Option<String>)> {
    let Ok(entries) = std::fs::read_dir(dir.join("plots")) else {
        return Vec::new();
    };
    let mut names: Vec<String> = entries
        .filter_map(|e| e.ok())
        .filter(|e| e.file_type().is_ok_and(|t| t.is_file()))
        .filter_map(|e| e.file_name().to_str().map(str::to_string))
        .filter(|n| n.ends_with(".svg") && !n.starts_with('.'))
        .collect();
    let rank = |n: &str| {
        ["time_vs_error", "steps_histogram", "memory_vs", "mrays_vs"]
            .iter()
            .position(|p| n.starts_with(p))
            .unwrap_or(4)
    };
    names.sort_by(|a, b| rank(a).cmp(&rank(b)).then(a.cmp(b)));
    names
        .into_iter()
        .map(|n| {
            let svg = marchmesh_safeio::read_capped(&dir.join("plots").join(&n), PLOT_CAP_BYTES)
                .ok()
                .and_then(|b| String::from_utf8(b).ok())
                .filter(|s| svg_is_plain(s))
                .map(|s| {
                    let s = s.trim();
                    match s.find("<svg") {
                        Some(i) => s[i..].to_string(),
                        None => s.to_string(),
                    }
                });
            (n, svg)
        })
        .collect()
}

/// One configuration in the viewer: image paths relative to the run folder (URL-encoded),
/// `None` where the file is not there.
#[derive(Serialize)]
struct ViewerEntry {
    id: String,
    group: String,
    scene: String,
    label: String,
    width: u32,
    height: u32,
    reference: Option<String>,
    render: Option<String>,
    diff: Option<String>,
}

fn viewer_entries(res: &Results, dir: &Path) -> Vec<ViewerEntry> {
    let existing = |rel: String| dir.join(&rel).is_file().then(|| url_path(&rel));
    let mut order: Vec<(&str, &str)> = Vec::new();
    for r in &res.rows {
        if !order.contains(&(r.group.as_str(), r.scene.as_str())) {
            order.push((r.group.as_str(), r.scene.as_str()));
        }
    }
    let mut out = Vec::new();
    for (g, sc) in order {
        for r in res.rows.iter().filter(|r| r.group == g && r.scene == sc) {
            out.push(ViewerEntry {
                id: r.config_id.clone(),
                group: r.group.clone(),
                scene: r.scene.clone(),
                label: entry_label(r),
                width: r.width,
                height: r.height,
                reference: existing(format!(
                    "images/{}_{}x{}_reference.png",
                    slug(&r.scene),
                    r.width,
                    r.height
                )),
                render: existing(format!("images/{}.png", slug(&r.config_id))),
                diff: existing(format!("images/{}.diff.png", slug(&r.config_id))),
            });
        }
    }
    out
}

fn entry_label(r: &Row) -> String {
    let psnr = r
        .psnr_db
        .map_or_else(|| "no PSNR".to_string(), |p| format!("{p:.1} dB"));
    format!(
        "{}:{} {}x{} t{} ({:.2} ms, {psnr})",
        r.backend, r.quality, r.width, r.height, r.threads, r.render_ms_median
    )
}

/// JSON for a `<script type="application/json">` block: `<`, `>` and `&` as `\u` escapes
/// so no text in it can close the element.
fn script_json(v: &impl Serialize) -> String {
    serde_json::to_string(v)
        .unwrap_or_else(|_| "[]".into())
        .replace('<', "\\u003c")
        .replace('>', "\\u003e")
        .replace('&', "\\u0026")
}

const STYLE: &str = r#"
:root { --fg: #1d1f23; --muted: #5b616b; --line: #d8dbe0; --head: #f2f4f7; --accent: #2463c4; }
* { box-sizing: border-box; }
body { margin: 0; font: 14px/1.45 system-ui, -apple-system, "Segoe UI", Roboto, "Helvetica Neue", Arial, sans-serif; color: var(--fg); background: #fff; }
header, main { max-width: 1500px; margin: 0 auto; padding: 0 20px; }
header { padding-top: 12px; border-bottom: 1px solid var(--line); }
nav ul { list-style: none; padding: 0; margin: 6px 0 12px; display: flex; flex-wrap: wrap; gap: 4px 14px; }
nav a, a { color: var(--accent); text-decoration: none; }
nav a:hover, a:hover { text-decoration: underline; }
h1 { font-size: 22px; margin: 8px 0; }
h2 { font-size: 18px; margin: 28px 0 8px; padding-top: 8px; border-top: 1px solid var(--line); }
h3 { font-size: 15px; margin: 18px 0 6px; }
code { font: 12.5px/1.3 ui-monospace, SFMono-Regular, Menlo, Consolas, monospace; background: #f3f4f6; padding: 1px 4px; border-radius: 3px; }
.table-wrap { overflow-x: auto; margin: 8px 0 12px; border: 1px solid var(--line); border-radius: 4px; }
table { border-collapse: collapse; font-size: 12.5px; white-space: nowrap; }
th, td { padding: 3px 8px; border-bottom: 1px solid var(--line); text-align: left; }
th { background: var(--head); position: sticky; top: 0; font-weight: 600; white-space: normal; min-width: 5em; vertical-align: bottom; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
tbody tr:hover { background: #f7f9fc; }
.plots { display: flex; flex-wrap: wrap; gap: 16px; }
figure { margin: 0; border: 1px solid var(--line); border-radius: 4px; padding: 6px; max-width: 100%; }
figure svg, figure img { display: block; max-width: 100%; height: auto; }
figcaption { color: var(--muted); font-size: 12px; }
.viewer .controls { display: flex; flex-wrap: wrap; align-items: center; gap: 6px 10px; margin: 8px 0; }
.viewer select { max-width: 100%; font: inherit; padding: 2px; }
.viewer button { font: inherit; padding: 3px 10px; border: 1px solid var(--line); border-radius: 4px; background: #fff; cursor: pointer; }
.viewer button[aria-pressed="true"] { background: var(--accent); border-color: var(--accent); color: #fff; }
.viewer button:disabled { opacity: 0.4; cursor: default; }
.viewer .group { display: inline-flex; gap: 3px; align-items: center; }
#zoom-label { min-width: 3em; text-align: center; font-variant-numeric: tabular-nums; }
.stage { overflow: auto; max-height: 78vh; border: 1px solid var(--line); background: #808080 repeating-conic-gradient(#777 0 25%, #8a8a8a 0 50%) 0 0 / 16px 16px; }
.stage img { display: block; image-rendering: pixelated; image-rendering: crisp-edges; }
.stage img[hidden] { display: none; }
.status, .hint, .pixel { color: var(--muted); font-size: 12.5px; margin: 4px 0; }
.status.warn { color: #a33; }
.legend { display: inline-flex; align-items: center; gap: 6px; font-size: 12px; color: var(--muted); }
.ramp { display: inline-block; width: 120px; height: 10px; border: 1px solid var(--line); background: linear-gradient(to right, #0d0840, #265999, #26a673, #f2e626); }
.swatch { display: inline-block; width: 10px; height: 10px; border: 1px solid var(--line); }
footer { max-width: 1500px; margin: 24px auto; padding: 8px 20px; color: var(--muted); font-size: 12px; border-top: 1px solid var(--line); }
"#;

/// Records script errors on `<html data-errors>` (tests read it from the dumped DOM).
const ERROR_HOOK: &str = r#"
(function () {
  var root = document.documentElement;
  function note(msg) {
    root.setAttribute("data-errors", (root.getAttribute("data-errors") || "") + msg + "\n");
  }
  window.onerror = function (msg, src, line, col) { note(msg + " at " + line + ":" + col); };
  window.addEventListener("unhandledrejection", function (e) { note("unhandled rejection: " + e.reason); });
})();
"#;

const VIEWER_JS: &str = r#"
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
  var state = { i: 0, kind: "render", zoom: 1 };

  function parseHash() {
    var h = (location.hash || "").replace(/^#/, "");
    h.split("&").forEach(function (part) {
      var eq = part.indexOf("=");
      if (eq < 0) return;
      var key = part.slice(0, eq), value;
      try { value = decodeURIComponent(part.slice(eq + 1)); } catch (e) { return; }
      if (key === "flip" || key === "view") {
        if (value === "difference") value = "diff";
        if (KINDS.indexOf(value) >= 0) state.kind = value;
      } else if (key === "config") {
        for (var j = 0; j < data.length; j++) {
          if (data[j].id === value) { state.i = j; return; }
        }
        var n = parseInt(value, 10);
        if (String(n) === value && n >= 0 && n < data.length) state.i = n;
      } else if (key === "zoom") {
        var z = parseInt(value, 10);
        if (ZOOMS.indexOf(z) >= 0) state.zoom = z;
      }
    });
  }

  function writeHash() {
    var h = "#flip=" + state.kind + "&zoom=" + state.zoom + "&config=" + encodeURIComponent(data[state.i].id);
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

  parseHash();
  if (!data[state.i][state.kind]) {
    root.setAttribute("data-missing", state.kind);
  }
  KINDS.forEach(function (k) {
    kindButtons[k].addEventListener("click", function () { flip(k); });
  });
  sel.addEventListener("change", function () { select(parseInt(sel.value, 10)); });
  document.getElementById("zoom-in").addEventListener("click", function () { step(1); });
  document.getElementById("zoom-out").addEventListener("click", function () { step(-1); });
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
      default: handled = false;
    }
    if (handled) ev.preventDefault();
  });
  show();
  root.setAttribute("data-ready", "1");
})();
"#;

/// The `report.html` of the run in `dir` (the run folder): summary tables, the plots of
/// `dir/plots/` inlined, and the image viewer over the files present in `dir/images/`.
/// All text from the results is escaped; images are referenced by relative path.
pub fn report_html(res: &Results, dir: &Path) -> String {
    let (summary, toc) = markdown_to_html(&summary_markdown(res));
    let plots = plots(dir);
    let entries = viewer_entries(res, dir);
    let any_image = entries
        .iter()
        .any(|e| e.reference.is_some() || e.render.is_some() || e.diff.is_some());

    let mut h = String::new();
    let _ = write!(
        h,
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n\
         <meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n\
         <meta http-equiv=\"Content-Security-Policy\" content=\"default-src 'none'; img-src 'self' data:; style-src 'unsafe-inline'; script-src 'unsafe-inline'\">\n\
         <title>marchmesh {} run {}</title>\n<style>{STYLE}</style>\n<script>{ERROR_HOOK}</script>\n</head>\n<body>\n",
        escape(&res.suite),
        escape(&res.run_id)
    );
    h.push_str("<header>\n<nav><ul>\n");
    for (id, text) in &toc {
        let _ = writeln!(h, "<li><a href=\"#{id}\">{}</a></li>", escape(text));
    }
    if !plots.is_empty() {
        h.push_str("<li><a href=\"#plots\">Plots</a></li>\n");
    }
    h.push_str("<li><a href=\"#images\">Images</a></li>\n</ul></nav>\n</header>\n<main>\n");
    h.push_str(&summary);

    if !plots.is_empty() {
        h.push_str("<h2 id=\"plots\">Plots</h2>\n<div class=\"plots\">\n");
        for (name, svg) in &plots {
            h.push_str("<figure>");
            match svg {
                Some(svg) => h.push_str(svg),
                None => {
                    let _ = write!(
                        h,
                        "<img src=\"{}\" alt=\"{}\">",
                        escape(&url_path(&format!("plots/{name}"))),
                        escape(name)
                    );
                }
            }
            let _ = writeln!(
                h,
                "<figcaption>plots/{}</figcaption></figure>",
                escape(name)
            );
        }
        h.push_str("</div>\n");
    }

    h.push_str("<h2 id=\"images\">Images</h2>\n");
    if !any_image {
        h.push_str(
            "<p class=\"status\" id=\"no-images\">No images in this run: the suite turned them off \
             (<code>images: false</code>) or none were written, so there is nothing to view.</p>\n",
        );
    } else {
        write_viewer(&mut h, &entries);
    }
    let _ = write!(
        h,
        "</main>\n<footer>Generated by marchmesh {} from <code>results.json</code> of run {}; \
         <code>marchmesh report DIR</code> regenerates it. Images are read from <code>images/</code> \
         beside this file.</footer>\n</body>\n</html>\n",
        escape(&res.provenance.version),
        escape(&res.run_id)
    );
    h
}

fn write_viewer(h: &mut String, entries: &[ViewerEntry]) {
    h.push_str(
        "<div class=\"viewer\" id=\"viewer\">\n<div class=\"controls\">\n\
         <label>Configuration <select id=\"cfg\">\n",
    );
    let mut open: Option<(&str, &str)> = None;
    for (i, e) in entries.iter().enumerate() {
        if open != Some((e.group.as_str(), e.scene.as_str())) {
            if open.is_some() {
                h.push_str("</optgroup>\n");
            }
            let _ = writeln!(
                h,
                "<optgroup label=\"{} / {}\">",
                escape(&e.group),
                escape(&e.scene)
            );
            open = Some((e.group.as_str(), e.scene.as_str()));
        }
        let _ = writeln!(
            h,
            "<option value=\"{i}\" title=\"{}\"{}>{}</option>",
            escape(&e.id),
            if i == 0 { " selected" } else { "" },
            escape(&e.label)
        );
    }
    if open.is_some() {
        h.push_str("</optgroup>\n");
    }
    h.push_str(
        "</select></label>\n<span class=\"group\" role=\"group\" aria-label=\"image\">\
         <button type=\"button\" id=\"show-reference\" aria-pressed=\"false\">1 reference</button>\
         <button type=\"button\" id=\"show-render\" aria-pressed=\"true\">2 render</button>\
         <button type=\"button\" id=\"show-diff\" aria-pressed=\"false\">3 difference</button></span>\n\
         <span class=\"group\" role=\"group\" aria-label=\"zoom\">\
         <button type=\"button\" id=\"zoom-out\" title=\"zoom out (-)\">&minus;</button>\
         <span id=\"zoom-label\">1x</span>\
         <button type=\"button\" id=\"zoom-in\" title=\"zoom in (+)\">+</button></span>\n\
         <span class=\"legend\" title=\"difference heatmap colours\">difference: \
         <span class=\"ramp\"></span> 0 to 64+ levels; <span class=\"swatch\" style=\"background:#f0f\"></span> \
         silhouette; <span class=\"swatch\" style=\"background:#000\"></span> both miss</span>\n</div>\n",
    );
    let first = &entries[0];
    let (src, kind) = match (&first.render, &first.reference) {
        (Some(p), _) => (Some(p), "render"),
        (None, Some(p)) => (Some(p), "reference"),
        _ => (None, "none"),
    };
    let _ = writeln!(
        h,
        "<p class=\"status\" id=\"status\"></p>\n<div class=\"stage\" id=\"stage\">\
         <img id=\"view\" data-kind=\"{kind}\"{} alt=\"\" width=\"{}\" height=\"{}\"></div>\n\
         <p class=\"pixel\" id=\"pixel\"></p>\n\
         <p class=\"hint\">Keys: <code>1</code> reference, <code>2</code> render, <code>3</code> \
         difference, <code>+</code>/<code>-</code> zoom (1x to 16x, pixels stay sharp; the mouse \
         wheel over the image zooms around the pointer), <code>[</code>/<code>]</code> previous / \
         next configuration. The zoom and scroll position stay when flipping, so the same pixels \
         are compared. The address keeps the view (<code>#flip=diff&amp;zoom=4&amp;config=ID</code>).</p>\n\
         <noscript><p class=\"status warn\">The viewer needs JavaScript; the images are in \
         <code>images/</code>.</p></noscript>\n</div>",
        src.map_or(String::new(), |p| format!(" src=\"{}\"", escape(p))),
        first.width,
        first.height
    );
    let _ = writeln!(
        h,
        "<script type=\"application/json\" id=\"viewer-data\">{}</script>\n<script>{VIEWER_JS}</script>",
        script_json(&entries)
    );
}
