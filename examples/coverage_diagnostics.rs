//! Candidate-coverage diagnostics behind the README's "what we measured on the way"
//! (issue 2) and the loss decomposition of issue 6. Prints tables; asserts nothing
//! (it is a measurement tool, not a test). `train/` only, or a folder you name:
//!
//! ```text
//! cargo run --release --example coverage_diagnostics -- ceilings        # DK=k (default 20)
//! DM=qm_hedgehog_spikes cargo run --release --example coverage_diagnostics -- mesh
//! DPP=64 DR=0.05 cargo run --release --example coverage_diagnostics -- sweep
//! [DDIR=/path/to/meshes] cargo run --release --example coverage_diagnostics -- losses
//! ```
//!
//! `sweep` reads CandidateConfig overrides from DK, DPP, DR, DS, DWI1, DWI, DWL, DWS.
//! `losses` splits the ground-truth faces of each mesh (10% noise) into: not a
//! candidate, candidate under the threshold, over it but dropped by the post-process,
//! recovered; and the output's false positives by origin. Run it on the validation
//! split of `train/` (never tune on `eval/`).

#[path = "../tests/common/candidates.rs"]
mod cands_common;
use cands_common::*;
use point2quad::pipeline::candidates::{knn_table, CandidateConfig};
use std::collections::HashSet;

fn kset(knn: &point2quad::spatial::kdtree::KnnTable, i: usize, k: usize) -> Vec<u32> {
    let (idx, _) = knn.row(i);
    idx.iter().copied().filter(|&j| j as usize != i).take(k).collect()
}

fn ceilings() {
    let files = mesh_files("train").unwrap();
    let cfg = CandidateConfig::default();
    let k: usize = std::env::var("DK").ok().and_then(|v| v.parse().ok()).unwrap_or(20);
    for noisy in [false, true] {
        let mut t = [0usize; 8];
        for path in &files {
            let mesh = load_quad_mesh(path);
            let pts = if noisy { noisy_cloud(&mesh, 1) } else { mesh.vertices.clone() };
            let (_, c) = coverage(&pts, &mesh.quads, &cfg);
            let have: HashSet<[u32; 4]> = c.quads.iter().map(key).collect();
            let frame = point2quad::pipeline::frame::Frame::fit(&pts).unwrap();
            let local = frame.to_local_all(&pts);
            let knn = knn_table(&local, k);
            let n = local.len();
            let sets: Vec<HashSet<u32>> = (0..n).map(|i| kset(&knn, i, k).into_iter().collect()).collect();
            let edge = |a: u32, b: u32| sets[a as usize].contains(&b) || sets[b as usize].contains(&a);
            let mut m = [0usize; 8];
            for f in &mesh.quads {
                m[0] += 1;
                let covered = have.contains(&key(f));
                if covered {
                    m[1] += 1;
                }
                let a = (0..4).any(|s| (1..4).all(|d| sets[f[s] as usize].contains(&f[(s + d) % 4])));
                let b = (0..4).all(|s| edge(f[s], f[(s + 1) % 4]));
                // corner with both its edge-neighbours in its kNN
                let c3 = (0..4).any(|s| {
                    sets[f[s] as usize].contains(&f[(s + 1) % 4])
                        && sets[f[s] as usize].contains(&f[(s + 3) % 4])
                        && (edge(f[(s + 1) % 4], f[(s + 2) % 4]) || edge(f[(s + 3) % 4], f[(s + 2) % 4]))
                });
                if a {
                    m[2] += 1;
                }
                if b {
                    m[3] += 1;
                }
                if a || b {
                    m[4] += 1;
                }
                if !covered && a {
                    m[5] += 1;
                }
                if !covered && !a && b {
                    m[6] += 1;
                }
                if a || c3 {
                    m[7] += 1;
                }
            }
            let r = |x: usize| x as f64 / m[0] as f64;
            println!("{:28} {} faces {:6} cov {:.4} A {:.4} B {:.4} AorB {:.4} AorC3 {:.4} | missedA {:.4} missedBnotA {:.4}",
                path.file_stem().unwrap().to_string_lossy(), if noisy {"N"} else {"C"}, m[0], r(m[1]), r(m[2]), r(m[3]), r(m[4]), r(m[7]), r(m[5]), r(m[6]));
            for i in 0..8 {
                t[i] += m[i];
            }
        }
        let r = |x: usize| x as f64 / t[0] as f64;
        println!(
            "TOTAL {} cov {:.4} A {:.4} B {:.4} AorB {:.4} AorC3 {:.4} missedA {:.4} missedBnotA {:.4}",
            if noisy { "N" } else { "C" },
            r(t[1]),
            r(t[2]),
            r(t[3]),
            r(t[4]),
            r(t[7]),
            r(t[5]),
            r(t[6])
        );
    }
}

fn one_mesh() {
    let name = std::env::var("DM").unwrap_or("qm_hedgehog_spikes".into());
    let files = mesh_files("train").unwrap();
    let path = files.iter().find(|p| p.to_string_lossy().contains(&name)).unwrap();
    let mesh = load_quad_mesh(path);
    let pts = mesh.vertices.clone();
    let cfg = CandidateConfig::default();
    let (_, c) = coverage(&pts, &mesh.quads, &cfg);
    let have: HashSet<[u32; 4]> = c.quads.iter().map(key).collect();
    let frame = point2quad::pipeline::frame::Frame::fit(&pts).unwrap();
    let local = frame.to_local_all(&pts);
    let knn = knn_table(&local, 200);
    let n = local.len();
    let rank = |i: u32, j: u32| -> usize {
        let (idx, _) = knn.row(i as usize);
        idx.iter().filter(|&&x| x != i).position(|&x| x == j).unwrap_or(999)
    };
    let mut hist = std::collections::BTreeMap::new();
    let mut ratios = vec![];
    let mut nmiss = 0;
    for f in &mesh.quads {
        if have.contains(&key(f)) {
            continue;
        }
        nmiss += 1;
        // best corner: max rank of others minimal
        let best = (0..4).map(|s| (1..4).map(|d| rank(f[s], f[(s + d) % 4])).max().unwrap()).min().unwrap();
        let b = match best {
            0..=20 => 20,
            21..=30 => 30,
            31..=50 => 50,
            51..=100 => 100,
            101..=200 => 200,
            _ => 999,
        };
        *hist.entry(b).or_insert(0) += 1;
        let l: Vec<f64> = (0..4)
            .map(|s| {
                let a = pts[f[s] as usize];
                let b = pts[f[(s + 1) % 4] as usize];
                ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
            })
            .collect();
        let r = l.iter().cloned().fold(f64::MAX, f64::min) / l.iter().cloned().fold(0.0, f64::max);
        ratios.push(r);
    }
    ratios.sort_by(|a, b| a.partial_cmp(b).unwrap());
    println!("{name}: n {n} faces {} missed {nmiss}; ceiling-k histogram {:?}", mesh.quads.len(), hist);
    let q = |p: f64| ratios[((ratios.len() - 1) as f64 * p) as usize];
    println!(
        "edge ratio of missed: p10 {:.3} p25 {:.3} p50 {:.3} p75 {:.3} p90 {:.3}",
        q(0.1),
        q(0.25),
        q(0.5),
        q(0.75),
        q(0.9)
    );
    println!("below 0.1: {}", ratios.iter().filter(|&&r| r < 0.1).count());
}

fn envf(k: &str, d: f64) -> f64 {
    std::env::var(k).ok().and_then(|v| v.parse().ok()).unwrap_or(d)
}

fn sweep() {
    let files = mesh_files("train").unwrap();
    let mut cfg = CandidateConfig::default();
    cfg.k = envf("DK", cfg.k as f64) as usize;
    cfg.per_point = envf("DPP", cfg.per_point as f64) as usize;
    cfg.min_edge_ratio = envf("DR", cfg.min_edge_ratio as f64) as f32;
    cfg.max_edge_over_spacing = envf("DS", cfg.max_edge_over_spacing as f64) as f32;
    cfg.w_inside_first = envf("DWI1", cfg.w_inside_first as f64) as f32;
    cfg.w_inside = envf("DWI", cfg.w_inside as f64) as f32;
    cfg.w_length = envf("DWL", cfg.w_length as f64) as f32;
    cfg.w_shape = envf("DWS", cfg.w_shape as f64) as f32;
    let step = envf("DSTEP", 1.0) as usize;
    let mut out = String::new();
    for noisy in [false, true] {
        let mut all = Cov::default();
        let mut hh = Cov::default();
        for path in files.iter().step_by(step) {
            let mesh = load_quad_mesh(path);
            let pts = if noisy { noisy_cloud(&mesh, 1) } else { mesh.vertices.clone() };
            let (c, _) = coverage(&pts, &mesh.quads, &cfg);
            all.add(&c);
            if path.to_string_lossy().contains("hedgehog") {
                hh = c;
            }
        }
        out += &format!(
            "{} cov {:.4} ({:.4} w/o hedgehog) {:.2}/pt {:.1}s | ",
            if noisy { "N" } else { "C" },
            all.ratio(),
            (all.covered - hh.covered) as f64 / (all.faces - hh.faces) as f64,
            all.per_point(),
            all.secs
        );
    }
    println!("SWEEP {:?} {}", cfg, out);
}

fn losses() {
    use point2quad::mesh::postprocess::{postprocess, PostprocessConfig};
    use point2quad::pipeline::features::face_input;
    use point2quad::pipeline::model::Model;
    let model =
        Model::from_bytes(include_bytes!("../fixtures/point2quad-default.p2qm"), std::path::Path::new("m"))
            .unwrap();
    // Default: the validation split `train` holds out (by a hash of the sample name) —
    // the real meshes among its 23 validation samples.
    const VAL: [&str; 6] = [
        "thingi_113418",
        "thingi_129929",
        "thingi_1312954",
        "thingi_136243",
        "thingi_1450321",
        "thingi_49382",
    ];
    let mut files: Vec<_> = match std::env::var("DDIR") {
        Ok(dir) => std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().path()).collect(),
        Err(_) => mesh_files("train")
            .unwrap()
            .into_iter()
            .filter(|p| VAL.iter().any(|v| p.file_stem().is_some_and(|s| s == *v)))
            .collect(),
    };
    files.sort();
    let mut tot = [0usize; 10];
    for path in &files {
        let mesh = load_quad_mesh(path);
        let pts = noisy_cloud(&mesh, 1);
        let frame = point2quad::pipeline::frame::Frame::fit(&pts).unwrap();
        let local = frame.to_local_all(&pts);
        let c = point2quad::pipeline::candidates::generate(&local, &CandidateConfig::default()).unwrap();
        let x = face_input(&local, &c, model.config().use_context);
        let probs = model.predict(&x).unwrap();
        let gt: HashSet<[u32; 4]> = mesh.quads.iter().map(key).collect();
        let pmap: std::collections::HashMap<[u32; 4], f32> =
            c.quads.iter().zip(&probs).map(|(q, &p)| (key(q), p)).collect();
        let (faces, fp): (Vec<[u32; 4]>, Vec<f32>) =
            c.quads.iter().zip(&probs).filter(|(_, &p)| p > 0.5).map(|(q, &p)| (*q, p)).unzip();
        let (out, _) = postprocess(&pts, &faces, &fp, &PostprocessConfig::default()).unwrap();
        let outk: HashSet<[u32; 4]> = out.quads.iter().map(key).collect();
        let mut m = [0usize; 10];
        for f in &mesh.quads {
            let k = key(f);
            m[0] += 1;
            match pmap.get(&k) {
                None => m[1] += 1,
                Some(&p) if p <= 0.5 => {
                    m[2] += 1;
                    if outk.contains(&k) {
                        m[3] += 1;
                    }
                }
                Some(_) => {
                    if !outk.contains(&k) {
                        m[4] += 1;
                    }
                }
            }
            if outk.contains(&k) {
                m[5] += 1;
            }
        }
        let nv = pts.len() as u32;
        for q in &out.quads {
            let k = key(q);
            if gt.contains(&k) {
                continue;
            }
            m[6] += 1; // false positive
            if q.iter().any(|&v| v >= nv) {
                m[7] += 1;
            }
            // uses a new vertex
            else if !pmap.contains_key(&k) {
                m[8] += 1;
            }
            // hole fill from existing points, not a candidate
            else if pmap[&k] > 0.5 {
                m[9] += 1;
            } // predicted positive
        }
        println!("{:20} gt {} | notcand {} lowp {} (of which in output {}) highp-but-dropped {} | recovered {} || FP {} newvert {} fill-noncand {} predicted {} | out {}",
            path.file_stem().unwrap().to_string_lossy(), m[0], m[1], m[2], m[3], m[4], m[5], m[6], m[7], m[8], m[9], out.quads.len());
        for i in 0..10 {
            tot[i] += m[i];
        }
    }
    let r = |x: usize| x as f64 / tot[0] as f64;
    println!("TOTAL gt {} notcand {:.4} lowp {:.4} lowp-in-out {:.4} highp-dropped {:.4} recall {:.4} | FP/gt {:.4} newvert {:.4} fill-noncand {:.4} predicted {:.4}", tot[0], r(tot[1]), r(tot[2]), r(tot[3]), r(tot[4]), r(tot[5]), r(tot[6]), r(tot[7]), r(tot[8]), r(tot[9]));
}

fn main() {
    match std::env::args().nth(1).as_deref() {
        Some("ceilings") => ceilings(),
        Some("mesh") => one_mesh(),
        Some("sweep") => sweep(),
        Some("losses") => losses(),
        _ => eprintln!("usage: coverage_diagnostics ceilings|mesh|sweep|losses (see the file header)"),
    }
}
