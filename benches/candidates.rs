//! Candidate generation benchmark (`pipeline::candidates::generate`, DESIGN §2): a noisy
//! synthetic cloud of 10,010 points (a 130 × 70 torus, major radius 1, minor 0.4, 9,100
//! vertices, plus 10% noise points off the faces, noise seed 1), normalised as the pipeline
//! does, default `CandidateConfig`. Prints `bench candidates_10k <ms> ms`, the median of
//! several runs after a warm-up, and `bench candidates_10k_cpu <ms> ms`, the mean process CPU
//! time (user + system, all threads) per run, which other programs sharing the cores disturb
//! far less than wall time. Threads follow `RAYON_NUM_THREADS`.
//!
//! With `CANDIDATES_BENCH_XYZ=PATH` the cloud is also written there (to time other builds of
//! `point2quad candidates` on exactly the same input). `CANDIDATES_BENCH_FAR=F` turns on
//! the far completion with F per point (`--far F`; session 29).

use point2quad::mesh::shapes;
use point2quad::pipeline::candidates::{generate, CandidateConfig};
use point2quad::pipeline::frame::Frame;
use point2quad::pipeline::noise::{noise_points, NoiseConfig};
use point2quad::rng::Rng;
use std::hint::black_box;
use std::time::Instant;

#[path = "common/mod.rs"]
mod common;
use common::cpu_ms;

const RUNS: usize = 7;

fn main() {
    let mesh = shapes::torus(130, 70, 1.0, 0.4);
    let mut rng = Rng::new(1);
    let mut cloud = mesh.vertices.clone();
    cloud.extend(noise_points(&mesh, &NoiseConfig::default(), &mut rng).expect("bench: noise points"));
    if let Ok(path) = std::env::var("CANDIDATES_BENCH_XYZ") {
        point2quad::io::points::write_points_xyz(std::path::Path::new(&path), &cloud)
            .expect("bench: write cloud");
    }
    let frame = Frame::fit(&cloud).expect("bench: frame");
    let points = frame.to_local_all(&cloud);
    let far =
        std::env::var("CANDIDATES_BENCH_FAR").ok().map(|v| v.parse().expect("bench: CANDIDATES_BENCH_FAR"));
    let cfg = CandidateConfig { far_per_point: far.unwrap_or(0), ..CandidateConfig::default() };

    let warm = generate(&points, &cfg).expect("bench: candidates");
    let cpu0 = cpu_ms();
    let mut t: Vec<f64> = (0..RUNS)
        .map(|_| {
            let s = Instant::now();
            black_box(generate(black_box(&points), &cfg).expect("bench: candidates"));
            s.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    let cpu = cpu0.zip(cpu_ms()).map(|(a, b)| (b - a) / RUNS as f64);
    t.sort_by(f64::total_cmp);
    eprintln!(
        "candidates bench: {} points, {} candidates ({:.2} per point), {} threads",
        points.len(),
        warm.len(),
        warm.len() as f64 / points.len() as f64,
        point2quad::par::num_threads()
    );
    println!("bench candidates_10k {:.1} ms", t[RUNS / 2]);
    if let Some(c) = cpu {
        println!("bench candidates_10k_cpu {c:.1} ms");
    }
}
