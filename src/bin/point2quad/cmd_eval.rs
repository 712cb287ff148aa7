//! `point2quad eval`: the quality metrics of a mesh (DESIGN §7) and, with `--gt`,
//! its accuracy against a ground-truth mesh; a table, or one JSON object with `--json`.

use std::fmt::Write as _;
use std::path::Path;

use crate::args::{Args, Spec};
use point2quad::io::mesh_io::{read_mesh, read_mesh_allow_empty};
use point2quad::mesh::quality::{compare, mesh_metrics, GtMetrics, MeshMetrics};
use point2quad::{Error, Result};

/// The text of `point2quad eval --help`.
pub const HELP: &str = "\
point2quad eval: mesh quality and accuracy metrics (DESIGN §7)

USAGE:
    point2quad eval PRED [--gt GT] [--json] [--seed S]

ARGS:
    PRED          the mesh to measure (.obj .ply .off; any polygons)
    --gt GT       ground-truth mesh: adds Chamfer distance (the paper's sum of both
                  one-sided means over 10,000 area-weighted samples per mesh, in units of
                  GT's bounding-box diagonal) and face precision / recall (vertices matched
                  within 1e-5 of GT's bounding-box diagonal)
    --json        print one JSON object instead of a table
    --seed S      seed of the Chamfer sampling (default 0)

Shape measures (scaled Jacobian, edge ratio, angle deviation) use quad faces only;
other faces are counted. Edges are the undirected sides of the faces.

An empty PRED (no faces: vertices only, or a well-formed file with nothing in it) is
scored, not refused: every count is 0, quad-only is vacuously true, watertightness
and manifoldness are 0 (0 of 0 edges; an empty output must never score as perfect),
and the shape means are 0. With --gt: precision 0 (0 of 0 faces, scored 0), recall 0,
and Chamfer undefined (the distance to an empty surface is unbounded): `null` in
--json, with \"empty_prediction\": true, and a note on stderr. GT must have faces.
";

/// Runs `point2quad eval` on its arguments (after the subcommand name).
///
/// # Errors
/// `Usage` for bad arguments; read, parse and write errors naming the file.
pub fn run(argv: &[String]) -> Result<()> {
    let spec = Spec { valued: &["--gt", "--seed"], switches: &["--json"] };
    let args = Args::parse("eval", argv, &spec)?;
    let pred_path = &args.expect_positional("eval", 1, "one mesh PRED")?[0];
    let seed: u64 = args.parsed("eval", "--seed", 0)?;
    // An empty prediction is a result to score (see HELP); the ground truth is not.
    let pred = read_mesh_allow_empty(Path::new(pred_path))?;
    let metrics = mesh_metrics(&pred);
    let gt = match args.value("--gt") {
        Some(g) => {
            let gt = read_mesh(Path::new(g))?;
            // A predicted mesh is pure quad: a ground-truth face that is not a quad with
            // four distinct corners can never be matched, so recall cannot reach 1.
            let odd: Vec<usize> = (0..gt.faces.len())
                .filter(|&f| {
                    let c = &gt.faces[f];
                    c.len() != 4 || (0..4).any(|i| c[i + 1..].contains(&c[i]))
                })
                .collect();
            if let Some(&first) = odd.first() {
                crate::output::note!(
                    "point2quad eval: note: {g}: {} of its {} faces are not quads with four distinct \
                     corners (the first is face {first}, counting from 0, with {} corners); they count \
                     in recall, and no predicted quad can match them",
                    odd.len(),
                    gt.faces.len(),
                    gt.faces[first].len()
                );
            }
            // The library's message says "ground-truth" or "predicted"; name the files.
            Some(compare(&pred, &gt, seed).map_err(|e| match e {
                Error::InvalidInput(m) => Error::InvalidInput(format!("{pred_path} against {g}: {m}")),
                other => other,
            })?)
        }
        None => None,
    };
    if gt.as_ref().is_some_and(|g| g.empty_prediction) {
        crate::output::note!(
            "point2quad eval: note: {pred_path} has no faces to sample (empty prediction): \
             precision 0, recall 0, Chamfer undefined"
        );
    }
    if args.switch("--json") {
        crate::output::stdout(&format!("{}\n", to_json(&metrics, gt.as_ref())))?;
    } else {
        crate::output::stdout(&to_table(pred_path, &metrics, gt.as_ref()))?;
    }
    Ok(())
}

/// A JSON number; the metrics are finite by construction, `null` guards the impossible.
fn num(x: f64) -> String {
    if x.is_finite() {
        format!("{x}")
    } else {
        "null".into()
    }
}

/// A JSON number, or `null` for an undefined value (Chamfer of an empty prediction).
fn opt_num(x: Option<f64>) -> String {
    x.map_or_else(|| "null".into(), num)
}

/// One JSON object (keys of DESIGN §7 first, then the extra counts).
fn to_json(m: &MeshMetrics, gt: Option<&GtMetrics>) -> String {
    let mut fields: Vec<(&str, String)> = vec![
        ("faces", m.faces.to_string()),
        ("quad_only", m.quad_only.to_string()),
        ("boundary_edges", m.boundary_edges.to_string()),
        ("boundary_loops", m.boundary_loops.to_string()),
        ("odd_boundary_loops", m.odd_boundary_loops.to_string()),
        ("nonmanifold_edges", m.nonmanifold_edges.to_string()),
        ("nonmanifold_vertices", m.nonmanifold_vertices.to_string()),
        ("watertightness", num(m.watertightness)),
        ("manifoldness", num(m.manifoldness)),
        ("scaled_jacobian", num(m.scaled_jacobian)),
        ("edge_ratio", num(m.edge_ratio)),
        ("angle_dev_deg", num(m.angle_dev_deg)),
        ("angle_rms_deg", num(m.angle_rms_deg)),
        ("vertices", m.vertices.to_string()),
        ("unreferenced_vertices", m.unreferenced_vertices.to_string()),
        ("quads", m.quads.to_string()),
        ("non_quad_faces", m.non_quad_faces.to_string()),
        ("edges", m.edges.to_string()),
        ("degenerate_quads", m.degenerate_quads.to_string()),
        ("scaled_jacobian_min", num(m.scaled_jacobian_min)),
        ("inverted_quads", m.inverted_quads.to_string()),
    ];
    if let Some(g) = gt {
        fields.extend([
            ("chamfer", opt_num(g.chamfer)),
            ("chamfer_pred_to_gt", opt_num(g.chamfer_pred_to_gt)),
            ("chamfer_gt_to_pred", opt_num(g.chamfer_gt_to_pred)),
            ("precision", num(g.precision)),
            ("recall", num(g.recall)),
            ("matched_vertices", g.matched_vertices.to_string()),
            ("empty_prediction", g.empty_prediction.to_string()),
        ]);
    }
    let body: Vec<String> = fields.iter().map(|(k, v)| format!("\"{k}\": {v}")).collect();
    format!("{{{}}}", body.join(", "))
}

fn to_table(path: &str, m: &MeshMetrics, gt: Option<&GtMetrics>) -> String {
    let mut s = String::new();
    let mut row = |k: &str, v: String| {
        let _ = writeln!(s, "  {k:<24} {v}");
    };
    row("mesh", path.to_string());
    row("vertices", format!("{} ({} unreferenced)", m.vertices, m.unreferenced_vertices));
    row("faces", format!("{} ({} quads, {} other)", m.faces, m.quads, m.non_quad_faces));
    row("quad only", if m.quad_only { "yes" } else { "no" }.into());
    row("edges", m.edges.to_string());
    row("boundary edges", m.boundary_edges.to_string());
    row(
        "boundary loops",
        format!("{} ({} odd: not closable by quads alone)", m.boundary_loops, m.odd_boundary_loops),
    );
    row("non-manifold edges", m.nonmanifold_edges.to_string());
    row("non-manifold vertices", m.nonmanifold_vertices.to_string());
    row("watertightness", format!("{:.4}", m.watertightness));
    row("manifoldness", format!("{:.4}", m.manifoldness));
    row(
        "scaled Jacobian",
        format!(
            "{:.4} mean, {:.4} min, {} quads <= 0",
            m.scaled_jacobian, m.scaled_jacobian_min, m.inverted_quads
        ),
    );
    row("edge ratio (max/min)", format!("{:.4} mean", m.edge_ratio));
    row("angle |θ−90°|", format!("{:.3}° mean, {:.3}° RMS", m.angle_dev_deg, m.angle_rms_deg));
    row("degenerate quads", m.degenerate_quads.to_string());
    if let Some(g) = gt {
        let chamfer = match (g.chamfer, g.chamfer_pred_to_gt, g.chamfer_gt_to_pred) {
            (Some(c), Some(p2g), Some(g2p)) => format!("{c:.6} (pred→GT {p2g:.6} + GT→pred {g2p:.6})"),
            _ => "undefined (empty prediction: no faces to sample)".into(),
        };
        row("Chamfer (/ GT diagonal)", chamfer);
        row("face precision", format!("{:.4}", g.precision));
        row("face recall", format!("{:.4}", g.recall));
        row("matched vertices", g.matched_vertices.to_string());
    }
    s
}
