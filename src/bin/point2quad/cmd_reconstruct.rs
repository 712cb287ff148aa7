//! `point2quad reconstruct`: point cloud in, manifold pure-quad mesh out.

use crate::args::{Args, Spec};
use crate::cmd_candidates::MAX_K;
use crate::output::say;
use point2quad::io::atomic::commit_all;
use point2quad::io::mesh_io::{prepare_mesh_with, WriteOptions};
use point2quad::io::points::read_points;
use point2quad::mesh::poly::PolyMesh;
use point2quad::mesh::watertight::WatertightConfig;
use point2quad::pipeline::model::{Model, SHIPPED_NAME};
use point2quad::pipeline::reconstruct::{
    reconstruct_observed, ReconstructConfig, SecondPass, SecondPassCover, SecondPassMode, StageDone,
};
use point2quad::{Error, Result};
use std::path::{Path, PathBuf};

/// From this many input points on, each stage is named on stderr as it ends (a
/// 200,000-point cloud takes about 20 s on two cores).
const PROGRESS_POINTS: usize = 50_000;

/// Whether to name each stage as it ends: asked for, or a cloud of at least
/// [`PROGRESS_POINTS`] points.
fn wants_progress(asked: bool, points: usize) -> bool {
    asked || points >= PROGRESS_POINTS
}

pub const HELP: &str = "\
point2quad reconstruct: point cloud -> pure-quad manifold mesh

USAGE:
    point2quad reconstruct INPUT -o OUT.{obj,ply,off} [OPTIONS]

INPUT is a point cloud (.xyz/.txt/.pts/.csv, .ply, .obj or .off; only positions are
read; a first line of column names is a header: columns named x, y, z are read
wherever they are, else the first three), at any scale, pose or offset. The output
mesh's vertices are the input points, written back exactly and in input order (points
no face uses stay as isolated vertices, unless --drop-unused), then the vertices hole
filling added that some face uses.
Duplicate and near-duplicate points count once (faces use one point of each group:
of exact copies the first in input order, of near-duplicates the first in coordinate
order), and far outliers (more than 10,000 times the cloud's radius away) are left
out; both are reported and stay in the output as isolated vertices (unless
--drop-unused). The order of the points does not matter: any order gives the same
faces.

OPTIONS:
    -o, --output OUT      output mesh; format from the extension (required)
    --model FILE[,FILE…]  weights written by `point2quad train`, any preset; with
                          several (comma-separated), an ensemble: each scores every
                          candidate and their probabilities are averaged
                          [the shipped weights]
    --svg PREVIEW.svg     also write a shaded SVG picture of the result
    --drop-unused         leave the points no face uses (noise, strays, duplicates) out
                          of the output; the kept points stay in input order, then
                          the vertices hole filling added that some face uses
                          (default: every input point is written, unused ones as
                          isolated vertices, so indices match the input)
    --rounds N            run at most the first N of the model's refinement rounds,
                          0 to 8: the probabilities the model refined with N rounds
                          gives (default: all; the shipped weights have 6)
    --small-cloud-rounds P,N
                          clouds of fewer than P distinct points run at most N
                          refinement rounds; `off`: no such limit (session 34: the
                          shipped weights' sixth round stays off clouds smaller than
                          any it was trained on) [200,5]
    --progress            name each stage on stderr as it ends, with its time
                          (default: for clouds of 50,000 points or more)
    --no-postprocess      write the faces the network predicts, unrepaired
                          (may be non-manifold: the paper's raw output)
    --threshold T         probability above which a candidate is kept [0.5]
    --k K                 neighbours searched per point for candidates, 3 to 64 [20]
    --per-point P         candidates kept per proposing point before de-duplication,
                          1 to 1024; the shipped weights were trained with 32 [32]
    --continue-rank R     lattice continuation: candidates ranked below R (0 to 1000)
                          propose the quads across their sides, snapped to the
                          nearest points (0 turns it off) [2]
    --far F               far completion: each point also keeps its F best quads
                          with a corner beyond its k nearest (anisotropic faces;
                          clouds of 200+ distinct points only), 0 to 64; the
                          shipped weights were trained with 0 [0]
    --max-floater-faces N remove open components of at most N faces after insertion
                          (floaters; 0 keeps them) [4]
    --rescue-min-prob P   at holes, candidates scored under the threshold but at least P
                          are inserted where they glue to the border on 2+ edges [0.1]
    --rescue-lone P       at holes, also rescue a candidate glued to the border on one
                          edge only when one of its corners is a point no face uses
                          yet and its probability is at least P and at least
                          --rescue-min-prob, 0 <= P <= 1 (session 23 experiment;
                          default: never)
    --no-rescue           do not rescue candidates at holes
    --rescue-keep-parity  refuse a rescued candidate that leaves more odd boundary
                          loops (which quads cannot close) than it found (session 30
                          experiment; default: off)
    --no-unfold           keep predicted faces folded back over a neighbour (default:
                          of each edge whose two quads' normals have a dot under
                          -0.95, the less probable face is taken out after insertion,
                          or the other where that one cannot go)
    --no-close            leave odd loops and loops the hole filling could not close
                          open (default: pair odd loops through the faces between
                          them, quadrangulate loops of at most 40 edges; implies
                          --no-seal and --no-untangle)
    --no-seal             leave the loops the closing could not close (default: take
                          out the faces around each, or a path of faces to another
                          odd loop, and re-split the larger hole into quads the
                          classifier supports, when it does not lose support)
    --no-inverted-fills   never close a 4-edge hole with a quad whose scaled Jacobian
                          is under 0.02 (inverted or folded: the only quad its four
                          corners make); such holes stay open (default: closed)
    --merge-share F       points closer than F times the distance from either to its
                          8th nearest other point are one point; 0 merges exact
                          duplicates only, 0 <= F <= 0.5 [0.001]
    --no-untangle         keep badly shaped faces (scaled Jacobian under 0.02:
                          inverted, folded) as they are (default: re-split each with
                          the faces next to it over the same vertices when that gives
                          better-shaped quads)
    --second-pass MODE    after the post-process, take the points no face uses that
                          lie inside a face the classifier believes (noise, most
                          likely) out, propose and score the candidates again without
                          them and post-process once more: `average` scores a
                          candidate both passes proposed by the mean of its two
                          probabilities, `replace` keeps the second pass's alone,
                          `off` runs one pass (about half the time) [average]
    --second-pass-tau T   how far off a face's plane a point still lies inside it, in
                          units of the face's mean edge length, 0 <= T <= 10 [0.25]
    --second-pass-cover C which faces call the points inside them noise: `believed`
                          those the classifier predicted real, `all` every face of the
                          first pass's mesh (rescued, filled and closing quads too),
                          `learned` a learned test over 16 values per point, the
                          `believed` rule's among them (session 35) [learned]
    --watertight          close every hole at the end, at the price of faces that are
                          not the classifier's: each odd loop is paired with another
                          by splitting the strip of least believed faces between them
                          (new vertices on the edges it crosses), then every even loop
                          is filled, with new vertices where needed. For closed
                          objects: an open surface's border is closed too, unless
                          it is longer than --watertight-max-loop. A loop that only
                          degenerate quads could close (its points on a line, or on
                          one another) stays open, counted as `left open` in the
                          summary (default: off; session 32)
    --watertight-max-loop N  with --watertight, loops of more than N edges stay open
                          (0: none does) [0]
";

const SPEC: Spec = Spec {
    valued: &[
        "-o",
        "--output",
        "--model",
        "--svg",
        "--threshold",
        "--k",
        "--per-point",
        "--continue-rank",
        "--far",
        "--max-floater-faces",
        "--rescue-min-prob",
        "--rescue-lone",
        "--merge-share",
        "--second-pass",
        "--second-pass-tau",
        "--second-pass-cover",
        "--watertight-max-loop",
        "--rounds",
        "--small-cloud-rounds",
    ],
    switches: &[
        "--no-postprocess",
        "--no-rescue",
        "--rescue-keep-parity",
        "--no-unfold",
        "--no-close",
        "--no-seal",
        "--no-inverted-fills",
        "--no-untangle",
        "--progress",
        "--watertight",
        "--drop-unused",
    ],
};

/// `--model`'s value: one weights file, or (when no file has that name) a
/// comma-separated list of them, an ensemble. Each model comes with its file name.
fn load_models(cmd: &str, value: &str) -> Result<Vec<(String, Model)>> {
    if value.is_empty() || Path::new(value).exists() || !value.contains(',') {
        return Ok(vec![(value.to_string(), Model::load(Path::new(value))?)]);
    }
    let names: Vec<&str> = value.split(',').collect();
    if names.iter().any(|n| n.is_empty()) {
        return Err(Error::Usage(format!(
            "{cmd}: --model {value}: an empty name in the list (FILE[,FILE…]; see `point2quad {cmd} --help`)"
        )));
    }
    names.iter().map(|n| Ok((n.to_string(), Model::load(Path::new(n))?))).collect()
}

/// `--rounds N` and `--small-cloud-rounds P,N` into `cfg`.
fn parse_rounds(a: &Args, cmd: &str, cfg: &mut ReconstructConfig) -> Result<()> {
    const MAX: usize = point2quad::pipeline::model::MAX_REFINE_ROUNDS;
    if a.value("--rounds").is_some() {
        cfg.max_rounds =
            Some(a.parsed_in(cmd, "--rounds", 0usize, 0, MAX, "a model has at most that many")?);
    }
    if a.value("--small-cloud-rounds") == Some("off") {
        cfg.small_cloud_points = 0;
    } else if let Some(v) = a.value("--small-cloud-rounds") {
        let bad = || {
            Error::Usage(format!(
                "{cmd}: --small-cloud-rounds {}: expected P,N (fewer than P points run at most N \
                 rounds; P at least 1, N 0 to {MAX}) or off; see `point2quad {cmd} --help`)",
                v.escape_debug()
            ))
        };
        let (p, n) = v.split_once(',').ok_or_else(bad)?;
        let p: usize = p.trim().parse().map_err(|_| bad())?;
        let n: usize = n.trim().parse().map_err(|_| bad())?;
        if p == 0 || n > MAX {
            return Err(bad());
        }
        cfg.small_cloud_points = p;
        cfg.small_cloud_rounds = n;
    }
    Ok(())
}

pub fn run(argv: &[String]) -> Result<()> {
    let cmd = "reconstruct";
    let a = Args::parse(cmd, argv, &SPEC)?;
    let input = PathBuf::from(&a.expect_positional(cmd, 1, "one INPUT point cloud")?[0]);
    let out = PathBuf::from(a.value("-o").or(a.value("--output")).ok_or_else(|| {
        Error::Usage(format!("{cmd}: missing -o OUT.{{obj,ply,off}} (see `point2quad {cmd} --help`)"))
    })?);
    let mut cfg = ReconstructConfig { run_postprocess: !a.switch("--no-postprocess"), ..Default::default() };
    cfg.threshold = a.parsed(cmd, "--threshold", cfg.threshold)?;
    if !(0.0..1.0).contains(&cfg.threshold) {
        return Err(Error::Usage(format!(
            "{cmd}: --threshold must be in [0, 1), got {} (a probability; see `point2quad {cmd} --help`)",
            cfg.threshold
        )));
    }
    cfg.candidates.k =
        a.parsed_in(cmd, "--k", cfg.candidates.k, 3, MAX_K, "work grows with the cube of k")?;
    cfg.candidates.per_point = a.parsed_in(
        cmd,
        "--per-point",
        cfg.candidates.per_point,
        1,
        crate::cmd_candidates::MAX_PER_POINT,
        "more keeps every candidate anyway",
    )?;
    cfg.candidates.continue_rank = a.parsed_in(
        cmd,
        "--continue-rank",
        cfg.candidates.continue_rank as usize,
        0,
        1000,
        "a rank among a point's candidates",
    )? as u16;
    crate::cmd_candidates::parse_far(&a, cmd, &mut cfg.candidates)?;
    parse_rounds(&a, cmd, &mut cfg)?;
    let pp = &mut cfg.postprocess;
    pp.max_floater_faces = a.parsed(cmd, "--max-floater-faces", pp.max_floater_faces)?;
    pp.rescue.min_prob =
        a.parsed_in(cmd, "--rescue-min-prob", pp.rescue.min_prob, 0.0, 1.0, "it is a probability")?;
    pp.rescue.enabled = !a.switch("--no-rescue");
    pp.rescue.keep_parity = a.switch("--rescue-keep-parity");
    // Settings of a step that is turned off would be ignored without a word.
    for opt in ["--rescue-min-prob", "--rescue-lone", "--rescue-keep-parity"] {
        if !pp.rescue.enabled && (a.value(opt).is_some() || a.switch(opt)) {
            return Err(Error::Usage(format!(
                "{cmd}: {opt} has no effect with --no-rescue; give one of them"
            )));
        }
    }
    // The rescue takes candidates scored at most the threshold (session 27's audit: a
    // higher bound rescued nothing, without a word).
    if a.value("--rescue-min-prob").is_some() && pp.rescue.min_prob > cfg.threshold {
        return Err(Error::Usage(format!(
            "{cmd}: --rescue-min-prob {} is above the threshold {}: the rescue takes candidates \
             scored at most the threshold, so it would rescue none; give a lower bound, or --no-rescue",
            pp.rescue.min_prob, cfg.threshold
        )));
    }
    // `--no-close` turns the seal and the untangling off with the closing.
    for opt in ["--no-seal", "--no-untangle"] {
        if a.switch("--no-close") && a.switch(opt) {
            return Err(Error::Usage(format!(
                "{cmd}: {opt} has no effect with --no-close (which turns it off too); give one of them"
            )));
        }
    }
    if !cfg.run_postprocess {
        let valued = [
            "--max-floater-faces",
            "--rescue-min-prob",
            "--rescue-lone",
            "--second-pass",
            "--second-pass-tau",
            "--second-pass-cover",
            "--watertight-max-loop",
        ];
        // Every switch but these three sets a post-process step.
        let mut switches = SPEC
            .switches
            .iter()
            .filter(|o| !matches!(**o, "--no-postprocess" | "--progress" | "--drop-unused"));
        let given = valued.iter().find(|o| a.value(o).is_some()).or(switches.find(|o| a.switch(o)));
        if let Some(opt) = given {
            return Err(Error::Usage(format!(
                "{cmd}: {opt} sets a post-process step and has no effect with --no-postprocess; give one of them"
            )));
        }
    }
    let pp = &mut cfg.postprocess;
    if a.value("--rescue-lone").is_some() {
        pp.rescue.lone_min_prob =
            Some(a.parsed_in(cmd, "--rescue-lone", 0.5f32, 0.0, 1.0, "it is a probability")?);
    }
    if a.switch("--no-unfold") {
        pp.unfold_min_dot = f64::NEG_INFINITY;
    }
    pp.close.enabled = !a.switch("--no-close");
    pp.close.seal = !a.switch("--no-seal");
    if a.switch("--no-inverted-fills") {
        pp.hole_fill.loop4_min_scaled_jacobian = pp.close.min_scaled_jacobian;
    }
    pp.close.untangle = !a.switch("--no-untangle");
    cfg.merge_share = a.parsed_in(
        cmd,
        "--merge-share",
        cfg.merge_share,
        0.0,
        0.5,
        "a share of the 8th-neighbour distance",
    )?;
    let mode = match a.value("--second-pass") {
        None | Some("average") => Some(SecondPassMode::Average),
        Some("replace") => Some(SecondPassMode::Replace),
        Some("off") => None,
        Some(m) => {
            return Err(Error::Usage(format!(
                "{cmd}: --second-pass {}: expected average, replace or off (see `point2quad {cmd} --help`)",
                m.escape_debug()
            )))
        }
    };
    match mode {
        None => {
            for opt in ["--second-pass-tau", "--second-pass-cover"] {
                if a.value(opt).is_some() {
                    return Err(Error::Usage(format!(
                        "{cmd}: {opt} has no effect with --second-pass off; give one of them"
                    )));
                }
            }
            cfg.second_pass = None;
        }
        Some(mode) => {
            let tau =
                a.parsed_in(cmd, "--second-pass-tau", 0.25f64, 0.0, 10.0, "a share of a face's edge length")?;
            let cover = match a.value("--second-pass-cover") {
                Some("believed") => SecondPassCover::Believed,
                Some("all") => SecondPassCover::All,
                None | Some("learned") => SecondPassCover::Learned,
                Some(c) => {
                    return Err(Error::Usage(format!(
                    "{cmd}: --second-pass-cover {}: expected believed, all or learned (see `point2quad {cmd} --help`)",
                    c.escape_debug()
                )))
                }
            };
            cfg.second_pass = cfg.run_postprocess.then_some(SecondPass { tau, mode, cover });
        }
    }
    if a.switch("--watertight") {
        let max_loop_edges =
            a.parsed_in(cmd, "--watertight-max-loop", 0usize, 0, usize::MAX, "a loop length")?;
        cfg.watertight = Some(WatertightConfig { max_loop_edges, ..Default::default() });
    } else if a.value("--watertight-max-loop").is_some() {
        return Err(Error::Usage(format!(
            "{cmd}: --watertight-max-loop has no effect without --watertight; give both or neither"
        )));
    }
    // Check the output names before the work, not after it.
    point2quad::io::mesh_io::MeshFormat::from_path(&out)?;
    let svg = a.value("--svg").map(Path::new);
    if let Some(svg) = svg {
        if !svg.extension().is_some_and(|e| e.eq_ignore_ascii_case("svg")) {
            return Err(Error::Usage(format!(
                "{cmd}: --svg {}: the preview is SVG; its name must end in .svg (see `point2quad {cmd} --help`)",
                svg.display()
            )));
        }
    }
    let t0 = std::time::Instant::now();
    let points = read_points(&input)?;
    let t_read = t0.elapsed().as_secs_f64();
    // The output folders: after the input (its errors come first), before the work.
    crate::output::check_output_path(&out)?;
    crate::output::check_not_input(cmd, &out, &input)?;
    if let Some(svg) = svg {
        crate::output::check_output_path(svg)?;
        crate::output::check_not_input(cmd, svg, &input)?;
    }
    let models = match a.value("--model") {
        Some(m) => load_models(cmd, m)?,
        None => vec![(SHIPPED_NAME.to_string(), Model::shipped()?)],
    };
    // Nor may an output replace a weights file (`--model w.obj -o w.obj` did).
    if a.value("--model").is_some() {
        for (name, _) in &models {
            crate::output::check_not_input(cmd, &out, Path::new(name))?;
            if let Some(svg) = svg {
                crate::output::check_not_input(cmd, svg, Path::new(name))?;
            }
        }
    }
    let members: Vec<&Model> = models.iter().map(|(_, m)| m).collect();
    // Progress on long work: a large cloud's stages are named as they end.
    let long = wants_progress(a.switch("--progress"), points.len());
    if long {
        say!(
            "reconstruct: {} points read from {} in {t_read:.1} s; stage times follow",
            points.len(),
            input.display()
        );
    }
    let mut progress = |s: StageDone| {
        if long {
            let pass = if s.pass == 2 { "second pass: " } else { "" };
            say!("reconstruct: {pass}{} {:.1} s", s.stage, s.seconds);
        }
    };
    // The library's refusals (too few points, no extent…) do not know the file.
    let (mesh, rep) = reconstruct_observed(&points, &members, &cfg, &mut progress).map_err(|e| match e {
        Error::InvalidInput(m) => Error::invalid(format!("{}: {m}", input.display())),
        // The library names a model by its place in the ensemble; here it has a file.
        Error::Checkpoint { path, msg } => {
            let k = path.to_str().and_then(|p| p.strip_prefix("<model ")).and_then(|p| p.strip_suffix('>'));
            let name = k.and_then(|k| k.parse::<usize>().ok()).and_then(|k| models.get(k)).map(|(n, _)| n);
            Error::Checkpoint { path: name.map_or(path, PathBuf::from), msg }
        }
        other => other,
    })?;
    let t1 = std::time::Instant::now();
    let drop_unused = a.switch("--drop-unused");
    let poly = if drop_unused { PolyMesh::from(&mesh.without_unused().0) } else { PolyMesh::from(&mesh) };
    // Both files are written in full before either replaces its target: half a result
    // is worse than none, and a failed preview must not cost the old content of `-o`.
    let mut staged = vec![prepare_mesh_with(&out, &poly, &WriteOptions::default())?];
    if let Some(svg) = svg {
        let opts = point2quad::io::svg::RenderOptions::default();
        staged.push(point2quad::io::svg::prepare_svg(svg, &poly, &opts)?);
    }
    commit_all(staged)?;
    let t_write = t1.elapsed().as_secs_f64();
    let stages: Vec<String> = std::iter::once(("read", t_read))
        .chain(rep.timings.iter().copied())
        .chain(std::iter::once(("write", t_write)))
        .map(|(n, s)| format!("{n} {:.0} ms", s * 1e3))
        .collect();
    // All zero under --no-postprocess.
    let pp = rep.postprocess.clone().unwrap_or_default();
    let (filled, refused) = (pp.hole_fill.quads_added(), pp.refused_on_insertion + pp.removed_by_score);
    // Through `output::info` (silenced by --quiet): `eprintln!` panics when stderr is a closed pipe.
    crate::output::info(&format!(
        "reconstruct: {} points, {} candidates, {} predicted real, {} faces kept ({} removed/refused), {} floater faces removed, {} folded faces taken out, {} candidates rescued at holes, {} hole quads filled ({} new vertices), {} loops closed ({} quads, {} faces taken out), {} loops sealed ({} faces replaced by {}), {} badly shaped faces re-split -> {}\n",
        rep.points,
        rep.candidates,
        rep.predicted,
        rep.faces,
        refused,
        pp.floater_faces_removed,
        pp.unfolded,
        pp.rescued,
        filled,
        // The post-process's own: `--watertight`'s are on its line below (session 39's
        // audit: they were counted here too).
        rep.vertices_added.saturating_sub(rep.watertight.as_ref().map_or(0, |w| w.vertices_added)),
        pp.close.loops_closed,
        pp.close.quads_added,
        pp.close.faces_removed,
        pp.close.sealed,
        pp.close.seal_removed,
        pp.close.seal_added,
        pp.close.untangled,
        out.display()
    ));
    if let Some(w) = &rep.watertight {
        crate::output::info(&format!(
            "reconstruct: watertight: {} odd loop pair(s) joined by splitting {} face(s), {} loop(s) filled with {} quad(s) (the longest {} edges), {} new vertices in all, {} loop(s) left open\n",
            w.odd_pairs, w.faces_split, w.loops_filled, w.quads_added, w.longest_loop, w.vertices_added, w.loops_left
        ));
    }
    if drop_unused {
        crate::output::info(&format!(
            "reconstruct: --drop-unused: {} of {} vertices no face uses left out of the output\n",
            mesh.vertices.len() - poly.vertices.len(),
            mesh.vertices.len()
        ));
    }
    if cfg.second_pass.is_some() && cfg.run_postprocess {
        crate::output::info(&match rep.second_pass_dropped {
            Some(d) => format!(
                "reconstruct: second pass: {d} point(s) no face used lay inside a face and were left out as noise\n"
            ),
            None => "reconstruct: second pass: nothing to leave out; the first pass's mesh stands\n".to_string(),
        });
    }
    hygiene_notes(
        "reconstruct",
        &input,
        &points,
        &Hygiene {
            duplicates: rep.duplicates,
            outliers: rep.outliers,
            first_outlier: rep.first_outlier,
            unresolved: rep.unresolved,
            first_unresolved: rep.first_unresolved,
        },
    );
    if rep.faces == 0 {
        crate::output::stderr(&format!(
            "reconstruct: warning: no faces: {} holds no surface the model recognises \
             ({} candidates, {} predicted real{}); {}{}\n",
            input.display(),
            rep.candidates,
            rep.predicted,
            best_hint(rep.predicted, rep.best_probability),
            if drop_unused {
                "the output is empty (--drop-unused)"
            } else {
                "the output has the points only"
            },
            off_default_candidates(&cfg.candidates)
        ));
    }
    // A raw scan (points scattered at random, no quad layout) gives a sparse result
    // without any error: say so when most usable points are no face's corner.
    let usable = rep.points.saturating_sub(rep.duplicates + rep.outliers);
    let mut used = vec![false; points.len()];
    for q in &mesh.quads {
        for &v in q {
            if let Some(u) = used.get_mut(v as usize) {
                *u = true;
            }
        }
    }
    let corners = used.iter().filter(|&&u| u).count();
    if rep.faces > 0 && 2 * corners < usable {
        crate::output::stderr(&format!(
            "reconstruct: warning: {}: only {corners} of {usable} points are corners of a face, so most of \
             the surface was not found; if the points are not the vertices of a quad mesh (a raw scan), \
             resample them first: the method picks faces among the input points (README, \"What the \
             input must be\"); if they are, quads elongated beyond about 7:1 are a known limit \
             (README, \"Where it fails\"){}\n",
            input.display(),
            off_default_candidates(&cfg.candidates)
        ));
    }
    // The second pass leaves out what it takes for noise; a fifth of the cloud is twice
    // the paper's noise. A layout the weights do not know ends so too: a triangle mesh
    // split into quads loses its triangles' centres (session 39's audit: 304 of 962
    // points of a clean cloud).
    if let Some(d) = rep.second_pass_dropped.filter(|&d| d >= 10 && 5 * d > usable) {
        crate::output::stderr(&format!(
            "reconstruct: warning: {}: the second pass left {d} of {usable} points out as noise (more than a \
             fifth); if they are vertices of the mesh, its layout is one the weights do not know, such as a \
             triangle mesh split into quads around the triangles' centres (README, \"Where it fails\"), for \
             which the project has weights of its own: `--model fixtures/point2quad-trisplit.p2qm` (a file \
             of the source tree)\n",
            input.display()
        ));
    }
    crate::output::info(&format!(
        "reconstruct: time: {} (total {:.0} ms, {})\n",
        stages.join(", "),
        t0.elapsed().as_secs_f64() * 1e3,
        match point2quad::par::num_threads() {
            1 => "1 thread".to_string(),
            n => format!("{n} threads"),
        }
    ));
    Ok(())
}

/// For the no-faces warning: when nothing was predicted real but candidates exist, the
/// best candidate's probability and the `--threshold` that would keep it (tiny or odd
/// clouds, where the model hesitates everywhere: an icosahedron's 12 vertices, whose
/// best candidate scores 0.248). Empty otherwise.
fn best_hint(predicted: usize, best: Option<f32>) -> String {
    match best {
        Some(p) if predicted == 0 => format!(
            "; the most probable candidate scored {p:.3}: `--threshold` below that keeps the \
             candidates above it"
        ),
        _ => String::new(),
    }
}

/// When `--k`, `--per-point` or `--far` differ from the defaults the shipped weights were
/// trained with, a clause saying so for the no-faces and the few-corners warnings (session 24's
/// audit: `--per-point 64` or `--k 3` alone gave no faces, and the warning blamed the
/// input; session 30's: `--per-point 64` gave 124 faces where 32 gives 1,848, and the
/// few-corners warning did not name it); empty otherwise.
fn off_default_candidates(c: &point2quad::pipeline::candidates::CandidateConfig) -> String {
    let d = point2quad::pipeline::candidates::CandidateConfig::default();
    let mut off = Vec::new();
    if c.k != d.k {
        off.push(format!("--k {} (default {})", c.k, d.k));
    }
    if c.per_point != d.per_point {
        off.push(format!("--per-point {} (default {})", c.per_point, d.per_point));
    }
    if c.far_per_point != d.far_per_point {
        off.push(format!("--far {} (default {})", c.far_per_point, d.far_per_point));
    }
    if off.is_empty() {
        return String::new();
    }
    let (verb, pronoun) = if off.len() == 1 { ("differs", "it") } else { ("differ", "them") };
    format!(
        "; {} {verb} from the defaults that the shipped weights and `point2quad dataset` use, \
         which can alone explain it: try without {pronoun}",
        off.join(" and ")
    )
}

/// What the input hygiene left out or could not resolve (the library's
/// `ReconstructReport` / `PreparedCloud` counts).
pub struct Hygiene {
    pub duplicates: usize,
    pub outliers: usize,
    pub first_outlier: Option<usize>,
    pub unresolved: usize,
    pub first_unresolved: Option<usize>,
}

/// The notes `reconstruct` and `candidates` print about the input hygiene: duplicates
/// counted once, far outliers left out, and points the normalised frame cannot resolve
/// (a cloud spanning too many orders of magnitude), each naming the file.
pub fn hygiene_notes(cmd: &str, input: &std::path::Path, points: &[[f64; 3]], h: &Hygiene) {
    if h.duplicates > 0 {
        crate::output::stderr(&format!(
            "{cmd}: {} duplicate or near-duplicate point(s) counted once ({})\n",
            h.duplicates,
            if cmd == "reconstruct" { "see --merge-share" } else { "as `reconstruct` counts them" }
        ));
    }
    if let Some(i) = h.first_outlier {
        // Many "outliers" are a part of their own (session 37's audit: 2,000 points in a
        // 1e-9 speck beside a 1,910-point cube made the cube the outliers): say which
        // part was kept, and how to get the other.
        let many = if h.outliers * 10 >= points.len() {
            format!(
                concat!(
                    ". That is {:.0}% of the points: the rest, packed more than {:.0e} times closer ",
                    "together, is what gets reconstructed; if the left-out points are the object, ",
                    "reconstruct them on their own"
                ),
                100.0 * h.outliers as f64 / points.len() as f64,
                point2quad::pipeline::reconstruct::OUTLIER_RADII
            )
        } else {
            String::new()
        };
        crate::output::stderr(&format!(
            "{cmd}: warning: {}: {} far outlier(s) left out (more than {:.0e} times the cloud's radius away); the first is point {i} (counting from 0) at {:?}{many}\n",
            input.display(),
            h.outliers,
            point2quad::pipeline::reconstruct::OUTLIER_RADII,
            points[i]
        ));
    }
    if let Some(i) = h.first_unresolved {
        crate::output::stderr(&format!(
            "{cmd}: warning: {}: {} point(s) lie closer together than the normalised frame resolves \
             (their 8 nearest neighbours within 1e-6 of the cloud's radius: f32 precision), so \
             they are left out (no face uses them) and their part's faces are lost; the first is point {i} \
             (counting from 0) at {:?}. The cloud spans too many orders of magnitude (parts far \
             apart, or far points beside a small bulk): reconstruct its parts separately\n",
            input.display(),
            h.unresolved,
            points[i]
        ));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stage_lines_from_the_threshold_on_or_when_asked() {
        assert!(!wants_progress(false, PROGRESS_POINTS - 1));
        assert!(wants_progress(false, PROGRESS_POINTS));
        assert!(wants_progress(true, 4));
        assert_eq!(PROGRESS_POINTS, 50_000, "the help text and README say 50,000");
    }
}
