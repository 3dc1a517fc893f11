//! Placeholder, replaced by the real bench in the next step.
fn main() {}
