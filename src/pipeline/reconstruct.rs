//! Reconstruction, end to end and in memory (the embedder's entry point; no file
//! I/O): validate and normalise the cloud, propose candidate quads, compute their
//! features, classify them (with the point encoder's features of their corners when
//! the model has one), post-process the faces predicted real into a manifold
//! pure-quad mesh. The output's vertices are the input points, bit-identical and in
//! order (unused ones stay as isolated vertices, so indices match the input), then the
//! vertices the hole filling added that some face uses (mapped back to the input's
//! frame). Exact duplicate points are one point to the pipeline: faces use the first
//! occurrence; a group of near-duplicates, its first point in coordinate order.

use crate::mesh::halfedge::corner_set;
use crate::mesh::poly::QuadMesh;
use crate::mesh::postprocess::{postprocess_with_reserve, PostprocessConfig, PostprocessReport};
use crate::mesh::watertight::{close_all, WatertightConfig, WatertightReport};
use crate::pipeline::candidates::{generate, CandidateConfig};
use crate::pipeline::features::FaceRows;
use crate::pipeline::frame::Frame;
use crate::pipeline::model::Model;
use crate::pipeline::second_pass::{covered_unused, covered_unused_by, learned_noise, point_features};
use crate::{Error, Result};

/// Largest neighbour count that [`reconstruct`] accepts (the candidates' bound,
/// [`crate::pipeline::candidates::MAX_NEIGHBOURS`]).
pub const MAX_NEIGHBOURS: usize = crate::pipeline::candidates::MAX_NEIGHBOURS;

/// Settings of [`reconstruct`].
#[derive(Clone, Debug)]
pub struct ReconstructConfig {
    /// Candidate generation.
    pub candidates: CandidateConfig,
    /// Faces with probability above this are handed to the post-process.
    pub threshold: f32,
    /// Run the post-process (paper filter, manifold insertion, hole filling). Without
    /// it the raw predicted faces are returned (possibly non-manifold: the paper's raw
    /// network output).
    pub run_postprocess: bool,
    /// Post-process settings.
    pub postprocess: PostprocessConfig,
    /// Near-duplicate merging: two points closer than this share of the distance from
    /// either to its 8th nearest other point are one point (the group's first in
    /// coordinate order is used, since session 41; see [`near_duplicate_roots`]). A cloud
    /// appended to a copy of itself moved by a rounding error otherwise fills every
    /// neighbourhood with near-copies
    /// and the surface is lost. Default 0.001: real quad meshes have vertex pairs at
    /// 0.0011 (`femhead_quad` of `train/`) and 0.015 (`qm_monkey`) of that distance
    /// (sliver edges), and merging one drops every face at the merged vertex. 0 merges
    /// exact duplicates only.
    pub merge_share: f32,
    /// A second pass without the points the first pass's mesh says are noise
    /// ([`SecondPass`]); `None` runs one pass. Default: τ 0.25,
    /// [`SecondPassMode::Average`] (session 26), [`SecondPassCover::Learned`] (since
    /// session 35). Part of the post-process: ignored when `run_postprocess` is false.
    pub second_pass: Option<SecondPass>,
    /// After the post-process (and the second pass), close every hole, odd ones paired
    /// by split strips of the least believed faces, even ones filled with new vertices
    /// ([`crate::mesh::watertight::close_all`]; not in the paper, session 32). `None`
    /// (the default) leaves the loops the classifier's faces do not close. Part of the
    /// post-process: ignored when `run_postprocess` is false.
    pub watertight: Option<WatertightConfig>,
    /// Each model runs at most this many of its refinement rounds (`None`: all of
    /// them); the result is what the model refined with that many rounds gives
    /// ([`crate::pipeline::refine::Refiner::apply_first`]).
    pub max_rounds: Option<usize>,
    /// Clouds of fewer points than this run at most [`ReconstructConfig::small_cloud_rounds`]
    /// refinement rounds (session 34; default 200 and 5: the shipped weights' sixth
    /// round runs on clouds of 200 points or more; 0 never applies). The rounds
    /// learn from the training clouds, the smallest of which has 238 points: a
    /// late round may then read a tiny cloud, most of whose faces are on its border,
    /// as it never saw one. Counted over the cloud each pass scores (distinct points,
    /// without the far outliers; the second pass without the points it left out).
    pub small_cloud_points: usize,
    /// See [`ReconstructConfig::small_cloud_points`].
    pub small_cloud_rounds: usize,
}

impl ReconstructConfig {
    /// How many refinement rounds a cloud of `points` points runs at most under this
    /// configuration (`None`: all the model has).
    pub fn rounds_for(&self, points: usize) -> Option<usize> {
        let small = (points < self.small_cloud_points).then_some(self.small_cloud_rounds);
        match (self.max_rounds, small) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }
}

/// The second pass of [`reconstruct`] (session 26): after the first pass's
/// post-process, points no face uses that lie inside an output face
/// ([`covered_unused`]) are taken for noise; candidates are proposed and scored again
/// without them, the two passes' candidates are merged ([`SecondPassMode`]) and the
/// post-process runs once more on the merged list.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SecondPass {
    /// How far off a face's plane a point may lie and still be inside it, in units of
    /// the face's mean edge length.
    pub tau: f64,
    /// How the passes' probabilities are combined.
    pub mode: SecondPassMode,
    /// Which of the first pass's faces say that a point inside them is noise.
    pub cover: SecondPassCover,
}

/// Which faces of the first pass's mesh cover points for [`SecondPass`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SecondPassCover {
    /// Every face of the finished mesh (hole fills, rescued and closing quads too).
    All,
    /// Only the faces the classifier predicted real (above the threshold): a point
    /// under a face the post-process added to close a hole may be a true vertex the
    /// first pass missed.
    Believed,
    /// A learned test over 16 values per point, the [`SecondPassCover::Believed`] rule's
    /// among them ([`crate::pipeline::second_pass::point_features`],
    /// [`crate::pipeline::second_pass::learned_noise`]; the default since session 35).
    Learned,
}

/// How [`SecondPass`] combines the two passes' candidates.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SecondPassMode {
    /// The second pass's candidates and probabilities alone.
    Replace,
    /// Both passes' candidates (the first pass's without a noise corner); a candidate
    /// both proposed gets the mean of its two probabilities.
    Average,
}

impl Default for ReconstructConfig {
    fn default() -> Self {
        ReconstructConfig {
            candidates: CandidateConfig::default(),
            threshold: 0.5,
            run_postprocess: true,
            postprocess: PostprocessConfig::default(),
            merge_share: 0.001,
            second_pass: Some(SecondPass {
                tau: 0.25,
                mode: SecondPassMode::Average,
                cover: SecondPassCover::Learned,
            }),
            watertight: None,
            max_rounds: None,
            small_cloud_points: 200,
            small_cloud_rounds: 5,
        }
    }
}

/// What a reconstruction did, and how long each stage took.
#[derive(Clone, Debug, Default)]
pub struct ReconstructReport {
    /// Input points.
    pub points: usize,
    /// Candidate quads proposed.
    pub candidates: usize,
    /// Candidates predicted real (probability above the threshold).
    pub predicted: usize,
    /// The highest probability among the candidates whose count is `predicted` (the
    /// merged ones after a second pass); `None` when there is no candidate. When nothing
    /// is predicted real it says how far below the threshold the cloud's best quad is.
    pub best_probability: Option<f32>,
    /// The post-process's account (absent with `run_postprocess = false`).
    pub postprocess: Option<PostprocessReport>,
    /// Faces in the output.
    pub faces: usize,
    /// Vertices added by the post-process (hole filling, the closing) and by
    /// `--watertight`'s closing ([`ReconstructReport::watertight`] counts those apart)
    /// that some output face uses: an added vertex whose faces a later step took out is
    /// not in the output (session 41).
    pub vertices_added: usize,
    /// Points left out as exact or near duplicates of another (in the output they are
    /// isolated vertices; faces use one point of each group: of exact copies the first
    /// in input order, of near-duplicates the first in coordinate order, so that any
    /// order of the input gives the same faces).
    pub duplicates: usize,
    /// Points left out as far outliers (see [`far_outliers`]), isolated in the output.
    pub outliers: usize,
    /// The first far outlier's index in the input, if any.
    pub first_outlier: Option<usize>,
    /// Points the normalised frame cannot resolve ([`PreparedCloud::unresolved`]).
    pub unresolved: usize,
    /// The first of them (input index), if any.
    pub first_unresolved: Option<usize>,
    /// Points the second pass left out as noise, when it ran; `None` when it did not
    /// (not configured; no point to leave out; fewer than 4 points, or no candidate,
    /// left): the first pass's mesh is then the output. `candidates` counts the first
    /// pass's candidates; `predicted` those above the threshold after the merge.
    pub second_pass_dropped: Option<usize>,
    /// What the watertight closing did, when it ran ([`ReconstructConfig::watertight`]).
    pub watertight: Option<WatertightReport>,
    /// (stage, seconds), in pipeline order.
    pub timings: Vec<(&'static str, f64)>,
}

/// Point cloud → pure-quad manifold mesh with `model`. The order of `points` does not
/// matter (since session 30): any order of the same points gives the same faces on the
/// same points, and the same added vertices (near-duplicates too since session 41: a
/// group's faces use its first point in coordinate order; of exact copies, which are
/// the same point, the first given).
///
/// # Errors
/// `Error::InvalidInput` for fewer than 4 (distinct) points, non-finite coordinates
/// (naming the point), a cloud with no extent, a threshold outside [0, 1), a merge
/// share outside [0, 0.5], a neighbour count above [`MAX_NEIGHBOURS`] or a second
/// pass's `tau` that is negative or not finite; shape errors
/// if the model does not fit; `Error::Checkpoint` (path `<model K>`) when a model's
/// probabilities are not finite.
pub fn reconstruct(points: &[[f64; 3]], model: &Model, cfg: &ReconstructConfig) -> Result<QuadMesh> {
    reconstruct_with_report(points, model, cfg).map(|(m, _)| m)
}

/// [`reconstruct`], also returning what each stage did and its time.
///
/// # Errors
/// As [`reconstruct`].
pub fn reconstruct_with_report(
    points: &[[f64; 3]],
    model: &Model,
    cfg: &ReconstructConfig,
) -> Result<(QuadMesh, ReconstructReport)> {
    reconstruct_ensemble_with_report(points, &[model], cfg)
}

/// [`reconstruct`] with an ensemble: every member scores the same candidates (its
/// classifier, then its own refinement rounds) and a candidate's probability is the
/// mean of the members'. One member is exactly [`reconstruct`].
///
/// # Errors
/// As [`reconstruct`], and `Error::InvalidInput` for an empty ensemble.
pub fn reconstruct_ensemble(
    points: &[[f64; 3]],
    models: &[&Model],
    cfg: &ReconstructConfig,
) -> Result<QuadMesh> {
    reconstruct_ensemble_with_report(points, models, cfg).map(|(m, _)| m)
}

/// [`reconstruct_ensemble`], also returning what each stage did and its time (the
/// classify and refine stages summed over the members).
///
/// # Errors
/// As [`reconstruct_ensemble`].
pub fn reconstruct_ensemble_with_report(
    points: &[[f64; 3]],
    models: &[&Model],
    cfg: &ReconstructConfig,
) -> Result<(QuadMesh, ReconstructReport)> {
    reconstruct_observed(points, models, cfg, &mut |_| {})
}

/// A stage of [`reconstruct_observed`] that has just ended.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StageDone {
    /// 2 for the stages the second pass runs on its own cloud (candidates, features,
    /// classify, refine), else 1.
    pub pass: u8,
    /// The stage's name, as in [`ReconstructReport::timings`].
    pub stage: &'static str,
    /// Its time (0 on wasm32, which has no clock).
    pub seconds: f64,
}

/// [`reconstruct_ensemble_with_report`], calling `observer` as each stage ends (for
/// progress on large clouds): every entry of the report's timings, in order, as pass
/// 1, except that when the second pass scored its cloud, the "second pass" entry right
/// after that is the sum of its stages, which the observer hears one by one as pass 2.
///
/// # Errors
/// As [`reconstruct_ensemble`].
pub fn reconstruct_observed(
    points: &[[f64; 3]],
    models: &[&Model],
    cfg: &ReconstructConfig,
    observer: &mut dyn FnMut(StageDone),
) -> Result<(QuadMesh, ReconstructReport)> {
    if models.is_empty() {
        return Err(Error::invalid("an ensemble needs at least one model"));
    }
    check_config(cfg)?;
    let mut report = ReconstructReport { points: points.len(), ..Default::default() };
    let mut clock = Clock::new(observer);
    let prep = prepare_cloud(points, cfg.merge_share)?;
    report.duplicates = prep.duplicates;
    report.outliers = prep.outliers;
    report.first_outlier = prep.first_outlier;
    report.unresolved = prep.unresolved;
    report.first_unresolved = prep.first_unresolved;
    let PreparedCloud { distinct, uniq, frame, local, .. } = prep;
    clock.lap(&mut report, "normalise");
    let (quads, probs) = score_cloud(&local, models, cfg, &mut clock, &mut report)?;
    let (faces, face_probs, reserve, reserve_probs) = split_at_threshold(&quads, &probs, cfg.threshold);
    report.predicted = faces.len();
    report.best_probability = best_of(&probs);
    // Index `i` of the distinct points (or, past them, of a vertex hole filling added)
    // → index in the output, whose vertices are the input points, then the added ones.
    let (n, u) = (points.len(), uniq.len());
    let to_output = |i: u32| if (i as usize) < u { distinct[i as usize] } else { (n - u) as u32 + i };
    // The stage the last lap times: the post-process; with a second pass, the test that
    // found nothing to leave out, its post-process, or nothing more when its scoring
    // found no candidate (its "second pass" entry is then the last).
    let mut last = Some("postprocess");
    let mesh = if cfg.run_postprocess {
        // The post-process runs in the normalised frame (in f64): in the input's own
        // coordinates its squared lengths and areas overflow at 1e200 and vanish at
        // 1e-200. Its thresholds are angles and ratios, so only the vertices the hole
        // filling adds need mapping back; the input's own are written back as given.
        let local64: Vec<[f64; 3]> = uniq.iter().map(|&p| frame.to_local_f64(p)).collect();
        // Candidates above the threshold and the rest (the reserve) → mesh.
        let post = |(faces, face_probs, reserve, reserve_probs): &Split| {
            postprocess_with_reserve(&local64, faces, face_probs, reserve, reserve_probs, &cfg.postprocess)
        };
        let first = (faces, face_probs, reserve, reserve_probs);
        let (mut mesh, mut pp) = post(&first)?;
        let mut final_split: Option<Split> = None;
        let faces = &first.0;
        if let Some(sp) = &cfg.second_pass {
            clock.lap(&mut report, "postprocess");
            last = Some("second pass");
            let noise = match sp.cover {
                SecondPassCover::All => covered_unused(&mesh.vertices, u, &mesh.quads, sp.tau),
                SecondPassCover::Believed => {
                    covered_unused_by(&mesh.vertices, u, &mesh.quads, &believed_in(&mesh, faces), sp.tau)
                }
                SecondPassCover::Learned => learned_noise(&first_pass_point_features(
                    &local,
                    &mesh,
                    u,
                    (&quads, &probs),
                    faces,
                    cfg.threshold,
                    sp.tau,
                )),
            };
            let kept: Vec<u32> = (0..u as u32).filter(|&i| !noise[i as usize]).collect();
            if kept.len() < u && kept.len() >= 4 {
                let local2: Vec<[f32; 3]> = kept.iter().map(|&i| local[i as usize]).collect();
                let mut report2 = ReconstructReport::default();
                clock.pass = 2;
                let (q2, p2) = score_cloud(&local2, models, cfg, &mut clock, &mut report2)?;
                clock.pass = 1;
                // The sum of the stages the observer was told of one by one.
                let t: f64 = report2.timings.iter().map(|t| t.1).sum();
                report.timings.push(("second pass", t));
                last = None;
                // No candidate among the points left (too few, or all on a line): the
                // first pass's mesh stands.
                if !q2.is_empty() {
                    let q2: Vec<[u32; 4]> = q2.iter().map(|q| q.map(|v| kept[v as usize])).collect();
                    let (quads, probs) = merge_passes(&quads, &probs, &noise, &q2, &p2, sp.mode);
                    let second = split_at_threshold(&quads, &probs, cfg.threshold);
                    report.predicted = second.0.len();
                    report.best_probability = best_of(&probs);
                    report.second_pass_dropped = Some(u - kept.len());
                    last = Some("second postprocess");
                    (mesh, pp) = post(&second)?;
                    final_split = Some(second);
                }
            }
        }
        if let Some(wcfg) = &cfg.watertight {
            if let Some(l) = last {
                clock.lap(&mut report, l);
            }
            last = Some("watertight");
            // Every candidate of the last scoring with its probability: the strips run
            // through the least believed faces, and the rescue takes its quads there.
            let (f, fp, r, rp) = final_split.as_ref().unwrap_or(&first);
            let all: Vec<[u32; 4]> = f.iter().chain(r).copied().collect();
            let all_p: Vec<f32> = fp.iter().chain(rp).copied().collect();
            let (closed, wr) = close_all(&mesh, wcfg, &all, &all_p)?;
            mesh = closed;
            report.watertight = Some(wr);
        }
        // A vertex the hole filling added whose quads a later step took out (the seal,
        // the untangle, the unfold) would stay in the output, isolated (session 41's
        // audit): only the input's points stay whether used or not.
        let mesh = mesh.without_unused_from(u).0;
        report.vertices_added = mesh.vertices.len() - u;
        report.postprocess = Some(pp);
        let mut vertices = points.to_vec();
        vertices.extend(mesh.vertices[u..].iter().map(|&p| frame.to_world_f64(p)));
        QuadMesh { vertices, quads: mesh.quads.iter().map(|q| q.map(to_output)).collect() }
    } else {
        QuadMesh { vertices: points.to_vec(), quads: faces.iter().map(|q| q.map(to_output)).collect() }
    };
    report.faces = mesh.quads.len();
    if let Some(last) = last {
        clock.lap(&mut report, last);
    }
    Ok((mesh, report))
}

/// What [`SecondPassCover::Learned`]'s test reads about each point of `points`, as
/// [`reconstruct`] computes it after its first pass: the input index of each distinct
/// point the pipeline works on ([`PreparedCloud::distinct`]) with its
/// [`point_features`]. The post-process runs as `cfg` says (it must run:
/// `run_postprocess`); the second pass's `tau` is read from `cfg.second_pass` (0.25
/// without one). For fitting the test (`examples/noise_test_fit.rs`).
///
/// # Errors
/// As [`reconstruct`] (the same settings refused), and `InvalidInput` when
/// `cfg.run_postprocess` is false.
pub fn first_pass_features(
    points: &[[f64; 3]],
    model: &Model,
    cfg: &ReconstructConfig,
) -> Result<Vec<(u32, [f32; crate::pipeline::second_pass::NOISE_FEATURES])>> {
    if !cfg.run_postprocess {
        return Err(Error::invalid("the first pass's features need the post-process"));
    }
    check_config(cfg)?;
    let tau = cfg.second_pass.map_or(0.25, |sp| sp.tau);
    let prep = prepare_cloud(points, cfg.merge_share)?;
    let mut quiet = |_: StageDone| {};
    let mut clock = Clock::new(&mut quiet);
    let mut report = ReconstructReport::default();
    let (quads, probs) = score_cloud(&prep.local, &[model], cfg, &mut clock, &mut report)?;
    let (faces, face_probs, reserve, reserve_probs) = split_at_threshold(&quads, &probs, cfg.threshold);
    let u = prep.uniq.len();
    let local64: Vec<[f64; 3]> = prep.uniq.iter().map(|&p| prep.frame.to_local_f64(p)).collect();
    let (mesh, _) =
        postprocess_with_reserve(&local64, &faces, &face_probs, &reserve, &reserve_probs, &cfg.postprocess)?;
    let x = first_pass_point_features(&prep.local, &mesh, u, (&quads, &probs), &faces, cfg.threshold, tau);
    Ok(prep.distinct.iter().copied().zip(x).collect())
}

/// The settings [`reconstruct`] refuses before any work on the cloud (the merge share is
/// checked by [`prepare_cloud`]): a threshold outside [0, 1), a second pass's `tau` that
/// is negative or not finite, neighbour counts out of range.
fn check_config(cfg: &ReconstructConfig) -> Result<()> {
    if !(cfg.threshold >= 0.0 && cfg.threshold < 1.0) {
        return Err(Error::invalid(format!("threshold {} must be in [0, 1)", cfg.threshold)));
    }
    if let Some(sp) = &cfg.second_pass {
        if !(sp.tau >= 0.0 && sp.tau.is_finite()) {
            return Err(Error::invalid(format!("second pass: tau {} must be finite and at least 0", sp.tau)));
        }
    }
    crate::pipeline::candidates::check_neighbour_counts(&cfg.candidates)
}

/// The highest of `probs` (`None` when empty).
fn best_of(probs: &[f32]) -> Option<f32> {
    probs.iter().copied().reduce(f32::max)
}

/// The faces of `mesh` the classifier predicted real: those whose vertex set is one of
/// `faces` (the candidates above the threshold).
fn believed_in(mesh: &QuadMesh, faces: &[[u32; 4]]) -> Vec<[u32; 4]> {
    let believed: std::collections::HashSet<[u32; 4]> = faces.iter().map(|&q| corner_set(q)).collect();
    mesh.quads.iter().copied().filter(|&q| believed.contains(&corner_set(q))).collect()
}

/// [`point_features`] of the first pass: its finished `mesh` (in the normalised frame),
/// its scored candidates, and `faces`, those above the threshold.
fn first_pass_point_features(
    local: &[[f32; 3]],
    mesh: &QuadMesh,
    u: usize,
    (quads, probs): (&[[u32; 4]], &[f32]),
    faces: &[[u32; 4]],
    threshold: f32,
    tau: f64,
) -> Vec<[f32; crate::pipeline::second_pass::NOISE_FEATURES]> {
    let covering = believed_in(mesh, faces);
    point_features(local, &mesh.vertices, u, quads, probs, &mesh.quads, &covering, threshold, tau)
}

/// Candidates of a normalised cloud and their probabilities (the members' mean):
/// candidates, features, classification and refinement rounds, timed into `report`.
fn score_cloud(
    local: &[[f32; 3]],
    models: &[&Model],
    cfg: &ReconstructConfig,
    clock: &mut Clock<'_>,
    report: &mut ReconstructReport,
) -> Result<(Vec<[u32; 4]>, Vec<f32>)> {
    let cands = generate(local, &cfg.candidates)?;
    report.candidates = cands.len();
    clock.lap(report, "candidates");
    // The face input depends on the model only through `use_context`: one row maker
    // per value the members need. The rows themselves are made chunk by chunk while
    // the classifier scores them (session 38; before, the whole `M × 45` matrix was
    // built here and held through classification: at a million points, 1.45 GB and the
    // run's peak), so the "features" stage is now only the context columns' edge
    // table, and making the rows is timed with "classify".
    let mut inputs: [Option<FaceRows>; 2] = [None, None];
    for m in models {
        let ctx = m.config().use_context;
        if inputs[ctx as usize].is_none() {
            inputs[ctx as usize] = Some(FaceRows::new(local, &cands, ctx));
        }
    }
    clock.lap(report, "features");
    // Every member's classifier first, so that the row makers and the candidates'
    // side tables (the largest buffers at millions of candidates) are freed before the
    // refinement rounds build their graph.
    let mut bases = Vec::with_capacity(models.len());
    for (k, model) in models.iter().enumerate() {
        let Some(rows) = &inputs[model.config().use_context as usize] else {
            return Err(Error::invalid("internal error: no face rows for a member"));
        };
        // The point encoder (if the model has one) reads the same normalised cloud the
        // candidates were built in, as in training.
        let base = model.predict_base_rows(local, rows)?;
        check_probabilities(k, &base)?;
        bases.push(base);
    }
    drop(inputs);
    // The rest of `cands` (kNN table, normals, ranks) goes with the block.
    let quads = {
        let c = cands;
        c.quads
    };
    // Freeing those counts with classification, not with the first round.
    let t_classify = clock.split();
    let mut t_refine = None;
    let mut probs: Vec<f32> = Vec::new();
    for (k, (model, base)) in models.iter().zip(bases).enumerate() {
        // Refinement rounds (when the model has them) rescore every candidate by its
        // rivals and neighbours: the same as `predict_with_points`, timed apart.
        let p = match model.refiner() {
            Some(r) => {
                let n = cfg.rounds_for(local.len()).unwrap_or(usize::MAX);
                let p = r.apply_first(&model.params, local, &quads, &base, n)?;
                *t_refine.get_or_insert(0.0) += clock.split();
                check_probabilities(k, &p)?;
                p
            }
            None => base,
        };
        if probs.is_empty() {
            probs = p;
        } else {
            probs.iter_mut().zip(&p).for_each(|(a, b)| *a += b);
        }
    }
    if models.len() > 1 {
        let inv = 1.0 / models.len() as f32;
        probs.iter_mut().for_each(|a| *a *= inv);
    }
    clock.record(report, "classify", t_classify);
    if let Some(t) = t_refine {
        clock.record(report, "refine", t);
    }
    Ok((quads, probs))
}

/// Candidates above the threshold and their probabilities, then the rest and theirs.
type Split = (Vec<[u32; 4]>, Vec<f32>, Vec<[u32; 4]>, Vec<f32>);

/// Candidates above `threshold` (with their probabilities), then the rest (the
/// reserve the post-process may rescue at holes).
fn split_at_threshold(quads: &[[u32; 4]], probs: &[f32], threshold: f32) -> Split {
    let (mut faces, mut face_probs, mut reserve, mut reserve_probs) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for (q, &p) in quads.iter().zip(probs) {
        if p > threshold {
            faces.push(*q);
            face_probs.push(p);
        } else {
            reserve.push(*q);
            reserve_probs.push(p);
        }
    }
    (faces, face_probs, reserve, reserve_probs)
}

/// The candidates of the two passes as one list. Under [`SecondPassMode::Replace`],
/// the second pass's alone. Under [`SecondPassMode::Average`], first-pass candidates
/// with a corner taken for noise go; a vertex set both passes proposed keeps the first
/// pass's cyclic order (each pass keeps one polygon per vertex set; on a set in convex
/// position both find the same one) and gets the mean of its two probabilities; one
/// only a pass proposed keeps that pass's order and probability.
fn merge_passes(
    q1: &[[u32; 4]],
    p1: &[f32],
    noise: &[bool],
    q2: &[[u32; 4]],
    p2: &[f32],
    mode: SecondPassMode,
) -> (Vec<[u32; 4]>, Vec<f32>) {
    if mode == SecondPassMode::Replace {
        return (q2.to_vec(), p2.to_vec());
    }
    let key = |q: &[u32; 4]| corner_set(*q);
    let first: std::collections::HashMap<[u32; 4], usize> = q1
        .iter()
        .enumerate()
        .filter(|(_, q)| q.iter().all(|&v| !noise.get(v as usize).copied().unwrap_or(false)))
        .map(|(i, q)| (key(q), i))
        .collect();
    let mut quads = Vec::with_capacity(q2.len() + first.len());
    let mut probs = Vec::with_capacity(q2.len() + first.len());
    let mut taken = vec![false; q1.len()];
    for (q, &p) in q2.iter().zip(p2) {
        match first.get(&key(q)) {
            Some(&i) => {
                taken[i] = true;
                quads.push(q1[i]);
                probs.push(0.5 * (p + p1[i]));
            }
            None => {
                quads.push(*q);
                probs.push(p);
            }
        }
    }
    let mut rest: Vec<usize> = first.values().copied().filter(|&i| !taken[i]).collect();
    rest.sort_unstable();
    for i in rest {
        quads.push(q1[i]);
        probs.push(p1[i]);
    }
    (quads, probs)
}

/// A cloud made ready for the pipeline by [`prepare_cloud`].
#[derive(Clone, Debug)]
pub struct PreparedCloud {
    /// Input index of each point the pipeline works on (of each group of exact duplicates
    /// the first in input order, of near-duplicates the first in coordinate order; far
    /// outliers left out), in coordinate order
    /// (by x, then y, then z; since session 30: every step from the outliers on reads the
    /// points in that order), so that no stage depends on the input's order.
    pub distinct: Vec<u32>,
    /// Those points, as given.
    pub uniq: Vec<[f64; 3]>,
    /// The normalising frame fitted to them.
    pub frame: Frame,
    /// Those points in the frame (f32, what candidates and the network read).
    pub local: Vec<[f32; 3]>,
    /// Input points left out as exact or near duplicates of an earlier one.
    pub duplicates: usize,
    /// Input points left out as far outliers ([`far_outliers`]).
    pub outliers: usize,
    /// The first far outlier's input index.
    pub first_outlier: Option<usize>,
    /// Distinct points whose whole neighbourhood the normalised frame cannot resolve:
    /// their 8 nearest other points lie within [`UNRESOLVED_SHARE`] of the frame's
    /// radius, i.e. at the f32 resolution every later stage works in. A cloud that
    /// spans too many orders of magnitude (two objects 1e9 apart, a few points at 1e30
    /// beside a unit-sized bulk) has such points: at f32 resolution its small parts
    /// collapse, so they are left out (isolated in the output, like far outliers; since
    /// session 27: before, faces proposed over the collapsed positions came out wrong),
    /// and their faces are lost. Fewer than 4 points left is an error.
    pub unresolved: usize,
    /// The first such point's input index.
    pub first_unresolved: Option<usize>,
}

/// A point whose 8 nearest other points all lie closer than this share of the frame's
/// radius is "unresolved" ([`PreparedCloud::unresolved`]): 2⁻²⁰, 16 f32 steps at the
/// radius.
pub const UNRESOLVED_SHARE: f64 = 1.0 / 1048576.0;

/// The input hygiene [`reconstruct`] (and the CLI's `candidates`) run before any work:
/// validates the cloud as given (errors name input indices), counts exact duplicates
/// once, leaves far outliers out, fits the normalising frame and merges near-duplicates
/// (`merge_share`, see [`ReconstructConfig::merge_share`]; 0: exact duplicates only).
///
/// # Errors
/// `InvalidInput` as [`Frame::fit`], for fewer than 4 distinct points, or a merge share
/// outside [0, 0.5].
pub fn prepare_cloud(points: &[[f64; 3]], merge_share: f32) -> Result<PreparedCloud> {
    if !(0.0..=0.5).contains(&merge_share) {
        return Err(Error::invalid(format!("merge share {merge_share} must be in [0, 0.5]")));
    }
    // Validate the cloud as given (errors name input indices), then work on its
    // distinct points: exact duplicates fill the k nearest neighbours with copies
    // (5 copies of each point left a k = 20 search 4 distinct neighbours, and half the
    // faces of a cube were lost) and add nothing to the surface.
    Frame::fit(points)?;
    // Nothing downstream may depend on the input's order (session 30: a shuffled cloud
    // lost recall, as candidates' corners started at their smallest index and the
    // network had learnt that noise points come last): the points are taken in
    // coordinate order, and every later tie that falls by index falls by position.
    let mut distinct = distinct_points(points);
    let key = |i: u32| points[i as usize].map(|c| c + 0.0);
    distinct.sort_by(|a, b| {
        let (p, q) = (key(*a), key(*b));
        p[0].total_cmp(&q[0]).then(p[1].total_cmp(&q[1])).then(p[2].total_cmp(&q[2]))
    });
    let too_few = |u: usize| {
        Error::invalid(format!(
            "point cloud has {u} distinct point(s) (of {}); at least 4 are needed for a quad",
            points.len()
        ))
    };
    if distinct.len() < 4 {
        return Err(too_few(distinct.len()));
    }
    // Far outliers (a stray point 1e10 away) would squeeze the rest of the cloud into
    // a speck of the normalised frame, below f32 resolution: left out. Beyond 10⁴ times
    // the 95th percentile of the distances from the median; and when more than 5% are
    // strays (the percentile is then one of them) and they would leave most of the
    // cloud below the frame's resolution, beyond 10⁴ times the median distance
    // (session 30). A second object far away but resolved stays.
    let (mut uniq, mut frame, mut local) = framed(points, &distinct)?;
    let mut far = far_outliers(&uniq);
    // The neighbour table and the unresolved points of the cloud as it stands, when the
    // median rule needed them and cut nothing (then they are the ones used below).
    let mut resolved = None;
    if far.is_empty() {
        let strays = far_outliers_beyond_median(&uniq);
        if !strays.is_empty() {
            // A bulk of at most NEAR_K points has a stray among its 8 nearest, so the
            // resolution test cannot see it squeezed (session 41's fuzz: one point at
            // 1e308 beside 4–6 unit points; the merge then made them one): such strays go.
            if local.len() - strays.len() <= NEAR_K {
                far = strays;
            } else {
                let (knn, reach, lost) = resolution(&local);
                if 2 * lost.len() > local.len() {
                    far = strays;
                } else {
                    resolved = Some((knn, reach, lost));
                }
            }
        }
    }
    let (outliers, first_outlier) = (far.len(), far.iter().map(|&j| distinct[j] as usize).min());
    if !far.is_empty() {
        let before = distinct.len();
        distinct = without(&distinct, &far);
        if distinct.len() < 4 {
            return Err(Error::invalid(format!(
                "point cloud: leaving out {outliers} far outlier(s) leaves {} of its {before} distinct \
                 points; at least 4 are needed for a quad",
                distinct.len()
            )));
        }
        (uniq, frame, local) = framed(points, &distinct)?;
    }
    let (mut knn, mut reach, lost) = match resolved {
        Some(r) => r,
        None => resolution(&local),
    };
    let (unresolved, first_unresolved) = (lost.len(), lost.iter().map(|&i| distinct[i] as usize).min());
    if !lost.is_empty() {
        // Left out like far outliers: at f32 resolution their positions collapse onto
        // a few values, and the faces proposed over them are wrong (inverted, folded).
        distinct = without(&distinct, &lost);
        if distinct.len() < 4 {
            return Err(Error::invalid(format!(
                "point cloud: {unresolved} of its {} distinct points lie closer together than the \
                 normalised frame resolves (their 8 nearest neighbours within {UNRESOLVED_SHARE:.1e} \
                 of the cloud's radius: f32 precision), leaving {} (at least 4 are needed); the \
                 first is point {} (counting from 0). The cloud spans too many orders of magnitude \
                 (parts far apart): reconstruct its parts separately",
                unresolved + distinct.len(),
                distinct.len(),
                first_unresolved.unwrap_or(0)
            )));
        }
        (uniq, frame, local) = framed(points, &distinct)?;
        // The neighbour table serves the near-duplicate merge alone.
        if merge_share > 0.0 {
            knn = crate::pipeline::candidates::knn_table(&local, NEAR_K);
            reach = reach_of(&knn, local.len());
        }
    }
    if merge_share > 0.0 {
        let roots = near_duplicate_roots_with(&knn, &reach, merge_share);
        if roots.iter().enumerate().any(|(i, &r)| r as usize != i) {
            // Each group keeps its root, its first point in coordinate order (its faces
            // use it). It kept its first in input order until session 41, whose audit
            // found that the one choice left to the input's order: a shuffled cloud of
            // near-duplicates gave another mesh (141 of 684 faces on one cloud).
            let keep: Vec<usize> = (0..roots.len()).filter(|&i| roots[i] as usize == i).collect();
            if keep.len() < 4 {
                // Not "distinct": the points are distinct, the merge made them one.
                return Err(Error::invalid(format!(
                    "point cloud: merging near-duplicates (points closer than {merge_share} times the \
                     distance to their 8th nearest other point) leaves {} of its {} distinct points; at \
                     least 4 are needed for a quad. Groups of 8 or fewer points far from the rest \
                     merge this way; a merge share of 0 (`reconstruct --merge-share 0`) merges exact \
                     duplicates only",
                    keep.len(),
                    roots.len()
                )));
            }
            distinct = keep.iter().map(|&i| distinct[i]).collect();
            (uniq, frame, local) = framed(points, &distinct)?;
        }
    }
    let duplicates = points.len() - distinct.len() - outliers - unresolved;
    Ok(PreparedCloud {
        distinct,
        uniq,
        frame,
        local,
        duplicates,
        outliers,
        first_outlier,
        unresolved,
        first_unresolved,
    })
}

/// `list` without its entries at the positions `drop` (positions into `list`), in order.
fn without(list: &[u32], drop: &[usize]) -> Vec<u32> {
    let mut out = vec![false; list.len()];
    drop.iter().for_each(|&j| out[j] = true);
    list.iter().zip(&out).filter(|(_, &o)| !o).map(|(&i, _)| i).collect()
}

/// A model whose output is not a probability (NaN or infinite: diverged or damaged
/// weights) is the model's fault, not the cloud's: `Error::Checkpoint` with the path
/// `<model K>` (K its place in the ensemble, from 0), which the CLI replaces by the
/// file's name.
fn check_probabilities(k: usize, p: &[f32]) -> Result<()> {
    match p.iter().position(|x| !x.is_finite()) {
        None => Ok(()),
        Some(i) => Err(Error::Checkpoint {
            path: std::path::PathBuf::from(format!("<model {k}>")),
            msg: format!(
                "the network gives a non-finite probability ({}) for candidate {i}: its weights are unusable",
                p[i]
            ),
        }),
    }
}

/// How far from the cloud's bulk a point may lie, in units of the bulk's radius (see
/// [`far_outliers`]).
pub const OUTLIER_RADII: f64 = 1e4;

/// Indices of the far outliers of `points`: farther from the coordinate-wise median than
/// [`OUTLIER_RADII`] times the 95th percentile of all points' distances from it. A quad
/// cannot join such a point to the rest (edge ratios below 1e-4), and normalising the
/// cloud with it would leave the rest below f32 resolution. Empty when that percentile
/// is 0 (most points identical) or for fewer than 20 points (no bulk to speak of).
/// More than 5% of strays hide behind the percentile: [`far_outliers_beyond_median`].
pub fn far_outliers(points: &[[f64; 3]]) -> Vec<usize> {
    if points.len() < 20 {
        return Vec::new();
    }
    beyond_quantile(points, 95)
}

/// The points farther from the coordinate-wise median than [`OUTLIER_RADII`] times the
/// median of all points' distances from it: up to half the points may be such strays
/// (session 30: 36 points at 1e9 beside 640 on a torus hid behind [`far_outliers`]'s
/// percentile and took the torus's faces). `prepare_cloud` leaves them out only when
/// the percentile rule finds none and they would leave most of the cloud below the
/// frame's resolution, so a second object far away but resolved stays. Empty for fewer
/// than 5 points or a median distance of 0.
pub fn far_outliers_beyond_median(points: &[[f64; 3]]) -> Vec<usize> {
    if points.len() < 5 {
        return Vec::new();
    }
    beyond_quantile(points, 50)
}

/// Points as given, their normalising frame, and their coordinates in it.
type Framed = (Vec<[f64; 3]>, Frame, Vec<[f32; 3]>);

/// The points `distinct` (input indices) of `points`, their normalising frame and their
/// coordinates in it.
fn framed(points: &[[f64; 3]], distinct: &[u32]) -> Result<Framed> {
    let uniq: Vec<[f64; 3]> = distinct.iter().map(|&i| points[i as usize]).collect();
    let frame = Frame::fit(&uniq)?;
    let local = frame.to_local_all(&uniq);
    Ok((uniq, frame, local))
}

/// A normalised cloud's [`NEAR_K`]-nearest table, each point's reach, and the points
/// the frame does not resolve: their reach under [`UNRESOLVED_SHARE`] of its radius.
fn resolution(local: &[[f32; 3]]) -> (crate::spatial::kdtree::KnnTable, Vec<f32>, Vec<usize>) {
    let knn = crate::pipeline::candidates::knn_table(local, NEAR_K);
    let reach = reach_of(&knn, local.len());
    let lost = (0..local.len()).filter(|&i| (reach[i] as f64) < UNRESOLVED_SHARE).collect();
    (knn, reach, lost)
}

/// The points farther from the coordinate-wise median than [`OUTLIER_RADII`] times the
/// `percent`-th percentile of the distances from it (none when that is 0).
fn beyond_quantile(points: &[[f64; 3]], percent: usize) -> Vec<usize> {
    // In raw coordinates, with a scaled norm: squares overflow at 1e200 and vanish at
    // 1e-200 (a bulk at 1 beside a point at 1e200 is both). A difference that
    // overflows is an infinite distance.
    let mut median = [0.0f64; 3];
    let mut col: Vec<f64> = Vec::with_capacity(points.len());
    for (a, m) in median.iter_mut().enumerate() {
        col.clear();
        col.extend(points.iter().map(|p| p[a]));
        let mid = col.len() / 2;
        *m = *col.select_nth_unstable_by(mid, f64::total_cmp).1;
    }
    let norm = |p: &[f64; 3]| {
        let v = [p[0] - median[0], p[1] - median[1], p[2] - median[2]];
        let big = v.iter().fold(0.0f64, |m, c| m.max(c.abs()));
        if big == 0.0 || !big.is_finite() {
            return big;
        }
        big * v.iter().map(|c| (c / big) * (c / big)).sum::<f64>().sqrt()
    };
    let d: Vec<f64> = points.iter().map(norm).collect();
    let mut sorted = d.clone();
    let at = (sorted.len() * percent) / 100;
    let r = *sorted.select_nth_unstable_by(at, f64::total_cmp).1;
    if r <= 0.0 {
        return Vec::new();
    }
    (0..d.len()).filter(|&i| d[i] > OUTLIER_RADII * r).collect()
}

/// Near-duplicate groups of a normalised cloud with no exact duplicates: `roots[i]` is
/// the smallest index of the group of point `i`. Points `i` and `j` join when `j` is
/// among the 8 nearest of `i` (or the reverse) and closer than `share` times the
/// smaller of their distances to their 8th nearest other point; groups are the
/// transitive closure. Scale-free; a quad mesh's vertices never join (their nearest
/// other vertex is a sizeable share of their 8th), while a copy of the cloud moved by
/// a rounding error or a small share of the spacing joins its original.
pub fn near_duplicate_roots(local: &[[f32; 3]], share: f32) -> Vec<u32> {
    let knn = crate::pipeline::candidates::knn_table(local, NEAR_K);
    near_duplicate_roots_with(&knn, &reach_of(&knn, local.len()), share)
}

/// Neighbours [`near_duplicate_roots`] reads per point (its reach is the distance to
/// the last of them).
const NEAR_K: usize = 8;

/// Per point, the distance to its farthest of the [`NEAR_K`] nearest other points.
fn reach_of(knn: &crate::spatial::kdtree::KnnTable, n: usize) -> Vec<f32> {
    (0..n).map(|i| knn.row(i).1.last().copied().unwrap_or(0.0).sqrt()).collect()
}

/// [`near_duplicate_roots`] over a [`NEAR_K`]-nearest table and its reaches.
fn near_duplicate_roots_with(knn: &crate::spatial::kdtree::KnnTable, reach: &[f32], share: f32) -> Vec<u32> {
    let n = reach.len();
    let mut parent: Vec<u32> = (0..n as u32).collect();
    if n < 2 {
        return parent;
    }
    fn root(p: &mut [u32], mut x: u32) -> u32 {
        while p[x as usize] != x {
            let up = p[p[x as usize] as usize];
            p[x as usize] = up;
            x = up;
        }
        x
    }
    for i in 0..n {
        let (idx, d2) = knn.row(i);
        for (&j, &d2) in idx.iter().zip(d2) {
            if j as usize == i || d2.sqrt() > share * reach[i].min(reach[j as usize]) {
                continue;
            }
            let (a, b) = (root(&mut parent, i as u32), root(&mut parent, j));
            // The smaller index stays the root, so a group's root is its first point.
            if a != b {
                let (lo, hi) = if a < b { (a, b) } else { (b, a) };
                parent[hi as usize] = lo;
            }
        }
    }
    (0..n as u32).map(|i| root(&mut parent, i)).collect()
}

/// Indices of the first occurrence of each distinct point, in input order (`-0.0`
/// and `0.0` are one value). The cloud has been validated: every coordinate is finite.
fn distinct_points(points: &[[f64; 3]]) -> Vec<u32> {
    let key = |p: &[f64; 3]| p.map(|c| (c + 0.0).to_bits());
    let mut order: Vec<u32> = (0..points.len() as u32).collect();
    // Stable: equal points keep input order, so the first of a run is the first occurrence.
    order.sort_by_key(|&i| key(&points[i as usize]));
    let mut first: Vec<u32> = Vec::with_capacity(points.len());
    for (j, &i) in order.iter().enumerate() {
        if j == 0 || key(&points[order[j - 1] as usize]) != key(&points[i as usize]) {
            first.push(i);
        }
    }
    first.sort_unstable();
    first
}

/// Times the stages and tells the observer of [`reconstruct_observed`] as each ends.
struct Clock<'a> {
    t: crate::clock::Stopwatch,
    /// 2 while the second pass scores its cloud, else 1.
    pass: u8,
    observer: &'a mut dyn FnMut(StageDone),
}

impl<'a> Clock<'a> {
    fn new(observer: &'a mut dyn FnMut(StageDone)) -> Clock<'a> {
        Clock { t: crate::clock::Stopwatch::start(), pass: 1, observer }
    }
    /// Records the time since the last lap (0 on wasm32, which has no clock).
    fn lap(&mut self, report: &mut ReconstructReport, stage: &'static str) {
        let t = self.split();
        self.record(report, stage, t);
    }
    /// Seconds since the last lap or split, restarting the count (0 on wasm32).
    fn split(&mut self) -> f64 {
        self.t.split()
    }
    /// Records a stage's time, measured by [`Clock::split`]s, and tells the observer.
    fn record(&mut self, report: &mut ReconstructReport, stage: &'static str, seconds: f64) {
        report.timings.push((stage, seconds));
        (self.observer)(StageDone { pass: self.pass, stage, seconds });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::shapes;
    use crate::pipeline::model::ModelConfig;

    /// The defaults session 35 shipped: the sixth round stays off clouds under 200
    /// points, and the second pass's noise points are the learned test's.
    #[test]
    fn the_defaults_gate_the_sixth_round_and_learn_the_noise() {
        let cfg = ReconstructConfig::default();
        assert_eq!(cfg.rounds_for(199), Some(5));
        assert_eq!(cfg.rounds_for(200), None);
        assert_eq!(cfg.second_pass.map(|s| s.cover), Some(SecondPassCover::Learned));
    }

    /// The merge of the two passes, against its definition written out per case.
    #[test]
    fn the_passes_merge_by_vertex_set() {
        // First pass: A, B (corner 9 is noise), C; second pass: A (another cyclic
        // order), D.
        let q1 = [[0, 1, 2, 3], [1, 9, 4, 5], [2, 3, 6, 7]];
        let p1 = [0.8, 0.9, 0.2];
        let mut noise = vec![false; 10];
        noise[9] = true;
        let q2 = [[1, 2, 3, 0], [4, 5, 6, 7]];
        let p2 = [0.4, 0.7];
        let (q, p) = merge_passes(&q1, &p1, &noise, &q2, &p2, SecondPassMode::Average);
        assert_eq!(q, vec![[0, 1, 2, 3], [4, 5, 6, 7], [2, 3, 6, 7]]);
        assert!((p[0] - 0.6).abs() < 1e-6 && p[1] == 0.7 && p[2] == 0.2, "{p:?}");
        let (q, p) = merge_passes(&q1, &p1, &noise, &q2, &p2, SecondPassMode::Replace);
        assert_eq!(q, q2.to_vec());
        assert_eq!(p, vec![0.4, 0.7]);
    }

    #[test]
    fn distinct_points_keeps_first_occurrences_in_order() {
        let p = [[1.0, 0.0, 0.0], [0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [-0.0, 0.0, -0.0], [2.0, 0.0, 0.0]];
        assert_eq!(distinct_points(&p), vec![0, 1, 4]);
        assert_eq!(distinct_points(&p[..1]), vec![0]);
    }

    /// Regression: a cube's points each repeated 5 times (the copies after the
    /// originals) lost half its faces (kNN full of copies). The copies must change
    /// nothing: the same faces on the first occurrences, and the copies isolated.
    #[test]
    fn exact_duplicates_give_the_faces_of_the_distinct_cloud() {
        let model = Model::new(ModelConfig::default_preset(), 7).expect("test: model");
        let pts = shapes::cube_sphere(4).vertices;
        let cfg = ReconstructConfig { threshold: 0.3, ..Default::default() };
        let clean = reconstruct(&pts, &model, &cfg).expect("clean");
        assert!(!clean.quads.is_empty());
        let mut dup = pts.clone();
        for _ in 0..5 {
            dup.extend(pts.iter().map(|p| p.map(|c| if c == 0.0 { -c } else { c })));
        }
        let m = reconstruct(&dup, &model, &cfg).expect("duplicated");
        assert_eq!(
            m.quads,
            clean
                .quads
                .iter()
                .map(|q| q.map(|i| if (i as usize) < pts.len() { i } else { i + 5 * pts.len() as u32 }))
                .collect::<Vec<_>>()
        );
        assert_eq!(&m.vertices[..dup.len()], &dup[..]);
        assert_eq!(&m.vertices[dup.len()..], &clean.vertices[pts.len()..]);
        // Three distinct points, however many copies: refused, saying so.
        let few: Vec<[f64; 3]> = (0..30).map(|i| [(i % 3) as f64, 0.0, (i % 3 == 1) as u8 as f64]).collect();
        let e = reconstruct(&few, &model, &cfg).unwrap_err().to_string();
        assert!(e.contains("3 distinct point(s) (of 30)"), "{e}");
    }

    /// An ensemble keeps (without the post-process) exactly the candidates whose mean
    /// probability over the members, each computed alone by `predict_with_points` on
    /// the normalised cloud, is above the threshold; two copies of one model are that
    /// model; an empty ensemble is an error.
    #[test]
    fn an_ensemble_thresholds_the_members_mean_probability() {
        let a = Model::new(ModelConfig::default_preset(), 7).expect("test: model a");
        let b = Model::new(ModelConfig::default_preset(), 8).expect("test: model b");
        let pts: Vec<[f64; 3]> = shapes::torus(10, 6, 2.0, 0.7)
            .vertices
            .iter()
            .map(|p| [p[0] * 3.0 + 1.0, p[1], p[2] - 2.0])
            .collect();
        let cfg = ReconstructConfig { run_postprocess: false, threshold: 0.5, ..Default::default() };
        let frame = Frame::fit(&pts).expect("frame");
        let local = frame.to_local_all(&pts);
        let cands = generate(&local, &cfg.candidates).expect("candidates");
        let prob = |m: &Model| {
            let x = crate::pipeline::features::face_input(&local, &cands, m.config().use_context);
            m.predict_with_points(&local, &cands.quads, &x).expect("probabilities")
        };
        let (pa, pb) = (prob(&a), prob(&b));
        let kept = |p: &[f32]| -> Vec<[u32; 4]> {
            cands.quads.iter().zip(p).filter(|(_, &p)| p > cfg.threshold).map(|(q, _)| *q).collect()
        };
        let mean: Vec<f32> = pa.iter().zip(&pb).map(|(x, y)| (x + y) * 0.5).collect();
        let (ka, kb, km) = (kept(&pa), kept(&pb), kept(&mean));
        assert!(ka != kb, "the two members keep the same candidates; the test cannot tell them apart");
        let ens = reconstruct_ensemble(&pts, &[&a, &b], &cfg).expect("ensemble");
        assert_eq!(ens.quads, km);
        let twice = reconstruct_ensemble(&pts, &[&a, &a], &cfg).expect("twice");
        assert_eq!(twice.quads, ka);
        assert_eq!(reconstruct(&pts, &a, &cfg).expect("alone").quads, ka);
        let e = reconstruct_ensemble(&pts, &[], &cfg).unwrap_err().to_string();
        assert!(e.contains("at least one model"), "{e}");
    }

    /// Regression: a library caller's `k = 100000` was only capped by the cloud size
    /// (C(k, 3) triples per point: hours of work); now an error naming the setting.
    #[test]
    fn huge_neighbour_counts_are_errors() {
        let model = Model::new(ModelConfig::default_preset(), 7).expect("test: model");
        let pts = shapes::cube_sphere(3).vertices;
        let mut cfg = ReconstructConfig::default();
        cfg.candidates.k = MAX_NEIGHBOURS;
        assert!(reconstruct(&pts, &model, &cfg).is_ok());
        let settings: [fn(&mut CandidateConfig); 3] =
            [|c| c.k = 100_000, |c| c.normal_k = 65, |c| c.spacing_k = usize::MAX];
        for set in settings {
            let mut cfg = ReconstructConfig::default();
            set(&mut cfg.candidates);
            let e = reconstruct(&pts, &model, &cfg).unwrap_err().to_string();
            assert!(e.contains("is above 64"), "{e}");
        }
    }
}
