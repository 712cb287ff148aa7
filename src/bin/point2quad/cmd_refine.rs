//! `point2quad refine`: adds refinement rounds to a trained model and trains them on
//! the classifier's own probabilities over a dataset (the classifier stays frozen).

use crate::args::{Args, Spec};
use crate::cmd_train::{draws_arg, fold_of, load_dir, parent_name, Split, MAX_FOLDS};
use crate::output::say;
use point2quad::nn::checkpoint;
use point2quad::pipeline::dataset::noise_variant;
use point2quad::pipeline::model::{Model, MAX_REFINE_ROUNDS};
use point2quad::pipeline::refine::{
    train_refiner, RefineInput, RefineProgress, RefineSample, RefineTrainConfig, SideRule,
};
use point2quad::pipeline::train::{check_samples, sample_input, TrainConfig};
use point2quad::{Error, Result};
use std::path::{Path, PathBuf};

pub const HELP: &str = "\
point2quad refine: train refinement rounds on top of a trained classifier

USAGE:
    point2quad refine --data DIR --model BASE --out MODEL [OPTIONS]

Scores every candidate of the .p2qs samples in DIR with BASE's classifier, then
trains ROUNDS small MLPs one after the other: each reads, per candidate, its current
probability and those of its rivals and neighbours (the best other candidate on
the same side of each edge, across each edge, over its diagonals, the probability
mass at its corners; with --features flow also how the best neighbour across
each edge continues the candidate's lattice lines and how its size compares; with
--features inside also how much the points inside the candidate look like
vertices) and gives a new probability. BASE's classifier (and point encoder) is
copied unchanged; rounds BASE already had are replaced. The validation split is
train's (same hash of the sample name, same --val-fraction and --hold-out), so use the dataset
BASE was trained on. MODEL is written atomically at the end (a run takes minutes).

OPTIONS:
    --data DIR            dataset folder (required)
    --model BASE          trained weights (required)
    --out MODEL           output weights (required)
    --rounds N            refinement rounds, 1..8 (the shipped weights: 6) [6]
    --widths W,W          hidden widths of each round's MLP [32,32]
    --epochs N            passes over the training candidates per round, 1..1000 [4]
    --batch B             candidates per step, 1..1000000 [4096]
    --lr X                initial learning rate (x0.1 over a round) [0.1]
    --seed S              initialisation and shuffling seed [0]
    --val-fraction F      share of samples held out for validation [0.15]
    --hold-out A,B,...    also hold out the samples with these names (as train)
    --fold-models M0,M1,...
                          score each training sample of fold i of K (K models, as
                          `train --fold i/K`) with Mi, a classifier that never saw it,
                          instead of BASE: the rounds then learn from probabilities
                          like those BASE gives on clouds it never saw (stacking).
                          Validation samples are scored with BASE. Each Mi must have
                          been trained with `--fold i/K` and the same --val-fraction and
                          --hold-out, and have BASE's input (preset, frame, normals)
    --sides RULE          how a round tells a rival (same side of an edge) from a
                          neighbour (across it): normals = by the direction the two
                          run the edge, reversed where their normals point opposite
                          ways (an orientation seam); direction = by direction alone
                          (models refined before session 8) [normals]
    --features SET        what a round reads: flow = the probability columns and the
                          8 flow columns (the shipped weights since session 18; needs
                          --sides normals); inside = flow and 2 columns on the
                          points inside the candidate (the most probability mass
                          and likely faces at one: a quad over a vertex is no
                          face; needs --sides normals); base = the probability
                          columns alone (models refined before session 18) [flow]
    --draws WHICH         samples of `dataset --noise-variants`: first = each sample's
                          first noise draw only (NAME; NAME~2 ... left out); all = every
                          draw, so the rounds also learn from BASE's scores on noise
                          points it was not trained on (the shipped rounds, since
                          session 22). Validation reads first draws either way.
                          (`train --draws` defaults to all, this one to first) [first]
    --precise-bn          first replace the classifier's batch-norm running statistics
                          (momentum averages over its last training steps, mostly the
                          last 20 or so clouds) by the mean over the training samples
                          read here of each block's batch statistics, each cloud's
                          candidates one batch (an even spread of at most 12,000, as
                          a training step draws); then score and train the rounds.
                          MODEL keeps those statistics. Not for models with a point
                          encoder or ones reading each cloud's own statistics, nor
                          with --fold-models (session 33)
";

const SPEC: Spec = Spec {
    valued: &[
        "--data",
        "--model",
        "--out",
        "--rounds",
        "--widths",
        "--epochs",
        "--batch",
        "--lr",
        "--seed",
        "--val-fraction",
        "--hold-out",
        "--sides",
        "--features",
        "--draws",
        "--fold-models",
    ],
    switches: &["--precise-bn"],
};

fn parse_widths(v: &str) -> Result<Vec<usize>> {
    let bad = || {
        Error::Usage(format!(
            "refine: --widths {v:?}: expected positive widths like 32,32 (at most 1024 each)"
        ))
    };
    if v.trim().is_empty() {
        return Ok(Vec::new());
    }
    let w: Vec<usize> =
        v.split(',').map(|x| x.trim().parse::<usize>().map_err(|_| bad())).collect::<Result<_>>()?;
    if w.is_empty() || w.len() > 8 || w.iter().any(|&x| x == 0 || x > 1024) {
        return Err(bad());
    }
    Ok(w)
}

pub fn run(argv: &[String]) -> Result<()> {
    let cmd = "refine";
    let a = Args::parse(cmd, argv, &SPEC)?;
    a.expect_positional(cmd, 0, "no positional arguments")?;
    let data = PathBuf::from(a.required(cmd, "--data")?);
    let base_path = PathBuf::from(a.required(cmd, "--model")?);
    let out = PathBuf::from(a.required(cmd, "--out")?);
    let rounds = a.parsed_in(cmd, "--rounds", 6usize, 1, MAX_REFINE_ROUNDS, "refinement rounds")?;
    let widths = parse_widths(a.value("--widths").unwrap_or("32,32"))?;
    let sides_name = a.value("--sides").unwrap_or("normals");
    let sides = SideRule::from_name(sides_name).ok_or_else(|| {
        Error::Usage(format!("refine: --sides {sides_name:?}: expected normals or direction"))
    })?;
    let input_name = a.value("--features").unwrap_or("flow");
    let input = RefineInput::from_name(input_name).ok_or_else(|| {
        Error::Usage(format!("refine: --features {input_name:?}: expected flow, inside or base"))
    })?;
    if input.reads_flow() && sides != SideRule::Normals {
        return Err(Error::Usage(format!(
            "refine: --features {} needs --sides normals (use --features base)",
            input.name()
        )));
    }
    let mut cfg = RefineTrainConfig::default();
    cfg.epochs = a.parsed_in(cmd, "--epochs", cfg.epochs, 1, 1000, "passes per round")?;
    cfg.batch = a.parsed_in(cmd, "--batch", cfg.batch, 1, 1_000_000, "candidates per step")?;
    cfg.sgd.lr = a.parsed(cmd, "--lr", cfg.sgd.lr)?;
    if !(cfg.sgd.lr.is_finite() && cfg.sgd.lr > 0.0) {
        return Err(Error::Usage(format!("refine: --lr must be a finite number > 0, got {}", cfg.sgd.lr)));
    }
    cfg.seed = a.parsed(cmd, "--seed", 0u64)?;
    let split = Split::from_args(cmd, &a)?;
    // By default the rounds train on each sample's first noise draw (`NAME`; `NAME~2`, …
    // of `dataset --noise-variants` are left out), so their time and figures stay those
    // of the dataset without variants; `--draws all` keeps the training part's draws.
    // Validation reads first draws either way.
    let all_draws = draws_arg(cmd, &a, false)?;
    crate::output::check_output_path(&out)?;
    crate::output::check_not_in_dataset(cmd, &out, &data)?;
    crate::output::check_not_input(cmd, &out, &base_path)?;
    for m in a.value("--fold-models").into_iter().flat_map(|v| v.split(',')) {
        crate::output::check_not_input(cmd, &out, Path::new(m.trim()))?;
    }
    let mut base = Model::load(&base_path)?;
    let fold_models: Vec<Model> = match a.value("--fold-models") {
        None => Vec::new(),
        Some(v) => {
            let paths: Vec<&str> = v.split(',').map(str::trim).collect();
            if paths.len() < 2 || paths.len() > MAX_FOLDS || paths.iter().any(|p| p.is_empty()) {
                return Err(Error::Usage(format!(
                    "refine: --fold-models {v:?}: expected 2 to {MAX_FOLDS} weights files separated by commas"
                )));
            }
            let ms = paths.iter().map(|p| Model::load(Path::new(p))).collect::<Result<Vec<_>>>()?;
            for (p, m) in paths.iter().zip(&ms) {
                if m.config().face_in() != base.config().face_in()
                    || m.config().sign_free_normals != base.config().sign_free_normals
                    || m.config().local_frame != base.config().local_frame
                {
                    return Err(Error::Usage(format!(
                        "refine: --fold-models: {p} reads a different input from {} (preset, frame or normals)",
                        base_path.display()
                    )));
                }
            }
            ms
        }
    };
    let precise = a.switch("--precise-bn");
    if precise && !fold_models.is_empty() {
        return Err(Error::Usage(
            "refine: --precise-bn recomputes BASE's statistics, but with --fold-models the training samples are scored by the fold models".into(),
        ));
    }
    // Checked before the data is read (a bad combination fails at once); built again
    // below, once --precise-bn has set the classifier's statistics.
    base.with_refinement_reading(rounds, &widths, sides, input, cfg.seed)?;
    let t0 = std::time::Instant::now();
    let (samples, names) = load_dir(cmd, &data, |s| {
        noise_variant(&s.name).1 == 1 || (all_draws && !split.is_validation(&s.name))
    })?;
    let drawn = names.len();
    if samples.len() < drawn {
        let why = if all_draws {
            "validation reads each sample's first"
        } else {
            "the rounds read each sample's first"
        };
        say!("refine: {} further noise draws (NAME~2, ...) left out: {why}", drawn - samples.len());
    }
    check_samples(&samples, &base)?;
    for m in &fold_models {
        check_samples(&samples, m)?;
    }
    split.check_names(cmd, samples.iter().map(|s| s.name.as_str()))?;
    // Before the samples are scored, which takes a while.
    if samples.iter().all(|s| split.is_validation(&s.name)) {
        return Err(split.nothing_to_train(cmd));
    }
    let fin = base.config().face_in();
    if precise {
        let t = std::time::Instant::now();
        // One sample's rows at a time.
        let rows = samples.iter().filter(|s| !split.is_validation(&s.name)).map(|s| sample_input(s, fin));
        let used = base
            .precise_batch_norm(rows, TrainConfig::default().max_candidates)
            .map_err(|e| Error::invalid(format!("refine --precise-bn: {}: {e}", base_path.display())))?;
        say!(
            "refine: batch-norm statistics of the classifier recomputed over {used} training samples in {:.1}s",
            t.elapsed().as_secs_f64()
        );
    }
    let mut model = base.with_refinement_reading(rounds, &widths, sides, input, cfg.seed)?;
    let n_samples = samples.len();
    let (mut tr, mut va) = (Vec::new(), Vec::new());
    for (i, s) in samples.into_iter().enumerate() {
        let x = sample_input(&s, fin);
        let validation = split.is_validation(&s.name);
        let scorer = if validation || fold_models.is_empty() {
            &base
        } else {
            &fold_models[fold_of(parent_name(&s.name), fold_models.len())]
        };
        let p = scorer
            .predict_base(&s.points, &s.candidates, &x)
            .map_err(|e| Error::invalid(format!("sample {}: {e}", s.name)))?;
        let rs =
            RefineSample { points: s.points, name: s.name, quads: s.candidates, labels: s.labels, base: p };
        if validation {
            va.push(rs);
        } else {
            tr.push(rs);
        }
        crate::output::info(&format!("\rrefine: scored {}/{n_samples} samples   ", i + 1));
    }
    let cands: usize = tr.iter().map(|s| s.quads.len()).sum();
    say!(
        "\rrefine: {} training / {} validation samples ({cands} training candidates) scored in {:.1}s; {rounds} round(s) of widths {widths:?}",
        tr.len(),
        va.len(),
        t0.elapsed().as_secs_f64()
    );
    if tr.is_empty() {
        return Err(split.nothing_to_train(cmd));
    }
    let t1 = std::time::Instant::now();
    let no_val = va.is_empty();
    let mut progress = |p: RefineProgress| match p {
        RefineProgress::Epoch { round, epoch, loss } => {
            crate::output::info(&format!(
                "\rround {round}/{rounds} epoch {epoch}/{}: loss {loss:.4}, {:.0}s   ",
                cfg.epochs,
                t1.elapsed().as_secs_f64()
            ));
        }
        // Without validation samples there is nothing to score (zeros would read as a
        // useless model), as `train` says too.
        RefineProgress::Round(r) if no_val => {
            say!("\rround {}: loss {:.4}; no validation samples", r.round, r.loss)
        }
        RefineProgress::Round(r) => say!(
            "\rround {}: loss {:.4}; validation P/R at 0.5 and AP {:.3}/{:.3}/{:.4} -> {:.3}/{:.3}/{:.4}",
            r.round,
            r.loss,
            r.val_before.precision,
            r.val_before.recall,
            r.val_before.average_precision,
            r.val_after.precision,
            r.val_after.recall,
            r.val_after.average_precision
        ),
    };
    let (refiner, params) =
        model.refiner_and_params_mut().ok_or_else(|| Error::invalid("no refinement rounds"))?;
    train_refiner(refiner, params, &tr, &va, &cfg, &mut progress)?;
    checkpoint::save(Path::new(&out), &model.to_checkpoint(None))?;
    say!("refine: done in {:.1} min; weights in {}", t0.elapsed().as_secs_f64() / 60.0, out.display());
    Ok(())
}
