//! `point2quad repair`: the post-process (paper's score filter, manifold insertion,
//! hole filling) applied to a quad mesh or face soup from a file; reports on stderr.

use std::path::Path;

use crate::args::{Args, Spec};
use crate::output::say;
use point2quad::io::mesh_io::{read_mesh, write_mesh, MeshFormat};
use point2quad::mesh::poly::PolyMesh;
use point2quad::mesh::postprocess::{postprocess, PostprocessConfig};
use point2quad::mesh::watertight::{close_all, WatertightConfig};
use point2quad::{Error, Result};

pub const HELP: &str = "\
point2quad repair: make a pure-quad, oriented, manifold mesh out of a quad mesh or face soup

USAGE:
    point2quad repair MESH -o OUT.{obj,ply,off} [OPTIONS]

MESH is an .obj, .off or .ply file whose faces may overlap, repeat or be non-manifold.
First, quads that repeat a vertex (\"degenerate\") or have no area (\"zero-area\": two
corners at one position, all four at one point, or all on one line; within 1e-12 of
the quad's size) are dropped and counted. Steps: (a) the paper's filter deletes the
worst-scoring face while any face scores above the limit (score (boundary edges +
1)(10 non-manifold edges + 1)); (b) the survivors are inserted by priority, refusing
any face that would break manifoldness (opposite-oriented patches are flipped to
agree); (c) greedy hole filling, then what is left: two loops with an odd number of
edges (which quads cannot close) are merged by removing the face or two between them,
and loops of at most 40 edges are split into quads over their own vertices. Closed
components are then turned outward. Output vertices are the input's, in order and
unchanged, plus those the hole filling adds that some face uses.

OPTIONS:
    -o FILE                output mesh (.obj .ply .off), written atomically
    --drop-non-quads       drop faces that are not quads (default: error naming the first)
    --priority P           order (default): earlier faces win ties and go in first;
                           uniform: all faces equal (ties broken by index)
    --score-limit N        delete faces scoring above N, N >= 1 (default 10: faces on non-manifold
                           edges; 2 is the paper's rule, which also deletes faces with two or
                           more boundary edges and so erodes open borders and clustered holes)
    --no-filter            skip step (a)
    --no-fill              skip step (c)
    --no-close             skip the odd-loop pairing and quadrangulation of step (c)
    --max-hole-edges N     leave boundary loops longer than N open (default 40)
    --watertight           then close every loop still open: odd loops paired by
                           splitting the strip of faces between them (new vertices on
                           the edges it crosses; earlier faces count as more believed),
                           even loops filled, with new vertices where needed; also the
                           border of an open surface unless it is longer than
                           --watertight-max-loop; a loop that only degenerate quads
                           could close stays open, counted as `left open` (session 32)
    --watertight-max-loop N  with --watertight, loops of more than N edges stay open
                           (0: none does) [0]
    -h, --help             this help
";

pub fn run(argv: &[String]) -> Result<()> {
    let spec = Spec {
        valued: &["-o", "--priority", "--score-limit", "--max-hole-edges", "--watertight-max-loop"],
        switches: &["--drop-non-quads", "--no-filter", "--no-fill", "--no-close", "--watertight"],
    };
    let a = Args::parse("repair", argv, &spec)?;
    let input = &a.expect_positional("repair", 1, "one input mesh")?[0];
    let output = a.required("repair", "-o")?;
    // Fail on a bad output extension before doing any work.
    MeshFormat::from_path(Path::new(output))?;
    let mut cfg = PostprocessConfig {
        // Scores are (E_b + 1)(10·E_n + 1) ≥ 1: a limit below 1 deletes every face.
        score_limit: a.parsed_in(
            "repair",
            "--score-limit",
            PostprocessConfig::default().score_limit,
            1,
            u32::MAX,
            "every score is at least 1, so a lower limit deletes every face",
        )?,
        score_filter: !a.switch("--no-filter"),
        fill_holes: !a.switch("--no-fill"),
        // A user's mesh keeps its small parts (reconstruct drops floaters of 4 faces).
        max_floater_faces: 0,
        ..Default::default()
    };
    cfg.close.enabled = !a.switch("--no-fill") && !a.switch("--no-close");
    cfg.hole_fill.max_hole_edges = a.parsed("repair", "--max-hole-edges", cfg.hole_fill.max_hole_edges)?;
    let uniform = match a.value("--priority").unwrap_or("order") {
        "order" => false,
        "uniform" => true,
        other => {
            return Err(Error::Usage(format!(
                "repair: --priority must be order or uniform, not {other:?} (see `point2quad repair --help`)"
            )))
        }
    };

    let watertight = if a.switch("--watertight") {
        let max_loop_edges =
            a.parsed_in("repair", "--watertight-max-loop", 0usize, 0, usize::MAX, "a loop length")?;
        Some(WatertightConfig { max_loop_edges, ..Default::default() })
    } else if a.value("--watertight-max-loop").is_some() {
        return Err(Error::Usage(
            "repair: --watertight-max-loop has no effect without --watertight; give both or neither".into(),
        ));
    } else {
        None
    };
    let poly = read_mesh(Path::new(input))?;
    // After the input (its errors come first), before the work.
    crate::output::check_output_path(Path::new(output))?;
    crate::output::check_not_input("repair", Path::new(output), Path::new(input))?;
    let (quads, dropped) = if a.switch("--drop-non-quads") {
        let (q, d) = poly.to_quads_lossy();
        (q, d)
    } else {
        let q = poly.to_quads().map_err(|e| {
            Error::invalid(format!("{input}: {} (use --drop-non-quads to drop such faces)", bare(e)))
        })?;
        (q, 0)
    };
    let n = quads.quads.len();
    let probs: Vec<f32> =
        if uniform { vec![1.0; n] } else { (0..n).map(|i| 1.0 - i as f32 / (n.max(1) as f32)).collect() };
    let (mut out, rep) = postprocess(&quads.vertices, &quads.quads, &probs, &cfg)
        .map_err(|e| Error::invalid(format!("{input}: {}", bare(e))))?;
    let mut closed = None;
    if let Some(w) = &watertight {
        // The input's faces, with their priority as the belief.
        let (m, r) = close_all(&out, w, &quads.quads, &probs)
            .map_err(|e| Error::invalid(format!("{input}: {}", bare(e))))?;
        out = m;
        closed = Some(r);
    }
    // Added vertices no quad uses any more (a later step took their quads out) are
    // dropped; the input's stay, used or not (session 41's audit).
    let before = out.vertices.len();
    let out = out.without_unused_from(quads.vertices.len()).0;
    let unused_dropped = before - out.vertices.len();
    write_mesh(Path::new(output), &PolyMesh::from(&out))?;

    say!("repair {input} -> {output}");
    say!(
        "  faces read {}, non-quads dropped {dropped}, degenerate dropped {} (repeated vertex), \
         zero-area dropped {} (coincident or collinear corners), duplicates dropped {} (same corners)",
        rep.faces_in,
        rep.degenerate,
        rep.zero_area,
        rep.duplicates
    );
    if cfg.score_filter {
        say!("  score filter (limit {}): removed {}", cfg.score_limit, rep.removed_by_score);
    }
    say!("  inserted {}, refused (would break manifoldness) {}", rep.inserted, rep.refused_on_insertion);
    if cfg.fill_holes {
        let h = &rep.hole_fill;
        say!(
            "  hole filling: {} of {} eligible loops closed ({} loops before), quads added {} (patterns {:?}), \
             vertices added {}, unused input points reused {}",
            h.loops_closed,
            h.loops_eligible,
            h.loops_before,
            h.quads_added(),
            h.quads_by_pattern,
            h.vertices_added,
            h.vertices_reused
        );
    }
    if cfg.close.enabled {
        say!(
            "  closing: {} loops closed with {} quads, {} faces taken out to pair odd loops, {} refused faces put in at holes",
            rep.close.loops_closed,
            rep.close.quads_added,
            rep.close.faces_removed,
            rep.rescued
        );
    }
    say!("  components re-oriented (closed: outward; open: as most input faces): {}", rep.components_flipped);
    if let Some(w) = &closed {
        say!(
            "  watertight: {} odd loop pair(s) joined by splitting {} face(s), {} loop(s) filled with {} quad(s) (the longest {} edges), {} new vertices, {} loop(s) left open",
            w.odd_pairs,
            w.faces_split,
            w.loops_filled,
            w.quads_added,
            w.longest_loop,
            w.vertices_added,
            w.loops_left
        );
    }
    let loops_out = closed.as_ref().map_or(rep.boundary_loops_out, |w| w.loops_left);
    let dropped_note = if unused_dropped > 0 {
        format!(" ({unused_dropped} added vertices no face uses any more left out)")
    } else {
        String::new()
    };
    say!(
        "  output: {} vertices{dropped_note}, {} quads, {} boundary loops",
        out.vertices.len(),
        out.quads.len(),
        loops_out
    );
    Ok(())
}

/// An error's message without the "invalid input:" prefix, to be wrapped with the path.
fn bare(e: Error) -> String {
    match e {
        Error::InvalidInput(m) => m,
        other => other.to_string(),
    }
}
