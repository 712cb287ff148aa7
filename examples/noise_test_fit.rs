//! Fits the learned noise test of the second pass (`reconstruct --second-pass-cover
//! learned`, session 35): reads clouds whose first `V` points are a mesh's vertices and
//! the rest noise points, computes what the test reads about each point after the first
//! pass (`reconstruct::first_pass_features`), and fits a logistic regression to "is a
//! noise point" by Newton's method (mean log-loss, L2 `--l2` on every weight, 50 steps).
//! Prints the weights in `second_pass::LEARNED_WEIGHTS`' order and what they and the
//! shipped ones take on the data. A measurement tool; asserts nothing.
//!
//! ```text
//! scripts/judge/noise_test_data.sh MODEL OUT [--rounds N]   # the clouds and OUT/list.txt
//! cargo run --release --example noise_test_fit -- MODEL OUT/list.txt [--rounds N] [--l2 1e-3]
//! ```
//! LIST holds one `CLOUD V` per line. Session 35 fitted the shipped weights this way on
//! the judge's seed-18 model (`scripts/judge/heldout.sh 18 6`) with `--rounds 5`.

use std::path::Path;

use nalgebra::{DMatrix, DVector};
use point2quad::io::points::read_points;
use point2quad::pipeline::model::Model;
use point2quad::pipeline::reconstruct::{first_pass_features, ReconstructConfig};
use point2quad::pipeline::second_pass::{LEARNED_CUTOFF, LEARNED_WEIGHTS, NOISE_FEATURES};

fn main() -> point2quad::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let value = |name: &str| args.iter().position(|a| a == name).and_then(|i| args.get(i + 1)).cloned();
    let files: Vec<&String> = {
        let mut skip = false;
        args.iter()
            .filter(|a| {
                let s = skip;
                skip = a.starts_with("--");
                !s && !a.starts_with("--")
            })
            .collect()
    };
    let (Some(model), Some(list)) = (files.first(), files.get(1)) else {
        eprintln!("usage: noise_test_fit MODEL LIST [--rounds N] [--l2 L]");
        std::process::exit(2);
    };
    let model = Model::load(Path::new(model))?;
    let mut cfg = ReconstructConfig::default();
    if let Some(n) = value("--rounds") {
        cfg.max_rounds = Some(n.parse().expect("--rounds N"));
    }
    let l2: f64 = value("--l2").map_or(1e-3, |v| v.parse().expect("--l2 L"));
    let mut rows: Vec<[f32; NOISE_FEATURES]> = Vec::new();
    let mut labels: Vec<f64> = Vec::new();
    let text = std::fs::read_to_string(list.as_str()).expect("the list");
    for line in text.lines().filter(|l| !l.trim().is_empty()) {
        let mut it = line.split_whitespace();
        let (cloud, v) = (it.next().expect("CLOUD"), it.next().expect("V").parse::<u32>().expect("V"));
        let points = read_points(Path::new(cloud))?;
        let x = first_pass_features(&points, &model, &cfg)?;
        let noise = x.iter().filter(|(i, _)| *i >= v).count();
        eprintln!("{cloud}: {} points, {noise} noise", x.len());
        for (i, f) in x {
            rows.push(f);
            labels.push(f64::from(u8::from(i >= v)));
        }
    }
    let n = rows.len();
    let x = DMatrix::from_fn(n, NOISE_FEATURES, |r, c| f64::from(rows[r][c]));
    let y = DVector::from_vec(labels);
    let mut w = DVector::<f64>::zeros(NOISE_FEATURES);
    for _ in 0..50 {
        let p = (&x * &w).map(|z| 1.0 / (1.0 + (-z).exp()));
        let g = x.transpose() * (&p - &y) / n as f64 + &w * l2;
        let s = p.map(|q| q * (1.0 - q));
        let xs = DMatrix::from_fn(n, NOISE_FEATURES, |r, c| x[(r, c)] * s[r]);
        let h = x.transpose() * xs / n as f64 + DMatrix::<f64>::identity(NOISE_FEATURES, NOISE_FEATURES) * l2;
        let step = h.lu().solve(&g).expect("a regular Hessian");
        w -= step;
    }
    println!("{} points, {} noise", n, y.iter().filter(|&&t| t > 0.5).count());
    let fitted: Vec<String> = w.iter().map(|v| format!("{v:.6}")).collect();
    println!("weights: {}", fitted.join(", "));
    let count = |weights: &[f64], cutoff: f64| {
        let (mut noise, mut truth) = (0, 0);
        for (r, &t) in rows.iter().zip(y.iter()) {
            let z: f64 = r.iter().zip(weights).map(|(a, b)| f64::from(*a) * b).sum();
            if z > cutoff {
                if t > 0.5 {
                    noise += 1;
                } else {
                    truth += 1;
                }
            }
        }
        (noise, truth)
    };
    let (a, b) = count(w.as_slice(), 0.0);
    println!("fitted test: takes {a} noise points and {b} true vertices");
    let shipped: Vec<f64> = LEARNED_WEIGHTS.iter().map(|&v| f64::from(v)).collect();
    let (a, b) = count(&shipped, f64::from(LEARNED_CUTOFF));
    println!("shipped test: takes {a} noise points and {b} true vertices");
    let rule = rows.iter().zip(y.iter()).filter(|(r, _)| r[1] > 0.5);
    let (a, b) = rule.fold((0, 0), |(a, b), (_, &t)| if t > 0.5 { (a + 1, b) } else { (a, b + 1) });
    println!("believed-face rule: takes {a} noise points and {b} true vertices");
    Ok(())
}
