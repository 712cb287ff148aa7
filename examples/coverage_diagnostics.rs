//! Candidate-coverage diagnostics behind "What we measured on the way" in docs/DETAILS.md
//! (issue 2) and the loss decomposition of issue 6. Prints tables; asserts nothing
//! (it is a measurement tool, not a test). `train/` only, or a folder you name:
//!
//! ```text
//! cargo run --release --example coverage_diagnostics -- ceilings        # DK=k (default 20)
//! DM=qm_hedgehog_spikes cargo run --release --example coverage_diagnostics -- mesh
//! DPP=64 DR=0.05 cargo run --release --example coverage_diagnostics -- sweep
//! [DDIR=/path/to/meshes] cargo run --release --example coverage_diagnostics -- losses
//! FNORM=0 FVAR=1 FK=64 FV=12 FT=30 cargo run --release --example coverage_diagnostics -- far
//! DM=qm_armadillo [DN=1] cargo run --release --example coverage_diagnostics -- ranks
//! [DM=name] cargo run --release --example coverage_diagnostics -- normals
//! [DM=name] cargo run --release --example coverage_diagnostics -- seams
//! [DM=name] cargo run --release --example coverage_diagnostics -- agreement
//! [DFP=4] cargo run --release --example coverage_diagnostics -- permesh
//! PC=1 PT=0.8 FK=64 PB=0 PK=8 cargo run --release --example coverage_diagnostics -- pgram
//! ```
//!
//! `sweep` reads CandidateConfig overrides from DK, DPP, DR, DS, DWI1, DWI, DWL, DWS,
//! DSN (min sine), DND (min normal dot), DNK (normal k), DSK (spacing k), DCR / DCS / DCI
//! (the continuation's rank, snap tolerance and steps); DM limits it
//! to the meshes whose name contains it.
//! `losses` splits the ground-truth faces of each mesh (10% noise) into: not a
//! candidate, candidate under the threshold, over it but dropped by the post-process,
//! recovered; and the output's false positives by origin. Run it on the validation
//! split of `train/` (never tune on `eval/`).
//! `far` measures what proposals beyond the k nearest could reach: "direction-diverse"
//! neighbours (of the FK nearest, by distance, each at least FT degrees from every
//! one taken before, at most FV; FNORM=1 also requires normal agreement and a small
//! elevation) and the ceilings of proposers that use them (C1: a corner with both
//! edge neighbours in kNN ∪ diverse, the diagonal in one of theirs; A' with FVAR=1:
//! a ∈ kNN(p), b diverse of p, x ∈ kNN(b); FVAR=2: all four edges in kNN ∪ diverse).
//! `ranks` prints the proposer rank, score and inside count of the true faces the
//! default budget drops. `normals` counts PCA normals more than 45° off the ground
//! truth (and, of the others, those whose sign is wrong, and the ground-truth edges
//! between a right and a wrong sign: orientation seams), and the missed faces that
//! touch one. `seams` counts pairs of adjacent true faces whose candidates run their
//! shared edge the same way, and how many the normals rule of the refinement reads
//! right. `agreement`: the true candidates with a corner normal against the face.

#[path = "../tests/common/candidates.rs"]
mod cands_common;
use cands_common::*;
use point2quad::pipeline::candidates::{knn_table, CandidateConfig, Candidates};
use point2quad::pipeline::refine::{opposite_normals, quad_normal};
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

/// Per `train/` mesh: faces, and the true faces missed clean and with 10% noise, split by
/// whether some corner has the other three among its 20 nearest (proposable: lost to a
/// filter or the ranking) or not (beyond the kNN proposal).
fn per_mesh() {
    let files = mesh_files("train").unwrap();
    let cfg = cfg_from_env();
    let mut tot = [0usize; 5];
    println!("mesh faces | clean missed (proposable) | noisy missed (proposable)");
    for path in &files {
        let mesh = load_quad_mesh(path);
        let mut row = [mesh.quads.len(), 0, 0, 0, 0];
        for (s, noisy) in [false, true].into_iter().enumerate() {
            let pts = if noisy { noisy_cloud(&mesh, 1) } else { mesh.vertices.clone() };
            let (_, c) = coverage(&pts, &mesh.quads, &cfg);
            let have: HashSet<[u32; 4]> = c.quads.iter().map(key).collect();
            let frame = point2quad::pipeline::frame::Frame::fit(&pts).unwrap();
            let local = frame.to_local_all(&pts);
            let knn = knn_table(&local, cfg.k);
            let sets: Vec<HashSet<u32>> =
                (0..local.len()).map(|i| kset(&knn, i, cfg.k).into_iter().collect()).collect();
            for f in mesh.quads.iter().filter(|f| !have.contains(&key(f))) {
                row[1 + 2 * s] += 1;
                if (0..4).any(|x| (1..4).all(|d| sets[f[x] as usize].contains(&f[(x + d) % 4]))) {
                    row[2 + 2 * s] += 1;
                }
            }
        }
        let name = path.file_stem().unwrap().to_string_lossy();
        println!("{name} {} | {} ({}) | {} ({})", row[0], row[1], row[2], row[3], row[4]);
        for (t, r) in tot.iter_mut().zip(row) {
            *t += r;
        }
    }
    println!("TOTAL {} | {} ({}) | {} ({})", tot[0], tot[1], tot[2], tot[3], tot[4]);
}

/// The prototype's direction-diverse neighbours of point `i` from its kNN row `idx`
/// (nearest first): each at a cosine under `cos_t` with every one taken before, at most
/// `v`, duplicates of `i` skipped; with their unit directions.
fn diverse_of(local: &[[f32; 3]], idx: &[u32], i: u32, v: usize, cos_t: f32) -> Vec<(u32, [f32; 3])> {
    let p = local[i as usize];
    let mut div: Vec<(u32, [f32; 3])> = vec![];
    for &j in idx {
        if j == i || div.len() >= v {
            continue;
        }
        let q = local[j as usize];
        let d = [q[0] - p[0], q[1] - p[1], q[2] - p[2]];
        let dl = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        if dl == 0.0 {
            continue;
        }
        let t = [d[0] / dl, d[1] / dl, d[2] / dl];
        if div.iter().all(|(_, r)| r[0] * t[0] + r[1] * t[1] + r[2] * t[2] < cos_t) {
            div.push((j, t));
        }
    }
    div
}

/// The prototype's shape filters on the quad `q`: 0 when its edge ratio is at most
/// `rmin`, 1 when a corner's sine is under the config's, 2 when two corner normals
/// disagree beyond the config's dot, 3 when it passes; with its edge vectors and lengths.
fn shape_stage(
    local: &[[f32; 3]],
    q: [u32; 4],
    rmin: f32,
    cfg: &CandidateConfig,
) -> (u8, [[f32; 3]; 4], [f32; 4]) {
    let sub3 = |a: [f32; 3], b: [f32; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let crs = |a: [f32; 3], b: [f32; 3]| {
        [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
    };
    let dt = |a: [f32; 3], b: [f32; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let qp = q.map(|k| local[k as usize]);
    let ev: [[f32; 3]; 4] = std::array::from_fn(|s| sub3(qp[(s + 1) % 4], qp[s]));
    let len = ev.map(|e| dt(e, e).sqrt());
    let lmin = len.iter().copied().fold(f32::INFINITY, f32::min);
    let lmax = len.iter().copied().fold(0.0, f32::max);
    if lmin.is_nan() || lmin <= rmin * lmax {
        return (0, ev, len);
    }
    let mut cn = [[0f32; 3]; 4];
    for s in 0..4 {
        let cc = crs(ev[(s + 3) % 4], ev[s]);
        let cl = dt(cc, cc).sqrt();
        let sine = cl / (len[(s + 3) % 4] * len[s]);
        if sine.is_nan() || sine < cfg.min_sine {
            return (1, ev, len);
        }
        cn[s] = [cc[0] / cl, cc[1] / cl, cc[2] / cl];
    }
    let agree = (0..4).all(|s| (0..s).all(|t| dt(cn[s], cn[t]) >= cfg.min_normal_dot));
    (if agree { 3 } else { 2 }, ev, len)
}

/// Prototype of the far completion (the module header's `pgram`): parallelogram
/// completion from a near neighbour a and a direction-diverse b, x among b's nearest.
fn pgram() {
    let files = mesh_files("train").unwrap();
    let cfg = cfg_from_env();
    let ka = envf("PA", 8.0) as usize;
    let kf = envf("FK", 64.0) as usize;
    let v = envf("FV", 12.0) as usize;
    let cos_t = (envf("FT", 30.0) as f32).to_radians().cos();
    let tau = envf("PT", 0.5) as f32;
    let rmin = envf("PR", 0.03) as f32;
    let keepn = envf("PK", 8.0) as usize;
    let only = std::env::var("DM").unwrap_or_default();
    let verbose = envf("PV", 0.0) > 0.0;
    let curve = envf("PC", 0.0) > 0.0;
    for noisy in [false, true] {
        let mut curve_acc = [(0usize, 0usize); 9];
        let (mut faces, mut cov0, mut cov1, mut nc0, mut nc1, mut npts) =
            (0usize, 0usize, 0usize, 0usize, 0usize, 0usize);
        for path in files.iter().filter(|p| p.to_string_lossy().contains(&only)) {
            let mesh = load_quad_mesh(path);
            let pts = if noisy { noisy_cloud(&mesh, 1) } else { mesh.vertices.clone() };
            let (c0, c) = coverage(&pts, &mesh.quads, &cfg);
            let frame = point2quad::pipeline::frame::Frame::fit(&pts).unwrap();
            let local = frame.to_local_all(&pts);
            let n = local.len();
            let knn = knn_table(&local, kf);
            let mut have: HashSet<[u32; 4]> = c.quads.iter().map(key).collect();
            let main_keys = have.clone();
            let mut lists: Vec<Vec<[u32; 4]>> = vec![];
            let base = have.len();
            let sub3 = |a: [f32; 3], b: [f32; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
            let crs = |a: [f32; 3], b: [f32; 3]| {
                [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
            };
            let dt = |a: [f32; 3], b: [f32; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
            let nrm = |a: [f32; 3]| dt(a, a).sqrt();
            for i in 0..n {
                let (idx, _) = knn.row(i);
                let p = local[i];
                let near: Vec<u32> = idx.iter().copied().filter(|&j| j as usize != i).take(ka).collect();
                let div = diverse_of(&local, idx, i as u32, v, cos_t);
                let mut found: Vec<(f32, [u32; 4])> = vec![];
                let pb_n = envf("PB", 0.0) as usize;
                let mut bs: Vec<u32> = vec![];
                for &(b0, _) in &div {
                    if !bs.contains(&b0) {
                        bs.push(b0);
                    }
                    if near.contains(&b0) {
                        continue;
                    }
                    let (bidx, _) = knn.row(b0 as usize);
                    for &bb in bidx.iter().filter(|&&j| j != b0 && j as usize != i).take(pb_n) {
                        if !bs.contains(&bb) {
                            bs.push(bb);
                        }
                    }
                }
                for &a in &near {
                    for &b in &bs {
                        if a == b {
                            continue;
                        }
                        let (pa, pb) = (local[a as usize], local[b as usize]);
                        let la = nrm(sub3(pa, p));
                        let lb = nrm(sub3(pb, p));
                        let ua = sub3(pa, p).map(|c| c / la);
                        let ub = sub3(pb, p).map(|c| c / lb);
                        // x: of b's near neighbours, the one whose sides best parallel p's
                        let mut bestx = None;
                        let mut bests = -1.0f32;
                        let (bidx, _) = knn.row(b as usize);
                        for &x in bidx.iter().filter(|&&j| j != b).take(ka) {
                            if x as usize == i || x == a {
                                continue;
                            }
                            let px = local[x as usize];
                            let (dxb, dxa) = (sub3(px, pb), sub3(px, pa));
                            let (lxb, lxa) = (nrm(dxb), nrm(dxa));
                            if lxb == 0.0 || lxa == 0.0 {
                                continue;
                            }
                            let c1 = dt(dxb, ua) / lxb;
                            let c2 = dt(dxa, ub) / lxa;
                            if c1.min(c2) > bests {
                                bests = c1.min(c2);
                                bestx = Some(x);
                            }
                        }
                        let Some(x) = bestx else { continue };
                        if bests < tau {
                            continue;
                        }
                        let off = 1.0 - bests;
                        let q = [i as u32, a, x, b];
                        let qp = q.map(|k| local[k as usize]);
                        let (passed, ev, len) = shape_stage(&local, q, rmin, &cfg);
                        if passed < 3 {
                            continue;
                        }
                        // points inside the quad (plane tolerance, edge margin)
                        let nd = crs(sub3(qp[2], qp[0]), sub3(qp[3], qp[1]));
                        let nl = nrm(nd);
                        if nl == 0.0 {
                            continue;
                        }
                        let nq = nd.map(|c| c / nl);
                        let lbar = (len[0] + len[1] + len[2] + len[3]) / 4.0;
                        let ptol = envf("PPT", 0.3) as f32 * lbar;
                        let marg = envf("PM", 0.05) as f32 * lbar;
                        let mut inside = 0;
                        for &y in idx {
                            if q.contains(&y) {
                                continue;
                            }
                            let py = local[y as usize];
                            if dt(sub3(py, qp[0]), nq).abs() > ptol {
                                continue;
                            }
                            if (0..4).all(|s| dt(crs(ev[s], sub3(py, qp[s])), nq) / len[s] >= -marg) {
                                inside += 1;
                            }
                        }
                        let wi = envf("PWI", 1.0) as f32;
                        found.push((off + wi * inside as f32, q));
                    }
                }
                found.sort_by(|x, y| x.0.total_cmp(&y.0));
                if envf("PD", -1.0) == i as f64 {
                    let gt: HashSet<[u32; 4]> = mesh.quads.iter().map(key).collect();
                    for (r, (sc, q)) in found.iter().enumerate() {
                        if r < 15 || gt.contains(&key(q)) {
                            let l: Vec<String> = (0..4)
                                .map(|s| {
                                    format!(
                                        "{:.4}",
                                        nrm(sub3(local[q[(s + 1) % 4] as usize], local[q[s] as usize]))
                                    )
                                })
                                .collect();
                            println!(
                                "  rank {r} score {sc:.3} {:?} {} len {:?}",
                                q,
                                if gt.contains(&key(q)) { "TRUE" } else { "" },
                                l
                            );
                        }
                    }
                }
                let gate = envf("PG", f64::INFINITY) as f32;
                let mut kept = 0;
                let mut list = vec![];
                for (sc, q) in found {
                    if sc > gate || list.len() >= 64 {
                        break;
                    }
                    let kq = key(&q);
                    if main_keys.contains(&kq) || list.contains(&kq) {
                        continue;
                    }
                    list.push(kq);
                    if kept < keepn {
                        have.insert(kq);
                        kept += 1;
                    }
                }
                lists.push(list);
            }
            if curve {
                let gt: HashSet<[u32; 4]> = mesh.quads.iter().map(key).collect();
                for (ci, kk) in [1usize, 2, 4, 8, 12, 16, 24, 32, 64].into_iter().enumerate() {
                    let mut set: HashSet<[u32; 4]> = HashSet::new();
                    for l in &lists {
                        set.extend(l.iter().take(kk).copied());
                    }
                    let extra_true = set.iter().filter(|q| gt.contains(*q)).count();
                    curve_acc[ci].0 += extra_true;
                    curve_acc[ci].1 += set.len();
                }
            }
            let cov = mesh.quads.iter().filter(|f| have.contains(&key(f))).count();
            if verbose {
                // why the missed faces were not proposed: best stage over corners and turns
                let mut why = [0usize; 9];
                for f in mesh.quads.iter().filter(|f| !have.contains(&key(f))) {
                    let mut best = 0;
                    for s in 0..4 {
                        for dir in 0..2 {
                            let (pp, mut a, x, mut b) =
                                (f[s], f[(s + 1) % 4], f[(s + 2) % 4], f[(s + 3) % 4]);
                            if dir == 1 {
                                std::mem::swap(&mut a, &mut b);
                            }
                            let (idx, _) = knn.row(pp as usize);
                            let near: Vec<u32> = idx.iter().copied().filter(|&j| j != pp).take(ka).collect();
                            let inf = idx.contains(&b);
                            let mut stage = 0;
                            if near.contains(&a) {
                                stage = 1;
                                if inf {
                                    stage = 2;
                                    let (bidx, _) = knn.row(b as usize);
                                    if bidx.iter().filter(|&&j| j != b).take(ka).any(|&j| j == x) {
                                        stage = 4;
                                        // diverse?
                                        let dv = diverse_of(&local, idx, pp, v, cos_t);
                                        if dv.iter().any(|&(j, _)| j == b) {
                                            let (passed, _, _) =
                                                shape_stage(&local, [pp, a, x, b], rmin, &cfg);
                                            stage = 5 + passed as usize;
                                        }
                                    }
                                }
                            }
                            best = best.max(stage);
                        }
                    }
                    why[best] += 1;
                }
                println!("  missed: a not near {} | b beyond FK {} | x not in b's near {} | - {} | b not diverse {} | ratio {} | sine {} | normals {} | ranked out/x not best {}", why[0], why[1], why[2], why[3], why[4], why[5], why[6], why[7], why[8]);
                println!(
                    "{} {} {} -> {} ({:.2} -> {:.2}/pt)",
                    path.file_stem().unwrap().to_string_lossy(),
                    mesh.quads.len(),
                    c0.covered,
                    cov,
                    base as f64 / n as f64,
                    have.len() as f64 / n as f64
                );
            }
            faces += mesh.quads.len();
            cov0 += c0.covered;
            cov1 += cov;
            nc0 += base;
            nc1 += have.len();
            npts += n;
        }
        println!(
            "{} coverage {:.4} -> {:.4}; per point {:.2} -> {:.2}",
            if noisy { "noisy" } else { "clean" },
            cov0 as f64 / faces as f64,
            cov1 as f64 / faces as f64,
            nc0 as f64 / npts as f64,
            nc1 as f64 / npts as f64
        );
        if curve {
            for (ci, kk) in [1usize, 2, 4, 8, 12, 16, 24, 32, 64].into_iter().enumerate() {
                println!(
                    "  keep {kk:2}: coverage {:.4} per point {:.2}",
                    (cov0 + curve_acc[ci].0) as f64 / faces as f64,
                    (nc0 + curve_acc[ci].1) as f64 / npts as f64
                );
            }
        }
    }
}

fn envf(k: &str, d: f64) -> f64 {
    std::env::var(k).ok().and_then(|v| v.parse().ok()).unwrap_or(d)
}

fn cfg_from_env() -> CandidateConfig {
    let mut cfg = CandidateConfig::default();
    cfg.k = envf("DK", cfg.k as f64) as usize;
    cfg.per_point = envf("DPP", cfg.per_point as f64) as usize;
    cfg.min_edge_ratio = envf("DR", cfg.min_edge_ratio as f64) as f32;
    cfg.max_edge_over_spacing = envf("DS", cfg.max_edge_over_spacing as f64) as f32;
    cfg.w_inside_first = envf("DWI1", cfg.w_inside_first as f64) as f32;
    cfg.w_inside = envf("DWI", cfg.w_inside as f64) as f32;
    cfg.w_length = envf("DWL", cfg.w_length as f64) as f32;
    cfg.w_shape = envf("DWS", cfg.w_shape as f64) as f32;
    cfg.min_sine = envf("DSN", cfg.min_sine as f64) as f32;
    cfg.min_normal_dot = envf("DND", cfg.min_normal_dot as f64) as f32;
    cfg.normal_k = envf("DNK", cfg.normal_k as f64) as usize;
    cfg.spacing_k = envf("DSK", cfg.spacing_k as f64) as usize;
    cfg.continue_rank = envf("DCR", cfg.continue_rank as f64) as u16;
    cfg.continue_snap = envf("DCS", cfg.continue_snap as f64) as f32;
    cfg.continue_steps = envf("DCI", cfg.continue_steps as f64) as usize;
    cfg.far_per_point = envf("DFP", cfg.far_per_point as f64) as usize;
    cfg.far_k = envf("DFK", cfg.far_k as f64) as usize;
    cfg
}

fn sweep() {
    let files = mesh_files("train").unwrap();
    let cfg = cfg_from_env();
    let step = envf("DSTEP", 1.0) as usize;
    let only = std::env::var("DM").unwrap_or_default();
    let mut out = String::new();
    for noisy in [false, true] {
        let mut all = Cov::default();
        let mut hh = Cov::default();
        for path in files.iter().step_by(step).filter(|p| p.to_string_lossy().contains(&only)) {
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
    let model = Model::shipped().unwrap();
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

/// Visible neighbours of every point: among its `kf` nearest, by distance, those
/// with an agreeing normal and a small elevation whose tangent direction is at least
/// `theta` from every nearer accepted one, at most `v` of them.
fn visible(local: &[[f32; 3]], normals: &[[f32; 3]], kf: usize, v: usize, cos_t: f32) -> Vec<Vec<u32>> {
    let knn = knn_table(local, kf);
    let use_normals = envf("FNORM", 1.0) > 0.0;
    (0..local.len())
        .map(|i| {
            let (idx, _) = knn.row(i);
            let n = normals[i];
            let mut acc: Vec<(u32, [f32; 3])> = vec![];
            for &j in idx {
                if j as usize == i || acc.len() >= v {
                    continue;
                }
                let q = local[j as usize];
                let d = [q[0] - local[i][0], q[1] - local[i][1], q[2] - local[i][2]];
                let dl = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                let nq = normals[j as usize];
                if dl == 0.0 {
                    continue;
                }
                if !use_normals {
                    let t = [d[0] / dl, d[1] / dl, d[2] / dl];
                    if acc.iter().all(|(_, r)| r[0] * t[0] + r[1] * t[1] + r[2] * t[2] < cos_t) {
                        acc.push((j, t));
                    }
                    continue;
                }
                if n[0] * nq[0] + n[1] * nq[1] + n[2] * nq[2] < 0.5 {
                    continue;
                }
                let e = d[0] * n[0] + d[1] * n[1] + d[2] * n[2];
                if e.abs() > 0.5 * dl {
                    continue;
                }
                let t = [d[0] - e * n[0], d[1] - e * n[1], d[2] - e * n[2]];
                let tl = (t[0] * t[0] + t[1] * t[1] + t[2] * t[2]).sqrt();
                let t = [t[0] / tl, t[1] / tl, t[2] / tl];
                if acc.iter().all(|(_, r)| r[0] * t[0] + r[1] * t[1] + r[2] * t[2] < cos_t) {
                    acc.push((j, t));
                }
            }
            acc.into_iter().map(|(j, _)| j).collect()
        })
        .collect()
}

fn far_ceilings() {
    let files = mesh_files("train").unwrap();
    let cfg = CandidateConfig::default();
    let kf = envf("FK", 64.0) as usize;
    let v = envf("FV", 8.0) as usize;
    let theta = envf("FT", 40.0) as f32;
    let cos_t = theta.to_radians().cos();
    for noisy in [false, true] {
        let mut t = [0usize; 6];
        let (mut sizes, mut npts) = (0usize, 0usize);
        for path in &files {
            let mesh = load_quad_mesh(path);
            let pts = if noisy { noisy_cloud(&mesh, 1) } else { mesh.vertices.clone() };
            let (_, c) = coverage(&pts, &mesh.quads, &cfg);
            let have: HashSet<[u32; 4]> = c.quads.iter().map(key).collect();
            let frame = point2quad::pipeline::frame::Frame::fit(&pts).unwrap();
            let local = frame.to_local_all(&pts);
            let n = local.len();
            let knn = knn_table(&local, cfg.k);
            let kn: Vec<HashSet<u32>> = (0..n).map(|i| kset(&knn, i, cfg.k).into_iter().collect()).collect();
            let vis = visible(&local, &c.normals, kf, v, cos_t);

            let vn: Vec<HashSet<u32>> = vis.iter().map(|x| x.iter().copied().collect()).collect();
            let k12n = envf("FK12", 12.0) as usize;
            let k12: Vec<HashSet<u32>> = (0..n).map(|i| kset(&knn, i, k12n).into_iter().collect()).collect();
            sizes += (0..n).map(|i| k12[i].union(&vn[i]).count()).sum::<usize>();
            npts += n;
            let inn = |a: u32, b: u32| kn[a as usize].contains(&b) || vn[a as usize].contains(&b);
            let edge = |a: u32, b: u32| inn(a, b) || inn(b, a);
            let mut m = [0usize; 6];
            for f in &mesh.quads {
                m[0] += 1;
                let covered = have.contains(&key(f));
                m[1] += covered as usize;
                let a = (0..4).any(|s| (1..4).all(|d| kn[f[s] as usize].contains(&f[(s + d) % 4])));
                let b = (0..4).all(|s| edge(f[s], f[(s + 1) % 4]));
                // proposer p with both edge neighbours in N(p), diagonal in N(a) ∪ N(b)
                let c1 = (0..4).any(|s| {
                    let (p, a, x, b) = (f[s], f[(s + 1) % 4], f[(s + 2) % 4], f[(s + 3) % 4]);
                    inn(p, a) && inn(p, b) && (inn(a, x) || inn(b, x))
                });
                // V: (env FVAR) 1: a ∈ kNN(p), b ∈ VN(p), x ∈ kNN(b); 2: a, b ∈ N(p), x ∈ N(a) ∩ N(b)
                let var = envf("FVAR", 2.0) as usize;
                let vb = (0..4).any(|s| {
                    (0..2).any(|dir| {
                        let (p, mut a, x, mut b) = (f[s], f[(s + 1) % 4], f[(s + 2) % 4], f[(s + 3) % 4]);
                        if dir == 1 {
                            std::mem::swap(&mut a, &mut b);
                        }
                        match var {
                            1 => {
                                kn[p as usize].contains(&a)
                                    && vn[p as usize].contains(&b)
                                    && kn[b as usize].contains(&x)
                            }
                            _ => inn(p, a) && inn(p, b) && inn(a, x) && inn(b, x),
                        }
                    })
                });
                m[2] += a as usize;
                m[3] += (a || b) as usize;
                m[4] += (a || c1) as usize;
                m[5] += (a || vb) as usize;
            }
            let r = |x: usize| x as f64 / m[0] as f64;
            println!(
                "{:28} {} cov {:.4} A {:.4} AorB' {:.4} AorC1 {:.4} A' {:.4}",
                path.file_stem().unwrap().to_string_lossy(),
                if noisy { "N" } else { "C" },
                r(m[1]),
                r(m[2]),
                r(m[3]),
                r(m[4]),
                r(m[5])
            );
            for i in 0..6 {
                t[i] += m[i];
            }
        }
        let r = |x: usize| x as f64 / t[0] as f64;
        println!(
            "TOTAL {} FK {kf} FV {v} FT {theta} cov {:.4} A {:.4} AorB' {:.4} AorC1 {:.4} A' {:.4} (|N'| {:.1})",
            if noisy { "N" } else { "C" },
            r(t[1]),
            r(t[2]),
            r(t[3]),
            r(t[4]),
            r(t[5]),
            sizes as f64 / npts as f64
        );
    }
}

/// Rank, score and inside count of the true faces that the default budget drops
/// (DM = mesh name, DN = 1 for the noisy cloud).
fn ranks() {
    let name = std::env::var("DM").unwrap_or("qm_armadillo".into());
    let files = mesh_files("train").unwrap();
    let path = files.iter().find(|p| p.to_string_lossy().contains(&name)).unwrap();
    let mesh = load_quad_mesh(path);
    let pts = if envf("DN", 0.0) > 0.0 { noisy_cloud(&mesh, 1) } else { mesh.vertices.clone() };
    let cfg = CandidateConfig::default();
    let (_, c) = coverage(&pts, &mesh.quads, &cfg);
    let have: HashSet<[u32; 4]> = c.quads.iter().map(key).collect();
    let mut all = cfg.clone();
    all.per_point = point2quad::pipeline::candidates::MAX_PER_POINT;
    let (_, ca) = coverage(&pts, &mesh.quads, &all);
    let idx: std::collections::HashMap<[u32; 4], usize> =
        ca.quads.iter().enumerate().map(|(i, q)| (key(q), i)).collect();
    let mut hist = std::collections::BTreeMap::new();
    let mut shown = 0;
    let mut nins = [0usize; 4];
    for f in &mesh.quads {
        if have.contains(&key(f)) {
            continue;
        }
        let Some(&i) = idx.get(&key(f)) else {
            *hist.entry(99999).or_insert(0) += 1;
            continue;
        };
        let r = ca.rank[i] as usize;
        let b = [32, 48, 64, 96, 128, 256, 512, 99998].into_iter().find(|&b| r < b).unwrap();
        *hist.entry(b).or_insert(0) += 1;
        nins[(ca.inside[i] as usize).min(3)] += 1;
        if shown < 12 {
            shown += 1;
            let l: Vec<f64> = (0..4)
                .map(|s| {
                    let a = pts[f[s] as usize];
                    let b = pts[f[(s + 1) % 4] as usize];
                    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
                })
                .collect();
            let sp: Vec<f32> = f.iter().map(|&v| ca.spacing[v as usize]).collect();
            println!(
                "missed rank {r} score {:.3} inside {} proposers {} len {:.3?} spacing {:.3?}",
                ca.score[i], ca.inside[i], ca.proposers[i], l, sp
            );
        }
    }
    println!("{name}: rank histogram of missed (99999 = not proposable) {hist:?}; inside 0/1/2/3+ {nins:?}");
}

/// Runs `f` on every `train/` mesh whose name contains `DM` (all when unset) with its
/// candidates over the clean cloud of its vertices (config from the environment).
fn each_train_mesh(mut f: impl FnMut(&str, &point2quad::mesh::poly::QuadMesh, &Candidates)) {
    let only = std::env::var("DM").unwrap_or_default();
    let cfg = cfg_from_env();
    for path in mesh_files("train").unwrap().iter().filter(|p| p.to_string_lossy().contains(&only)) {
        let mesh = load_quad_mesh(path);
        let (_, c) = coverage(&mesh.vertices, &mesh.quads, &cfg);
        f(&path.file_stem().unwrap().to_string_lossy(), &mesh, &c);
    }
}

/// Share of points whose PCA normal is off the ground-truth vertex normal (area
/// weighted face normals) by more than 45°, and how the missed faces split by it
/// (DM = mesh name, all meshes when unset).
fn normals_check() {
    each_train_mesh(|name, mesh, c| {
        let pts = mesh.vertices.clone();
        let have: HashSet<[u32; 4]> = c.quads.iter().map(key).collect();
        let mut gn = vec![[0.0f64; 3]; pts.len()];
        for f in &mesh.quads {
            let d1: Vec<f64> = (0..3).map(|a| pts[f[2] as usize][a] - pts[f[0] as usize][a]).collect();
            let d2: Vec<f64> = (0..3).map(|a| pts[f[3] as usize][a] - pts[f[1] as usize][a]).collect();
            let n =
                [d1[1] * d2[2] - d1[2] * d2[1], d1[2] * d2[0] - d1[0] * d2[2], d1[0] * d2[1] - d1[1] * d2[0]];
            for &v in f {
                for a in 0..3 {
                    gn[v as usize][a] += n[a];
                }
            }
        }
        // The frame is a similarity: map the GT normal's tip through it and compare
        // directions (|cos|, the PCA sign is not the point here).
        let frame = point2quad::pipeline::frame::Frame::fit(&pts).unwrap();
        // Per point: the cosine of the GT normal (in the cloud's frame) with the PCA one.
        let cos: Vec<f64> = (0..pts.len())
            .map(|i| {
                let g = [pts[i][0] + gn[i][0], pts[i][1] + gn[i][1], pts[i][2] + gn[i][2]];
                let gl = frame.to_local_all(&[g, pts[i]]);
                let d: Vec<f64> = (0..3).map(|a| (gl[0][a] - gl[1][a]) as f64).collect();
                let dl = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                let n = c.normals[i];
                let dot = d[0] * n[0] as f64 + d[1] * n[1] as f64 + d[2] * n[2] as f64;
                if dl == 0.0 {
                    0.0
                } else {
                    dot / dl
                }
            })
            .collect();
        let bad: Vec<bool> = cos.iter().map(|c| c.abs() < std::f64::consts::FRAC_1_SQRT_2).collect();
        let nb = bad.iter().filter(|&&b| b).count();
        // Signed: well-aligned normals (|cos| ≥ 0.707) that point the wrong way.
        let flipped: Vec<bool> = (0..pts.len()).map(|i| !bad[i] && cos[i] < 0.0).collect();
        let nf = flipped.iter().filter(|&&b| b).count();
        // Orientation seams: GT edges between two well-aligned normals of which exactly one is flipped.
        let (mut seams, mut edges) = (0usize, 0usize);
        for f in &mesh.quads {
            for e in 0..4 {
                let (u, v) = (f[e] as usize, f[(e + 1) % 4] as usize);
                if !bad[u] && !bad[v] {
                    edges += 1;
                    seams += (flipped[u] != flipped[v]) as usize;
                }
            }
        }
        let nf_seam = seams as f64 / edges.max(1) as f64;
        let (mut missed, mut missed_bad) = (0, 0);
        for f in &mesh.quads {
            if !have.contains(&key(f)) {
                missed += 1;
                missed_bad += f.iter().any(|&v| bad[v as usize]) as usize;
            }
        }
        println!(
            "{:28} points {} bad normals {:.4} flipped {:.4} seam-edges {:.4} | missed faces {} of which with a bad-normal corner {}",
            name,
            pts.len(),
            nb as f64 / pts.len() as f64,
            nf as f64 / pts.len() as f64,
            nf_seam,
            missed,
            missed_bad
        );
    });
}

/// Orientation seams among candidates: pairs of ground-truth faces sharing an edge,
/// both candidates, whose candidate orders run the shared edge the same way (a
/// consistently oriented pair runs it both ways), and how many of those a comparison
/// of the two candidates' own normals (|n_c·n_d| ≥ 0.5) would read correctly.
fn seams() {
    each_train_mesh(|name, mesh, c| {
        let pts = mesh.vertices.clone();
        let mut ord: std::collections::HashMap<[u32; 4], [u32; 4]> = Default::default();
        for q in &c.quads {
            ord.insert(key(q), *q);
        }
        let pts32 = to_f32(&pts);
        let nrm = |q: &[u32; 4]| quad_normal(&pts32, *q);
        let mut by_edge: std::collections::HashMap<(u32, u32), Vec<[u32; 4]>> = Default::default();
        for f in &mesh.quads {
            if let Some(q) = ord.get(&key(f)) {
                for i in 0..4 {
                    let (a, b) = (q[i], q[(i + 1) % 4]);
                    by_edge.entry((a.min(b), a.max(b))).or_default().push(*q);
                }
            }
        }
        let (mut pairs, mut seam, mut seam_fix, mut ok_broken, mut ambiguous) = (0, 0, 0, 0, 0);
        for ((a, b), qs) in &by_edge {
            if qs.len() != 2 {
                continue;
            }
            pairs += 1;
            let dir = |q: &[u32; 4]| (0..4).any(|i| q[i] == *a && q[(i + 1) % 4] == *b);
            let same = dir(&qs[0]) == dir(&qs[1]);
            let (x, y) = (nrm(&qs[0]), nrm(&qs[1]));
            let opposite = opposite_normals(x, y);
            if (x[0] * y[0] + x[1] * y[1] + x[2] * y[2]).abs() < 0.5 {
                ambiguous += 1;
            }
            if same {
                seam += 1;
                seam_fix += opposite as usize;
            } else {
                ok_broken += opposite as usize;
            }
        }
        println!(
            "{:28} adjacent true pairs {pairs} seams {seam} ({:.4}) fixed by normals {seam_fix} | consistent pairs the rule would break {ok_broken} | |dot|<0.5 {ambiguous}",
            name,
            seam as f64 / pairs.max(1) as f64
        );
    });
}

/// Corner-normal agreement of the true faces among the candidates: the share whose
/// smallest dot of a corner's (oriented) PCA normal with the face normal from the
/// candidate's order is negative (a corner across an orientation seam), below 0.5, and
/// the same with |dot| (what a sign-free reading would see).
fn agreement() {
    each_train_mesh(|name, mesh, c| {
        let pts = mesh.vertices.clone();
        let truth: HashSet<[u32; 4]> = mesh.quads.iter().map(key).collect();
        let local = point2quad::pipeline::frame::Frame::fit(&pts).unwrap().to_local_all(&pts);
        let (mut n, mut neg, mut low, mut low_abs) = (0usize, 0usize, 0usize, 0usize);
        for q in c.quads.iter().filter(|q| truth.contains(&key(q))) {
            let f = quad_normal(&local, *q);
            let dots: Vec<f32> = q
                .iter()
                .map(|&v| {
                    let m = c.normals[v as usize];
                    m[0] * f[0] + m[1] * f[1] + m[2] * f[2]
                })
                .collect();
            let mn = dots.iter().copied().fold(f32::INFINITY, f32::min);
            let mna = dots.iter().map(|d| d.abs()).fold(f32::INFINITY, f32::min);
            n += 1;
            neg += (mn < 0.0) as usize;
            low += (mn < 0.5) as usize;
            low_abs += (mna < 0.5) as usize;
        }
        println!(
            "{:28} true candidates {n} min corner dot < 0: {:.4}  < 0.5: {:.4}  |dot| < 0.5: {:.4}",
            name,
            neg as f64 / n.max(1) as f64,
            low as f64 / n.max(1) as f64,
            low_abs as f64 / n.max(1) as f64
        );
    });
}

fn main() {
    match std::env::args().nth(1).as_deref() {
        Some("ceilings") => ceilings(),
        Some("mesh") => one_mesh(),
        Some("sweep") => sweep(),
        Some("permesh") => per_mesh(),
        Some("pgram") => pgram(),
        Some("losses") => losses(),
        Some("far") => far_ceilings(),
        Some("ranks") => ranks(),
        Some("normals") => normals_check(),
        Some("seams") => seams(),
        Some("agreement") => agreement(),
        Some("grow") => grow(),
        _ => eprintln!("usage: coverage_diagnostics ceilings|mesh|sweep|losses (see the file header)"),
    }
}

/// `grow`: lattice continuation. From seed candidates, the quad across each side a → b
/// of a seed (a, b, c, d) is predicted by parallelogram: a' = a + (a − d), b' = b + (b − c),
/// each snapped to its nearest point when within GT × the side length; repeated GI
/// times from the new quads. Seeds: GS=all (every candidate), gt (only true faces: the
/// ceiling of continuing from accepted faces), rank (candidates of rank < GR).
fn grow() {
    use point2quad::spatial::kdtree::KdTree;
    let files = mesh_files("train").unwrap();
    let cfg = CandidateConfig::default();
    let env = |k: &str, d: f32| std::env::var(k).ok().and_then(|v| v.parse().ok()).unwrap_or(d);
    let tol = env("GT", 0.3);
    let iters = env("GI", 3.0) as usize;
    let rank_lim = env("GR", 4.0) as u16;
    let seeds = std::env::var("GS").unwrap_or_else(|_| "all".into());
    let dm = std::env::var("DM").ok();
    for noisy in [false, true] {
        let (mut faces, mut before, mut after, mut pts_n, mut cands, mut added) =
            (0usize, 0usize, 0usize, 0usize, 0usize, 0usize);
        for path in &files {
            let name = path.file_stem().unwrap().to_string_lossy().to_string();
            if dm.as_ref().is_some_and(|d| !name.contains(d.as_str())) {
                continue;
            }
            let mesh = load_quad_mesh(path);
            let pts = if noisy { noisy_cloud(&mesh, 1) } else { mesh.vertices.clone() };
            let (cov, c) = coverage(&pts, &mesh.quads, &cfg);
            let frame = point2quad::pipeline::frame::Frame::fit(&pts).unwrap();
            let local = frame.to_local_all(&pts);
            let tree = KdTree::build(&local);
            let gt: HashSet<[u32; 4]> = mesh.quads.iter().map(key).collect();
            let mut have: HashSet<[u32; 4]> = c.quads.iter().map(key).collect();
            let mut frontier: Vec<[u32; 4]> = c
                .quads
                .iter()
                .zip(&c.rank)
                .filter(|(q, r)| match seeds.as_str() {
                    "gt" => gt.contains(&key(q)),
                    "rank" => **r < rank_lim,
                    _ => true,
                })
                .map(|(q, _)| *q)
                .collect();
            let mut n_added = 0usize;
            for _ in 0..iters {
                let mut next = Vec::new();
                for q in &frontier {
                    for e in 0..4 {
                        let (a, b, cc, d) = (q[e], q[(e + 1) % 4], q[(e + 2) % 4], q[(e + 3) % 4]);
                        let (pa, pb, pc, pd) =
                            (local[a as usize], local[b as usize], local[cc as usize], local[d as usize]);
                        let la = [2.0 * pa[0] - pd[0], 2.0 * pa[1] - pd[1], 2.0 * pa[2] - pd[2]];
                        let lb = [2.0 * pb[0] - pc[0], 2.0 * pb[1] - pc[1], 2.0 * pb[2] - pc[2]];
                        let (Some(na), Some(nb)) = (tree.nearest(la), tree.nearest(lb)) else { continue };
                        let sa = point2quad::spatial::kdtree::dist_sq(pa, pd).sqrt();
                        let sb = point2quad::spatial::kdtree::dist_sq(pb, pc).sqrt();
                        if na.dist_sq.sqrt() > tol * sa || nb.dist_sq.sqrt() > tol * sb {
                            continue;
                        }
                        let nq = [b, a, na.index, nb.index];
                        if (0..4).any(|i| (i + 1..4).any(|j| nq[i] == nq[j])) {
                            continue;
                        }
                        if have.insert(key(&nq)) {
                            n_added += 1;
                            if seeds != "gt" || gt.contains(&key(&nq)) {
                                next.push(nq);
                            }
                        }
                    }
                }
                frontier = next;
            }
            let cov_after = mesh.quads.iter().filter(|f| have.contains(&key(f))).count();
            println!(
                "{:28} {} faces {:6} cov {:.4} -> {:.4}  cand/pt {:.2} + {:.2}",
                name,
                if noisy { "N" } else { "C" },
                mesh.quads.len(),
                cov.ratio(),
                cov_after as f64 / mesh.quads.len() as f64,
                cov.per_point(),
                n_added as f64 / pts.len() as f64
            );
            faces += mesh.quads.len();
            before += cov.covered;
            after += cov_after;
            pts_n += pts.len();
            cands += cov.candidates;
            added += n_added;
        }
        println!(
            "TOTAL {} cov {:.4} -> {:.4}  cand/pt {:.2} + {:.2}",
            if noisy { "N" } else { "C" },
            before as f64 / faces as f64,
            after as f64 / faces as f64,
            cands as f64 / pts_n as f64,
            added as f64 / pts_n as f64
        );
    }
}
