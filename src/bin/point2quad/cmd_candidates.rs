//! `point2quad candidates`: candidate quads of a point cloud, one per line as 4
//! zero-based input indices in cyclic order (DESIGN §2, §6).

use crate::args::{Args, Spec};
use point2quad::pipeline::candidates::{generate, CandidateConfig};
use point2quad::pipeline::reconstruct::prepare_cloud;
use point2quad::{Error, Result};

/// `--help` text.
pub const HELP: &str = "\
point2quad candidates: candidate quads of a point cloud (from the points alone)

USAGE:
    point2quad candidates INPUT -o CAND.txt [--k K] [--per-point P] [--continue-rank R]
                          [--far F]

ARGS:
    INPUT            points: .xyz/.txt/.pts/.csv (x y z columns), .ply, .obj (v lines), .off

OPTIONS:
    -o, --output F   where to write the candidates: one per line, 4 zero-based input
                     point indices in cyclic order (counter-clockwise about the
                     estimated outward normal)
    --k K            neighbours searched per point (default 20; 3 to 64)
    --per-point P    candidates kept per proposing point before de-duplication
                     (default 32; 1 to 1024)
    --continue-rank R
                     lattice continuation: candidates ranked below R propose the
                     quads across their sides, snapped to the nearest points
                     (default 2, as `reconstruct`; 0 turns it off; 0 to 1000)
    --far F          far completion: each point also keeps its F best quads with a
                     corner beyond its k nearest, completed as parallelograms
                     towards its direction-diverse neighbours (anisotropic faces;
                     clouds of 200+ distinct points only; default 0, off, as
                     `reconstruct`; 0 to 64)
    -h, --help       this text

The input is cleaned as `reconstruct` cleans it: exact and near-duplicate points
count once (one point of each group: of exact copies the first in input order, of
near-duplicates the first in coordinate order; the others are in no candidate), and far outliers
(more than 10,000 times the cloud's radius away) are left out; both are noted on stderr.
A summary (points, candidates, candidates per point, time) goes to stderr.
";

/// Largest `--k` (here and in `reconstruct`): the library's bound (candidate work grows
/// with the cube of k; DESIGN §2 finds coverage saturated at k = 20).
pub const MAX_K: usize = point2quad::pipeline::reconstruct::MAX_NEIGHBOURS;

/// Largest `--per-point`: the library's bound.
pub const MAX_PER_POINT: usize = point2quad::pipeline::candidates::MAX_PER_POINT;

/// Largest `--far` (here, in `reconstruct` and `dataset`): a point's far quads come
/// from at most 8 × 12 (near, diverse) pairs, so 64 keeps nearly all of them.
pub const MAX_FAR: usize = 64;

/// Reads `--far` into `cfg.far_per_point` (0 to [`MAX_FAR`]).
pub fn parse_far(args: &Args, cmd: &str, cfg: &mut CandidateConfig) -> Result<()> {
    cfg.far_per_point =
        args.parsed_in(cmd, "--far", cfg.far_per_point, 0, MAX_FAR, "a point has at most 96 far pairs")?;
    Ok(())
}

/// Runs the subcommand.
///
/// # Errors
/// Usage errors for bad arguments, I/O and parse errors from reading or writing,
/// `InvalidInput` for clouds that cannot give candidates (fewer than 4 points, NaN).
pub fn run(argv: &[String]) -> Result<()> {
    const CMD: &str = "candidates";
    let spec =
        Spec { valued: &["-o", "--output", "--k", "--per-point", "--continue-rank", "--far"], switches: &[] };
    let args = Args::parse(CMD, argv, &spec)?;
    let input = &args.expect_positional(CMD, 1, "one INPUT file")?[0];
    let output = match args.value("-o").or(args.value("--output")) {
        Some(o) => o.to_string(),
        None => {
            return Err(Error::Usage(format!("{CMD}: missing -o CAND.txt (see `point2quad {CMD} --help`)")))
        }
    };
    let mut cfg = CandidateConfig::default();
    cfg.k = args.parsed_in(CMD, "--k", cfg.k, 3, MAX_K, "work grows with the cube of k")?;
    cfg.per_point = args.parsed_in(
        CMD,
        "--per-point",
        cfg.per_point,
        1,
        MAX_PER_POINT,
        "more keeps every candidate anyway",
    )?;
    cfg.continue_rank = args.parsed_in(
        CMD,
        "--continue-rank",
        cfg.continue_rank as usize,
        0,
        1000,
        "a rank among a point's candidates",
    )? as u16;
    parse_far(&args, CMD, &mut cfg)?;
    let t0 = std::time::Instant::now();
    let points = point2quad::io::points::read_points(std::path::Path::new(input))?;
    let t_read = t0.elapsed();
    // After the input (its errors come first), before the work.
    // A mesh or picture name got the index list under it (session 24's audit).
    let ext = std::path::Path::new(&output).extension().map(|e| e.to_string_lossy().to_ascii_lowercase());
    if let Some(e) = ext.filter(|e| ["obj", "ply", "off", "svg", "stl"].contains(&e.as_str())) {
        return Err(Error::Usage(format!(
            "{CMD}: -o {output}: the candidates are a text list (4 point indices per line), not a .{e} file; \
             name it .txt (`point2quad reconstruct` writes meshes)"
        )));
    }
    crate::output::check_output_path(std::path::Path::new(&output))?;
    crate::output::check_not_input(CMD, std::path::Path::new(&output), std::path::Path::new(input))?;
    // The library's refusals do not know the file; name it (once: not "invalid
    // input: FILE: invalid input: …").
    let named = |e: Error| match e {
        Error::InvalidInput(m) => Error::invalid(format!("{input}: {m}")),
        other => other,
    };
    // The same input hygiene as `reconstruct` (duplicates counted once, far outliers
    // left out, near-duplicates merged at its default share), so the candidates are
    // the ones `reconstruct` classifies; indices are mapped back to the input's.
    let merge_share = point2quad::pipeline::reconstruct::ReconstructConfig::default().merge_share;
    let prep = prepare_cloud(&points, merge_share).map_err(named)?;
    let t1 = std::time::Instant::now();
    let cands = generate(&prep.local, &cfg).map_err(named)?;
    let t_gen = t1.elapsed();
    let mut text = String::with_capacity(cands.quads.len() * 24);
    for q in &cands.quads {
        use std::fmt::Write;
        let q = q.map(|i| prep.distinct[i as usize]);
        let _ = writeln!(text, "{} {} {} {}", q[0], q[1], q[2], q[3]);
    }
    point2quad::io::atomic::write_atomic(std::path::Path::new(&output), |w| {
        w.write_all(text.as_bytes()).map_err(|e| point2quad::Error::io(&output, e))
    })?;
    // Through `output::info` (silenced by --quiet): `eprintln!` panics when stderr is a closed pipe.
    crate::output::info(&format!(
        "candidates: {} points, {} candidates ({:.2} per point), read {:.3} s, generate {:.3} s -> {}\n",
        points.len(),
        cands.quads.len(),
        cands.quads.len() as f64 / points.len() as f64,
        t_read.as_secs_f64(),
        t_gen.as_secs_f64(),
        output
    ));
    crate::cmd_reconstruct::hygiene_notes(
        CMD,
        std::path::Path::new(input),
        &points,
        &crate::cmd_reconstruct::Hygiene {
            duplicates: prep.duplicates,
            outliers: prep.outliers,
            first_outlier: prep.first_outlier,
            unresolved: prep.unresolved,
            first_unresolved: prep.first_unresolved,
        },
    );
    Ok(())
}
