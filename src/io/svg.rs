//! SVG pictures of meshes, as people look at meshes: an orthographic view, faces
//! drawn back to front (painter's order) with Lambert shading, back faces dimmed,
//! thin dark face edges, and boundary (red) and non-manifold (blue) edges on top.
//! [`render_svg`] is pure (a `String`); [`write_svg`] puts it in a file atomically.

use std::fmt::Write as _;
use std::path::Path;

use crate::error::{Error, Result};
use crate::io::atomic::{prepare_atomic, Staged};
use crate::math::{add, cross, dot, normalize, scale};
use crate::mesh::poly::PolyMesh;
use crate::mesh::quality::edge_uses;

/// How to draw a mesh.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderOptions {
    /// Viewer direction around the up axis, in degrees; 0 looks from +z (from −y when
    /// `z_up`), 90 from +x.
    pub azimuth_deg: f64,
    /// Viewer height above the horizontal plane, in degrees (90 looks down the up axis).
    pub elevation_deg: f64,
    /// Picture width in pixels.
    pub width: u32,
    /// Picture height in pixels; `None` fits the mesh's projected aspect ratio
    /// (between 0.3 and 2 times the width).
    pub height: Option<u32>,
    /// Treat +z as up instead of +y (the azimuth then turns around z).
    pub z_up: bool,
    /// Draw the edges of every face (thin, dark). Boundary and non-manifold edges
    /// are always drawn.
    pub face_edges: bool,
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions {
            azimuth_deg: 30.0,
            elevation_deg: 20.0,
            width: 800,
            height: None,
            z_up: false,
            face_edges: true,
        }
    }
}

/// Colour of boundary edges (edges with one face).
pub const BOUNDARY_COLOR: &str = "#e0201b";
/// Colour of non-manifold edges (edges with more than two faces).
pub const NONMANIFOLD_COLOR: &str = "#1f50e0";
const FACE_EDGE_COLOR: &str = "#202428";
const FRONT_RGB: [f64; 3] = [168.0, 192.0, 232.0];
const BACK_RGB: [f64; 3] = [150.0, 128.0, 110.0];
const MARGIN: f64 = 12.0;
/// Height of the caption strip under the drawing.
const CAPTION: f64 = 16.0;

/// The viewer's frame: `right` and `up` span the picture, `toward` points at the viewer.
struct View {
    right: [f64; 3],
    up: [f64; 3],
    toward: [f64; 3],
}

impl View {
    /// The view of a z-up world: the y-up view of the world turned by (x, y, z) ↦
    /// (x, z, −y), which maps its vectors (a, b, c) back to (a, −c, b).
    fn new_up(azimuth_deg: f64, elevation_deg: f64, z_up: bool) -> View {
        let v = View::new(azimuth_deg, elevation_deg);
        if !z_up {
            return v;
        }
        let back = |w: [f64; 3]| [w[0], -w[2], w[1]];
        View { right: back(v.right), up: back(v.up), toward: back(v.toward) }
    }

    fn new(azimuth_deg: f64, elevation_deg: f64) -> View {
        let (az, el) = (azimuth_deg.to_radians(), elevation_deg.to_radians());
        let (az, el) = (if az.is_finite() { az } else { 0.0 }, if el.is_finite() { el } else { 0.0 });
        let toward = [el.cos() * az.sin(), el.sin(), el.cos() * az.cos()];
        // Looking straight down or up the y axis leaves the azimuth to orient the picture.
        let right = normalize(cross([0.0, 1.0, 0.0], toward)).unwrap_or([az.cos(), 0.0, -az.sin()]);
        let up = cross(toward, right);
        View { right, up, toward }
    }
}

fn rgb(c: [f64; 3], k: f64) -> String {
    let ch = |x: f64| (x * k).round().clamp(0.0, 255.0) as u8;
    format!("#{:02x}{:02x}{:02x}", ch(c[0]), ch(c[1]), ch(c[2]))
}

/// Newell's normal of a polygon (robust for non-planar and concave faces).
fn newell(p: &[[f64; 3]]) -> Option<[f64; 3]> {
    let mut n = [0.0; 3];
    for i in 0..p.len() {
        let (a, b) = (p[i], p[(i + 1) % p.len()]);
        n[0] += (a[1] - b[1]) * (a[2] + b[2]);
        n[1] += (a[2] - b[2]) * (a[0] + b[0]);
        n[2] += (a[0] - b[0]) * (a[1] + b[1]);
    }
    normalize(n)
}

/// Draws `mesh` as an SVG document (see the module header for the look). Faces with
/// fewer than 3 vertices, an index out of range or a non-finite coordinate are not
/// drawn (an XML comment says how many). A mesh with nothing to draw gives a valid
/// SVG with a note. The output contains no NaN and does not depend on the thread
/// count.
pub fn render_svg(mesh: &PolyMesh, opts: &RenderOptions) -> String {
    let width = f64::from(opts.width.max(16));
    let finite = |v: u32| mesh.vertices.get(v as usize).filter(|p| p.iter().all(|c| c.is_finite()));
    let drawn: Vec<usize> = (0..mesh.faces.len())
        .filter(|&f| mesh.faces[f].len() >= 3 && mesh.faces[f].iter().all(|&v| finite(v).is_some()))
        .collect();
    let skipped = mesh.faces.len() - drawn.len();
    let mut svg = String::new();

    if drawn.is_empty() {
        let height = f64::from(opts.height.unwrap_or(opts.width / 2).max(16));
        header(&mut svg, width, height, mesh.faces.len());
        let _ = writeln!(
            svg,
            "<text x=\"{:.1}\" y=\"{:.1}\" font-family=\"sans-serif\" font-size=\"16\" \
             text-anchor=\"middle\" fill=\"#555555\">empty mesh: no face to draw ({} faces, {} skipped)</text>",
            width / 2.0,
            height / 2.0,
            mesh.faces.len(),
            skipped
        );
        svg.push_str("</svg>\n");
        return svg;
    }

    let view = View::new_up(opts.azimuth_deg, opts.elevation_deg, opts.z_up);
    // Project every vertex that a drawn face uses.
    let mut used = vec![false; mesh.vertices.len()];
    for &f in &drawn {
        for &v in &mesh.faces[f] {
            used[v as usize] = true;
        }
    }
    // The picture does not depend on the mesh's scale (it is fitted below), so work on
    // coordinates divided by the largest one drawn: a finite mesh at 1e300 would
    // otherwise overflow in the projection and the normals and print NaN sizes.
    let size = mesh
        .vertices
        .iter()
        .zip(&used)
        .filter(|(_, u)| **u)
        .flat_map(|(p, _)| p.iter())
        .fold(0.0f64, |m, c| m.max(c.abs()));
    let unit = |p: [f64; 3]| if size > 0.0 { p.map(|c| c / size) } else { p };
    let proj: Vec<[f64; 3]> = mesh
        .vertices
        .iter()
        .map(|&p| {
            let p = unit(p);
            [dot(p, view.right), dot(p, view.up), dot(p, view.toward)]
        })
        .collect();
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for (p, _) in proj.iter().zip(&used).filter(|(_, u)| **u) {
        for k in 0..2 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let extent = [hi[0] - lo[0], hi[1] - lo[1]];
    // The picture is the drawing area plus a caption strip at the bottom.
    let height = match opts.height {
        Some(h) => f64::from(h.max(16)),
        None if extent[0] > 0.0 => (((width - 2.0 * MARGIN) * extent[1] / extent[0] + 2.0 * MARGIN)
            .clamp(0.3 * width, 2.0 * width)
            + CAPTION)
            .round(),
        None => width + CAPTION,
    };
    let area = (height - CAPTION).max(2.0 * MARGIN + 1.0);
    let fit_x = if extent[0] > 0.0 { (width - 2.0 * MARGIN) / extent[0] } else { f64::INFINITY };
    let fit_y = if extent[1] > 0.0 { (area - 2.0 * MARGIN) / extent[1] } else { f64::INFINITY };
    let s = if fit_x.min(fit_y).is_finite() { fit_x.min(fit_y) } else { 1.0 };
    // Centre the drawing in the picture; SVG's y grows downwards.
    let (cx, cy) = (0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]));
    let px = |p: [f64; 3]| -> (f64, f64) { (width / 2.0 + (p[0] - cx) * s, area / 2.0 - (p[1] - cy) * s) };

    // Painter's order: farthest (smallest depth towards the viewer) first; ties by index.
    let depth = |f: usize| {
        let face = &mesh.faces[f];
        face.iter().map(|&v| proj[v as usize][2]).sum::<f64>() / face.len() as f64
    };
    let mut order: Vec<(f64, usize)> = drawn.iter().map(|&f| (depth(f), f)).collect();
    order.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));

    // Stroke width follows the typical projected edge length, so dense meshes stay readable.
    let mut lens: Vec<f64> = drawn
        .iter()
        .map(|&f| {
            let (a, b) = (mesh.faces[f][0] as usize, mesh.faces[f][1] as usize);
            ((proj[a][0] - proj[b][0]).hypot(proj[a][1] - proj[b][1])) * s
        })
        .collect();
    lens.sort_by(f64::total_cmp);
    let stroke = (0.06 * lens[lens.len() / 2]).clamp(0.15, 1.0);

    let light = normalize(add(add(view.toward, scale(view.up, 0.7)), scale(view.right, -0.5)))
        .expect("internal error: the light direction is a sum of orthonormal vectors");

    header(&mut svg, width, height, mesh.faces.len());
    if skipped > 0 {
        let _ = writeln!(
            svg,
            "<!-- {skipped} faces not drawn: fewer than 3 vertices, bad index or non-finite -->"
        );
    }
    let edge_stroke = if opts.face_edges { FACE_EDGE_COLOR } else { "none" };
    let _ =
        writeln!(svg, "<g stroke=\"{edge_stroke}\" stroke-width=\"{stroke:.2}\" stroke-linejoin=\"round\">");
    let mut pts: Vec<[f64; 3]> = Vec::new();
    for &(_, f) in &order {
        pts.clear();
        pts.extend(mesh.faces[f].iter().map(|&v| unit(mesh.vertices[v as usize])));
        let fill = match newell(&pts) {
            Some(n) if dot(n, view.toward) >= 0.0 => rgb(FRONT_RGB, 0.35 + 0.65 * dot(n, light).max(0.0)),
            Some(n) => rgb(BACK_RGB, 0.25 + 0.35 * (-dot(n, light)).max(0.0)),
            None => rgb(BACK_RGB, 0.3),
        };
        svg.push_str("<polygon points=\"");
        for (i, &v) in mesh.faces[f].iter().enumerate() {
            let (x, y) = px(proj[v as usize]);
            let _ = write!(svg, "{}{x:.1},{y:.1}", if i == 0 { "" } else { " " });
        }
        let _ = writeln!(svg, "\" fill=\"{fill}\"/>");
    }
    svg.push_str("</g>\n");

    // Boundary and non-manifold edges, over everything (hidden ones too: defects must show).
    let edges = edge_uses(&PolyMesh {
        vertices: Vec::new(),
        faces: drawn.iter().map(|&f| mesh.faces[f].clone()).collect(),
    });
    let (mut boundary, mut nonmanifold) = (0usize, 0usize);
    let _ = writeln!(svg, "<g stroke-width=\"{:.2}\" stroke-linecap=\"round\">", (3.0 * stroke).max(1.2));
    for e in &edges {
        let (class, color) = match e.faces {
            1 => ("boundary", BOUNDARY_COLOR),
            2 => continue,
            _ => ("nonmanifold", NONMANIFOLD_COLOR),
        };
        if e.faces == 1 {
            boundary += 1;
        } else {
            nonmanifold += 1;
        }
        let (x1, y1) = px(proj[e.verts[0] as usize]);
        let (x2, y2) = px(proj[e.verts[1] as usize]);
        let _ = writeln!(
            svg,
            "<line class=\"{class}\" stroke=\"{color}\" x1=\"{x1:.1}\" y1=\"{y1:.1}\" x2=\"{x2:.1}\" y2=\"{y2:.1}\"/>"
        );
    }
    svg.push_str("</g>\n");
    let _ = writeln!(
        svg,
        "<text x=\"6\" y=\"{:.1}\" font-family=\"sans-serif\" font-size=\"11\" fill=\"#444444\">{} faces, \
         {boundary} boundary edges (red), {nonmanifold} non-manifold edges (blue)</text>",
        height - 5.0,
        drawn.len()
    );
    svg.push_str("</svg>\n");
    svg
}

/// Renders `mesh` with [`render_svg`] and writes the picture to `path` atomically
/// (a temporary file renamed over `path`, so a failed write leaves no half file).
///
/// # Errors
/// `Io` naming `path` when the file cannot be written.
pub fn write_svg(path: &Path, mesh: &PolyMesh, opts: &RenderOptions) -> Result<()> {
    prepare_svg(path, mesh, opts)?.commit()
}

/// [`write_svg`] up to the rename (see [`crate::io::atomic::prepare_atomic`]).
///
/// # Errors
/// As [`write_svg`].
pub fn prepare_svg(path: &Path, mesh: &PolyMesh, opts: &RenderOptions) -> Result<Staged> {
    let svg = render_svg(mesh, opts);
    prepare_atomic(path, |w| w.write_all(svg.as_bytes()).map_err(|e| Error::io(path, e)))
}

fn header(svg: &mut String, width: f64, height: f64, faces: usize) {
    let _ = writeln!(svg, "<?xml version=\"1.0\" encoding=\"UTF-8\"?>");
    let _ = writeln!(
        svg,
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{width:.0}\" height=\"{height:.0}\" \
         viewBox=\"0 0 {width:.0} {height:.0}\">"
    );
    let _ = writeln!(svg, "<title>point2quad render: {faces} faces</title>");
    let _ = writeln!(svg, "<rect width=\"100%\" height=\"100%\" fill=\"#ffffff\"/>");
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square_pair() -> PolyMesh {
        PolyMesh {
            vertices: vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [1.0, 1.0, 0.0],
                [0.0, 1.0, 0.0],
                [2.0, 0.0, 0.0],
                [2.0, 1.0, 0.0],
            ],
            faces: vec![vec![0, 1, 2, 3], vec![1, 4, 5, 2]],
        }
    }

    #[test]
    fn draws_one_polygon_per_face_and_marks_boundary() {
        let svg = render_svg(&square_pair(), &RenderOptions::default());
        assert_eq!(svg.matches("<polygon").count(), 2);
        assert_eq!(svg.matches("class=\"boundary\"").count(), 6);
        assert_eq!(svg.matches("class=\"nonmanifold\"").count(), 0);
        assert!(!svg.contains("NaN") && !svg.contains("inf"));
    }

    #[test]
    fn front_and_back_faces_are_shaded_differently() {
        let mut m = square_pair();
        m.faces[1].reverse();
        let svg =
            render_svg(&m, &RenderOptions { azimuth_deg: 0.0, elevation_deg: 0.0, ..Default::default() });
        let fills: Vec<&str> = svg.split("fill=\"").skip(2).map(|s| &s[..7]).take(2).collect();
        assert_eq!(fills.len(), 2);
        assert_ne!(fills[0], fills[1]);
    }

    /// Regression: a finite mesh with 1e308 coordinates overflowed in the projection
    /// and wrote `height="NaN"` and NaN polygon points.
    #[test]
    fn huge_and_tiny_coordinates_render_without_nan() {
        for k in [1e308, 1e200, 1e-200, 5e-324] {
            let mut m = square_pair();
            for p in &mut m.vertices {
                *p = p.map(|c| (c - 0.5) * k);
            }
            let svg = render_svg(&m, &RenderOptions::default());
            assert!(!svg.contains("NaN") && !svg.contains("inf"), "{k}: {svg}");
            assert_eq!(svg.matches("<polygon").count(), 2, "{k}");
        }
        // Stretched to 1e300 along x and moved off the origin: still drawn, no NaN.
        let near = render_svg(&square_pair(), &RenderOptions::default());
        let mut far = square_pair();
        for p in &mut far.vertices {
            p[0] = p[0] * 1e300 + 1e300;
        }
        let svg = render_svg(&far, &RenderOptions::default());
        assert!(!svg.contains("NaN") && !svg.contains("inf"), "{svg}");
        assert_eq!(svg.matches("<polygon").count(), near.matches("<polygon").count());
    }

    #[test]
    fn view_frame_is_orthonormal_even_looking_straight_down() {
        for (az, el, z_up) in
            [(30.0, 20.0, false), (0.0, 90.0, true), (123.0, -90.0, false), (f64::NAN, 1.0, true)]
        {
            let v = View::new_up(az, el, z_up);
            assert!((dot(cross(v.right, v.up), v.toward) - 1.0).abs() < 1e-12, "right-handed");
            for (a, b) in [(v.right, v.up), (v.up, v.toward), (v.toward, v.right)] {
                assert!(dot(a, b).abs() < 1e-12);
            }
            for a in [v.right, v.up, v.toward] {
                assert!((dot(a, a) - 1.0).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn z_up_looks_up_the_z_axis() {
        let v = View::new_up(0.0, 0.0, true);
        assert!((v.up[2] - 1.0).abs() < 1e-12);
        assert!((v.toward[1] + 1.0).abs() < 1e-12);
        let v = View::new_up(0.0, 90.0, true);
        assert!((v.toward[2] - 1.0).abs() < 1e-12);
    }
}
