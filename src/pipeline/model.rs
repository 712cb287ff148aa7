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
//! One [`ModelConfig`] describes the whole network; the presets `paper` and `default`
//! differ only in its numbers. The config is stored as `key = value` text inside the
//! checkpoint, so a weights file is self-describing.

use crate::nn::batch_norm::BatchNormConfig;
use crate::nn::checkpoint::{self, Checkpoint, TrainState};
use crate::nn::conv1d::{Conv1d, ConvBnAct};
use crate::nn::module::{Module, ResidualBlock};
use crate::rng::Rng;
use crate::tensor::{Act, Graph, ParamStore, Tensor, Var};
use crate::{Error, Result};
use std::path::Path;
use std::sync::Arc;

/// The whole network's shape.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelConfig {
    /// Preset name this config came from (informational).
    pub preset: String,
    /// Whether the per-candidate context features follow F_info in the input.
    pub use_context: bool,
    /// Face-encoder widths: the outputs of its 5 layers (residual block after the 2nd).
    pub face_widths: [usize; 5],
    /// Per-point feature width d_P gathered for each corner (0: no point encoder).
    pub point_dim: usize,
    /// Classifier hidden widths (each conv1d+BN+ReLU); a final conv1d maps to 2 logits.
    pub classifier_widths: Vec<usize>,
    /// LeakyReLU slope in the face encoder.
    pub leaky_slope: f32,
    /// Batch-norm momentum (PyTorch convention).
    pub bn_momentum: f32,
}

impl ModelConfig {
    /// The paper's widths (DESIGN §3): face 29→128→128(res)→256→512→256, classifier
    /// 512→512→256→128→64→2, d_P = 64.
    pub fn paper() -> ModelConfig {
        ModelConfig {
            preset: "paper".into(),
            use_context: false,
            face_widths: [128, 128, 256, 512, 256],
            point_dim: 64,
            classifier_widths: vec![512, 256, 128, 64],
            leaky_slope: 0.1,
            bn_momentum: 0.02,
        }
    }

    /// The preset sized to train on two CPU cores: same structure, about a quarter of
    /// the widths, plus the cheap context features (DESIGN §8), and batch-norm momentum
    /// 0.1 (few steps per epoch: 0.02 leaves the running statistics far off for many
    /// epochs).
    pub fn default_preset() -> ModelConfig {
        ModelConfig {
            preset: "default".into(),
            use_context: true,
            face_widths: [64, 64, 96, 128, 96],
            point_dim: 0,
            classifier_widths: vec![128, 64, 32],
            leaky_slope: 0.1,
            bn_momentum: 0.1,
        }
    }

    /// A preset by name (`default` or `paper`).
    ///
    /// # Errors
    /// `Error::Usage` for an unknown name.
    pub fn preset(name: &str) -> Result<ModelConfig> {
        match name {
            "default" => Ok(ModelConfig::default_preset()),
            "paper" => Ok(ModelConfig::paper()),
            other => Err(Error::Usage(format!("unknown model preset {other:?} (use default or paper)"))),
        }
    }

    /// Width of the face encoder's input.
    pub fn face_in(&self) -> usize {
        crate::pipeline::features::F_INFO_DIM
            + if self.use_context { crate::pipeline::features::CONTEXT_DIM } else { 0 }
    }

    /// The config as `key = value` lines (stored in checkpoints).
    pub fn to_text(&self) -> String {
        let list = |v: &[usize]| v.iter().map(|x| x.to_string()).collect::<Vec<_>>().join(",");
        format!(
            "preset = {}\nuse_context = {}\nface_in = {}\nface_widths = {}\npoint_dim = {}\nclassifier_widths = {}\nleaky_slope = {}\nbn_momentum = {}\n",
            self.preset,
            self.use_context,
            self.face_in(),
            list(&self.face_widths),
            self.point_dim,
            list(&self.classifier_widths),
            self.leaky_slope,
            self.bn_momentum
        )
    }

    /// Parses [`ModelConfig::to_text`] output; `name` is used in errors.
    ///
    /// # Errors
    /// `Error::Parse` naming the line for a malformed or missing key, and when the
    /// stored input width does not match this build's feature layout.
    pub fn from_text(text: &str, name: &Path) -> Result<ModelConfig> {
        let mut c = ModelConfig::default_preset();
        let mut face_in = None;
        let mut seen = 0u32;
        for (i, line) in text.lines().enumerate() {
            let line = line.trim();
            if line.is_empty() || line.starts_with('#') {
                continue;
            }
            let bad = |m: &str| Error::parse(name, i + 1, format!("model config: {m}: {line:?}"));
            let (k, v) = line.split_once('=').ok_or_else(|| bad("expected key = value"))?;
            let (k, v) = (k.trim(), v.trim());
            let usize_list = |v: &str| -> Result<Vec<usize>> {
                v.split(',').map(|x| x.trim().parse::<usize>().map_err(|_| bad("bad width list"))).collect()
            };
            match k {
                "preset" => c.preset = v.to_string(),
                "use_context" => c.use_context = v.parse().map_err(|_| bad("bad bool"))?,
                "face_in" => face_in = Some(v.parse::<usize>().map_err(|_| bad("bad number"))?),
                "face_widths" => {
                    let w = usize_list(v)?;
                    c.face_widths = w.try_into().map_err(|_| bad("face_widths needs 5 widths"))?;
                }
                "point_dim" => c.point_dim = v.parse().map_err(|_| bad("bad number"))?,
                "classifier_widths" => c.classifier_widths = usize_list(v)?,
                "leaky_slope" => c.leaky_slope = v.parse().map_err(|_| bad("bad number"))?,
                "bn_momentum" => c.bn_momentum = v.parse().map_err(|_| bad("bad number"))?,
                _ => return Err(bad("unknown key")),
            }
            seen += 1;
        }
        if seen < 7 {
            return Err(Error::parse(name, 0, "model config: missing keys"));
        }
        if c.face_widths.contains(&0) || c.classifier_widths.contains(&0) {
            return Err(Error::parse(name, 0, "model config: zero width"));
        }
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
}

/// A network with its parameters.
pub struct Model {
    /// The layers.
    pub net: Network,
    /// All parameters and batch-norm buffers.
    pub params: ParamStore,
}

impl Model {
    /// A freshly initialised network (Kaiming-uniform convs, BN weight 1 / bias 0).
    ///
    /// # Errors
    /// `Error::InvalidInput` for a config with zero widths.
    pub fn new(config: ModelConfig, seed: u64) -> Result<Model> {
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
        Ok(Model { net: Network { config, face, residual, classifier, head }, params })
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
    /// batch-norm statistics, nothing recorded).
    ///
    /// # Errors
    /// `Error::Shape` when `face_features.len()` is not a multiple of the input width.
    pub fn predict(&self, face_features: &[f32]) -> Result<Vec<f32>> {
        let fin = self.net.config.face_in();
        if face_features.len() % fin != 0 {
            return Err(Error::Shape {
                op: "predict",
                msg: format!("{} values is not M × {fin}", face_features.len()),
            });
        }
        let m = face_features.len() / fin;
        if m == 0 {
            return Ok(Vec::new());
        }
        if self.net.config.point_dim > 0 {
            return Err(Error::Shape {
                op: "predict",
                msg: "point-encoder models need predict_with_points".into(),
            });
        }
        let mut g = Graph::eval_shared(&self.params);
        let x = g.input(Tensor::new(&[m, fin], face_features.to_vec())?);
        let logits = self.net.forward(&mut g, x, None)?;
        Ok(probabilities(g.value(logits).data()))
    }

    /// The weights and config as a checkpoint (with the optional training state).
    pub fn to_checkpoint(&self, train: Option<TrainState>) -> Checkpoint {
        Checkpoint::from_store(&self.params, self.net.config.to_text().as_bytes(), train)
    }

    /// Rebuilds a model from a checkpoint image; `name` is used in errors.
    ///
    /// # Errors
    /// `Error::Checkpoint` for a corrupt file, a config this build cannot read, or
    /// tensors that do not match the config.
    pub fn from_checkpoint(ckpt: &Checkpoint, name: &Path) -> Result<Model> {
        let text = std::str::from_utf8(&ckpt.config).map_err(|_| Error::Checkpoint {
            path: name.to_path_buf(),
            msg: "model config is not UTF-8".into(),
        })?;
        let config = ModelConfig::from_text(text, name)
            .map_err(|e| Error::Checkpoint { path: name.to_path_buf(), msg: e.to_string() })?;
        let mut model = Model::new(config, 0)?;
        ckpt.apply_to(&mut model.params, name)?;
        Ok(model)
    }

    /// Loads a weights/checkpoint file image from memory.
    ///
    /// # Errors
    /// As [`Model::from_checkpoint`].
    pub fn from_bytes(bytes: &[u8], name: &Path) -> Result<Model> {
        Model::from_checkpoint(&Checkpoint::from_bytes(bytes, name)?, name)
    }

    /// Loads a weights/checkpoint file.
    ///
    /// # Errors
    /// I/O errors and those of [`Model::from_checkpoint`].
    pub fn load(path: &Path) -> Result<Model> {
        Model::from_checkpoint(&checkpoint::load(path)?, path)
    }
}

impl Network {
    /// Builds the logits `[M × 2]` on `g` from the face features `[M × face_in]`
    /// and, when the config has a point encoder, per-point features `[N × d_P]` with
    /// the candidates' corner indices (`4·M`, row-major).
    ///
    /// # Errors
    /// `Error::Shape` when the inputs do not match the config.
    pub fn forward(
        &self,
        g: &mut Graph,
        face_features: Var,
        point: Option<(Var, Arc<[u32]>)>,
    ) -> Result<Var> {
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

/// Softmax probability of class 1 for rows of 2 logits.
pub fn probabilities(logits: &[f32]) -> Vec<f32> {
    logits
        .chunks_exact(2)
        .map(|l| {
            let d = (l[0] - l[1]) as f64;
            (1.0 / (1.0 + d.exp())) as f32
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tensor::Grads;

    #[test]
    fn config_text_round_trips_and_rejects_garbage() {
        for c in [ModelConfig::paper(), ModelConfig::default_preset()] {
            let back = ModelConfig::from_text(&c.to_text(), Path::new("x")).unwrap();
            assert_eq!(back, c);
        }
        let p = Path::new("cfg");
        assert!(ModelConfig::from_text("preset = x\nbogus = 1\n", p).is_err());
        assert!(ModelConfig::from_text("", p).is_err());
        let mut t = ModelConfig::default_preset().to_text();
        t = t.replace("face_widths = 64", "face_widths = 0");
        assert!(ModelConfig::from_text(&t, p).is_err());
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

    #[test]
    fn paper_model_with_point_features_trains_a_step() {
        let mut model = Model::new(ModelConfig::paper(), 3).unwrap();
        assert!(model.param_count() > 500_000);
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
}
