//! Determinism: a forward + backward pass over enough rows to span many GEMM row
//! blocks and several reduction chunks gives bit-identical outputs, gradients and
//! running statistics run after run and for 1, 2 or 3 worker threads.

use point2quad::nn::batch_norm::BatchNormConfig;
use point2quad::nn::conv1d::{Conv1d, ConvBnAct};
use point2quad::nn::loss::weighted_cross_entropy;
use point2quad::nn::module::{Module, ResidualBlock};
use point2quad::rng::Rng;
use point2quad::tensor::{Act, Grads, Graph, ParamStore, Tensor};

/// Outputs, every gradient and every stored tensor after one training pass.
fn pass() -> Vec<Vec<f32>> {
    let mut rng = Rng::new(11);
    let mut s = ParamStore::new();
    let bn = BatchNormConfig::default();
    let l0 = ConvBnAct::new(&mut s, "l0", 7, 24, Act::LeakyRelu(0.1), bn, &mut rng).unwrap();
    let res = ResidualBlock::new(&mut s, "r", 24, Act::LeakyRelu(0.1), bn, &mut rng).unwrap();
    let head = Conv1d::new(&mut s, "h", 24, 2, true, &mut rng).unwrap();
    let m = 17_000; // > 2 reduction chunks of 8192 rows, 67 row blocks
    let x = Tensor::new(&[m, 7], (0..m * 7).map(|_| rng.f32() * 2.0 - 1.0).collect()).unwrap();
    let y: Vec<u8> = (0..m).map(|_| (rng.f32() < 0.3) as u8).collect();
    let mut grads = Grads::new();
    let mut g = Graph::train(&mut s);
    let xv = g.input(x);
    let h = l0.forward(&mut g, xv).unwrap();
    let h = res.forward(&mut g, h).unwrap();
    let logits = head.forward(&mut g, h).unwrap();
    let loss = weighted_cross_entropy(&mut g, logits, &y, 2.5).unwrap();
    g.backward(loss, &mut grads).unwrap();
    let mut out = vec![g.value(logits).data().to_vec()];
    drop(g);
    for id in s.ids() {
        out.push(s.get(id).data().to_vec());
        if let Some(t) = grads.get(id) {
            out.push(t.data().to_vec());
        }
    }
    out
}

#[test]
fn same_seed_same_bits() {
    assert_eq!(pass(), pass());
}

#[cfg(feature = "parallel")]
#[test]
fn bit_identical_across_thread_counts() {
    let run = |n: usize| rayon::ThreadPoolBuilder::new().num_threads(n).build().unwrap().install(pass);
    let one = run(1);
    assert_eq!(one, run(2));
    assert_eq!(one, run(3));
}
