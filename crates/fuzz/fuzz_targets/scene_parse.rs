//! Any bytes fed to the scene parser and validator give `Ok` or a clean error, never a panic.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = marchmesh_scene::parse_scene(text, "<fuzz>", std::path::Path::new("."));
    }
});
