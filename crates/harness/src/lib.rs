//! The marchmesh benchmark harness.
//!
//! [`backend`] builds any backend by name with `key=value` options; the rest of the harness
//! runs suites and writes reports.

pub mod backend;
