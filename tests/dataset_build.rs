//! Building samples from meshes and the `point2quad dataset` command: cloud layout (mesh
//! vertices first, in the normalised frame, then noise), labels against the ground truth,
//! determinism for a seed, and the CLI's files, index and error handling.

use std::path::PathBuf;
use std::process::Command;

use point2quad::mesh::shapes;
use point2quad::pipeline::candidates::{generate, CandidateConfig};
use point2quad::pipeline::dataset::{
    build_sample, build_sample_with, encode_sample, label_candidates, load_sample, read_sample, stretch_mesh,
    CornerStart,
};
use point2quad::pipeline::features::{face_input, CONTEXT_DIM, F_INFO_DIM};
use point2quad::pipeline::frame::Frame;
use point2quad::pipeline::noise::{noise_points, NoiseConfig};
use point2quad::rng::Rng;
use proptest::prelude::*;

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// `stretch_mesh` keeps the faces and stretches along one axis: for every pair of
    /// vertices, |Δ'|² = |Δ|² + (f² − 1)(Δ·a)² (the reference), with |a| = 1 and
    /// 1 ≤ f ≤ the largest factor; the same seed gives the same copy.
    #[test]
    fn stretch_mesh_stretches_along_one_axis(seed in any::<u64>(), max in 1.0f64..10.0, which in 0usize..3) {
        let mesh = match which {
            0 => shapes::torus(10, 6, 1.0, 0.4),
            1 => shapes::cube_sphere(3),
            _ => shapes::random_pose(&shapes::torus(8, 5, 2.0, 0.5), &mut Rng::new(seed ^ 1)),
        };
        let (out, a, f) = stretch_mesh(&mesh, max, &mut Rng::new(seed)).unwrap();
        prop_assert_eq!(&out.quads, &mesh.quads);
        prop_assert_eq!(out.vertices.len(), mesh.vertices.len());
        prop_assert!(((a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt() - 1.0).abs() < 1e-12);
        prop_assert!((1.0..=max).contains(&f), "factor {} outside [1, {}]", f, max);
        let n = mesh.vertices.len();
        for i in (0..n).step_by(7) {
            for j in (i + 1..n).step_by(5) {
                let d: [f64; 3] = std::array::from_fn(|k| mesh.vertices[j][k] - mesh.vertices[i][k]);
                let e: [f64; 3] = std::array::from_fn(|k| out.vertices[j][k] - out.vertices[i][k]);
                let along = d[0] * a[0] + d[1] * a[1] + d[2] * a[2];
                let want = d.iter().map(|x| x * x).sum::<f64>() + (f * f - 1.0) * along * along;
                let got = e.iter().map(|x| x * x).sum::<f64>();
                prop_assert!((got - want).abs() <= 1e-9 * (1.0 + want), "{} vs {}", got, want);
            }
        }
        let again = stretch_mesh(&mesh, max, &mut Rng::new(seed)).unwrap();
        prop_assert_eq!(again.0, out);
    }
}

#[test]
fn stretch_mesh_rejects_bad_factors() {
    let mesh = shapes::cube_sphere(2);
    for bad in [0.5, 0.0, -2.0, f64::NAN, f64::INFINITY] {
        assert!(stretch_mesh(&mesh, bad, &mut Rng::new(1)).is_err(), "{bad}");
    }
    let (same, _, f) = stretch_mesh(&mesh, 1.0, &mut Rng::new(1)).unwrap();
    assert_eq!(f, 1.0);
    assert_eq!(same, mesh);
}

#[test]
fn sample_layout_labels_and_determinism() {
    let mesh = shapes::random_pose(&shapes::torus(24, 10, 1.0, 0.4), &mut Rng::new(1));
    let noise = NoiseConfig::default();
    let cfg = CandidateConfig::default();
    let s = build_sample("torus", &mesh, &noise, &cfg, &mut Rng::new(7)).unwrap();
    let v = mesh.vertices.len();
    assert_eq!(s.n_mesh_vertices as usize, v);
    assert_eq!(s.points.len(), v + (0.1 * v as f64).round() as usize);
    // Reference: the same noise draws and frame, computed here.
    let mut all = mesh.vertices.clone();
    all.extend(noise_points(&mesh, &noise, &mut Rng::new(7)).unwrap());
    let frame = Frame::fit(&all).unwrap();
    for (p, q) in s.points.iter().zip(&all) {
        assert_eq!(*p, frame.to_local(*q));
    }
    assert_eq!(s.gt_faces, mesh.quads);
    // Samples store F_info, then the context features (what the default model reads).
    let dim = F_INFO_DIM + CONTEXT_DIM;
    assert_eq!(s.feature_dim as usize, dim);
    assert_eq!(s.features.len(), s.candidates.len() * dim);
    // The candidates of `generate`, each started at its corner of smallest coordinates
    // (session 30: not at its smallest index, which is never a noise point here).
    let mut c = generate(&s.points, &cfg).unwrap();
    assert_eq!(s.candidates.len(), c.quads.len());
    let mut started_elsewhere = 0;
    for (got, q) in s.candidates.iter().zip(&c.quads) {
        let k = (0..4).find(|&k| q[k] == got[0]).expect("a corner of the generated quad");
        assert_eq!(*got, [q[k], q[(k + 1) % 4], q[(k + 2) % 4], q[(k + 3) % 4]], "a rotation of {q:?}");
        let least = got.iter().map(|&v| s.points[v as usize]).fold([f32::INFINITY; 3], |m, p| {
            if (p[0], p[1], p[2]) < (m[0], m[1], m[2]) {
                p
            } else {
                m
            }
        });
        assert_eq!(s.points[got[0] as usize], least, "{got:?} starts at its smallest corner");
        started_elsewhere += usize::from(k != 0);
    }
    assert!(started_elsewhere > s.candidates.len() / 4, "{started_elsewhere} of {}", s.candidates.len());
    c.quads = s.candidates.clone();
    assert_eq!(s.features, face_input(&s.points, &c, true));
    // `CornerStart::Index` (what the shipped weights were trained on, `make train`'s
    // `--corner-start index`): the candidates exactly as `generate` gives them, smallest
    // index first, with the same noise draws and labels by vertex set.
    let old = build_sample_with("torus", &mesh, &noise, &cfg, CornerStart::Index, &mut Rng::new(7)).unwrap();
    let g = generate(&s.points, &cfg).unwrap();
    assert_eq!(old.points, s.points);
    assert_eq!(old.candidates, g.quads);
    assert!(old.candidates.iter().all(|q| q[0] == *q.iter().min().unwrap()));
    assert_eq!(old.features, face_input(&s.points, &g, true));
    assert_eq!(old.labels, s.labels);
    assert_ne!(old.candidates, s.candidates);
    assert_eq!(s.labels, label_candidates(&s.candidates, &mesh.quads));
    assert!(s.positives() > 0 && s.coverage() > 0.0);
    // Same seed, same bytes; round trip through the format.
    let t = build_sample("torus", &mesh, &noise, &cfg, &mut Rng::new(7)).unwrap();
    let (a, b) = (encode_sample(&s).unwrap(), encode_sample(&t).unwrap());
    assert_eq!(a, b);
    assert_eq!(read_sample(&a, "<memory>").unwrap(), s);
}

#[test]
fn bad_meshes_are_errors() {
    let noise = NoiseConfig::default();
    let cfg = CandidateConfig::default();
    let mut m = shapes::grid(4, 4, 1.0, 1.0);
    m.quads[3][1] = 1000;
    assert!(build_sample("bad", &m, &noise, &cfg, &mut Rng::new(0)).is_err());
    let mut m = shapes::grid(4, 4, 1.0, 1.0);
    m.quads.clear();
    assert!(build_sample("empty", &m, &noise, &cfg, &mut Rng::new(0)).is_err());
    let mut m = shapes::grid(4, 4, 1.0, 1.0);
    m.vertices[0][0] = f64::INFINITY;
    assert!(build_sample("inf", &m, &noise, &cfg, &mut Rng::new(0)).is_err());
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("p2q_dataset_cli_{name}_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

fn p2q(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_point2quad")).args(args).output().unwrap()
}

#[test]
fn cli_is_deterministic_and_writes_an_index() {
    let (a, b) = (tmp("a"), tmp("b"));
    let meshes = tmp("meshes");
    std::fs::create_dir_all(&meshes).unwrap();
    // One quad mesh, one triangle mesh (skipped with a warning naming it).
    std::fs::write(
        meshes.join("square.obj"),
        "v 0 0 0\nv 1 0 0\nv 2 0 0\nv 0 1 0\nv 1 1 0\nv 2 1 0\nv 0 2 0\nv 1 2 0\nv 2 2 0\nf 1 2 5 4\nf 2 3 6 5\nf 4 5 8 7\nf 5 6 9 8\n",
    )
    .unwrap();
    std::fs::write(meshes.join("tri.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    for out in [&a, &b] {
        let o = p2q(&[
            "dataset",
            "--out",
            out.to_str().unwrap(),
            "--synthetic",
            "2",
            "--meshes",
            meshes.to_str().unwrap(),
            "--seed",
            "5",
        ]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(o.status.success(), "{err}");
        assert!(err.contains("tri.obj") && err.contains("not a pure-quad"), "{err}");
        assert!(err.contains("[1/4]") && err.contains("coverage"), "{err}");
    }
    let index = std::fs::read_to_string(a.join("index.txt")).unwrap();
    assert_eq!(index, std::fs::read_to_string(b.join("index.txt")).unwrap());
    let lines: Vec<&str> = index.lines().filter(|l| !l.starts_with('#')).collect();
    assert_eq!(lines.len(), 3, "{index}");
    for line in lines {
        let cols: Vec<&str> = line.split('\t').collect();
        assert_eq!(cols.len(), 5, "{line}");
        let (fa, fb) = (std::fs::read(a.join(cols[0])).unwrap(), std::fs::read(b.join(cols[0])).unwrap());
        assert_eq!(fa, fb, "{} differs between runs", cols[0]);
        let s = load_sample(&a.join(cols[0])).unwrap();
        assert_eq!(cols[1].parse::<usize>().unwrap(), s.points.len());
        assert_eq!(cols[2].parse::<usize>().unwrap(), s.candidates.len());
        assert_eq!(cols[3].parse::<usize>().unwrap(), s.positives());
    }
    assert!(a.join("square.p2qs").exists());
    for d in [a, b, meshes] {
        std::fs::remove_dir_all(d).unwrap();
    }
}

/// `--tri-split N` adds N samples, `syn_tri_<i>_<family>`, with true faces among their
/// candidates, after the others, which keep their bytes. (The conversion itself is
/// tested against its definition in `shapes_props`.)
#[test]
fn cli_tri_split_samples_leave_the_others_alone() {
    let (a, b) = (tmp("tri_a"), tmp("tri_b"));
    for (out, extra) in [(&a, &[][..]), (&b, &["--tri-split", "1"][..])] {
        let mut args = vec!["dataset", "--out", out.to_str().unwrap(), "--synthetic", "2", "--seed", "5"];
        args.extend(extra);
        let o = p2q(&args);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    let names = |d: &PathBuf| -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(d)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    };
    let (na, nb) = (names(&a), names(&b));
    let extra: Vec<&String> = nb.iter().filter(|n| !na.contains(n)).collect();
    assert_eq!(extra.len(), 1, "{nb:?}");
    assert!(extra[0].starts_with("syn_tri_00000_") && extra[0].ends_with(".p2qs"), "{extra:?}");
    for n in na.iter().filter(|n| n.ends_with(".p2qs")) {
        assert_eq!(std::fs::read(a.join(n)).unwrap(), std::fs::read(b.join(n)).unwrap(), "{n}");
    }
    let s = load_sample(&b.join(extra[0])).unwrap();
    assert!(s.positives() > 0);
    for d in [a, b] {
        std::fs::remove_dir_all(d).unwrap();
    }
}

#[test]
fn cli_errors() {
    let out = tmp("err");
    let o = p2q(&["dataset", "--out", out.to_str().unwrap(), "--meshes", "/nonexistent/p2q_meshes"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("/nonexistent/p2q_meshes"));
    let o = p2q(&["dataset", "--out", out.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
    let o = p2q(&["dataset", "--synthetic", "1"]);
    assert!(String::from_utf8_lossy(&o.stderr).contains("--out"));
    let o = p2q(&["dataset", "--out", out.to_str().unwrap(), "--synthetic", "x"]);
    assert_eq!(o.status.code(), Some(2));
    let o = p2q(&["dataset", "--out", out.to_str().unwrap(), "--synthetic", "1", "--noise", "-1"]);
    assert_eq!(o.status.code(), Some(2));
    let o = p2q(&["dataset", "--help"]);
    assert!(o.status.success() && String::from_utf8_lossy(&o.stdout).contains("--synthetic"));
    let _ = std::fs::remove_dir_all(out);
}
