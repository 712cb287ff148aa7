//! How ambiguous a ground truth is for a method that picks faces from the points alone:
//! for each true face among a sample's candidates, the best-shaped *rival* — a
//! candidate that is not a face, uses only mesh vertices (no noise point), and covers
//! part of the face (shares three of its corners, or both ends of one of its
//! diagonals). Prints, per sample, the share of true candidates whose best rival has
//! a scaled Jacobian (F_info column 12) at least 0.05 above theirs, and at least equal.
//! Where that share is large, the ground truth chose worse-shaped quads than the points
//! offer (a remesher following a cross field does), and face precision and recall
//! measure which tiling was picked as much as whether the mesh is good.
//! A measurement tool; asserts nothing.
//!
//! ```text
//! point2quad dataset --out D --meshes MESHDIR --noise 0.1 --seed 1
//! cargo run --release --example rival_shapes -- D/*.p2qs
//! ```

use std::collections::HashMap;
use std::path::Path;

use point2quad::pipeline::dataset::load_sample;

fn main() -> point2quad::Result<()> {
    let files: Vec<String> = std::env::args().skip(1).collect();
    if files.is_empty() {
        eprintln!("usage: rival_shapes SAMPLE.p2qs...");
        std::process::exit(2);
    }
    println!("sample | GT faces | true candidates | rival better by ≥ 0.05 | rival at least as good");
    let (mut all, mut better, mut equal) = (0usize, 0usize, 0usize);
    for f in &files {
        let s = load_sample(Path::new(f))?;
        let d = s.feature_dim as usize;
        let sj = |c: usize| s.features[c * d + 12];
        let mut by_vertex: HashMap<u32, Vec<usize>> = HashMap::new();
        for (c, q) in s.candidates.iter().enumerate() {
            for &v in q {
                by_vertex.entry(v).or_default().push(c);
            }
        }
        let (mut n, mut b, mut e) = (0usize, 0usize, 0usize);
        for (c, q) in s.candidates.iter().enumerate() {
            if s.labels[c] == 0 {
                continue;
            }
            n += 1;
            let diagonals = [[q[0], q[2]], [q[1], q[3]]];
            let mut best = f32::NEG_INFINITY;
            let mut seen: Vec<usize> = Vec::new();
            for v in q {
                for &r in &by_vertex[v] {
                    let rq = s.candidates[r];
                    if r == c
                        || s.labels[r] == 1
                        || seen.contains(&r)
                        || rq.iter().any(|&x| x >= s.n_mesh_vertices)
                    {
                        continue;
                    }
                    seen.push(r);
                    let shared = rq.iter().filter(|x| q.contains(x)).count();
                    if shared >= 3 || diagonals.iter().any(|dg| dg.iter().all(|x| rq.contains(x))) {
                        best = best.max(sj(r));
                    }
                }
            }
            b += usize::from(best >= sj(c) + 0.05);
            e += usize::from(best >= sj(c));
        }
        let share = |k: usize| if n > 0 { k as f64 / n as f64 } else { 0.0 };
        println!("{} | {} | {} | {:.3} | {:.3}", s.name, s.gt_faces.len(), n, share(b), share(e));
        (all, better, equal) = (all + n, better + b, equal + e);
    }
    if all > 0 {
        println!(
            "all (true-candidate-weighted) | | {all} | {:.3} | {:.3}",
            better as f64 / all as f64,
            equal as f64 / all as f64
        );
    }
    Ok(())
}
