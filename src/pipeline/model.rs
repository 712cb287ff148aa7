//! The Point2Quad network (DESIGN §3): a point encoder giving `d_P` features per
//! point, gathered for the 4 corners of every candidate; a face encoder over the
//! candidate's geometric features; a classifier over the concatenation → 2 logits.
//!
//! ```text
//! F_in (29 F_info [+ context])  ─ face encoder: 5 × (conv1d+BN+LeakyReLU 0.1), residual after layer 2 ─► Z_F  [M × d_F]
//! points ─ point encoder (KPFCNN) ─► Z_P [N × d_P] ─ gather ×4 corners ─────────────────────────────► [M × 4·d_P]
//! [Z_P×4 ; Z_F] ─ classifier: (conv1d+BN+ReLU) × 4, conv1d → 2 logits (column 1 = "face is real")
//! ```
//!
//! One [`ModelConfig`] describes the whole network; the presets ([`PRESETS`]: `default`
//! without point encoder, `default_kp` with a small KPFCNN, `paper`) differ only in its
//! numbers. The config is stored as `key = value` text inside the checkpoint, so a weights
//! file is self-describing; the point encoder's parameters, batch-norm statistics and kernel
//! points are tensors of the same [`ParamStore`], so checkpoints, the optimiser and resuming
//! cover them. The point encoder reads the cloud in the normalised frame the candidates were
//! built in ([`Model::predict_with_points`]).

use crate::nn::batch_norm::BatchNormConfig;
use crate::nn::checkpoint::{self, Checkpoint, TrainState};
use crate::nn::conv1d::{Conv1d, ConvBnAct};
use crate::nn::kpfcnn::{prepare, BlockKind, InputFeatures, Kpfcnn, KpfcnnConfig};
use crate::nn::module::{Module, ResidualBlock};
use crate::pipeline::features::FaceRows;
use crate::pipeline::refine::{RefineInput, Refiner, SideRule};
use crate::rng::Rng;
use crate::spatial::neighborhoods::NeighborCap;
use crate::tensor::{Act, Graph, ParamId, ParamStore, Tensor, Var};
use crate::{Error, Result};
use std::path::Path;
use std::sync::Arc;

/// The shipped weights' file image ([`Model::shipped`] loads it): the `default` preset
/// reading normals without their signs, with 6 refinement rounds, about 340 KB.
pub const SHIPPED_WEIGHTS: &[u8] = include_bytes!("../../fixtures/point2quad-default.p2qm");

/// How errors and notes name the shipped weights.
pub const SHIPPED_NAME: &str = "<shipped fixtures/point2quad-default.p2qm>";

/// The model presets [`ModelConfig::preset`] knows, in the order the CLI lists them.
pub const PRESETS: [&str; 3] = ["default", "default_kp", "paper"];

/// The whole network's shape.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelConfig {
    /// Preset name this config came from (informational).
    pub preset: String,
    /// Whether the per-candidate context features follow F_info in the input.
    pub use_context: bool,
    /// Whether the model reads F_info in each candidate's own frame
    /// ([`crate::pipeline::features::to_local_frame`], applied inside the model, so
    /// callers always pass the cloud-frame rows) instead of the cloud's frame.
    pub local_frame: bool,
    /// Whether the model reads the point normals without their signs
    /// ([`crate::pipeline::features::sign_free_normals`], applied inside the model
    /// after the frame, so callers pass the same rows). Written to the config only when
    /// set; older files are without.
    pub sign_free_normals: bool,
    /// Face-encoder widths: the outputs of its 5 layers (residual block after the 2nd).
    pub face_widths: [usize; 5],
    /// Per-point feature width d_P gathered for each corner (0: no point encoder).
    pub point_dim: usize,
    /// The point encoder (KPFCNN): `Some` exactly when `point_dim > 0`, with
    /// `out_dim == point_dim`. Its `seed` is a salt mixed with the model's seed at
    /// initialisation; kernel points and weights are stored in checkpoints, so loading
    /// does not depend on it.
    pub point_encoder: Option<KpfcnnConfig>,
    /// Classifier hidden widths (each conv1d+BN+ReLU); a final conv1d maps to 2 logits.
    pub classifier_widths: Vec<usize>,
    /// LeakyReLU slope in the face encoder.
    pub leaky_slope: f32,
    /// Batch-norm momentum (PyTorch convention).
    pub bn_momentum: f32,
    /// Refinement rounds after the classifier ([`crate::pipeline::refine`]; 0: none).
    /// Presets have none: `point2quad refine` adds them to a trained model.
    pub refine_rounds: usize,
    /// Hidden widths of each refinement round's MLP.
    pub refine_widths: Vec<usize>,
    /// How the refinement rounds read rivals and neighbours (`refine_sides` in the
    /// file, written only for [`SideRule::Normals`]; files without it are
    /// [`SideRule::Direction`], the rule before session 8).
    pub refine_sides: SideRule,
    /// What the refinement rounds read (`refine_input` in the text form; absent =
    /// [`RefineInput::Base`], which every model refined before session 18 has).
    pub refine_input: RefineInput,
    /// Batch norm at inference reads the statistics of the cloud being scored (all its
    /// candidates in one batch, and all its points in the point encoder) instead of the
    /// running averages from training ([`Graph::with_batch_stats`]). Training draws one
    /// cloud a step, so each step's statistics are one cloud's; running averages over
    /// many clouds fit none of them well, which the point encoder's features show most
    /// (docs/EXPERIMENTS.md, sessions 27 and 28). Up to 131,072 candidates are scored in
    /// one batch; larger clouds take the statistics of a spread sample of them
    /// (`Model::score_rows`, private). `cloud_batch_stats = true` in the text form,
    /// written only when set (files without it read the running averages).
    pub cloud_batch_stats: bool,
}

impl ModelConfig {
    /// The paper's widths (DESIGN §3): face 29→128→128(res)→256→512→256, classifier
    /// 512→512→256→128→64→2, and the `paper` KPFCNN ([`KpfcnnConfig::paper`], about
    /// 24.4M parameters) with d_P = 64.
    pub fn paper() -> ModelConfig {
        ModelConfig {
            preset: "paper".into(),
            use_context: false,
            local_frame: false,
            sign_free_normals: false,
            face_widths: [128, 128, 256, 512, 256],
            point_dim: 64,
            point_encoder: Some(KpfcnnConfig { out_dim: 64, ..KpfcnnConfig::paper() }),
            classifier_widths: vec![512, 256, 128, 64],
            leaky_slope: 0.1,
            bn_momentum: 0.02,
            refine_rounds: 0,
            refine_widths: Vec::new(),
            refine_sides: SideRule::Direction,
            refine_input: RefineInput::Base,
            cloud_batch_stats: false,
        }
    }

    /// The preset sized to train on two CPU cores: same structure, about a quarter of
    /// the widths, plus the cheap context features (DESIGN §8), and batch-norm momentum
    /// 0.1 (few steps per epoch: 0.02 leaves the running statistics far off for many
    /// epochs). No point encoder (the shipped weights are this preset).
    pub fn default_preset() -> ModelConfig {
        ModelConfig {
            preset: "default".into(),
            use_context: true,
            local_frame: true,
            sign_free_normals: false,
            face_widths: [64, 64, 96, 128, 96],
            point_dim: 0,
            point_encoder: None,
            classifier_widths: vec![128, 64, 32],
            leaky_slope: 0.1,
            bn_momentum: 0.1,
            refine_rounds: 0,
            refine_widths: Vec::new(),
            refine_sides: SideRule::Direction,
            refine_input: RefineInput::Base,
            cloud_batch_stats: false,
        }
    }

    /// `default` plus a small KPFCNN point encoder, sized so that a training step on a
    /// 10,000-point cloud stays well under a second on two cores: 3 levels (cells 0.03
    /// nominal, 0.06, 0.12), blocks simple, resnetb, (strided, resnetb) ×2, widths
    /// 16 → 64, 15 rigid kernel points, d_P = 32, batch-norm momentum 0.1 like the face
    /// net. Batch norm is read with each cloud's own statistics at inference
    /// ([`ModelConfig::cloud_batch_stats`]): with the running averages its validation
    /// precision swings from epoch to epoch (session 27).
    pub fn default_kp() -> ModelConfig {
        let d_p = 32;
        ModelConfig {
            preset: "default_kp".into(),
            point_dim: d_p,
            point_encoder: Some(KpfcnnConfig {
                first_features_dim: 16,
                out_dim: d_p,
                bn_momentum: 0.1,
                ..KpfcnnConfig::default_preset()
            }),
            cloud_batch_stats: true,
            ..ModelConfig::default_preset()
        }
    }

    /// A preset by name (one of [`PRESETS`]).
    ///
    /// # Errors
    /// `Error::Usage` for an unknown name.
    pub fn preset(name: &str) -> Result<ModelConfig> {
        match name {
            "default" => Ok(ModelConfig::default_preset()),
            "default_kp" => Ok(ModelConfig::default_kp()),
            "paper" => Ok(ModelConfig::paper()),
            other => Err(Error::Usage(format!(
                "unknown model preset {other:?} (use one of {})",
                PRESETS.join(", ")
            ))),
        }
    }

    /// Width of the face encoder's input.
    pub fn face_in(&self) -> usize {
        crate::pipeline::features::F_INFO_DIM
            + if self.use_context { crate::pipeline::features::CONTEXT_DIM } else { 0 }
    }

    /// A lower bound on the weights [`Model::new`] allocates for this config: the
    /// products `c_in · c_out` of every convolution of the face encoder, the classifier
    /// and the refinement rounds, and a bound per block of the point encoder (saturating,
    /// so a forged width cannot overflow it). Every one of them is stored in a weights
    /// file, so a file holding fewer values than this cannot be this config's
    /// ([`Model::from_checkpoint`] checks it before allocating anything).
    pub fn min_weights(&self) -> u64 {
        let chain = |cin: u64, widths: &[usize], out: usize| -> u64 {
            let mut total = 0u64;
            let mut c = cin;
            for &w in widths.iter().chain(std::iter::once(&out)) {
                total = total.saturating_add(c.saturating_mul(w as u64));
                c = w as u64;
            }
            total
        };
        let w = &self.face_widths;
        // The face encoder's five layers and its residual block's two w1 × w1 convs.
        let face = chain(self.face_in() as u64, &w[..4], w[4])
            .saturating_add((w[1] as u64).saturating_mul(w[1] as u64).saturating_mul(2));
        let cls_in = (w[4] as u64).saturating_add((self.point_dim as u64).saturating_mul(4));
        let cls = chain(cls_in, &self.classifier_widths, 2);
        let round = chain(self.refine_input.dim() as u64, &self.refine_widths, 2);
        let rounds = round.saturating_mul(self.refine_rounds as u64);
        // The point encoder (as `kpfcnn::plan` lays it out): its Simple block's KPConv,
        // K · input features · f / 2 weights (f the first width), and for every further
        // block a KPConv of c_out / 4 ≥ f / 4 features in and out, K · (f / 4)² at least.
        let kp = self.point_encoder.as_ref().map_or(0, |k| {
            let kn = k.num_kernel_points as u64;
            let f = k.first_features_dim as u64;
            let first = kn.saturating_mul(k.input.dim() as u64).saturating_mul(f / 2);
            let block = kn.saturating_mul((f / 4).saturating_mul(f / 4));
            let more = (k.blocks.len().saturating_sub(1) as u64).saturating_mul(block);
            first.saturating_add(more)
        });
        face.saturating_add(cls).saturating_add(rounds).saturating_add(kp)
    }

    /// Checks the config's consistency.
    ///
    /// # Errors
    /// `Error::InvalidInput` naming the problem: a zero width, a leaky slope outside
    /// [0, 1] (a leaky ReLU's; session 39's audit loaded 4294967295 from a forged file,
    /// which then scored nothing), a point encoder without `point_dim` (or the reverse),
    /// its `out_dim` differing from `point_dim`, or an invalid KPFCNN config.
    pub fn validate(&self) -> Result<()> {
        if !(0.0..=1.0).contains(&self.leaky_slope) {
            return Err(Error::invalid(format!(
                "model config: leaky_slope {} is outside [0, 1]",
                self.leaky_slope
            )));
        }
        if self.face_widths.contains(&0)
            || self.classifier_widths.contains(&0)
            || self.refine_widths.contains(&0)
        {
            return Err(Error::invalid("model config: zero width"));
        }
        if self.refine_rounds > MAX_REFINE_ROUNDS {
            return Err(Error::invalid(format!(
                "model config: {} refinement rounds (at most {MAX_REFINE_ROUNDS})",
                self.refine_rounds
            )));
        }
        if self.refine_input.reads_flow() && self.refine_sides != SideRule::Normals {
            return Err(Error::invalid(format!(
                "model config: refine_input = {} needs refine_sides = normals",
                self.refine_input.name()
            )));
        }
        match (&self.point_encoder, self.point_dim) {
            (None, 0) => Ok(()),
            (None, d) => Err(Error::invalid(format!("model config: point_dim {d} but no point encoder"))),
            (Some(_), 0) => Err(Error::invalid("model config: a point encoder but point_dim 0")),
            (Some(k), d) if k.out_dim != d => Err(Error::invalid(format!(
                "model config: point encoder gives {} features per point, point_dim is {d}",
                k.out_dim
            ))),
            (Some(k), _) => k.validate(),
        }
    }

    /// The config as `key = value` lines (stored in checkpoints). The point encoder's
    /// keys (`kp_*`) are written only when there is one, so a config without it reads
    /// exactly as before they existed.
    pub fn to_text(&self) -> String {
        let list = |v: &[usize]| v.iter().map(|x| x.to_string()).collect::<Vec<_>>().join(",");
        let mut t = format!(
            "preset = {}\nuse_context = {}\nface_in = {}\nface_widths = {}\npoint_dim = {}\nclassifier_widths = {}\nleaky_slope = {}\nbn_momentum = {}\n",
            self.preset,
            self.use_context,
            self.face_in(),
            list(&self.face_widths),
            self.point_dim,
            list(&self.classifier_widths),
            self.leaky_slope,
            self.bn_momentum
        );
        if self.local_frame {
            t += "local_frame = true\n";
        }
        if self.sign_free_normals {
            t += "sign_free_normals = true\n";
        }
        if self.cloud_batch_stats {
            t += "cloud_batch_stats = true\n";
        }
        if self.refine_rounds > 0 {
            t += &format!(
                "refine_rounds = {}\nrefine_widths = {}\n",
                self.refine_rounds,
                list(&self.refine_widths)
            );
            if self.refine_sides != SideRule::Direction {
                t += &format!("refine_sides = {}\n", self.refine_sides.name());
            }
            if self.refine_input != RefineInput::Base {
                t += &format!("refine_input = {}\n", self.refine_input.name());
            }
        }
        if let Some(k) = &self.point_encoder {
            let blocks: Vec<&str> = k.blocks.iter().map(|&b| block_name(b)).collect();
            let input = match k.input {
                InputFeatures::Ones => "ones",
                InputFeatures::OnesXyz => "ones_xyz",
            };
            let cap = match k.neighbor_cap {
                NeighborCap::Fixed(n) => format!("fixed {n}"),
                NeighborCap::Percentile(p) => format!("percentile {p}"),
            };
            // `{}` prints floats in their shortest round-tripping form.
            t += &format!(
                "kp_blocks = {}\nkp_first_features_dim = {}\nkp_input = {input}\nkp_first_cell = {}\nkp_conv_radius = {}\nkp_kp_extent = {}\nkp_num_kernel_points = {}\nkp_neighbor_cap = {cap}\nkp_bn_momentum = {}\nkp_bn_eps = {}\nkp_leaky_slope = {}\nkp_seed = {}\n",
                blocks.join(","),
                k.first_features_dim,
                k.first_cell,
                k.conv_radius,
                k.kp_extent,
                k.num_kernel_points,
                k.bn_momentum,
                k.bn_eps,
                k.leaky_slope,
                k.seed
            );
            // Written only when set, so files without it read as before.
            if k.spacing_cells > 0.0 {
                t += &format!("kp_spacing_cells = {}\n", k.spacing_cells);
            }
            if k.input_cell > 0.0 {
                t += &format!("kp_input_cell = {}\n", k.input_cell);
            }
        }
        t
    }

    /// Parses [`ModelConfig::to_text`] output; `name` is used in errors. Configs
    /// written before the point encoder existed (no `kp_*` keys, `point_dim = 0`) read
    /// unchanged.
    ///
    /// # Errors
    /// `Error::Parse` naming the line for a malformed, unknown or repeated key; naming
    /// the file (line 0) for missing keys, an inconsistent config (see
    /// [`ModelConfig::validate`]), and when the stored input width does not match this
    /// build's feature layout.
    pub fn from_text(text: &str, name: &Path) -> Result<ModelConfig> {
        // A config without `local_frame` predates it: cloud-frame F_info.
        let mut c = ModelConfig { local_frame: false, ..ModelConfig::default_preset() };
        let mut kp = KpfcnnConfig::default_preset();
        let mut face_in = None;
        let mut seen: Vec<&str> = Vec::new();
        let mut kp_seen = 0usize;
        let mut kp_optional = 0usize;
        for (i, line) in text.lines().enumerate() {
            let line = line.trim();
            if line.is_empty() || line.starts_with('#') {
                continue;
            }
            let bad = |m: &str| Error::parse(name, i + 1, format!("model config: {m}: {line:?}"));
            let (k, v) = line.split_once('=').ok_or_else(|| bad("expected key = value"))?;
            let (k, v) = (k.trim(), v.trim());
            if seen.contains(&k) {
                return Err(bad("repeated key"));
            }
            let usize_list = |v: &str| -> Result<Vec<usize>> {
                v.split(',').map(|x| x.trim().parse::<usize>().map_err(|_| bad("bad width list"))).collect()
            };
            // Finite only: an infinite slope or momentum gives NaN probabilities later.
            let num =
                |v: &str| v.parse::<f32>().ok().filter(|x| x.is_finite()).ok_or_else(|| bad("bad number"));
            let int = |v: &str| v.parse::<usize>().map_err(|_| bad("bad number"));
            match k {
                "preset" => c.preset = v.to_string(),
                "use_context" => c.use_context = v.parse().map_err(|_| bad("bad bool"))?,
                "local_frame" => c.local_frame = v.parse().map_err(|_| bad("bad bool"))?,
                "sign_free_normals" => c.sign_free_normals = v.parse().map_err(|_| bad("bad bool"))?,
                "cloud_batch_stats" => c.cloud_batch_stats = v.parse().map_err(|_| bad("bad bool"))?,
                "face_in" => face_in = Some(int(v)?),
                "face_widths" => {
                    let w = usize_list(v)?;
                    c.face_widths = w.try_into().map_err(|_| bad("face_widths needs 5 widths"))?;
                }
                "point_dim" => c.point_dim = int(v)?,
                "classifier_widths" => c.classifier_widths = usize_list(v)?,
                "leaky_slope" => c.leaky_slope = num(v)?,
                "bn_momentum" => c.bn_momentum = num(v)?,
                "refine_rounds" => c.refine_rounds = int(v)?,
                "refine_widths" => c.refine_widths = usize_list(v)?,
                "refine_sides" => {
                    c.refine_sides = SideRule::from_name(v)
                        .ok_or_else(|| bad("refine_sides must be direction or normals"))?;
                }
                "refine_input" => {
                    c.refine_input = RefineInput::from_name(v)
                        .ok_or_else(|| bad("refine_input must be base, flow or inside"))?;
                }
                _ if k.starts_with("kp_") => {
                    match k {
                        "kp_blocks" => {
                            kp.blocks = v
                                .split(',')
                                .map(|b| parse_block(b.trim()).ok_or_else(|| bad("unknown block kind")))
                                .collect::<Result<_>>()?
                        }
                        "kp_first_features_dim" => kp.first_features_dim = int(v)?,
                        "kp_input" => {
                            kp.input = match v {
                                "ones" => InputFeatures::Ones,
                                "ones_xyz" => InputFeatures::OnesXyz,
                                _ => return Err(bad("kp_input must be ones or ones_xyz")),
                            }
                        }
                        "kp_first_cell" => kp.first_cell = num(v)?,
                        "kp_spacing_cells" => kp.spacing_cells = num(v)?,
                        "kp_input_cell" => kp.input_cell = num(v)?,
                        "kp_conv_radius" => kp.conv_radius = num(v)?,
                        "kp_kp_extent" => kp.kp_extent = num(v)?,
                        "kp_num_kernel_points" => kp.num_kernel_points = int(v)?,
                        "kp_neighbor_cap" => {
                            kp.neighbor_cap = match v.split_once(' ') {
                                Some(("fixed", n)) => NeighborCap::Fixed(int(n.trim())?),
                                Some(("percentile", p)) => NeighborCap::Percentile(
                                    p.trim().parse::<f64>().map_err(|_| bad("bad number"))?,
                                ),
                                _ => return Err(bad("kp_neighbor_cap must be 'fixed N' or 'percentile P'")),
                            }
                        }
                        "kp_bn_momentum" => kp.bn_momentum = num(v)?,
                        "kp_bn_eps" => kp.bn_eps = num(v)?,
                        "kp_leaky_slope" => kp.leaky_slope = num(v)?,
                        "kp_seed" => kp.seed = v.parse().map_err(|_| bad("bad number"))?,
                        _ => return Err(bad("unknown key")),
                    }
                    // The optional ones (absent in files written before them) do not
                    // stand in for a required one.
                    if matches!(k, "kp_spacing_cells" | "kp_input_cell") {
                        kp_optional += 1;
                    } else {
                        kp_seen += 1;
                    }
                }
                _ => return Err(bad("unknown key")),
            }
            seen.push(k);
        }
        // Named, so that no optional key (`local_frame`, `face_in`, the refinement's)
        // can stand in for a missing one.
        let missing: Vec<&str> = REQUIRED_KEYS.iter().copied().filter(|k| !seen.contains(k)).collect();
        if !missing.is_empty() {
            return Err(Error::parse(name, 0, format!("model config: missing keys: {}", missing.join(", "))));
        }
        if c.point_dim > 0 {
            if kp_seen < KP_KEYS {
                return Err(Error::parse(
                    name,
                    0,
                    format!("model config: point_dim {} needs all {KP_KEYS} kp_* keys", c.point_dim),
                ));
            }
            kp.out_dim = c.point_dim;
            c.point_encoder = Some(kp);
        } else if kp_seen + kp_optional > 0 {
            return Err(Error::parse(name, 0, "model config: kp_* keys with point_dim 0"));
        }
        c.validate().map_err(|e| Error::parse(name, 0, e.to_string()))?;
        if let Some(fi) = face_in {
            if fi != c.face_in() {
                return Err(Error::parse(
                    name,
                    0,
                    format!(
                        "model config: weights expect {fi} input features, this build computes {}",
                        c.face_in()
                    ),
                ));
            }
        }
        Ok(c)
    }
}

/// Most refinement rounds a config may ask for.
pub const MAX_REFINE_ROUNDS: usize = 8;

/// Number of `kp_*` keys [`ModelConfig::to_text`] writes for a point encoder.
const KP_KEYS: usize = 12;

/// Keys every model config has (every file since the first).
const REQUIRED_KEYS: [&str; 7] =
    ["preset", "use_context", "face_widths", "point_dim", "classifier_widths", "leaky_slope", "bn_momentum"];

fn block_name(b: BlockKind) -> &'static str {
    match b {
        BlockKind::Simple => "simple",
        BlockKind::Resnetb => "resnetb",
        BlockKind::ResnetbStrided => "resnetb_strided",
    }
}

fn parse_block(s: &str) -> Option<BlockKind> {
    [BlockKind::Simple, BlockKind::Resnetb, BlockKind::ResnetbStrided]
        .into_iter()
        .find(|&b| block_name(b) == s)
}

/// The layers (parameter handles) of the network; the values live in a
/// [`ParamStore`], so a training graph can borrow the store mutably while the
/// network is borrowed shared.
pub struct Network {
    /// Its shape.
    pub config: ModelConfig,
    face: Vec<ConvBnAct>,
    residual: ResidualBlock,
    classifier: Vec<ConvBnAct>,
    head: Conv1d,
    point: Option<Kpfcnn>,
    refine: Option<Refiner>,
}

/// A network with its parameters.
pub struct Model {
    /// The layers.
    pub net: Network,
    /// All parameters and batch-norm buffers (the point encoder's, with its kernel
    /// points, included).
    pub params: ParamStore,
}

impl Model {
    /// A freshly initialised network (Kaiming-uniform convs, BN weight 1 / bias 0; the
    /// point encoder as [`Kpfcnn::new`] with its seed salted by `seed`).
    ///
    /// # Errors
    /// `Error::InvalidInput` for an inconsistent config ([`ModelConfig::validate`]).
    pub fn new(config: ModelConfig, seed: u64) -> Result<Model> {
        config.validate()?;
        let mut rng = Rng::new(seed);
        let mut params = ParamStore::new();
        let bn = BatchNormConfig { momentum: config.bn_momentum, ..BatchNormConfig::default() };
        let leaky = Act::LeakyRelu(config.leaky_slope);
        let w = config.face_widths;
        let mut face = Vec::new();
        let mut cin = config.face_in();
        for (i, &cout) in w.iter().enumerate() {
            face.push(ConvBnAct::new(&mut params, &format!("face.{i}"), cin, cout, leaky, bn, &mut rng)?);
            cin = cout;
        }
        let residual = ResidualBlock::new(&mut params, "face.res", w[1], leaky, bn, &mut rng)?;
        let mut classifier = Vec::new();
        let mut cin = 4 * config.point_dim + w[4];
        for (i, &cout) in config.classifier_widths.iter().enumerate() {
            classifier.push(ConvBnAct::new(
                &mut params,
                &format!("cls.{i}"),
                cin,
                cout,
                Act::Relu,
                bn,
                &mut rng,
            )?);
            cin = cout;
        }
        let head = Conv1d::new(&mut params, "cls.head", cin, 2, true, &mut rng)?;
        // Created last, so the face net and classifier draw the same initial weights
        // for a seed whether or not there is a point encoder.
        let point = match &config.point_encoder {
            Some(k) => {
                let salted =
                    KpfcnnConfig { seed: k.seed ^ seed.wrapping_mul(0x9E37_79B9_7F4A_7C15), ..k.clone() };
                Some(Kpfcnn::new(&salted, &mut params)?)
            }
            None => None,
        };
        // Last of all, so a model with refinement rounds draws the classifier's initial
        // weights of the same model without them.
        let refine = if config.refine_rounds > 0 {
            Some(Refiner::new(
                &mut params,
                config.refine_rounds,
                &config.refine_widths,
                config.refine_sides,
                config.refine_input,
                &mut rng,
            )?)
        } else {
            None
        };
        Ok(Model { net: Network { config, face, residual, classifier, head, point, refine }, params })
    }

    /// The network's shape.
    pub fn config(&self) -> &ModelConfig {
        &self.net.config
    }

    /// Number of trainable scalars.
    pub fn param_count(&self) -> usize {
        self.params.num_trainable()
    }

    /// Probability that each candidate is a real face, in inference mode (running
    /// batch-norm statistics, or the cloud's own with [`ModelConfig::cloud_batch_stats`];
    /// nothing recorded), for a model without point encoder.
    ///
    /// # Errors
    /// `Error::Shape` when `face_features.len()` is not a multiple of the input width,
    /// or the model has a point encoder (use [`Model::predict_with_points`]).
    pub fn predict(&self, face_features: &[f32]) -> Result<Vec<f32>> {
        if self.net.config.point_dim > 0 {
            return Err(Error::Shape {
                op: "predict",
                msg: "point-encoder models need predict_with_points".into(),
            });
        }
        if self.net.refine.is_some() {
            return Err(Error::Shape {
                op: "predict",
                msg:
                    "models with refinement rounds need predict_with_points (the rounds read the candidates)"
                        .into(),
            });
        }
        self.classify(face_features)
    }

    /// The classifier's probabilities of a model without point encoder (no refinement).
    fn classify(&self, face_features: &[f32]) -> Result<Vec<f32>> {
        self.classify_in_chunks(face_features, CLASSIFY_CHUNK_ROWS)
    }

    /// [`Model::classify`] over at most `chunk` rows at a time: in inference mode every
    /// row is scored on its own (batch norm reads its running statistics), so the
    /// result does not depend on the chunking, and memory holds one chunk's
    /// activations instead of every candidate's (a 200,000-point cloud has 1.6M
    /// candidates). A [`ModelConfig::cloud_batch_stats`] model: see [`Model::score_rows`].
    fn classify_in_chunks(&self, face_features: &[f32], chunk: usize) -> Result<Vec<f32>> {
        self.score_rows(&InputRows::Matrix(face_features), None, chunk, CLOUD_STATS_ROWS)
    }

    /// The classifier's probabilities for the rows of `input`; with `points`,
    /// the per-point features already through the classifier's first layer
    /// ([`Network::point_projection`]) and each row's corners. Chunks of at most `chunk`
    /// rows, except for a [`ModelConfig::cloud_batch_stats`] model, whose batch norm
    /// reads the statistics of the cloud's candidates: up to `stats_rows`
    /// ([`CLOUD_STATS_ROWS`] outside tests) rows they are one batch; beyond, the
    /// statistics are those of an even spread of `stats_rows` rows (row ⌊i·m/N⌋ for
    /// i < N), and every row is then scored in chunks with them, so memory stays bounded
    /// as with running statistics. (Training draws at most 12,000 candidates of a cloud a
    /// step: its statistics were samples too.)
    fn score_rows(
        &self,
        input: &InputRows<'_>,
        points: Option<(&[f32], &[[u32; 4]])>,
        chunk: usize,
        stats_rows: usize,
    ) -> Result<Vec<f32>> {
        let m = self.input_rows(input)?;
        let stats_rows = stats_rows.max(2);
        let fin = self.net.config.face_in();
        let cloud = self.net.config.cloud_batch_stats;
        let one_batch = cloud && m <= stats_rows;
        let sampled;
        let params = if cloud && !one_batch {
            let pick: Vec<usize> = even_spread(m, stats_rows).collect();
            let rows = input.gather(&pick, fin);
            let corners: Option<Vec<[u32; 4]>> = points.map(|(_, c)| pick.iter().map(|&i| c[i]).collect());
            let mut g = Graph::eval_shared(&self.params).with_batch_stats(true).capturing_stats();
            self.logits(&mut g, rows, points.map(|p| p.0).zip(corners.as_deref()))?;
            let mut store = self.params.clone();
            for st in g.captured_stats() {
                store.get_mut(st.running_mean).data_mut().copy_from_slice(&st.mean);
                store.get_mut(st.running_var).data_mut().copy_from_slice(&st.var);
            }
            sampled = store;
            &sampled
        } else {
            &self.params
        };
        let chunk = if one_batch { m } else { chunk }.max(1);
        let mut out = Vec::with_capacity(m);
        for lo in (0..m).step_by(chunk) {
            let hi = (lo + chunk).min(m);
            let corners = points.map(|(proj, cs)| (proj, &cs[lo..hi]));
            let mut g = Graph::eval_shared(params).with_batch_stats(one_batch);
            let logits = self.logits(&mut g, input.range(lo, hi, fin), corners)?;
            out.extend(probabilities(g.value(logits).data()));
        }
        Ok(out)
    }

    /// The number of rows of `input`, checked against this model's input width.
    fn input_rows(&self, input: &InputRows<'_>) -> Result<usize> {
        match input {
            InputRows::Matrix(x) => self.rows(x),
            InputRows::Faces(f) if f.dim() == self.net.config.face_in() => Ok(f.len()),
            InputRows::Faces(f) => Err(Error::Shape {
                op: "predict",
                msg: format!(
                    "rows of {} values for a model that reads {}",
                    f.dim(),
                    self.net.config.face_in()
                ),
            }),
        }
    }

    /// Replaces the classifier's batch-norm running statistics by the mean, over
    /// `batches`, of each block's batch statistics ("precise" batch norm; session 33).
    /// Each batch is one cloud's F_info rows (cloud frame, as a dataset sample stores
    /// them), read as one batch as a training step reads a cloud: an even spread of at
    /// most `max_rows` of them (row ⌊i·m/N⌋ for i < N). Every cloud counts once, the
    /// variance unbiased (m/(m − 1)) as the running one. Batches of fewer than 2 rows
    /// are skipped. In batch-statistics mode no block reads the running buffers, so the
    /// result does not depend on them and equals the mean of what each batch alone
    /// gives. Returns the number of batches used.
    ///
    /// # Errors
    /// `Error::InvalidInput` for a model with a point encoder (its blocks need the
    /// clouds' points) or one whose batch norm reads each cloud's own statistics
    /// ([`ModelConfig::cloud_batch_stats`]: the running ones are never read), for no
    /// usable batch or `max_rows` < 2, and non-finite statistics; `Error::Shape` for a
    /// batch that is not whole rows of the input width.
    pub fn precise_batch_norm<B: AsRef<[f32]>>(
        &mut self,
        batches: impl IntoIterator<Item = B>,
        max_rows: usize,
    ) -> Result<usize> {
        if self.net.config.point_dim > 0 {
            return Err(Error::invalid(
                "precise batch-norm statistics: models with a point encoder are not supported",
            ));
        }
        if self.net.config.cloud_batch_stats {
            return Err(Error::invalid(
                "precise batch-norm statistics: this model's batch norm reads each cloud's own statistics",
            ));
        }
        if max_rows < 2 {
            return Err(Error::invalid(format!("precise batch-norm statistics: max_rows {max_rows} < 2")));
        }
        let fin = self.net.config.face_in();
        // Per block (in execution order): the buffers and the sums of means and variances.
        let mut sums: Vec<(ParamId, ParamId, Vec<f64>, Vec<f64>)> = Vec::new();
        let mut used = 0usize;
        for rows in batches {
            let rows = rows.as_ref();
            let m = self.rows(rows)?;
            if m < 2 {
                continue;
            }
            let n = m.min(max_rows);
            let picked: Vec<f32> =
                even_spread(m, n).flat_map(|r| rows[r * fin..(r + 1) * fin].iter().copied()).collect();
            let mut g = Graph::eval_shared(&self.params).with_batch_stats(true).capturing_stats();
            self.logits(&mut g, picked, None)?;
            let stats = g.captured_stats();
            if used == 0 {
                sums = stats
                    .iter()
                    .map(|st| {
                        (st.running_mean, st.running_var, vec![0.0; st.mean.len()], vec![0.0; st.var.len()])
                    })
                    .collect();
            }
            if stats.len() != sums.len() {
                return Err(Error::invalid("precise batch-norm statistics: blocks differ between batches"));
            }
            let unbias = n as f64 / (n as f64 - 1.0);
            for (st, (_, _, ms, vs)) in stats.iter().zip(sums.iter_mut()) {
                for (a, &b) in ms.iter_mut().zip(&st.mean) {
                    *a += b as f64;
                }
                for (a, &b) in vs.iter_mut().zip(&st.var) {
                    *a += b as f64 * unbias;
                }
            }
            used += 1;
        }
        if used == 0 {
            return Err(Error::invalid("precise batch-norm statistics: no batch of 2 or more rows"));
        }
        let mean = |v: &[f64]| v.iter().map(|&x| (x / used as f64) as f32).collect::<Vec<f32>>();
        let new: Vec<(ParamId, Vec<f32>, ParamId, Vec<f32>)> =
            sums.iter().map(|(rm, rv, ms, vs)| (*rm, mean(ms), *rv, mean(vs))).collect();
        if new.iter().any(|(_, m, _, v)| m.iter().chain(v).any(|x| !x.is_finite())) {
            return Err(Error::invalid("precise batch-norm statistics: non-finite statistics"));
        }
        for (rm, m, rv, v) in new {
            self.params.get_mut(rm).data_mut().copy_from_slice(&m);
            self.params.get_mut(rv).data_mut().copy_from_slice(&v);
        }
        Ok(used)
    }

    /// The logits of `rows` (cloud-frame F_info rows, framed here) in `g`; with
    /// `points`, as [`Model::score_rows`].
    fn logits(&self, g: &mut Graph, rows: Vec<f32>, points: Option<(&[f32], &[[u32; 4]])>) -> Result<Var> {
        let fin = self.net.config.face_in();
        let x = g.input(Tensor::new(&[rows.len() / fin, fin], self.framed(rows))?);
        match points {
            None => self.net.forward(g, x, None),
            Some((proj, corners)) => self.net.forward_points_eval(g, x, proj, corners),
        }
    }

    /// Probability that each candidate is a real face, in inference mode, for any
    /// model: `points` is the cloud in the normalised frame the candidates were built in
    /// (what the point encoder reads), `corners` the candidates (indices into `points`,
    /// one per row of `face_features`). Without a point encoder this is
    /// [`Model::predict`] (the points are not read).
    ///
    /// # Errors
    /// `Error::Shape` when `face_features` is not `corners.len()` rows of the input
    /// width; `Error::InvalidInput` for a corner index out of range (naming the
    /// candidate) or, with a point encoder, a cloud [`prepare`] rejects.
    pub fn predict_with_points(
        &self,
        points: &[[f32; 3]],
        corners: &[[u32; 4]],
        face_features: &[f32],
    ) -> Result<Vec<f32>> {
        let base = self.predict_base(points, corners, face_features)?;
        match &self.net.refine {
            Some(r) => r.apply(&self.params, points, corners, &base),
            None => Ok(base),
        }
    }

    /// The refinement rounds, when the model has any.
    pub fn refiner(&self) -> Option<&Refiner> {
        self.net.refine.as_ref()
    }

    /// The refinement rounds with the parameter store mutable (for training them).
    pub fn refiner_and_params_mut(&mut self) -> Option<(&Refiner, &mut ParamStore)> {
        let Model { net, params } = self;
        net.refine.as_ref().map(|r| (r, params))
    }

    /// This model's classifier (and point encoder) with `rounds` fresh refinement
    /// rounds of hidden `widths` reading sides by `sides` (initialised from `seed`; any
    /// rounds `self` had are dropped). Its probabilities equal `self`'s classifier's
    /// until the rounds are trained ([`crate::pipeline::refine::train_refiner`]).
    ///
    /// # Errors
    /// `InvalidInput` for a zero width or more than [`MAX_REFINE_ROUNDS`] rounds.
    pub fn with_refinement(
        &self,
        rounds: usize,
        widths: &[usize],
        sides: SideRule,
        seed: u64,
    ) -> Result<Model> {
        self.with_refinement_reading(rounds, widths, sides, RefineInput::Base, seed)
    }

    /// As [`Model::with_refinement`], with rounds that read `input`.
    ///
    /// # Errors
    /// As [`Model::with_refinement`]; `InvalidInput` for [`RefineInput::Flow`] or
    /// [`RefineInput::Inside`] with [`SideRule::Direction`].
    pub fn with_refinement_reading(
        &self,
        rounds: usize,
        widths: &[usize],
        sides: SideRule,
        input: RefineInput,
        seed: u64,
    ) -> Result<Model> {
        let config = ModelConfig {
            refine_rounds: rounds,
            refine_widths: widths.to_vec(),
            refine_sides: sides,
            refine_input: input,
            ..self.net.config.clone()
        };
        let mut out = Model::new(config, seed)?;
        for id in self.params.ids() {
            let name = self.params.name(id);
            if name.starts_with("refine.") {
                continue;
            }
            let to =
                out.params.find(name).ok_or_else(|| Error::invalid(format!("parameter '{name}' missing")))?;
            out.params.set(to, self.params.get(id).clone())?;
        }
        if let Some(kp) = &mut out.net.point {
            kp.load_kernel_points(&out.params)?;
        }
        Ok(out)
    }

    /// The classifier's own probabilities (what [`Model::predict_with_points`] gives
    /// before any refinement round): the input of refinement training.
    ///
    /// # Errors
    /// As [`Model::predict_with_points`].
    pub fn predict_base(
        &self,
        points: &[[f32; 3]],
        corners: &[[u32; 4]],
        face_features: &[f32],
    ) -> Result<Vec<f32>> {
        self.predict_base_with(points, corners, &InputRows::Matrix(face_features), CLOUD_STATS_ROWS)
    }

    /// [`Model::predict_base`] with the rows made chunk by chunk as they are scored
    /// (`rows` gives the same values as [`crate::pipeline::features::face_input`], so
    /// the probabilities are the same, bit for bit), for the candidates `rows` was made
    /// of.
    ///
    /// # Errors
    /// As [`Model::predict_base`]; `Error::Shape` also when `rows` has another width than
    /// the model reads.
    pub fn predict_base_rows(&self, points: &[[f32; 3]], rows: &FaceRows<'_>) -> Result<Vec<f32>> {
        self.predict_base_with(points, rows.quads(), &InputRows::Faces(rows), CLOUD_STATS_ROWS)
    }

    /// [`Model::predict_base`] with `stats_rows` for [`Model::score_rows`].
    fn predict_base_with(
        &self,
        points: &[[f32; 3]],
        corners: &[[u32; 4]],
        input: &InputRows<'_>,
        stats_rows: usize,
    ) -> Result<Vec<f32>> {
        let m = self.input_rows(input)?;
        if m != corners.len() {
            return Err(Error::Shape {
                op: "predict_with_points",
                msg: format!("{m} feature rows for {} candidates", corners.len()),
            });
        }
        let Some(kp) = &self.net.point else {
            return self.score_rows(input, None, CLASSIFY_CHUNK_ROWS, stats_rows);
        };
        check_corners(corners, points.len())?;
        if m == 0 {
            return Ok(Vec::new());
        }
        let pyr = prepare(points, kp.config())?;
        let proj = {
            let mut g = Graph::eval_shared(&self.params).with_batch_stats(self.net.config.cloud_batch_stats);
            let pf = kp.forward(&mut g, &pyr)?;
            let proj = self.net.point_projection(&mut g, pf)?;
            g.value(proj).data().to_vec()
        };
        self.score_rows(input, Some((&proj, corners)), CLASSIFY_CHUNK_ROWS, stats_rows)
    }

    /// The input rows as the network reads them: with [`ModelConfig::local_frame`], each
    /// row's F_info in the candidate's own frame; otherwise unchanged. Training and
    /// inference both go through this.
    pub fn framed(&self, mut rows: Vec<f32>) -> Vec<f32> {
        let fin = self.net.config.face_in();
        let (local, sign_free) = (self.net.config.local_frame, self.net.config.sign_free_normals);
        if (local || sign_free) && fin >= crate::pipeline::features::F_INFO_DIM {
            let ctx = self.net.config.use_context;
            crate::par::for_each_chunk_mut(&mut rows, fin * 256, |_, chunk| {
                for row in chunk.chunks_mut(fin) {
                    if local {
                        crate::pipeline::features::to_local_frame(row);
                    }
                    if sign_free {
                        crate::pipeline::features::sign_free_normals(row, ctx);
                    }
                }
            });
        }
        rows
    }

    /// Rows of `face_features` for this model's input width.
    fn rows(&self, face_features: &[f32]) -> Result<usize> {
        let fin = self.net.config.face_in();
        if face_features.len() % fin != 0 {
            return Err(Error::Shape {
                op: "predict",
                msg: format!("{} values is not M × {fin}", face_features.len()),
            });
        }
        Ok(face_features.len() / fin)
    }

    /// The weights and config as a checkpoint (with the optional training state).
    pub fn to_checkpoint(&self, train: Option<TrainState>) -> Checkpoint {
        Checkpoint::from_store(&self.params, self.net.config.to_text().as_bytes(), train)
    }

    /// Rebuilds a model from a checkpoint image; `name` is used in errors.
    ///
    /// # Errors
    /// `Error::Checkpoint` for a corrupt file, a config this build cannot read, or
    /// tensors that do not match the config (the point encoder's kernel points
    /// included).
    pub fn from_checkpoint(ckpt: &Checkpoint, name: &Path) -> Result<Model> {
        // The checkpoint error names the file once: the inner error's own path (the
        // config parser's) and "invalid input:" prefix are dropped.
        let as_ckpt_err = |e: Error| {
            let msg = match e {
                Error::Parse { line, msg, .. } if line > 0 => format!("config line {line}: {msg}"),
                Error::Parse { msg, .. } => msg,
                Error::InvalidInput(m) => m,
                other => other.to_string(),
            };
            Error::Checkpoint { path: name.to_path_buf(), msg }
        };
        // A diverged training run, or a damaged file whose checksum was redone, would
        // otherwise give NaN probabilities, reported against the input cloud.
        for (tname, t) in &ckpt.tensors {
            if let Some(i) = t.data().iter().position(|x| !x.is_finite()) {
                return Err(Error::Checkpoint {
                    path: name.to_path_buf(),
                    msg: format!("tensor {tname} holds a non-finite value ({}) at index {i}", t.data()[i]),
                });
            }
            if tname.ends_with(".running_var") {
                if let Some(i) = t.data().iter().position(|&x| x < 0.0) {
                    return Err(Error::Checkpoint {
                        path: name.to_path_buf(),
                        msg: format!(
                            "tensor {tname} holds a negative variance ({}) at index {i}",
                            t.data()[i]
                        ),
                    });
                }
            }
        }
        let text = std::str::from_utf8(&ckpt.config).map_err(|_| Error::Checkpoint {
            path: name.to_path_buf(),
            msg: "model config is not UTF-8".into(),
        })?;
        let config = ModelConfig::from_text(text, name).map_err(as_ckpt_err)?;
        // Before anything is allocated: a config whose widths the stored tensors cannot
        // hold (a damaged or forged file with a valid checksum) would otherwise ask for
        // terabytes and abort the process.
        let stored: u64 = ckpt.tensors.iter().map(|(_, t)| t.data().len() as u64).sum();
        let needed = config.min_weights();
        if needed > stored {
            return Err(Error::Checkpoint {
                path: name.to_path_buf(),
                msg: format!(
                    "model config asks for at least {needed} weights (its widths), but the file holds {stored} values"
                ),
            });
        }
        let mut model = Model::new(config, 0).map_err(as_ckpt_err)?;
        ckpt.apply_to(&mut model.params, name)?;
        if let Some(kp) = &mut model.net.point {
            kp.load_kernel_points(&model.params).map_err(as_ckpt_err)?;
        }
        Ok(model)
    }

    /// Loads a weights/checkpoint file image from memory.
    ///
    /// # Errors
    /// As [`Model::from_checkpoint`].
    pub fn from_bytes(bytes: &[u8], name: &Path) -> Result<Model> {
        Model::from_checkpoint(&Checkpoint::from_bytes(bytes, name)?, name)
    }

    /// The weights shipped with the crate (`fixtures/point2quad-default.p2qm`, what
    /// `make train` writes and `point2quad reconstruct` uses without `--model`), compiled
    /// into the library: no file is read. A program that never calls this does not
    /// carry the bytes (the linker drops them; [`SHIPPED_WEIGHTS`]).
    ///
    /// # Errors
    /// None in practice (a test loads them); the signature is that of
    /// [`Model::from_bytes`], whose errors name the weights [`SHIPPED_NAME`].
    pub fn shipped() -> Result<Model> {
        Model::from_bytes(SHIPPED_WEIGHTS, Path::new(SHIPPED_NAME))
    }

    /// Loads a weights/checkpoint file.
    ///
    /// # Errors
    /// I/O errors and those of [`Model::from_checkpoint`].
    pub fn load(path: &Path) -> Result<Model> {
        Model::from_checkpoint(&checkpoint::load(path)?, path)
    }
}

/// Rows the classifier scores at a time in inference ([`Model::classify`]): a multiple
/// of the GEMM's row block, so chunking changes no bit of the result.
const CLASSIFY_CHUNK_ROWS: usize = 64 * crate::tensor::gemm::ROW_BLOCK;

/// The classifier's input rows: a whole matrix (`M × face_in`, row-major), or a
/// [`FaceRows`] that makes any row on demand.
enum InputRows<'a> {
    Matrix(&'a [f32]),
    Faces(&'a FaceRows<'a>),
}

impl InputRows<'_> {
    /// Rows `lo..hi`, row-major, `w` values each (the model's input width, which
    /// `Model::input_rows` checked).
    fn range(&self, lo: usize, hi: usize, w: usize) -> Vec<f32> {
        match self {
            InputRows::Matrix(x) => x[lo * w..hi * w].to_vec(),
            InputRows::Faces(f) => f.rows(lo, hi),
        }
    }

    /// The rows `pick`, in that order, row-major, `w` values each.
    fn gather(&self, pick: &[usize], w: usize) -> Vec<f32> {
        match self {
            InputRows::Matrix(x) => {
                pick.iter().flat_map(|&i| x[i * w..(i + 1) * w].iter().copied()).collect()
            }
            InputRows::Faces(f) => {
                let dim = f.dim();
                let mut out = vec![0.0f32; pick.len() * dim];
                for (row, &i) in out.chunks_mut(dim).zip(pick) {
                    f.fill(i, row);
                }
                out
            }
        }
    }
}

/// `n` row indices spread evenly over `m` rows: ⌊i·m/n⌋ for i < n (in u64: i · m passes
/// u32 on 32-bit targets, wasm32, for large clouds).
fn even_spread(m: usize, n: usize) -> impl Iterator<Item = usize> {
    (0..n).map(move |i| (i as u64 * m as u64 / n as u64) as usize)
}

/// Candidates up to which a [`ModelConfig::cloud_batch_stats`] model scores a cloud in
/// one batch; beyond, its statistics come from this many of them ([`Model::score_rows`]).
/// 131,072 candidates: a cloud of about 12,000 points.
const CLOUD_STATS_ROWS: usize = 1 << 17;

/// `InvalidInput` naming the first candidate with a corner index `>= n_points`.
pub(crate) fn check_corners(corners: &[[u32; 4]], n_points: usize) -> Result<()> {
    if let Some((c, q)) = corners.iter().enumerate().find(|(_, q)| q.iter().any(|&v| v as usize >= n_points))
    {
        return Err(Error::invalid(format!(
            "candidate {c} {q:?} refers to a point beyond the {n_points} given"
        )));
    }
    Ok(())
}

/// The candidates' corners flattened row-major (`4·M`), as [`Network::forward`] reads them.
pub fn corner_indices(corners: &[[u32; 4]]) -> Arc<[u32]> {
    corners.iter().flatten().copied().collect::<Vec<u32>>().into()
}

impl Network {
    /// The point encoder, when the config has one.
    pub fn point_encoder(&self) -> Option<&Kpfcnn> {
        self.point.as_ref()
    }

    /// Builds the logits `[M × 2]` on `g` from the face features `[M × face_in]`
    /// and, when the config has a point encoder, per-point features `[N × d_P]` (from
    /// [`Network::point_encoder`], or any other source) with the candidates' corner
    /// indices (`4·M`, row-major: [`corner_indices`]).
    ///
    /// # Errors
    /// `Error::Shape` when the inputs do not match the config.
    pub fn forward(
        &self,
        g: &mut Graph,
        face_features: Var,
        point: Option<(Var, Arc<[u32]>)>,
    ) -> Result<Var> {
        let mut h = self.face_code(g, face_features)?;
        let m = g.value(h).rows();
        if self.config.point_dim > 0 {
            let (pf, corners) = point.ok_or_else(|| Error::Shape {
                op: "model",
                msg: "this model needs per-point features (point_dim > 0)".into(),
            })?;
            if corners.len() != 4 * m {
                return Err(Error::Shape {
                    op: "model",
                    msg: format!("{} corner indices for {m} candidates", corners.len()),
                });
            }
            let gathered = g.gather_rows(pf, corners, false)?;
            let gathered = g.reshape(gathered, &[m, 4 * self.config.point_dim])?;
            h = g.concat_cols(&[gathered, h])?;
        }
        for layer in &self.classifier {
            let next = layer.forward(g, h)?;
            g.free(h);
            h = next;
        }
        self.head.forward(g, h)
    }
}

impl Network {
    /// The face encoder: `[M × face_in]` → `[M × face_widths[4]]`.
    fn face_code(&self, g: &mut Graph, face_features: Var) -> Result<Var> {
        let mut h = face_features;
        for (i, layer) in self.face.iter().enumerate() {
            let next = layer.forward(g, h)?;
            if i > 0 {
                g.free(h);
            }
            h = next;
            if i == 1 {
                let r = self.residual.forward(g, h)?;
                g.free(h);
                h = r;
            }
        }
        Ok(h)
    }

    /// The per-point features through the corner blocks of the classifier's first
    /// layer: row p holds W_i · pf_p for the corner slots i = 0..4 (4 · cout values),
    /// so a candidate's pre-activation is its face code's part plus four looked-up
    /// rows instead of a gathered 4 · d_P-wide input. Without hidden classifier
    /// layers, `pf` itself.
    fn point_projection(&self, g: &mut Graph, pf: Var) -> Result<Var> {
        let Some(first) = self.classifier.first() else {
            return Ok(pf);
        };
        let dp = self.config.point_dim;
        let (cout, cin) = (first.cout, first.cin);
        if g.value(pf).cols() != dp || cin < 4 * dp {
            return Err(Error::Shape {
                op: "model",
                msg: format!("point features {} for layer input {cin} and d_P {dp}", g.value(pf).shape()),
            });
        }
        let wv = g.param(first.weight);
        let w = g.value(wv).data();
        // Corner blocks stacked: row i·cout + o = W[o, i·dp .. (i+1)·dp].
        let mut w_pts = Vec::with_capacity(4 * cout * dp);
        for i in 0..4 {
            for o in 0..cout {
                w_pts.extend_from_slice(&w[o * cin + i * dp..o * cin + (i + 1) * dp]);
            }
        }
        let w_pts = g.input(Tensor::new(&[4 * cout, dp], w_pts)?);
        g.matmul_t(pf, w_pts)
    }

    /// Inference form of [`Network::forward`] for a point-encoder model, equal to it up
    /// to float rounding (tested). The classifier's first layer reads
    /// `[z(c0) ; z(c1) ; z(c2) ; z(c3) ; face code]` with weight blocks `[W0 … W3 Wf]`:
    /// its pre-activation is `Σ_i (Z·W_iᵀ)[c_i] + code·Wfᵀ`, so each point's features
    /// go through the corner blocks once per point (N rows, `proj` from
    /// [`Network::point_projection`]) instead of once per candidate corner (4·M rows,
    /// M ≈ 10 N), and no `M × 4·d_P` gather is built. Nothing is recorded for a
    /// backward pass: training uses `forward`.
    fn forward_points_eval(
        &self,
        g: &mut Graph,
        face_features: Var,
        proj: &[f32],
        corners: &[[u32; 4]],
    ) -> Result<Var> {
        let dp = self.config.point_dim;
        let Some(first) = self.classifier.first() else {
            let pf = g.input(Tensor::new(&[proj.len() / dp.max(1), dp], proj.to_vec())?);
            return self.forward(g, face_features, Some((pf, corner_indices(corners))));
        };
        let h = self.face_code(g, face_features)?;
        let (m, wf) = (g.value(h).rows(), g.value(h).cols());
        let (cout, cin) = (first.cout, first.cin);
        if m != corners.len() || cin != 4 * dp + wf || proj.len() % (4 * cout) != 0 {
            return Err(Error::Shape {
                op: "model",
                msg: format!("{m} candidates, {} corners, layer input {cin} ≠ 4·{dp} + {wf}", corners.len()),
            });
        }
        let wv = g.param(first.weight);
        let w = g.value(wv).data();
        let mut w_face = Vec::with_capacity(cout * wf);
        for o in 0..cout {
            w_face.extend_from_slice(&w[o * cin + 4 * dp..(o + 1) * cin]);
        }
        let w_face = g.input(Tensor::new(&[cout, wf], w_face)?);
        let code = g.matmul_t(h, w_face)?;
        g.free(h);
        let mut pre = g.value(code).data().to_vec();
        g.free(code);
        {
            const ROWS: usize = 256;
            crate::par::for_each_chunk_mut(&mut pre, ROWS * cout, |ch, block| {
                for (r, row) in block.chunks_exact_mut(cout).enumerate() {
                    let c = corners[ch * ROWS + r];
                    for (i, &v) in c.iter().enumerate() {
                        let src = &proj[v as usize * 4 * cout + i * cout..][..cout];
                        for (a, b) in row.iter_mut().zip(src) {
                            *a += b;
                        }
                    }
                }
            });
        }
        let x = g.input(Tensor::new(&[m, cout], pre)?);
        let (gamma, beta) = (g.param(first.bn.weight), g.param(first.bn.bias));
        let mut h = g.conv_bn_act(x, None, gamma, beta, first.bn.refs(), first.act)?;
        for layer in &self.classifier[1..] {
            let next = layer.forward(g, h)?;
            g.free(h);
            h = next;
        }
        self.head.forward(g, h)
    }
}

/// Softmax probability of class 1 for rows of 2 logits.
pub fn probabilities(logits: &[f32]) -> Vec<f32> {
    logits.chunks_exact(2).map(|l| face_probability(l[0], l[1])).collect()
}

/// The softmax probability of class 1 ("face is real") from the logit pair (l0, l1).
pub fn face_probability(l0: f32, l1: f32) -> f32 {
    let d = (l0 - l1) as f64;
    (1.0 / (1.0 + d.exp())) as f32
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tensor::Grads;

    #[test]
    fn config_text_round_trips_and_rejects_garbage() {
        let odd = ModelConfig {
            point_encoder: Some(KpfcnnConfig {
                input: InputFeatures::OnesXyz,
                neighbor_cap: NeighborCap::Fixed(7),
                first_cell: 0.1 + 0.2,
                seed: u64::MAX,
                out_dim: 5,
                spacing_cells: 1.0 / 3.0,
                input_cell: 0.1 + 0.7,
                ..KpfcnnConfig::paper()
            }),
            point_dim: 5,
            ..ModelConfig::default_kp()
        };
        for name in PRESETS {
            let c = ModelConfig::preset(name).unwrap();
            assert_eq!(c.preset, name);
            c.validate().unwrap();
        }
        for c in PRESETS.iter().map(|n| ModelConfig::preset(n).unwrap()).chain([odd]) {
            let back = ModelConfig::from_text(&c.to_text(), Path::new("x")).unwrap();
            assert_eq!(back, c);
        }
        assert!(ModelConfig::preset("nope").is_err());
        let p = Path::new("cfg");
        assert!(ModelConfig::from_text("preset = x\nbogus = 1\n", p).is_err());
        assert!(ModelConfig::from_text("", p).is_err());
        let mut t = ModelConfig::default_preset().to_text();
        t = t.replace("face_widths = 64", "face_widths = 0");
        assert!(ModelConfig::from_text(&t, p).is_err());
        // A leaky ReLU's slope lies in [0, 1] (session 39's audit loaded 4294967295).
        let def = ModelConfig::default_preset().to_text();
        assert!(def.contains("leaky_slope = 0.1\n"));
        for (slope, ok) in
            [("4294967295", false), ("1.5", false), ("-0.1", false), ("NaN", false), ("1", true), ("0", true)]
        {
            let r = ModelConfig::from_text(
                &def.replace("leaky_slope = 0.1", &format!("leaky_slope = {slope}")),
                p,
            );
            assert_eq!(r.is_ok(), ok, "{slope}: {r:?}");
        }
        // `local_frame`: written only when set; a config without it predates it.
        assert!(
            def.contains("local_frame = true\n") && !ModelConfig::paper().to_text().contains("local_frame")
        );
        let old = ModelConfig::from_text(&def.replace("local_frame = true\n", ""), p).unwrap();
        assert_eq!(old, ModelConfig { local_frame: false, ..ModelConfig::default_preset() });
        assert!(ModelConfig::from_text(&def.replace("local_frame = true", "local_frame = yes"), p).is_err());
        // `sign_free_normals` likewise.
        assert!(!def.contains("sign_free_normals"));
        let sf = ModelConfig { sign_free_normals: true, ..ModelConfig::default_preset() };
        let sf_text = sf.to_text();
        assert!(sf_text.contains("sign_free_normals = true\n"), "{sf_text}");
        assert_eq!(ModelConfig::from_text(&sf_text, p).unwrap(), sf);
        assert!(ModelConfig::from_text(
            &sf_text.replace("sign_free_normals = true", "sign_free_normals = 1"),
            p
        )
        .is_err());
        // `cloud_batch_stats` likewise: set in `default_kp` only, and a `default_kp` file
        // from before it existed reads the running statistics.
        assert!(
            !def.contains("cloud_batch_stats") && !ModelConfig::paper().to_text().contains("cloud_batch")
        );
        let kp_text = ModelConfig::default_kp().to_text();
        assert!(kp_text.contains("cloud_batch_stats = true\n"), "{kp_text}");
        assert_eq!(ModelConfig::from_text(&kp_text, p).unwrap(), ModelConfig::default_kp());
        assert_eq!(
            ModelConfig::from_text(&kp_text.replace("cloud_batch_stats = true\n", ""), p).unwrap(),
            ModelConfig { cloud_batch_stats: false, ..ModelConfig::default_kp() }
        );
        assert!(ModelConfig::from_text(&kp_text.replace("stats = true", "stats = 1"), p).is_err());
        assert!(ModelConfig::from_text(&format!("{kp_text}cloud_batch_stats = true\n"), p).is_err());
        // Required keys are named when missing; optional ones do not stand in for them.
        for key in REQUIRED_KEYS {
            let short: String = def
                .lines()
                .filter(|l| !l.starts_with(&format!("{key} ")))
                .map(|l| format!("{l}\n"))
                .collect();
            assert!(short.len() < def.len(), "{key}");
            let e = ModelConfig::from_text(&format!("{short}sign_free_normals = true\n"), p).unwrap_err();
            assert!(e.to_string().contains(&format!("missing keys: {key}")), "{e}");
        }
        // Point-encoder keys: all needed with point_dim > 0, none allowed without, each
        // value checked.
        let kp = ModelConfig::default_kp().to_text();
        let without = |key: &str| kp.lines().filter(|l| !l.starts_with(key)).collect::<Vec<_>>().join("\n");
        assert!(ModelConfig::from_text(&without("kp_seed"), p).is_err());
        assert!(ModelConfig::from_text(&without("kp_"), p).is_err());
        let def = ModelConfig::default_preset().to_text();
        assert!(ModelConfig::from_text(&format!("{def}kp_seed = 1\n"), p).is_err());
        assert!(ModelConfig::from_text(&format!("{kp}kp_seed = 1\n"), p).is_err(), "repeated key");
        // `kp_spacing_cells` is optional (files before it read as 0) and checked.
        assert!(!kp.contains("kp_spacing_cells"));
        let spaced = ModelConfig::from_text(&format!("{kp}kp_spacing_cells = 1.5\n"), p).unwrap();
        assert_eq!(spaced.point_encoder.as_ref().map(|k| k.spacing_cells), Some(1.5));
        for bad in ["-1", "inf", "x"] {
            assert!(ModelConfig::from_text(&format!("{kp}kp_spacing_cells = {bad}\n"), p).is_err(), "{bad}");
        }
        // `kp_input_cell` likewise; neither optional key stands in for a required one.
        assert!(!kp.contains("kp_input_cell"));
        let voxel = ModelConfig::from_text(&format!("{kp}kp_input_cell = 0.25\n"), p).unwrap();
        assert_eq!(voxel.point_encoder.as_ref().map(|k| k.input_cell), Some(0.25));
        assert_eq!(ModelConfig::from_text(&voxel.to_text(), p).unwrap(), voxel);
        for bad in ["-1", "inf", "x", "1.5"] {
            assert!(ModelConfig::from_text(&format!("{kp}kp_input_cell = {bad}\n"), p).is_err(), "{bad}");
        }
        let both = "kp_spacing_cells = 1\nkp_input_cell = 0.5\n";
        assert!(ModelConfig::from_text(&format!("{}\n{both}", without("kp_seed")), p).is_err());
        assert!(ModelConfig::from_text(&format!("{def}{both}"), p).is_err());
        for (from, to) in [
            ("simple,", "simplex,"),
            ("kp_input = ones", "kp_input = twos"),
            ("kp_neighbor_cap = percentile 0.9", "kp_neighbor_cap = some 0.9"),
            ("kp_first_features_dim = 16", "kp_first_features_dim = 6"),
            ("kp_first_cell = 0.03", "kp_first_cell = -1"),
            ("kp_num_kernel_points = 15", "kp_num_kernel_points = 0"),
        ] {
            assert!(kp.contains(from), "{from}");
            assert!(ModelConfig::from_text(&kp.replace(from, to), p).is_err(), "{to}");
        }
    }

    /// Scoring in chunks of whole GEMM row blocks gives bit-identical probabilities
    /// (inference scores each row on its own, and the products run in the same blocks);
    /// any other chunking agrees to float rounding (a block under 6 rows takes the plain
    /// loop instead of the SIMD kernel). For any number of rows, none included.
    #[test]
    fn chunked_classification_equals_one_batch() {
        use crate::tensor::gemm::ROW_BLOCK;
        const _: () = assert!(CLASSIFY_CHUNK_ROWS % ROW_BLOCK == 0);
        let mut rng = Rng::new(3);
        let model = Model::new(ModelConfig::default_preset(), 5).unwrap();
        let fin = model.config().face_in();
        for m in [0usize, 1, 5, 33, 1500] {
            let x: Vec<f32> = (0..m * fin).map(|_| rng.f32() * 2.0 - 1.0).collect();
            let whole = model.classify_in_chunks(&x, usize::MAX / fin).unwrap();
            assert_eq!(whole.len(), m);
            for chunk in [ROW_BLOCK, 2 * ROW_BLOCK] {
                assert_eq!(model.classify_in_chunks(&x, chunk).unwrap(), whole, "m {m}, chunk {chunk}");
            }
            for chunk in [1, 7, 33] {
                let got = model.classify_in_chunks(&x, chunk).unwrap();
                assert_eq!(got.len(), m);
                let worst = got.iter().zip(&whole).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
                assert!(worst <= 1e-6, "m {m}, chunk {chunk}: {worst}");
            }
        }
    }

    /// A `cloud_batch_stats` model scores all rows in one batch whatever the chunk size,
    /// with batch norm on those rows' statistics: the same probabilities as the train
    /// graph's forward pass (which uses batch statistics too), and not those of the same
    /// weights read with their running statistics. Its running statistics stay as they
    /// were.
    #[test]
    fn cloud_batch_stats_score_the_whole_cloud_at_once() {
        let mut rng = Rng::new(8);
        let cfg = ModelConfig { cloud_batch_stats: true, ..ModelConfig::default_preset() };
        let mut model = Model::new(cfg, 5).unwrap();
        // Running statistics away from the batch's.
        for id in model.params.ids().collect::<Vec<_>>() {
            if model.params.name(id).contains("running_mean") {
                model.params.get_mut(id).data_mut().iter_mut().for_each(|x| *x = 0.7);
            }
        }
        let before = model.params.clone();
        let fin = model.config().face_in();
        let m = 300;
        let x: Vec<f32> = (0..m * fin).map(|_| rng.f32() * 2.0 - 1.0).collect();
        let whole = model.classify_in_chunks(&x, usize::MAX / fin).unwrap();
        for chunk in [1, 7, 128] {
            assert_eq!(model.classify_in_chunks(&x, chunk).unwrap(), whole, "chunk {chunk}");
        }
        let want = {
            let mut params = model.params.clone();
            let mut g = Graph::new(&mut params, false, true);
            let xv = g.input(Tensor::new(&[m, fin], model.framed(x.clone())).unwrap());
            let logits = model.net.forward(&mut g, xv, None).unwrap();
            probabilities(g.value(logits).data())
        };
        let worst = whole.iter().zip(&want).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
        assert!(worst <= 1e-5, "{worst}");
        for id in model.params.ids() {
            assert_eq!(model.params.get(id), before.get(id), "{}", model.params.name(id));
        }
        model.net.config.cloud_batch_stats = false;
        let other = model.classify_in_chunks(&x, usize::MAX / fin).unwrap();
        let diff = other.iter().zip(&whole).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
        assert!(diff > 1e-3, "the check could not fail: {diff}");
    }

    /// Beyond `stats_rows` candidates a `cloud_batch_stats` model takes its statistics
    /// from the spread sample (rows ⌊i·m/N⌋) and scores every row with them, in any
    /// chunks: the sampled rows get exactly what scoring the sample alone as one batch
    /// gives, any other row what the same features get there (a row copied from a
    /// sampled one scores as it), and the whole differs from one batch of every row.
    /// For the face-only and the point-encoder paths.
    #[test]
    fn large_clouds_take_their_statistics_from_a_spread_sample() {
        let close = |a: &[f32], b: &[f32]| a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0f32, f32::max);
        for kp in [false, true] {
            let mut rng = Rng::new(21);
            let base = if kp { ModelConfig::default_kp() } else { ModelConfig::default_preset() };
            let model = Model::new(ModelConfig { cloud_batch_stats: true, ..base }, 3).unwrap();
            let fin = model.config().face_in();
            let (m, n_stats, n) = (1000usize, 64usize, 200usize);
            let pts: Vec<[f32; 3]> = (0..n).map(|_| [0; 3].map(|_| rng.f32() * 2.0 - 1.0)).collect();
            let mut corners: Vec<[u32; 4]> = (0..m).map(|_| [0; 4].map(|_| rng.below(n) as u32)).collect();
            let mut x: Vec<f32> = (0..m * fin).map(|_| rng.f32() * 2.0 - 1.0).collect();
            let pick: Vec<usize> = (0..n_stats).map(|i| i * m / n_stats).collect();
            // Rows 1, 2, 3 (not sampled) copy sampled rows 0, 15 and 31.
            for (r, p) in [(1usize, 0usize), (2, 15 * m / n_stats), (3, 31 * m / n_stats)] {
                assert!(!pick.contains(&r) && pick.contains(&p));
                let row = x[p * fin..(p + 1) * fin].to_vec();
                x[r * fin..(r + 1) * fin].copy_from_slice(&row);
                corners[r] = corners[p];
            }
            let score = |x: &[f32], c: &[[u32; 4]], stats: usize| {
                if kp {
                    model.predict_base_with(&pts, c, &InputRows::Matrix(x), stats).unwrap()
                } else {
                    model.score_rows(&InputRows::Matrix(x), None, 100, stats).unwrap()
                }
            };
            let got = score(&x, &corners, n_stats);
            assert_eq!(got.len(), m);
            let xs: Vec<f32> = pick.iter().flat_map(|&i| x[i * fin..(i + 1) * fin].to_vec()).collect();
            let cs: Vec<[u32; 4]> = pick.iter().map(|&i| corners[i]).collect();
            let alone = score(&xs, &cs, n_stats);
            let at_pick: Vec<f32> = pick.iter().map(|&i| got[i]).collect();
            assert!(close(&at_pick, &alone) <= 1e-5, "kp {kp}: {}", close(&at_pick, &alone));
            for (r, p) in [(1usize, 0usize), (2, 15 * m / n_stats), (3, 31 * m / n_stats)] {
                assert!((got[r] - got[p]).abs() <= 1e-5, "kp {kp}: row {r} {} row {p} {}", got[r], got[p]);
            }
            // Chunks do not matter (the point path slices each chunk's corners).
            let proj = kp.then(|| {
                let enc = model.net.point_encoder().unwrap();
                let pyr = prepare(&pts, enc.config()).unwrap();
                let mut g = Graph::eval_shared(&model.params).with_batch_stats(true);
                let pf = enc.forward(&mut g, &pyr).unwrap();
                let proj = model.net.point_projection(&mut g, pf).unwrap();
                g.value(proj).data().to_vec()
            });
            let points = proj.as_deref().map(|p| (p, &corners[..]));
            assert!(
                close(&model.score_rows(&InputRows::Matrix(&x), points, 7, n_stats).unwrap(), &got) <= 1e-6,
                "kp {kp}"
            );
            let whole = score(&x, &corners, m);
            assert!(close(&whole, &got) > 1e-4, "kp {kp}: the check could not fail");
        }
    }

    /// Rows made chunk by chunk (`InputRows::Faces`, what `reconstruct` scores) give the
    /// probabilities of the whole face-input matrix, bit for bit: for the face-only and
    /// the point-encoder paths, with the statistics of one batch and of a spread sample
    /// (more candidates than `stats_rows`), over several chunks; rows of the wrong width
    /// are refused.
    #[test]
    fn rows_made_in_chunks_score_as_the_whole_matrix() {
        use crate::pipeline::candidates::{generate, CandidateConfig};
        use crate::pipeline::features::face_input;
        let pts: Vec<[f32; 3]> = (0..150)
            .map(|i| [(i % 15) as f32 * 0.1, (i / 15) as f32 * 0.1, 0.02 * ((i * 7) % 5) as f32])
            .collect();
        let cands = generate(&pts, &CandidateConfig::default()).unwrap();
        assert!(cands.len() > 300, "{} candidates", cands.len());
        for kp in [false, true] {
            let base = if kp { ModelConfig::default_kp() } else { ModelConfig::default_preset() };
            let model = Model::new(ModelConfig { cloud_batch_stats: true, ..base }, 5).unwrap();
            let ctx = model.config().use_context;
            let rows = FaceRows::new(&pts, &cands, ctx);
            let x = face_input(&pts, &cands, ctx);
            for stats in [64, usize::MAX] {
                let want =
                    model.predict_base_with(&pts, &cands.quads, &InputRows::Matrix(&x), stats).unwrap();
                let got =
                    model.predict_base_with(&pts, &cands.quads, &InputRows::Faces(&rows), stats).unwrap();
                let bits = |v: &[f32]| v.iter().map(|p| p.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&got), bits(&want), "kp {kp}, stats {stats}");
                if !kp {
                    let chunked = model.score_rows(&InputRows::Faces(&rows), None, 100, stats).unwrap();
                    assert_eq!(bits(&chunked), bits(&want), "chunks of 100, stats {stats}");
                }
            }
            let other = FaceRows::new(&pts, &cands, !ctx);
            assert!(matches!(model.predict_base_rows(&pts, &other), Err(Error::Shape { .. })), "kp {kp}");
        }
    }

    /// The shipped weights (the `default` preset reading normals without their signs,
    /// plus 6 refinement rounds of widths 32, 32 reading sides by normals and the flow
    /// columns) load, and re-serialise to the very same bytes.
    #[test]
    fn shipped_weights_load_and_reserialise_bit_exactly() {
        let bytes = SHIPPED_WEIGHTS;
        let m = Model::shipped().unwrap();
        let want = ModelConfig {
            refine_rounds: 6,
            refine_widths: vec![32, 32],
            refine_sides: SideRule::Normals,
            refine_input: RefineInput::Flow,
            sign_free_normals: true,
            ..ModelConfig::default_preset()
        };
        assert_eq!(m.config(), &want);
        assert_eq!(m.to_checkpoint(None).to_bytes(), bytes.to_vec());
    }

    /// A `local_frame` model gives the same probabilities for F_info rows of a rotated
    /// cloud (offsets and corner normals rotated); a cloud-frame model does not.
    #[test]
    fn local_frame_models_ignore_a_rotation_of_the_cloud() {
        let mut rng = Rng::new(9);
        let r = rng.rotation();
        let rot = |v: [f32; 3]| -> [f32; 3] {
            std::array::from_fn(|i| (0..3).map(|j| r[i][j] as f32 * v[j]).sum::<f32>())
        };
        // Rows of a slightly bent quad: offsets, then shape columns, normals, context.
        let m = 16;
        let fin = ModelConfig::default_preset().face_in();
        let mut rows = Vec::new();
        for k in 0..m {
            let t = k as f32 * 0.1;
            // Offsets of several spacings, as far candidates have, so that an untrained
            // network's output visibly depends on them.
            let q = [[0.0, 0.0, 0.0], [1.0 + t, 0.1, 0.0], [1.1, 1.0, 0.2 * t], [0.0, 0.9 + t, 0.1]]
                .map(|p: [f32; 3]| p.map(|x| 10.0 * x));
            let geo = crate::pipeline::candidates::quad_geom(q);
            let mut row = vec![0.0f32; fin];
            let mut f = [0.0f32; crate::pipeline::features::F_INFO_DIM];
            crate::pipeline::features::f_info_row(&q, &[1.0; 4], [0, 1, 2, 3], &mut f);
            row[..f.len()].copy_from_slice(&f);
            row[f.len()..].iter_mut().enumerate().for_each(|(i, x)| *x = geo.len[i % 4] + i as f32 * 0.01);
            rows.push(row);
        }
        let rotated: Vec<f32> = rows
            .iter()
            .flat_map(|row| {
                let mut r2 = row.clone();
                for c in [0, 3, 6, 9, 17, 20, 23, 26] {
                    let v = rot([row[c], row[c + 1], row[c + 2]]);
                    r2[c..c + 3].copy_from_slice(&v);
                }
                r2
            })
            .collect();
        let rows: Vec<f32> = rows.concat();
        for local in [true, false] {
            let cfg = ModelConfig { local_frame: local, ..ModelConfig::default_preset() };
            let model = Model::new(cfg, 3).unwrap();
            let (a, b) = (model.predict(&rows).unwrap(), model.predict(&rotated).unwrap());
            let worst = a.iter().zip(&b).map(|(x, y)| (x - y).abs()).fold(0.0f32, f32::max);
            eprintln!("local_frame {local}: worst probability change under rotation {worst:e}");
            if local {
                assert!(worst < 1e-6, "local frame: worst difference {worst}");
            } else {
                assert!(worst > 1e-5, "cloud frame: rotation changed nothing ({worst})");
            }
        }
    }

    /// A `sign_free_normals` model gives the same probabilities when some corners'
    /// point normals are negated (an orientation seam), with their context agreement
    /// dots negated alike; a model without it does not. Also in the cloud frame.
    #[test]
    fn sign_free_models_ignore_the_signs_of_point_normals() {
        use crate::pipeline::features::F_INFO_DIM;
        let mut rng = Rng::new(4);
        let fin = ModelConfig::default_preset().face_in();
        let (mut rows, mut seamed) = (Vec::new(), Vec::new());
        for k in 0..16 {
            let t = k as f32 * 0.1;
            let q = [[0.0, 0.0, 0.0], [1.0 + t, 0.1, 0.0], [1.1, 1.0, 0.2 * t], [0.0, 0.9 + t, 0.1]];
            let mut row: Vec<f32> = (0..fin).map(|_| rng.f32()).collect();
            let mut f = [0.0f32; F_INFO_DIM];
            crate::pipeline::features::f_info_row(&q, &[1.0; 4], [0, 1, 2, 3], &mut f);
            row[..F_INFO_DIM].copy_from_slice(&f);
            // Corner normals near +z (the face normal's side), tilted at random.
            for i in 0..4 {
                let n = [0.3 * (rng.f32() - 0.5), 0.3 * (rng.f32() - 0.5), 1.0];
                row[17 + 3 * i..20 + 3 * i].copy_from_slice(&n);
                row[F_INFO_DIM + 10 + i] = 0.8 + 0.2 * rng.f32();
            }
            let mut s = row.clone();
            for i in [1, 3] {
                for v in &mut s[17 + 3 * i..20 + 3 * i] {
                    *v = -*v;
                }
                s[F_INFO_DIM + 10 + i] = -s[F_INFO_DIM + 10 + i];
            }
            rows.extend(row);
            seamed.extend(s);
        }
        for (local, sign_free) in [(true, true), (false, true), (true, false)] {
            let cfg = ModelConfig {
                local_frame: local,
                sign_free_normals: sign_free,
                ..ModelConfig::default_preset()
            };
            let model = Model::new(cfg, 3).unwrap();
            let (a, b) = (model.predict(&rows).unwrap(), model.predict(&seamed).unwrap());
            let worst = a.iter().zip(&b).map(|(x, y)| (x - y).abs()).fold(0.0f32, f32::max);
            if sign_free {
                assert!(worst == 0.0, "local {local}: a seam changed a probability by {worst}");
            } else {
                assert!(worst > 1e-5, "signed model: the seam changed nothing ({worst})");
            }
        }
    }

    #[test]
    fn forward_shapes_and_checkpoint_round_trip() {
        let model = Model::new(ModelConfig::default_preset(), 1).unwrap();
        let fin = model.config().face_in();
        let m = 7;
        let mut rng = Rng::new(2);
        let feats: Vec<f32> = (0..m * fin).map(|_| rng.f32() * 2.0 - 1.0).collect();
        let p = model.predict(&feats).unwrap();
        assert_eq!(p.len(), m);
        assert!(p.iter().all(|x| (0.0..=1.0).contains(x)));
        let bytes = model.to_checkpoint(None).to_bytes();
        let back = Model::from_bytes(&bytes, Path::new("mem")).unwrap();
        assert_eq!(back.predict(&feats).unwrap(), p);
        assert!(Model::from_bytes(&bytes[..bytes.len() - 3], Path::new("mem")).is_err());
    }

    /// A weights file whose config asks for more than its tensors hold (a forged width
    /// with the checksum redone) is refused before anything is allocated; every real
    /// config's bound is within its own weights, so no valid file is refused.
    #[test]
    fn forged_widths_are_refused_before_allocation() {
        for cfg in [
            ModelConfig::default_preset(),
            ModelConfig::default_kp(),
            ModelConfig::paper(),
            ModelConfig { refine_rounds: 3, refine_widths: vec![32, 16], ..ModelConfig::default_preset() },
            // A lone Simple block with a wide first layer (review, session 20: the first
            // bound charged it K · f, twice its K · f / 2 with one input feature).
            ModelConfig {
                point_encoder: Some(KpfcnnConfig {
                    blocks: vec![BlockKind::Simple],
                    first_features_dim: 1024,
                    out_dim: 1,
                    ..KpfcnnConfig::default_preset()
                }),
                point_dim: 1,
                ..ModelConfig::default_preset()
            },
            ModelConfig {
                point_encoder: Some(KpfcnnConfig {
                    blocks: vec![BlockKind::Simple, BlockKind::Resnetb],
                    first_features_dim: 256,
                    num_kernel_points: 64,
                    out_dim: 1,
                    ..KpfcnnConfig::default_preset()
                }),
                point_dim: 1,
                ..ModelConfig::default_preset()
            },
            ModelConfig {
                refine_rounds: 5,
                refine_widths: vec![32, 16],
                refine_input: RefineInput::Flow,
                refine_sides: SideRule::Normals,
                ..ModelConfig::default_preset()
            },
        ] {
            let model = Model::new(cfg.clone(), 0).unwrap();
            let trainable = model.params.num_trainable() as u64;
            assert!(
                cfg.min_weights() <= trainable,
                "{}: bound {} > {trainable}",
                cfg.preset,
                cfg.min_weights()
            );
            // The bound is not vacuous: without a point encoder it is most of the weights.
            if cfg.point_encoder.is_none() {
                let b = cfg.min_weights();
                assert!(b * 10 >= trainable * 8, "{}: bound {b} ≪ {trainable}", cfg.preset);
            }
        }
        let model = Model::new(
            ModelConfig { refine_rounds: 2, refine_widths: vec![32, 16], ..ModelConfig::default_preset() },
            0,
        )
        .unwrap();
        let ckpt = model.to_checkpoint(None);
        let text = String::from_utf8(ckpt.config.clone()).unwrap();
        assert!(Model::from_checkpoint(&ckpt, Path::new("ok.p2qm")).is_ok());
        for (old, new) in [
            ("face_widths = 64,64,96,128,96", "face_widths = 64,64,96,128,4000000000"),
            ("classifier_widths = 128,64,32", "classifier_widths = 128,64,18446744073709551615"),
            ("refine_widths = 32,16", "refine_widths = 32,16000000000"),
        ] {
            assert!(text.contains(old), "{old:?} not in the config text");
            let forged = Checkpoint { config: text.replace(old, new).into_bytes(), ..ckpt.clone() };
            let bytes = forged.to_bytes();
            let err =
                Model::from_bytes(&bytes, Path::new("forged.p2qm")).err().expect("forged widths accepted");
            let msg = err.to_string();
            assert!(msg.contains("forged.p2qm") && msg.contains("asks for at least"), "{new}: {msg}");
        }
    }

    #[test]
    fn paper_model_with_point_features_trains_a_step() {
        let mut model = Model::new(ModelConfig::paper(), 3).unwrap();
        assert_eq!(model.param_count(), 24_364_224 + face_and_classifier_params(model.config()));
        let (m, n) = (5usize, 9usize);
        let fin = model.config().face_in();
        let mut rng = Rng::new(4);
        let feats = Tensor::new(&[m, fin], (0..m * fin).map(|_| rng.f32()).collect()).unwrap();
        let pts = Tensor::new(&[n, 64], (0..n * 64).map(|_| rng.f32()).collect()).unwrap();
        let corners: Arc<[u32]> = (0..4 * m).map(|i| (i % n) as u32).collect::<Vec<_>>().into();
        let Model { net, params } = &mut model;
        let mut g = Graph::train(params);
        let x = g.input(feats);
        let pf = g.input(pts);
        let logits = net.forward(&mut g, x, Some((pf, corners))).unwrap();
        assert_eq!(g.value(logits).dims(), &[m, 2]);
        let loss = crate::nn::loss::weighted_cross_entropy(&mut g, logits, &[1, 0, 0, 1, 0], 1.5).unwrap();
        let mut grads = Grads::new();
        g.backward(loss, &mut grads).unwrap();
        assert!(grads.norm_sq() > 0.0);
    }

    /// Trainable scalars of the face encoder and classifier alone, counted from the
    /// config (conv weights, biases only on the head, BN γ and β).
    fn face_and_classifier_params(c: &ModelConfig) -> usize {
        let unary = |cin: usize, cout: usize| cin * cout + 2 * cout;
        let mut n = 0;
        let mut cin = c.face_in();
        for &w in &c.face_widths {
            n += unary(cin, w);
            cin = w;
        }
        n += 2 * unary(c.face_widths[1], c.face_widths[1]);
        cin = 4 * c.point_dim + c.face_widths[4];
        for &w in &c.classifier_widths {
            n += unary(cin, w);
            cin = w;
        }
        n + 2 * cin + 2
    }

    #[test]
    fn point_encoder_params_live_in_the_model_store() {
        let d = Model::new(ModelConfig::default_preset(), 1).unwrap();
        assert_eq!(d.param_count(), face_and_classifier_params(d.config()));
        let m = Model::new(ModelConfig::default_kp(), 1).unwrap();
        let kcfg = m.config().point_encoder.clone().unwrap();
        assert_eq!(m.param_count(), kcfg.param_count() + face_and_classifier_params(m.config()));
        let kernels = m.params.ids().filter(|&id| m.params.name(id).ends_with(".kernel_points")).count();
        assert_eq!(kernels, kcfg.blocks.len());
        // The seed reaches the point encoder too.
        let other = Model::new(ModelConfig::default_kp(), 2).unwrap();
        let w = m.params.find("kpfcnn.enc0.kpconv.weight").unwrap();
        assert_ne!(m.params.get(w).data(), other.params.get(w).data());
    }

    #[test]
    fn inconsistent_point_configs_are_errors() {
        let no_encoder = ModelConfig { point_encoder: None, ..ModelConfig::default_kp() };
        assert!(Model::new(no_encoder, 0).is_err());
        let no_dim = ModelConfig { point_dim: 0, ..ModelConfig::default_kp() };
        assert!(Model::new(no_dim, 0).is_err());
        let mismatch = ModelConfig { point_dim: 8, ..ModelConfig::default_kp() };
        assert!(Model::new(mismatch, 0).is_err());
        // predict refuses a point model; predict_with_points checks the corners.
        let m = Model::new(ModelConfig::default_kp(), 0).unwrap();
        let fin = m.config().face_in();
        let pts = [[0.0f32, 0.0, 0.0], [0.1, 0.0, 0.0], [0.0, 0.1, 0.0], [0.1, 0.1, 0.0]];
        assert!(m.predict(&vec![0.0; fin]).is_err());
        assert!(m.predict_with_points(&pts, &[[0, 1, 2, 4]], &vec![0.0; fin]).is_err());
        assert!(m.predict_with_points(&pts, &[[0, 1, 2, 3]; 2], &vec![0.0; fin]).is_err());
        assert_eq!(m.predict_with_points(&pts, &[], &[]).unwrap(), Vec::<f32>::new());
    }

    #[test]
    fn factored_point_inference_equals_the_training_forward() {
        // predict_with_points factors the classifier's first layer per point; the
        // training forward gathers and concatenates. Same model, same inputs: the
        // logits must agree to float rounding. Non-trivial BN statistics and weights
        // (a few SGD-free random perturbations) so no block is zero.
        for seed in 0..3u64 {
            // Seed 2: level 0 on voxels (`input_cell`), several points to a voxel here (the
            // cloud shrunk to radius 0.05 below).
            let mut cfg = ModelConfig::default_kp();
            if seed == 2 {
                cfg.point_encoder.as_mut().unwrap().input_cell = 1.0;
            }
            let mut m = Model::new(cfg, seed).unwrap();
            let mut rng = Rng::new(10 + seed);
            let n = 300;
            let pts: Vec<[f32; 3]> = (0..n)
                .map(|_| {
                    let v = [rng.f32() * 2.0 - 1.0, rng.f32() * 2.0 - 1.0, rng.f32() * 2.0 - 1.0];
                    let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt().max(1e-3);
                    let l = if seed == 2 { l * 20.0 } else { l };
                    [v[0] / l, v[1] / l, v[2] / l]
                })
                .collect();
            let mc = 257; // not a multiple of the 256-row chunks
            let corners: Vec<[u32; 4]> = (0..mc).map(|_| [0; 4].map(|_| rng.below(n) as u32)).collect();
            let fin = m.config().face_in();
            let feats: Vec<f32> = (0..mc * fin).map(|_| rng.f32() * 2.0 - 1.0).collect();
            let params = &mut m.params;
            for id in params.ids().collect::<Vec<_>>() {
                if params.name(id).contains("running_var") {
                    for x in params.get_mut(id).data_mut() {
                        *x = 0.5 + rng.f32();
                    }
                } else if params.name(id).contains("running_mean") {
                    for x in params.get_mut(id).data_mut() {
                        *x = 0.2 * (rng.f32() - 0.5);
                    }
                }
            }
            // Running statistics, and each cloud's own (`default_kp`'s setting).
            for cloud in [false, true] {
                m.net.config.cloud_batch_stats = cloud;
                let fast = m.predict_with_points(&pts, &corners, &feats).unwrap();
                let kp = m.net.point_encoder().unwrap();
                let pyr = prepare(&pts, kp.config()).unwrap();
                if seed == 2 {
                    assert!(pyr.points[0].len() < n / 2, "{} voxels", pyr.points[0].len());
                }
                let mut g = Graph::eval_shared(&m.params).with_batch_stats(cloud);
                let pf = kp.forward(&mut g, &pyr).unwrap();
                // The rows as training feeds them (in the candidate's frame for this preset).
                let x = g.input(Tensor::new(&[mc, fin], m.framed(feats.clone())).unwrap());
                let logits = m.net.forward(&mut g, x, Some((pf, corner_indices(&corners)))).unwrap();
                let slow = probabilities(g.value(logits).data());
                assert_eq!(fast.len(), slow.len());
                let worst = fast.iter().zip(&slow).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
                assert!(
                    worst < 1e-6,
                    "seed {seed}, cloud {cloud}: factored and gathered inference differ by {worst}"
                );
                // And the probabilities are not all saturated (the check would be vacuous).
                assert!(slow.iter().any(|&p| p > 0.01 && p < 0.99));
            }
        }
    }

    /// Random F_info-like rows: `m` rows of `fin` values in [−1, 1].
    fn random_rows(rng: &mut Rng, m: usize, fin: usize) -> Vec<f32> {
        (0..m * fin).map(|_| rng.uniform(-1.0, 1.0) as f32).collect()
    }

    fn buffers(m: &Model) -> Vec<Vec<f32>> {
        let names: Vec<ParamId> =
            m.params.ids().filter(|&id| m.params.name(id).contains(".running_")).collect();
        names.iter().map(|&id| m.params.get(id).data().to_vec()).collect()
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig { cases: 24, ..Default::default() })]

        /// Precise statistics against references: the first block's running mean and
        /// (unbiased) variance equal a brute-force pass over the framed rows times its
        /// weights; over several batches every buffer is the mean of what each batch
        /// alone gives; a cap on the rows equals passing the even spread of rows itself;
        /// the running buffers the model had do not matter.
        #[test]
        fn precise_batch_norm_matches_references(
            seed in 0u64..1000,
            sizes in proptest::collection::vec(0usize..60, 1..5),
            cap in 2usize..80,
        ) {
            let mut rng = Rng::new(seed);
            let base = Model::new(ModelConfig::default_preset(), seed).unwrap();
            let fin = base.config().face_in();
            let batches: Vec<Vec<f32>> = sizes.iter().map(|&m| random_rows(&mut rng, m, fin)).collect();
            let usable: Vec<&Vec<f32>> = batches.iter().filter(|b| b.len() / fin >= 2).collect();
            let mut all = Model::new(ModelConfig::default_preset(), seed).unwrap();
            // Other running buffers to start from: they must not matter.
            for id in all.params.ids().collect::<Vec<_>>() {
                if all.params.name(id).contains(".running_") {
                    for x in all.params.get_mut(id).data_mut() {
                        *x = rng.uniform(0.5, 2.0) as f32;
                    }
                }
            }
            let r = all.precise_batch_norm(batches.iter().map(|b| b.as_slice()), usize::MAX);
            if usable.is_empty() {
                proptest::prop_assert!(r.is_err());
                return Ok(());
            }
            proptest::prop_assert_eq!(r.unwrap(), usable.len());
            // The mean of the single-batch results, buffer by buffer.
            let singles: Vec<Vec<Vec<f32>>> = usable
                .iter()
                .map(|b| {
                    let mut m = Model::new(ModelConfig::default_preset(), seed).unwrap();
                    m.precise_batch_norm([b.as_slice()], usize::MAX).unwrap();
                    buffers(&m)
                })
                .collect();
            for (k, got) in buffers(&all).iter().enumerate() {
                for (j, &g) in got.iter().enumerate() {
                    let want = singles.iter().map(|s| s[k][j] as f64).sum::<f64>() / singles.len() as f64;
                    proptest::prop_assert!((g as f64 - want).abs() <= 1e-5 * (1.0 + want.abs()), "buffer {k}[{j}]: {g} against {want}");
                }
            }
            // Brute force for the first block of the first usable batch.
            let b = usable[0];
            let m = b.len() / fin;
            let x = base.framed(b.to_vec());
            let block = &base.net.face[0];
            let w = base.params.get(block.weight).data();
            let (mut mean, mut var) = (vec![0.0f64; block.cout], vec![0.0f64; block.cout]);
            let y: Vec<Vec<f64>> = (0..m)
                .map(|i| (0..block.cout).map(|c| (0..fin).map(|k| x[i * fin + k] as f64 * w[c * fin + k] as f64).sum()).collect())
                .collect();
            for c in 0..block.cout {
                mean[c] = y.iter().map(|r| r[c]).sum::<f64>() / m as f64;
                var[c] = y.iter().map(|r| (r[c] - mean[c]).powi(2)).sum::<f64>() / (m as f64 - 1.0);
            }
            let mut one = Model::new(ModelConfig::default_preset(), seed).unwrap();
            one.precise_batch_norm([b.as_slice()], usize::MAX).unwrap();
            let rm = one.params.get(block.bn.running_mean).data();
            let rv = one.params.get(block.bn.running_var).data();
            for c in 0..block.cout {
                proptest::prop_assert!((rm[c] as f64 - mean[c]).abs() <= 1e-4 * (1.0 + mean[c].abs()), "mean {c}: {} against {}", rm[c], mean[c]);
                proptest::prop_assert!((rv[c] as f64 - var[c]).abs() <= 1e-4 * (1.0 + var[c]), "var {c}: {} against {}", rv[c], var[c]);
            }
            // A cap on the rows: the same as passing the even spread itself.
            let mut capped = Model::new(ModelConfig::default_preset(), seed).unwrap();
            capped.precise_batch_norm([b.as_slice()], cap).unwrap();
            let n = m.min(cap);
            let spread: Vec<f32> =
                (0..n).flat_map(|i| b[(i * m / n) * fin..(i * m / n + 1) * fin].iter().copied()).collect();
            let mut direct = Model::new(ModelConfig::default_preset(), seed).unwrap();
            direct.precise_batch_norm([spread.as_slice()], usize::MAX).unwrap();
            proptest::prop_assert_eq!(buffers(&capped), buffers(&direct));
        }
    }

    /// What it refuses: a point encoder, statistics read per cloud, a cap under 2,
    /// nothing usable, ragged rows; a refused call leaves the buffers alone.
    #[test]
    fn precise_batch_norm_refuses_what_it_cannot_do() {
        let mut kp = Model::new(ModelConfig::default_kp(), 1).unwrap();
        let fin = kp.config().face_in();
        let rows = vec![0.5f32; 4 * fin];
        assert!(kp
            .precise_batch_norm([rows.as_slice()], 100)
            .unwrap_err()
            .to_string()
            .contains("point encoder"));
        let mut m = Model::new(ModelConfig::default_preset(), 1).unwrap();
        let fin = m.config().face_in();
        let before = buffers(&m);
        let rows = vec![0.5f32; 4 * fin];
        assert!(m.precise_batch_norm([rows.as_slice()], 1).is_err());
        assert!(m.precise_batch_norm([&rows[..fin]], 100).unwrap_err().to_string().contains("no batch"));
        assert!(m.precise_batch_norm([&rows[..fin + 1]], 100).is_err());
        assert_eq!(buffers(&m), before);
        m.net.config.cloud_batch_stats = true;
        assert!(m
            .precise_batch_norm([rows.as_slice()], 100)
            .unwrap_err()
            .to_string()
            .contains("own statistics"));
    }
}
