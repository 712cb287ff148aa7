//! Measurement helpers shared by the benchmarks (each bench includes this file with
//! `#[path = "common/mod.rs"] mod common;` and uses what it needs).

#![allow(dead_code)]

use std::time::Instant;

/// Process CPU time (user + system, all threads) in ms from `/proc/self/stat`, whose
/// clock ticks are `USER_HZ` = 100 per second on Linux; `None` elsewhere.
pub fn cpu_ms() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    let fields: Vec<&str> = stat.rsplit_once(')')?.1.split_whitespace().collect();
    let ticks: u64 = fields.get(11)?.parse::<u64>().ok()? + fields.get(12)?.parse::<u64>().ok()?;
    Some(ticks as f64 * 10.0)
}

/// Peak resident set in MiB from `VmHWM` of `/proc/self/status` (Linux); `None` elsewhere.
pub fn peak_rss_mib() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    // The line reads "VmHWM:   123456 kB".
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib / 1024.0)
}

/// Median of a non-empty list.
pub fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Median wall time (ms) of `runs` calls after one warm-up call.
pub fn median_ms(runs: usize, mut f: impl FnMut()) -> f64 {
    f();
    median(
        (0..runs.max(1))
            .map(|_| {
                let s = Instant::now();
                f();
                s.elapsed().as_secs_f64() * 1e3
            })
            .collect(),
    )
}

/// Median wall time and mean CPU time per call (ms; the warm-up included in the mean).
pub fn timed(runs: usize, mut f: impl FnMut()) -> (f64, f64) {
    let c0 = cpu_ms().unwrap_or(0.0);
    let wall = median_ms(runs, &mut f);
    let c1 = cpu_ms().unwrap_or(0.0);
    (wall, (c1 - c0) / (runs.max(1) + 1) as f64)
}
