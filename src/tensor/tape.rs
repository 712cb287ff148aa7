//! The Wengert tape: a [`Graph`] records every op in execution order as a node holding
//! its value and its [`Op`]; `backward` walks the nodes in reverse and applies one
//! exhaustive `match` of gradient rules, accumulating (`+=`) into input gradients and,
//! at parameter leaves, into a [`Grads`].
//!
//! Modes: [`Graph::train`] records and normalises batch norm with batch statistics
//! (updating the running ones); [`Graph::eval`] records nothing (no op, no saved
//! buffer: "no_grad") and uses running statistics; [`Graph::new`] picks each flag.
//! In a non-recording graph [`Graph::free`] drops a value as soon as the caller no
//! longer needs it, so inference keeps only live activations.

use super::conv_bn;
use super::gemm;
use super::op::{Act, ConvBnSaved, CustomOp, Op};
use super::params::{Grads, ParamId, ParamKind, ParamStore};
use super::shape::Shape;
use super::tensor::Tensor;
use crate::{Error, Result};
use std::sync::Arc;

/// A value on the tape (an index into the graph's nodes). Only meaningful for the
/// graph that returned it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Var(pub(crate) usize);

enum Value {
    Owned(Tensor),
    Param(ParamId),
    Freed,
}

struct Node {
    value: Value,
    op: Op,
    needs_grad: bool,
    param: Option<ParamId>,
}

/// References to the batch-norm tensors of one layer, for [`Graph::conv_bn_act`].
#[derive(Clone, Copy, Debug)]
pub struct BnRefs {
    /// Running mean buffer `[C]`.
    pub running_mean: ParamId,
    /// Running variance buffer `[C]`.
    pub running_var: ParamId,
    /// Added to the variance before the square root.
    pub eps: f32,
    /// PyTorch convention: `running = (1 − momentum)·running + momentum·batch`.
    pub momentum: f32,
}

/// How a graph holds the parameter store: mutably (train mode updates batch-norm
/// running statistics) or shared (inference on a model others may read too).
enum Store<'p> {
    Mut(&'p mut ParamStore),
    Shared(&'p ParamStore),
}

impl std::ops::Deref for Store<'_> {
    type Target = ParamStore;
    fn deref(&self) -> &ParamStore {
        match self {
            Store::Mut(p) => p,
            Store::Shared(p) => p,
        }
    }
}

impl std::ops::DerefMut for Store<'_> {
    fn deref_mut(&mut self) -> &mut ParamStore {
        match self {
            Store::Mut(p) => p,
            // Only `Graph::eval_shared` builds a shared store, and it is never in train
            // mode, the one place that writes to the store.
            Store::Shared(_) => unreachable!("internal error: a shared-store graph wrote to its parameters"),
        }
    }
}

/// The tape, borrowing the parameter store for its lifetime.
pub struct Graph<'p> {
    params: Store<'p>,
    nodes: Vec<Node>,
    record: bool,
    train: bool,
    /// Outside train mode: batch norm reads the batch's own statistics (≥ 2 rows)
    /// instead of the running ones, and updates nothing ([`Graph::with_batch_stats`]).
    batch_stats: bool,
    /// `Some` when asked ([`Graph::capturing_stats`]): the statistics each batch-norm
    /// block normalised with, in execution order.
    captured: Option<Vec<BnStats>>,
    spent: bool,
}

/// The statistics one batch-norm block normalised a batch with: the mean and the biased
/// variance of its input columns, with the ids of the block's running buffers (what
/// reads the same statistics back as running ones). See [`Graph::capturing_stats`].
#[derive(Clone, Debug, PartialEq)]
pub struct BnStats {
    /// The block's `running_mean` buffer.
    pub running_mean: ParamId,
    /// The block's `running_var` buffer.
    pub running_var: ParamId,
    /// Column means of the batch.
    pub mean: Vec<f32>,
    /// Column variances of the batch (biased: divided by the row count).
    pub var: Vec<f32>,
}

fn shape_err(op: &'static str, msg: String) -> Error {
    Error::Shape { op, msg }
}

#[derive(Clone, Copy, PartialEq, Debug)]
enum Bc {
    Full,
    Row,
    Col,
    One,
}

#[inline]
fn bi(bc: Bc, r: usize, c: usize, cols: usize) -> usize {
    match bc {
        Bc::Full => r * cols + c,
        Bc::Row => c,
        Bc::Col => r,
        Bc::One => 0,
    }
}

fn classify(t: Shape, rows: usize, cols: usize) -> Option<Bc> {
    if t.rows() == rows && t.cols() == cols {
        Some(Bc::Full)
    } else if t.numel() == 1 {
        Some(Bc::One)
    } else if t.rows() == 1 && t.cols() == cols {
        Some(Bc::Row)
    } else if t.rows() == rows && t.cols() == 1 {
        Some(Bc::Col)
    } else {
        None
    }
}

fn broadcast(op: &'static str, a: Shape, b: Shape) -> Result<(Shape, Bc, Bc)> {
    let out = if b.numel() > a.numel() { b } else { a };
    match (classify(a, out.rows(), out.cols()), classify(b, out.rows(), out.cols())) {
        (Some(x), Some(y)) => Ok((out, x, y)),
        _ => Err(shape_err(op, format!("cannot broadcast {a} with {b} (same, [1×C], [R×1] or one element)"))),
    }
}

/// Adds `f(flat, r, c)` for every output element into `dst`, summing over broadcast dims.
fn acc_reduce(dst: &mut [f32], bc: Bc, rows: usize, cols: usize, f: impl Fn(usize, usize, usize) -> f32) {
    // Row-major loops with the broadcast kind matched once (no division per element).
    match bc {
        Bc::Full => {
            for r in 0..rows {
                let d = &mut dst[r * cols..(r + 1) * cols];
                for (c, x) in d.iter_mut().enumerate() {
                    *x += f(r * cols + c, r, c);
                }
            }
        }
        Bc::Row => {
            for r in 0..rows {
                for (c, x) in dst[..cols].iter_mut().enumerate() {
                    *x += f(r * cols + c, r, c);
                }
            }
        }
        Bc::Col => {
            for (r, x) in dst[..rows].iter_mut().enumerate() {
                for c in 0..cols {
                    *x += f(r * cols + c, r, c);
                }
            }
        }
        Bc::One => {
            for r in 0..rows {
                for c in 0..cols {
                    dst[0] += f(r * cols + c, r, c);
                }
            }
        }
    }
}

fn grad_slot(grads: &mut [Option<Tensor>], v: Var, shape: Shape) -> &mut Tensor {
    grads[v.0].get_or_insert_with(|| Tensor::zeros_like_shape(shape))
}

impl<'p> Graph<'p> {
    /// A graph over `params`. `record`: keep ops for `backward`; `train`: batch norm
    /// uses (and updates) batch statistics, dropout is active.
    pub fn new(params: &'p mut ParamStore, record: bool, train: bool) -> Graph<'p> {
        Graph {
            params: Store::Mut(params),
            nodes: Vec::new(),
            record,
            train,
            batch_stats: false,
            captured: None,
            spent: false,
        }
    }

    /// Training graph: records, batch statistics.
    pub fn train(params: &'p mut ParamStore) -> Graph<'p> {
        Graph::new(params, true, true)
    }

    /// Inference graph ("no_grad"): records nothing, running statistics.
    pub fn eval(params: &'p mut ParamStore) -> Graph<'p> {
        Graph::new(params, false, false)
    }

    /// Inference graph over a shared store: like [`Graph::eval`], for a model that is
    /// only borrowed (`reconstruct(&Model)`), or used from several threads at once.
    pub fn eval_shared(params: &'p ParamStore) -> Graph<'p> {
        Graph {
            params: Store::Shared(params),
            nodes: Vec::new(),
            record: false,
            train: false,
            batch_stats: false,
            captured: None,
            spent: false,
        }
    }

    /// Outside train mode, batch norm normalises with the statistics of the rows it is
    /// given (when there are at least 2; one row reads the running statistics) instead
    /// of the running averages, and leaves the running averages alone. For a model whose
    /// batch norm is meant to be read per cloud
    /// ([`crate::pipeline::model::ModelConfig::cloud_batch_stats`]). The result then
    /// depends on which rows share a graph. In train mode batch statistics are used
    /// anyway; this changes nothing there.
    pub fn with_batch_stats(mut self, on: bool) -> Graph<'p> {
        self.batch_stats = on;
        self
    }

    /// Keeps the statistics of every batch-norm block that normalises with batch
    /// statistics (train mode, or [`Graph::with_batch_stats`] with ≥ 2 rows), in
    /// execution order ([`Graph::captured_stats`]). Writing them into a copy of the
    /// running buffers makes an ordinary inference graph normalise any rows as this
    /// batch was: how a large cloud is scored in chunks with statistics taken from a
    /// sample of its candidates.
    pub fn capturing_stats(mut self) -> Graph<'p> {
        self.captured = Some(Vec::new());
        self
    }

    /// The statistics kept since [`Graph::capturing_stats`] (empty without it).
    pub fn captured_stats(&self) -> &[BnStats] {
        self.captured.as_deref().unwrap_or(&[])
    }

    /// True when ops are recorded for `backward`.
    pub fn is_recording(&self) -> bool {
        self.record
    }

    /// True in train mode (batch statistics, dropout on).
    pub fn is_train(&self) -> bool {
        self.train
    }

    /// The parameter store.
    pub fn params(&self) -> &ParamStore {
        &self.params
    }

    /// Number of nodes on the tape.
    pub fn len(&self) -> usize {
        self.nodes.len()
    }

    /// True when nothing was pushed yet.
    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }

    /// A constant input (no gradient).
    pub fn input(&mut self, t: Tensor) -> Var {
        self.nodes.push(Node { value: Value::Owned(t), op: Op::Leaf, needs_grad: false, param: None });
        Var(self.nodes.len() - 1)
    }

    /// The parameter `id` as a leaf; it receives a gradient when the graph records
    /// and the parameter is trainable. Its value is read from the store, not copied.
    pub fn param(&mut self, id: ParamId) -> Var {
        let needs = self.record && self.params.kind(id) == ParamKind::Trainable;
        self.nodes.push(Node { value: Value::Param(id), op: Op::Leaf, needs_grad: needs, param: Some(id) });
        Var(self.nodes.len() - 1)
    }

    /// The value of `v`.
    ///
    /// # Panics
    /// When `v` was freed with [`Graph::free`] or comes from another graph.
    pub fn value(&self, v: Var) -> &Tensor {
        match &self.nodes[v.0].value {
            Value::Owned(t) => t,
            Value::Param(id) => self.params.get(*id),
            Value::Freed => panic!("Graph::value: node {} was freed", v.0),
        }
    }

    /// Moves the value of `v` out (it is freed on the tape). Parameters are cloned.
    ///
    /// # Errors
    /// `Error::InvalidInput` when the value was already freed, or the graph records
    /// and the value may still be needed by `backward`.
    pub fn take(&mut self, v: Var) -> Result<Tensor> {
        if self.record && self.nodes[v.0].needs_grad {
            return Err(Error::invalid("Graph::take on a recorded value that backward may need"));
        }
        match std::mem::replace(&mut self.nodes[v.0].value, Value::Freed) {
            Value::Owned(t) => Ok(t),
            Value::Param(id) => {
                self.nodes[v.0].value = Value::Param(id);
                Ok(self.params.get(id).clone())
            }
            Value::Freed => Err(Error::invalid(format!("Graph::take: node {} already freed", v.0))),
        }
    }

    /// Drops the value of `v` when the graph does not record (inference keeps only
    /// live buffers). In a recording graph this does nothing (backward needs values).
    pub fn free(&mut self, v: Var) {
        if !self.record {
            if let Value::Owned(_) = self.nodes[v.0].value {
                self.nodes[v.0].value = Value::Freed;
            }
        }
    }

    fn check_live(&self, op: &'static str, vars: &[Var]) -> Result<()> {
        for v in vars {
            if v.0 >= self.nodes.len() {
                return Err(shape_err(op, format!("variable {} is not on this tape", v.0)));
            }
            if let Value::Freed = self.nodes[v.0].value {
                return Err(shape_err(op, format!("variable {} was freed", v.0)));
            }
        }
        Ok(())
    }

    fn wants_grad(&self, vars: &[Var]) -> bool {
        self.record && vars.iter().any(|v| self.nodes[v.0].needs_grad)
    }

    fn push(&mut self, value: Tensor, op: Op) -> Var {
        let needs = self.wants_grad(&op.inputs());
        let op = if needs { op } else { Op::Leaf };
        self.nodes.push(Node { value: Value::Owned(value), op, needs_grad: needs, param: None });
        Var(self.nodes.len() - 1)
    }

    // ---------------------------------------------------------------- ops

    /// Matrix product `a · b` of 2-D views: `[M × K] · [K × N] → [M × N]`.
    ///
    /// # Errors
    /// `Error::Shape` when the inner dimensions differ or a rank is not 2.
    pub fn matmul(&mut self, a: Var, b: Var) -> Result<Var> {
        self.matmul_impl(a, b, false)
    }

    /// `a · bᵀ`: `[M × K] · [N × K]ᵀ → [M × N]` (a linear layer with weight `[out × in]`).
    ///
    /// # Errors
    /// `Error::Shape` when the inner dimensions differ or a rank is not 2.
    pub fn matmul_t(&mut self, a: Var, b: Var) -> Result<Var> {
        self.matmul_impl(a, b, true)
    }

    fn matmul_impl(&mut self, a: Var, b: Var, trans_b: bool) -> Result<Var> {
        self.check_live("matmul", &[a, b])?;
        let (ta, tb) = (self.value(a), self.value(b));
        if ta.shape().rank() != 2 || tb.shape().rank() != 2 {
            return Err(shape_err(
                "matmul",
                format!("needs 2-D operands, got {} and {}", ta.shape(), tb.shape()),
            ));
        }
        let (m, k) = (ta.dims()[0], ta.dims()[1]);
        let (k2, n) = if trans_b { (tb.dims()[1], tb.dims()[0]) } else { (tb.dims()[0], tb.dims()[1]) };
        if k != k2 {
            return Err(shape_err(
                "matmul",
                format!("{} · {}{}", ta.shape(), tb.shape(), if trans_b { "ᵀ" } else { "" }),
            ));
        }
        let mut out = vec![0.0f32; m * n];
        gemm::gemm_rows(m, n, k, ta.data(), false, tb.data(), trans_b, &mut out, 0.0);
        let t = Tensor::new(&[m, n], out)?;
        Ok(self.push(t, Op::MatMul { a, b, trans_b }))
    }

    fn binary(
        &mut self,
        name: &'static str,
        a: Var,
        b: Var,
        f: impl Fn(f32, f32) -> f32,
    ) -> Result<(Tensor, ())> {
        self.check_live(name, &[a, b])?;
        let (ta, tb) = (self.value(a), self.value(b));
        let (shape, ca, cb) = broadcast(name, ta.shape(), tb.shape())?;
        let (rows, cols) = (shape.rows(), shape.cols());
        let (ad, bd) = (ta.data(), tb.data());
        let mut out = vec![0.0f32; shape.numel()];
        if ca == Bc::Full && cb == Bc::Full {
            for ((o, &x), &y) in out.iter_mut().zip(ad).zip(bd) {
                *o = f(x, y);
            }
        } else {
            for r in 0..rows {
                for c in 0..cols {
                    out[r * cols + c] = f(ad[bi(ca, r, c, cols)], bd[bi(cb, r, c, cols)]);
                }
            }
        }
        Ok((Tensor::from_shape(shape, out)?, ()))
    }

    /// `a + b`; either side may be broadcast as a row `[1 × C]` (or `[C]`), a column
    /// `[R × 1]` or a single element against the other's `R × C` view.
    ///
    /// # Errors
    /// `Error::Shape` when the shapes do not broadcast.
    pub fn add(&mut self, a: Var, b: Var) -> Result<Var> {
        let (t, ()) = self.binary("add", a, b, |x, y| x + y)?;
        Ok(self.push(t, Op::Add { a, b }))
    }

    /// `a − b`, broadcasting as [`Graph::add`].
    ///
    /// # Errors
    /// `Error::Shape` when the shapes do not broadcast.
    pub fn sub(&mut self, a: Var, b: Var) -> Result<Var> {
        let (t, ()) = self.binary("sub", a, b, |x, y| x - y)?;
        Ok(self.push(t, Op::Sub { a, b }))
    }

    /// `a ⊙ b`, broadcasting as [`Graph::add`].
    ///
    /// # Errors
    /// `Error::Shape` when the shapes do not broadcast.
    pub fn mul(&mut self, a: Var, b: Var) -> Result<Var> {
        let (t, ()) = self.binary("mul", a, b, |x, y| x * y)?;
        Ok(self.push(t, Op::Mul { a, b }))
    }

    /// `a ⊘ b`, broadcasting as [`Graph::add`].
    ///
    /// # Errors
    /// `Error::Shape` when the shapes do not broadcast.
    pub fn div(&mut self, a: Var, b: Var) -> Result<Var> {
        let (t, ()) = self.binary("div", a, b, |x, y| x / y)?;
        Ok(self.push(t, Op::Div { a, b }))
    }

    fn unary(&mut self, name: &'static str, a: Var, f: impl Fn(f32) -> f32) -> Result<Tensor> {
        self.check_live(name, &[a])?;
        let ta = self.value(a);
        let data = ta.data().iter().map(|&x| f(x)).collect();
        Tensor::from_shape(ta.shape(), data)
    }

    /// `s · a`.
    ///
    /// # Errors
    /// `Error::Shape` when `a` was freed.
    pub fn scale(&mut self, a: Var, s: f32) -> Result<Var> {
        let t = self.unary("scale", a, |x| s * x)?;
        Ok(self.push(t, Op::Scale { a, s }))
    }

    /// `a + s`.
    ///
    /// # Errors
    /// `Error::Shape` when `a` was freed.
    pub fn add_scalar(&mut self, a: Var, s: f32) -> Result<Var> {
        let t = self.unary("add_scalar", a, |x| x + s)?;
        Ok(self.push(t, Op::AddScalar { a }))
    }

    /// `exp(a)`.
    ///
    /// # Errors
    /// `Error::Shape` when `a` was freed.
    pub fn exp(&mut self, a: Var) -> Result<Var> {
        let t = self.unary("exp", a, f32::exp)?;
        Ok(self.push(t, Op::Exp { a }))
    }

    /// `ln(a)` (non-positive values give −inf/NaN, as in IEEE arithmetic).
    ///
    /// # Errors
    /// `Error::Shape` when `a` was freed.
    pub fn log(&mut self, a: Var) -> Result<Var> {
        let t = self.unary("log", a, f32::ln)?;
        Ok(self.push(t, Op::Log { a }))
    }

    /// `max(0, a)`.
    ///
    /// # Errors
    /// `Error::Shape` when `a` was freed.
    pub fn relu(&mut self, a: Var) -> Result<Var> {
        let t = self.unary("relu", a, |x| x.max(0.0))?;
        Ok(self.push(t, Op::Relu { a }))
    }

    /// Leaky ReLU: `a` where `a > 0`, `slope · a` elsewhere.
    ///
    /// # Errors
    /// `Error::Shape` when `a` was freed.
    pub fn leaky_relu(&mut self, a: Var, slope: f32) -> Result<Var> {
        let t = self.unary("leaky_relu", a, |x| if x > 0.0 { x } else { slope * x })?;
        Ok(self.push(t, Op::LeakyRelu { a, slope }))
    }

    /// Sum of all elements (a scalar; f64 accumulation).
    ///
    /// # Errors
    /// `Error::Shape` when `a` was freed.
    pub fn sum(&mut self, a: Var) -> Result<Var> {
        self.check_live("sum", &[a])?;
        let s: f64 = self.value(a).data().iter().map(|&x| x as f64).sum();
        Ok(self.push(Tensor::scalar(s as f32), Op::Sum { a }))
    }

    /// Mean of all elements (a scalar; NaN for an empty tensor).
    ///
    /// # Errors
    /// `Error::Shape` when `a` was freed.
    pub fn mean(&mut self, a: Var) -> Result<Var> {
        self.check_live("mean", &[a])?;
        let t = self.value(a);
        let s: f64 = t.data().iter().map(|&x| x as f64).sum();
        Ok(self.push(Tensor::scalar((s / t.len() as f64) as f32), Op::Mean { a }))
    }

    /// Sum over an axis of the 2-D view: `axis = 0` sums rows → `[1 × C]`, `axis = 1`
    /// sums columns → `[R × 1]`.
    ///
    /// # Errors
    /// `Error::Shape` for an axis other than 0 or 1.
    pub fn sum_axis(&mut self, a: Var, axis: usize) -> Result<Var> {
        self.sum_axis_impl(a, axis, false)
    }

    /// Mean over an axis of the 2-D view (see [`Graph::sum_axis`]).
    ///
    /// # Errors
    /// `Error::Shape` for an axis other than 0 or 1.
    pub fn mean_axis(&mut self, a: Var, axis: usize) -> Result<Var> {
        self.sum_axis_impl(a, axis, true)
    }

    fn sum_axis_impl(&mut self, a: Var, axis: usize, mean: bool) -> Result<Var> {
        self.check_live("sum_axis", &[a])?;
        let t = self.value(a);
        let (rows, cols) = (t.rows(), t.cols());
        let d = t.data();
        let out = match axis {
            0 => {
                let mut s = vec![0.0f64; cols];
                for row in d.chunks_exact(cols.max(1)) {
                    for (x, &v) in s.iter_mut().zip(row) {
                        *x += v as f64;
                    }
                }
                let k = if mean { 1.0 / rows as f64 } else { 1.0 };
                Tensor::new(&[1, cols], s.iter().map(|&v| (v * k) as f32).collect())?
            }
            1 => {
                let k = if mean { 1.0 / cols as f64 } else { 1.0 };
                let s = (0..rows)
                    .map(|r| (d[r * cols..(r + 1) * cols].iter().map(|&v| v as f64).sum::<f64>() * k) as f32)
                    .collect();
                Tensor::new(&[rows, 1], s)?
            }
            _ => return Err(shape_err("sum_axis", format!("axis {axis} of a 2-D view"))),
        };
        Ok(self.push(out, Op::SumAxis { a, axis, mean }))
    }

    /// Log-softmax over the last dimension, row by row (max-shifted, stable).
    ///
    /// # Errors
    /// `Error::Shape` when `a` was freed or has no columns.
    pub fn log_softmax(&mut self, a: Var) -> Result<Var> {
        self.check_live("log_softmax", &[a])?;
        let t = self.value(a);
        let cols = t.cols();
        if cols == 0 {
            return Err(shape_err("log_softmax", format!("no columns in {}", t.shape())));
        }
        let mut out = t.data().to_vec();
        for row in out.chunks_exact_mut(cols) {
            let mx = row.iter().fold(f32::NEG_INFINITY, |m, &v| m.max(v));
            let lse = row.iter().map(|&v| ((v - mx) as f64).exp()).sum::<f64>().ln() as f32 + mx;
            row.iter_mut().for_each(|v| *v -= lse);
        }
        let t = Tensor::from_shape(t.shape(), out)?;
        Ok(self.push(t, Op::LogSoftmax { a }))
    }

    /// Rows of `a` (2-D view `[N × C]`) picked by `idx` → `[len(idx) × C]`. With
    /// `padded`, index `N` is allowed and gives a zero row (the "shadow" neighbour).
    ///
    /// # Errors
    /// `Error::Shape` for an index out of range (naming its position).
    pub fn gather_rows(&mut self, a: Var, idx: Arc<[u32]>, padded: bool) -> Result<Var> {
        self.check_live("gather_rows", &[a])?;
        let t = self.value(a);
        let (n, c) = (t.rows(), t.cols());
        let lim = if padded { n } else { n.saturating_sub(1) };
        if let Some(p) = idx.iter().position(|&i| i as usize > lim || (!padded && n == 0)) {
            return Err(shape_err(
                "gather_rows",
                format!(
                    "index {} at position {p} out of range for {n} rows{}",
                    idx[p],
                    if padded { " (+shadow)" } else { "" }
                ),
            ));
        }
        let mut out = vec![0.0f32; idx.len() * c];
        for (orow, &i) in out.chunks_exact_mut(c.max(1)).zip(idx.iter()) {
            if (i as usize) < n {
                orow.copy_from_slice(t.row(i as usize));
            }
        }
        let t = Tensor::new(&[idx.len(), c], out)?;
        Ok(self.push(t, Op::GatherRows { a, idx, padded }))
    }

    /// Concatenation along the last dimension of 2-D views with equal row counts.
    ///
    /// # Errors
    /// `Error::Shape` when the row counts differ or `parts` is empty.
    pub fn concat_cols(&mut self, parts: &[Var]) -> Result<Var> {
        self.check_live("concat_cols", parts)?;
        let Some(&first) = parts.first() else {
            return Err(shape_err("concat_cols", "no parts".into()));
        };
        let rows = self.value(first).rows();
        let mut widths = Vec::with_capacity(parts.len());
        for &p in parts {
            let t = self.value(p);
            if t.rows() != rows {
                return Err(shape_err("concat_cols", format!("{} rows vs {rows} rows", t.rows())));
            }
            widths.push(t.cols());
        }
        let total: usize = widths.iter().sum();
        let mut out = vec![0.0f32; rows * total];
        let mut off = 0;
        for (&p, &w) in parts.iter().zip(&widths) {
            let t = self.value(p);
            for r in 0..rows {
                out[r * total + off..r * total + off + w].copy_from_slice(t.row(r));
            }
            off += w;
        }
        let t = Tensor::new(&[rows, total], out)?;
        Ok(self.push(t, Op::ConcatCols { parts: parts.to_vec() }))
    }

    /// Max over neighbours: `a` is `[N × C]`, `idx` holds `k` source rows per output row
    /// (`len = N_out · k`, index `N` = the zero shadow row); output `[N_out × C]`, each
    /// channel the max over the row's neighbours. `k = 0` gives zeros.
    ///
    /// # Errors
    /// `Error::Shape` when `idx.len()` is not a multiple of `k` or an index exceeds `N`.
    pub fn max_neighbors(&mut self, a: Var, idx: &[u32], k: usize) -> Result<Var> {
        self.check_live("max_neighbors", &[a])?;
        let t = self.value(a);
        let (n, c) = (t.rows(), t.cols());
        if k == 0 && !idx.is_empty() || k > 0 && idx.len() % k != 0 {
            return Err(shape_err(
                "max_neighbors",
                format!("{} indices is not a multiple of k = {k}", idx.len()),
            ));
        }
        if let Some(p) = idx.iter().position(|&i| i as usize > n) {
            return Err(shape_err("max_neighbors", format!("index {} at {p} out of range 0..={n}", idx[p])));
        }
        let n_out = idx.len().checked_div(k).unwrap_or(0);
        let mut out = vec![0.0f32; n_out * c];
        let mut argmax = vec![n as u32; n_out * c];
        let d = t.data();
        for i in 0..n_out {
            let nb = &idx[i * k..(i + 1) * k];
            let (orow, arow) = (&mut out[i * c..(i + 1) * c], &mut argmax[i * c..(i + 1) * c]);
            orow.fill(f32::NEG_INFINITY);
            for &s in nb {
                if (s as usize) < n {
                    let src = &d[s as usize * c..(s as usize + 1) * c];
                    for j in 0..c {
                        if src[j] > orow[j] {
                            orow[j] = src[j];
                            arow[j] = s;
                        }
                    }
                } else {
                    for j in 0..c {
                        if 0.0 > orow[j] {
                            orow[j] = 0.0;
                            arow[j] = s;
                        }
                    }
                }
            }
            // All-NaN rows keep −inf → report 0 with the shadow as source.
            for j in 0..c {
                if orow[j] == f32::NEG_INFINITY && arow[j] == n as u32 {
                    orow[j] = 0.0;
                }
            }
        }
        let t = Tensor::new(&[n_out, c], out)?;
        Ok(self.push(t, Op::MaxNeighbors { a, argmax }))
    }

    /// Same values under `dims` (same element count).
    ///
    /// # Errors
    /// `Error::Shape` when the element counts differ.
    pub fn reshape(&mut self, a: Var, dims: &[usize]) -> Result<Var> {
        self.check_live("reshape", &[a])?;
        let t = self.value(a).clone().reshape(dims)?;
        Ok(self.push(t, Op::Reshape { a }))
    }

    /// Fused conv1d (kernel 1, no bias: the batch norm's shift replaces it) + batch
    /// norm + activation: `act(γ·(x·Wᵀ − μ)/sqrt(σ² + eps) + β)`. `x: [M × C_in]`,
    /// `w: [C_out × C_in]` (`None`: batch norm alone), `gamma`, `beta`: `[C_out]`. In
    /// train mode μ, σ² are the batch's (biased variance) and the running buffers
    /// are updated (`running = (1 − m)·running + m·batch`, unbiased variance, as
    /// PyTorch); otherwise the running statistics are used.
    ///
    /// # Errors
    /// `Error::Shape` on mismatched widths, or fewer than 2 rows in train mode;
    /// `Error::InvalidInput` for a negative leaky slope.
    pub fn conv_bn_act(
        &mut self,
        x: Var,
        w: Option<Var>,
        gamma: Var,
        beta: Var,
        bn: BnRefs,
        act: Act,
    ) -> Result<Var> {
        let mut vars = vec![x, gamma, beta];
        vars.extend(w);
        self.check_live("conv_bn_act", &vars)?;
        if let Act::LeakyRelu(s) = act {
            if s.is_nan() || s < 0.0 {
                return Err(Error::invalid(format!("leaky slope {s} must be ≥ 0 in the fused block")));
            }
        }
        let tx = self.value(x);
        if tx.shape().rank() != 2 {
            return Err(shape_err("conv_bn_act", format!("input must be [M × C], got {}", tx.shape())));
        }
        let (m, cin) = (tx.rows(), tx.cols());
        let cout = match w {
            Some(w) => {
                let tw = self.value(w);
                if tw.shape().rank() != 2 || tw.dims()[1] != cin {
                    return Err(shape_err(
                        "conv_bn_act",
                        format!("weight {} for input {}", tw.shape(), tx.shape()),
                    ));
                }
                tw.dims()[0]
            }
            None => cin,
        };
        for (name, v) in [("gamma", gamma), ("beta", beta)] {
            if self.value(v).len() != cout {
                return Err(shape_err(
                    "conv_bn_act",
                    format!("{name} {} for {cout} channels", self.value(v).shape()),
                ));
            }
        }
        for id in [bn.running_mean, bn.running_var] {
            if self.params.get(id).len() != cout {
                return Err(shape_err(
                    "conv_bn_act",
                    format!("'{}' {} for {cout} channels", self.params.name(id), self.params.get(id).shape()),
                ));
            }
        }
        if self.train && m < 2 {
            return Err(shape_err(
                "conv_bn_act",
                format!("batch norm in train mode needs ≥ 2 rows, got {m}"),
            ));
        }
        let record = self.wants_grad(&vars);
        let wd = w.map(|w| self.value(w).data());
        // Train mode (or batch statistics asked for): z and batch statistics (fused per
        // row block); the running update in train mode only.
        let batch = self.train || (self.batch_stats && m >= 2);
        let (z, mean, invstd) = if batch {
            let (z, mean, var) = conv_bn::linear_stats(tx.data(), m, cin, wd, cout);
            if self.train {
                let mom = bn.momentum;
                let unbias = m as f64 / (m as f64 - 1.0);
                let rm = self.params.get_mut(bn.running_mean).data_mut();
                for (r, &b) in rm.iter_mut().zip(&mean) {
                    *r = (1.0 - mom) * *r + mom * b as f32;
                }
                let rv = self.params.get_mut(bn.running_var).data_mut();
                for (r, &b) in rv.iter_mut().zip(&var) {
                    *r = (1.0 - mom) * *r + mom * (b * unbias) as f32;
                }
            }
            let eps = bn.eps as f64;
            let invstd = var.iter().map(|&v| (1.0 / (v + eps).sqrt()) as f32).collect::<Vec<f32>>();
            let mean = mean.iter().map(|&v| v as f32).collect::<Vec<f32>>();
            if let Some(kept) = &mut self.captured {
                kept.push(BnStats {
                    running_mean: bn.running_mean,
                    running_var: bn.running_var,
                    mean: mean.clone(),
                    var: var.iter().map(|&v| v as f32).collect(),
                });
            }
            (Some(z), mean, invstd)
        } else {
            let rm = self.params.get(bn.running_mean).data().to_vec();
            let rv = self.params.get(bn.running_var).data();
            (None, rm, rv.iter().map(|&v| (1.0 / (v as f64 + bn.eps as f64).sqrt()) as f32).collect())
        };
        let (g, b) = (self.value(gamma).data(), self.value(beta).data());
        let scale: Vec<f32> = (0..cout).map(|j| g[j] * invstd[j]).collect();
        let shift: Vec<f32> = (0..cout).map(|j| b[j] - mean[j] * scale[j]).collect();
        let wd = w.map(|w| self.value(w).data());
        let xd = self.value(x).data();
        let (out, z) = match (z, record) {
            // Inference: one fused pass per row block, nothing saved.
            (None, false) => (conv_bn::linear_affine_act(xd, m, cin, wd, cout, &scale, &shift, act), None),
            (Some(mut z), false) => {
                conv_bn::affine_act_inplace(&mut z, cout, &scale, &shift, act);
                (z, None)
            }
            (z, true) => {
                let z = match z {
                    Some(z) => z,
                    None => conv_bn::linear_stats(xd, m, cin, wd, cout).0,
                };
                let mut out = vec![0.0f32; m * cout];
                conv_bn::affine_act(&z, &mut out, cout, &scale, &shift, act);
                (out, Some(z))
            }
        };
        let out_t = Tensor::new(&[m, cout], out)?;
        match z {
            Some(z) => {
                let saved = ConvBnSaved { x, w, gamma, beta, act, batch_stats: batch, z, mean, invstd };
                Ok(self.push(out_t, Op::ConvBnAct(Box::new(saved))))
            }
            None => Ok(self.push(out_t, Op::Leaf)),
        }
    }

    /// Applies a [`CustomOp`] to `inputs` (see `op.rs` for how to write one).
    ///
    /// # Errors
    /// Whatever the op's `forward` returns.
    pub fn custom(&mut self, mut op: Box<dyn CustomOp>, inputs: &[Var]) -> Result<Var> {
        self.check_live(op.name(), inputs)?;
        let vals: Vec<&Tensor> = inputs.iter().map(|&v| self.value(v)).collect();
        let out = op.forward(&vals)?;
        Ok(self.push(out, Op::Custom { inputs: inputs.to_vec(), op }))
    }

    // ---------------------------------------------------------------- backward

    /// Reverse pass from a one-element `loss` (seed 1), adding every trainable
    /// parameter's gradient into `grads`. The tape is spent afterwards (its ops are
    /// consumed; values stay readable).
    ///
    /// # Errors
    /// `Error::InvalidInput` when the graph does not record or was already spent;
    /// `Error::Shape` when `loss` is not a single element.
    pub fn backward(&mut self, loss: Var, grads: &mut Grads) -> Result<()> {
        self.check_live("backward", &[loss])?;
        let shape = self.value(loss).shape();
        if shape.numel() != 1 {
            return Err(shape_err("backward", format!("loss must be one element, got {shape}")));
        }
        self.backward_from(loss, Tensor::from_shape(shape, vec![1.0])?, grads)
    }

    /// Reverse pass seeded with `seed = ∂L/∂out` (same shape as `out`).
    ///
    /// # Errors
    /// As [`Graph::backward`], and `Error::Shape` when the seed's shape differs.
    pub fn backward_from(&mut self, out: Var, seed: Tensor, grads: &mut Grads) -> Result<()> {
        if !self.record {
            return Err(Error::invalid("backward on a graph that does not record (eval / no_grad mode)"));
        }
        if self.spent {
            return Err(Error::invalid("backward called twice on the same graph"));
        }
        self.check_live("backward", &[out])?;
        if self.value(out).shape() != seed.shape() {
            return Err(shape_err(
                "backward",
                format!("seed {} for output {}", seed.shape(), self.value(out).shape()),
            ));
        }
        self.spent = true;
        let mut g: Vec<Option<Tensor>> = (0..self.nodes.len()).map(|_| None).collect();
        g[out.0] = Some(seed);
        for i in (0..=out.0).rev() {
            let Some(gout) = g[i].take() else { continue };
            if !self.nodes[i].needs_grad {
                continue;
            }
            if let Some(id) = self.nodes[i].param {
                grads.accumulate(id, gout)?;
                continue;
            }
            let op = std::mem::replace(&mut self.nodes[i].op, Op::Leaf);
            self.apply_grad(i, op, gout, &mut g)?;
        }
        Ok(())
    }

    fn needs(&self, v: Var) -> bool {
        self.nodes[v.0].needs_grad
    }

    /// The gradient rules: one arm per [`Op`] variant.
    fn apply_grad(&self, i: usize, op: Op, gout: Tensor, g: &mut [Option<Tensor>]) -> Result<()> {
        let gd = gout.data();
        let outv = self.value(Var(i));
        match op {
            Op::Leaf => {}
            Op::MatMul { a, b, trans_b } => {
                let (ta, tb) = (self.value(a), self.value(b));
                let (m, k) = (ta.dims()[0], ta.dims()[1]);
                let n = outv.dims()[1];
                if self.needs(a) {
                    // ∂a = g · op(b)ᵀ
                    let ga = grad_slot(g, a, ta.shape());
                    gemm::gemm_rows(m, k, n, gd, false, tb.data(), !trans_b, ga.data_mut(), 1.0);
                }
                if self.needs(b) {
                    let gb = grad_slot(g, b, tb.shape());
                    if trans_b {
                        gemm::gemm_tn(n, k, m, gd, ta.data(), gb.data_mut(), 1.0);
                    // ∂b = gᵀ·a
                    } else {
                        gemm::gemm_tn(k, n, m, ta.data(), gd, gb.data_mut(), 1.0);
                        // ∂b = aᵀ·g
                    }
                }
            }
            Op::Add { a, b } | Op::Sub { a, b } | Op::Mul { a, b } | Op::Div { a, b } => {
                let kind = match op {
                    Op::Add { .. } => 0,
                    Op::Sub { .. } => 1,
                    Op::Mul { .. } => 2,
                    _ => 3,
                };
                let (ta, tb) = (self.value(a), self.value(b));
                let (_, ca, cb) = broadcast("backward", ta.shape(), tb.shape())?;
                let (rows, cols) = (outv.rows(), outv.cols());
                let (ad, bd) = (ta.data(), tb.data());
                if self.needs(a) {
                    let ga = grad_slot(g, a, ta.shape()).data_mut();
                    acc_reduce(ga, ca, rows, cols, |f, r, c| match kind {
                        0 | 1 => gd[f],
                        2 => gd[f] * bd[bi(cb, r, c, cols)],
                        _ => gd[f] / bd[bi(cb, r, c, cols)],
                    });
                }
                if self.needs(b) {
                    let gb = grad_slot(g, b, tb.shape()).data_mut();
                    acc_reduce(gb, cb, rows, cols, |f, r, c| match kind {
                        0 => gd[f],
                        1 => -gd[f],
                        2 => gd[f] * ad[bi(ca, r, c, cols)],
                        _ => {
                            let y = bd[bi(cb, r, c, cols)];
                            -gd[f] * ad[bi(ca, r, c, cols)] / (y * y)
                        }
                    });
                }
            }
            Op::Scale { a, s } => {
                let ga = grad_slot(g, a, outv.shape()).data_mut();
                ga.iter_mut().zip(gd).for_each(|(x, &y)| *x += s * y);
            }
            Op::AddScalar { a } | Op::Reshape { a } => {
                let sa = self.value(a).shape();
                let ga = grad_slot(g, a, sa).data_mut();
                ga.iter_mut().zip(gd).for_each(|(x, &y)| *x += y);
            }
            Op::Sum { a } | Op::Mean { a } => {
                let sa = self.value(a).shape();
                let k = if matches!(op, Op::Mean { .. }) { gd[0] / sa.numel() as f32 } else { gd[0] };
                grad_slot(g, a, sa).data_mut().iter_mut().for_each(|x| *x += k);
            }
            Op::SumAxis { a, axis, mean } => {
                let sa = self.value(a).shape();
                let (rows, cols) = (sa.rows(), sa.cols());
                let ga = grad_slot(g, a, sa).data_mut();
                let k = if !mean {
                    1.0
                } else if axis == 0 {
                    1.0 / rows as f32
                } else {
                    1.0 / cols as f32
                };
                for r in 0..rows {
                    for c in 0..cols {
                        ga[r * cols + c] += k * if axis == 0 { gd[c] } else { gd[r] };
                    }
                }
            }
            Op::Exp { a } => {
                let ga = grad_slot(g, a, outv.shape()).data_mut();
                for ((x, &y), &o) in ga.iter_mut().zip(gd).zip(outv.data()) {
                    *x += y * o;
                }
            }
            Op::Log { a } => {
                let ad = self.value(a).data();
                let ga = grad_slot(g, a, outv.shape()).data_mut();
                for ((x, &y), &v) in ga.iter_mut().zip(gd).zip(ad) {
                    *x += y / v;
                }
            }
            Op::LogSoftmax { a } => {
                let cols = outv.cols();
                let ga = grad_slot(g, a, outv.shape()).data_mut();
                for ((garow, grow), orow) in
                    ga.chunks_exact_mut(cols).zip(gd.chunks_exact(cols)).zip(outv.data().chunks_exact(cols))
                {
                    let s: f32 = grow.iter().sum();
                    for j in 0..cols {
                        garow[j] += grow[j] - orow[j].exp() * s;
                    }
                }
            }
            Op::Relu { a } | Op::LeakyRelu { a, .. } => {
                let slope = if let Op::LeakyRelu { slope, .. } = op { slope } else { 0.0 };
                let ad = self.value(a).data();
                let ga = grad_slot(g, a, outv.shape()).data_mut();
                for ((x, &y), &v) in ga.iter_mut().zip(gd).zip(ad) {
                    *x += if v > 0.0 { y } else { slope * y };
                }
            }
            Op::GatherRows { a, idx, .. } => {
                let sa = self.value(a).shape();
                let (n, c) = (sa.rows(), sa.cols());
                let ga = grad_slot(g, a, sa).data_mut();
                for (grow, &s) in gd.chunks_exact(c.max(1)).zip(idx.iter()) {
                    let s = s as usize;
                    if s < n {
                        ga[s * c..(s + 1) * c].iter_mut().zip(grow).for_each(|(x, &y)| *x += y);
                    }
                }
            }
            Op::ConcatCols { parts } => {
                let total = outv.cols();
                let rows = outv.rows();
                let mut off = 0;
                for p in parts {
                    let sp = self.value(p).shape();
                    let w = sp.cols();
                    if self.needs(p) {
                        let gp = grad_slot(g, p, sp).data_mut();
                        for r in 0..rows {
                            let src = &gd[r * total + off..r * total + off + w];
                            gp[r * w..(r + 1) * w].iter_mut().zip(src).for_each(|(x, &y)| *x += y);
                        }
                    }
                    off += w;
                }
            }
            Op::MaxNeighbors { a, argmax } => {
                let sa = self.value(a).shape();
                let (n, c) = (sa.rows(), sa.cols());
                let ga = grad_slot(g, a, sa).data_mut();
                for (f, (&s, &y)) in argmax.iter().zip(gd).enumerate() {
                    if (s as usize) < n {
                        ga[s as usize * c + f % c] += y;
                    }
                }
            }
            Op::ConvBnAct(s) => {
                let s = *s;
                let tx = self.value(s.x);
                let (m, cin) = (tx.rows(), tx.cols());
                let cout = outv.cols();
                let gamma = self.value(s.gamma).data();
                let mut gz = gout.into_data();
                let (dgamma, dbeta) = conv_bn::bn_act_backward(
                    &mut gz,
                    outv.data(),
                    &s.z,
                    m,
                    cout,
                    &s.mean,
                    &s.invstd,
                    gamma,
                    s.act,
                    s.batch_stats,
                );
                drop(s.z);
                if self.needs(s.gamma) {
                    let gg = grad_slot(g, s.gamma, self.value(s.gamma).shape()).data_mut();
                    gg.iter_mut().zip(&dgamma).for_each(|(x, &y)| *x += y);
                }
                if self.needs(s.beta) {
                    let gb = grad_slot(g, s.beta, self.value(s.beta).shape()).data_mut();
                    gb.iter_mut().zip(&dbeta).for_each(|(x, &y)| *x += y);
                }
                match s.w {
                    Some(w) => {
                        let tw = self.value(w);
                        if self.needs(w) {
                            let gw = grad_slot(g, w, tw.shape()).data_mut();
                            gemm::gemm_tn(cout, cin, m, &gz, tx.data(), gw, 1.0);
                            // ∂W = ∂zᵀ·x
                        }
                        if self.needs(s.x) {
                            let gx = grad_slot(g, s.x, tx.shape()).data_mut();
                            gemm::gemm_rows(m, cin, cout, &gz, false, tw.data(), false, gx, 1.0);
                            // ∂x = ∂z·W
                        }
                    }
                    None => {
                        if self.needs(s.x) {
                            let gx = grad_slot(g, s.x, tx.shape()).data_mut();
                            gx.iter_mut().zip(&gz).for_each(|(x, &y)| *x += y);
                        }
                    }
                }
                return Ok(());
            }
            Op::Custom { inputs, op } => {
                let vals: Vec<&Tensor> = inputs.iter().map(|&v| self.value(v)).collect();
                let needs: Vec<bool> = inputs.iter().map(|&v| self.needs(v)).collect();
                let res = op.backward(&vals, outv, &gout, &needs)?;
                if res.len() != inputs.len() {
                    return Err(shape_err(
                        op.name(),
                        format!("backward gave {} gradients for {} inputs", res.len(), inputs.len()),
                    ));
                }
                for ((&v, gi), val) in inputs.iter().zip(res).zip(&vals) {
                    if let (Some(gi), true) = (gi, self.needs(v)) {
                        if gi.len() != val.len() {
                            return Err(shape_err(
                                op.name(),
                                format!("gradient {} for input {}", gi.shape(), val.shape()),
                            ));
                        }
                        grad_slot(g, v, val.shape()).add_assign(&gi)?;
                    }
                }
            }
        }
        Ok(())
    }
}
