//! Upper bounds on the numeric CLI options that size work (`candidates --k/--per-point`,
//! `reconstruct --k`, `dataset --synthetic`, `train --epochs`): the bound itself is accepted, one past it
//! (and a 20-digit value) is a usage error (exit 2) naming the option, the bounds and the
//! value, before any file is read or written.

#[path = "common/candidates.rs"]
mod cands_common;
#[path = "common/scratch.rs"]
mod scratch;

use std::process::{Command, Output};

use cands_common::rows_lattice;
use scratch::Scratch;

fn p2q(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_point2quad")).args(args).output().expect("test: run the binary")
}

/// A gently curved 6 × 5 sheet of points, as .xyz text (small: at k = 64 every point
/// sees the whole sheet, and C(29, 3) triples per point keep the test quick).
fn sheet() -> String {
    let mut s = String::new();
    for j in 0..5 {
        for i in 0..6 {
            let (x, y) = (i as f64 * 0.1, j as f64 * 0.1);
            s.push_str(&format!("{x} {y} {}\n", 0.05 * (x * 3.0).sin()));
        }
    }
    s
}

#[test]
fn work_sizing_options_are_bounded() {
    let dir = Scratch::new("cli_bounds");
    let c = &dir.write("sheet.xyz", sheet().as_bytes());
    let (cand, mesh, ds) = (dir.p("c.txt"), dir.p("m.obj"), dir.p("ds"));
    let huge = "18446744073709551615"; // usize::MAX: `8 * per_point` overflowed before
    let before = dir.entries();
    let refused: Vec<(Vec<&str>, &str, &str)> = vec![
        (vec!["candidates", c, "-o", &cand, "--k", "65"], "--k must be between 3 and 64", "65"),
        (
            vec!["dataset", "--out", &ds, "--synthetic", "1", "--min-aspect", "0.01"],
            "--min-aspect must be between 0.05 and 1",
            "0.01",
        ),
        (
            vec!["dataset", "--out", &ds, "--synthetic", "1", "--min-aspect", "nan"],
            "--min-aspect must be between 0.05 and 1",
            // Echoed as typed (session 24).
            "nan",
        ),
        (vec!["candidates", c, "-o", &cand, "--k", "2"], "--k must be between 3 and 64", "2"),
        (vec!["candidates", c, "-o", &cand, "--k", huge], "--k must be between 3 and 64", huge),
        (
            vec!["candidates", c, "-o", &cand, "--per-point", "1025"],
            "--per-point must be between 1 and 1024",
            "1025",
        ),
        (
            vec!["candidates", c, "-o", &cand, "--per-point", "0"],
            "--per-point must be between 1 and 1024",
            "0",
        ),
        (
            vec!["candidates", c, "-o", &cand, "--per-point", huge],
            "--per-point must be between 1 and 1024",
            huge,
        ),
        (
            vec!["candidates", c, "-o", &cand, "--continue-rank", "1001"],
            "--continue-rank must be between 0 and 1000",
            "1001",
        ),
        (
            vec!["reconstruct", c, "-o", &mesh, "--continue-rank", huge],
            "--continue-rank must be between 0 and 1000",
            huge,
        ),
        (vec!["reconstruct", c, "-o", &mesh, "--k", "65"], "--k must be between 3 and 64", "65"),
        (vec!["reconstruct", c, "-o", &mesh, "--rounds", "9"], "--rounds must be between 0 and 8", "9"),
        (vec!["candidates", c, "-o", &cand, "--far", "65"], "--far must be between 0 and 64", "65"),
        (vec!["reconstruct", c, "-o", &mesh, "--far", huge], "--far must be between 0 and 64", huge),
        (
            vec!["dataset", "--out", &ds, "--synthetic", "1", "--far", "65"],
            "--far must be between 0 and 64",
            "65",
        ),
        (
            vec!["reconstruct", c, "-o", &mesh, "--per-point", "0"],
            "--per-point must be between 1 and 1024",
            "0",
        ),
        (
            vec!["reconstruct", c, "-o", &mesh, "--per-point", "1025"],
            "--per-point must be between 1 and 1024",
            "1025",
        ),
        (vec!["reconstruct", c, "-o", &mesh, "--k", huge], "--k must be between 3 and 64", huge),
        (
            vec!["dataset", "--out", &ds, "--synthetic", "1", "--per-point", "0"],
            "--per-point must be between 1 and 1024",
            "0",
        ),
        (
            vec!["dataset", "--out", &ds, "--synthetic", "1", "--per-point", "1025"],
            "--per-point must be between 1 and 1024",
            "1025",
        ),
        (
            vec!["dataset", "--out", &ds, "--synthetic", "100001"],
            "--synthetic must be between 0 and 100000",
            "100001",
        ),
        (
            vec!["train", "--data", &ds, "--out", &mesh, "--epochs", "100001"],
            "--epochs must be between 1 and 100000",
            "100001",
        ),
        (
            vec!["train", "--data", &ds, "--out", &mesh, "--epochs", "0"],
            "--epochs must be between 1 and 100000",
            "0",
        ),
        (
            vec!["dataset", "--out", &ds, "--synthetic", huge],
            "--synthetic must be between 0 and 100000",
            huge,
        ),
    ];
    for (args, msg, value) in &refused {
        let out = p2q(args);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(msg) && err.contains(&format!("got {value}")), "{args:?}: {err}");
        assert!(!err.contains("panicked"), "{args:?}: {err}");
        assert_eq!(dir.entries(), before, "{args:?}: files left behind");
    }
    // The bounds themselves are accepted and do the work.
    for args in [
        vec!["candidates", c, "-o", &cand, "--k", "64", "--per-point", "1024"],
        vec!["candidates", c, "-o", &cand, "--k", "3", "--per-point", "1"],
    ] {
        let out = p2q(&args);
        assert!(out.status.success(), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
        let text = std::fs::read_to_string(&cand).expect("test: candidates written");
        for line in text.lines() {
            let idx: Vec<usize> = line.split(' ').map(|t| t.parse().expect("test: index")).collect();
            assert!(idx.len() == 4 && idx.iter().all(|&i| i < 30), "{line}");
        }
    }
}

/// `reconstruct --small-cloud-rounds P,N` (session 34): malformed or out-of-range values
/// are usage errors that write nothing; a cloud of fewer than P points gives what
/// `--rounds N` gives, one of P points what no limit gives.
#[test]
fn small_cloud_rounds_is_checked_and_limits_small_clouds() {
    let dir = Scratch::new("cli_small_cloud");
    let c = &dir.write("sheet.xyz", sheet().as_bytes());
    let mesh = dir.p("m.obj");
    let before = dir.entries();
    for bad in ["200", "0,5", "200,9", "a,5", "200,", ",5", "-1,5", "200,5,1"] {
        let out = p2q(&["reconstruct", c, "-o", &mesh, "--small-cloud-rounds", bad]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{bad}: {err}");
        assert!(err.contains(&format!("--small-cloud-rounds {bad}: expected P,N")), "{bad}: {err}");
        assert_eq!(dir.entries(), before, "{bad}: files left behind");
    }
    // A noisy torus, where the rounds change the faces (on the sheet they do not).
    let torus = dir.p("torus.xyz");
    let out = p2q(&["synth", "--shape", "torus", "--seed", "1", "-o", &torus]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let n = std::fs::read_to_string(&torus).expect("test: cloud").lines().count();
    let run = |name: &str, opts: &[&str]| -> Vec<u8> {
        let path = dir.p(name);
        let mut args = vec!["reconstruct", torus.as_str(), "-o", &path];
        args.extend_from_slice(opts);
        let out = p2q(&args);
        assert!(out.status.success(), "{opts:?}: {}", String::from_utf8_lossy(&out.stderr));
        std::fs::read(&path).expect("test: mesh written")
    };
    let (all, none, two) =
        (run("d.obj", &[]), run("b.obj", &["--rounds", "0"]), run("f.obj", &["--rounds", "2"]));
    assert!(
        all != none && all != two && none != two,
        "the rounds change nothing here: the checks could not fail"
    );
    // Small: P above the point count. Not small: P at half of it (the second pass
    // scores the cloud without the points it takes for noise, so P = n would catch it).
    let (small, not_small) = (format!("{},0", n + 1), format!("{},0", n / 2));
    assert_eq!(run("a.obj", &["--small-cloud-rounds", &small]), none);
    assert_eq!(run("c.obj", &["--small-cloud-rounds", &not_small]), all);
    assert_eq!(run("e.obj", &["--small-cloud-rounds", &format!("{},2", n + 1)]), two);
    // `off` lifts the limit (the default's 200 points do not reach this cloud).
    assert_eq!(run("g.obj", &["--small-cloud-rounds", "off"]), all);
}

/// `reconstruct --per-point` (session 23) sizes the candidate budget as `candidates`
/// does: the summary line counts the same candidates as `candidates --per-point`.
#[test]
fn reconstruct_per_point_sets_the_budget() {
    let dir = Scratch::new("cli_per_point");
    let c = &dir.write("sheet.xyz", sheet().as_bytes());
    let count = |pp: &str| -> (usize, usize) {
        let (mesh, cand) = (dir.p(&format!("m{pp}.obj")), dir.p(&format!("c{pp}.txt")));
        let out = p2q(&["reconstruct", c, "-o", &mesh, "--per-point", pp]);
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        let err = String::from_utf8_lossy(&out.stderr).to_string();
        let n =
            err.split(" candidates").next().and_then(|h| h.rsplit(' ').next()).and_then(|t| t.parse().ok());
        let out = p2q(&["candidates", c, "-o", &cand, "--per-point", pp]);
        assert!(out.status.success());
        (
            n.unwrap_or_else(|| panic!("no candidate count in {err}")),
            std::fs::read_to_string(&cand).unwrap().lines().count(),
        )
    };
    let (one, one_cli) = count("1");
    let (many, many_cli) = count("64");
    assert_eq!((one, many), (one_cli, many_cli));
    assert!(one < many, "{one} vs {many}");
}

/// The lines `point2quad candidates CLOUD -o … OPTIONS` writes (it must succeed).
fn candidate_lines(dir: &Scratch, cloud: &str, options: &[&str]) -> std::collections::BTreeSet<String> {
    let cand = dir.p(&format!("c{}.txt", options.join("_").replace('-', "")));
    let mut args = vec!["candidates", cloud, "-o", &cand];
    args.extend_from_slice(options);
    let out = p2q(&args);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    std::fs::read_to_string(&cand).expect("test: candidates written").lines().map(str::to_string).collect()
}

/// `--continue-rank` adds candidates and keeps every one found without it (a budget of
/// one per point leaves the continuation something to find on the sheet).
#[test]
fn continuation_adds_candidates_from_the_cli() {
    let dir = Scratch::new("cli_continue");
    let c = &dir.write("sheet.xyz", sheet().as_bytes());
    let lines = |rank: &str| candidate_lines(&dir, c, &["--per-point", "1", "--continue-rank", rank]);
    let (off, on) = (lines("0"), lines("1"));
    assert!(off.is_subset(&on), "continuation dropped candidates");
    assert!(on.len() > off.len(), "nothing added: {} vs {}", on.len(), off.len());
}

/// `--far` (session 29) adds candidates and keeps every one found without it, on a
/// jittered lattice of 1 × 5 cells, most of which lie beyond the 8 nearest (`--k 8`).
#[test]
fn far_completion_adds_candidates_from_the_cli() {
    let dir = Scratch::new("cli_far");
    let text: String =
        rows_lattice(60, 12, 5.0).iter().map(|p| format!("{} {} {}\n", p[0], p[1], p[2])).collect();
    let c = &dir.write("rows.xyz", text.as_bytes());
    let lines = |far: &str| candidate_lines(&dir, c, &["--k", "8", "--continue-rank", "0", "--far", far]);
    let (off, on) = (lines("0"), lines("4"));
    assert!(off.is_subset(&on), "far completion dropped candidates");
    assert!(on.len() > off.len() + 100, "too little added: {} vs {}", on.len(), off.len());
}

/// Sample files of a dataset: (file name, bytes), sorted by name.
type Files = Vec<(std::path::PathBuf, Vec<u8>)>;

/// `dataset --synthetic 2 --seed 3` into a folder of `dir` named after `value`, with
/// `option value` when `value` is given: the folder and its sample files.
fn small_dataset(dir: &Scratch, option: &str, value: Option<&str>) -> (String, Files) {
    let out_dir = dir.p(&format!("ds{}", value.unwrap_or("default")));
    let mut args = vec!["dataset", "--out", &out_dir, "--synthetic", "2", "--seed", "3"];
    if let Some(v) = value {
        args.extend([option, v]);
    }
    let out = p2q(&args);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let mut files: Files = std::fs::read_dir(&out_dir)
        .expect("test: list")
        .map(|e| e.expect("test: entry").path())
        .filter(|p| p.extension().is_some_and(|x| x == "p2qs"))
        .map(|p| (p.file_name().expect("test: name").into(), std::fs::read(&p).expect("test: sample")))
        .collect();
    files.sort();
    (out_dir, files)
}

/// `dataset --corner-start` (session 30): `least` is the default (byte-identical files),
/// `index` gives other samples (the same candidates started elsewhere), anything else is
/// a usage error naming the option.
#[test]
fn dataset_corner_start_is_an_option() {
    let dir = Scratch::new("cli_dataset_corner_start");
    let files = |start: Option<&str>| small_dataset(&dir, "--corner-start", start).1;
    let (d, least, index) = (files(None), files(Some("least")), files(Some("index")));
    assert_eq!((d.len(), index.len()), (2, 2));
    assert_eq!(d, least, "the default is not least");
    assert!(d.iter().zip(&index).all(|(a, b)| a.0 == b.0 && a.1 != b.1 && a.1.len() == b.1.len()));
    let out = p2q(&["dataset", "--out", &dir.p("bad"), "--synthetic", "1", "--corner-start", "first"]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--corner-start must be least or index"), "{err}");
}

/// `dataset --per-point` (session 27) sizes the samples' candidate budget as
/// `reconstruct --per-point` does: more candidates per sample for a larger budget, never
/// a lower coverage, and the default is 32 (its files are byte-identical to an explicit 32).
#[test]
fn dataset_per_point_sets_the_budget() {
    let dir = Scratch::new("cli_dataset_per_point");
    let index = |pp: Option<&str>| -> (Files, Vec<(usize, f64)>) {
        let (out_dir, files) = small_dataset(&dir, "--per-point", pp);
        let text = std::fs::read_to_string(format!("{out_dir}/index.txt")).expect("test: index written");
        let rows = text
            .lines()
            .filter(|l| !l.starts_with('#'))
            .map(|l| {
                let c: Vec<&str> = l.split('\t').collect();
                (c[2].parse().expect("test: candidates"), c[4].parse().expect("test: coverage"))
            })
            .collect();
        (files, rows)
    };
    let (d, default) = index(None);
    let (e, explicit) = index(Some("32"));
    let (_, small) = index(Some("1"));
    let (_, large) = index(Some("64"));
    assert_eq!((d, &default), (e, &explicit), "the default is not 32");
    assert_eq!(default.len(), 2);
    for i in 0..2 {
        assert!(small[i].0 < default[i].0 && default[i].0 < large[i].0, "{small:?} {default:?} {large:?}");
        assert!(small[i].1 <= default[i].1 && default[i].1 <= large[i].1, "{small:?} {default:?} {large:?}");
    }
}
