//! Benchmark: the Point2Quad face encoder + classifier at the paper's widths (DESIGN §3)
//! on M = 120,000 candidates, batch norm in train mode, compound loss included.
//!
//! Encoder: fused Conv1d(k=1)+BN+LeakyReLU(0.1) 29→128, 128→128, residual block (two
//! 128→128 convs), 128→256, 256→512, 512→256. Classifier on [4×64 gathered point
//! features (random input here) ; 256] = 512: fused Conv1d+BN+ReLU 512→512, 512→256,
//! 256→128, 128→64, then Conv1d 64→2 (bias) → logits → weighted CE + face loss.
//!
//! Prints (median of RUNS after one warm-up):
//!   bench face_net_fwd_120k <ms> ms          train-mode forward incl. loss (recording)
//!   bench face_net_fwdbwd_120k <ms> ms       forward + backward
//!   bench face_net_fwd_eval_120k <ms> ms     inference forward (no_grad, running stats)
//!   bench face_net_gflops <x> GFLOP/s        of forward + backward: 3 · Σ 2·M·Cin·Cout / fwdbwd time
//!   bench face_net_peak_rss <MiB> MiB        VmHWM of the process
//! Threads: RAYON_NUM_THREADS (default all cores). `FACE_NET_M` overrides M. Run
//! without `--bench` (as `cargo test --all-targets` does) it only makes one small smoke
//! pass (M = 1024) and prints nothing on stdout.

use point2quad::nn::batch_norm::BatchNormConfig;
use point2quad::nn::conv1d::{Conv1d, ConvBnAct};
use point2quad::nn::loss::{face_loss, weighted_cross_entropy};
use point2quad::nn::module::{Module, ResidualBlock};
use point2quad::rng::Rng;
use point2quad::tensor::{Act, Grads, Graph, ParamStore, Tensor};
use std::time::Instant;

const RUNS: usize = 5;

struct FaceNet {
    enc: Vec<ConvBnAct>,
    res: ResidualBlock,
    cls: Vec<ConvBnAct>,
    head: Conv1d,
}

fn build(params: &mut ParamStore, rng: &mut Rng) -> FaceNet {
    let bn = BatchNormConfig { eps: 1e-5, momentum: 0.02 };
    let lr = Act::LeakyRelu(0.1);
    let widths = [(29, 128), (128, 128), (128, 256), (256, 512), (512, 256)];
    let enc = widths
        .iter()
        .enumerate()
        .map(|(i, &(a, b))| ConvBnAct::new(params, &format!("enc{i}"), a, b, lr, bn, rng).expect("layer"))
        .collect();
    let res = ResidualBlock::new(params, "enc_res", 128, lr, bn, rng).expect("res");
    let cw = [(512, 512), (512, 256), (256, 128), (128, 64)];
    let cls = cw
        .iter()
        .enumerate()
        .map(|(i, &(a, b))| {
            ConvBnAct::new(params, &format!("cls{i}"), a, b, Act::Relu, bn, rng).expect("layer")
        })
        .collect();
    let head = Conv1d::new(params, "cls_head", 64, 2, true, rng).expect("head");
    FaceNet { enc, res, cls, head }
}

fn flops_fwd(m: usize) -> f64 {
    let layers: [(usize, usize); 12] = [
        (29, 128),
        (128, 128),
        (128, 128),
        (128, 128),
        (128, 256),
        (256, 512),
        (512, 256),
        (512, 512),
        (512, 256),
        (256, 128),
        (128, 64),
        (64, 2),
    ];
    layers.iter().map(|&(a, b)| 2.0 * m as f64 * a as f64 * b as f64).sum()
}

/// Forward to the scalar loss; frees dead intermediates when not recording.
fn forward(
    net: &FaceNet,
    g: &mut Graph,
    finfo: &Tensor,
    pfeat: &Tensor,
    labels: &[u8],
) -> point2quad::tensor::Var {
    let x = g.input(finfo.clone());
    let mut h = net.enc[0].forward(g, x).expect("enc0");
    g.free(x);
    let h1 = net.enc[1].forward(g, h).expect("enc1");
    g.free(h);
    h = net.res.forward(g, h1).expect("res");
    g.free(h1);
    for l in &net.enc[2..] {
        let n = l.forward(g, h).expect("enc");
        g.free(h);
        h = n;
    }
    let p = g.input(pfeat.clone());
    let cat = g.concat_cols(&[p, h]).expect("concat");
    g.free(p);
    g.free(h);
    h = cat;
    for l in &net.cls {
        let n = l.forward(g, h).expect("cls");
        g.free(h);
        h = n;
    }
    let logits = net.head.forward(g, h).expect("head");
    let a = weighted_cross_entropy(g, logits, labels, 3.0).expect("ce");
    let b = face_loss(g, logits, labels).expect("fl");
    g.add(a, b).expect("loss")
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.partial_cmp(b).expect("finite timings"));
    v[v.len() / 2]
}

fn peak_rss_mib() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .and_then(|l| l.split_whitespace().nth(1).and_then(|v| v.parse::<f64>().ok()))
        })
        .map_or(f64::NAN, |kb| kb / 1024.0)
}

/// CPU seconds (user + system, all threads) of this process so far.
fn cpu_s() -> f64 {
    std::fs::read_to_string("/proc/self/stat")
        .ok()
        .and_then(|s| {
            let f: Vec<String> = s.rsplit(')').next()?.split_whitespace().map(String::from).collect();
            Some((f.get(11)?.parse::<f64>().ok()? + f.get(12)?.parse::<f64>().ok()?) / 100.0)
        })
        .unwrap_or(f64::NAN)
}

fn main() {
    let bench_mode = std::env::args().any(|a| a == "--bench");
    let default_m = if bench_mode { 120_000 } else { 1024 };
    let m: usize = std::env::var("FACE_NET_M").ok().and_then(|v| v.parse().ok()).unwrap_or(default_m);
    let runs = if bench_mode { RUNS } else { 0 };
    let mut rng = Rng::new(0);
    let mut params = ParamStore::new();
    let net = build(&mut params, &mut rng);
    let finfo = Tensor::new(&[m, 29], (0..m * 29).map(|_| rng.f32() * 2.0 - 1.0).collect()).expect("finfo");
    let pfeat = Tensor::new(&[m, 256], (0..m * 256).map(|_| rng.f32() * 2.0 - 1.0).collect()).expect("pfeat");
    let labels: Vec<u8> = (0..m).map(|_| (rng.f32() < 0.25) as u8).collect();

    let (mut fwd, mut fwdbwd, mut eval) = (Vec::new(), Vec::new(), Vec::new());
    for run in 0..=runs {
        let (t, c0) = (Instant::now(), cpu_s());
        {
            let mut g = Graph::train(&mut params);
            let l = forward(&net, &mut g, &finfo, &pfeat, &labels);
            std::hint::black_box(g.value(l).item().expect("scalar"));
        }
        let t_fwd = t.elapsed().as_secs_f64() * 1e3;
        let c_fwd = cpu_s() - c0;

        let (t, c0) = (Instant::now(), cpu_s());
        {
            let mut g = Graph::train(&mut params);
            let l = forward(&net, &mut g, &finfo, &pfeat, &labels);
            let mut grads = Grads::new();
            g.backward(l, &mut grads).expect("backward");
            std::hint::black_box(grads.norm_sq());
        }
        let t_fb = t.elapsed().as_secs_f64() * 1e3;
        let c_fb = cpu_s() - c0;

        let t = Instant::now();
        {
            let mut g = Graph::eval(&mut params);
            let l = forward(&net, &mut g, &finfo, &pfeat, &labels);
            std::hint::black_box(g.value(l).item().expect("scalar"));
        }
        let t_ev = t.elapsed().as_secs_f64() * 1e3;
        eprintln!(
            "run {run}: fwd {t_fwd:.0} ms ({c_fwd:.2} cpu-s), fwd+bwd {t_fb:.0} ms ({c_fb:.2} cpu-s), eval {t_ev:.0} ms"
        );
        if run > 0 {
            fwd.push(t_fwd);
            fwdbwd.push(t_fb);
            eval.push(t_ev);
        }
    }
    if !bench_mode {
        eprintln!("face_net: smoke run only (M = {m}); use `cargo bench --bench face_net` for figures");
        return;
    }
    let (f, fb, ev) = (median(fwd), median(fwdbwd), median(eval));
    let suffix = if m == 120_000 { "120k".to_string() } else { format!("{m}") };
    println!("bench face_net_fwd_{suffix} {f:.1} ms");
    println!("bench face_net_fwdbwd_{suffix} {fb:.1} ms");
    println!("bench face_net_fwd_eval_{suffix} {ev:.1} ms");
    println!("bench face_net_gflops {:.1} GFLOP/s", 3.0 * flops_fwd(m) / (fb * 1e-3) / 1e9);
    println!("bench face_net_peak_rss {:.0} MiB", peak_rss_mib());
}
