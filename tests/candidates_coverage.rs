//! Coverage of the candidate quads — the share of ground-truth faces whose vertex set
//! is among the candidates — on the shared `train/` meshes (clean, and with 10% noise
//! points from `pipeline::noise` at its default offset, seed 1) and on synthetic
//! shapes (`mesh::shapes`, every family, fixed seeds). Prints a table and asserts the
//! aggregate figures reached (a regression guard; see the asserts for the numbers).
//! `train/` only: `eval/` and `large/` are never used for tuning.
//!
//! Under `make test` the train measurement covers a deterministic subset (every 3rd
//! mesh in name order, 17 of 50) so the suite fits the CI budget; the subset has its
//! own measured thresholds. `P2Q_FULL_COVERAGE=1` (what `make coverage` sets) measures
//! all train meshes against the full-run thresholds.
//!
//! Run: `make coverage`, or
//! `P2Q_FULL_COVERAGE=1 cargo test --release --test candidates_coverage -- --ignored --nocapture`

#[path = "common/candidates.rs"]
mod cands_common;

use cands_common::*;
use point2quad::mesh::poly::QuadMesh;
use point2quad::mesh::shapes::{random_shape_of, Family};
use point2quad::pipeline::candidates::CandidateConfig;

/// Aggregate over meshes: (faces-weighted coverage, mean per-mesh coverage, candidates per point, worst mesh).
fn summarise(name: &str, rows: &[(String, Cov)]) -> (f64, f64, f64, f64) {
    let mut all = Cov::default();
    for (_, c) in rows {
        all.add(c);
    }
    let mean = rows.iter().map(|(_, c)| c.ratio()).sum::<f64>() / rows.len().max(1) as f64;
    let worst = rows.iter().map(|(_, c)| c.ratio()).fold(1.0f64, f64::min);
    println!(
        "{name}: coverage {:.4} (faces-weighted), {:.4} (mean of meshes), worst {:.4}; {:.2} candidates/point; generate {:.2} s total",
        all.ratio(),
        mean,
        worst,
        all.per_point(),
        all.secs
    );
    (all.ratio(), mean, all.per_point(), worst)
}

/// Coverage of `mesh`'s faces by the candidates of its vertices (clean) and of its
/// vertices plus 10% noise points (noisy, seed 1): one table row, one entry in each list.
fn measure(
    name: String,
    mesh: &QuadMesh,
    cfg: &CandidateConfig,
    clean: &mut Vec<(String, Cov)>,
    noisy: &mut Vec<(String, Cov)>,
) {
    let (c, _) = coverage(&mesh.vertices, &mesh.quads, cfg);
    let (n, _) = coverage(&noisy_cloud(mesh, 1), &mesh.quads, cfg);
    println!(
        "{name:24} {:7} {:9.4} {:7.2} | {:9.4} {:7.2}",
        c.faces,
        c.ratio(),
        c.per_point(),
        n.ratio(),
        n.per_point()
    );
    clean.push((name.clone(), c));
    noisy.push((name, n));
}

/// Prints the clean and noisy aggregates of `set` and asserts them against the floors
/// (and the candidates per point against [`MAX_PER_POINT`]).
fn check(set: &str, clean: &[(String, Cov)], noisy: &[(String, Cov)], clean_min: f64, noisy_min: f64) {
    let (c_all, _, c_pp, _) = summarise(&format!("{set} clean"), clean);
    let (n_all, _, n_pp, _) = summarise(&format!("{set} noisy"), noisy);
    assert!(c_all >= clean_min, "clean coverage {c_all:.4} < {clean_min}");
    assert!(n_all >= noisy_min, "noisy coverage {n_all:.4} < {noisy_min}");
    assert!(c_pp <= MAX_PER_POINT && n_pp <= MAX_PER_POINT, "{c_pp:.2} / {n_pp:.2} candidates per point");
}

/// Whether the full train measurement is asked for (`P2Q_FULL_COVERAGE` set to
/// anything but empty or `0`).
fn full_coverage() -> bool {
    std::env::var("P2Q_FULL_COVERAGE").is_ok_and(|v| !v.is_empty() && v != "0")
}

/// Every `SUBSET_STEP`-th train mesh (in name order, starting with the first) is
/// measured under `make test`.
const SUBSET_STEP: usize = 3;

/// The train meshes to measure (all with `P2Q_FULL_COVERAGE`, else the subset) and
/// whether that is all of them; `None` (and a note) when `../shared` is absent.
fn train_files() -> Option<(Vec<std::path::PathBuf>, bool)> {
    let Some(all_files) = mesh_files("train") else {
        println!("skipped: ../shared/data/quads/train not found");
        return None;
    };
    let full = full_coverage();
    Some((if full { all_files } else { all_files.into_iter().step_by(SUBSET_STEP).collect() }, full))
}

#[test]
#[ignore = "heavy: run in release by make test-heavy (about a minute on the subset; P2Q_FULL_COVERAGE=1: all 50 meshes)"]
fn coverage_on_train_meshes_clean_and_noisy() {
    let Some((files, full)) = train_files() else { return };
    let (clean_min, noisy_min) =
        if full { (CLEAN_MIN, NOISY_MIN) } else { (SUBSET_CLEAN_MIN, SUBSET_NOISY_MIN) };
    println!(
        "{} train meshes ({})",
        files.len(),
        if full { "all: P2Q_FULL_COVERAGE" } else { "subset: every 3rd; P2Q_FULL_COVERAGE=1 for all" }
    );
    let cfg = CandidateConfig::default();
    let (mut clean, mut noisy) = (Vec::new(), Vec::new());
    println!(
        "{:24} {:>7} {:>9} {:>7} | {:>9} {:>7}",
        "mesh", "faces", "clean", "cand/pt", "noisy", "cand/pt"
    );
    for path in &files {
        let name = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        measure(name, &load_quad_mesh(path), &cfg, &mut clean, &mut noisy);
    }
    check("train", &clean, &noisy, clean_min, noisy_min);
}

/// Far completion (`--far 4`, session 29; off by default) on the same train meshes: on
/// every mesh, clean and noisy, it covers every face the default covers (it only
/// adds), and the aggregates clear their own measured floors within the budget
/// of 24 candidates per point.
#[test]
#[ignore = "heavy: run in release by make test-heavy (about half a minute on the subset)"]
fn far_completion_coverage_on_train_meshes() {
    let Some((files, full)) = train_files() else { return };
    let (clean_min, noisy_min) =
        if full { (FAR_CLEAN_MIN, FAR_NOISY_MIN) } else { (FAR_SUBSET_CLEAN_MIN, FAR_SUBSET_NOISY_MIN) };
    let base = CandidateConfig::default();
    let far = CandidateConfig { far_per_point: 4, ..base.clone() };
    let (mut clean, mut noisy) = (Vec::new(), Vec::new());
    println!("{} train meshes, --far 4", files.len());
    for path in &files {
        let name = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        let mesh = load_quad_mesh(path);
        measure(name.clone(), &mesh, &far, &mut clean, &mut noisy);
        let (c0, _) = coverage(&mesh.vertices, &mesh.quads, &base);
        let (n0, _) = coverage(&noisy_cloud(&mesh, 1), &mesh.quads, &base);
        let (c1, n1) = (clean.last().expect("measured").1, noisy.last().expect("measured").1);
        assert!(c1.covered >= c0.covered && n1.covered >= n0.covered, "{name}: far completion lost faces");
    }
    let (c_all, _, c_pp, _) = summarise("train clean, --far 4", &clean);
    let (n_all, _, n_pp, _) = summarise("train noisy, --far 4", &noisy);
    assert!(c_all >= clean_min, "clean coverage {c_all:.4} < {clean_min}");
    assert!(n_all >= noisy_min, "noisy coverage {n_all:.4} < {noisy_min}");
    assert!(
        c_pp <= FAR_MAX_PER_POINT && n_pp <= FAR_MAX_PER_POINT,
        "{c_pp:.2} / {n_pp:.2} candidates per point"
    );
}

#[test]
#[ignore = "heavy: run in release by make test-heavy (under a minute)"]
fn coverage_on_synthetic_shapes_clean_and_noisy() {
    let cfg = CandidateConfig::default();
    let (mut clean, mut noisy) = (Vec::new(), Vec::new());
    for family in Family::ALL {
        for seed in 0..2u64 {
            let mut rng = point2quad::rng::Rng::new(1000 + seed);
            let mesh = random_shape_of(family, &mut rng);
            measure(format!("{}#{seed}", family.name()), &mesh, &cfg, &mut clean, &mut noisy);
        }
    }
    check("synthetic", &clean, &noisy, SYN_CLEAN_MIN, SYN_NOISY_MIN);
}

// Regression guards: the aggregates measured with `CandidateConfig::default()`
// (k = 20, 32 per proposer), rounded down. Measured: train clean 0.9750 at 9.94 per
// point, noisy 0.9595 at 10.59; synthetic clean 1.0000 at 9.52, noisy 0.9932 at 10.03.
// (The targets, 0.99 clean / 0.98 noisy on train, are not reached: see the
// "Known limits" in `pipeline::candidates`.)
const CLEAN_MIN: f64 = 0.97;
const NOISY_MIN: f64 = 0.955;
const SYN_CLEAN_MIN: f64 = 0.999;
const SYN_NOISY_MIN: f64 = 0.99;
const MAX_PER_POINT: f64 = 12.0;
// The same on the `make test` subset (every 3rd train mesh by name: 17 meshes, with
// qm_hedgehog_spikes, hence lower than the full run), rounded down. Measured: clean
// 0.9535 at 9.93 per point, noisy 0.9351 at 10.71.
const SUBSET_CLEAN_MIN: f64 = 0.95;
const SUBSET_NOISY_MIN: f64 = 0.935;
// `--far 4` (session 29), measured the same way, rounded down. Full train: clean 0.9790
// at 11.53 per point, noisy 0.9702 at 12.54 (the budget is 24); the subset: clean
// 0.9589 at 11.51, noisy 0.9465 at 12.65 (the default: 0.9535 / 0.9351).
const FAR_CLEAN_MIN: f64 = 0.978;
const FAR_NOISY_MIN: f64 = 0.97;
const FAR_SUBSET_CLEAN_MIN: f64 = 0.958;
const FAR_SUBSET_NOISY_MIN: f64 = 0.946;
const FAR_MAX_PER_POINT: f64 = 14.0;
