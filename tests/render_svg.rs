//! SVG render tests: well-formed XML, one polygon per drawable face, boundary edges
//! red and non-manifold edges blue (counted against the edge valences), empty and
//! degenerate meshes, and painter's order.

#[path = "common/quality.rs"]
mod quality_common;

use point2quad::io::svg::{render_svg, RenderOptions, BOUNDARY_COLOR, NONMANIFOLD_COLOR};
use point2quad::mesh::poly::PolyMesh;
use point2quad::mesh::quality::mesh_metrics;
use proptest::prelude::*;
use quality_common::{attr_values, check_xml, cube, grid, torus};

fn no_bad_numbers(svg: &str) -> bool {
    !svg.contains("NaN") && !svg.contains("inf")
}

fn count_lines(svg: &str, class: &str, color: &str) -> usize {
    svg.lines()
        .filter(|l| l.starts_with("<line") && l.contains(&format!("class=\"{class}\"")) && l.contains(color))
        .count()
}

#[test]
fn open_grid_boundary_is_red_and_complete() {
    for (nu, nv) in [(1, 1), (4, 3), (10, 2)] {
        let m = grid(nu, nv);
        let svg = render_svg(&m, &RenderOptions::default());
        let names = check_xml(&svg).unwrap();
        assert_eq!(names.first().map(String::as_str), Some("svg"));
        assert_eq!(names.iter().filter(|n| *n == "polygon").count(), m.faces.len());
        assert_eq!(count_lines(&svg, "boundary", BOUNDARY_COLOR), 2 * (nu + nv) as usize);
        assert_eq!(count_lines(&svg, "nonmanifold", NONMANIFOLD_COLOR), 0);
        assert!(no_bad_numbers(&svg));
    }
}

#[test]
fn closed_torus_has_no_highlighted_edges_and_fits_the_view() {
    let m = torus(30, 14, 0.35);
    let opts = RenderOptions { width: 640, ..RenderOptions::default() };
    let svg = render_svg(&m, &opts);
    check_xml(&svg).unwrap();
    assert_eq!(attr_values(&svg, "polygon", "points").len(), m.faces.len());
    assert_eq!(svg.matches("<line").count(), 0);
    let height: f64 = attr_values(&svg, "svg", "height")[0].parse().unwrap();
    // Every polygon vertex lies inside the picture.
    for pts in attr_values(&svg, "polygon", "points") {
        for xy in pts.split(' ') {
            let (x, y) = xy.split_once(',').unwrap();
            let (x, y): (f64, f64) = (x.parse().unwrap(), y.parse().unwrap());
            assert!((0.0..=640.0).contains(&x) && (0.0..=height).contains(&y), "{x},{y}");
        }
    }
}

#[test]
fn nonmanifold_edge_is_blue() {
    // Three quads hinged on edge 0–1, plus a fourth: one non-manifold edge.
    let vertices = vec![
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
        [0.0, 1.0, 0.0],
        [1.0, -1.0, 0.0],
        [0.0, -1.0, 0.0],
        [1.0, 0.0, 1.0],
        [0.0, 0.0, 1.0],
    ];
    let m = PolyMesh { vertices, faces: vec![vec![0, 1, 2, 3], vec![1, 0, 5, 4], vec![0, 1, 6, 7]] };
    let svg = render_svg(&m, &RenderOptions::default());
    check_xml(&svg).unwrap();
    let mm = mesh_metrics(&m);
    assert_eq!(count_lines(&svg, "nonmanifold", NONMANIFOLD_COLOR), 1);
    assert_eq!(count_lines(&svg, "boundary", BOUNDARY_COLOR), mm.boundary_edges);
}

#[test]
fn empty_mesh_gives_a_valid_svg_with_a_note() {
    for m in [PolyMesh::default(), PolyMesh { vertices: vec![[0.0; 3]; 3], faces: vec![vec![0, 1]] }] {
        let svg = render_svg(&m, &RenderOptions::default());
        let names = check_xml(&svg).unwrap();
        assert!(names.contains(&"text".to_string()));
        assert!(svg.contains("empty mesh"));
        assert_eq!(svg.matches("<polygon").count(), 0);
    }
}

#[test]
fn degenerate_faces_draw_without_nan() {
    let z = [0.0; 3];
    let m = PolyMesh {
        vertices: vec![z, z, z, z, [1.0, 0.0, 0.0], [f64::NAN, 0.0, 0.0], [f64::INFINITY, 1.0, 1.0]],
        faces: vec![vec![0, 1, 2, 3], vec![0, 4, 4, 0], vec![0, 4, 5, 1], vec![0, 4, 6], vec![0, 4, 99, 1]],
    };
    let svg = render_svg(&m, &RenderOptions::default());
    check_xml(&svg).unwrap();
    assert!(no_bad_numbers(&svg), "{svg}");
    assert_eq!(svg.matches("<polygon").count(), 2); // the NaN, inf and bad-index faces are skipped
    assert!(svg.contains("3 faces not drawn"));
    // A single point (all vertices equal) still gives finite coordinates.
    let p = PolyMesh { vertices: vec![[5.0; 3]; 4], faces: vec![vec![0, 1, 2, 3]] };
    let svg =
        render_svg(&p, &RenderOptions { azimuth_deg: 1e300, elevation_deg: -1e300, ..Default::default() });
    check_xml(&svg).unwrap();
    assert!(no_bad_numbers(&svg));
}

#[test]
fn painter_order_draws_the_near_cube_face_last() {
    // Looking from +z (azimuth 0, elevation 0): the cube's z = 1 face is nearest.
    let m = cube([0.0; 3]);
    let opts = RenderOptions {
        azimuth_deg: 0.0,
        elevation_deg: 0.0,
        width: 100,
        height: Some(100),
        ..Default::default()
    };
    let svg = render_svg(&m, &opts);
    let pts = attr_values(&svg, "polygon", "points");
    let fills = attr_values(&svg, "polygon", "fill");
    assert_eq!(pts.len(), 6);
    // The near face is the whole projected square: drawn last, it spans the drawing's full
    // x extent; and it is lit brightest (it faces the viewer; the light is near the viewer).
    let xs = |p: &String| -> Vec<f64> {
        p.split(' ').map(|xy| xy.split_once(',').unwrap().0.parse().unwrap()).collect()
    };
    let all: Vec<f64> = pts.iter().flat_map(xs).collect();
    let last = xs(pts.last().unwrap());
    let range =
        |v: &[f64]| (v.iter().cloned().fold(f64::INFINITY, f64::min), v.iter().cloned().fold(0.0, f64::max));
    assert_eq!(range(&last), range(&all));
    let (lo, hi) = range(&all);
    assert!(lo >= 12.0 && hi <= 88.0 && hi - lo > 50.0, "{lo} {hi}");
    let brightness =
        |c: &str| u32::from_str_radix(&c[1..3], 16).unwrap() + u32::from_str_radix(&c[3..5], 16).unwrap();
    let front = brightness(fills.last().unwrap());
    assert!(fills.iter().all(|f| brightness(f) <= front));
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(32))]

    /// Random soups (any face sizes, coincident points): well-formed, one polygon per
    /// drawable face, highlighted edges counted as the metrics count them.
    #[test]
    fn random_soups_render_well_formed(
        pts in prop::collection::vec(prop::array::uniform3(-3.0f64..3.0), 1..10),
        raw in prop::collection::vec(prop::collection::vec(0u32..10, 3..6), 0..12),
        az in -360.0f64..360.0, el in -90.0f64..90.0,
    ) {
        let n = pts.len() as u32;
        let faces: Vec<Vec<u32>> = raw.iter().map(|f| f.iter().map(|v| v % n).collect()).collect();
        let m = PolyMesh { vertices: pts, faces };
        let svg = render_svg(&m, &RenderOptions { azimuth_deg: az, elevation_deg: el, ..Default::default() });
        prop_assert!(check_xml(&svg).is_ok(), "{:?}", check_xml(&svg));
        prop_assert!(no_bad_numbers(&svg));
        prop_assert_eq!(svg.matches("<polygon").count(), m.faces.len());
        let mm = mesh_metrics(&m);
        prop_assert_eq!(count_lines(&svg, "boundary", BOUNDARY_COLOR), mm.boundary_edges);
        prop_assert_eq!(count_lines(&svg, "nonmanifold", NONMANIFOLD_COLOR), mm.nonmanifold_edges);
    }
}
