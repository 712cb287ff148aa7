//! The second pass (`ReconstructConfig::second_pass`, session 26): which points the
//! first pass's mesh calls noise, against a brute-force reference, and the second
//! pass's output through the library API.

use point2quad::mesh::halfedge::HalfedgeMesh;
use point2quad::mesh::validate::validate;
use point2quad::pipeline::reconstruct::{
    first_pass_features, reconstruct, reconstruct_observed, reconstruct_with_report, ReconstructConfig,
    SecondPass, SecondPassCover, SecondPassMode, StageDone,
};
use point2quad::pipeline::second_pass::{
    covered_unused, covered_unused_by, learned_noise, point_features, LEARNED_CUTOFF, LEARNED_WEIGHTS,
    NOISE_FEATURES,
};
use point2quad::rng::Rng;
use point2quad::spatial::kdtree::dist_sq;
use proptest::prelude::*;
#[path = "common/shipped.rs"]
mod shipped;
use shipped::shipped;

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

/// Reference: barycentric coordinates of the projected point in each of the quad's
/// four corner triangles (projected onto the face's plane), every face tried (no grid).
fn brute(pos: &[[f64; 3]], n_points: usize, quads: &[[u32; 4]], tau: f64) -> Vec<bool> {
    brute_by(pos, n_points, quads, quads, tau)
}

fn brute_by(
    pos: &[[f64; 3]],
    n_points: usize,
    users: &[[u32; 4]],
    quads: &[[u32; 4]],
    tau: f64,
) -> Vec<bool> {
    let mut used = vec![false; pos.len()];
    users.iter().flatten().for_each(|&v| used[v as usize] = true);
    (0..n_points)
        .map(|i| {
            !used[i]
                && quads.iter().any(|q| {
                    let c = q.map(|v| pos[v as usize]);
                    let n = cross(sub(c[2], c[0]), sub(c[3], c[1]));
                    let len = dot(n, n).sqrt();
                    if len == 0.0 {
                        return false;
                    }
                    let n = n.map(|x| x / len);
                    let edge = (0..4)
                        .map(|k| dot(sub(c[k], c[(k + 1) % 4]), sub(c[k], c[(k + 1) % 4])).sqrt())
                        .sum::<f64>()
                        / 4.0;
                    let d = dot(sub(pos[i], c[0]), n);
                    if d.abs() > tau * edge {
                        return false;
                    }
                    let p = sub(pos[i], n.map(|x| x * d));
                    [[0, 1, 2], [0, 2, 3], [0, 1, 3], [1, 2, 3]].iter().any(|t| {
                        // The triangle as seen along the normal: its corners projected
                        // onto the plane through the point's projection.
                        let flat = |x: [f64; 3]| sub(x, n.map(|k| k * dot(sub(x, p), n)));
                        let (a, b, cc) = (flat(c[t[0]]), flat(c[t[1]]), flat(c[t[2]]));
                        let (v0, v1, v2) = (sub(b, a), sub(cc, a), sub(p, a));
                        let (d00, d01, d11, d20, d21) =
                            (dot(v0, v0), dot(v0, v1), dot(v1, v1), dot(v2, v0), dot(v2, v1));
                        let den = d00 * d11 - d01 * d01;
                        if den.abs() < 1e-12 * d00.max(d11).powi(2) {
                            return false;
                        }
                        let v = (d11 * d20 - d01 * d21) / den;
                        let w = (d00 * d21 - d01 * d20) / den;
                        let eps = 1e-9;
                        v >= -eps && w >= -eps && v + w <= 1.0 + eps
                    })
                })
        })
        .collect()
}

/// A bumpy grid of quads (some taken out) and loose points near it; the points on the
/// edge of a face (within 1e-6 of the reference's decision) are left out of the
/// comparison, where the two tests may round apart.
fn scene(seed: u64) -> (Vec<[f64; 3]>, usize, Vec<[u32; 4]>) {
    let mut rng = Rng::new(seed);
    let n = 4 + (seed % 5) as usize;
    let mut pos = Vec::new();
    for y in 0..n {
        for x in 0..n {
            pos.push([
                x as f64 + 0.3 * (rng.f64() - 0.5),
                y as f64 + 0.3 * (rng.f64() - 0.5),
                0.3 * rng.f64(),
            ]);
        }
    }
    let mut quads = Vec::new();
    for y in 0..n - 1 {
        for x in 0..n - 1 {
            if rng.f64() < 0.8 {
                let v = (y * n + x) as u32;
                quads.push([v, v + 1, v + 1 + n as u32, v + n as u32]);
            }
        }
    }
    for _ in 0..60 {
        pos.push([
            (n as f64) * rng.f64() - 0.5,
            (n as f64) * rng.f64() - 0.5,
            0.15 + 0.6 * (rng.f64() - 0.5),
        ]);
    }
    // A degenerate face (four points on a line: no normal, contains nothing) and, for
    // a third of the seeds, a face over the whole grid (too large for the grid's cells:
    // tested apart).
    let d = pos.len() as u32;
    for k in 0..4 {
        pos.push([0.2 + 0.1 * k as f64, 0.5, 0.3]);
    }
    quads.push([d, d + 1, d + 2, d + 3]);
    if seed % 3 == 0 {
        let m = n as u32;
        quads.push([0, m - 1, m * m - 1, m * (m - 1)]);
    }
    let np = pos.len();
    // A vertex the hole filling added: never marked, even inside a face.
    pos.push([0.5, 0.5, 0.1]);
    (pos, np, quads)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    #[test]
    fn covered_unused_by_a_subset_equals_the_brute_force_reference(seed in 0u64..1_000_000, tau in 0.05f64..0.6) {
        let (pos, np, quads) = scene(seed);
        let covering: Vec<[u32; 4]> = quads.iter().copied().enumerate().filter(|(k, _)| (k * 7 + seed as usize) % 3 != 0).map(|(_, q)| q).collect();
        let got = covered_unused_by(&pos, np, &quads, &covering, tau);
        let want = brute_by(&pos, np, &quads, &covering, tau);
        let narrow = brute_by(&pos, np, &quads, &covering, tau * (1.0 - 1e-9));
        let wide = brute_by(&pos, np, &quads, &covering, tau * (1.0 + 1e-9));
        for i in 0..np {
            if narrow[i] == wide[i] {
                prop_assert_eq!(got[i], want[i], "point {} {:?}", i, pos[i]);
            }
        }
    }

    #[test]
    fn covered_unused_equals_the_brute_force_reference(seed in 0u64..1_000_000, tau in 0.05f64..0.6) {
        let (pos, np, quads) = scene(seed);
        let got = covered_unused(&pos, np, &quads, tau);
        let want = brute(&pos, np, &quads, tau);
        prop_assert_eq!(got.len(), np);
        // Points within a hair of a decision boundary (plane slack or a triangle's
        // edge) may round either way: compared with a slightly narrower and a slightly
        // wider tau, a point must agree with one of them.
        let narrow = brute(&pos, np, &quads, tau * (1.0 - 1e-9));
        let wide = brute(&pos, np, &quads, tau * (1.0 + 1e-9));
        for i in 0..np {
            if narrow[i] == wide[i] {
                prop_assert_eq!(got[i], want[i], "point {} {:?}", i, pos[i]);
            }
        }
    }
}

/// Candidates for [`point_features`]' reference: the scene's faces, quads of four grid
/// points near each other (some folded or crossing), and quads with a loose point as a
/// corner, each with a random probability (some under the 0.05 the "strictly inside"
/// column ignores, some above 0.9); about half of the faces are "believed".
fn candidates(
    seed: u64,
    pos: &[[f64; 3]],
    np: usize,
    quads: &[[u32; 4]],
) -> (Vec<[u32; 4]>, Vec<f32>, Vec<[u32; 4]>) {
    let mut rng = Rng::new(seed ^ 0x5eed);
    let mut cands: Vec<[u32; 4]> = quads.to_vec();
    // Not the scene's four collinear points (np − 4 ..): a quad with three of them has a
    // triangle of no area, on which the library's sign test and the reference's
    // tolerance disagree by design.
    let pool = np - 4;
    for _ in 0..3 * quads.len() {
        let a = rng.below(pool);
        // Three more among the points nearest a (brute force), drawn from the 8 nearest.
        let mut order: Vec<usize> = (0..pool).filter(|&j| j != a).collect();
        order.sort_by(|&i, &j| {
            let di = dot(sub(pos[i], pos[a]), sub(pos[i], pos[a]));
            let dj = dot(sub(pos[j], pos[a]), sub(pos[j], pos[a]));
            di.total_cmp(&dj)
        });
        let mut pick = vec![a];
        while pick.len() < 4 {
            let j = order[rng.below(8.min(order.len()))];
            if !pick.contains(&j) {
                pick.push(j);
            }
        }
        cands.push([pick[0], pick[1], pick[2], pick[3]].map(|v| v as u32));
    }
    let probs: Vec<f32> = cands
        .iter()
        .map(|_| match rng.below(4) {
            0 => 0.04 * rng.f64() as f32,
            1 => 0.9 + 0.1 * rng.f64() as f32,
            _ => rng.f64() as f32,
        })
        .collect();
    let believed: Vec<[u32; 4]> = quads.iter().copied().filter(|_| rng.f64() < 0.5).collect();
    (cands, probs, believed)
}

/// An independent reference for [`point_features`]: every candidate tried for every
/// point (no grid, no kd-tree), the point-in-face test of [`brute_by`], nearest
/// neighbours by sorting all distances. Returns the columns and, per point, whether it
/// lies within a hair of a point-in-face decision (then the inside columns are not
/// compared).
#[allow(clippy::too_many_arguments)]
fn reference_features(
    local: &[[f32; 3]],
    pos: &[[f64; 3]],
    np: usize,
    cands: &[[u32; 4]],
    probs: &[f32],
    mesh: &[[u32; 4]],
    believed: &[[u32; 4]],
    threshold: f32,
    tau: f64,
) -> (Vec<[f32; NOISE_FEATURES]>, Vec<bool>) {
    let inside = |t: f64, users: &[[u32; 4]], quads: &[[u32; 4]]| brute_by(pos, np, users, quads, t);
    let above = |t: f32| -> Vec<[u32; 4]> {
        cands.iter().zip(probs).filter(|(_, &p)| p > t).map(|(q, _)| *q).collect()
    };
    let mut hair = vec![false; np];
    let mut at = |f: &dyn Fn(f64) -> Vec<bool>| -> Vec<bool> {
        let (lo, hi) = (f(tau * (1.0 - 1e-9)), f(tau * (1.0 + 1e-9)));
        (0..np).for_each(|i| hair[i] |= lo[i] != hi[i]);
        f(tau)
    };
    let rule = at(&|t| inside(t, mesh, believed));
    let any = at(&|t| inside(t, mesh, mesh));
    let in_above = at(&|t| inside(t, &[], &above(threshold)));
    let in_above9 = at(&|t| inside(t, &[], &above(0.9)));
    // "Strictly inside": a quad holds the point and the point is not its corner.
    let mut span = vec![0f32; np];
    let mut span_mesh = vec![0f32; np];
    for (list, ps, out) in [(cands, probs.to_vec(), &mut span), (mesh, vec![1.0; mesh.len()], &mut span_mesh)]
    {
        for (q, &p) in list.iter().zip(&ps) {
            if p < 0.05 {
                continue;
            }
            let held = at(&|t| inside(t, &[], &[*q]));
            for i in 0..np {
                if held[i] && !q.contains(&(i as u32)) {
                    out[i] = out[i].max(p);
                }
            }
        }
    }
    let x = (0..np)
        .map(|i| {
            let mine: Vec<f32> =
                cands.iter().zip(probs).filter(|(q, _)| q.contains(&(i as u32))).map(|(_, &p)| p).collect();
            let (mut maxp, mut sum) = (0f32, 0f32);
            for &p in &mine {
                maxp = maxp.max(p);
                sum += p;
            }
            let uses = |list: &[[u32; 4]]| list.iter().flatten().filter(|&&v| v as usize == i).count() as f32;
            let mut d: Vec<f32> =
                (0..np).filter(|&j| j != i).map(|j| dist_sq(local[i], local[j]).sqrt()).collect();
            d.sort_by(f32::total_cmp);
            let near: Vec<f32> = d.into_iter().take(9).collect();
            let mean = near.iter().sum::<f32>() / near.len() as f32;
            let flag = |b: bool| b as u8 as f32;
            [
                flag(uses(mesh) > 0.0),
                flag(rule[i]),
                flag(any[i]),
                maxp,
                sum / 4.0,
                mine.len() as f32 / 10.0,
                uses(mesh) / 4.0,
                uses(believed) / 4.0,
                flag(in_above[i]),
                flag(in_above9[i]),
                near[0] / mean,
                near[1] / mean,
                if mine.is_empty() { 0.0 } else { sum / mine.len() as f32 },
                span[i],
                span_mesh[i],
                1.0,
            ]
        })
        .collect();
    (x, hair)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]

    /// Every column of the learned test's input against the independent reference; the
    /// inside columns skipped for points within a hair of a decision.
    #[test]
    fn point_features_equal_the_brute_force_reference(seed in 0u64..1_000_000, tau in 0.05f64..0.6) {
        let (pos, np, mesh) = scene(seed);
        let (cands, probs, believed) = candidates(seed, &pos, np, &mesh);
        let local: Vec<[f32; 3]> = pos[..np].iter().map(|p| p.map(|x| x as f32)).collect();
        let got = point_features(&local, &pos, np, &cands, &probs, &mesh, &believed, 0.5, tau);
        let (want, hair) = reference_features(&local, &pos, np, &cands, &probs, &mesh, &believed, 0.5, tau);
        prop_assert_eq!(got.len(), np);
        let inside_columns = [1usize, 2, 8, 9, 13, 14];
        // A corner of a quad lies on its triangles' boundary, where the library's sign
        // test and the reference's tolerance may round apart: columns 8 and 9 (which do
        // not leave the quads' own corners out) are not compared at such points.
        let corner_of = |t: f32| {
            let mut m = vec![false; np];
            cands.iter().zip(&probs).filter(|(_, &p)| p > t).flat_map(|(q, _)| q.iter()).for_each(|&v| m[v as usize] = true);
            m
        };
        let (corner5, corner9) = (corner_of(0.5), corner_of(0.9));
        for i in 0..np {
            for c in 0..NOISE_FEATURES {
                if hair[i] && inside_columns.contains(&c) || c == 8 && corner5[i] || c == 9 && corner9[i] {
                    continue;
                }
                prop_assert_eq!(got[i][c], want[i][c], "point {} column {}", i, c);
            }
        }
        // The test is the weighted sum against the cutoff.
        let noise = learned_noise(&got);
        for i in 0..np {
            let z: f32 = got[i].iter().zip(&LEARNED_WEIGHTS).map(|(a, b)| a * b).sum();
            prop_assert_eq!(noise[i], z > LEARNED_CUTOFF);
        }
    }
}

/// A flat grid with points near some face centres (a noise model's points): the first
/// pass leaves them unused and inside faces, the second pass drops exactly those, and
/// no output face uses one; the output is a valid manifold mesh whose first vertices
/// are the input, bit for bit, in both modes.
/// A 12 × 12 grid, gently waved, plus 12 noise points near face centres.
fn grid_with_noise() -> (Vec<[f64; 3]>, usize, usize) {
    let n = 12;
    let mut pts = Vec::new();
    for y in 0..n {
        for x in 0..n {
            pts.push([x as f64 * 0.1, y as f64 * 0.1, 0.02 * ((x * 7 + y * 3) % 5) as f64 / 5.0]);
        }
    }
    let grid = pts.len();
    let mut rng = Rng::new(3);
    for k in 0..12 {
        let (x, y) = (1 + (k * 5) % (n - 3), 1 + (k * 7) % (n - 3));
        let c = |dx: usize, dy: usize| pts[(y + dy) * n + x + dx];
        let m = [0, 1, 2].map(|a| (c(0, 0)[a] + c(1, 0)[a] + c(1, 1)[a] + c(0, 1)[a]) / 4.0);
        pts.push([
            m[0] + 0.02 * (rng.f64() - 0.5),
            m[1] + 0.02 * (rng.f64() - 0.5),
            m[2] + 0.004 * (rng.f64() - 0.5),
        ]);
    }
    (pts, n, grid)
}

#[test]
fn the_second_pass_drops_the_points_inside_faces_and_keeps_the_mesh_valid() {
    let (pts, n, grid) = grid_with_noise();
    let one = ReconstructConfig { second_pass: None, ..Default::default() };
    let first = reconstruct(&pts, shipped(), &one).expect("first pass");
    let mut used = vec![false; first.vertices.len()];
    first.quads.iter().flatten().for_each(|&v| used[v as usize] = true);
    let expect = covered_unused(&first.vertices, pts.len(), &first.quads, 0.25);
    // The premise: the noise points are unused and inside faces after one pass.
    assert!(expect[grid..].iter().filter(|&&e| e).count() >= 8, "{:?}", &expect[grid..]);
    for (mode, cover) in [
        (SecondPassMode::Replace, SecondPassCover::All),
        (SecondPassMode::Average, SecondPassCover::All),
        (SecondPassMode::Average, SecondPassCover::Believed),
        (SecondPassMode::Average, SecondPassCover::Learned),
    ] {
        let cfg = ReconstructConfig {
            second_pass: Some(SecondPass { tau: 0.25, mode, cover }),
            ..Default::default()
        };
        let (m, rep) = reconstruct_with_report(&pts, shipped(), &cfg).expect("second pass");
        let all = expect.iter().filter(|&&e| e).count();
        if cover == SecondPassCover::All {
            assert_eq!(rep.second_pass_dropped, Some(all), "{mode:?}");
            for q in &m.quads {
                assert!(q.iter().all(|&v| !expect[v as usize]), "{mode:?}: face {q:?} uses a dropped point");
            }
        } else {
            // Only the believed faces cover (learned: a test whose rule column is
            // theirs): on this grid never more points than all faces hold.
            let d = rep.second_pass_dropped.expect("the pass ran");
            assert!(d >= 1 && d <= all, "{d} of {all}");
        }
        assert_eq!(&m.vertices[..pts.len()], &pts[..]);
        let he = HalfedgeMesh::from_quads(m.vertices.len(), &m.quads).expect("manifold");
        validate(&he).expect("valid");
        // Every face of the grid is found once the noise is out.
        assert!(m.quads.len() >= (n - 1) * (n - 1) - 2, "{mode:?}: {} faces", m.quads.len());
    }
    // A tau the test cannot use is refused.
    for tau in [f64::NAN, -0.1, f64::INFINITY] {
        let cfg = ReconstructConfig {
            second_pass: Some(SecondPass { tau, mode: SecondPassMode::Average, cover: SecondPassCover::All }),
            ..Default::default()
        };
        assert!(reconstruct(&pts, shipped(), &cfg).is_err(), "tau {tau}");
    }
    // Without a second pass the report says so.
    let (_, rep) = reconstruct_with_report(&pts, shipped(), &one).expect("one pass");
    assert_eq!(rep.second_pass_dropped, None);
}

/// `reconstruct_observed` tells of every stage as it ends: the report's timings in
/// order (pass 1), the second pass's own stages one by one (pass 2) in place of the
/// report's "second pass" sum that follows them; and its result is
/// `reconstruct_with_report`'s. Paths: one pass; a second pass that drops the noise; one
/// that finds nothing to drop (the grid alone); no post-process.
#[test]
fn the_observer_hears_every_stage_in_order() {
    let (pts, _, grid) = grid_with_noise();
    let two = ReconstructConfig::default();
    let cases = [
        (&pts[..], ReconstructConfig { second_pass: None, ..Default::default() }, "one pass"),
        (&pts[..], two.clone(), "dropped"),
        (&pts[..grid], two.clone(), "nothing to drop"),
        (&pts[..], ReconstructConfig { run_postprocess: false, ..two.clone() }, "no post-process"),
    ];
    for (cloud, cfg, case) in cases {
        let mut heard: Vec<StageDone> = Vec::new();
        let (mesh, rep) =
            reconstruct_observed(cloud, &[shipped()], &cfg, &mut |s| heard.push(s)).expect("observed");
        let (plain, _) = reconstruct_with_report(cloud, shipped(), &cfg).expect("plain");
        assert_eq!(mesh.quads, plain.quads, "{case}");
        let pass1: Vec<(&str, f64)> =
            heard.iter().filter(|s| s.pass == 1).map(|s| (s.stage, s.seconds)).collect();
        let pass2: Vec<&StageDone> = heard.iter().filter(|s| s.pass == 2).collect();
        // The pass-2 stages come together, between pass-1 stages.
        let first2 = heard.iter().position(|s| s.pass == 2).unwrap_or(heard.len());
        assert!(heard[first2..first2 + pass2.len()].iter().all(|s| s.pass == 2), "{case}");
        let mut timings = rep.timings.clone();
        if pass2.is_empty() {
            assert!(
                !timings.iter().any(|t| t.0 == "second pass") || rep.second_pass_dropped.is_none(),
                "{case}"
            );
        } else {
            // The sum entry sits where the pass-2 stages were heard.
            assert_eq!(timings[first2].0, "second pass", "{case}: {timings:?}");
            let (_, sum) = timings.remove(first2);
            let names: Vec<&str> = pass2.iter().map(|s| s.stage).collect();
            assert_eq!(names, ["candidates", "features", "classify", "refine"], "{case}");
            let heard_sum: f64 = pass2.iter().map(|s| s.seconds).sum();
            assert!((heard_sum - sum).abs() <= 1e-12 * sum.max(1.0), "{case}: {heard_sum} against {sum}");
        }
        assert_eq!(pass1, timings, "{case}");
        assert_eq!(pass1.first().map(|t| t.0), Some("normalise"), "{case}");
        // Each case takes the path it is named for.
        let last = rep.timings.last().map(|t| t.0);
        match case {
            "one pass" | "no post-process" => {
                assert!(pass2.is_empty() && last == Some("postprocess"), "{case}: {:?}", rep.timings)
            }
            "dropped" => {
                assert!(rep.second_pass_dropped.is_some() && last == Some("second postprocess"), "{case}")
            }
            _ => assert!(pass2.is_empty() && last == Some("second pass"), "{case}: {:?}", rep.timings),
        }
    }
}

/// `first_pass_features` reads the points as the pipeline's second pass does: one row per
/// distinct input point, and the learned test over its rows drops as many points as the
/// second pass under `SecondPassCover::Learned` reports; the post-process is required.
#[test]
fn first_pass_features_are_what_the_learned_second_pass_reads() {
    let (mut pts, _, _) = grid_with_noise();
    pts.push(pts[3]); // a duplicate: not a row of its own
    let cfg = ReconstructConfig {
        second_pass: Some(SecondPass {
            tau: 0.25,
            mode: SecondPassMode::Average,
            cover: SecondPassCover::Learned,
        }),
        ..Default::default()
    };
    let rows = first_pass_features(&pts, shipped(), &cfg).expect("features");
    assert_eq!(rows.len(), pts.len() - 1);
    let mut seen: Vec<u32> = rows.iter().map(|r| r.0).collect();
    seen.sort_unstable();
    assert_eq!(seen, (0..pts.len() as u32 - 1).collect::<Vec<_>>());
    let x: Vec<[f32; NOISE_FEATURES]> = rows.iter().map(|r| r.1).collect();
    let noise = learned_noise(&x).iter().filter(|&&b| b).count();
    assert!(noise >= 1, "the test finds the grid's noise points");
    let (_, rep) = reconstruct_with_report(&pts, shipped(), &cfg).expect("reconstruct");
    assert_eq!(rep.second_pass_dropped, Some(noise));
    let off = ReconstructConfig { run_postprocess: false, ..cfg.clone() };
    assert!(first_pass_features(&pts, shipped(), &off).is_err());
    // The settings `reconstruct` refuses are refused here too.
    let bad = ReconstructConfig { threshold: f32::NAN, ..cfg };
    assert!(first_pass_features(&pts, shipped(), &bad).is_err());
}
