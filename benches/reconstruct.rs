//! End-to-end reconstruction benchmark (`pipeline::reconstruct::reconstruct`, DESIGN §6) with
//! the shipped weights (`fixtures/point2quad-default.p2qm`, embedded as the CLI embeds them)
//! and the default `ReconstructConfig`, on a noisy synthetic cloud of 10,010 points: a 130 × 70
//! torus (major radius 1, minor 0.4, 9,100 vertices) plus 10% noise points off its faces
//! (`pipeline::noise`, default config, seed 1) — the same cloud as `benches/candidates.rs`.
//!
//! Prints `bench reconstruct_10k <ms> ms`, the median wall time of several runs after a
//! warm-up; `bench reconstruct_10k_cpu <ms> ms`, the mean process CPU time (user + system,
//! all threads) per timed run, which other programs sharing the cores disturb far less than
//! wall time (Linux only, like the next line); then `bench reconstruct_10k_peak_rss <MiB> MiB`,
//! the process's peak resident set (`VmHWM` of `/proc/self/status`; where that is unavailable
//! a note goes to stderr and the line is left out). The peak covers the whole process: the cloud, the model and the largest run.
//! The per-stage medians of `reconstruct_with_report`'s timings go to stderr (they are not
//! `bench` lines: scripts read only the two names above). Threads follow `RAYON_NUM_THREADS`.
//! `RECONSTRUCT_BENCH_FAR=F` turns on the far completion in the candidates (`--far F`;
//! session 29) with the same weights, to time it.

use point2quad::mesh::shapes;
use point2quad::pipeline::model::Model;
use point2quad::pipeline::noise::{noise_points, NoiseConfig};
use point2quad::pipeline::reconstruct::{reconstruct, reconstruct_with_report, ReconstructConfig};
use point2quad::rng::Rng;
use std::hint::black_box;
use std::time::Instant;

#[path = "common/mod.rs"]
mod common;
use common::{cpu_ms, median, peak_rss_mib};

const RUNS: usize = 5;

fn main() {
    let mesh = shapes::torus(130, 70, 1.0, 0.4);
    let mut rng = Rng::new(1);
    let mut cloud = mesh.vertices.clone();
    cloud.extend(noise_points(&mesh, &NoiseConfig::default(), &mut rng).expect("bench: noise points"));
    let model = Model::shipped().expect("bench: shipped weights");
    let mut cfg = ReconstructConfig::default();
    if let Ok(f) = std::env::var("RECONSTRUCT_BENCH_FAR") {
        cfg.candidates.far_per_point = f.parse().expect("bench: RECONSTRUCT_BENCH_FAR");
    }

    // Warm-up, and the account of what one run produces.
    let (warm, report) = reconstruct_with_report(&cloud, &model, &cfg).expect("bench: reconstruct");

    let mut wall = Vec::with_capacity(RUNS);
    let mut stages: Vec<(&'static str, Vec<f64>)> = Vec::new();
    let cpu0 = cpu_ms();
    for _ in 0..RUNS {
        let s = Instant::now();
        black_box(reconstruct(black_box(&cloud), &model, &cfg).expect("bench: reconstruct"));
        wall.push(s.elapsed().as_secs_f64() * 1e3);
    }
    let cpu = cpu0.zip(cpu_ms()).map(|(a, b)| (b - a) / RUNS as f64);
    // Stage timings come from separate runs so the timed runs above go through the plain
    // `reconstruct` entry point, as an embedder calls it.
    for _ in 0..RUNS {
        let (_, r) = reconstruct_with_report(&cloud, &model, &cfg).expect("bench: reconstruct");
        for (i, &(name, secs)) in r.timings.iter().enumerate() {
            if stages.len() <= i {
                stages.push((name, Vec::with_capacity(RUNS)));
            }
            stages[i].1.push(secs * 1e3);
        }
    }

    eprintln!(
        "reconstruct bench: {} points, {} candidates, {} predicted, {} faces, {} vertices added, {} threads",
        cloud.len(),
        report.candidates,
        report.predicted,
        warm.quads.len(),
        report.vertices_added,
        point2quad::par::num_threads()
    );
    for (name, t) in stages {
        eprintln!("reconstruct bench: stage {name:<12} {:.1} ms (median)", median(t));
    }
    println!("bench reconstruct_10k {:.1} ms", median(wall));
    if let Some(c) = cpu {
        println!("bench reconstruct_10k_cpu {c:.1} ms");
    }
    match peak_rss_mib() {
        Some(mib) => println!("bench reconstruct_10k_peak_rss {mib:.1} MiB"),
        None => eprintln!(
            "reconstruct bench: note: peak resident set unavailable (no VmHWM in /proc/self/status \
             on this platform); reconstruct_10k_peak_rss not reported"
        ),
    }
}
