//! `point2quad eval` and `point2quad render` end to end: the JSON parses back (with a
//! parser written in tests/common) and agrees with the library, the table is readable,
//! the SVG is well formed, and bad usage fails cleanly.

#[path = "common/quality.rs"]
mod quality_common;

use std::process::{Command, Output};

use point2quad::mesh::quality::{compare, mesh_metrics};
use quality_common::{check_xml, grid, parse_json, temp_dir, torus, write_obj, Json};

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
    let dir = temp_dir("eval_json");
    let mut m = torus(16, 8, 0.4);
    // Perturb a little so the shape measures are not trivial, then open one face.
    for (i, p) in m.vertices.iter_mut().enumerate() {
        p[0] += 0.01 * ((i * 7 % 5) as f64 - 2.0);
    }
    m.faces.pop();
    let path = dir.join("pred.obj");
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
    let dir = temp_dir("eval_gt");
    let gt = grid(6, 4);
    let mut pred = gt.clone();
    pred.faces.truncate(18);
    let (gp, pp) = (dir.join("gt.obj"), dir.join("pred.obj"));
    write_obj(&gp, &gt);
    write_obj(&pp, &pred);
    let j =
        json_of(&p2q(&["eval", pp.to_str().unwrap(), "--gt", gp.to_str().unwrap(), "--json", "--seed", "4"]));
    assert_eq!(num(&j, "precision"), 1.0);
    assert_eq!(num(&j, "recall"), 0.75);
    let lib = compare(&pred, &gt, 4).unwrap();
    assert_eq!(num(&j, "chamfer"), lib.chamfer);
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
    let dir = temp_dir("eval_empty");
    let path = dir.join("points.obj");
    std::fs::write(&path, "v 0 0 0\nv 1 0 0\n").unwrap();
    let j = json_of(&p2q(&["eval", path.to_str().unwrap(), "--json"]));
    for k in KEYS.iter().filter(|k| **k != "quad_only") {
        assert_eq!(num(&j, k), 0.0, "{k}");
    }
}

#[test]
fn eval_and_render_fail_cleanly_on_bad_usage() {
    let dir = temp_dir("bad_usage");
    let missing = dir.join("missing.obj");
    let out = p2q(&["eval", missing.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("missing.obj"));
    assert_eq!(p2q(&["eval"]).status.code(), Some(2));
    assert_eq!(p2q(&["eval", "a.obj", "--bogus"]).status.code(), Some(2));
    let m = dir.join("m.obj");
    write_obj(&m, &grid(2, 2));
    let svg = dir.join("m.svg");
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
    let dir = temp_dir("render");
    let m = torus(20, 10, 0.4);
    let (mp, sp) = (dir.join("t.obj"), dir.join("t.svg"));
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
