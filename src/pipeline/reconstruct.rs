//! Reconstruction, end to end and in memory (the embedder's entry point; no file
//! I/O): validate and normalise the cloud, propose candidate quads, compute their
//! features, classify them (with the point encoder's features of their corners when
//! the model has one), post-process the faces predicted real into a manifold
//! pure-quad mesh. The output's vertices are the input points, bit-identical and in
//! order (unused ones stay as isolated vertices, so indices match the input), then any
//! vertices the hole filling added (mapped back to the input's frame).

use crate::mesh::poly::QuadMesh;
use crate::mesh::postprocess::{postprocess, PostprocessConfig, PostprocessReport};
use crate::pipeline::candidates::{generate, CandidateConfig};
use crate::pipeline::features::face_input;
use crate::pipeline::frame::Frame;
use crate::pipeline::model::Model;
use crate::{Error, Result};

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
}

impl Default for ReconstructConfig {
    fn default() -> Self {
        ReconstructConfig {
            candidates: CandidateConfig::default(),
            threshold: 0.5,
            run_postprocess: true,
            postprocess: PostprocessConfig::default(),
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
    /// The post-process's account (absent with `run_postprocess = false`).
    pub postprocess: Option<PostprocessReport>,
    /// Faces in the output.
    pub faces: usize,
    /// Vertices added by hole filling.
    pub vertices_added: usize,
    /// (stage, seconds), in pipeline order.
    pub timings: Vec<(&'static str, f64)>,
}

/// Point cloud → pure-quad manifold mesh with `model`.
///
/// # Errors
/// `Error::InvalidInput` for fewer than 4 points, non-finite coordinates (naming the
/// point), or a cloud with no extent; shape errors if the model does not fit.
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
    if !(cfg.threshold >= 0.0 && cfg.threshold < 1.0) {
        return Err(Error::invalid(format!("threshold {} must be in [0, 1)", cfg.threshold)));
    }
    let mut report = ReconstructReport { points: points.len(), ..Default::default() };
    let mut clock = Clock::new();
    let frame = Frame::fit(points)?;
    let local = frame.to_local_all(points);
    clock.lap(&mut report, "normalise");
    let cands = generate(&local, &cfg.candidates)?;
    report.candidates = cands.len();
    clock.lap(&mut report, "candidates");
    let x = face_input(&local, &cands, model.config().use_context);
    clock.lap(&mut report, "features");
    // The point encoder (if the model has one) reads the same normalised cloud the
    // candidates were built in, as in training.
    let probs = model.predict_with_points(&local, &cands.quads, &x)?;
    clock.lap(&mut report, "classify");
    let mut faces = Vec::new();
    let mut face_probs = Vec::new();
    for (q, &p) in cands.quads.iter().zip(&probs) {
        if p > cfg.threshold {
            faces.push(*q);
            face_probs.push(p);
        }
    }
    report.predicted = faces.len();
    let mesh = if cfg.run_postprocess {
        // The post-process runs in the normalised frame (in f64): in the input's own
        // coordinates its squared lengths and areas overflow at 1e200 and vanish at
        // 1e-200. Its thresholds are angles and ratios, so only the vertices the hole
        // filling adds need mapping back; the input's own are written back as given.
        let local64: Vec<[f64; 3]> = points.iter().map(|&p| frame.to_local_f64(p)).collect();
        let (mesh, pp) = postprocess(&local64, &faces, &face_probs, &cfg.postprocess)?;
        report.vertices_added = mesh.vertices.len() - points.len();
        report.postprocess = Some(pp);
        let mut vertices = points.to_vec();
        vertices.extend(mesh.vertices[points.len()..].iter().map(|&p| frame.to_world_f64(p)));
        QuadMesh { vertices, quads: mesh.quads }
    } else {
        QuadMesh { vertices: points.to_vec(), quads: faces }
    };
    report.faces = mesh.quads.len();
    clock.lap(&mut report, "postprocess");
    Ok((mesh, report))
}

struct Clock {
    #[cfg(not(target_arch = "wasm32"))]
    t: std::time::Instant,
}

impl Clock {
    fn new() -> Clock {
        Clock {
            #[cfg(not(target_arch = "wasm32"))]
            t: std::time::Instant::now(),
        }
    }
    /// Records the time since the last lap (0 on wasm32, which has no clock).
    fn lap(&mut self, report: &mut ReconstructReport, stage: &'static str) {
        #[cfg(not(target_arch = "wasm32"))]
        {
            let now = std::time::Instant::now();
            report.timings.push((stage, (now - self.t).as_secs_f64()));
            self.t = now;
        }
        #[cfg(target_arch = "wasm32")]
        report.timings.push((stage, 0.0));
    }
}
