//! `report.html`: one self-contained page per run folder (inline CSS and JavaScript, no
//! network) with the summary tables of [`summary_markdown`], the SVG plots of `plots/`
//! inlined, and an image viewer that flips between the reference, a configuration's render
//! and its difference heatmap at a shared pixel zoom. Images stay files in `images/` and are
//! referenced by relative path, so the page works wherever the run folder is copied.
//!
//! The viewer honours a URL fragment at load: `#flip=reference|render|diff`, `config=ID` (a
//! configuration id or its index), `zoom=1..16` and `solo=1` (only the viewer, full window),
//! e.g. `report.html#flip=diff&zoom=4`.

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

/// A relative file path as a URL path: bytes outside `A-Za-z0-9-._~/=,` percent-encoded.
fn url_path(p: &str) -> String {
    let mut out = String::with_capacity(p.len());
    for b in p.bytes() {
        if b.is_ascii_alphanumeric() || b"-._~/=,".contains(&b) {
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
pub(crate) fn svg_is_plain(svg: &str) -> bool {
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
    #[serde(skip)]
    label: String,
    width: u32,
    height: u32,
    reference: Option<String>,
    render: Option<String>,
    diff: Option<String>,
}

fn viewer_entries(res: &Results, dir: &Path) -> Vec<ViewerEntry> {
    let existing = |rel: String| dir.join(&rel).is_file().then(|| url_path(&rel));
    let mut out = Vec::new();
    for (_, rows) in crate::report::group_scenes(res) {
        for r in rows {
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

/// The page's style sheet (inlined).
const STYLE: &str = include_str!("html/style.css");

/// Records script errors on `<html data-errors>` (tests read it from the dumped DOM).
const ERROR_HOOK: &str = include_str!("html/error_hook.js");

/// The image viewer (inlined after its JSON data block).
const VIEWER_JS: &str = include_str!("html/viewer.js");

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
         <meta http-equiv=\"Content-Security-Policy\" content=\"default-src 'none'; img-src 'self' file: data:; style-src 'unsafe-inline'; script-src 'unsafe-inline'\">\n\
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
    // The decision chart opens the page, under the summary's first section heading (the
    // answer), before its table.
    let chart = crate::decision::DecisionChart::of_run(res);
    if chart.is_empty() {
        h.push_str(&summary);
    } else {
        let figure = format!(
            "</h2>\n<figure class=\"decision\" id=\"decision-chart\">{}<figcaption>Decision chart: per scene and accuracy target, the fastest backend among the configurations reaching the target, and by how much.</figcaption></figure>\n",
            chart.svg().trim_end()
        );
        h.push_str(&summary.replacen("</h2>\n", &figure, 1));
    }

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
             (<code>images: false</code>), none were written, or this is a merged run whose images \
             stay in its shards' folders.</p>\n",
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

/// Appends the image viewer over `entries` (nothing when there are none).
fn write_viewer(h: &mut String, entries: &[ViewerEntry]) {
    let Some(first) = entries.first() else {
        return;
    };
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
         <button type=\"button\" id=\"solo\" aria-pressed=\"false\" title=\"show only the viewer (f)\">full window</button>\n\
         <span class=\"legend\" title=\"difference heatmap colours\">difference: \
         <span class=\"ramp\"></span> 0 to 64+ levels; <span class=\"swatch\" style=\"background:#f0f\"></span> \
         silhouette; <span class=\"swatch\" style=\"background:#000\"></span> both miss</span>\n</div>\n",
    );
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
         next configuration, <code>f</code> full window. The zoom and scroll position stay when flipping, so the same pixels \
         are compared. The address keeps the view (<code>#flip=diff&amp;zoom=4&amp;config=ID&amp;solo=1</code>).</p>\n\
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::results::tests_support::{results, row};

    fn tmp(name: &str) -> std::path::PathBuf {
        let d = std::env::temp_dir().join(format!("marchmesh-html-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(d.join("images")).unwrap();
        d
    }

    /// `html` with the contents of `<script>` elements and inlined `<svg>` removed, so the
    /// rest can be checked for markup that user text must not produce.
    fn outside_scripts(html: &str) -> String {
        let mut out = String::new();
        let mut rest = html;
        while let Some(i) = rest.find("<script") {
            out.push_str(&rest[..i]);
            let end = rest[i..].find("</script>").unwrap();
            rest = &rest[i + end + "</script>".len()..];
        }
        out.push_str(rest);
        out
    }

    #[test]
    fn escaping_covers_markup_and_quotes() {
        assert_eq!(
            escape(r#"<a href="x" title='y'>&</a>"#),
            "&lt;a href=&quot;x&quot; title=&#39;y&#39;&gt;&amp;&lt;/a&gt;"
        );
        assert_eq!(url_path("images/a b#?.png"), "images/a%20b%23%3F.png");
    }

    #[test]
    fn markdown_subset_converts() {
        let (h, toc) = markdown_to_html(
            "# Title `x<y>`\n\nOne **bold** line\nand `a*b`.\n\n- item `<i>`\n- two\n\n## A / B\n\n| h1 | h2 |\n|---|---|\n| 1.5 | <b> |\n\nLone ** star and ` tick.\n",
        );
        assert!(h.contains("<h1>Title <code>x&lt;y&gt;</code></h1>"), "{h}");
        assert!(
            h.contains("<p>One <strong>bold</strong> line\nand <code>a*b</code>.</p>"),
            "{h}"
        );
        assert!(
            h.contains("<ul>\n<li>item <code>&lt;i&gt;</code></li>\n<li>two</li>\n</ul>"),
            "{h}"
        );
        assert!(h.contains("<h2 id=\"section-1\">A / B</h2>"), "{h}");
        assert_eq!(toc, [("section-1".to_string(), "A / B".to_string())]);
        assert!(
            h.contains("<thead><tr><th>h1</th><th>h2</th></tr></thead><tbody>\n<tr><td class=\"num\">1.5</td><td>&lt;b&gt;</td></tr>\n</tbody></table></div>"),
            "{h}"
        );
        assert!(h.contains("<p>Lone ** star and ` tick.</p>"), "{h}");
        assert!(!h.contains("<b>"), "{h}");
    }

    #[test]
    fn hostile_config_ids_and_notes_are_escaped() {
        let mut r = row("sdf", "<script>alert(1)</script>", 1.0, Some(40.0), 10);
        r.config_id = "g/s/sdf:<script>alert(1)</script>/x1/t1".into();
        r.scene = "s\"><img src=x onerror=alert(2)>".into();
        r.notes = "</script><script>alert(3)</script>".into();
        let mut res = results(vec![r.clone()]);
        res.description = "<iframe src=//evil>".into();
        res.failures.push(crate::results::Failure {
            config_id: "</script>&'\"".into(),
            error: "<b>boom</b> `</code><script>`".into(),
        });
        let dir = tmp("hostile");
        std::fs::write(
            dir.join("images")
                .join(format!("{}.png", slug(&r.config_id))),
            b"png",
        )
        .unwrap();
        let html = report_html(&res, &dir);
        let outside = outside_scripts(&html);
        for bad in [
            "<script>alert",
            "<img src=x",
            "<iframe",
            "<b>boom",
            "onerror=alert(2)>",
        ] {
            assert!(!outside.contains(bad), "{bad} unescaped in\n{outside}");
        }
        assert!(outside.contains("&lt;script&gt;alert(1)&lt;/script&gt;"));
        // Inside the JSON data block nothing can close the element.
        let data_start = html.find("id=\"viewer-data\">").unwrap();
        let data = &html[data_start..];
        let data = &data[..data.find("</script>").unwrap()];
        assert!(!data[1..].contains('<'), "{data}");
        assert!(data.contains("\\u003cscript\\u003e"), "{data}");
        // Exactly the page's own two scripts plus the JSON block.
        assert_eq!(html.matches("<script").count(), 3, "{html}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn every_row_is_in_the_tables_and_the_viewer() {
        let mut rows = vec![
            row("sdf", "coarse", 2.0, Some(30.0), 10),
            row("sdf", "fine", 4.0, Some(45.0), 10),
            row("mesh", "default", 3.0, Some(50.0), 100),
        ];
        let mut other = row("mesh", "default", 5.0, None, 100);
        other.scene = "t".into();
        other.config_id = "g/t/mesh:default/x1/t1".into();
        rows.push(other);
        for r in &mut rows {
            r.width = 8;
            r.height = 4;
        }
        let res = results(rows.clone());
        let dir = tmp("rows");
        for r in &rows {
            let png = dir.join(format!("images/{}.png", slug(&r.config_id)));
            std::fs::write(png, b"png").unwrap();
        }
        let html = report_html(&res, &dir);
        for r in &rows {
            assert!(
                html.contains(&format!("title=\"{}\"", escape(&r.config_id))),
                "{}",
                r.config_id
            );
            assert!(
                html.contains(&format!("<td>{}</td><td>{}</td>", r.backend, r.quality)),
                "{}",
                r.config_id
            );
        }
        assert_eq!(html.matches("<option ").count(), rows.len());
        assert!(html.contains("<optgroup label=\"g / s\">"));
        assert!(html.contains("<optgroup label=\"g / t\">"));
        assert!(
            html.contains("<a href=\"#section-") && html.contains("\">g / s</a>"),
            "{html}"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn plots_are_inlined_and_unsafe_svg_is_only_linked() {
        let res = results(vec![
            row("sdf", "a", 2.0, Some(30.0), 10),
            row("mesh", "b", 3.0, Some(50.0), 100),
        ]);
        let dir = tmp("plots");
        let names = crate::report::write_plots(&res, &dir.join("plots")).unwrap();
        assert!(!names.is_empty());
        std::fs::write(
            dir.join("plots").join("zz evil.svg"),
            "<svg xmlns=\"http://www.w3.org/2000/svg\"><script>alert(1)</script></svg>",
        )
        .unwrap();
        std::fs::write(
            dir.join("plots").join("zz handler.svg"),
            "<svg onload=\"alert(1)\"></svg>",
        )
        .unwrap();
        let html = report_html(&res, &dir);
        for n in &names {
            assert!(
                html.contains(&format!("<figcaption>plots/{n}</figcaption>")),
                "{n}"
            );
            let svg = std::fs::read_to_string(dir.join("plots").join(n)).unwrap();
            assert!(svg_is_plain(&svg), "{n} is not recognised as plain SVG");
            assert!(html.contains(svg.trim()), "{n} not inlined");
        }
        assert!(html.contains("<img src=\"plots/zz%20evil.svg\" alt=\"zz evil.svg\">"));
        assert!(html.contains("<img src=\"plots/zz%20handler.svg\""));
        assert!(!html.contains("alert(1)"));
        // The plots, and the decision chart at the top.
        assert_eq!(html.matches("<svg").count(), names.len() + 1);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn inlined_assets_cannot_close_their_elements() {
        for asset in [STYLE, ERROR_HOOK, VIEWER_JS] {
            let lower = asset.to_ascii_lowercase();
            assert!(!lower.contains("</script") && !lower.contains("</style"));
        }
    }

    #[test]
    fn svg_check_rejects_active_content() {
        assert!(svg_is_plain(
            "<?xml version=\"1.0\"?>\n<svg width=\"2\" height=\"2\" xmlns=\"http://www.w3.org/2000/svg\">\n<rect x=\"0\" y=\"0\" fill=\"#FFF\"/>\n<text x=\"1\">a &lt; b</text>\n</svg>\n"
        ));
        for bad in [
            "<svg><foreignObject></foreignObject></svg>",
            "<svg><a href=\"javascript:x\"></a></svg>",
            "<svg><rect style=\"fill:url(http://x)\"/></svg>",
            "<svg><rect fill=\"url(#x)\"/></svg>",
            "<svg><rect/></svg><script>x</script>",
            "<svg><rect ONLOAD=\"x\"/></svg>",
            "<svg><rect x=1/></svg>",
            "<svg><!-- x --></svg>",
            "<svg>",
            "text",
        ] {
            assert!(!svg_is_plain(bad), "{bad}");
        }
    }

    #[test]
    fn images_present_are_referenced_and_missing_ones_are_not() {
        let mut a = row("sdf", "a", 2.0, Some(30.0), 10);
        let mut b = row("mesh", "b", 3.0, Some(50.0), 100);
        for r in [&mut a, &mut b] {
            r.width = 8;
            r.height = 4;
        }
        let res = results(vec![a.clone(), b.clone()]);
        let dir = tmp("images");
        let img = dir.join("images");
        std::fs::write(img.join("s_8x4_reference.png"), b"png").unwrap();
        std::fs::write(img.join(format!("{}.png", slug(&a.config_id))), b"png").unwrap();
        std::fs::write(img.join(format!("{}.diff.png", slug(&a.config_id))), b"png").unwrap();
        std::fs::write(img.join(format!("{}.png", slug(&b.config_id))), b"png").unwrap();
        let entries = viewer_entries(&res, &dir);
        assert_eq!(
            entries[0].reference.as_deref(),
            Some("images/s_8x4_reference.png")
        );
        assert_eq!(
            entries[0].diff.as_deref(),
            Some(format!("images/{}.diff.png", slug(&a.config_id)).as_str())
        );
        assert!(entries[1].render.is_some());
        assert!(entries[1].diff.is_none(), "b has no difference image");
        let html = report_html(&res, &dir);
        assert!(html.contains(&format!(
            "<img id=\"view\" data-kind=\"render\" src=\"images/{}.png\"",
            slug(&a.config_id)
        )));
        assert!(!html.contains(&format!("{}.diff.png", slug(&b.config_id))));
        assert!(!html.contains("no-images"));

        // A run without images says so instead of showing broken images.
        for f in std::fs::read_dir(&img).unwrap() {
            std::fs::remove_file(f.unwrap().path()).unwrap();
        }
        let html = report_html(&res, &dir);
        assert!(html.contains("No images in this run"), "{html}");
        assert!(!html.contains("<img id=\"view\""));
        assert!(
            !html.contains("src=\"images/"),
            "no image paths without images"
        );
        // ...and so does a folder without images/ at all.
        std::fs::remove_dir(&img).unwrap();
        assert!(report_html(&res, &dir).contains("No images in this run"));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
