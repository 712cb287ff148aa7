//! How ambiguous a ground truth is for a method that picks faces from the points alone:
//! for each true face among a sample's candidates, the best-shaped *rival* — a
//! candidate that is not a face, uses only mesh vertices (no noise point), and covers
//! part of the face (shares three of its corners, or both ends of one of its
//! diagonals). Prints, per sample, the share of true candidates whose best rival has
//! a scaled Jacobian (F_info column 12) at least 0.05 above theirs, and at least equal.
//! Where that share is large, the ground truth chose worse-shaped quads than the points
//! offer (a remesher following a cross field does), and face precision and recall
//! measure which tiling was picked as much as whether the mesh is good.
//! With `--recall`, it reads pairs SAMPLE OUTPUT (a reconstruction of a cloud whose
//! first points are the sample's mesh vertices, in order, as `point2quad synth --from`
//! writes it) and prints the output's recall of the ambiguous true faces (those with a
//! rival better by ≥ 0.05) and of the other true faces that are candidates.
//! A measurement tool; asserts nothing.
//!
//! ```text
//! point2quad dataset --out D --meshes MESHDIR --noise 0.1 --seed 1
//! cargo run --release --example rival_shapes -- D/*.p2qs
//! cargo run --release --example rival_shapes -- --recall D/a.p2qs OUT/a.obj D/b.p2qs OUT/b.obj
//! ```

use std::collections::{HashMap, HashSet};
use std::path::Path;

use point2quad::io::mesh_io::read_mesh;
use point2quad::pipeline::dataset::{load_sample, Sample};

/// `num / den`, 0 when `den` is 0.
fn ratio(num: usize, den: usize) -> f64 {
    if den > 0 {
        num as f64 / den as f64
    } else {
        0.0
    }
}

fn sorted(q: &[u32]) -> Vec<u32> {
    let mut k = q.to_vec();
    k.sort_unstable();
    k
}

/// Per true candidate of `s`: whether its best rival beats its scaled Jacobian by
/// ≥ 0.05, and whether by ≥ 0 (see the module header).
fn rivals(s: &Sample) -> Vec<(usize, bool, bool)> {
    let d = s.feature_dim as usize;
    let sj = |c: usize| s.features[c * d + 12];
    let mut by_vertex: HashMap<u32, Vec<usize>> = HashMap::new();
    for (c, q) in s.candidates.iter().enumerate() {
        for &v in q {
            by_vertex.entry(v).or_default().push(c);
        }
    }
    let mut out = Vec::new();
    for (c, q) in s.candidates.iter().enumerate() {
        if s.labels[c] == 0 {
            continue;
        }
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
        out.push((c, best >= sj(c) + 0.05, best >= sj(c)));
    }
    out
}

/// `--recall SAMPLE OUTPUT ...`: recall of the ambiguous and the other true candidates.
fn recall(args: &[String]) -> point2quad::Result<()> {
    println!("sample | ambiguous true faces | their recall | other true candidates | their recall");
    let mut t = [0usize; 4];
    for pair in args.chunks(2) {
        let [sample, output] = pair else {
            eprintln!("--recall takes pairs SAMPLE.p2qs OUTPUT");
            std::process::exit(2);
        };
        let s = load_sample(Path::new(sample))?;
        let out: HashSet<Vec<u32>> = read_mesh(Path::new(output))?.faces.iter().map(|f| sorted(f)).collect();
        let mut c = [0usize; 4];
        for (cand, amb, _) in rivals(&s) {
            let k = if amb { 0 } else { 2 };
            c[k] += 1;
            c[k + 1] += usize::from(out.contains(&sorted(&s.candidates[cand])));
        }
        println!("{} | {} | {:.3} | {} | {:.3}", s.name, c[0], ratio(c[1], c[0]), c[2], ratio(c[3], c[2]));
        for i in 0..4 {
            t[i] += c[i];
        }
    }
    println!("all | {} | {:.3} | {} | {:.3}", t[0], ratio(t[1], t[0]), t[2], ratio(t[3], t[2]));
    Ok(())
}

fn main() -> point2quad::Result<()> {
    let files: Vec<String> = std::env::args().skip(1).collect();
    if files.first().map(String::as_str) == Some("--recall") {
        return recall(&files[1..]);
    }
    if files.is_empty() {
        eprintln!(
            "usage: rival_shapes SAMPLE.p2qs... | rival_shapes --recall SAMPLE OUTPUT [SAMPLE OUTPUT ...]"
        );
        std::process::exit(2);
    }
    println!("sample | GT faces | true candidates | rival better by ≥ 0.05 | rival at least as good");
    let (mut all, mut better, mut equal) = (0usize, 0usize, 0usize);
    for f in &files {
        let s = load_sample(Path::new(f))?;
        let r = rivals(&s);
        let n = r.len();
        let b = r.iter().filter(|x| x.1).count();
        let e = r.iter().filter(|x| x.2).count();
        println!("{} | {} | {} | {:.3} | {:.3}", s.name, s.gt_faces.len(), n, ratio(b, n), ratio(e, n));
        (all, better, equal) = (all + n, better + b, equal + e);
    }
    if all > 0 {
        println!(
            "all (true-candidate-weighted) | | {all} | {:.3} | {:.3}",
            ratio(better, all),
            ratio(equal, all)
        );
    }
    Ok(())
}
