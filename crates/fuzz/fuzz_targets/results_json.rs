//! Any bytes taken as a `results.json`: parsing and the value check give `Ok` or a clean
//! error; an accepted run renders its summary, verdicts and HTML report without a panic or
//! a hang (no files are written).
#![no_main]

use libfuzzer_sys::fuzz_target;
use marchmesh_harness::results::Results;

fuzz_target!(|data: &[u8]| {
    let Ok(res) = serde_json::from_slice::<Results>(data) else {
        return;
    };
    if res.check_values().is_err() {
        return;
    }
    let _ = marchmesh_harness::report::summary_markdown(&res.markdown_safe());
    let _ = marchmesh_harness::verdicts::compare_runs(&res, &res, 40.0);
    let _ = marchmesh_harness::html::report_html(&res, std::path::Path::new("/nonexistent-fuzz-dir"));
});
