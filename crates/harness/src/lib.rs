//! The marchmesh benchmark harness.
//!
//! [`backend`] builds any backend by name with `key=value` options; the rest of the harness
//! runs suites and writes reports.

// The counting allocator is the one place that needs unsafe code (GlobalAlloc is an unsafe trait).
#[allow(unsafe_code)]
pub mod alloc;
pub mod backend;
pub mod bench;
pub mod images;
pub mod report;
pub mod results;
pub mod rss;
pub mod stats;
pub mod suite;
