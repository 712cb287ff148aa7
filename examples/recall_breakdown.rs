//! Where the faces of a reconstruction are lost, stage by stage: for a ground-truth
//! quad mesh and a cloud whose first points are its vertices (as `point2quad synth
//! --from` writes it), counts the ground-truth faces that are not candidates, that the
//! classifier scores in each probability band, that the post-process refuses, and
//! those in the output; and the output's wrong faces by origin.
//!
//! `cargo run --release --example recall_breakdown -- MESH CLOUD.xyz [MODEL] [--support=W] [--threshold=T]`
//! (several MESH CLOUD pairs may follow one another; totals at the end).

use std::collections::{HashMap, HashSet};
use std::path::Path;

use point2quad::io::mesh_io::read_mesh;
use point2quad::io::points::read_points;
use point2quad::mesh::postprocess::postprocess;
use point2quad::pipeline::candidates::generate;
use point2quad::pipeline::features::face_input;
use point2quad::pipeline::frame::Frame;
use point2quad::pipeline::model::Model;
use point2quad::pipeline::reconstruct::ReconstructConfig;

fn key(f: &[u32]) -> [u32; 4] {
    let mut k = [f[0], f[1], f[2], f[3]];
    k.sort_unstable();
    k
}

fn main() -> point2quad::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let files: Vec<&String> = args.iter().filter(|a| !a.starts_with("--")).collect();
    let model_path = files.iter().find(|f| f.ends_with(".p2qm")).map(|s| s.as_str());
    let model = Model::load(Path::new(model_path.unwrap_or("fixtures/point2quad-default.p2qm")))?;
    let pairs: Vec<&&String> = files.iter().filter(|f| !f.ends_with(".p2qm")).collect();
    let mut cfg = ReconstructConfig::default();
    for a in &args {
        if let Some(w) = a.strip_prefix("--support=") {
            cfg.postprocess.support_weight = w.parse().expect("--support=W");
        }
        if a == "--no-score-filter" {
            cfg.postprocess.score_filter = false;
        }
        if let Some(w) = a.strip_prefix("--score-limit=") {
            cfg.postprocess.score_limit = w.parse().expect("--score-limit=L");
        }
        if let Some(w) = a.strip_prefix("--threshold=") {
            cfg.threshold = w.parse().expect("--threshold=T");
        }
    }
    let bands = [0.0f32, 0.1, 0.2, 0.3, 0.4, 0.5];
    let mut total = [0usize; 12];
    println!("mesh | GT faces | not cand | p≤.1 | .1–.2 | .2–.3 | .3–.4 | .4–.5 | p>.5 lost | out (p>.5) | out (p≤.5, refilled) | out (not cand., filled) | wrong out");
    for pair in pairs.chunks(2) {
        let gt = read_mesh(Path::new(pair[0].as_str()))?;
        let pts = read_points(Path::new(pair[1].as_str()))?;
        let frame = Frame::fit(&pts)?;
        let local = frame.to_local_all(&pts);
        let cands = generate(&local, &cfg.candidates)?;
        let x = face_input(&local, &cands, model.config().use_context);
        let probs = model.predict_with_points(&local, &cands.quads, &x)?;
        let prob_of: HashMap<[u32; 4], f32> =
            cands.quads.iter().zip(&probs).map(|(q, &p)| (key(q), p)).collect();
        let (mut faces, mut fp) = (vec![], vec![]);
        for (q, &p) in cands.quads.iter().zip(&probs) {
            if p > cfg.threshold {
                faces.push(*q);
                fp.push(p);
            }
        }
        let (mesh, _) = postprocess(&pts, &faces, &fp, &cfg.postprocess)?;
        let out: HashSet<[u32; 4]> = mesh.quads.iter().map(|q| key(q)).collect();
        let gtk: HashSet<[u32; 4]> = gt.faces.iter().filter(|f| f.len() == 4).map(|f| key(f)).collect();
        let mut row = vec![0usize; 12];
        row[0] = gtk.len();
        for k in &gtk {
            match prob_of.get(k) {
                None => row[1] += 1,
                Some(&p) if p <= 0.5 => {
                    let b = bands.iter().rposition(|&t| p > t).unwrap_or(0);
                    if out.contains(k) {
                        row[9] += 1;
                    } else {
                        row[2 + b] += 1;
                    }
                }
                Some(_) => {
                    if out.contains(k) {
                        row[8] += 1;
                    } else {
                        row[7] += 1;
                    }
                }
            }
        }
        for q in &out {
            if !gtk.contains(q) {
                row[11] += 1;
            }
            if !prob_of.contains_key(q) && gtk.contains(q) {
                row[10] += 1;
            }
        }
        let name = Path::new(pair[0].as_str())
            .file_stem()
            .map(|s| s.to_string_lossy().to_string())
            .unwrap_or_default();
        println!("{name} | {}", row.iter().map(|v| v.to_string()).collect::<Vec<_>>().join(" | "));
        for (t, r) in total.iter_mut().zip(&row) {
            *t += r;
        }
    }
    println!("TOTAL | {}", total.iter().map(|v| v.to_string()).collect::<Vec<_>>().join(" | "));
    let right = (total[8] + total[9] + total[10]) as f64;
    println!("face-weighted: P {:.4} R {:.4}", right / (right + total[11] as f64), right / total[0] as f64);
    Ok(())
}
