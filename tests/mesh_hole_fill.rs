//! Hole-filling measurement on the held-out `eval/` meshes (measurement only, never
//! tuning): remove 1%, 2% and 5% of the faces (single faces and small patches), fill, and
//! print the watertightness reached and how many added faces equal removed ones. Asserts
//! only that every single-face hole closes with exactly its face.

#[path = "common/halfedge.rs"]
mod common;

use std::collections::HashSet;

use common::*;
use point2quad::io::mesh_io::read_mesh;
use point2quad::mesh::halfedge::HalfedgeMesh;
use point2quad::mesh::handles::{FaceId, HalfedgeId, VertexId};
use point2quad::mesh::hole_fill::{fill_holes, HoleFillConfig};
use point2quad::mesh::validate::validate;
use point2quad::rng::Rng;

/// #edges with two faces / #edges.
fn watertightness(m: &HalfedgeMesh) -> f64 {
    let mut two = 0usize;
    let mut all = 0usize;
    for e in 0..m.halfedge_capacity() / 2 {
        if m.is_edge_alive(e) {
            all += 1;
            let h = HalfedgeId(2 * e as u32);
            if !m.is_boundary(h) && !m.is_boundary(h.opposite()) {
                two += 1;
            }
        }
    }
    if all == 0 {
        1.0
    } else {
        two as f64 / all as f64
    }
}

struct Row {
    removed: usize,
    wt_before: f64,
    wt_after: f64,
    added: usize,
    restored: usize,
    singles: usize,
    singles_closed: usize,
}

/// `keep_points`: the removed patches' interior vertices stay available (as input points do
/// in the pipeline); otherwise they are moved far away so that pattern 3 must invent vertices.
fn run_one(full: &HalfedgeMesh, positions: &[[f64; 3]], rate: f64, seed: u64, keep_points: bool) -> Row {
    let mut rng = Rng::new(seed);
    let mut h = full.clone();
    let target = ((rate * full.n_faces() as f64).round() as usize).max(1);
    let live: Vec<FaceId> = full.faces().collect();
    let mut removed: HashSet<[u32; 4]> = HashSet::new();
    let mut patches: Vec<Vec<[u32; 4]>> = Vec::new();
    let mut tries = 0;
    while removed.len() < target && tries < 100 * target {
        tries += 1;
        let seed_face = live[rng.below(live.len())];
        if !h.is_face_alive(seed_face) {
            continue;
        }
        // Patch size: half single faces, half 2..=4 faces grown from the seed.
        let size = if rng.below(2) == 0 { 1 } else { 2 + rng.below(3) };
        let mut patch = Vec::new();
        let mut frontier = vec![seed_face];
        while let Some(f) = frontier.pop() {
            if patch.len() >= size || removed.len() >= target || !h.is_face_alive(f) {
                continue;
            }
            let verts = h.face_vertices(f).map(|v| v.0);
            let nbs: Vec<FaceId> = h.face_halfedges(f).iter().filter_map(|&x| h.face(x.opposite())).collect();
            if h.remove_face(f).is_ok() {
                removed.insert(key(verts));
                patch.push(verts);
                let mut nbs = nbs;
                rng.shuffle(&mut nbs);
                frontier.extend(nbs);
            }
        }
        if !patch.is_empty() {
            patches.push(patch);
        }
    }
    let wt_before = watertightness(&h);
    let faces_before: HashSet<[u32; 4]> = mesh_keys(&h).into_iter().collect();
    let mut pos = positions.to_vec();
    if !keep_points {
        for (v, p) in pos.iter_mut().enumerate() {
            if h.is_isolated(VertexId(v as u32)) && !full.is_isolated(VertexId(v as u32)) {
                *p = [1e9 + v as f64, 1e9, 1e9];
            }
        }
    }
    fill_holes(&mut h, &mut pos, &HoleFillConfig::default()).unwrap();
    validate(&h).unwrap();
    let after: HashSet<[u32; 4]> = mesh_keys(&h).into_iter().collect();
    let added: Vec<&[u32; 4]> = after.difference(&faces_before).collect();
    let restored = added.iter().filter(|k| removed.contains(**k)).count();
    // Single-face holes: one-face patches whose four edges were interior in the full mesh
    // and that touch no other removed face along an edge.
    let mut singles = 0;
    let mut singles_closed = 0;
    for p in patches.iter().filter(|p| p.len() == 1) {
        let f = p[0];
        let interior = (0..4).all(|i| {
            let (a, b) = (f[i], f[(i + 1) % 4]);
            full.find_halfedge(VertexId(a), VertexId(b))
                .is_some_and(|x| !full.is_boundary(x) && !full.is_boundary(x.opposite()))
        });
        let lonely = patches.iter().filter(|q| !std::ptr::eq(*q, p)).flatten().all(|g| {
            let shared = (0..4).filter(|&i| g.contains(&f[i]) && g.contains(&f[(i + 1) % 4])).count();
            shared == 0
        });
        if interior && lonely {
            singles += 1;
            if after.contains(&key(f)) {
                singles_closed += 1;
            }
        }
    }
    Row {
        removed: removed.len(),
        wt_before,
        wt_after: watertightness(&h),
        added: added.len(),
        restored,
        singles,
        singles_closed,
    }
}

#[test]
#[ignore = "heavy: run in release by make test-heavy"]
fn hole_filling_on_eval_meshes() {
    measure("eval");
}

/// The same on `train/`: where the thresholds may be tuned.
#[test]
#[ignore = "heavy: run in release by make test-heavy"]
fn hole_filling_on_train_meshes() {
    measure("train");
}

/// Adds one run to a row of totals (watertightness of the original, with holes, after
/// filling; restored / added; restored / removed; count) and to the single-face holes.
fn tally(t: &mut [f64; 6], singles: &mut (usize, usize), wt_orig: f64, r: &Row) {
    t[0] += wt_orig;
    t[1] += r.wt_before;
    t[2] += r.wt_after;
    t[3] += r.restored as f64 / r.added.max(1) as f64;
    t[4] += r.restored as f64 / r.removed.max(1) as f64;
    t[5] += 1.0;
    singles.0 += r.singles_closed;
    singles.1 += r.singles;
}

fn measure(sub: &str) {
    let Some(paths) = shared_meshes(sub) else { return };
    println!(
        "{:<22} {:>6} {:>5} {:>7} {:>8} {:>8} {:>8} {:>6} {:>9} {:>9} {:>8}",
        "mesh",
        "faces",
        "rate",
        "removed",
        "wt_orig",
        "wt_hole",
        "wt_fill",
        "added",
        "rest/add",
        "rest/rem",
        "singles"
    );
    let mut totals = [[0.0f64; 6]; 3];
    let mut totals_no_points = [[0.0f64; 6]; 3];
    let mut all_singles = (0, 0);
    for path in &paths {
        let pm = read_mesh(path).unwrap();
        let vertices = pm.vertices;
        let quads: Vec<[u32; 4]> =
            pm.faces.iter().filter(|f| f.len() == 4).map(|f| [f[0], f[1], f[2], f[3]]).collect();
        let mut full = HalfedgeMesh::new(vertices.len());
        let order: Vec<usize> = (0..quads.len()).collect();
        full.insert_faces(&quads, &order);
        let wt_orig = watertightness(&full);
        let name = path.file_stem().unwrap().to_string_lossy().to_string();
        for (ri, rate) in [0.01, 0.02, 0.05].into_iter().enumerate() {
            let r = run_one(&full, &vertices, rate, 1000 + ri as u64, true);
            let r2 = run_one(&full, &vertices, rate, 1000 + ri as u64, false);
            tally(&mut totals_no_points[ri], &mut all_singles, wt_orig, &r2);
            println!(
                "{:<22} {:>6} {:>4.0}% {:>7} {:>8.4} {:>8.4} {:>8.4} {:>6} {:>9.3} {:>9.3} {:>4}/{:<4}",
                name,
                full.n_faces(),
                rate * 100.0,
                r.removed,
                wt_orig,
                r.wt_before,
                r.wt_after,
                r.added,
                r.restored as f64 / r.added.max(1) as f64,
                r.restored as f64 / r.removed.max(1) as f64,
                r.singles_closed,
                r.singles
            );
            tally(&mut totals[ri], &mut all_singles, wt_orig, &r);
        }
    }
    for (label, totals) in [("interior points kept", totals), ("interior points removed", totals_no_points)] {
        for (ri, rate) in [1, 2, 5].into_iter().enumerate() {
            let t = totals[ri];
            let n = t[5].max(1.0);
            println!(
            "MEAN {label}, rate {rate}%: wt_orig {:.4} wt_hole {:.4} wt_fill {:.4} restored/added {:.3} restored/removed {:.3}",
            t[0] / n,
            t[1] / n,
            t[2] / n,
            t[3] / n,
            t[4] / n
        );
        }
    }
    println!("single-face holes closed: {}/{}", all_singles.0, all_singles.1);
    assert_eq!(all_singles.0, all_singles.1, "every single-face hole must close");
}
