//! Any bytes fed to the suite parser give `Ok` or a clean error naming the file, never a
//! panic; an accepted suite stays within the configuration maximum.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data)
        && let Ok(suite) = marchmesh_harness::suite::parse(
            text,
            std::path::Path::new("/nonexistent-fuzz-dir/suite.json"),
        )
    {
        let configs = marchmesh_harness::bench::configurations(&suite, &Default::default());
        assert!(configs.len() as u64 <= marchmesh_harness::suite::MAX_CONFIGURATIONS);
    }
});
