//! Half-edge insertion benchmark (`HalfedgeMesh::insert_faces`, the core of the
//! post-process's step (b)) and the whole post-process on a noisy soup.
//!
//! Prints, each the median wall time of several runs after a warm-up:
//! - `bench mesh_insert_sphere_ordered <ms> ms`: the 21,600 quads of `cube_sphere(60)` in
//!   index order (neighbours mostly arrive next to each other);
//! - `bench mesh_insert_sphere_shuffled <ms> ms`: the same quads, each reversed with
//!   probability 1/2, in a random order (seed 0): many faces wait for neighbours and many
//!   patches are flipped to agree;
//! - `bench mesh_insert_cage_shuffled <ms> ms`: a random voxel cage (seed 3, 24 × 24 × 12
//!   cells, half filled: tunnels, valence 3–6 corners), shuffled and reversed the same way;
//! - `bench postprocess_soup <ms> ms`: `postprocess` (score filter, insertion by probability,
//!   hole filling) of a soup over `cube_sphere(40)` (9,600 quads): 3% of the true faces
//!   dropped, 20% wrong quads added (fins on true edges, corners moved to other vertices).
//!
//! A checksum of each result goes to stderr so that runs can be compared.

use point2quad::mesh::halfedge::HalfedgeMesh;
use point2quad::mesh::postprocess::{postprocess, PostprocessConfig};
use point2quad::mesh::shapes;
use point2quad::rng::Rng;
use std::hint::black_box;

#[path = "common/mod.rs"]
mod common;
use common::median_ms;

const RUNS: usize = 9;

/// Faces reversed at random and a random insertion order.
fn shuffled(quads: &[[u32; 4]], rng: &mut Rng) -> (Vec<[u32; 4]>, Vec<usize>) {
    let faces: Vec<[u32; 4]> =
        quads.iter().map(|&f| if rng.below(2) == 0 { f } else { [f[0], f[3], f[2], f[1]] }).collect();
    let mut order: Vec<usize> = (0..faces.len()).collect();
    rng.shuffle(&mut order);
    (faces, order)
}

/// Times `insert_faces` into a fresh mesh and reports the faces it kept.
fn bench_insert(name: &str, n_vertices: usize, faces: &[[u32; 4]], order: &[usize]) {
    let ms = median_ms(RUNS, || {
        let mut m = HalfedgeMesh::new(n_vertices);
        black_box(m.insert_faces(black_box(faces), black_box(order)));
    });
    let mut m = HalfedgeMesh::new(n_vertices);
    let out = m.insert_faces(faces, order);
    eprintln!("{name}: {} of {} faces inserted, {} refused", m.n_faces(), faces.len(), out.refused.len());
    println!("bench {name} {ms:.2} ms");
}

fn main() {
    let sphere = shapes::cube_sphere(60);
    let order: Vec<usize> = (0..sphere.quads.len()).collect();
    bench_insert("mesh_insert_sphere_ordered", sphere.vertices.len(), &sphere.quads, &order);
    let (faces, order) = shuffled(&sphere.quads, &mut Rng::new(0));
    bench_insert("mesh_insert_sphere_shuffled", sphere.vertices.len(), &faces, &order);
    let cage = shapes::voxel_cage(&mut Rng::new(3), [24, 24, 12], 0.5);
    let (faces, order) = shuffled(&cage.quads, &mut Rng::new(0));
    bench_insert("mesh_insert_cage_shuffled", cage.vertices.len(), &faces, &order);

    let m = shapes::cube_sphere(40);
    let mut rng = Rng::new(1);
    let nv = m.vertices.len();
    let mut soup: Vec<([u32; 4], f32)> = Vec::new();
    for &f in &m.quads {
        if rng.f64() >= 0.03 {
            soup.push((f, 0.5 + 0.5 * rng.f32()));
        }
    }
    for _ in 0..m.quads.len() / 5 {
        let g = m.quads[rng.below(m.quads.len())];
        let i = rng.below(4);
        let f = if rng.below(2) == 0 {
            [g[i], g[(i + 1) % 4], rng.below(nv) as u32, rng.below(nv) as u32]
        } else {
            let mut f = g;
            f[i] = rng.below(nv) as u32;
            f
        };
        soup.push((f, 0.7 * rng.f32()));
    }
    rng.shuffle(&mut soup);
    let faces: Vec<[u32; 4]> = soup.iter().map(|x| x.0).collect();
    let probs: Vec<f32> = soup.iter().map(|x| x.1).collect();
    let cfg = PostprocessConfig::default();
    let ms = median_ms(RUNS, || {
        black_box(postprocess(&m.vertices, black_box(&faces), &probs, &cfg).ok());
    });
    match postprocess(&m.vertices, &faces, &probs, &cfg) {
        Ok((qm, rep)) => eprintln!("postprocess_soup: {} faces out: {rep:?}", qm.quads.len()),
        Err(e) => eprintln!("postprocess_soup: {e}"),
    }
    println!("bench postprocess_soup {ms:.2} ms");
}
