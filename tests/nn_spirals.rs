//! End-to-end learning check: a small MLP built from the crate's parts (fused
//! conv1d+BN+ReLU blocks, a biased Conv1d head, weighted cross-entropy, SGD with
//! momentum) must fit two interleaved spirals to ≥ 98% train accuracy (measured in
//! eval mode, i.e. with the running batch-norm statistics) within a fixed step budget.

use point2quad::nn::batch_norm::BatchNormConfig;
use point2quad::nn::conv1d::{Conv1d, ConvBnAct};
use point2quad::nn::loss::weighted_cross_entropy;
use point2quad::nn::module::{Module, Sequential};
use point2quad::nn::optim::{Sgd, SgdConfig};
use point2quad::rng::Rng;
use point2quad::tensor::{Act, Grads, Graph, ParamStore, Tensor};

fn spirals(n_per: usize, rng: &mut Rng) -> (Tensor, Vec<u8>) {
    let mut x = Vec::new();
    let mut y = Vec::new();
    for class in 0..2u8 {
        for i in 0..n_per {
            let t = 0.25 + 4.0 * std::f64::consts::PI * i as f64 / n_per as f64; // 2 turns
            let r = t / (4.0 * std::f64::consts::PI);
            let a = t + class as f64 * std::f64::consts::PI;
            x.push((r * a.cos() + 0.01 * rng.normal()) as f32);
            x.push((r * a.sin() + 0.01 * rng.normal()) as f32);
            y.push(class);
        }
    }
    (Tensor::new(&[2 * n_per, 2], x).unwrap(), y)
}

#[test]
fn mlp_learns_two_spirals() {
    let mut rng = Rng::new(7);
    let (x, y) = spirals(150, &mut rng);
    let mut params = ParamStore::new();
    let bn = BatchNormConfig::default();
    let net = Sequential::new(vec![
        Box::new(ConvBnAct::new(&mut params, "l0", 2, 64, Act::Relu, bn, &mut rng).unwrap()),
        Box::new(ConvBnAct::new(&mut params, "l1", 64, 64, Act::Relu, bn, &mut rng).unwrap()),
        Box::new(ConvBnAct::new(&mut params, "l2", 64, 64, Act::Relu, bn, &mut rng).unwrap()),
        Box::new(Conv1d::new(&mut params, "head", 64, 2, true, &mut rng).unwrap()),
    ]);
    let mut sgd =
        Sgd::new(SgdConfig { lr: 0.1, momentum: 0.9, weight_decay: 0.0, clip: Some(100.0), nesterov: false })
            .unwrap();
    let mut grads = Grads::new();
    for _step in 0..600 {
        grads.zero();
        let mut g = Graph::train(&mut params);
        let xv = g.input(x.clone());
        let logits = net.forward(&mut g, xv).unwrap();
        let loss = weighted_cross_entropy(&mut g, logits, &y, 1.0).unwrap();
        g.backward(loss, &mut grads).unwrap();
        drop(g);
        sgd.step(&mut params, &grads, 0.1).unwrap();
    }
    let mut g = Graph::eval(&mut params);
    let xv = g.input(x.clone());
    let logits = net.forward(&mut g, xv).unwrap();
    let l = g.value(logits);
    let correct = (0..y.len()).filter(|&i| ((l.row(i)[1] > l.row(i)[0]) as u8) == y[i]).count();
    let acc = correct as f64 / y.len() as f64;
    assert!(acc >= 0.98, "train accuracy {acc}");
}
