//! `point2quad dataset`: writes labelled training samples (`.p2qs`, format in
//! `pipeline::dataset`) from random synthetic shapes and/or a folder of quad meshes,
//! plus an `index.txt` summary. Deterministic for a seed; samples run in parallel.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use crate::args::{Args, Spec};
use crate::output::{note, say};
use point2quad::io::mesh_io::read_mesh;
use point2quad::mesh::coarsen::{coarsen as coarsen_mesh, CoarsenConfig};
use point2quad::mesh::poly::QuadMesh;
use point2quad::mesh::shapes::triangle_split;
use point2quad::pipeline::candidates::CandidateConfig;
use point2quad::pipeline::dataset::{
    build_sample_with, index_line, sample_rng, save_sample, stretch_mesh, synthetic_mesh_with_aspect,
    variant_rng, CornerStart, EXTENSION, VARIANT_SEP,
};
use point2quad::pipeline::noise::NoiseConfig;
use point2quad::{par, Error, Result};

pub const HELP: &str = "\
point2quad dataset: write labelled training samples (points, candidates, F_info, labels)

USAGE:
    point2quad dataset --out DIR [--synthetic N] [--meshes DIR] [--noise 0.1] [--seed S]

OPTIONS:
    --out DIR         output folder (created if missing): one <name>.p2qs per sample
                      and index.txt (file, points, candidates, positives, coverage)
    --synthetic N     N random synthetic quad meshes (all shape families, random pose;
                      at most 100000)
    --bumpy           make three synthetic shapes in four bumpy: they then bend by up
                      to ~30 degrees between neighbouring faces, as coarse organic
                      meshes do (an experiment: not in the shipped weights' recipe)
    --min-aspect F    the elongated third of the synthetic shapes draws its aspect
                      factor from [F, 1) (0.05 <= F <= 1; default 0.25: quads up to
                      about 4:1; an experiment of session 20, not in the shipped recipe)
    --tri-split N     N more synthetic samples, syn_tri_<i>_<family>, each a random
                      synthetic shape (from a stream of their own; --bumpy and
                      --min-aspect apply) converted as a triangle mesh usually is:
                      every quad cut into two triangles, every triangle into three
                      quads around its centroid (`synth --triangle-split`; not in the
                      default weights' recipe: `make train-trisplit` uses 32; at most
                      100000)
    --meshes DIR      every .obj/.off/.ply file directly in DIR (sorted by name);
                      sample NAME is the file's stem (`mesh_` before a stem that
                      starts with `syn_`, the synthetic samples' names)
    --coarsen F[,F2,...]
                      also a coarse copy of each mesh of --meshes, sample NAME@c:
                      random chords (strips of quads) collapsed until at most F of
                      its faces are left (0 < F < 1, e.g. 0.5), so it bends more
                      from face to face, as coarse meshes of organic shapes do;
                      each further share adds copies NAME@c2, NAME@c3, ... (at
                      most 8 shares). `train`/`refine` split, fold and hold out
                      every NAME@... with NAME. A mesh no chord of which can be
                      collapsed gets no copy. `make train` uses 0.5
    --stretch F[,F2,...]
                      also a stretched copy of each mesh of --meshes, sample
                      NAME@s: stretched along a random axis by a random factor
                      between 1 and F (1 < F <= 10), so its quads change aspect
                      and shear, as on an object scaled unevenly; each further
                      factor adds copies NAME@s2, NAME@s3, ... (at most 8).
                      Split, folded and held out with NAME, like --coarsen's
                      copies (which come first)
    --noise F         noise points per mesh vertex (default 0.1; at most 100)
    --offset F        largest noise offset along the face normal, as a fraction of
                      the face's mean edge length (default 0.1; at most 100)
    --noise-variants N
                      N draws of the noise points per sample (1 to 16; default 1):
                      besides sample NAME, samples NAME~2 ... NAME~N of the same
                      mesh with other noise points, hence other candidates. `train`
                      trains on one of the N draws of each per epoch, in turn (at the
                      cost of one), or on NAME only with `--draws first`; `refine`
                      reads NAME only unless `--draws all`; validation reads NAME
                      only. `make train` uses 3 (the classifier on first draws, the
                      rounds on all). N times the files, time and memory
    --seed S          random seed (default 0); the same seed gives the same files
    --continue-rank R lattice continuation in the candidates, as `reconstruct
                      --continue-rank` (0 turns it off; 0 to 1000) [2]
    --per-point P     candidates kept per proposing point before de-duplication,
                      as `reconstruct --per-point` (1 to 1024) [32]; a model
                      trained on such data wants the same value at reconstruct
    --far F           far completion in the candidates, as `reconstruct --far`
                      (0 to 64) [0]; a model trained on such data wants the same
                      value at reconstruct
    --corner-start least|index
                      where each candidate's corners start: at its corner of
                      smallest coordinates, or at its smallest index, which here is
                      never a noise point (noise points follow the mesh vertices),
                      a cue no real cloud gives; the shipped weights were trained
                      with index (`make train` asks for it) [least]

At least one of --synthetic, --tri-split and --meshes is needed. A mesh that cannot
be read (a folder or a broken link named like one too), is not pure-quad, has no
faces, has a face that repeats a corner, or none of whose faces is among its
candidates is skipped with a warning naming it. The run fails if a sample cannot be written, and then
removes the samples it wrote (and --out, if it made it). Progress goes to stderr, one
line per sample. Sample k (synthetic first, then the meshes in name order, their
copies, then the --tri-split samples) uses its own random stream derived from the seed
and k (the --tri-split shapes: from the seed and their own number).
";

/// Mixed into the seed for `--tri-split`'s shapes: a stream apart from `--synthetic`'s, so
/// the two sets are different shapes.
const TRI_SPLIT_STREAM: u64 = 0x7472_695f_7370_6c69;

/// Largest `--synthetic`: each sample costs about a second on two cores and writes a
/// file, so 100,000 is already a day's run; the bound catches typos (and a job list
/// sized by a 20-digit number) before any work or any folder is made.
const MAX_SYNTHETIC: usize = 100_000;

/// Largest `--noise` (noise points per vertex) and `--offset` (edge lengths off the
/// surface): the paper uses 0.1 and 0.1; a hundred times the surface's own points, or
/// offsets of a hundred edges, are no longer a noisy surface.
const MAX_NOISE: f64 = 100.0;

/// Most values `--coarsen` and `--stretch` each take (each adds a copy of every mesh).
const MAX_COPIES: usize = 8;

/// Largest `--noise-variants`: each draw repeats the whole dataset's work and files.
const MAX_NOISE_VARIANTS: usize = 16;

/// Largest `--stretch` factor: beyond ten to one the quads are needles.
const MAX_STRETCH: f64 = 10.0;

/// Where a sample comes from.
enum Job {
    Synthetic(usize),
    /// A mesh file and the sample name to use for it.
    File(PathBuf, String),
    /// A mesh file, coarsened to this share of its faces by `--coarsen`, and the
    /// sample name (`NAME@c`, `NAME@c2`, ...).
    Coarse(PathBuf, String, f64),
    /// A mesh file, stretched by `--stretch` (largest factor), and the sample name
    /// (`NAME@s`, `NAME@s2`, ...).
    Stretch(PathBuf, String, f64),
    /// Synthetic shape `.0` of the `--tri-split` stream, converted by
    /// [`triangle_split`]; sample name `syn_tri_<index>_<family>`.
    TriSplit(usize),
    /// Another draw of the noise points of job `.0` (an index into the jobs): the same
    /// mesh, variant number `.1` (≥ 2), sample name `NAME~v` for that job's `NAME`.
    Variant(usize, usize),
}

impl Job {
    /// The mesh file a file-based job reads.
    fn mesh_path(&self) -> Option<&Path> {
        match self {
            Job::File(path, _) | Job::Coarse(path, _, _) | Job::Stretch(path, _, _) => Some(path),
            Job::Synthetic(_) | Job::TriSplit(_) | Job::Variant(..) => None,
        }
    }
}

/// The comma-separated numbers of `--{flag}` (at most `MAX_COPIES`), each
/// checked by `ok` (which says what it wants); empty without the option. They need
/// `--meshes`.
fn copy_values(
    args: &Args,
    cmd: &str,
    flag: &str,
    ok: impl Fn(f64) -> std::result::Result<(), String>,
) -> Result<Vec<f64>> {
    let Some(v) = args.value(flag) else {
        return Ok(Vec::new());
    };
    let mut values = Vec::new();
    for part in v.split(',') {
        let f: f64 = part
            .trim()
            .parse()
            .map_err(|_| Error::Usage(format!("{cmd}: {flag} {v:?}: cannot parse {part:?} as a number")))?;
        ok(f).map_err(|want| Error::Usage(format!("{cmd}: {flag} must be {want}, got {part}")))?;
        values.push(f);
    }
    if values.len() > MAX_COPIES {
        return Err(Error::Usage(format!(
            "{cmd}: {flag} takes at most {MAX_COPIES} values, got {}",
            values.len()
        )));
    }
    if args.value("--meshes").is_none() {
        return Err(Error::Usage(format!("{cmd}: {flag} needs --meshes DIR (it copies those meshes)")));
    }
    Ok(values)
}

pub fn run(argv: &[String]) -> Result<()> {
    const CMD: &str = "dataset";
    let spec = Spec {
        valued: &[
            "--out",
            "--synthetic",
            "--tri-split",
            "--meshes",
            "--noise",
            "--offset",
            "--seed",
            "--continue-rank",
            "--per-point",
            "--far",
            "--coarsen",
            "--stretch",
            "--min-aspect",
            "--noise-variants",
            "--corner-start",
        ],
        switches: &["--bumpy"],
    };
    let args = Args::parse(CMD, argv, &spec)?;
    let bumpy = args.switch("--bumpy");
    let start = match args.value("--corner-start") {
        None | Some("least") => CornerStart::Least,
        Some("index") => CornerStart::Index,
        Some(other) => {
            return Err(Error::Usage(format!(
                "{CMD}: --corner-start must be least or index, got {other:?} (see `point2quad {CMD} --help`)"
            )))
        }
    };
    let min_aspect: f64 = args.parsed_in(
        CMD,
        "--min-aspect",
        point2quad::mesh::shapes::DEFAULT_MIN_ASPECT,
        0.05,
        1.0,
        "the candidates' edge-ratio filter stops at 0.1",
    )?;
    if !args.positional.is_empty() {
        return Err(Error::Usage(format!(
            "{CMD}: unexpected argument {:?} (see `point2quad {CMD} --help`)",
            args.positional[0]
        )));
    }
    let out = PathBuf::from(args.required(CMD, "--out")?);
    let synthetic: usize = args.parsed_in(
        CMD,
        "--synthetic",
        0,
        0,
        MAX_SYNTHETIC,
        "about a second of work and a file per sample",
    )?;
    let tri_split: usize = args.parsed_in(
        CMD,
        "--tri-split",
        0,
        0,
        MAX_SYNTHETIC,
        "about six seconds of work and a file per sample",
    )?;
    let seed: u64 = args.parsed(CMD, "--seed", 0)?;
    let mut cand_cfg = CandidateConfig::default();
    cand_cfg.continue_rank = args.parsed_in(
        CMD,
        "--continue-rank",
        cand_cfg.continue_rank as usize,
        0,
        1000,
        "a rank among a point's candidates",
    )? as u16;
    cand_cfg.per_point = args.parsed_in(
        CMD,
        "--per-point",
        cand_cfg.per_point,
        1,
        crate::cmd_candidates::MAX_PER_POINT,
        "more keeps every candidate anyway",
    )?;
    crate::cmd_candidates::parse_far(&args, CMD, &mut cand_cfg)?;
    let coarsen = copy_values(&args, CMD, "--coarsen", |f| {
        if f > 0.0 && f < 1.0 {
            Ok(())
        } else {
            Err("shares of the faces, 0 < F < 1".into())
        }
    })?;
    let stretch = copy_values(&args, CMD, "--stretch", |f| {
        if f > 1.0 && f <= MAX_STRETCH {
            Ok(())
        } else {
            Err(format!("stretch factors, 1 < F <= {MAX_STRETCH}"))
        }
    })?;
    let noise_variants: usize = args.parsed_in(
        CMD,
        "--noise-variants",
        1,
        1,
        MAX_NOISE_VARIANTS,
        "each draw adds a file per sample",
    )?;
    let noise = NoiseConfig {
        fraction: args.parsed(CMD, "--noise", NoiseConfig::default().fraction)?,
        offset: args.parsed(CMD, "--offset", NoiseConfig::default().offset)?,
    };
    check_noise(CMD, &noise)?;
    let mut jobs: Vec<Job> = (0..synthetic).map(Job::Synthetic).collect();
    let mut not_files = Vec::new();
    if let Some(dir) = args.value("--meshes") {
        let files;
        (files, not_files) = mesh_files(Path::new(dir))?;
        let stems: Vec<String> =
            files.iter().map(|p| sanitize(&p.file_stem().unwrap_or_default().to_string_lossy())).collect();
        let mut taken: std::collections::HashSet<String> = std::collections::HashSet::new();
        for (path, stem) in files.iter().zip(&stems) {
            // `a.obj` and `a.off` side by side: keep both, named apart by extension.
            let mut name = if stems.iter().filter(|s| *s == stem).count() > 1 {
                let ext = path.extension().unwrap_or_default().to_string_lossy().to_ascii_lowercase();
                format!("{stem}_{ext}")
            } else {
                stem.clone()
            };
            // Stems that sanitise alike (`x~2.obj` and `x_2.obj` are both `x_2`) would
            // write one file: later ones, in name order, get a number.
            if taken.contains(&name) {
                let base = name.clone();
                let mut k = 2;
                while taken.contains(&format!("{base}_{k}")) || stems.contains(&format!("{base}_{k}")) {
                    k += 1;
                }
                name = format!("{base}_{k}");
            }
            taken.insert(name.clone());
            jobs.push(Job::File(path.clone(), name));
        }
        // After every plain job, so each of those keeps its index, hence its random
        // stream and its bytes, with or without --coarsen.
        // The copies of each share after those of the shares before it, for the same
        // reason: `--coarsen 0.5,0.25` repeats the samples of `--coarsen 0.5`.
        let plain: Vec<(PathBuf, String)> = jobs
            .iter()
            .filter_map(|j| match j {
                Job::File(p, n) => Some((p.clone(), n.clone())),
                _ => None,
            })
            .collect();
        for (i, &share) in coarsen.iter().enumerate() {
            let suffix = if i == 0 { "@c".to_string() } else { format!("@c{}", i + 1) };
            jobs.extend(plain.iter().map(|(p, n)| Job::Coarse(p.clone(), format!("{n}{suffix}"), share)));
        }
        for (i, &factor) in stretch.iter().enumerate() {
            let suffix = if i == 0 { "@s".to_string() } else { format!("@s{}", i + 1) };
            jobs.extend(plain.iter().map(|(p, n)| Job::Stretch(p.clone(), format!("{n}{suffix}"), factor)));
        }
    }
    // After the plain jobs and the copies, so each of those keeps its index, hence its
    // random stream and its bytes, with or without --tri-split.
    jobs.extend((0..tri_split).map(Job::TriSplit));
    // After every other job, so each of those keeps its index, hence its random stream
    // and its bytes, with or without --noise-variants.
    let base_jobs = jobs.len();
    for v in 2..=noise_variants {
        jobs.extend((0..base_jobs).map(|k| Job::Variant(k, v)));
    }
    if jobs.is_empty() {
        return Err(Error::Usage(format!(
            "{CMD}: nothing to do: give --synthetic N or --tri-split N (N > 0) and/or --meshes DIR with .obj/.off/.ply files"
        )));
    }
    let made_out = !out.exists();
    if !made_out && !out.is_dir() {
        // `create_dir_all` said only "File exists (os error 17)".
        return Err(Error::io(
            &out,
            std::io::Error::other("exists and is not a folder (--out names the folder the samples go to)"),
        ));
    }
    if !made_out && out.is_dir() {
        // `train` reads every sample in the folder: old ones would join the new set.
        let old = std::fs::read_dir(&out)
            .map_err(|e| Error::io(&out, e))?
            .filter_map(|e| e.ok())
            .filter(|e| e.path().extension().is_some_and(|x| x == EXTENSION))
            .count();
        if old > 0 {
            return Err(Error::Usage(format!(
                "{CMD}: {} already holds {old} sample(s) (.{EXTENSION}) from an earlier run, which `train` \
                 would read with the new ones; give an empty or new folder, or remove them",
                out.display()
            )));
        }
    }
    std::fs::create_dir_all(&out).map_err(|e| Error::io(&out, e))?;
    let total = jobs.len();
    let done = AtomicUsize::new(0);
    // A warning that a job is skipped, counted in the progress.
    let skip = |why: std::fmt::Arguments| {
        let n = done.fetch_add(1, Ordering::Relaxed) + 1;
        note!("[{n}/{total}] warning: skipping {why}");
    };
    let results: Vec<Result<Option<(String, String)>>> = par::map(total, |k| {
        // A noise variant builds its job's mesh exactly as that job does, then draws
        // the noise from a stream of its own.
        let (k, variant) = match jobs[k] {
            Job::Variant(of, v) => (of, Some(v)),
            _ => (k, None),
        };
        let (name, mesh, rng) = match &jobs[k] {
            Job::Synthetic(i) => synthetic_mesh_with_aspect(seed, *i, bumpy, min_aspect),
            Job::TriSplit(i) => {
                let (name, mesh, mut rng) =
                    synthetic_mesh_with_aspect(seed ^ TRI_SPLIT_STREAM, *i, bumpy, min_aspect);
                let name = name.replacen("syn_", "syn_tri_", 1);
                (name, triangle_split(&mesh, &mut rng), rng)
            }
            Job::File(path, name) | Job::Coarse(path, name, _) | Job::Stretch(path, name, _) => {
                let mesh = match load_quads(path) {
                    Ok(mesh) => mesh,
                    Err(msg) => {
                        skip(format_args!("{msg}"));
                        return Ok(None);
                    }
                };
                let mut rng = sample_rng(seed, k);
                let mesh = match &jobs[k] {
                    Job::Coarse(_, _, share) => {
                        let cfg = CoarsenConfig { face_fraction: *share, ..Default::default() };
                        let coarse = coarsen_mesh(&mesh, &cfg, &mut rng);
                        if coarse.quads.len() == mesh.quads.len() {
                            let n = done.fetch_add(1, Ordering::Relaxed) + 1;
                            note!("[{n}/{total}] {name}: no chord could be collapsed (or the mesh is not a valid manifold); no sample");
                            return Ok(None);
                        }
                        coarse
                    }
                    Job::Stretch(_, _, factor) => stretch_mesh(&mesh, *factor, &mut rng)?.0,
                    _ => mesh,
                };
                (name.clone(), mesh, rng)
            }
            Job::Variant(..) => return Err(Error::invalid("dataset: a noise variant of a noise variant")),
        };
        let (name, mut rng) = match variant {
            Some(v) => (format!("{name}{VARIANT_SEP}{v}"), variant_rng(seed, k, v)),
            None => (name, rng),
        };
        let sample = match (
            build_sample_with(&name, &mesh, &noise, &cand_cfg, start, &mut rng),
            jobs[k].mesh_path(),
        ) {
            (Ok(s), _) => s,
            // A mesh file that loads but cannot make a sample (e.g. every face has zero
            // area, so no noise point can be placed) is skipped like any unusable file.
            (Err(e), Some(path)) => {
                let why = match e {
                    Error::InvalidInput(m) => m,
                    other => other.to_string(),
                };
                // build_sample's message starts with the sample's name; the path says more.
                let why = why.strip_prefix(&format!("{name}: ")).unwrap_or(&why);
                let why = why.strip_prefix("invalid input: ").unwrap_or(why);
                skip(format_args!("{}: {why}", path.display()));
                return Ok(None);
            }
            (Err(e), None) => return Err(e),
        };
        // A mesh none of whose faces is a candidate (all corners on a line, say) would
        // be a sample of negatives only (session 27's audit: such samples were written).
        if let Some(path) = jobs[k].mesh_path() {
            if !sample.labels.iter().any(|&l| l != 0) {
                skip(format_args!(
                    "{}{}: none of its {} faces is among the {} candidates (degenerate faces?)",
                    path.display(),
                    variant.map(|v| format!(" (noise draw {v})")).unwrap_or_default(),
                    mesh.quads.len(),
                    sample.candidates.len()
                ));
                return Ok(None);
            }
        }
        let file = format!("{name}.{EXTENSION}");
        save_sample(&out.join(&file), &sample)?;
        let n = done.fetch_add(1, Ordering::Relaxed) + 1;
        say!(
            "[{n}/{total}] {name}: {} points, {} candidates, coverage {:.4}",
            sample.points.len(),
            sample.candidates.len(),
            sample.coverage()
        );
        Ok(Some((index_line(&file, &sample), file)))
    });
    for p in &not_files {
        note!("warning: skipping {}: {}", p.display(), not_a_file(p));
    }
    let mut index = String::from("# file\tpoints\tcandidates\tpositives\tcoverage\n");
    let mut files = Vec::new();
    let mut failed = None;
    for r in results {
        match r {
            Ok(Some((line, file))) => {
                index.push_str(&line);
                index.push('\n');
                files.push(file);
            }
            Ok(None) => {}
            Err(e) => failed = failed.or(Some(e)),
        }
    }
    // All or nothing (session 27's audit: a sample that failed to write left the others
    // and no index, and the folder then refused a rerun): what this run wrote goes.
    let undo = |files: &[String]| {
        for f in files {
            let _ = std::fs::remove_file(out.join(f));
        }
        if made_out {
            let _ = std::fs::remove_dir(&out);
        }
    };
    if let Some(e) = failed {
        undo(&files);
        return Err(e);
    }
    let written = files.len();
    let total = total + not_files.len();
    if written == 0 {
        // Every mesh was skipped: an empty dataset only fails later, in `train`. The
        // folder goes too if this run made it (`remove_dir` leaves a non-empty one).
        if made_out {
            let _ = std::fs::remove_dir(&out);
        }
        return Err(Error::invalid(format!(
            "no sample written: all {total} meshes were skipped (see the warnings above)"
        )));
    }
    let index_path = out.join("index.txt");
    if let Err(e) = point2quad::io::atomic::write_atomic(&index_path, |w| {
        w.write_all(index.as_bytes()).map_err(|e| Error::io(&index_path, e))
    }) {
        undo(&files);
        return Err(e);
    }
    say!("dataset: {written} samples in {} ({} skipped)", out.display(), total - written);
    Ok(())
}

/// The .obj/.off/.ply files directly in `dir`, sorted by name.
/// Entries with a mesh extension that are not regular files (a folder, a broken link)
/// come back apart, sorted, to be skipped with a warning (session 27's audit: they were
/// skipped without a word).
fn mesh_files(dir: &Path) -> Result<(Vec<PathBuf>, Vec<PathBuf>)> {
    let entries = std::fs::read_dir(dir).map_err(|e| Error::io(dir, e))?;
    let (mut files, mut others) = (Vec::new(), Vec::new());
    for entry in entries {
        let path = entry.map_err(|e| Error::io(dir, e))?.path();
        let ext = path.extension().map(|e| e.to_string_lossy().to_ascii_lowercase());
        if matches!(ext.as_deref(), Some("obj" | "off" | "ply")) {
            if path.is_file() {
                files.push(path);
            } else {
                others.push(path);
            }
        }
    }
    files.sort();
    others.sort();
    Ok((files, others))
}

/// Why a mesh-named entry that is not a regular file is skipped.
fn not_a_file(path: &Path) -> &'static str {
    match std::fs::metadata(path) {
        Ok(m) if m.is_dir() => "a folder, not a mesh file",
        Ok(_) => "not a regular file",
        Err(_) if std::fs::symlink_metadata(path).is_ok() => "a link to nothing",
        Err(_) => "cannot be read",
    }
}

/// Reads a mesh file as a pure-quad mesh with at least one face; the message names
/// the file (once) and says why not.
fn load_quads(path: &Path) -> std::result::Result<QuadMesh, String> {
    // Read errors already start with the path.
    let poly = read_mesh(path).map_err(|e| e.to_string())?;
    let mesh = poly.to_quads().map_err(|e| format!("{}: not a pure-quad mesh ({e})", path.display()))?;
    if mesh.quads.is_empty() {
        // Regression: a vertices-only .ply failed the whole run ("pts: the mesh has no
        // faces", naming no file) instead of being skipped like other unusable meshes.
        return Err(format!("{}: no faces (a point cloud, not a mesh)", path.display()));
    }
    // A face that repeats a corner (`f 1 1 2 5`) is no quad: its label would teach the
    // classifier a shape no candidate has (session 27's audit: such meshes were taken).
    let repeats = |q: &[u32; 4]| (0..4).any(|i| (i + 1..4).any(|j| q[i] == q[j]));
    if let Some(f) = mesh.quads.iter().position(repeats) {
        let n = mesh.quads.iter().filter(|q| repeats(q)).count();
        return Err(format!(
            "{}: {n} face(s) repeat a corner, so they are not quads; the first is face {} (counting from 1)",
            path.display(),
            f + 1
        ));
    }
    Ok(mesh)
}

/// A file stem made safe as a sample (and file) name. The synthetic samples' names
/// (`syn_<index>_<family>`, `syn_tri_…`) are kept for them: a mesh whose stem starts
/// with `syn_` is named `mesh_syn_…` (session 41's audit: `syn_00000_cube.obj` in
/// `--meshes` beside `--synthetic 1` overwrote that sample, and the index listed the
/// name twice).
fn sanitize(stem: &str) -> String {
    let s: String =
        stem.chars().map(|c| if c.is_alphanumeric() || "-_.".contains(c) { c } else { '_' }).collect();
    if s.is_empty() {
        "mesh".into()
    } else if s.starts_with("syn_") {
        format!("mesh_{s}")
    } else {
        s
    }
}

/// A number for a message: in exponent form when very large or small (`{}` printed 1e300
/// with all its 301 digits; session 24's audit).
pub(crate) fn short(v: f64) -> String {
    if v != 0.0 && v.is_finite() && !(1e-4..1e6).contains(&v.abs()) {
        format!("{v:e}")
    } else {
        v.to_string()
    }
}

/// The bounds of `--noise` and `--offset` (`dataset` and `synth`): finite, at least 0 and
/// at most [`MAX_NOISE`].
///
/// # Errors
/// `Usage` naming the option and the value.
pub(crate) fn check_noise(cmd: &str, noise: &NoiseConfig) -> Result<()> {
    for (name, v) in [("--noise", noise.fraction), ("--offset", noise.offset)] {
        if !(v.is_finite() && v >= 0.0) {
            return Err(Error::Usage(format!(
                "{cmd}: {name} must be a finite number >= 0, got {}",
                short(v)
            )));
        }
        // A typo (1e9) otherwise fails only inside the first sample, after the output
        // folder was made.
        if v > MAX_NOISE {
            return Err(Error::Usage(format!(
                "{cmd}: {name} must be at most {MAX_NOISE}, got {} (the surface would be lost in the noise)",
                short(v)
            )));
        }
    }
    Ok(())
}
