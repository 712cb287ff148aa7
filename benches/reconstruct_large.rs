//! End-to-end reconstruction of a large cloud (`pipeline::reconstruct::reconstruct`,
//! shipped weights, default `ReconstructConfig`): a height field z = 0.05 sin 6x cos 5y
//! sampled on a regular N × N grid of the unit square, N = 1000 (one million points)
//! unless `RECONSTRUCT_LARGE_SIDE` says otherwise. The grid is a quad layout, so the
//! exact answer is known: its (N − 1)² cells.
//!
//! One timed run (a large cloud takes about a minute on two cores), no warm-up. Prints
//! `bench reconstruct_large <ms> ms`, `bench reconstruct_large_peak_rss <MiB> MiB` (the
//! process's peak resident set, `VmHWM`; Linux only, otherwise a note on stderr) and
//! `bench reconstruct_large_faces <count> faces`; the stage timings go to stderr.
//! Threads follow `RAYON_NUM_THREADS`.

use point2quad::pipeline::model::Model;
use point2quad::pipeline::reconstruct::{reconstruct_with_report, ReconstructConfig};
use std::time::Instant;

#[path = "common/mod.rs"]
mod common;
use common::peak_rss_mib;

fn main() {
    let side: usize = match std::env::var("RECONSTRUCT_LARGE_SIDE") {
        Ok(v) => v.parse().expect("bench: RECONSTRUCT_LARGE_SIDE must be a whole number"),
        Err(_) => 1000,
    };
    assert!(side >= 2, "bench: RECONSTRUCT_LARGE_SIDE must be at least 2");
    let step = 1.0 / (side - 1) as f64;
    let cloud: Vec<[f64; 3]> = (0..side * side)
        .map(|k| {
            let (x, y) = ((k / side) as f64 * step, (k % side) as f64 * step);
            [x, y, 0.05 * (6.0 * x).sin() * (5.0 * y).cos()]
        })
        .collect();
    let model = Model::shipped().expect("bench: shipped weights");
    let cfg = ReconstructConfig::default();
    let s = Instant::now();
    let (mesh, report) = reconstruct_with_report(&cloud, &model, &cfg).expect("bench: reconstruct");
    let ms = s.elapsed().as_secs_f64() * 1e3;
    eprintln!(
        "reconstruct_large bench: {} points ({side} x {side}), {} candidates, {} faces (exact: {}), {} threads",
        cloud.len(),
        report.candidates,
        mesh.quads.len(),
        (side - 1) * (side - 1),
        point2quad::par::num_threads()
    );
    for (name, secs) in &report.timings {
        eprintln!("reconstruct_large bench: stage {name:<12} {:.1} ms", secs * 1e3);
    }
    println!("bench reconstruct_large {ms:.1} ms");
    match peak_rss_mib() {
        Some(mib) => println!("bench reconstruct_large_peak_rss {mib:.1} MiB"),
        None => eprintln!(
            "reconstruct_large bench: note: peak resident set unavailable on this platform; not reported"
        ),
    }
    println!("bench reconstruct_large_faces {} faces", mesh.quads.len());
}
