//! `report.html` of a `bench --suite smoke` run: self-contained (no address outside the run
//! folder, every referenced image present), and, when Chromium is installed, loaded headless:
//! no JavaScript errors, the URL fragment `#flip=diff` flips the viewer to the difference
//! heatmap, and a screenshot is written. Without Chromium the browser part is skipped
//! (`scripts/install_chromium.sh` installs it).

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn marchmesh(args: &[&str], cwd: &Path) -> (bool, String, String) {
    marchmesh_testkit::run_program(env!("CARGO_BIN_EXE_marchmesh"), args, cwd)
}

fn repo() -> PathBuf {
    marchmesh_testkit::repo_root()
}

fn tmp(name: &str) -> PathBuf {
    marchmesh_testkit::temp_dir(&format!("cli-{name}"))
}

/// Drives `report.html` in a frame (same folder; needs `--allow-file-access-from-files`):
/// keys and a button, then writes each step's view, zoom, image and width into `<pre>`.
const DRIVER: &str = r##"<!DOCTYPE html><html><body>
<iframe id="f" src="report.html" width="1000" height="700"></iframe><pre id="out"></pre>
<script>
document.getElementById("f").onload = function () {
  var log = [];
  try {
    var w = this.contentWindow, d = w.document, root = d.documentElement;
    var state = function (name) {
      var img = d.getElementById("view");
      log.push([name, root.getAttribute("data-view"), root.getAttribute("data-zoom"),
        img.getAttribute("src"), img.style.width].join(" "));
    };
    var key = function (k) { d.dispatchEvent(new w.KeyboardEvent("keydown", { key: k, bubbles: true })); };
    state("start");
    key("3"); state("3");
    key("+"); key("+"); state("++");
    key("1"); state("1");
    key("2"); state("2");
    d.getElementById("zoom-out").click(); state("zoom-out");
    log.push("errors " + root.getAttribute("data-errors"));
  } catch (e) {
    log.push("exception " + e);
  }
  document.getElementById("out").textContent = log.join("\n");
};
</script></body></html>"##;

/// Runs headless Chromium on `url` with `extra` flags (its own profile in `profile`), killing
/// it after two minutes. Returns stdout and stderr.
fn headless(browser: &Path, profile: &Path, extra: &[&str], url: &str) -> (String, String) {
    let out_path = profile.with_extension("stdout");
    let err_path = profile.with_extension("stderr");
    let mut child = Command::new(browser)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-dev-shm-usage",
            "--no-first-run",
            "--enable-logging=stderr",
            "--v=0",
        ])
        .arg(format!("--user-data-dir={}", profile.display()))
        .args(extra)
        .arg(url)
        .stdin(Stdio::null())
        .stdout(std::fs::File::create(&out_path).unwrap())
        .stderr(std::fs::File::create(&err_path).unwrap())
        .spawn()
        .expect("start chromium");
    let start = Instant::now();
    loop {
        if child.try_wait().unwrap().is_some() {
            break;
        }
        if start.elapsed() > Duration::from_secs(120) {
            let _ = child.kill();
            let _ = child.wait();
            panic!("chromium did not finish within 120 s on {url}");
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    (
        std::fs::read_to_string(&out_path).unwrap_or_default(),
        std::fs::read_to_string(&err_path).unwrap_or_default(),
    )
}

/// The value of attribute `name` in the first `<tag` element of `dom` whose opening tag
/// contains `marker`.
fn attribute(dom: &str, tag: &str, marker: &str, name: &str) -> Option<String> {
    let mut rest = dom;
    while let Some(i) = rest.find(&format!("<{tag}")) {
        let end = rest[i..].find('>')? + i;
        let open = &rest[i..end];
        rest = &rest[end..];
        if !open.contains(marker) {
            continue;
        }
        let key = format!(" {name}=\"");
        let v = open.find(&key)? + key.len();
        return Some(open[v..v + open[v..].find('"')?].to_string());
    }
    None
}

/// `%XX` escapes of a URL path decoded.
fn percent_decode(s: &str) -> String {
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        let hex = (b[i] == b'%' && i + 2 < b.len())
            .then(|| std::str::from_utf8(&b[i + 1..i + 3]).ok())
            .flatten()
            .and_then(|h| u8::from_str_radix(h, 16).ok());
        match hex {
            Some(h) => {
                out.push(h);
                i += 3;
            }
            None => {
                out.push(b[i]);
                i += 1;
            }
        }
    }
    String::from_utf8(out).unwrap()
}

/// Console errors and blocked loads Chromium logged: uncaught exceptions and refusals
/// (a Content-Security-Policy violation would mean the page tried to reach outside itself).
fn console_errors(stderr: &str) -> Vec<&str> {
    stderr
        .lines()
        .filter(|l| {
            l.contains("CONSOLE")
                && [
                    "Uncaught",
                    "Refused",
                    "Content Security Policy",
                    "Failed to load",
                ]
                .iter()
                .any(|e| l.contains(e))
        })
        .collect()
}

#[test]
fn report_html_is_self_contained_and_its_viewer_flips_images_in_a_browser() {
    let out = tmp("report-html");
    let (ok, stdout, stderr) = marchmesh(
        &[
            "bench",
            "--suite",
            "smoke",
            "--results-dir",
            out.to_str().unwrap(),
        ],
        &repo(),
    );
    assert!(ok, "bench failed:\n{stdout}\n{stderr}");
    let run = std::fs::read_dir(&out)
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path();
    let report = run.join("report.html");
    let html = std::fs::read_to_string(&report).unwrap();

    // Self-contained: every src/href is a fragment or a relative path to a file of the run.
    for attr in ["src=\"", "href=\""] {
        for (i, _) in html.match_indices(attr) {
            let v = &html[i + attr.len()..];
            let v = &v[..v.find('"').unwrap()];
            assert!(!v.contains(':') && !v.starts_with("//"), "{attr}{v}");
            if !v.starts_with('#') {
                let file = run.join(percent_decode(v));
                assert!(file.is_file(), "{v} referenced but not in the run folder");
            }
        }
    }
    for bad in ["<link", "@import", "url(http", "<iframe"] {
        assert!(!html.contains(bad), "{bad}");
    }
    assert!(html.contains("<svg"), "plots are inlined");
    assert!(html.contains("id=\"viewer-data\""), "the viewer is there");
    assert!(
        html.contains(".diff.png"),
        "difference images are in the viewer"
    );

    let Some(browser) = marchmesh_testkit::tools::require(
        marchmesh_testkit::tools::Tool::Chromium,
        "report_html_is_self_contained_and_its_viewer_flips_images_in_a_browser",
    ) else {
        let _ = std::fs::remove_dir_all(&out);
        return;
    };
    let url = |fragment: &str| format!("file://{}{fragment}", report.display());
    let profile = out.join("chromium-profile");
    let res = marchmesh_harness::results::Results::read_json(&run.join("results.json")).unwrap();

    // The fragment flips the viewer to the difference image at load, without script errors.
    let (dom, log) = headless(
        &browser,
        &profile,
        &["--dump-dom"],
        &url("#flip=diff&zoom=4"),
    );
    let root = |name: &str| attribute(&dom, "html", "", name);
    assert_eq!(root("data-errors"), None, "script errors:\n{log}");
    assert_eq!(
        root("data-ready").as_deref(),
        Some("1"),
        "viewer script did not finish:\n{log}"
    );
    assert!(
        console_errors(&log).is_empty(),
        "{:?}",
        console_errors(&log)
    );
    assert_eq!(root("data-view").as_deref(), Some("diff"));
    assert_eq!(root("data-zoom").as_deref(), Some("4"));
    let view = |name: &str| attribute(&dom, "img", "id=\"view\"", name);
    assert_eq!(view("data-kind").as_deref(), Some("diff"), "{dom}");
    let src = view("src").unwrap();
    assert!(src.ends_with(".diff.png"), "{src}");
    let first = &res.rows[0];
    let style = view("style").unwrap_or_default();
    assert!(
        style.contains(&format!("width: {}px", 4 * first.width)),
        "zoom 4x sets the size: {style}"
    );
    assert_eq!(
        view("data-loaded").as_deref(),
        Some(src.as_str()),
        "the difference image did not load"
    );
    assert!(
        attribute(&dom, "button", "id=\"show-diff\"", "aria-pressed").as_deref() == Some("true")
    );

    // The page reads at 1400 pixels without sideways scrolling, the decision chart first.
    let (dom, log) = headless(
        &browser,
        &profile,
        &["--window-size=1400,1000", "--dump-dom"],
        &url(""),
    );
    let width = |name: &str| {
        attribute(&dom, "html", "", name)
            .and_then(|v| v.parse::<u32>().ok())
            .unwrap_or_else(|| panic!("no {name}:\n{log}"))
    };
    assert!(
        width("data-scroll-width") <= width("data-client-width"),
        "the page scrolls sideways at 1400 px: {} > {}",
        width("data-scroll-width"),
        width("data-client-width")
    );
    let chart = dom.find("id=\"decision-chart\"").expect("a decision chart");
    assert!(
        chart < dom.find(">Method</h2>").unwrap_or(usize::MAX),
        "chart before the method"
    );

    // Selecting a configuration and the reference by fragment.
    let last = res.rows.last().unwrap();
    let (dom, log) = headless(
        &browser,
        &profile,
        &["--dump-dom"],
        &url(&format!("#flip=reference&config={}", last.config_id)),
    );
    assert_eq!(attribute(&dom, "html", "", "data-errors"), None, "{log}");
    let src = attribute(&dom, "img", "id=\"view\"", "src").unwrap();
    assert!(
        src.ends_with(&format!(
            "{}_{}x{}_reference.png",
            marchmesh_harness::bench::slug(&last.scene),
            last.width,
            last.height
        )),
        "{src}"
    );

    // Keys flip the image and keep the zoom: a page beside the report drives it in a frame.
    std::fs::write(run.join("drive.html"), DRIVER).unwrap();
    let (dom, log) = headless(
        &browser,
        &profile,
        &["--allow-file-access-from-files", "--dump-dom"],
        &format!("file://{}", run.join("drive.html").display()),
    );
    let steps: Vec<&str> = dom
        .split("<pre id=\"out\">")
        .nth(1)
        .and_then(|s| s.split("</pre>").next())
        .unwrap_or_else(|| panic!("driver did not run:\n{dom}\n{log}"))
        .lines()
        .collect();
    let slug = marchmesh_harness::bench::slug(&first.config_id);
    let reference = format!(
        "images/{}_{}x{}_reference.png",
        marchmesh_harness::bench::slug(&first.scene),
        first.width,
        first.height
    );
    let w = |z: u32| format!("{}px", z * first.width);
    let expected = [
        format!("start render 1 images/{slug}.png {}", w(1)),
        format!("3 diff 1 images/{slug}.diff.png {}", w(1)),
        format!("++ diff 4 images/{slug}.diff.png {}", w(4)),
        format!("1 reference 4 {reference} {}", w(4)),
        format!("2 render 4 images/{slug}.png {}", w(4)),
        format!("zoom-out render 2 images/{slug}.png {}", w(2)),
        "errors null".to_string(),
    ];
    assert_eq!(steps, expected, "{log}");

    // A screenshot of the viewer alone.
    let shot = out.join("viewer.png");
    headless(
        &browser,
        &profile,
        &[
            "--hide-scrollbars",
            "--window-size=1280,900",
            &format!("--screenshot={}", shot.display()),
        ],
        &url("#flip=diff&zoom=4&solo=1"),
    );
    let png = std::fs::read(&shot).expect("screenshot written");
    assert!(
        png.len() > 1000 && png.starts_with(b"\x89PNG"),
        "{} bytes",
        png.len()
    );

    // Without images the page says so, and still loads without errors.
    std::fs::remove_dir_all(run.join("images")).unwrap();
    std::fs::remove_file(&report).unwrap();
    let (ok, stdout, stderr) = marchmesh(&["report", run.to_str().unwrap()], &repo());
    assert!(ok, "report failed:\n{stdout}\n{stderr}");
    let (dom, log) = headless(&browser, &profile, &["--dump-dom"], &url(""));
    assert!(dom.contains("No images in this run"), "{dom}");
    assert_eq!(attribute(&dom, "html", "", "data-errors"), None, "{log}");
    assert!(
        console_errors(&log).is_empty(),
        "{:?}",
        console_errors(&log)
    );
    let _ = std::fs::remove_dir_all(&out);
}
