//! kd-tree benchmark (DESIGN §6): 100,000 uniform random points in the unit cube (seed 0), build
//! time, then k = 12 nearest neighbours of every point (itself included) as one batch query.
//! Prints `bench kdtree_build_100k <ms> ms` and `bench kdtree_knn12_100k <ms> ms`, medians of
//! several runs after a warm-up. Threads follow `RAYON_NUM_THREADS`. On Linux it also reports to
//! stderr the mean process CPU time per run (all threads), which is far less sensitive than wall
//! time to other programs sharing the cores.

use point2quad::rng::Rng;
use point2quad::spatial::kdtree::KdTree;
use std::hint::black_box;
use std::time::Instant;

const N: usize = 100_000;
const K: usize = 12;
const RUNS: usize = 11;

/// Process CPU time (user + system, all threads) in ms from `/proc/self/stat`, whose clock ticks
/// are `USER_HZ` = 100 per second on Linux; `None` elsewhere.
fn cpu_ms() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    let fields: Vec<&str> = stat.rsplit_once(')')?.1.split_whitespace().collect();
    let ticks: u64 = fields.get(11)?.parse::<u64>().ok()? + fields.get(12)?.parse::<u64>().ok()?;
    Some(ticks as f64 * 10.0)
}

/// Median wall time of `RUNS` runs after a warm-up, and the mean CPU time per run if known.
fn median_ms(mut f: impl FnMut()) -> (f64, Option<f64>) {
    f(); // warm-up
    let cpu0 = cpu_ms();
    let mut t: Vec<f64> = (0..RUNS)
        .map(|_| {
            let s = Instant::now();
            f();
            s.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    let cpu = cpu0.zip(cpu_ms()).map(|(a, b)| (b - a) / RUNS as f64);
    t.sort_by(f64::total_cmp);
    (t[RUNS / 2], cpu)
}

fn main() {
    let mut rng = Rng::new(0);
    let points: Vec<[f32; 3]> = (0..N).map(|_| [rng.f32(), rng.f32(), rng.f32()]).collect();
    let build = median_ms(|| {
        black_box(KdTree::build(black_box(&points)));
    });
    let tree = KdTree::build(&points);
    let query = median_ms(|| {
        black_box(tree.knn_batch(black_box(&points), K));
    });
    // A checksum so that the work cannot be skipped and runs can be compared.
    let table = tree.knn_batch(&points, K);
    let self_first = (0..N).filter(|&i| table.row(i).0[0] as usize == i).count();
    eprintln!("kdtree bench: {N} points, k = {K}, {self_first} queries found themselves first");
    if let (Some(b), Some(q)) = (build.1, query.1) {
        eprintln!("kdtree bench: mean CPU time per run (all threads): build {b:.1} ms, knn {q:.1} ms");
    }
    let (build, query) = (build.0, query.0);
    println!("bench kdtree_build_100k {build:.2} ms");
    println!("bench kdtree_knn12_100k {query:.2} ms");
}
