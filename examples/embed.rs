//! Embedding point2quad as a library: points in memory, a quad mesh back, no file I/O.
//! The README's library section points here; `cargo test` compiles it, and
//! `cargo run --release --example embed` runs it (a torus's quad-grid vertices plus a few
//! stray points, reconstructed with the shipped weights).
//!
//! The same calls build with `--no-default-features` (no `rayon`) and for
//! `wasm32-unknown-unknown`: the library itself reads and writes no file, and starts
//! threads only with the `parallel` feature.

use point2quad::pipeline::model::Model;
use point2quad::pipeline::reconstruct::{reconstruct, reconstruct_observed, ReconstructConfig};

fn main() -> point2quad::Result<()> {
    // A torus sampled on a 24 x 12 quad grid, plus three stray points off its surface.
    let (nu, nv) = (24, 12);
    let mut points: Vec<[f64; 3]> = Vec::new();
    for i in 0..nu {
        for j in 0..nv {
            let (u, v) =
                (std::f64::consts::TAU * i as f64 / nu as f64, std::f64::consts::TAU * j as f64 / nv as f64);
            let r = 3.0 + v.cos();
            points.push([r * u.cos(), r * u.sin(), v.sin()]);
        }
    }
    points.extend([[0.0, 0.0, 2.5], [5.0, 5.0, 0.3], [-4.2, 0.1, -1.4]]);

    // The shipped weights, compiled into the library (a program that never calls
    // `Model::shipped` does not carry them). Weights of your own, from memory:
    // `Model::from_bytes(&bytes, std::path::Path::new("my.p2qm"))`.
    let model = Model::shipped()?;

    // Defaults: the shipped pipeline (threshold 0.5, post-process, second pass).
    let mesh = reconstruct(&points, &model, &ReconstructConfig::default())?;
    // The input points come back first, bit for bit; hole filling may append vertices.
    assert_eq!(&mesh.vertices[..points.len()], &points[..]);
    println!("{} points -> {} vertices, {} quads", points.len(), mesh.vertices.len(), mesh.quads.len());

    // With each stage's time as it ends (0 s on wasm32, which has no clock) and the
    // report the CLI's summary line is made from; several models average their
    // probabilities (an ensemble). A closed mesh on request:
    // `ReconstructConfig { watertight: Some(Default::default()), ..Default::default() }`.
    let (_, report) = reconstruct_observed(&points, &[&model], &ReconstructConfig::default(), &mut |s| {
        println!("  pass {} {:<18} {:.3} s", s.pass, s.stage, s.seconds)
    })?;
    println!("{} candidates, {} predicted real", report.candidates, report.predicted);
    Ok(())
}
