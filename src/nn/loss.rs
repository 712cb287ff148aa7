//! Losses on 2-class logits `[M × 2]` (column 1 = "face is real"), DESIGN §4.
//!
//! - [`weighted_cross_entropy`]: `−Σ_i w_i·log p_i[y_i] / Σ_i w_i` with `w_i = w` for
//!   positives and 1 for negatives — PyTorch's `cross_entropy(weight=[1, w])` with
//!   `reduction='mean'`, which divides by the SUM OF WEIGHTS, not by M.
//! - [`face_loss`]: `L_F = mean_i( y_i·p_i0 + (1 − y_i)·p_i1 )`, the probability mass on
//!   the wrong class (the public code's sound form; the paper's sign is wrong).

use crate::tensor::{Graph, Tensor, Var};
use crate::{Error, Result};

fn check(g: &Graph, logits: Var, labels: &[u8]) -> Result<usize> {
    let t = g.value(logits);
    if t.shape().rank() != 2 || t.cols() != 2 {
        return Err(Error::Shape { op: "loss", msg: format!("logits must be [M × 2], got {}", t.shape()) });
    }
    if t.rows() != labels.len() {
        return Err(Error::Shape {
            op: "loss",
            msg: format!("{} logit rows for {} labels", t.rows(), labels.len()),
        });
    }
    if labels.is_empty() {
        return Err(Error::invalid("loss over zero candidates"));
    }
    if let Some(i) = labels.iter().position(|&y| y > 1) {
        return Err(Error::invalid(format!("label {} at candidate {i} is not 0 or 1", labels[i])));
    }
    Ok(labels.len())
}

/// Weighted cross-entropy; `pos_weight` multiplies the positive class.
///
/// # Errors
/// `Error::Shape` unless logits are `[labels.len() × 2]`; `Error::InvalidInput` for no
/// candidates, a label other than 0/1, or a non-positive / non-finite weight.
pub fn weighted_cross_entropy(g: &mut Graph, logits: Var, labels: &[u8], pos_weight: f32) -> Result<Var> {
    let m = check(g, logits, labels)?;
    if !(pos_weight > 0.0 && pos_weight.is_finite()) {
        return Err(Error::invalid(format!(
            "positive-class weight {pos_weight} must be positive and finite"
        )));
    }
    let mut mask = vec![0.0f32; 2 * m];
    let mut wsum = 0.0f64;
    for (i, &y) in labels.iter().enumerate() {
        let w = if y == 1 { pos_weight } else { 1.0 };
        mask[2 * i + y as usize] = w;
        wsum += w as f64;
    }
    let lp = g.log_softmax(logits)?;
    let mk = g.input(Tensor::new(&[m, 2], mask)?);
    let picked = g.mul(lp, mk)?;
    let s = g.sum(picked)?;
    g.scale(s, (-1.0 / wsum) as f32)
}

/// The face loss: mean softmax probability of the wrong class.
///
/// # Errors
/// As [`weighted_cross_entropy`].
pub fn face_loss(g: &mut Graph, logits: Var, labels: &[u8]) -> Result<Var> {
    let m = check(g, logits, labels)?;
    let mut mask = vec![0.0f32; 2 * m];
    for (i, &y) in labels.iter().enumerate() {
        mask[2 * i + (1 - y as usize)] = 1.0;
    }
    let lp = g.log_softmax(logits)?;
    let p = g.exp(lp)?;
    let mk = g.input(Tensor::new(&[m, 2], mask)?);
    let wrong = g.mul(p, mk)?;
    let s = g.sum(wrong)?;
    g.scale(s, 1.0 / m as f32)
}
