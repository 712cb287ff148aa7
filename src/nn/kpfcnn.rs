//! KPFCNN (Thomas et al. 2019), the point encoder of DESIGN §3: rigid KPConv blocks on a
//! grid-subsampling pyramid, strided KPConv for pooling, nearest upsampling with skip
//! concatenation, and a unary head giving `d_P` features per input point.
//!
//! Geometry is prepared once per cloud ([`prepare`] → [`PointPyramid`]: levels, neighbour
//! tables, upsampling indices) and reused across epochs; [`Kpfcnn::forward`] records the network
//! on a tape. Blocks follow the authors' PyTorch code: unary = conv1d (no bias) + batch norm +
//! LeakyReLU; simple = KPConv(C_in → C/2) + BN + LeakyReLU; ResNet bottleneck = unary down to C/4
//! (skipped when already C/4) → KPConv → BN + LeakyReLU → unary up to C (no activation) + shortcut
//! (unary without activation when widths differ; max-pool over the pooling neighbourhood when
//! strided, shadow slots counting as a zero feature as in the authors' code), then LeakyReLU.
//! Neighbour caps are calibrated per cloud in [`prepare`] (the authors calibrate once over their
//! training batches); with sum aggregation a different cap only changes which far neighbours of
//! the densest 10% of points are dropped. Each KPConv's kernel points are also stored as a buffer
//! (`….kpconv.kernel_points`) so that checkpoints carry them ([`Kpfcnn::load_kernel_points`]).
//!
//! | preset | blocks | widths | levels (cells) | parameters |
//! |---|---|---|---|---|
//! | `default_preset()` | simple, resnetb, (strided, resnetb) ×2 | 32 → 128, d_P 64 | 3 (0.03 raw†, 0.06, 0.12) | 65,744 |
//! | `paper()` | S3DIS list, rigid | 128 → 2048, d_P 64 | 5 (0.03 raw†, 0.06 … 0.48) | 24,364,224 |
//!
//! † level 0 is the raw cloud unless [`KpfcnnConfig::input_cell`] puts it on voxels.
//!
//! `paper`: encoder 20,174,144 + decoder unaries 4,181,760 + head 8,320 = 24,364,224, the
//! authors' KPFCNN for this block list with rigid KPConv (no bias; K × C_in × C_out weights),
//! bias-free unaries + batch norm (γ, β), and the head unary 128 → 64 with batch norm in place of
//! their 128 → 128 head and classifier. Batch-norm running statistics are buffers, not counted.

use std::sync::Arc;

use crate::nn::batch_norm::{BatchNorm1d, BatchNormConfig};
use crate::nn::conv1d::ConvBnAct;
use crate::nn::kernel_points::scaled_kernel_points;
use crate::nn::kpconv::{KpConvGeometry, KpConvOp};
use crate::nn::module::Module;
use crate::rng::Rng;
use crate::spatial::kdtree::KdTree;
use crate::spatial::neighborhoods::{nearest_upsampling, radius_neighborhoods, NeighborCap, Neighborhoods};
use crate::spatial::subsample::{grid_subsample, subsample_pyramid};
use crate::tensor::{Act, Graph, ParamId, ParamKind, ParamStore, Tensor, Var};
use crate::{Error, Result};

/// One encoder block of the architecture list.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BlockKind {
    /// KPConv(C_in → C/2) + BN + LeakyReLU.
    Simple,
    /// ResNet bottleneck at the current level.
    Resnetb,
    /// ResNet bottleneck from the current level into the next, coarser one (pooling).
    ResnetbStrided,
}

/// Per-point input features.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum InputFeatures {
    /// A constant 1 per point (a zero feature would look like empty space).
    Ones,
    /// 1 plus the point's xyz (in the normalised frame).
    OnesXyz,
}

impl InputFeatures {
    /// Channels of the input tensor.
    pub fn dim(self) -> usize {
        match self {
            InputFeatures::Ones => 1,
            InputFeatures::OnesXyz => 4,
        }
    }
}

/// Hyperparameters of the encoder. The decoder is implied: one nearest-upsample + unary per
/// strided block, widths halving back to level 0, then the head unary to `out_dim`.
#[derive(Clone, Debug, PartialEq)]
pub struct KpfcnnConfig {
    /// Encoder blocks in order; each `ResnetbStrided` moves to the next level.
    pub blocks: Vec<BlockKind>,
    /// Block width at level 0 (doubles at each strided block).
    pub first_features_dim: usize,
    /// Input features.
    pub input: InputFeatures,
    /// Nominal cell of level 0 (the raw points, or their voxels with `input_cell`);
    /// level l has `first_cell · 2^l`.
    pub first_cell: f32,
    /// Neighbourhood (and kernel ball) radius, in cells of the level.
    pub conv_radius: f32,
    /// Kernel point influence extent σ, in cells of the level.
    pub kp_extent: f32,
    /// Kernel points per KPConv.
    pub num_kernel_points: usize,
    /// Neighbour table width rule, per level and per pooling table.
    pub neighbor_cap: NeighborCap,
    /// Batch-norm momentum (PyTorch convention).
    pub bn_momentum: f32,
    /// Batch-norm epsilon.
    pub bn_eps: f32,
    /// LeakyReLU slope.
    pub leaky_slope: f32,
    /// Output features per point, d_P.
    pub out_dim: usize,
    /// Seed of weight initialisation and kernel point rotations.
    pub seed: u64,
    /// When > 0, [`prepare`] scales each cloud so that its median nearest-neighbour
    /// distance is `spacing_cells · first_cell`: every cloud then looks equally dense to
    /// the network, whatever its sampling (sum-aggregating KPConvs otherwise give outputs
    /// that grow with the number of neighbours, and batch norm's running statistics mix
    /// clouds of very different density). 0 keeps the cloud as given (the presets).
    pub spacing_cells: f32,
    /// When > 0, level 0 is not the raw cloud but the cloud grid-subsampled with cell
    /// `input_cell · first_cell` (one barycentre per voxel), and each input point reads
    /// the output features of its voxel: level 0's neighbourhoods then hold a bounded
    /// number of points (about π (conv_radius / input_cell)² on a surface) however
    /// dense the cloud. 0 keeps the raw cloud as level 0 (DESIGN §3; the presets), whose
    /// cost grows with density. At most 1: level 0's voxels stay finer than level 1's
    /// cells.
    pub input_cell: f32,
}

impl Default for KpfcnnConfig {
    fn default() -> Self {
        KpfcnnConfig::default_preset()
    }
}

impl KpfcnnConfig {
    /// Small preset to train on two CPU cores: 3 levels, widths 32/64/128, d_P = 64.
    pub fn default_preset() -> Self {
        use BlockKind::*;
        KpfcnnConfig {
            blocks: vec![Simple, Resnetb, ResnetbStrided, Resnetb, ResnetbStrided, Resnetb],
            first_features_dim: 32,
            input: InputFeatures::Ones,
            first_cell: 0.03,
            conv_radius: 2.5,
            kp_extent: 1.0,
            num_kernel_points: 15,
            neighbor_cap: NeighborCap::Percentile(0.9),
            bn_momentum: 0.02,
            bn_eps: 1e-5,
            leaky_slope: 0.1,
            out_dim: 64,
            seed: 0,
            spacing_cells: 0.0,
            input_cell: 0.0,
        }
    }

    /// The `paper` preset of DESIGN §3: the S3DIS block list made rigid, first width 128,
    /// cells 0.03 (nominal, raw points) / 0.06 / 0.12 / 0.24 / 0.48, conv radius 2.5 cells,
    /// KP extent 1 cell, 15 kernel points, 90th-percentile caps, head 128 → 64.
    pub fn paper() -> Self {
        use BlockKind::*;
        KpfcnnConfig {
            blocks: vec![
                Simple,
                Resnetb,
                ResnetbStrided,
                Resnetb,
                Resnetb,
                ResnetbStrided,
                Resnetb,
                Resnetb,
                ResnetbStrided,
                Resnetb,
                Resnetb,
                ResnetbStrided,
                Resnetb,
                Resnetb,
            ],
            first_features_dim: 128,
            ..KpfcnnConfig::default_preset()
        }
    }

    /// Number of pyramid levels (1 + strided blocks).
    pub fn num_levels(&self) -> usize {
        1 + self.blocks.iter().filter(|b| **b == BlockKind::ResnetbStrided).count()
    }

    /// Cell of level `l`.
    pub fn cell(&self, level: usize) -> f32 {
        self.first_cell * (1u64 << level.min(62)) as f32
    }

    /// Checks the configuration.
    ///
    /// # Errors
    /// `InvalidInput` naming the first bad field.
    pub fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(Error::invalid(format!("KpfcnnConfig: {m}")));
        if self.blocks.first() != Some(&BlockKind::Simple) || self.blocks[1..].contains(&BlockKind::Simple) {
            return bad("the block list must start with exactly one Simple block".into());
        }
        if self.first_features_dim < 4 || self.first_features_dim % 4 != 0 {
            return bad(format!(
                "first_features_dim must be a positive multiple of 4, got {}",
                self.first_features_dim
            ));
        }
        for (name, v) in [
            ("first_cell", self.first_cell),
            ("conv_radius", self.conv_radius),
            ("kp_extent", self.kp_extent),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return bad(format!("{name} must be finite and > 0, got {v}"));
            }
        }
        if !(self.spacing_cells.is_finite() && self.spacing_cells >= 0.0) {
            return bad(format!("spacing_cells must be finite and ≥ 0, got {}", self.spacing_cells));
        }
        if !(self.input_cell.is_finite() && (0.0..=1.0).contains(&self.input_cell)) {
            return bad(format!("input_cell must be in [0, 1] (first cells), got {}", self.input_cell));
        }
        if !(self.bn_momentum.is_finite() && (0.0..=1.0).contains(&self.bn_momentum)) {
            return bad(format!("bn_momentum must be in [0, 1], got {}", self.bn_momentum));
        }
        if !(self.bn_eps.is_finite() && self.bn_eps > 0.0) {
            return bad(format!("bn_eps must be finite and > 0, got {}", self.bn_eps));
        }
        if !(0.0..=1.0).contains(&self.leaky_slope) {
            return bad(format!("leaky_slope must be in [0, 1], got {}", self.leaky_slope));
        }
        if self.out_dim == 0 {
            return bad("out_dim must be positive".into());
        }
        if self.num_levels() > 16 {
            return bad(format!("too many levels: {}", self.num_levels()));
        }
        if self.num_kernel_points == 0 || self.num_kernel_points > crate::nn::kernel_points::MAX_KERNEL_POINTS
        {
            return bad(format!("num_kernel_points out of range: {}", self.num_kernel_points));
        }
        Ok(())
    }

    /// The KPConv layers in execution order (for profiling and reports).
    pub fn kpconv_layers(&self) -> Vec<KpConvLayerShape> {
        plan(self)
            .blocks
            .iter()
            .map(|b| {
                let (c_in, c_out) = match b.kind {
                    BlockKind::Simple => (b.c_in, b.c_out / 2),
                    _ => (b.c_out / 4, b.c_out / 4),
                };
                KpConvLayerShape { level: b.level, strided: b.kind == BlockKind::ResnetbStrided, c_in, c_out }
            })
            .collect()
    }

    /// Learnable parameters of the network (KPConv and unary weights, batch-norm γ and β;
    /// running statistics are buffers and not counted), from the configuration alone.
    pub fn param_count(&self) -> usize {
        plan(self).param_count(self.num_kernel_points)
    }
}

/// Where a KPConv layer runs and its widths.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct KpConvLayerShape {
    /// Level of its support points (strided layers write into level + 1).
    pub level: usize,
    /// True for a strided (pooling) KPConv.
    pub strided: bool,
    /// Input channels.
    pub c_in: usize,
    /// Output channels.
    pub c_out: usize,
}

/// Shapes of one unary layer (weight `[out × in]`, BN over `out`).
#[derive(Clone, Copy, Debug)]
struct UnaryPlan {
    c_in: usize,
    c_out: usize,
}

#[derive(Clone, Debug)]
struct BlockPlan {
    kind: BlockKind,
    level: usize,
    c_in: usize,
    c_out: usize,
}

#[derive(Clone, Debug)]
struct Plan {
    blocks: Vec<BlockPlan>,
    /// Decoder unaries from the coarsest level back to level 0 (in execution order).
    decoder: Vec<UnaryPlan>,
    head: UnaryPlan,
}

fn plan(cfg: &KpfcnnConfig) -> Plan {
    let mut in_dim = cfg.input.dim();
    let mut out_dim = cfg.first_features_dim;
    let mut level = 0;
    let mut blocks = Vec::new();
    let mut skip_dims = Vec::new();
    for &kind in &cfg.blocks {
        if kind == BlockKind::ResnetbStrided {
            skip_dims.push(in_dim);
        }
        blocks.push(BlockPlan { kind, level, c_in: in_dim, c_out: out_dim });
        in_dim = if kind == BlockKind::Simple { out_dim / 2 } else { out_dim };
        if kind == BlockKind::ResnetbStrided {
            level += 1;
            out_dim *= 2;
        }
    }
    let mut decoder = Vec::new();
    for l in (0..level).rev() {
        out_dim /= 2;
        decoder.push(UnaryPlan { c_in: in_dim + skip_dims[l], c_out: out_dim });
        in_dim = out_dim;
    }
    Plan { blocks, decoder, head: UnaryPlan { c_in: in_dim, c_out: cfg.out_dim } }
}

impl Plan {
    fn param_count(&self, k: usize) -> usize {
        let unary = |u: UnaryPlan| u.c_in * u.c_out + 2 * u.c_out;
        let mut n = 0;
        for b in &self.blocks {
            match b.kind {
                BlockKind::Simple => n += k * b.c_in * (b.c_out / 2) + 2 * (b.c_out / 2),
                _ => {
                    let mid = b.c_out / 4;
                    if b.c_in != mid {
                        n += unary(UnaryPlan { c_in: b.c_in, c_out: mid });
                    }
                    n += k * mid * mid + 2 * mid;
                    n += unary(UnaryPlan { c_in: mid, c_out: b.c_out });
                    if b.c_in != b.c_out {
                        n += unary(UnaryPlan { c_in: b.c_in, c_out: b.c_out });
                    }
                }
            }
        }
        n + self.decoder.iter().map(|&u| unary(u)).sum::<usize>() + unary(self.head)
    }
}

/// Everything geometric the network needs for one cloud, computed once and reusable.
#[derive(Clone, Debug)]
pub struct PointPyramid {
    /// Points per level; level 0 is the input cloud in input order, or its voxels'
    /// barycentres with [`KpfcnnConfig::input_cell`] (either scaled when
    /// [`KpfcnnConfig::spacing_cells`] is set).
    pub points: Vec<Vec<[f32; 3]>>,
    /// Cell per level (level 0 nominal).
    pub cells: Vec<f32>,
    /// Same-level neighbourhoods (radius `conv_radius · cell`), per level.
    pub conv: Vec<Neighborhoods>,
    /// Pooling neighbourhoods: queries level l + 1, support level l, radius of level l.
    pub pool: Vec<Neighborhoods>,
    /// For each level-l point, its nearest level-(l + 1) point (for nearest upsampling).
    pub upsample: Vec<Arc<[u32]>>,
    /// With [`KpfcnnConfig::input_cell`]: for each input point, its level-0 point (the
    /// barycentre of its voxel), whose features it reads; `None` when level 0 is the
    /// input cloud.
    pub input_voxel: Option<Arc<[u32]>>,
}

/// Builds the pyramid of `points` for `cfg`: grid subsampling, radius neighbourhoods capped per
/// `cfg.neighbor_cap`, pooling neighbourhoods and upsampling indices. With
/// `cfg.spacing_cells > 0` the cloud is first scaled about the origin so that its median
/// nearest-neighbour distance ([`median_spacing`]) is `spacing_cells · first_cell`; a cloud
/// with no two distinct points is left as it is. With `cfg.input_cell > 0` the (scaled)
/// cloud is then grid-subsampled with cell `input_cell · first_cell` and the pyramid built
/// on the voxels' barycentres ([`PointPyramid::input_voxel`] maps the points to them).
///
/// # Errors
/// `InvalidInput` for an empty cloud, a non-finite coordinate (named by index) or a bad config.
pub fn prepare(points: &[[f32; 3]], cfg: &KpfcnnConfig) -> Result<PointPyramid> {
    cfg.validate()?;
    let n_levels = cfg.num_levels();
    let scaled: Vec<[f32; 3]>;
    let spacing = if cfg.spacing_cells > 0.0 { median_spacing(points) } else { None };
    let points = match spacing {
        Some(d) => {
            let f = cfg.spacing_cells * cfg.first_cell / d;
            if !f.is_finite() {
                return Err(Error::invalid(format!("KPFCNN: cannot scale a cloud of spacing {d} to cells")));
            }
            scaled = points.iter().map(|p| [p[0] * f, p[1] * f, p[2] * f]).collect();
            &scaled[..]
        }
        None => points,
    };
    let mut input_voxel = None;
    let voxels;
    let points = if cfg.input_cell > 0.0 {
        let v = grid_subsample(points, None, cfg.input_cell * cfg.first_cell)?;
        input_voxel = Some(Arc::from(v.cluster));
        voxels = v.points;
        &voxels[..]
    } else {
        points
    };
    let sub = subsample_pyramid(points, cfg.first_cell, n_levels)?;
    let trees: Vec<KdTree> = sub.levels.iter().map(|l| KdTree::build(l)).collect();
    let mut conv = Vec::with_capacity(n_levels);
    let mut pool = Vec::with_capacity(n_levels - 1);
    let mut upsample = Vec::with_capacity(n_levels - 1);
    for l in 0..n_levels {
        let radius = cfg.conv_radius * sub.cells[l];
        conv.push(radius_neighborhoods(&trees[l], &sub.levels[l], radius, cfg.neighbor_cap)?);
        if l + 1 < n_levels {
            pool.push(radius_neighborhoods(&trees[l], &sub.levels[l + 1], radius, cfg.neighbor_cap)?);
            upsample.push(nearest_upsampling(&trees[l + 1], &sub.levels[l])?.into());
        }
    }
    Ok(PointPyramid { points: sub.levels, cells: sub.cells, conv, pool, upsample, input_voxel })
}

/// The median, over the points that have one, of the distance to the nearest *other*
/// point at a positive distance (duplicates skipped; among each point's 8 nearest).
/// `None` for a cloud with no such pair, or when `points` holds a non-finite coordinate.
pub fn median_spacing(points: &[[f32; 3]]) -> Option<f32> {
    if points.len() < 2 || points.iter().any(|p| !p.iter().all(|c| c.is_finite())) {
        return None;
    }
    let tree = KdTree::build(points);
    let table = tree.knn_batch(points, 8);
    let mut d: Vec<f32> = (0..points.len())
        .filter_map(|i| table.row(i).1.iter().copied().find(|&d2| d2 > 0.0 && d2.is_finite()))
        .collect();
    if d.is_empty() {
        return None;
    }
    let mid = d.len() / 2;
    let (_, m, _) = d.select_nth_unstable_by(mid, f32::total_cmp);
    Some(m.sqrt())
}

impl PointPyramid {
    /// Number of levels.
    pub fn num_levels(&self) -> usize {
        self.points.len()
    }

    /// Number of input points: the rows of the network's output (level 0's points, or,
    /// with [`KpfcnnConfig::input_cell`], the points read from level 0's voxels).
    pub fn num_inputs(&self) -> usize {
        self.input_voxel.as_ref().map_or(self.points[0].len(), |v| v.len())
    }

    /// The input feature tensor `[N × C]` for `input`.
    ///
    /// # Errors
    /// Never in practice (shapes are consistent by construction); kept for the tensor constructor.
    pub fn input_features(&self, input: InputFeatures) -> Result<Tensor> {
        let pts = &self.points[0];
        let data: Vec<f32> = match input {
            InputFeatures::Ones => vec![1.0; pts.len()],
            InputFeatures::OnesXyz => pts.iter().flat_map(|p| [1.0, p[0], p[1], p[2]]).collect(),
        };
        Tensor::new(&[pts.len(), input.dim()], data)
    }
}

/// A KPConv's weights `[K × C_in × C_out]` and its kernel points (scaled to the radius).
/// The kernel points are also a buffer of the store (`kp`, `[K × 3]`), so a checkpoint
/// carries the exact points the weights were trained with (see
/// [`Kpfcnn::load_kernel_points`]); `kernel` is the copy the geometry reads.
#[derive(Clone, Debug)]
struct Conv {
    w: ParamId,
    kp: ParamId,
    kernel: Arc<Vec<[f32; 3]>>,
}

/// A ResNet bottleneck block's layers.
#[derive(Clone, Debug)]
struct ResBlock {
    unary1: Option<ConvBnAct>,
    conv: Conv,
    bn: BatchNorm1d,
    unary2: ConvBnAct,
    shortcut: Option<ConvBnAct>,
    level: usize,
    strided: bool,
}

#[derive(Clone, Debug)]
enum Block {
    Simple { conv: Conv, bn: BatchNorm1d, level: usize },
    Resnetb(Box<ResBlock>),
}

/// The network: parameter ids into a [`ParamStore`] plus fixed kernel points.
#[derive(Clone, Debug)]
pub struct Kpfcnn {
    cfg: KpfcnnConfig,
    blocks: Vec<Block>,
    decoder: Vec<ConvBnAct>,
    head: ConvBnAct,
}

struct Builder<'a> {
    params: &'a mut ParamStore,
    rng: Rng,
    cfg: &'a KpfcnnConfig,
    n_convs: u64,
}

impl Builder<'_> {
    fn bn_config(&self) -> BatchNormConfig {
        BatchNormConfig { eps: self.cfg.bn_eps, momentum: self.cfg.bn_momentum }
    }

    /// The tensor engine's fused unary (conv1d without bias + BN + activation, PyTorch init).
    fn unary(&mut self, name: &str, c_in: usize, c_out: usize, act: Act) -> Result<ConvBnAct> {
        let bn = self.bn_config();
        ConvBnAct::new(self.params, name, c_in, c_out, act, bn, &mut self.rng)
    }

    fn bn(&mut self, name: &str, c: usize) -> Result<BatchNorm1d> {
        let bn = self.bn_config();
        BatchNorm1d::new(self.params, name, c, bn)
    }

    fn conv(&mut self, name: &str, level: usize, c_in: usize, c_out: usize) -> Result<Conv> {
        // Uniform ±1/√(K·C_in): output variance independent of width before batch norm.
        let k = self.cfg.num_kernel_points;
        let bound = 1.0 / ((k * c_in) as f32).sqrt();
        let data = (0..k * c_in * c_out).map(|_| (self.rng.f32() * 2.0 - 1.0) * bound).collect();
        let w = self.params.add(
            &format!("{name}.weight"),
            ParamKind::Trainable,
            Tensor::new(&[k, c_in, c_out], data)?,
        )?;
        let radius = self.cfg.conv_radius * self.cfg.cell(level);
        let seed = self.cfg.seed.wrapping_mul(0x9E37_79B9).wrapping_add(self.n_convs);
        self.n_convs += 1;
        let kernel = scaled_kernel_points(k, seed, radius)?;
        let kp = self.params.add(
            &format!("{name}.kernel_points"),
            ParamKind::Buffer,
            Tensor::new(&[k, 3], kernel.iter().flatten().copied().collect())?,
        )?;
        Ok(Conv { w, kp, kernel: Arc::new(kernel) })
    }
}

impl Kpfcnn {
    /// Creates the network's parameters in `params` (names prefixed `kpfcnn.`).
    ///
    /// # Errors
    /// `InvalidInput` for a bad config or when a parameter name is already taken in `params`.
    pub fn new(cfg: &KpfcnnConfig, params: &mut ParamStore) -> Result<Self> {
        cfg.validate()?;
        let p = plan(cfg);
        let leaky = Act::LeakyRelu(cfg.leaky_slope);
        let mut b = Builder { params, rng: Rng::new(cfg.seed), cfg, n_convs: 0 };
        let mut blocks = Vec::with_capacity(p.blocks.len());
        for (i, bp) in p.blocks.iter().enumerate() {
            let name = format!("kpfcnn.enc{i}");
            blocks.push(match bp.kind {
                BlockKind::Simple => {
                    let conv = b.conv(&format!("{name}.kpconv"), bp.level, bp.c_in, bp.c_out / 2)?;
                    let bn = b.bn(&format!("{name}.bn"), bp.c_out / 2)?;
                    Block::Simple { conv, bn, level: bp.level }
                }
                kind => {
                    let mid = bp.c_out / 4;
                    let unary1 = if bp.c_in != mid {
                        Some(b.unary(&format!("{name}.unary1"), bp.c_in, mid, leaky)?)
                    } else {
                        None
                    };
                    let conv = b.conv(&format!("{name}.kpconv"), bp.level, mid, mid)?;
                    let bn = b.bn(&format!("{name}.bn"), mid)?;
                    let unary2 = b.unary(&format!("{name}.unary2"), mid, bp.c_out, Act::Identity)?;
                    let shortcut = if bp.c_in != bp.c_out {
                        Some(b.unary(&format!("{name}.shortcut"), bp.c_in, bp.c_out, Act::Identity)?)
                    } else {
                        None
                    };
                    Block::Resnetb(Box::new(ResBlock {
                        unary1,
                        conv,
                        bn,
                        unary2,
                        shortcut,
                        level: bp.level,
                        strided: kind == BlockKind::ResnetbStrided,
                    }))
                }
            });
        }
        let mut decoder = Vec::with_capacity(p.decoder.len());
        for (i, u) in p.decoder.iter().enumerate() {
            decoder.push(b.unary(&format!("kpfcnn.dec{i}"), u.c_in, u.c_out, leaky)?);
        }
        let head = b.unary("kpfcnn.head", p.head.c_in, p.head.c_out, leaky)?;
        Ok(Kpfcnn { cfg: cfg.clone(), blocks, decoder, head })
    }

    /// The configuration.
    pub fn config(&self) -> &KpfcnnConfig {
        &self.cfg
    }

    /// Re-reads every KPConv's kernel points from their buffers in `params`
    /// (`kpfcnn.enc<i>.kpconv.kernel_points`, `[K × 3]`). Call it after loading a
    /// checkpoint into `params`: the network then uses the points stored with the weights,
    /// not the ones [`Kpfcnn::new`] regenerated from the seed (which would differ if the
    /// placement code or the platform's `sin`/`cos` ever changed).
    ///
    /// # Errors
    /// `InvalidInput` when a buffer has the wrong shape or a non-finite coordinate.
    pub fn load_kernel_points(&mut self, params: &ParamStore) -> Result<()> {
        let k = self.cfg.num_kernel_points;
        for (i, block) in self.blocks.iter_mut().enumerate() {
            let conv = match block {
                Block::Simple { conv, .. } => conv,
                Block::Resnetb(r) => &mut r.conv,
            };
            let t = params.get(conv.kp);
            if t.dims() != [k, 3] {
                return Err(Error::invalid(format!(
                    "'{}' is {}, expected [{k}, 3]",
                    params.name(conv.kp),
                    t.shape()
                )));
            }
            if let Some(j) = t.data().iter().position(|x| !x.is_finite()) {
                return Err(Error::invalid(format!(
                    "'{}' (block {i}): kernel point {} is not finite",
                    params.name(conv.kp),
                    j / 3
                )));
            }
            conv.kernel = Arc::new(t.data().chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect());
        }
        Ok(())
    }

    /// The KPConv layers' parameters in execution order.
    fn convs(&self) -> impl Iterator<Item = (&Conv, usize, bool)> {
        self.blocks.iter().map(|b| match b {
            Block::Simple { conv, level, .. } => (conv, *level, false),
            Block::Resnetb(r) => (&r.conv, r.level, r.strided),
        })
    }

    fn geometry(
        &self,
        conv: &Conv,
        pyr: &PointPyramid,
        level: usize,
        strided: bool,
    ) -> Result<KpConvGeometry> {
        let (queries, nb) = if strided {
            (&pyr.points[level + 1], &pyr.pool[level])
        } else {
            (&pyr.points[level], &pyr.conv[level])
        };
        let sigma = self.cfg.kp_extent * pyr.cells[level];
        KpConvGeometry::new(queries, &pyr.points[level], &nb.indices, nb.cap, &conv.kernel, sigma)
    }

    /// The kernel influences of every KPConv layer on the cloud of `pyr` (they depend only on
    /// geometry and the fixed kernel points). Keep them with the pyramid and pass them to
    /// [`Kpfcnn::forward_with`] to skip recomputing them each epoch; they cost about
    /// 12 bytes × (non-zero influences), e.g. ~9 MB per level-0 layer for 10,000 points.
    ///
    /// # Errors
    /// As [`Kpfcnn::forward`].
    pub fn geometries(&self, pyr: &PointPyramid) -> Result<Vec<Arc<KpConvGeometry>>> {
        self.check_pyramid(pyr)?;
        self.convs()
            .map(|(conv, level, strided)| Ok(Arc::new(self.geometry(conv, pyr, level, strided)?)))
            .collect()
    }

    fn check_pyramid(&self, pyr: &PointPyramid) -> Result<()> {
        if pyr.num_levels() != self.cfg.num_levels() {
            return Err(Error::invalid(format!(
                "pyramid has {} levels, the network needs {}",
                pyr.num_levels(),
                self.cfg.num_levels()
            )));
        }
        Ok(())
    }

    /// Records the network on `g` for the cloud of `pyr` and returns its `[N × out_dim]` features
    /// (rows in input order), computing the KPConv influences on the fly.
    /// Train/eval behaviour (batch statistics) follows the graph's mode; in a non-recording
    /// (eval) graph, intermediates are freed as soon as they are consumed.
    ///
    /// # Errors
    /// `InvalidInput` when `pyr` has a different number of levels than the config implies;
    /// `Shape` from batch norm in train mode when a level has fewer than 2 points.
    pub fn forward(&self, g: &mut Graph, pyr: &PointPyramid) -> Result<Var> {
        self.forward_impl(g, pyr, None)
    }

    /// [`Kpfcnn::forward`] with influences precomputed by [`Kpfcnn::geometries`] for this pyramid.
    ///
    /// # Errors
    /// As [`Kpfcnn::forward`]; `InvalidInput` when `geoms` does not match the network's layers.
    pub fn forward_with(
        &self,
        g: &mut Graph,
        pyr: &PointPyramid,
        geoms: &[Arc<KpConvGeometry>],
    ) -> Result<Var> {
        let n = self.convs().count();
        let ok = geoms.len() == n
            && self.convs().zip(geoms).all(|((_, level, strided), geo)| {
                let q = if strided { pyr.points.get(level + 1) } else { pyr.points.get(level) };
                q.map(|q| q.len()) == Some(geo.n_queries)
                    && pyr.points.get(level).map(|s| s.len()) == Some(geo.n_support)
            });
        if !ok {
            return Err(Error::invalid(format!(
                "{} precomputed geometries do not match this network's {n} KPConv layers and pyramid",
                geoms.len()
            )));
        }
        self.forward_impl(g, pyr, Some(geoms))
    }

    fn forward_impl(
        &self,
        g: &mut Graph,
        pyr: &PointPyramid,
        geoms: Option<&[Arc<KpConvGeometry>]>,
    ) -> Result<Var> {
        self.check_pyramid(pyr)?;
        let mut layer = 0usize;
        let mut kpconv = |g: &mut Graph, x: Var, conv: &Conv, level: usize, strided: bool| -> Result<Var> {
            let geom = match geoms {
                Some(gs) => gs[layer].clone(),
                None => Arc::new(self.geometry(conv, pyr, level, strided)?),
            };
            layer += 1;
            let w = g.param(conv.w);
            g.custom(Box::new(KpConvOp::new(geom)), &[x, w])
        };
        let leaky = Act::LeakyRelu(self.cfg.leaky_slope);
        let mut x = g.input(pyr.input_features(self.cfg.input)?);
        let mut skips = Vec::new();
        for block in &self.blocks {
            x = match block {
                Block::Simple { conv, bn, level } => {
                    let y = kpconv(g, x, conv, *level, false)?;
                    g.free(x);
                    let z = bn.forward_act(g, y, leaky)?;
                    g.free(y);
                    z
                }
                Block::Resnetb(r) => {
                    let ResBlock { unary1, conv, bn, unary2, shortcut, level, strided } = r.as_ref();
                    if *strided {
                        skips.push(x);
                    }
                    let h1 = match unary1 {
                        Some(u) => u.forward(g, x)?,
                        None => x,
                    };
                    let h2 = kpconv(g, h1, conv, *level, *strided)?;
                    if h1 != x {
                        g.free(h1);
                    }
                    let h3 = bn.forward_act(g, h2, leaky)?;
                    g.free(h2);
                    let h4 = unary2.forward(g, h3)?;
                    g.free(h3);
                    let pooled = if *strided {
                        let nb = &pyr.pool[*level];
                        g.max_neighbors(x, &nb.indices, nb.cap)?
                    } else {
                        x
                    };
                    let sc = match shortcut {
                        Some(u) => u.forward(g, pooled)?,
                        None => pooled,
                    };
                    let s = g.add(h4, sc)?;
                    g.free(h4);
                    // The block input stays alive only when it is a skip link.
                    for v in [sc, pooled, x] {
                        if !skips.contains(&v) {
                            g.free(v);
                        }
                    }
                    let out = g.leaky_relu(s, self.cfg.leaky_slope)?;
                    g.free(s);
                    out
                }
            };
        }
        for (i, u) in self.decoder.iter().enumerate() {
            let level = self.decoder.len() - 1 - i;
            let up = g.gather_rows(x, pyr.upsample[level].clone(), false)?;
            g.free(x);
            let skip = skips.pop().expect("internal error: one skip per strided block");
            let cat = g.concat_cols(&[up, skip])?;
            g.free(up);
            g.free(skip);
            x = u.forward(g, cat)?;
            g.free(cat);
        }
        let out = self.head.forward(g, x)?;
        g.free(x);
        match &pyr.input_voxel {
            // Each input point reads its voxel's row.
            Some(voxel) => {
                let rows = g.gather_rows(out, voxel.clone(), false)?;
                g.free(out);
                Ok(rows)
            }
            None => Ok(out),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paper_preset_counts_24_4m_parameters() {
        let cfg = KpfcnnConfig::paper();
        assert_eq!(cfg.num_levels(), 5);
        assert_eq!(cfg.param_count(), 24_364_224);
        let d = KpfcnnConfig::default_preset();
        let mut ps = ParamStore::new();
        Kpfcnn::new(&d, &mut ps).unwrap();
        assert_eq!(ps.num_trainable(), d.param_count());
    }

    #[test]
    fn bad_configs_are_errors() {
        let mut c = KpfcnnConfig::default_preset();
        c.first_features_dim = 6;
        assert!(c.validate().is_err());
        let mut c = KpfcnnConfig::default_preset();
        c.blocks.insert(1, BlockKind::Simple);
        assert!(c.validate().is_err());
        let mut c = KpfcnnConfig::default_preset();
        c.first_cell = f32::NAN;
        assert!(prepare(&[[0.0; 3]], &c).is_err());
        assert!(prepare(&[], &KpfcnnConfig::default_preset()).is_err());
    }
}
