//! `point2quad repair` end to end: a soup made from a generated mesh (faces dropped, wrong
//! and duplicated quads added, a triangle) is repaired into a valid mesh; errors are clear.

#[path = "common/halfedge.rs"]
mod common;
#[path = "common/scratch.rs"]
mod scratch;

use std::process::Command;

use common::*;
use point2quad::io::mesh_io::{read_mesh, write_mesh};
use point2quad::mesh::halfedge::HalfedgeMesh;
use point2quad::mesh::poly::PolyMesh;
use point2quad::mesh::validate::validate;
use point2quad::rng::Rng;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_point2quad"))
}

#[test]
fn repair_turns_a_soup_into_a_valid_mesh() {
    let s = scratch::Scratch::new("repair");
    let m = from_shape("cube_sphere", point2quad::mesh::shapes::cube_sphere(4));
    let mut rng = Rng::new(3);
    let (faces, _) = random_soup(&m, &mut rng, 0.05, 30);
    let mut poly =
        PolyMesh { vertices: m.positions.clone(), faces: faces.iter().map(|f| f.to_vec()).collect() };
    poly.faces.push(vec![0, 1, 2]);
    let input = s.path("soup.obj");
    write_mesh(&input, &poly).unwrap();
    let out = s.path("out.ply");

    let r = bin().args(["repair", input.to_str().unwrap(), "-o", out.to_str().unwrap()]).output().unwrap();
    assert!(!r.status.success());
    let err = String::from_utf8_lossy(&r.stderr);
    assert!(err.contains("has 3 vertices") && err.contains("--drop-non-quads"), "{err}");
    assert!(!out.exists());

    let r = bin()
        .args(["repair", input.to_str().unwrap(), "-o", out.to_str().unwrap(), "--drop-non-quads"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&r.stderr);
    assert!(r.status.success(), "{err}");
    assert!(err.contains("inserted") && err.contains("hole filling"), "{err}");
    let res = read_mesh(&out).unwrap();
    assert_eq!(&res.vertices[..m.positions.len()], &m.positions[..]);
    let q = res.to_quads().unwrap();
    let h = HalfedgeMesh::from_quads(q.vertices.len(), &q.quads).unwrap();
    validate(&h).unwrap();
    assert!(h.n_faces() > m.quads.len() / 2, "{err}");
}

#[test]
fn repair_usage_errors() {
    let s = scratch::Scratch::new("repair");
    let r = bin().args(["repair", "--help"]).output().unwrap();
    assert!(r.status.success());
    assert!(String::from_utf8_lossy(&r.stdout).contains("--drop-non-quads"));
    let r = bin().args(["repair", "x.obj"]).output().unwrap();
    assert_eq!(r.status.code(), Some(2));
    let r = bin().args(["repair", "x.obj", "-o", "y.obj", "--priority", "bogus"]).output().unwrap();
    assert_eq!(r.status.code(), Some(2));
    let r = bin()
        .args(["repair", "/nonexistent/x.obj", "-o", s.path("y.obj").to_str().unwrap()])
        .output()
        .unwrap();
    assert_eq!(r.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&r.stderr).contains("/nonexistent/x.obj"));
}

/// Regression: `repair` kept zero-area quads (every topological check passes them). A
/// valid grid plus a quad with all four corners at one point, a collinear quad and a
/// triangle-shaped quad (two corners at one position), all on their own vertices: the
/// three are dropped and counted in the summary line, the grid is kept whole, and the
/// output has no degenerate quad by the metrics' own count.
#[test]
fn repair_drops_zero_area_quads_and_counts_them() {
    let s = scratch::Scratch::new("repair");
    use point2quad::mesh::quality::{is_degenerate_quad, mesh_metrics};
    let g = point2quad::mesh::shapes::grid(4, 3, 4.0, 3.0);
    let mut poly = PolyMesh::from(&g);
    let n = poly.vertices.len() as u32;
    poly.vertices.extend([[9.0, 9.0, 9.0]; 4]);
    poly.vertices.extend((0..4).map(|i| [10.0 + i as f64, 0.5 * i as f64, 1.0]));
    poly.vertices.extend([[0.0, 5.0, 0.0], [1.0, 5.0, 0.0], [1.0, 5.0, 0.0], [0.0, 6.0, 0.0]]);
    for k in 0..3 {
        poly.faces.push((0..4).map(|i| n + 4 * k + i).collect());
    }
    let input = s.path("zero_area.obj");
    write_mesh(&input, &poly).unwrap();
    let out = s.path("zero_area_out.obj");
    let r = bin().args(["repair", input.to_str().unwrap(), "-o", out.to_str().unwrap()]).output().unwrap();
    let err = String::from_utf8_lossy(&r.stderr);
    assert!(r.status.success(), "{err}");
    assert!(err.contains("zero-area dropped 3"), "{err}");
    let res = read_mesh(&out).unwrap();
    assert_eq!(res.vertices, poly.vertices);
    assert_eq!(res.faces.len(), g.quads.len(), "{err}");
    assert_eq!(mesh_metrics(&res).degenerate_quads, 0);
    let q = res.to_quads().unwrap();
    assert!(q.quads.iter().all(|f| !is_degenerate_quad(&f.map(|v| q.vertices[v as usize]))));
    validate(&HalfedgeMesh::from_quads(q.vertices.len(), &q.quads).unwrap()).unwrap();
}

/// A wrong quad over the diagonal of two true ones leaves two triangle holes, which no
/// quad can close on its own: `repair` pairs them through that quad and restores the
/// true pair; `--no-close` leaves them open; a small separate part stays.
#[test]
fn repair_pairs_odd_holes_unless_told_not_to() {
    let s = scratch::Scratch::new("repair");
    let g = point2quad::mesh::shapes::grid(4, 3, 4.0, 3.0);
    let id = |i: u32, j: u32| j * 5 + i;
    let (a, b, c, d, e, f) = (id(1, 1), id(2, 1), id(3, 1), id(3, 2), id(2, 2), id(1, 2));
    let key = |q: &[u32]| {
        let mut k = q.to_vec();
        k.sort_unstable();
        k
    };
    let dropped = [key(&[a, b, e, f]), key(&[b, c, d, e])];
    let mut poly = PolyMesh {
        vertices: g.vertices.clone(),
        faces: g.quads.iter().map(|q| q.to_vec()).filter(|q| !dropped.contains(&key(q))).collect(),
    };
    poly.faces.push(vec![a, b, d, e]);
    // A lone quad elsewhere: repair keeps a user's small parts.
    let n = poly.vertices.len() as u32;
    poly.vertices.extend([[10.0, 0.0, 0.0], [11.0, 0.0, 0.0], [11.0, 1.0, 0.0], [10.0, 1.0, 0.0]]);
    poly.faces.push(vec![n, n + 1, n + 2, n + 3]);
    let input = s.path("diag.obj");
    write_mesh(&input, &poly).unwrap();
    let faces_of = |extra: &[&str]| {
        let out = s.path("diag_out.obj");
        let mut args = vec!["repair", input.to_str().unwrap(), "-o", out.to_str().unwrap()];
        args.extend_from_slice(extra);
        let r = bin().args(&args).output().unwrap();
        let err = String::from_utf8_lossy(&r.stderr);
        assert!(r.status.success(), "{err}");
        let closing = extra.is_empty();
        assert_eq!(err.contains("closing: 1 loops closed with 2 quads, 1 faces taken out"), closing, "{err}");
        let q = read_mesh(&out).unwrap().to_quads().unwrap();
        validate(&HalfedgeMesh::from_quads(q.vertices.len(), &q.quads).unwrap()).unwrap();
        let mut k: Vec<Vec<u32>> = q.quads.iter().map(|f| key(f)).collect();
        k.sort();
        k
    };
    let mut want: Vec<Vec<u32>> = g.quads.iter().map(|f| key(f)).collect();
    want.push(vec![n, n + 1, n + 2, n + 3]);
    want.sort();
    assert_eq!(faces_of(&[]), want);
    let open = faces_of(&["--no-close"]);
    // The two true quads stay out, the diagonal one and the lone quad stay in.
    assert!(open.contains(&key(&[a, b, d, e])) && open.len() == g.quads.len(), "{open:?}");
}
