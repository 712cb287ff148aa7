//! kd-tree benchmark (DESIGN §6): 100,000 uniform random points in the unit cube (seed 0), build
//! time, then k = 12 nearest neighbours of every point (itself included) as one batch query.
//! Prints `bench kdtree_build_100k <ms> ms` and `bench kdtree_knn12_100k <ms> ms`, medians of
//! several runs after a warm-up. Threads follow `RAYON_NUM_THREADS`.

use point2quad::rng::Rng;
use point2quad::spatial::kdtree::KdTree;
use std::hint::black_box;
use std::time::Instant;

const N: usize = 100_000;
const K: usize = 12;
const RUNS: usize = 11;

fn median_ms(mut f: impl FnMut()) -> f64 {
    f(); // warm-up
    let mut t: Vec<f64> = (0..RUNS)
        .map(|_| {
            let s = Instant::now();
            f();
            s.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    t.sort_by(f64::total_cmp);
    t[RUNS / 2]
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
    println!("bench kdtree_build_100k {build:.2} ms");
    println!("bench kdtree_knn12_100k {query:.2} ms");
}
