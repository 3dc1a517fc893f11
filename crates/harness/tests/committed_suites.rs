//! Every committed suite under `scenes/suites` parses, its backends' `key=value` options
//! included (checked by the registry against each backend's settings type), so a change to an
//! options type that drops or renames a key users' suites rely on fails here.

#[test]
fn every_committed_suite_parses_with_its_backend_options() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/suites");
    let mut checked = 0;
    for entry in std::fs::read_dir(&dir).expect("scenes/suites") {
        let path = entry.expect("entry").path();
        if path.extension().is_some_and(|e| e == "json") {
            marchmesh_harness::suite::load(&path)
                .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            checked += 1;
        }
    }
    assert!(checked > 0, "no suites in {}", dir.display());
}
