//! Peak memory, for reports: the process's resident set (Linux `/proc/self/status`), sampled while
//! a piece of work runs, and the process's high-water mark (`VmHWM`).
//!
//! A stage's peak is sampled (every [`SAMPLE_INTERVAL`]) rather than taken from the kernel's mark
//! reset at the stage's start: that reset (writing `5` to `/proc/self/clear_refs`) also lowers what
//! the kernel reports for the whole process afterwards (`getrusage`, `/usr/bin/time`), so tools
//! outside would see the last stage's peak as the process's. Sampling can miss a spike shorter than
//! the interval; the process's own mark cannot, and reports give both. Elsewhere, or where /proc is
//! not mounted, the figures are `None` and reports leave them out.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

/// How often a measured piece of work's resident set is read.
pub const SAMPLE_INTERVAL: Duration = Duration::from_millis(2);

fn status_kib(field: &str) -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with(field))?;
    line[field.len()..].trim().trim_end_matches("kB").trim().parse::<u64>().ok()?.checked_mul(1024)
}

/// The process's resident set now, bytes.
pub fn rss_bytes() -> Option<u64> {
    status_kib("VmRSS:")
}

/// The process's resident high-water mark since it started, bytes (the kernel updates it lazily:
/// a sample of [`rss_bytes`] taken before memory was freed can be above it).
pub fn peak_rss_bytes() -> Option<u64> {
    status_kib("VmHWM:")
}

/// Runs `work` while a thread samples the resident set; the largest sample (with the sets at the
/// start and at the end), or `None` where the platform does not tell. The sampler stops when
/// `work` returns or unwinds.
pub fn measure<T>(work: impl FnOnce() -> T) -> (T, Option<u64>) {
    let Some(start) = rss_bytes() else { return (work(), None) };
    let peak = AtomicU64::new(start);
    let stop = AtomicBool::new(false);
    /// Sets the flag when dropped, also while unwinding (the scope then joins the sampler).
    struct Stop<'a>(&'a AtomicBool);
    impl Drop for Stop<'_> {
        fn drop(&mut self) {
            self.0.store(true, Ordering::Relaxed);
        }
    }
    let out = std::thread::scope(|scope| {
        let sampler = std::thread::Builder::new().name("verdant-memory".into()).spawn_scoped(scope, || {
            while !stop.load(Ordering::Relaxed) {
                if let Some(now) = rss_bytes() {
                    peak.fetch_max(now, Ordering::Relaxed);
                }
                std::thread::sleep(SAMPLE_INTERVAL);
            }
        });
        let _stop = Stop(&stop);
        let out = work();
        drop(_stop);
        if let Ok(handle) = sampler {
            let _ = handle.join();
        }
        out
    });
    if let Some(end) = rss_bytes() {
        peak.fetch_max(end, Ordering::Relaxed);
    }
    (out, Some(peak.load(Ordering::Relaxed)))
}

/// Hands memory the allocator holds free back to the system (glibc keeps what a large stage freed
/// in its arenas, so the next stage's resident set, and a build's reported peaks, would still count
/// it: the world preset's preview stage sat at 0.9 GB of which half was the view stage's freed
/// heap). A no-op where the allocator is not glibc's.
pub fn release_freed() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: malloc_trim only walks glibc's own arenas; it takes no pointers of ours
    unsafe {
        libc::malloc_trim(0);
    }
}

/// Bytes as MiB with one decimal (for reports).
pub fn mib(bytes: u64) -> f64 {
    (bytes as f64 / 1048576.0 * 10.0).round() / 10.0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_large_allocation_held_for_a_while_shows_in_the_measured_peak() {
        if rss_bytes().is_none() {
            eprintln!("skipped: /proc/self/status has no VmRSS here");
            return;
        }
        let size = 64 << 20;
        let (_, peak) = measure(|| {
            let mut v = vec![0u8; size];
            // touch every page so it is resident, and hold it over several sampling intervals
            for i in (0..size).step_by(4096) {
                v[i] = 1;
            }
            std::thread::sleep(SAMPLE_INTERVAL * 10);
            std::hint::black_box(&v);
        });
        let peak = peak.expect("a peak");
        assert!(peak >= size as u64, "peak {peak} B while {size} B were resident");
    }

    #[test]
    fn the_sampler_stops_when_the_work_panics() {
        let caught = std::panic::catch_unwind(|| measure(|| panic!("stage failed")));
        assert!(caught.is_err());
        // the scope joined the sampler: no thread of that name is left running
        let threads = std::fs::read_dir("/proc/self/task").map(|d| d.count()).unwrap_or(0);
        let named = std::fs::read_dir("/proc/self/task")
            .into_iter()
            .flatten()
            .flatten()
            .filter(|t| std::fs::read_to_string(t.path().join("comm")).is_ok_and(|c| c.trim() == "verdant-memory"))
            .count();
        assert_eq!(named, 0, "a sampler is still running ({threads} threads)");
    }
}
