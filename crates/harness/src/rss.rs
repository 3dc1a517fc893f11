//! Process peak resident set size per phase (Linux): `/proc/self/clear_refs` (writing `5`
//! resets the high-water mark to the current RSS) then `VmHWM` from `/proc/self/status`.
//! Elsewhere, or when the reset is not permitted, every reading is `None`.

/// Resets the kernel's peak-RSS mark for this process. False when not possible (not Linux,
/// no permission, no procfs).
pub fn reset_peak_rss() -> bool {
    #[cfg(target_os = "linux")]
    {
        std::fs::write("/proc/self/clear_refs", "5").is_ok()
    }
    #[cfg(not(target_os = "linux"))]
    {
        false
    }
}

/// The process's peak RSS in bytes (`VmHWM`), `None` when unavailable.
pub fn peak_rss_bytes() -> Option<u64> {
    status_kib("VmHWM:").map(|k| k * 1024)
}

/// The process's current RSS in bytes (`VmRSS`), `None` when unavailable.
pub fn current_rss_bytes() -> Option<u64> {
    status_kib("VmRSS:").map(|k| k * 1024)
}

fn status_kib(field: &str) -> Option<u64> {
    let text = std::fs::read_to_string("/proc/self/status").ok()?;
    parse_status_kib(&text, field)
}

/// Parses `Field:   1234 kB` out of `/proc/self/status` text.
fn parse_status_kib(text: &str, field: &str) -> Option<u64> {
    let line = text.lines().find(|l| l.starts_with(field))?;
    let mut parts = line[field.len()..].split_whitespace();
    let value: u64 = parts.next()?.parse().ok()?;
    (parts.next() == Some("kB")).then_some(value)
}

/// A phase of peak-RSS measurement.
#[derive(Debug, Clone, Copy)]
pub struct RssPhase {
    reset: bool,
}

impl RssPhase {
    /// Resets the high-water mark.
    pub fn start() -> Self {
        Self {
            reset: reset_peak_rss(),
        }
    }

    /// Peak RSS of the process during the phase, bytes; `None` if the mark could not be
    /// reset (the value would include earlier phases) or read.
    pub fn finish(self) -> Option<u64> {
        if self.reset { peak_rss_bytes() } else { None }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_status_lines() {
        let t = "Name:\tx\nVmHWM:\t  2048 kB\nVmRSS:\t 1024 kB\n";
        assert_eq!(parse_status_kib(t, "VmHWM:"), Some(2048));
        assert_eq!(parse_status_kib(t, "VmRSS:"), Some(1024));
        assert_eq!(parse_status_kib(t, "VmPeak:"), None);
        assert_eq!(parse_status_kib("VmHWM: 12 MB", "VmHWM:"), None);
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn linux_reports_a_plausible_peak() {
        // Other tests in this binary allocate and reset the high-water mark concurrently, so
        // only read current before peak and check both are plausible.
        let current = current_rss_bytes().expect("procfs");
        let peak = peak_rss_bytes().expect("procfs");
        assert!(current > 100 * 1024, "{current}");
        assert!(peak > 100 * 1024, "{peak}");
    }
}
