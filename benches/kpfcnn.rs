//! KPFCNN benchmark: forward and forward + backward on a 10,000-point cloud (torus vertices) for the `default`
//! and `paper` presets, with peak memory and a per-level split (neighbour search vs KPConv).
//! Each preset runs in its own child process so that its peak RSS is its own.
//! Lines: `bench <name> <value> <unit>`, medians of several runs after a warm-up.
//! Threads follow `RAYON_NUM_THREADS`.

use point2quad::nn::kpconv::{kpconv_forward, KpConvGeometry};
use point2quad::nn::kpfcnn::{prepare, Kpfcnn, KpfcnnConfig, PointPyramid};
use point2quad::rng::Rng;
use point2quad::spatial::kdtree::KdTree;
use point2quad::spatial::neighborhoods::{nearest_upsampling, radius_neighborhoods};
use point2quad::tensor::{Grads, Graph, ParamStore, Tensor};

#[path = "common/mod.rs"]
mod common;
use common::{median_ms, peak_rss_mib, timed};

const N: usize = 10_000;

/// The 10,000 vertices of a quad-mesh torus (`mesh::shapes::torus`, 200 × 50, major radius 0.7,
/// minor 0.3: inside the unit ball, spacing 0.022–0.038 ≈ the 0.03 level-0 cell).
fn cloud() -> Vec<[f32; 3]> {
    let m = point2quad::mesh::shapes::torus(200, 50, 0.7, 0.3);
    assert_eq!(m.vertices.len(), N, "torus vertex count");
    m.vertices.iter().map(|p| [p[0] as f32, p[1] as f32, p[2] as f32]).collect()
}

fn per_level(name: &str, cfg: &KpfcnnConfig, pts: &[[f32; 3]], pyr: &PointPyramid, runs: usize) {
    let mut rng = Rng::new(1);
    for l in 0..pyr.num_levels() {
        let radius = cfg.conv_radius * pyr.cells[l];
        let t_nb = median_ms(runs, || {
            let tree = KdTree::build(&pyr.points[l]);
            let _ = radius_neighborhoods(&tree, &pyr.points[l], radius, cfg.neighbor_cap).expect("valid");
            if l + 1 < pyr.num_levels() {
                let _ =
                    radius_neighborhoods(&tree, &pyr.points[l + 1], radius, cfg.neighbor_cap).expect("valid");
                let coarse = KdTree::build(&pyr.points[l + 1]);
                let _ = nearest_upsampling(&coarse, &pyr.points[l]).expect("valid");
            }
        });
        let layers: Vec<_> = cfg.kpconv_layers().into_iter().filter(|s| s.level == l).collect();
        let kernel = point2quad::nn::kernel_points::scaled_kernel_points(cfg.num_kernel_points, 0, radius)
            .expect("valid");
        let sigma = cfg.kp_extent * pyr.cells[l];
        let inputs: Vec<(Vec<f32>, Vec<f32>)> = layers
            .iter()
            .map(|s| {
                let f = (0..pyr.points[l].len() * s.c_in).map(|_| rng.f32() - 0.5).collect();
                let w = (0..cfg.num_kernel_points * s.c_in * s.c_out).map(|_| rng.f32() - 0.5).collect();
                (f, w)
            })
            .collect();
        let t_conv = median_ms(runs, || {
            for (s, (f, w)) in layers.iter().zip(&inputs) {
                let (q, nb) = if s.strided {
                    (&pyr.points[l + 1], &pyr.pool[l])
                } else {
                    (&pyr.points[l], &pyr.conv[l])
                };
                let g = KpConvGeometry::new(q, &pyr.points[l], &nb.indices, nb.cap, &kernel, sigma)
                    .expect("valid");
                let _ = kpconv_forward(&g, f, s.c_in, w, s.c_out).expect("valid");
            }
        });
        println!(
            "bench kpfcnn_level{l}_points_10k_{name} {} points (cap {}, {} KPConv layers)",
            pyr.points[l].len(),
            pyr.conv[l].cap,
            layers.len()
        );
        println!("bench kpfcnn_level{l}_neighbors_10k_{name} {t_nb:.2} ms");
        println!("bench kpfcnn_level{l}_kpconv_fwd_10k_{name} {t_conv:.2} ms");
    }
    let _ = pts;
}

fn run_preset(name: &str) {
    let cfg = match name {
        "paper" => KpfcnnConfig::paper(),
        _ => KpfcnnConfig::default_preset(),
    };
    let runs = if name == "paper" { 5 } else { 7 };
    let pts = cloud();
    let mut params = ParamStore::new();
    let net = Kpfcnn::new(&cfg, &mut params).expect("valid preset");
    println!("bench kpfcnn_params_{name} {} params", params.num_trainable());
    let t_prep = median_ms(runs, || {
        let _ = prepare(&pts, &cfg).expect("valid cloud");
    });
    println!("bench kpfcnn_prepare_10k_{name} {t_prep:.2} ms");
    let pyr = prepare(&pts, &cfg).expect("valid cloud");
    let (t_fwd, t_fwd_cpu) = timed(runs, || {
        let mut g = Graph::eval(&mut params);
        let out = net.forward(&mut g, &pyr).expect("forward");
        std::hint::black_box(g.value(out).data()[0]);
    });
    println!("bench kpfcnn_fwd_10k_{name} {t_fwd:.2} ms");
    println!("bench kpfcnn_fwd_cpu_10k_{name} {t_fwd_cpu:.0} ms");
    let (t_fwd_rec, t_fwd_rec_cpu) = timed(runs, || {
        let mut g = Graph::train(&mut params);
        let out = net.forward(&mut g, &pyr).expect("forward");
        std::hint::black_box(g.value(out).data()[0]);
    });
    println!("bench kpfcnn_fwd_train_10k_{name} {t_fwd_rec:.2} ms");
    println!("bench kpfcnn_fwd_train_cpu_10k_{name} {t_fwd_rec_cpu:.0} ms");
    let seed: Vec<f32> = {
        let mut r = Rng::new(2);
        (0..N * cfg.out_dim).map(|_| r.f32() - 0.5).collect()
    };
    let (t_fb, t_fb_cpu) = timed(runs, || {
        let mut grads = Grads::new();
        let mut g = Graph::train(&mut params);
        let out = net.forward(&mut g, &pyr).expect("forward");
        let s = Tensor::new(&[N, cfg.out_dim], seed.clone()).expect("shape");
        g.backward_from(out, s, &mut grads).expect("backward");
        std::hint::black_box(grads.norm_sq());
    });
    println!("bench kpfcnn_fwdbwd_10k_{name} {t_fb:.2} ms");
    println!("bench kpfcnn_fwdbwd_cpu_10k_{name} {t_fb_cpu:.0} ms");
    // The same with the KPConv influences precomputed once per cloud (reusable across epochs).
    let geoms = net.geometries(&pyr).expect("geometry");
    let (t_fbc, t_fbc_cpu) = timed(runs, || {
        let mut grads = Grads::new();
        let mut g = Graph::train(&mut params);
        let out = net.forward_with(&mut g, &pyr, &geoms).expect("forward");
        let s = Tensor::new(&[N, cfg.out_dim], seed.clone()).expect("shape");
        g.backward_from(out, s, &mut grads).expect("backward");
        std::hint::black_box(grads.norm_sq());
    });
    println!("bench kpfcnn_fwdbwd_cached_geometry_10k_{name} {t_fbc:.2} ms");
    println!("bench kpfcnn_fwdbwd_cached_geometry_cpu_10k_{name} {t_fbc_cpu:.0} ms");
    drop(geoms);
    per_level(name, &cfg, &pts, &pyr, runs);
    if let Some(rss) = peak_rss_mib() {
        println!("bench kpfcnn_peak_rss_10k_{name} {rss:.0} MiB");
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if let Some(pos) = args.iter().position(|a| a == "--preset") {
        run_preset(args.get(pos + 1).map(String::as_str).unwrap_or("default"));
        return;
    }
    // `cargo bench` passes `--bench`; `cargo test --all-targets` runs this binary without it
    // (harness = false), where a smoke run of the small preset is enough.
    if !args.iter().any(|a| a == "--bench") {
        let cfg = KpfcnnConfig::default_preset();
        let pyr = prepare(&cloud(), &cfg).expect("valid cloud");
        let mut params = ParamStore::new();
        let net = Kpfcnn::new(&cfg, &mut params).expect("valid preset");
        let mut g = Graph::eval(&mut params);
        let out = net.forward(&mut g, &pyr).expect("forward");
        assert_eq!(g.value(out).dims(), &[N, cfg.out_dim]);
        eprintln!("kpfcnn bench: smoke run only; `cargo bench --bench kpfcnn` measures");
        return;
    }
    println!("bench kpfcnn_threads {} threads", point2quad::par::num_threads());
    let exe = std::env::current_exe().expect("own path");
    for preset in ["default", "paper"] {
        let out = std::process::Command::new(&exe).args(["--preset", preset]).output().expect("run child");
        print!("{}", String::from_utf8_lossy(&out.stdout));
        if !out.status.success() {
            eprintln!("{}", String::from_utf8_lossy(&out.stderr));
            std::process::exit(1);
        }
    }
}
