//! Number and byte formatting shared by the summary, the findings and the plots.

use crate::results::Row;

/// Bytes with a binary unit (B, KiB, MiB, GiB), 3 significant digits.
pub fn bytes(b: u64) -> String {
    let units = ["B", "KiB", "MiB", "GiB", "TiB"];
    let mut v = b as f64;
    let mut u = 0;
    while v >= 1024.0 && u + 1 < units.len() {
        v /= 1024.0;
        u += 1;
    }
    if u == 0 {
        format!("{b} B")
    } else if v >= 100.0 {
        format!("{v:.0} {}", units[u])
    } else if v >= 10.0 {
        format!("{v:.1} {}", units[u])
    } else {
        format!("{v:.2} {}", units[u])
    }
}

/// `depth / normal` tail pixel counts of a row, `n/a` without a reference.
pub(crate) fn tail_px(r: &Row) -> String {
    match (r.depth_err_rel_tail_px, r.normal_err_deg_tail_px) {
        (Some(d), Some(n)) => format!("{d} / {n}"),
        _ => "n/a".into(),
    }
}

pub(crate) fn opt(v: Option<f64>, digits: usize) -> String {
    v.map_or("n/a".into(), |x| {
        if x != 0.0 && (x.abs() < 1e-3 || x.abs() >= 1e6) {
            format!("{x:.2e}")
        } else {
            format!("{x:.digits$}")
        }
    })
}

pub(crate) fn opt_bytes(v: Option<u64>) -> String {
    v.map_or("n/a".into(), bytes)
}

/// Axis numbers: at most 3 significant digits, k/M/G suffixes for large values.
pub(crate) fn short_num(v: f64) -> String {
    let a = v.abs();
    let (x, suffix) = if a >= 1e9 {
        (v / 1e9, "G")
    } else if a >= 1e6 {
        (v / 1e6, "M")
    } else if a >= 1e4 {
        (v / 1e3, "k")
    } else {
        (v, "")
    };
    let t = format!("{x:.3}");
    let t = if t.contains('.') {
        t.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        t
    };
    format!("{t}{suffix}")
}

/// `text` safe inside a Markdown table cell or line: `\\`, `|`, `[`, `]`, `` ` ``, `*` and `#`
/// are backslash-escaped, `<` and `>` become `&lt;` and `&gt;` (no HTML such as
/// `<img onerror=...>`), and control characters (a newline would start a heading) become
/// spaces. Plain names (letters, digits, `_-.:/=,`) come out unchanged.
pub fn md_escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '\\' | '|' | '[' | ']' | '`' | '*' | '#' => {
                out.push('\\');
                out.push(c);
            }
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            c if c.is_control() => out.push(' '),
            c => out.push(c),
        }
    }
    out
}
