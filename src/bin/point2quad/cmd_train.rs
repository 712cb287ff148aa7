//! `point2quad train`: trains the face classifier on datasets written by
//! `point2quad dataset`, with a validation split, per-epoch checkpoints and resume.

use crate::args::{Args, Spec};
use crate::output::{note, say};
use point2quad::nn::checkpoint::{self, Checkpoint, Fnv1a, TrainState};
use point2quad::nn::kpfcnn::KpfcnnConfig;
use point2quad::pipeline::dataset::{load_sample, noise_variant, Sample, EXTENSION, VARIANT_SEP};
use point2quad::pipeline::model::{Model, ModelConfig};
use point2quad::pipeline::train::{train, Progress, TrainConfig};
use point2quad::{Error, Result};
use std::path::{Path, PathBuf};

pub const HELP: &str = "\
point2quad train: train the Point2Quad face classifier

USAGE:
    point2quad train --data DIR --out MODEL [OPTIONS]

Reads every .p2qs sample in DIR (written by `point2quad dataset`), holds out a
validation part (by a hash of the sample name: the same split on every run), and
trains. After every epoch it writes MODEL (weights only, what `reconstruct --model`
reads) and MODEL.ckpt (weights + optimiser state + RNG: what --resume reads), both
atomically. Progress goes to stderr.

OPTIONS:
    --data DIR            dataset folder (required)
    --out MODEL           output weights file (required)
    --config NAME         model preset [default]:
                            default     face encoder + classifier (2-core friendly;
                                        the shipped weights)
                            default_kp  default + a small KPConv point encoder
                                        (KPFCNN, 3 levels, 32 features per point);
                                        its batch norm reads each cloud's own
                                        statistics when scoring (validation,
                                        refine, reconstruct)
                            paper       the paper's widths and KPFCNN (25.2M
                                        parameters; slow on a CPU)
                          (ignored with --resume: the checkpoint holds its config)
    --sign-free-normals   the model reads the point normals without their signs
                          (a corner normal against the face is negated; the
                          context's normal agreements become absolute values), so
                          orientation seams of the propagated normals do not show
                          (a fresh model only: not with --init or --resume; the
                          shipped weights use it)
    --kp-spacing-cells F  with a point encoder (default_kp, paper): scale each cloud
                          so that its median nearest-neighbour distance is F cells
                          of the encoder's first level, so every cloud looks equally
                          dense to it (a fresh model only) [off]
    --kp-input-cell F     with a point encoder: its level 0 is the cloud
                          grid-subsampled with cell F × its first cell (each point
                          reads its voxel's features) instead of every point, so its
                          cost stops growing with the cloud's density; 0 < F ≤ 1 (a
                          fresh model only) [off]
    --epochs N            total epochs, 1..100000 (a resumed run continues up to N;
                          left out, up to the checkpoint's own) [40]
    --resume CKPT         continue exactly from a MODEL.ckpt written earlier: it
                          records the run's --epochs, --seed, --lr,
                          --max-candidates, split (--val-fraction, --hold-out,
                          --fold), --draws and augmentation, and a fingerprint of
                          its samples; options left out are read from it, one
                          given with another value is refused (--lr is taken, with
                          a note; --epochs sets a new goal), and other data is
                          refused (--init starts a fine-tune on it)
    --init WEIGHTS        start from these weights (any weights file: its config is
                          used, refinement rounds are dropped) with a fresh optimiser,
                          learning-rate schedule and epoch count: a fine-tune
    --seed S              training seed [0]
    --lr X                initial learning rate [0.01]
    --val-fraction F      share of samples held out for validation [0.15]
    --hold-out A,B,...    also hold out the samples with these names (e.g. whole
                          meshes: qm_monkey,qm_feline); each must exist in DIR
    --max-candidates M    candidates drawn per step [12000]
    --fold I/K            also hold out fold I of K (0 <= I < K <= 16; the folds split
                          the samples by another hash of the name): K such runs give
                          the out-of-fold classifiers `refine --fold-models` reads
    --draws WHICH         samples of `dataset --noise-variants`: all = one draw of
                          each sample per epoch, in turn (NAME, NAME~2, ...); first =
                          each sample's first draw only (NAME), so training is exactly
                          that of the dataset without variants (`make train`: the
                          classifier reads first draws, its rounds every draw).
                          Validation reads first draws either way. (`refine
                          --draws` defaults to first, this one to all) [all]

AUGMENTATION (per step, from the training RNG; recorded in the checkpoint like the
options above):
    --scale MIN,MAX       anisotropic scale: each axis of a random orthonormal frame
                          scaled by a factor uniform in [MIN, MAX), 0 < MIN <= MAX
                          [0.9,1.1]; 1,1 turns it off
    --jitter F            Gaussian jitter of every point, sigma = F x its local
                          spacing, 0 <= F <= 1 [0.01]; 0 turns it off
    --no-rotate           no random rotation
    --no-augment          none of the three (cannot be combined with the others)
  With scale or jitter on, the face input of the drawn candidates is recomputed
  from the moved points (the candidates and labels stay the dataset's), and the
  point encoder sees the same points. Noise points come from the dataset.
";

const SPEC: Spec = Spec {
    valued: &[
        "--data",
        "--out",
        "--config",
        "--epochs",
        "--resume",
        "--init",
        "--seed",
        "--lr",
        "--val-fraction",
        "--hold-out",
        "--max-candidates",
        "--fold",
        "--scale",
        "--jitter",
        "--kp-spacing-cells",
        "--kp-input-cell",
        "--draws",
    ],
    switches: &["--no-rotate", "--no-augment", "--sign-free-normals"],
};

/// The point encoder's number options of a fresh model: flag, upper bound (with why)
/// if any, and the config field it sets. Each takes a finite value > 0.
type KpField = fn(&mut KpfcnnConfig) -> &mut f32;
/// An upper bound and why.
type Bound = Option<(f32, &'static str)>;
const KP_OPTIONS: [(&str, Bound, KpField); 2] = [
    ("--kp-spacing-cells", None, |k| &mut k.spacing_cells),
    ("--kp-input-cell", Some((1.0, "first cells: level 0's voxels finer than level 1's")), |k| {
        &mut k.input_cell
    }),
];

fn fnv(s: &str) -> u64 {
    point2quad::nn::checkpoint::fnv1a64(s.as_bytes())
}

/// `--draws first|all` of `train` and `refine` (`dataset --noise-variants`): whether every
/// noise draw of a sample is read (`all`) or its first only (`first`); `default_all` when
/// the option is not given.
pub(crate) fn draws_arg(cmd: &str, a: &Args, default_all: bool) -> Result<bool> {
    match a.value("--draws") {
        None => Ok(default_all),
        Some(v) => parse_draws(v).ok_or_else(|| {
            Error::Usage(format!(
                "{cmd}: --draws {v:?}: expected first or all (see `point2quad {cmd} --help`)"
            ))
        }),
    }
}

/// `first` → false, `all` → true (whether every noise draw is read).
fn parse_draws(v: &str) -> Option<bool> {
    match v {
        "first" => Some(false),
        "all" => Some(true),
        _ => None,
    }
}

/// `I/K` with 0 <= I < K <= [`MAX_FOLDS`].
fn parse_fold(v: &str) -> Option<(usize, usize)> {
    let (i, k) = v.split_once('/')?;
    let (i, k): (usize, usize) = (i.trim().parse().ok()?, k.trim().parse().ok()?);
    ((2..=MAX_FOLDS).contains(&k) && i < k).then_some((i, k))
}

/// The validation split shared by `train` and `refine`: a sample is held out when a hash
/// of its name falls under `fraction` (the same split on every run) or when its name is
/// one of `names` (`--hold-out`: whole meshes kept out of training to judge on).
#[derive(Clone, Debug)]
pub(crate) struct Split {
    pub fraction: f64,
    pub names: Vec<String>,
    /// `--fold I/K` (train only): samples of fold I are held out too.
    pub fold: Option<(usize, usize)>,
}

impl Split {
    /// `--val-fraction` and `--hold-out` of `a`, checked; `cmd` names the command in errors.
    pub(crate) fn from_args(cmd: &str, a: &Args) -> Result<Split> {
        let fraction: f64 = a.parsed(cmd, "--val-fraction", 0.15)?;
        if !(0.0..1.0).contains(&fraction) {
            return Err(Error::Usage(format!("{cmd}: --val-fraction must be in [0, 1), got {fraction}")));
        }
        let mut names = Vec::new();
        if let Some(v) = a.value("--hold-out") {
            for n in v.split(',') {
                let n = n.trim();
                if n.is_empty() {
                    return Err(Error::Usage(format!(
                        "{cmd}: --hold-out takes sample names separated by commas, got '{v}'"
                    )));
                }
                if noise_variant(n).1 > 1 {
                    return Err(Error::Usage(format!(
                        "{cmd}: --hold-out {n}: a noise draw goes wherever its sample goes; hold out {} instead",
                        noise_variant(n).0
                    )));
                }
                names.push(n.to_string());
            }
        }
        Ok(Split { fraction, names, fold: None })
    }

    /// `--fold I/K` of `a` into the split (train's option), checked.
    pub(crate) fn with_fold_arg(mut self, cmd: &str, a: &Args) -> Result<Split> {
        if let Some(v) = a.value("--fold") {
            self.fold = Some(parse_fold(v).ok_or_else(|| {
                Error::Usage(format!(
                    "{cmd}: --fold {v:?}: expected I/K with 0 <= I < K <= {MAX_FOLDS}, e.g. 0/2"
                ))
            })?);
        }
        Ok(self)
    }

    /// Whether the sample called `name` is in the validation part. A sample derived from
    /// a mesh (`NAME@c`, `dataset --coarsen`; `NAME~2`, `dataset --noise-variants`) goes
    /// wherever its mesh's sample `NAME` goes: the hash, the fold and `--hold-out` read
    /// the part before the `@` or `~`, so a held-out mesh is never trained on in another
    /// form; and a held-out copy (`--hold-out NAME@c`) takes its noise draws with it.
    pub(crate) fn is_validation(&self, name: &str) -> bool {
        let parent = parent_name(name);
        let drawn_for = noise_variant(name).0;
        self.names.iter().any(|n| n == name || n == parent || n == drawn_for)
            || is_validation(parent, self.fraction)
            || self.fold.is_some_and(|(i, k)| fold_of(parent, k) == i)
    }

    /// The error for a split that leaves nothing to train on, naming what put every
    /// sample into validation (it blamed `--val-fraction` alone, also when `--hold-out`
    /// had named every sample).
    pub(crate) fn nothing_to_train(&self, cmd: &str) -> Error {
        let mut why = Vec::new();
        if self.fraction > 0.0 {
            why.push(format!("--val-fraction {}", self.fraction));
        }
        if !self.names.is_empty() {
            why.push(format!("--hold-out ({} name(s))", self.names.len()));
        }
        if let Some((i, k)) = self.fold {
            why.push(format!("--fold {i}/{k}"));
        }
        Error::Usage(format!(
            "{cmd}: every sample fell into validation ({}); nothing is left to train on: lower --val-fraction, hold out fewer samples or leave out --fold",
            why.join(", ")
        ))
    }

    /// Error naming the `--hold-out` names that no sample of `samples` carries (a typo
    /// would otherwise silently train on the mesh meant to be held out).
    pub(crate) fn check_names<'a>(&self, cmd: &str, samples: impl Iterator<Item = &'a str>) -> Result<()> {
        let have: std::collections::HashSet<&str> = samples.collect();
        let missing: Vec<&str> =
            self.names.iter().map(|s| s.as_str()).filter(|n| !have.contains(n)).collect();
        if missing.is_empty() {
            Ok(())
        } else {
            Err(Error::Usage(format!(
                "{cmd}: --hold-out names no sample of the dataset: {}",
                missing.join(", ")
            )))
        }
    }
}

/// The mesh a sample was made from: the name up to the first `@` (a copy, `NAME@c`) or
/// `~` (a noise variant, `NAME~2`; sample names of `dataset` never hold either otherwise:
/// file stems are sanitised to letters, digits and `._-`).
pub(crate) fn parent_name(name: &str) -> &str {
    name.split(['@', VARIANT_SEP]).next().unwrap_or(name)
}

/// Whether the sample called `name` is in the validation part: by a hash of the name,
/// so every run (and `refine`) splits a dataset the same way.
pub(crate) fn is_validation(name: &str, fraction: f64) -> bool {
    (fnv(name) % 10_000) as f64 / 10_000.0 < fraction
}

/// Most folds `train --fold` and `refine --fold-models` take.
pub(crate) const MAX_FOLDS: usize = 16;

/// The fold (of `k`) of the sample called `name`: a hash of the name independent of the
/// validation hash's, so folds cut across the validation split.
pub(crate) fn fold_of(name: &str, k: usize) -> usize {
    ((fnv(name) >> 32) % k as u64) as usize
}

/// The `.p2qs` samples of `dir` that `keep` accepts, by file name, and the names of all
/// samples read (kept or not, in no order); `cmd` names the subcommand in the error.
pub(crate) fn load_dir(
    cmd: &str,
    dir: &Path,
    keep: impl Fn(&Sample) -> bool,
) -> Result<(Vec<Sample>, Vec<String>)> {
    let rd = std::fs::read_dir(dir).map_err(|e| Error::io(dir, e))?;
    let mut files: Vec<PathBuf> = Vec::new();
    for e in rd {
        let p = e.map_err(|e| Error::io(dir, e))?.path();
        if p.extension().and_then(|x| x.to_str()) == Some(EXTENSION) {
            files.push(p);
        }
    }
    files.sort();
    if files.is_empty() {
        return Err(Error::Usage(format!(
            "{cmd}: no .{EXTENSION} samples in {} (write some with `point2quad dataset --out DIR`)",
            dir.display()
        )));
    }
    // Each sample is read, judged by `keep` and dropped at once if it is not kept, so the
    // samples left out (other noise draws) never take memory together.
    let mut samples = Vec::new();
    // Splits, hold-outs and noise-draw groups go by the name inside each file: two files
    // with one name would be one sample to them.
    let mut seen: std::collections::HashMap<String, &PathBuf> = std::collections::HashMap::new();
    for p in &files {
        let s = load_sample(p)?;
        if let Some(first) = seen.insert(s.name.clone(), p) {
            return Err(Error::Usage(format!(
                "{cmd}: {} and {} hold samples of one name, {:?} (a copied file?); keep one",
                first.display(),
                p.display(),
                s.name
            )));
        }
        if keep(&s) {
            samples.push(s);
        }
    }
    Ok((samples, seen.into_keys().collect()))
}

/// Parses `--scale MIN,MAX`: two finite numbers with 0 < MIN <= MAX; as
/// `TrainConfig::scale` holds it (`None` for 1,1: no scaling).
fn parse_scale(v: &str) -> Result<Option<(f32, f32)>> {
    let bad =
        |why: &str| Error::Usage(format!("train: --scale {v:?}: {why} (see `point2quad train --help`)"));
    let (lo, hi) = v.split_once(',').ok_or_else(|| bad("expected MIN,MAX, e.g. 0.9,1.1"))?;
    let num = |x: &str| x.trim().parse::<f32>().map_err(|_| bad(&format!("cannot parse {x:?} as a number")));
    let (lo, hi) = (num(lo)?, num(hi)?);
    if !(lo.is_finite() && hi.is_finite()) {
        return Err(bad("MIN and MAX must be finite"));
    }
    if lo <= 0.0 {
        return Err(bad("MIN must be positive"));
    }
    if lo > hi {
        return Err(bad("MIN must not exceed MAX"));
    }
    Ok(if lo == 1.0 && hi == 1.0 { None } else { Some((lo, hi)) })
}

/// The augmentation options into `cfg` (defaults: `TrainConfig`'s).
fn augmentation(a: &Args, cfg: &mut TrainConfig) -> Result<()> {
    let cmd = "train";
    if a.switch("--no-augment") {
        if a.value("--scale").is_some() || a.value("--jitter").is_some() || a.switch("--no-rotate") {
            return Err(Error::Usage(
                "train: --no-augment cannot be combined with --scale, --jitter or --no-rotate".into(),
            ));
        }
        cfg.rotate = false;
        cfg.scale = None;
        cfg.jitter = 0.0;
        return Ok(());
    }
    cfg.rotate = !a.switch("--no-rotate");
    if let Some(v) = a.value("--scale") {
        cfg.scale = parse_scale(v)?;
    }
    // `parsed_in` refuses NaN too.
    cfg.jitter =
        a.parsed_in(cmd, "--jitter", cfg.jitter, 0.0, 1.0, "a fraction of the local point spacing")?;
    Ok(())
}

/// The options `--resume` continues a run with, as (record key, option that sets it).
/// The checkpoint stores their values (and a fingerprint of the data, key `data`): an
/// option left out on resume is read from it, one given with another value is refused
/// (`--lr` excepted: taken, with a note; and `--epochs`, which a resume may raise).
const RUN_OPTIONS: [(&str, &str); 11] = [
    ("epochs", "--epochs"),
    ("seed", "--seed"),
    ("lr", "--lr"),
    ("max-candidates", "--max-candidates"),
    ("val-fraction", "--val-fraction"),
    ("hold-out", "--hold-out"),
    ("fold", "--fold"),
    ("draws", "--draws"),
    ("scale", "--scale"),
    ("jitter", "--jitter"),
    ("rotate", "--no-rotate"),
];

/// The options of a run that `--resume` must continue with (what a checkpoint's run
/// record holds, besides the data's fingerprint).
struct RunOptions<'a> {
    cfg: &'a mut TrainConfig,
    split: &'a mut Split,
    all_draws: &'a mut bool,
}

impl RunOptions<'_> {
    /// The value of record key `key` (one of `RUN_OPTIONS`), as text that `set` reads back.
    fn get(&self, key: &str) -> String {
        match key {
            "epochs" => self.cfg.epochs.to_string(),
            "seed" => self.cfg.seed.to_string(),
            "lr" => self.cfg.sgd.lr.to_string(),
            "max-candidates" => self.cfg.max_candidates.to_string(),
            "val-fraction" => self.split.fraction.to_string(),
            // Sorted: the order the names were given in does not change the split.
            "hold-out" => {
                let mut v = self.split.names.clone();
                v.sort();
                v.dedup();
                v.join(",")
            }
            "fold" => self.split.fold.map(|(i, k)| format!("{i}/{k}")).unwrap_or_default(),
            "draws" => (if *self.all_draws { "all" } else { "first" }).to_string(),
            "scale" => self.cfg.scale.map_or("1,1".to_string(), |(lo, hi)| format!("{lo},{hi}")),
            "jitter" => self.cfg.jitter.to_string(),
            "rotate" => (if self.cfg.rotate { "yes" } else { "no" }).to_string(),
            _ => unreachable!("not a run option: {key}"),
        }
    }

    /// Sets record key `key` from `v` (as `get` wrote it); `None` when `v` does not parse.
    fn set(&mut self, key: &str, v: &str) -> Option<()> {
        match key {
            "epochs" => self.cfg.epochs = v.parse().ok().filter(|e| (1..=100_000).contains(e))?,
            "seed" => self.cfg.seed = v.parse().ok()?,
            "lr" => self.cfg.sgd.lr = v.parse().ok().filter(|x: &f32| x.is_finite() && *x > 0.0)?,
            "max-candidates" => self.cfg.max_candidates = v.parse().ok().filter(|&m: &usize| m >= 2)?,
            "val-fraction" => {
                self.split.fraction = v.parse().ok().filter(|f| (0.0..1.0).contains(f))?;
            }
            "hold-out" => {
                self.split.names =
                    if v.is_empty() { Vec::new() } else { v.split(',').map(str::to_string).collect() };
            }
            "fold" => self.split.fold = if v.is_empty() { None } else { Some(parse_fold(v)?) },
            "draws" => *self.all_draws = parse_draws(v)?,
            "scale" => self.cfg.scale = parse_scale(v).ok()?,
            "jitter" => self.cfg.jitter = v.parse().ok().filter(|j| (0.0..=1.0).contains(j))?,
            "rotate" => {
                self.cfg.rotate = match v {
                    "yes" => true,
                    "no" => false,
                    _ => return None,
                }
            }
            _ => return None,
        }
        Some(())
    }

    /// The run record of these options and the data fingerprint `data`.
    fn record(&self, data: &str) -> Vec<(String, String)> {
        let mut r: Vec<(String, String)> =
            RUN_OPTIONS.iter().map(|(k, _)| (k.to_string(), self.get(k))).collect();
        r.push(("data".to_string(), data.to_string()));
        r
    }

    /// Continues the run recorded in `record` (read from checkpoint `ckpt`): each option
    /// the command line leaves out takes the recorded value; one given with another
    /// value is a usage error, except `--lr` (taken, with a note: the schedule is
    /// recomputed from it) and `--epochs` (a new goal). Returns the recorded data
    /// fingerprint.
    fn adopt(&mut self, a: &Args, ckpt: &str, record: &[(String, String)]) -> Result<Option<String>> {
        let no_augment = a.switch("--no-augment");
        let mut data = None;
        for (key, stored) in record {
            if key == "data" {
                data = Some(stored.clone());
                continue;
            }
            let Some(&(_, opt)) = RUN_OPTIONS.iter().find(|(k, _)| k == key) else {
                note!("train: note: {ckpt} records {key} = {stored:?}, which this build does not read");
                continue;
            };
            let now = self.get(key);
            if &now == stored {
                continue;
            }
            let augmentation = matches!(key.as_str(), "scale" | "jitter" | "rotate");
            let given = if key == "rotate" { a.switch(opt) } else { a.value(opt).is_some() };
            if given && key == "epochs" {
                continue; // a resume may train on to another epoch count
            }
            if given || (augmentation && no_augment) {
                let opt = if given { opt } else { "--no-augment" };
                if key == "lr" {
                    note!(
                        "train: note: --lr {now} with --resume: the run in {ckpt} used --lr {stored}; the schedule from epoch 1 is recomputed with {now}, so the run no longer continues exactly"
                    );
                    continue;
                }
                let was =
                    if key == "rotate" { format!("rotate {stored}") } else { format!("{key} {stored:?}") };
                return Err(Error::Usage(format!(
                    "train: {opt} with --resume {ckpt}: the run there used {was}, this command gives {now:?}; give the same value, or leave the option out (--resume reads it from the checkpoint)"
                )));
            }
            self.set(key, stored).ok_or_else(|| Error::Checkpoint {
                path: ckpt.into(),
                msg: format!("run record {key} = {stored:?} is not a valid value"),
            })?;
        }
        Ok(data)
    }
}

/// A fingerprint of the samples a run reads (every field: name, points, mesh vertex
/// count, ground-truth faces, candidates, features, labels; in name order): FNV-1a 64
/// in hex, after the sample count.
fn data_fingerprint<'a>(samples: impl Iterator<Item = &'a Sample>) -> String {
    let mut v: Vec<&Sample> = samples.collect();
    v.sort_by(|x, y| x.name.cmp(&y.name));
    let mut h = Fnv1a::new();
    for s in &v {
        h.write(s.name.as_bytes());
        h.write(&(s.points.len() as u64).to_le_bytes());
        h.write(bytemuck::cast_slice(&s.points));
        h.write(&s.n_mesh_vertices.to_le_bytes());
        h.write(&(s.gt_faces.len() as u64).to_le_bytes());
        h.write(bytemuck::cast_slice(&s.gt_faces));
        h.write(&(s.candidates.len() as u64).to_le_bytes());
        h.write(bytemuck::cast_slice(&s.candidates));
        h.write(&s.feature_dim.to_le_bytes());
        h.write(bytemuck::cast_slice(&s.features));
        h.write(&s.labels);
    }
    format!("{} samples, {:016x}", v.len(), h.finish())
}

pub fn run(argv: &[String]) -> Result<()> {
    let cmd = "train";
    let a = Args::parse(cmd, argv, &SPEC)?;
    a.expect_positional(cmd, 0, "no positional arguments")?;
    let data = PathBuf::from(a.required(cmd, "--data")?);
    let out = PathBuf::from(a.required(cmd, "--out")?);
    let epochs = a.parsed_in(cmd, "--epochs", 40usize, 1, 100_000, "total epochs")?;
    let mut cfg = TrainConfig { epochs, ..TrainConfig::default() };
    cfg.seed = a.parsed(cmd, "--seed", 0u64)?;
    cfg.sgd.lr = a.parsed(cmd, "--lr", cfg.sgd.lr)?;
    cfg.max_candidates = a.parsed(cmd, "--max-candidates", cfg.max_candidates)?;
    // One message per option, naming it and the value given.
    let mut split = Split::from_args(cmd, &a)?.with_fold_arg(cmd, &a)?;
    // `--draws first` trains on each sample's first noise draw only, exactly as on the
    // dataset written without `--noise-variants`; `all` (the default) takes one draw of
    // each sample per epoch, in turn.
    let mut all_draws = draws_arg(cmd, &a, true)?;
    // Batch norm in train mode needs two rows: one candidate per step fails mid-epoch.
    if cfg.max_candidates < 2 {
        return Err(Error::Usage(format!(
            "train: --max-candidates must be at least 2 (batch norm needs two rows), got {}",
            cfg.max_candidates
        )));
    }
    if !(cfg.sgd.lr.is_finite() && cfg.sgd.lr > 0.0) {
        return Err(Error::Usage(format!("train: --lr must be a finite number > 0, got {}", cfg.sgd.lr)));
    }
    augmentation(&a, &mut cfg)?;
    // These options shape a fresh model's config; --init and --resume read theirs from a file.
    let from_file = a.value("--init").is_some() || a.value("--resume").is_some();
    for &(opt, ..) in &KP_OPTIONS {
        if a.value(opt).is_some() && from_file {
            return Err(Error::Usage(format!(
                "train: {opt} cannot be combined with --init or --resume (the weights file holds its config)"
            )));
        }
    }
    if a.switch("--sign-free-normals") && from_file {
        return Err(Error::Usage(
            "train: --sign-free-normals cannot be combined with --init or --resume (the weights file holds its config)"
                .into(),
        ));
    }
    if a.value("--init").is_some() && (a.value("--resume").is_some() || a.value("--config").is_some()) {
        return Err(Error::Usage(
            "train: --init cannot be combined with --resume or --config (the weights file holds its config)"
                .into(),
        ));
    }
    let ckpt_path = PathBuf::from(format!("{}.ckpt", out.display()));
    // Both files are first written after an epoch, which may be hours away; checked
    // even before the samples are read (a large dataset takes a while to load).
    crate::output::check_output_path(&out)?;
    crate::output::check_output_path(&ckpt_path)?;
    // Neither may be a file this run reads (`--out X --init X` replaced the weights it
    // started from; `--out C --resume C` turned the checkpoint into weights only). The
    // one exception is the usual resume, `--out M --resume M.ckpt`, which continues
    // its own checkpoint.
    for o in [&out, &ckpt_path] {
        crate::output::check_not_in_dataset(cmd, o, &data)?;
        if let Some(init) = a.value("--init") {
            crate::output::check_not_input(cmd, o, Path::new(init))?;
        }
    }
    if let Some(resume) = a.value("--resume") {
        crate::output::check_not_input(cmd, &out, Path::new(resume))?;
    }

    // The data fingerprint in a resumed checkpoint's run record: the data must match it.
    let mut resumed_data: Option<String> = None;
    let (mut model, resume) = match a.value("--resume") {
        Some(r) => {
            let ck = checkpoint::load(Path::new(r))?;
            let state = ck.train.clone().ok_or_else(|| Error::Checkpoint {
                path: r.into(),
                msg: "holds weights only, no training state (resume from the .ckpt file)".into(),
            })?;
            if state.run.is_empty() {
                // A checkpoint of a build before the run record: the options are not in it.
                note!(
                    "train: note: {r} holds no record of its run's options (an older build wrote it): the run continues exactly only with the options it started with"
                );
                if let Some(lr) = a.value("--lr") {
                    note!(
                        "train: note: --lr {lr} with --resume: the schedule from epoch 1 is recomputed with {lr}, so the run continues exactly only if it started with it"
                    );
                }
            } else {
                let mut opts = RunOptions { cfg: &mut cfg, split: &mut split, all_draws: &mut all_draws };
                resumed_data = opts.adopt(&a, r, &state.run)?;
            }
            let m = Model::from_checkpoint(&ck, Path::new(r))?;
            // The checkpoint holds its config: a --config naming another preset would be
            // silently ignored.
            if let Some(c) = a.value("--config") {
                if c != m.config().preset {
                    return Err(Error::Usage(format!(
                        "train: --config {c} with --resume {r}: the checkpoint holds a '{}' model (leave --config out)",
                        m.config().preset
                    )));
                }
            }
            (m, Some(state))
        }
        None => match a.value("--init") {
            Some(w) => {
                let m = Model::load(Path::new(w))?;
                // The rounds were trained on this classifier's probabilities: stale after.
                let m = if m.refiner().is_some() {
                    note!("train: --init {w}: its refinement rounds are dropped (run `point2quad refine` after)");
                    m.with_refinement(0, &[], point2quad::pipeline::refine::SideRule::Direction, 0)?
                } else {
                    m
                };
                (m, None)
            }
            None => {
                let mut config = ModelConfig::preset(a.value("--config").unwrap_or("default"))?;
                config.sign_free_normals = a.switch("--sign-free-normals");
                for &(opt, at_most, field) in &KP_OPTIONS {
                    let Some(v) = a.value(opt) else { continue };
                    let f: f32 = a.parsed(cmd, opt, 0.0f32)?;
                    let Some(kp) = config.point_encoder.as_mut() else {
                        return Err(Error::Usage(format!(
                            "train: {opt} {v}: the {} preset has no point encoder (use default_kp or paper)",
                            config.preset
                        )));
                    };
                    if !(f.is_finite() && f > 0.0) {
                        return Err(Error::Usage(format!(
                            "train: {opt} must be a finite number > 0, got {v}"
                        )));
                    }
                    if let Some((max, why)) = at_most.filter(|&(max, _)| f > max) {
                        return Err(Error::Usage(format!(
                            "train: {opt} must be at most {max} ({why}), got {v}"
                        )));
                    }
                    *field(kp) = f;
                }
                (Model::new(config, cfg.seed)?, None)
            }
        },
    };

    let t0 = std::time::Instant::now();
    let (samples, names) = load_dir(cmd, &data, |s| all_draws || noise_variant(&s.name).1 == 1)?;
    // Before the hold-out names are checked: other data fails on this, not on a recorded
    // name the user never typed.
    let fingerprint = data_fingerprint(samples.iter());
    if let (Some(r), Some(was)) = (a.value("--resume"), &resumed_data) {
        if *was != fingerprint {
            return Err(Error::Usage(format!(
                "train: --resume {r}: the samples in {} ({fingerprint}) are not those the run was trained on ({was}); resume on its own data, or start a fine-tune with --init",
                data.display()
            )));
        }
    }
    split.check_names(cmd, names.iter().map(String::as_str))?;
    if samples.len() < names.len() {
        say!(
            "train: {} further noise draws (NAME~2, ...) left out (--draws first)",
            names.len() - samples.len()
        );
    }
    let (mut tr, mut va): (Vec<Sample>, Vec<Sample>) = (Vec::new(), Vec::new());
    let mut extra_draws = 0;
    for s in samples {
        if split.is_validation(&s.name) {
            // Validation reads each sample's first noise draw only (`NAME`, not
            // `NAME~2`): the figures stay those of a dataset without variants.
            if noise_variant(&s.name).1 == 1 {
                va.push(s);
            }
        } else {
            extra_draws += usize::from(noise_variant(&s.name).1 > 1);
            tr.push(s);
        }
    }
    if tr.is_empty() {
        return Err(split.nothing_to_train("train"));
    }
    // With noise draws an epoch reads one draw of each sample: count the first draws'
    // candidates, and every draw's beside them.
    let first_cands: usize =
        tr.iter().filter(|s| noise_variant(&s.name).1 == 1).map(|s| s.labels.len()).sum();
    let all_cands: usize = tr.iter().map(|s| s.labels.len()).sum();
    let cands = if extra_draws > 0 {
        format!("{first_cands} training candidates in first draws, {all_cands} in all")
    } else {
        format!("{all_cands} training candidates")
    };
    let draws = if extra_draws > 0 {
        format!(" (and {extra_draws} more noise draws of them: one draw of each per epoch)")
    } else {
        String::new()
    };
    say!(
        "train: {} training{draws} / {} validation samples ({cands}) loaded in {:.1}s; model '{}' with {} parameters",
        tr.len() - extra_draws,
        va.len(),
        t0.elapsed().as_secs_f64(),
        model.config().preset,
        model.param_count()
    );
    let run_record =
        RunOptions { cfg: &mut cfg, split: &mut split, all_draws: &mut all_draws }.record(&fingerprint);
    let start_epoch = resume.as_ref().map(|s| s.epoch as usize).unwrap_or(0);
    let t_train = std::time::Instant::now();
    let no_val = va.is_empty();
    let mut progress = |p: Progress| match p {
        Progress::Step { epoch, step, steps, loss } => {
            crate::output::info(&format!(
                "\repoch {epoch}/{} step {step}/{steps} loss {loss:.4}   ",
                cfg.epochs
            ));
        }
        Progress::Epoch(r) => {
            let done = r.epoch - start_epoch;
            let per = t_train.elapsed().as_secs_f64() / done.max(1) as f64;
            let left = per * (cfg.epochs - r.epoch) as f64;
            let val = if no_val {
                "no validation samples".to_string()
            } else {
                format!(
                    "validation precision {:.3} recall {:.3} (of GT faces {:.3})",
                    r.val.precision(),
                    r.val.recall(),
                    r.val.mesh_recall()
                )
            };
            say!(
                "\repoch {}/{}: loss {:.4}, lr {:.2e}, {val}, {:.1}s, ~{:.0} min left",
                r.epoch,
                cfg.epochs,
                r.loss,
                r.lr,
                r.seconds,
                left / 60.0
            );
        }
    };
    let mut save = |m: &Model, st: &TrainState| -> Result<()> {
        let st = TrainState { run: run_record.clone(), ..st.clone() };
        checkpoint::save(&ckpt_path, &m.to_checkpoint(Some(st)))?;
        let weights: Checkpoint = m.to_checkpoint(None);
        checkpoint::save(&out, &weights)
    };
    // Kept for a resume that finds its run already complete (below).
    let resumed_state = resume.as_ref().filter(|st| st.epoch >= cfg.epochs as u64).cloned();
    let reports = train(&mut model, &tr, &va, &cfg, resume, &mut progress, &mut save)?;
    if let Some(r) = reports.last() {
        let val = if no_val {
            " (no validation samples)".to_string()
        } else {
            format!("; final validation precision {:.3} recall {:.3}", r.val.precision(), r.val.recall())
        };
        say!(
            "train: done in {:.1} min{val}; weights in {}, checkpoint in {}",
            t_train.elapsed().as_secs_f64() / 60.0,
            out.display(),
            ckpt_path.display()
        );
    } else {
        // The run is complete, but `--out` may name another file than the one it wrote
        // (`--resume old.p2qm.ckpt --out new.p2qm`): the weights and the checkpoint go
        // there too, so that the output the command names exists when it exits 0.
        if let Some(st) = &resumed_state {
            save(&model, st)?;
        }
        say!(
            "train: already at epoch {start_epoch} of {}; nothing to train; weights in {}, checkpoint in {}",
            cfg.epochs,
            out.display(),
            ckpt_path.display()
        );
    }
    Ok(())
}
