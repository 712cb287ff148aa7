//! Finite-difference gradient checking for any op, layer or closure built on the tape.
//! The closure's output is projected on a fixed random tensor `R` (loss `Σ out ⊙ R`,
//! accumulated in f64), its analytic gradient is taken with `backward_from(out, R)`,
//! and each checked parameter element is compared with the central difference
//! `(L(θ+ε) − L(θ−ε)) / 2ε`. Elements where the two one-sided differences disagree
//! (a ReLU kink or max switch inside the step) are skipped and counted; the check
//! fails if more than `max_skip_frac` are skipped.

use super::params::{Grads, ParamKind, ParamStore};
use super::tape::{Graph, Var};
use super::tensor::Tensor;
use crate::rng::Rng;
use crate::Result;

/// Settings of [`gradcheck`].
#[derive(Clone, Debug)]
pub struct GradCheckConfig {
    /// Finite-difference step.
    pub eps: f32,
    /// Relative tolerance.
    pub rtol: f64,
    /// Absolute tolerance.
    pub atol: f64,
    /// At most this many elements per parameter are checked (sampled with `seed`).
    pub max_per_param: usize,
    /// Seed of the projection tensor and the element sample.
    pub seed: u64,
    /// Build graphs in train mode (batch statistics) or eval mode.
    pub train: bool,
    /// Largest tolerated fraction of skipped (non-smooth) elements.
    pub max_skip_frac: f64,
}

impl Default for GradCheckConfig {
    fn default() -> Self {
        GradCheckConfig {
            eps: 1e-3,
            rtol: 1e-2,
            atol: 5e-3,
            max_per_param: 48,
            seed: 0,
            train: true,
            max_skip_frac: 0.1,
        }
    }
}

/// Outcome of [`gradcheck`].
#[derive(Clone, Debug, Default)]
pub struct GradCheckReport {
    /// Elements compared.
    pub checked: usize,
    /// Elements skipped as non-smooth.
    pub skipped: usize,
    /// Largest `|analytic − numeric| / (atol + rtol·max(|a|, |n|))` seen (≤ 1 passes).
    pub worst_ratio: f64,
    /// One line per failing element (empty when the check passes).
    pub failures: Vec<String>,
}

impl GradCheckReport {
    /// True when no element failed and few enough were skipped.
    pub fn passed(&self, cfg: &GradCheckConfig) -> bool {
        self.failures.is_empty()
            && (self.skipped as f64) <= cfg.max_skip_frac * (self.checked + self.skipped) as f64
    }
}

fn projected_loss<F>(params: &mut ParamStore, f: &mut F, r: &Tensor, train: bool) -> Result<f64>
where
    F: FnMut(&mut Graph) -> Result<Var>,
{
    let mut g = Graph::new(params, false, train);
    let out = f(&mut g)?;
    let o = g.value(out);
    Ok(o.data().iter().zip(r.data()).map(|(&a, &b)| a as f64 * b as f64).sum())
}

/// Checks the gradients of every trainable tensor of `params` for the function `f`
/// (which builds its output on the graph it is given; it may read inputs from
/// `params` too — make them trainable to check their gradient).
///
/// # Errors
/// Whatever `f` or the backward pass returns.
pub fn gradcheck<F>(params: &mut ParamStore, mut f: F, cfg: &GradCheckConfig) -> Result<GradCheckReport>
where
    F: FnMut(&mut Graph) -> Result<Var>,
{
    let mut rng = Rng::new(cfg.seed);
    let mut grads = Grads::new();
    let r = {
        let mut g = Graph::new(params, true, cfg.train);
        let out = f(&mut g)?;
        let shape = g.value(out).shape();
        let r = Tensor::from_shape(shape, (0..shape.numel()).map(|_| rng.f32() * 2.0 - 1.0).collect())?;
        g.backward_from(out, r.clone(), &mut grads)?;
        r
    };
    let l0 = projected_loss(params, &mut f, &r, cfg.train)?;
    let mut rep = GradCheckReport::default();
    let ids: Vec<_> = params.ids().filter(|&id| params.kind(id) == ParamKind::Trainable).collect();
    for id in ids {
        let n = params.get(id).len();
        let picks: Vec<usize> = if n <= cfg.max_per_param {
            (0..n).collect()
        } else {
            (0..cfg.max_per_param).map(|_| rng.below(n)).collect()
        };
        for j in picks {
            let analytic = grads.get(id).map_or(0.0, |t| t.data()[j]) as f64;
            let orig = params.get(id).data()[j];
            params.get_mut(id).data_mut()[j] = orig + cfg.eps;
            let lp = projected_loss(params, &mut f, &r, cfg.train)?;
            params.get_mut(id).data_mut()[j] = orig - cfg.eps;
            let lm = projected_loss(params, &mut f, &r, cfg.train)?;
            params.get_mut(id).data_mut()[j] = orig;
            // The actual step taken in f32 (orig ± eps rounds).
            let h = ((orig + cfg.eps) as f64 - (orig - cfg.eps) as f64) / 2.0;
            let numeric = (lp - lm) / (2.0 * h);
            let (dp, dm) = ((lp - l0) / h, (l0 - lm) / h);
            let tol = |a: f64, b: f64| cfg.atol + cfg.rtol * a.abs().max(b.abs());
            if (dp - dm).abs() > tol(dp, dm) {
                rep.skipped += 1;
                continue;
            }
            rep.checked += 1;
            let ratio = (analytic - numeric).abs() / tol(analytic, numeric);
            rep.worst_ratio = rep.worst_ratio.max(ratio);
            if ratio > 1.0 {
                rep.failures.push(format!(
                    "'{}'[{j}]: analytic {analytic:.6}, numeric {numeric:.6}",
                    params.name(id)
                ));
            }
        }
    }
    Ok(rep)
}
