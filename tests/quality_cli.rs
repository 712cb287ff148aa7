//! `point2quad eval` and `point2quad render` end to end: the JSON parses back (with a
//! parser written in tests/common) and agrees with the library, the table is readable,
//! the SVG is well formed, and bad usage fails cleanly.

#[path = "common/quality.rs"]
mod quality_common;
#[path = "common/scratch.rs"]
mod scratch;

use std::process::{Command, Output};

use point2quad::mesh::poly::PolyMesh;
use point2quad::mesh::quality::{compare, mesh_metrics};
use quality_common::{check_xml, grid, parse_json, torus, write_obj, Json};
use scratch::Scratch;

fn p2q(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_point2quad")).args(args).output().expect("test: run the binary")
}

const KEYS: [&str; 11] = [
    "faces",
    "quad_only",
    "boundary_edges",
    "nonmanifold_edges",
    "nonmanifold_vertices",
    "watertightness",
    "manifoldness",
    "scaled_jacobian",
    "edge_ratio",
    "angle_dev_deg",
    "angle_rms_deg",
];

fn json_of(out: &Output) -> Json {
    assert!(out.status.success(), "stderr: {}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8(out.stdout.clone()).unwrap();
    assert_eq!(text.trim_end().lines().count(), 1, "one line: {text}");
    parse_json(&text).unwrap_or_else(|e| panic!("{e}: {text}"))
}

fn num(j: &Json, k: &str) -> f64 {
    j.get(k).and_then(Json::num).unwrap_or_else(|| panic!("key {k} missing or not a number"))
}

#[test]
fn eval_json_agrees_with_the_library() {
    let dir = Scratch::new("quality_eval_json");
    let mut m = torus(16, 8, 0.4);
    // Perturb a little so the shape measures are not trivial, then open one face.
    for (i, p) in m.vertices.iter_mut().enumerate() {
        p[0] += 0.01 * ((i * 7 % 5) as f64 - 2.0);
    }
    m.faces.pop();
    let path = dir.path("pred.obj");
    write_obj(&path, &m);
    let j = json_of(&p2q(&["eval", path.to_str().unwrap(), "--json"]));
    let lib = mesh_metrics(&m);
    for k in KEYS {
        assert!(j.get(k).is_some(), "missing {k}");
    }
    assert_eq!(j.get("quad_only"), Some(&Json::Bool(true)));
    assert_eq!(num(&j, "faces"), lib.faces as f64);
    assert_eq!(num(&j, "boundary_edges"), 4.0);
    assert_eq!(num(&j, "nonmanifold_edges"), 0.0);
    for (k, v) in [
        ("watertightness", lib.watertightness),
        ("manifoldness", lib.manifoldness),
        ("scaled_jacobian", lib.scaled_jacobian),
        ("edge_ratio", lib.edge_ratio),
        ("angle_dev_deg", lib.angle_dev_deg),
        ("angle_rms_deg", lib.angle_rms_deg),
    ] {
        // Rust prints f64 with round-trip precision: the JSON number is the value.
        assert_eq!(num(&j, k), v, "{k}");
    }
    assert!(j.get("chamfer").is_none());
}

#[test]
fn eval_with_gt_reports_accuracy() {
    let dir = Scratch::new("quality_eval_gt");
    let gt = grid(6, 4);
    let mut pred = gt.clone();
    pred.faces.truncate(18);
    let (gp, pp) = (dir.path("gt.obj"), dir.path("pred.obj"));
    write_obj(&gp, &gt);
    write_obj(&pp, &pred);
    let j =
        json_of(&p2q(&["eval", pp.to_str().unwrap(), "--gt", gp.to_str().unwrap(), "--json", "--seed", "4"]));
    assert_eq!(num(&j, "precision"), 1.0);
    assert_eq!(num(&j, "recall"), 0.75);
    let lib = compare(&pred, &gt, 4).unwrap();
    assert_eq!(Some(num(&j, "chamfer")), lib.chamfer);
    assert!(num(&j, "chamfer") > 0.0);
    // The table says the same in words.
    let out = p2q(&["eval", pp.to_str().unwrap(), "--gt", gp.to_str().unwrap(), "--seed", "4"]);
    assert!(out.status.success());
    let table = String::from_utf8(out.stdout).unwrap();
    for word in ["watertightness", "scaled Jacobian", "face recall", "0.7500", "Chamfer"] {
        assert!(table.contains(word), "{word} in\n{table}");
    }
}

#[test]
fn eval_of_a_mesh_without_faces_is_all_finite() {
    let dir = Scratch::new("quality_eval_empty");
    let path = dir.path("points.obj");
    std::fs::write(&path, "v 0 0 0\nv 1 0 0\n").unwrap();
    let j = json_of(&p2q(&["eval", path.to_str().unwrap(), "--json"]));
    for k in KEYS.iter().filter(|k| **k != "quad_only") {
        assert_eq!(num(&j, k), 0.0, "{k}");
    }
}

/// An empty prediction is a result, not an error: scored 0 (precision 0 of 0 faces,
/// recall 0), Chamfer `null` with `empty_prediction: true` and a note; the same
/// numbers whether the file holds the ground truth's vertices or nothing at all.
/// Malformed files stay errors naming the file and line.
#[test]
fn eval_scores_an_empty_prediction_and_refuses_malformed_files() {
    let dir = Scratch::new("quality_eval_empty_pred");
    let gt = grid(3, 2);
    let gp = dir.path("gt.obj");
    write_obj(&gp, &gt);
    let g = gp.to_str().unwrap();
    let points_only = dir.path("points.obj");
    write_obj(&points_only, &PolyMesh { vertices: gt.vertices.clone(), faces: vec![] });
    let mut ply0 = b"ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\n".to_vec();
    ply0.extend_from_slice(
        b"property float z\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n",
    );
    let empties: Vec<(std::path::PathBuf, f64)> = vec![
        (points_only, gt.vertices.len() as f64),
        (dir.path("zero_bytes.obj"), 0.0),
        (dir.path("comments.obj"), 0.0),
        (dir.path("empty.off"), 0.0),
        (dir.path("empty.ply"), 0.0),
    ];
    std::fs::write(&empties[1].0, b"").unwrap();
    std::fs::write(&empties[2].0, b"# no output\no nothing\n").unwrap();
    std::fs::write(&empties[3].0, b"OFF\n0 0 0\n").unwrap();
    std::fs::write(&empties[4].0, &ply0).unwrap();
    for (path, vertices) in &empties {
        let p = path.to_str().unwrap();
        let out = p2q(&["eval", p, "--gt", g, "--json"]);
        let j = json_of(&out);
        for (k, v) in [
            ("faces", 0.0),
            ("precision", 0.0),
            ("recall", 0.0),
            ("watertightness", 0.0),
            ("manifoldness", 0.0),
            ("nonmanifold_vertices", 0.0),
            ("vertices", *vertices),
            ("unreferenced_vertices", *vertices),
            ("matched_vertices", *vertices),
        ] {
            assert_eq!(num(&j, k), v, "{p}: {k}");
        }
        for k in ["chamfer", "chamfer_pred_to_gt", "chamfer_gt_to_pred"] {
            assert_eq!(j.get(k), Some(&Json::Null), "{p}: {k}");
        }
        assert_eq!(j.get("empty_prediction"), Some(&Json::Bool(true)), "{p}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains("note") && err.contains(p) && err.contains("empty prediction"), "{err}");
        // Without --gt: the mesh metrics alone, no note.
        let out = p2q(&["eval", p, "--json"]);
        assert_eq!(num(&json_of(&out), "faces"), 0.0);
        assert!(out.stderr.is_empty(), "{}", String::from_utf8_lossy(&out.stderr));
        // The table says it in words.
        let out = p2q(&["eval", p, "--gt", g]);
        assert!(out.status.success());
        let table = String::from_utf8(out.stdout).unwrap();
        assert!(table.contains("undefined (empty prediction"), "{table}");
    }
    // A non-empty prediction is not flagged.
    let j = json_of(&p2q(&["eval", g, "--gt", g, "--json"]));
    assert_eq!(j.get("empty_prediction"), Some(&Json::Bool(false)));
    assert!(num(&j, "chamfer") > 0.0);
    // Malformed stays an error (exit 1, file and line named), as does an empty ground truth.
    for (name, bytes, line) in [
        ("binary.obj", &b"\x89PNG\r\n\x1a\n\0\0"[..], ":1:"),
        ("words.obj", b"# fine\nnot obj\n", ":2:"),
        ("headless.off", b"", "empty file"),
        ("lying.off", b"OFF\n2 0 0\n0 0 0\n", "truncated"),
        ("unterminated.ply", b"ply\nformat ascii 1.0\n", "header not terminated"),
    ] {
        let path = dir.path(name);
        std::fs::write(&path, bytes).unwrap();
        let out = p2q(&["eval", path.to_str().unwrap(), "--gt", g]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{name}: {err}");
        assert!(err.contains(path.to_str().unwrap()) && err.contains(line), "{name}: {err}");
        assert!(out.stdout.is_empty(), "{name}");
    }
    let zero = empties[1].0.to_str().unwrap();
    let svg = dir.path("zero.svg");
    for args in [vec!["eval", g, "--gt", zero], vec!["render", zero, "-o", svg.to_str().unwrap()]] {
        let out = p2q(&args);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {err}");
        assert!(err.contains(zero) && err.contains("no"), "{args:?}: {err}");
    }
    assert!(!svg.exists());
}

#[test]
fn eval_and_render_fail_cleanly_on_bad_usage() {
    let dir = Scratch::new("quality_bad_usage");
    let missing = dir.path("missing.obj");
    let out = p2q(&["eval", missing.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("missing.obj"));
    assert_eq!(p2q(&["eval"]).status.code(), Some(2));
    assert_eq!(p2q(&["eval", "a.obj", "--bogus"]).status.code(), Some(2));
    let m = dir.path("m.obj");
    write_obj(&m, &grid(2, 2));
    let svg = dir.path("m.svg");
    let (ms, ss) = (m.to_str().unwrap(), svg.to_str().unwrap());
    assert_eq!(p2q(&["render", ms]).status.code(), Some(2)); // no -o
    assert_eq!(p2q(&["render", ms, "-o", ss, "--view", "30"]).status.code(), Some(2));
    assert_eq!(p2q(&["render", ms, "-o", ss, "--view", "a,b"]).status.code(), Some(2));
    assert_eq!(p2q(&["render", ms, "-o", ss, "--width", "3"]).status.code(), Some(2));
    assert_eq!(p2q(&["render", ms, "-o", ss, "--up", "x"]).status.code(), Some(2));
    assert!(!svg.exists());
    assert!(p2q(&["eval", "--help"]).status.success());
    assert!(p2q(&["render", "--help"]).status.success());
}

#[test]
fn render_writes_a_well_formed_svg() {
    let dir = Scratch::new("quality_render");
    let m = torus(20, 10, 0.4);
    let (mp, sp) = (dir.path("t.obj"), dir.path("t.svg"));
    write_obj(&mp, &m);
    let out = p2q(&[
        "render",
        mp.to_str().unwrap(),
        "-o",
        sp.to_str().unwrap(),
        "--view",
        "45,35",
        "--width",
        "300",
        "--up",
        "z",
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let svg = std::fs::read_to_string(&sp).unwrap();
    let names = check_xml(&svg).unwrap();
    assert_eq!(names.iter().filter(|n| *n == "polygon").count(), m.faces.len());
    assert!(svg.contains("width=\"300\""));
}
