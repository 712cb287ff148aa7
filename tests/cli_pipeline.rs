//! The `point2quad` binary end to end on tiny data (synth → dataset → train →
//! reconstruct → eval), and its errors: damaged `--model` files, resuming from a
//! weights-only file, empty or missing folders, bad candidate inputs. Every failure
//! exits non-zero with a message naming the file, leaves no output, never panics.

#[path = "common/quality.rs"]
mod quality_common;
#[path = "common/scratch.rs"]
mod scratch;

use point2quad::mesh::halfedge::HalfedgeMesh;
use point2quad::mesh::poly::PolyMesh;
use point2quad::mesh::shapes;
use point2quad::mesh::validate::validate;
use std::path::Path;
use std::process::{Command, Output};

use quality_common::{parse_json, Json};
use scratch::Scratch;

/// Runs the binary; asserts no panic text whatever the outcome.
fn run(args: &[&str]) -> Output {
    let out = Command::new(env!("CARGO_BIN_EXE_point2quad"))
        .args(args)
        .env("RAYON_NUM_THREADS", "1")
        .output()
        .expect("test: run the binary");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!err.contains("panicked") && !err.contains("RUST_BACKTRACE"), "panic in {args:?}: {err}");
    out
}

fn ok(args: &[&str]) -> Output {
    let out = run(args);
    assert!(out.status.success(), "{args:?} failed: {}", String::from_utf8_lossy(&out.stderr));
    out
}

/// Runs a command that must fail with `code`; returns its stderr.
fn fails(args: &[&str], code: i32) -> String {
    let out = run(args);
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(code), "{args:?}: {err}");
    assert!(err.contains("error"), "{args:?}: no error message: {err}");
    err
}

/// The `.p2qs` file names in `dir`, sorted.
fn sample_files(dir: &str) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".p2qs"))
        .collect();
    v.sort();
    v
}

/// Writes three small quad meshes into `dir`.
fn write_meshes(dir: &str) {
    std::fs::create_dir_all(dir).unwrap();
    let meshes = [
        ("a_sphere", shapes::cube_sphere(4)),
        ("b_torus", shapes::torus(12, 6, 1.0, 0.4)),
        ("c_tube", shapes::cylinder(12, 5, 0.5, 1.0, false)),
    ];
    for (name, m) in meshes {
        point2quad::io::mesh_io::write_mesh(&Path::new(dir).join(format!("{name}.obj")), &PolyMesh::from(&m))
            .unwrap();
    }
}

/// `s/data`: the dataset of the three meshes of [`write_meshes`] (seed 3).
fn three_mesh_data(s: &Scratch) -> String {
    let meshes = s.p("meshes");
    write_meshes(&meshes);
    let data = s.p("data");
    ok(&["dataset", "--meshes", &meshes, "--out", &data, "--seed", "3"]);
    data
}

/// `train` for one epoch on `data` (no validation, 300 candidates a step) into `model`.
fn train_tiny(data: &str, model: &str, extra: &[&str]) -> Output {
    let mut args = vec![
        "train",
        "--data",
        data,
        "--out",
        model,
        "--epochs",
        "1",
        "--val-fraction",
        "0",
        "--max-candidates",
        "300",
    ];
    args.extend_from_slice(extra);
    ok(&args)
}

/// A weights file (1 epoch on three small meshes) and the data folder, in `s`.
fn trained(s: &Scratch) -> String {
    let data = three_mesh_data(s);
    let model = s.p("m.p2qm");
    let out = train_tiny(&data, &model, &[]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("epoch 1/1"), "no progress line: {err}");
    assert!(Path::new(&model).is_file() && Path::new(&format!("{model}.ckpt")).is_file());
    model
}

#[test]
fn synth_dataset_train_reconstruct_eval_end_to_end() {
    let s = Scratch::new("e2e");
    let model = trained(&s);
    let (cloud, gt) = (s.p("cloud.xyz"), s.p("gt.obj"));
    ok(&["synth", "--from", &s.p("meshes/a_sphere.obj"), "-o", &cloud, "--gt", &gt, "--seed", "5"]);
    let (mesh, svg) = (s.p("out.obj"), s.p("out.svg"));
    // One epoch on three tiny meshes predicts (almost) nothing real at 0.5, and an
    // empty prediction would only score 0; threshold 0 hands every candidate to the
    // post-process, which must still produce a valid mesh.
    let out = ok(&["reconstruct", &cloud, "-o", &mesh, "--model", &model, "--svg", &svg, "--threshold", "0"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("points") && err.contains("candidates") && err.contains("time"), "{err}");
    // The output: a valid manifold pure-quad mesh whose first vertices are the cloud's.
    let pts = point2quad::io::points::read_points(Path::new(&cloud)).unwrap();
    let pm = point2quad::io::mesh_io::read_mesh(Path::new(&mesh)).unwrap();
    assert!(pm.vertices.len() >= pts.len());
    assert_eq!(&pm.vertices[..pts.len()], &pts[..], "input points not written back exactly");
    let q = pm.to_quads().expect("pure quad");
    assert!(!q.quads.is_empty());
    validate(&HalfedgeMesh::from_quads(q.vertices.len(), &q.quads).expect("manifold")).expect("valid");
    assert!(std::fs::read_to_string(&svg).unwrap().contains("<svg"));
    let out = ok(&["eval", &mesh, "--gt", &gt, "--json"]);
    let json = parse_json(String::from_utf8_lossy(&out.stdout).trim()).expect("eval --json is JSON");
    assert!(matches!(json, Json::Obj(_)), "{json:?}");
    // The output's own figures are consistent with the file, and the GT figures exist.
    assert_eq!(json.get("quads").and_then(Json::num), Some(q.quads.len() as f64));
    assert_eq!(json.get("manifoldness").and_then(Json::num), Some(1.0));
    for key in ["precision", "recall", "chamfer"] {
        assert!(json.get(key).and_then(Json::num).is_some_and(f64::is_finite), "{key} in {json:?}");
    }
    // Raw path too.
    let raw = s.p("raw.off");
    ok(&["reconstruct", &cloud, "-o", &raw, "--model", &model, "--no-postprocess", "--threshold", "0.3"]);
    assert!(Path::new(&raw).is_file());
    // An ensemble of two copies of one model averages equal probabilities: the same mesh.
    let (one, two) = (s.p("one.obj"), s.p("two.obj"));
    ok(&["reconstruct", &cloud, "-o", &one, "--model", &model, "--threshold", "0.3"]);
    ok(&["reconstruct", &cloud, "-o", &two, "--model", &format!("{model},{model}"), "--threshold", "0.3"]);
    assert_eq!(std::fs::read(&one).unwrap(), std::fs::read(&two).unwrap());
}

#[test]
fn reconstruct_rejects_bad_model_files_and_writes_nothing() {
    let s = Scratch::new("badmodel");
    let model = trained(&s);
    let cloud = s.p("cloud.xyz");
    ok(&["synth", "--from", &s.p("meshes/b_torus.obj"), "-o", &cloud]);
    let good = std::fs::read(&model).unwrap();
    let mut flipped = good.clone();
    let mid = flipped.len() / 2;
    flipped[mid] ^= 0x40;
    let cases: [(&str, Vec<u8>); 5] = [
        ("truncated.p2qm", good[..good.len() / 3].to_vec()),
        ("short.p2qm", good[..good.len() - 1].to_vec()),
        ("corrupted.p2qm", flipped),
        ("empty.p2qm", Vec::new()),
        ("text.p2qm", b"v 0 0 0\nv 1 0 0\n".to_vec()),
    ];
    for (name, bytes) in cases {
        let path = s.p(name);
        std::fs::write(&path, bytes).unwrap();
        let out = s.p("never.obj");
        let err =
            fails(&["reconstruct", &cloud, "-o", &out, "--model", &path, "--svg", &s.p("never.svg")], 1);
        assert!(err.contains(name), "{name}: message does not name the file: {err}");
        assert!(
            !Path::new(&out).exists() && !Path::new(&s.p("never.svg")).exists(),
            "{name}: output left behind"
        );
    }
    // An ensemble member that is broken is named; an empty name in the list is a usage error.
    std::fs::write(s.p("cut.p2qm"), &good[..good.len() / 2]).unwrap();
    let err = fails(
        &["reconstruct", &cloud, "-o", &s.p("never.obj"), "--model", &format!("{model},{}", s.p("cut.p2qm"))],
        1,
    );
    assert!(err.contains("cut.p2qm"), "{err}");
    let err = fails(&["reconstruct", &cloud, "-o", &s.p("never.obj"), "--model", &format!("{model},")], 2);
    assert!(err.contains("empty name"), "{err}");
    assert!(!Path::new(&s.p("never.obj")).exists());
    // A model file that does not exist, and a folder.
    let err = fails(&["reconstruct", &cloud, "-o", &s.p("never.obj"), "--model", &s.p("missing.p2qm")], 1);
    assert!(err.contains("missing.p2qm"), "{err}");
    let err = fails(&["reconstruct", &cloud, "-o", &s.p("never.obj"), "--model", &s.p("meshes")], 1);
    assert!(err.contains("meshes"), "{err}");
    assert!(!Path::new(&s.p("never.obj")).exists());
    // Resuming from the weights-only file explains that the .ckpt is needed.
    let err = fails(
        &["train", "--data", &s.p("data"), "--out", &s.p("m2.p2qm"), "--epochs", "2", "--resume", &model],
        1,
    );
    assert!(err.contains(".ckpt") && err.contains("m.p2qm"), "{err}");
    assert!(!Path::new(&s.p("m2.p2qm")).exists());
    // Resuming from the checkpoint works and continues at epoch 2.
    let (data, ckpt) = (s.p("data"), format!("{model}.ckpt"));
    let resume = |out: &str, extra: &[&str]| {
        let args = ["train", "--data", &data, "--out", out, "--epochs", "2", "--val-fraction", "0"];
        let out = ok(&[&args[..], &["--max-candidates", "300", "--resume", &ckpt], extra].concat());
        String::from_utf8_lossy(&out.stderr).to_string()
    };
    let err = resume(&s.p("m2.p2qm"), &[]);
    assert!(err.contains("epoch 2/2") && !err.contains("epoch 1/2"), "{err}");
    assert!(!err.contains("note: --lr"), "{err}");
    // A rate given with --resume is taken, with a note that the run no longer continues
    // exactly (the checkpoint does not store it).
    let err = resume(&s.p("m3.p2qm"), &["--lr", "0.003"]);
    assert!(err.contains("note: --lr 0.003 with --resume"), "{err}");
}

#[test]
fn clean_errors_on_empty_and_missing_inputs() {
    let s = Scratch::new("errors");
    let empty = s.p("empty");
    std::fs::create_dir_all(&empty).unwrap();
    let err = fails(&["train", "--data", &empty, "--out", &s.p("m.p2qm"), "--epochs", "1"], 2);
    assert!(err.contains("empty") && err.contains("p2qs"), "{err}");
    for lr in ["inf", "nan", "0", "-1"] {
        let err = fails(&["train", "--data", &empty, "--out", &s.p("m.p2qm"), "--lr", lr], 2);
        assert!(err.contains("--lr"), "{lr}: {err}");
    }
    let err = fails(&["train", "--data", &s.p("nowhere"), "--out", &s.p("m.p2qm")], 1);
    assert!(err.contains("nowhere"), "{err}");
    let err = fails(&["dataset", "--meshes", &s.p("nowhere"), "--out", &s.p("d")], 1);
    assert!(err.contains("nowhere"), "{err}");
    assert!(!Path::new(&s.p("m.p2qm")).exists());
    // Candidates on bad point files.
    let cand = s.p("c.txt");
    let cases: [(&str, &str); 5] = [
        ("nan.xyz", "0 0 0\n1 0 0\nnan 1 0\n0 0 1\n1 1 1\n"),
        ("two.xyz", "0 0 0\n1 0 0\n"),
        ("blank.xyz", ""),
        ("words.xyz", "hello world\n"),
        ("same.xyz", "1 2 3\n1 2 3\n1 2 3\n1 2 3\n1 2 3\n"),
    ];
    for (name, text) in cases {
        let p = s.p(name);
        std::fs::write(&p, text).unwrap();
        let out = run(&["candidates", &p, "-o", &cand]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{name}: {err}");
        assert!(err.contains(name), "{name}: {err}");
        assert!(!Path::new(&cand).exists(), "{name}: output left behind");
    }
    let err = fails(&["candidates", &s.p("missing.xyz"), "-o", &cand], 1);
    assert!(err.contains("missing.xyz"), "{err}");
    // Reconstruct on the same bad clouds (with a model, so the cloud is what fails).
    let model = s.p("fresh.p2qm");
    let m = point2quad::pipeline::model::Model::new(
        point2quad::pipeline::model::ModelConfig::default_preset(),
        0,
    )
    .unwrap();
    point2quad::nn::checkpoint::save(Path::new(&model), &m.to_checkpoint(None)).unwrap();
    for name in ["nan.xyz", "two.xyz", "blank.xyz", "same.xyz"] {
        let out = s.p("r.obj");
        let err = fails(&["reconstruct", &s.p(name), "-o", &out, "--model", &model], 1);
        assert!(err.contains(name) || err.contains("point"), "{name}: {err}");
        assert!(!Path::new(&out).exists());
    }
}

#[test]
fn help_on_every_command() {
    for cmd in
        ["reconstruct", "candidates", "eval", "dataset", "train", "refine", "repair", "render", "synth"]
    {
        for flag in ["--help", "-h"] {
            let out = ok(&[cmd, flag]);
            let text = String::from_utf8_lossy(&out.stdout);
            assert!(text.starts_with(&format!("point2quad {cmd}")), "{cmd} {flag}: {text}");
            assert!(text.contains("USAGE"), "{cmd}: {text}");
        }
    }
    assert!(String::from_utf8_lossy(&ok(&["--help"]).stdout).contains("COMMANDS"));
    assert_eq!(run(&["bogus"]).status.code(), Some(2));
}

/// Runs the binary with its stderr a pipe whose reading end is already closed: every
/// progress or summary line then fails with EPIPE (Rust ignores SIGPIPE).
fn run_with_closed_stderr(args: &[&str]) -> std::process::ExitStatus {
    let mut child = Command::new(env!("CARGO_BIN_EXE_point2quad"))
        .args(args)
        .env("RAYON_NUM_THREADS", "1")
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("test: spawn");
    drop(child.stderr.take());
    child.wait().expect("test: wait")
}

#[test]
fn a_closed_stderr_does_not_kill_train_or_reconstruct() {
    // Regression: `eprint!` in the progress and summary lines panicked (exit 101) on
    // EPIPE, so `point2quad train ... 2>&1 | head` killed the training run.
    let s = Scratch::new("epipe");
    let meshes = s.p("meshes");
    write_meshes(&meshes);
    let data = s.p("data");
    ok(&["dataset", "--meshes", &meshes, "--out", &data]);
    let model = s.p("m.p2qm");
    let st = run_with_closed_stderr(&[
        "train",
        "--data",
        &data,
        "--out",
        &model,
        "--epochs",
        "2",
        "--val-fraction",
        "0",
        "--max-candidates",
        "200",
    ]);
    assert!(st.success(), "train: {st:?}");
    assert!(Path::new(&model).is_file());
    let cloud = s.p("c.xyz");
    ok(&["synth", "--from", &s.p("meshes/c_tube.obj"), "-o", &cloud]);
    let out = s.p("o.obj");
    let st = run_with_closed_stderr(&["reconstruct", &cloud, "-o", &out, "--model", &model]);
    assert!(st.success(), "reconstruct: {st:?}");
    assert!(Path::new(&out).is_file());
}

#[test]
fn reconstruct_bounds_k() {
    // Regression: --k 0..2 silently gave no candidates, and --k 100000 on 300 points
    // ran for over ten minutes (enumeration grows as k³).
    let s = Scratch::new("k");
    let cloud = s.p("c.xyz");
    ok(&["synth", "--shape", "cube", "-o", &cloud]);
    let model = s.p("fresh.p2qm");
    let m = point2quad::pipeline::model::Model::new(
        point2quad::pipeline::model::ModelConfig::default_preset(),
        0,
    )
    .unwrap();
    point2quad::nn::checkpoint::save(Path::new(&model), &m.to_checkpoint(None)).unwrap();
    for k in ["0", "2", "65", "100000", "-1", "x"] {
        let out = s.p("o.obj");
        let err = fails(&["reconstruct", &cloud, "-o", &out, "--model", &model, "--k", k], 2);
        assert!(err.contains("--k"), "{k}: {err}");
        assert!(!Path::new(&out).exists());
    }
    ok(&["reconstruct", &cloud, "-o", &s.p("o.obj"), "--model", &model, "--k", "12"]);
    // Regression: an unwritable --svg failed after the mesh was written, leaving it.
    std::fs::remove_file(s.p("o.obj")).unwrap();
    let err = fails(
        &["reconstruct", &cloud, "-o", &s.p("o.obj"), "--model", &model, "--svg", &s.p("nodir/p.svg")],
        1,
    );
    assert!(err.contains("p.svg"), "{err}");
    assert!(!Path::new(&s.p("o.obj")).exists(), "mesh left behind");
}

/// `refine` of `rounds` rounds of width 4, one epoch, on the tiny data, with `extra`
/// options.
fn refine_tiny(data: &str, model: &str, out: &str, rounds: &str, extra: &[&str]) -> Output {
    let mut args = vec![
        "refine",
        "--data",
        data,
        "--model",
        model,
        "--out",
        out,
        "--rounds",
        rounds,
        "--widths",
        "4",
        "--epochs",
        "1",
        "--val-fraction",
        "0.5",
    ];
    args.extend_from_slice(extra);
    ok(&args)
}

/// `refine --precise-bn` (session 33): the refined model's classifier has the running
/// statistics the library computes over the training samples (here every sample: the
/// tiny data has no validation part), its weights are the base's, and they differ
/// from the base's statistics; a model with a point encoder is refused by name, and
/// the switch beside `--fold-models` as a usage error.
#[test]
fn refine_precise_bn_recomputes_the_classifiers_statistics() {
    use point2quad::pipeline::model::Model;
    let s = Scratch::new("precise");
    let model = trained(&s);
    let data = s.p("data");
    let refined = s.p("p.p2qm");
    let out = refine_tiny(&data, &model, &refined, "1", &["--precise-bn"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("batch-norm statistics of the classifier recomputed over 3 training samples"),
        "{err}"
    );
    let got = Model::load(Path::new(&refined)).unwrap();
    let base = Model::load(Path::new(&model)).unwrap();
    let mut want = Model::load(Path::new(&model)).unwrap();
    let fin = base.config().face_in();
    let mut files: Vec<_> = std::fs::read_dir(&data)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "p2qs"))
        .collect();
    files.sort();
    assert_eq!(files.len(), 3);
    let rows: Vec<Vec<f32>> = files
        .iter()
        .map(|f| {
            point2quad::pipeline::train::sample_input(
                &point2quad::pipeline::dataset::load_sample(f).unwrap(),
                fin,
            )
        })
        .collect();
    assert_eq!(want.precise_batch_norm(&rows, 12_000).unwrap(), 3);
    let mut running = 0;
    let mut moved = false;
    for id in base.params.ids() {
        let name = base.params.name(id);
        if name.starts_with("refine.") {
            continue;
        }
        let g = got.params.get(got.params.find(name).unwrap()).data();
        if name.contains(".running_") {
            running += 1;
            let w = want.params.get(id).data();
            for (a, b) in g.iter().zip(w) {
                assert!((a - b).abs() <= 1e-5 * (1.0 + b.abs()), "{name}: {a} against {b}");
            }
            moved |= g != base.params.get(id).data();
        } else {
            assert_eq!(g, base.params.get(id).data(), "{name}");
        }
    }
    assert!(running >= 2 && moved, "{running} buffers, moved {moved}");
    // Without the switch the statistics are the base's.
    let plain = s.p("plain.p2qm");
    refine_tiny(&data, &model, &plain, "1", &[]);
    let plain = Model::load(Path::new(&plain)).unwrap();
    for id in base.params.ids().filter(|&id| base.params.name(id).contains(".running_")) {
        let name = base.params.name(id);
        assert_eq!(
            plain.params.get(plain.params.find(name).unwrap()).data(),
            base.params.get(id).data(),
            "{name}"
        );
    }
    let kp = s.p("kp.p2qm");
    let m = Model::new(point2quad::pipeline::model::ModelConfig::default_kp(), 0).unwrap();
    point2quad::nn::checkpoint::save(Path::new(&kp), &m.to_checkpoint(None)).unwrap();
    let never = s.p("never.p2qm");
    let err = fails(&["refine", "--data", &data, "--model", &kp, "--out", &never, "--precise-bn"], 1);
    assert!(
        err.contains("--precise-bn") && err.contains("kp.p2qm") && err.contains("point encoder"),
        "{err}"
    );
    assert!(!Path::new(&never).exists());
    // With out-of-fold scorers BASE's statistics would not be what scores the rounds' data.
    let folds = format!("{model},{model}");
    let err = fails(
        &[
            "refine",
            "--data",
            &data,
            "--model",
            &model,
            "--out",
            &never,
            "--precise-bn",
            "--fold-models",
            &folds,
        ],
        2,
    );
    assert!(err.contains("--precise-bn") && err.contains("--fold-models"), "{err}");
    assert!(!Path::new(&never).exists());
}

/// `refine` end to end on the tiny data: the rounds train, the weights file is
/// written, `reconstruct --model` reads it and gives a valid mesh; bad options and
/// inputs are usage or data errors that write nothing.
#[test]
fn refine_trains_rounds_that_reconstruct_reads() {
    let s = Scratch::new("refine");
    let model = trained(&s);
    let data = s.p("data");
    let refined = s.p("r.p2qm");
    let out = refine_tiny(&data, &model, &refined, "2", &[]);
    let err = String::from_utf8_lossy(&out.stderr);
    // The tiny data has no validation samples: the rounds say so (session 20; they
    // printed validation figures of 0 before).
    assert!(
        err.contains("round 1:") && err.contains("round 2:") && err.contains("no validation samples"),
        "{err}"
    );
    let m = point2quad::pipeline::model::Model::load(Path::new(&refined)).unwrap();
    assert_eq!(m.config().refine_rounds, 2);
    assert_eq!(m.config().refine_widths, vec![4]);
    assert_eq!(m.config().refine_sides, point2quad::pipeline::refine::SideRule::Normals);
    // The flow columns by default (session 18); `--features base` gives the older input.
    assert_eq!(m.config().refine_input, point2quad::pipeline::refine::RefineInput::Flow);
    let base_refined = s.p("rb.p2qm");
    refine_tiny(&data, &model, &base_refined, "1", &["--features", "base"]);
    let mb = point2quad::pipeline::model::Model::load(Path::new(&base_refined)).unwrap();
    assert_eq!(mb.config().refine_input, point2quad::pipeline::refine::RefineInput::Base);
    assert!(!mb.config().to_text().contains("refine_input"), "{}", mb.config().to_text());
    let cloud = s.p("cloud.xyz");
    ok(&["synth", "--from", &s.p("meshes/b_torus.obj"), "-o", &cloud, "--seed", "2"]);
    let mesh = s.p("out.obj");
    ok(&["reconstruct", &cloud, "-o", &mesh, "--model", &refined, "--threshold", "0"]);
    let pm = point2quad::io::mesh_io::read_mesh(Path::new(&mesh)).unwrap();
    let q = pm.to_quads().expect("pure quad");
    validate(&HalfedgeMesh::from_quads(q.vertices.len(), &q.quads).expect("manifold")).expect("valid");
    // `--features inside` (session 23): its config line; reconstruct reads it, and
    // with `--rescue-lone` too.
    let inside = s.p("ri.p2qm");
    refine_tiny(&data, &model, &inside, "1", &["--features", "inside"]);
    let mi = point2quad::pipeline::model::Model::load(Path::new(&inside)).unwrap();
    assert_eq!(mi.config().refine_input, point2quad::pipeline::refine::RefineInput::Inside);
    for extra in [vec![], vec!["--rescue-lone", "0.3"]] {
        let args =
            [&["reconstruct", &cloud, "-o", &mesh, "--model", &inside, "--threshold", "0.2"][..], &extra]
                .concat();
        ok(&args);
        let q = point2quad::io::mesh_io::read_mesh(Path::new(&mesh)).unwrap().to_quads().expect("pure quad");
        validate(&HalfedgeMesh::from_quads(q.vertices.len(), &q.quads).expect("manifold")).expect("valid");
    }
    for v in ["nan", "-0.1", "1.5"] {
        let err = fails(&["reconstruct", &cloud, "-o", &s.p("never.obj"), "--rescue-lone", v], 2);
        assert!(err.contains("--rescue-lone"), "{v}: {err}");
    }
    for opt in ["--rescue-lone", "--rescue-min-prob"] {
        let err = fails(&["reconstruct", &cloud, "-o", &s.p("never.obj"), opt, "0.3", "--no-rescue"], 2);
        assert!(err.contains(opt) && err.contains("--no-rescue"), "{err}");
    }
    // `--rescue-keep-parity` (session 30, off by default): accepted, and refused beside
    // `--no-rescue`.
    ok(&["reconstruct", &cloud, "-o", &mesh, "--model", &refined, "--rescue-keep-parity"]);
    let q = point2quad::io::mesh_io::read_mesh(Path::new(&mesh)).unwrap().to_quads().expect("pure quad");
    validate(&HalfedgeMesh::from_quads(q.vertices.len(), &q.quads).expect("manifold")).expect("valid");
    let err =
        fails(&["reconstruct", &cloud, "-o", &s.p("never.obj"), "--rescue-keep-parity", "--no-rescue"], 2);
    assert!(err.contains("--rescue-keep-parity") && err.contains("--no-rescue"), "{err}");
    // Post-process settings with the post-process off were ignored without a word.
    let never_obj = s.p("never.obj");
    for opt in [
        &["--max-floater-faces", "2"][..],
        &["--rescue-min-prob", "0.3"],
        &["--rescue-keep-parity"],
        &["--no-close"],
        &["--no-untangle"],
        &["--no-unfold"],
    ] {
        let args = [&["reconstruct", &cloud, "-o", &never_obj, "--no-postprocess"][..], opt].concat();
        let err = fails(&args, 2);
        assert!(err.contains(opt[0]) && err.contains("no effect with --no-postprocess"), "{err}");
    }
    assert!(!Path::new(&s.p("never.obj")).exists());
    // Bad options: usage errors naming the option; nothing written.
    let never = s.p("never.p2qm");
    for (opt, val) in [
        ("--rounds", "0"),
        ("--rounds", "9"),
        ("--widths", "0"),
        ("--widths", "a,b"),
        ("--epochs", "0"),
        ("--batch", "0"),
        ("--lr", "nan"),
        ("--val-fraction", "1"),
        ("--sides", "left"),
        ("--features", "lattice"),
    ] {
        let err = fails(&["refine", "--data", &data, "--model", &model, "--out", &never, opt, val], 2);
        assert!(err.contains(opt), "{opt} {val}: {err}");
    }
    let err = fails(&["refine", "--data", &data, "--out", &never], 2);
    assert!(err.contains("--model"), "{err}");
    // The flow columns need the normals rule's neighbours.
    let err =
        fails(&["refine", "--data", &data, "--model", &model, "--out", &never, "--sides", "direction"], 2);
    assert!(err.contains("--features flow") && err.contains("--sides normals"), "{err}");
    let err = fails(
        &[
            "refine",
            "--data",
            &data,
            "--model",
            &model,
            "--out",
            &never,
            "--sides",
            "direction",
            "--features",
            "inside",
        ],
        2,
    );
    assert!(err.contains("--features inside") && err.contains("--sides normals"), "{err}");
    refine_tiny(&data, &model, &base_refined, "1", &["--features", "base", "--sides", "direction"]);
    let err = fails(&["refine", "--data", &data, "--model", &s.p("missing.p2qm"), "--out", &never], 1);
    assert!(err.contains("missing.p2qm"), "{err}");
    let err = fails(&["refine", "--data", &s.p("nowhere"), "--model", &model, "--out", &never], 1);
    assert!(err.contains("nowhere"), "{err}");
    assert!(!Path::new(&never).exists());
}

/// `point2quad eval MESH --json`'s figure `key`, after checking that `MESH` is a pure-quad
/// mesh that passes the half-edge validator.
fn valid_mesh_metric(mesh: &str, key: &str) -> f64 {
    let out = ok(&["eval", mesh, "--json"]);
    let json = parse_json(String::from_utf8_lossy(&out.stdout).trim()).unwrap();
    let q = point2quad::io::mesh_io::read_mesh(Path::new(mesh)).unwrap().to_quads().expect("pure quad");
    validate(&HalfedgeMesh::from_quads(q.vertices.len(), &q.quads).expect("manifold")).expect("valid");
    json.get(key).and_then(Json::num).unwrap()
}

/// The closing steps of the post-process: with the shipped weights on a noisy cloud of
/// a random synthetic shape (one whose reconstruction has holes), the default leaves no more border than the greedy fill alone (each step only
/// removes border), both outputs are valid, the summary says what was done, and bad
/// values of the new options are usage errors that write nothing.
#[test]
fn reconstruct_closing_options() {
    let s = Scratch::new("close");
    let cloud = s.p("cloud.xyz");
    let border = |mesh: &str| valid_mesh_metric(mesh, "boundary_edges");
    let (full, plain) = (s.p("full.obj"), s.p("plain.obj"));
    // The first of a few seeds whose reconstruction without the closing steps has holes
    // (which ones do depends on the shipped weights).
    let has_holes = |seed: &str| {
        ok(&["synth", "--shape", "random", "-o", &cloud, "--noise", "0.1", "--seed", seed]);
        ok(&["reconstruct", &cloud, "-o", &plain, "--no-rescue", "--no-close", "--max-floater-faces", "0"]);
        border(&plain) > 0.0
    };
    let seeds = ["5", "1", "2", "3", "4", "6", "7", "8", "9", "10", "11", "12"];
    assert!(seeds.iter().any(|seed| has_holes(seed)), "no case with holes among seeds {seeds:?}");
    let out = ok(&["reconstruct", &cloud, "-o", &full]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("rescued") && err.contains("loops closed") && err.contains("floater"), "{err}");
    let (b_full, b_plain) = (border(&full), border(&plain));
    assert!(b_full <= b_plain, "{b_full} > {b_plain}");
    // Untangling re-splits faces over the same vertices: same border, worst shape no worse.
    assert!(err.contains("badly shaped faces re-split"), "{err}");
    let tangled = s.p("tangled.obj");
    ok(&["reconstruct", &cloud, "-o", &tangled, "--no-untangle"]);
    assert_eq!(border(&tangled), b_full);
    let worst = |mesh: &str| {
        let out = ok(&["eval", mesh, "--json"]);
        let json = parse_json(String::from_utf8_lossy(&out.stdout).trim()).unwrap();
        json.get("scaled_jacobian_min").and_then(Json::num).unwrap()
    };
    assert!(worst(&full) >= worst(&tangled), "{} < {}", worst(&full), worst(&tangled));
    for (opt, v) in [("--rescue-min-prob", "1.5"), ("--rescue-min-prob", "x"), ("--max-floater-faces", "-1")]
    {
        let o = s.p("bad.obj");
        let err = fails(&["reconstruct", &cloud, "-o", &o, opt, v], 2);
        assert!(err.contains(opt), "{opt} {v}: {err}");
        assert!(!Path::new(&o).exists());
    }
}

/// `--no-inverted-fills` leaves a 4-edge hole open rather than close it with an inverted
/// quad, and `--no-seal` turns the seal off: both outputs are valid, the default one has
/// inverted quads here and the first none, and neither has a shorter border than the
/// default; the summary reports the seal.
#[test]
fn reconstruct_inverted_fills_and_seal_switches() {
    let s = Scratch::new("inverted");
    let cloud = s.p("cloud.xyz");
    let metrics =
        |mesh: &str| (valid_mesh_metric(mesh, "inverted_quads"), valid_mesh_metric(mesh, "boundary_edges"));
    let (full, no_inv, no_seal) = (s.p("full.obj"), s.p("no_inv.obj"), s.p("no_seal.obj"));
    // The first of a few seeds whose one-pass reconstruction has an inverted quad (which
    // ones do depends on the shipped weights; the second pass, on since session 26,
    // leaves none among them, so the switches are compared on one pass).
    let inverted = |seed: &str| {
        ok(&["synth", "--shape", "random", "-o", &cloud, "--noise", "0.1", "--seed", seed]);
        let out = ok(&["reconstruct", &cloud, "-o", &full, "--second-pass", "off"]);
        (metrics(&full).0 > 0.0).then(|| String::from_utf8_lossy(&out.stderr).to_string())
    };
    let seeds = ["4", "1", "2", "3", "5", "6", "7", "8", "9", "10", "11", "12"];
    let err = seeds.iter().find_map(|seed| inverted(seed));
    let err = err.unwrap_or_else(|| panic!("no case with inverted fills among seeds {seeds:?}"));
    assert!(err.contains("loops sealed"), "{err}");
    ok(&["reconstruct", &cloud, "-o", &no_inv, "--no-inverted-fills", "--second-pass", "off"]);
    ok(&["reconstruct", &cloud, "-o", &no_seal, "--no-seal", "--second-pass", "off"]);
    let ((inv_full, b_full), (inv_no, b_no), (_, b_no_seal)) =
        (metrics(&full), metrics(&no_inv), metrics(&no_seal));
    assert!(inv_full > 0.0);
    assert_eq!(inv_no, 0.0);
    assert!(b_no >= b_full, "{b_no} < {b_full}");
    assert!(b_no_seal >= b_full, "{b_no_seal} < {b_full}");
}

/// `reconstruct --second-pass` (session 26): both modes write a valid mesh, the summary
/// names the points left out, and the option's mistakes are usage errors that write
/// nothing (an unknown mode, a tau without a mode or out of range, either with
/// --no-postprocess).
#[test]
fn reconstruct_second_pass_option() {
    let s = Scratch::new("second_pass");
    let cloud = s.p("cloud.xyz");
    ok(&["synth", "--shape", "torus", "-o", &cloud, "--noise", "0.1", "--seed", "3"]);
    for mode in ["average", "replace"] {
        let mesh = s.p(&format!("{mode}.obj"));
        let out =
            ok(&["reconstruct", &cloud, "-o", &mesh, "--second-pass", mode, "--second-pass-tau", "0.3"]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains("second pass:") && err.contains("left out as noise"), "{err}");
        assert!(valid_mesh_metric(&mesh, "faces") > 0.0);
    }
    let one = s.p("one.obj");
    let out = ok(&["reconstruct", &cloud, "-o", &one, "--second-pass", "off"]);
    assert!(!String::from_utf8_lossy(&out.stderr).contains("second pass"));
    // The default is `average`, tau 0.25, the learned test (session 35).
    let (dflt, avg) = (s.p("default.obj"), s.p("avg.obj"));
    let out = ok(&["reconstruct", &cloud, "-o", &dflt]);
    assert!(String::from_utf8_lossy(&out.stderr).contains("second pass:"));
    let explicit =
        ["--second-pass", "average", "--second-pass-tau", "0.25", "--second-pass-cover", "learned"];
    ok(&[&["reconstruct", &cloud, "-o", &avg][..], &explicit].concat());
    assert_eq!(std::fs::read(&dflt).unwrap(), std::fs::read(&avg).unwrap());
    let never = s.p("never.obj");
    for (args, needle) in [
        (&["--second-pass", "both"][..], "expected average, replace or off"),
        (&["--second-pass", "off", "--second-pass-tau", "0.3"], "with --second-pass off"),
        (&["--second-pass", "off", "--second-pass-cover", "all"], "with --second-pass off"),
        (&["--second-pass", "average", "--second-pass-cover", "some"], "expected believed, all or learned"),
        (&["--second-pass", "average", "--second-pass-tau", "11"], "--second-pass-tau"),
        (&["--second-pass", "average", "--second-pass-tau", "nan"], "--second-pass-tau"),
        (&["--second-pass", "average", "--no-postprocess"], "no effect with --no-postprocess"),
        (&["--second-pass-cover", "all", "--no-postprocess"], "no effect with --no-postprocess"),
    ] {
        let argv = [&["reconstruct", &cloud, "-o", &never][..], args].concat();
        let err = fails(&argv, 2);
        assert!(err.contains(needle), "{args:?}: {err}");
    }
    assert!(!Path::new(&never).exists());
}

/// `reconstruct --drop-unused`: the output holds only the points some face uses, in
/// input order, with the same faces (compared by their corners' coordinates) as the
/// default output, whose unused points (noise, a duplicate, a far outlier) are isolated
/// vertices; `eval` scores both alike; with `--no-postprocess` too, and with
/// `--watertight`, whose added vertices follow the kept points.
#[test]
fn reconstruct_drop_unused_leaves_out_isolated_vertices() {
    let s = Scratch::new("drop_unused");
    // A noisy cloud plus a duplicate of its first point and a far outlier, both unused by
    // any face; returns the cloud's point count.
    let make = |cloud: &str, shape: &str, seed: &str| -> usize {
        ok(&["synth", "--shape", shape, "-o", cloud, "--noise", "0.1", "--seed", seed]);
        let text = std::fs::read_to_string(cloud).unwrap();
        let mut lines = text.lines().filter(|l| !l.starts_with('#') && !l.trim().is_empty());
        let first = lines.next().unwrap().to_string();
        std::fs::write(cloud, format!("{text}{first}\n1e9 1e9 1e9\n")).unwrap();
        lines.count() + 3
    };
    let read = |m: &str| point2quad::io::mesh_io::read_mesh(Path::new(m)).unwrap().to_quads().unwrap();
    let corners = |q: &point2quad::mesh::poly::QuadMesh| {
        let mut f: Vec<Vec<[u64; 3]>> = q
            .quads
            .iter()
            .map(|f| f.iter().map(|&v| q.vertices[v as usize].map(f64::to_bits)).collect())
            .collect();
        f.sort();
        f
    };
    let torus = s.p("torus.xyz");
    let n_torus = make(&torus, "torus", "5");
    // For --watertight, the first random shape whose closing adds vertices.
    let holed = s.p("holed.xyz");
    let probe = s.p("probe.obj");
    let n_holed = ["1", "2", "3", "4", "5", "6", "7", "8", "9", "10", "11", "12"]
        .iter()
        .map(|seed| make(&holed, "random", seed))
        .find(|&n| {
            ok(&["reconstruct", &holed, "-o", &probe, "--watertight"]);
            read(&probe).vertices.len() > n
        })
        .expect("no random shape among 12 seeds whose closing adds vertices");
    for (cloud, n_points, extra) in [
        (&torus, n_torus, &[][..]),
        (&torus, n_torus, &["--no-postprocess"][..]),
        (&holed, n_holed, &["--watertight"][..]),
    ] {
        let (full, compact) = (s.p("full.obj"), s.p("compact.obj"));
        ok(&[&["reconstruct", cloud, "-o", &full][..], extra].concat());
        let out = ok(&[&["reconstruct", cloud, "-o", &compact, "--drop-unused"][..], extra].concat());
        let (f, c) = (read(&full), read(&compact));
        let mut used = vec![false; f.vertices.len()];
        f.quads.iter().flatten().for_each(|&v| used[v as usize] = true);
        let unused = used.iter().filter(|u| !**u).count();
        assert!(unused >= 2, "{extra:?}: the test needs unused points ({unused})");
        // The kept vertices are the used ones, in order; every one is a corner.
        let kept: Vec<[f64; 3]> =
            f.vertices.iter().zip(&used).filter(|(_, u)| **u).map(|(v, _)| *v).collect();
        assert_eq!(c.vertices, kept, "{extra:?}");
        // Vertices the post-process or the closing added come last, all of them.
        let added = f.vertices.len() - n_points;
        assert_eq!(c.vertices[c.vertices.len() - added..], f.vertices[n_points..], "{extra:?}");
        let mut c_used = vec![false; c.vertices.len()];
        c.quads.iter().flatten().for_each(|&v| c_used[v as usize] = true);
        assert!(c_used.iter().all(|u| *u), "{extra:?}: an isolated vertex is left");
        assert_eq!(corners(&c), corners(&f), "{extra:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(&format!("--drop-unused: {unused} of {} vertices", f.vertices.len())), "{err}");
        if extra.is_empty() {
            let score = |m: &str| {
                let out = ok(&["eval", m, "--gt", &full, "--json"]);
                let j = parse_json(String::from_utf8_lossy(&out.stdout).trim()).unwrap();
                (j.get("precision").and_then(Json::num), j.get("recall").and_then(Json::num))
            };
            assert_eq!(score(&compact), (Some(1.0), Some(1.0)));
        }
    }
}

/// `train --init`: a fine-tune starts from the given weights (their config, epoch 1 of
/// its own count); a refined model's rounds are dropped with a message; combinations with
/// --resume or --config are usage errors, a missing file a data error naming it. And
/// `train --sign-free-normals` writes that flag into a fresh model's config.
#[test]
fn train_init_fine_tunes_from_weights() {
    let s = Scratch::new("init");
    let model = trained(&s);
    let data = s.p("data");
    let tuned = s.p("tuned.p2qm");
    let base = ["train", "--data", &data, "--out", &tuned, "--epochs", "1", "--val-fraction", "0"];
    let with =
        |extra: &[&str]| -> Vec<String> { base.iter().chain(extra.iter()).map(|x| x.to_string()).collect() };
    let args = with(&["--init", &model, "--max-candidates", "300", "--lr", "0.001"]);
    let out = ok(&args.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(String::from_utf8_lossy(&out.stderr).contains("epoch 1/1"));
    let (a, b) = (
        point2quad::pipeline::model::Model::load(Path::new(&model)).unwrap(),
        point2quad::pipeline::model::Model::load(Path::new(&tuned)).unwrap(),
    );
    assert_eq!(a.config(), b.config());
    // Trained further: some weight moved.
    let moved = a.params.ids().any(|id| a.params.get(id) != b.params.get(id));
    assert!(moved, "--init trained nothing");
    // From a refined model: its rounds go.
    let refined = s.p("r.p2qm");
    refine_tiny(&data, &model, &refined, "1", &[]);
    let args = with(&["--init", &refined, "--max-candidates", "300"]);
    let out = ok(&args.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(String::from_utf8_lossy(&out.stderr).contains("refinement rounds are dropped"));
    assert_eq!(
        point2quad::pipeline::model::Model::load(Path::new(&tuned)).unwrap().config().refine_rounds,
        0
    );
    for extra in [vec!["--init", &model, "--resume", "x.ckpt"], vec!["--init", &model, "--config", "default"]]
    {
        let args = with(&extra);
        let err = fails(&args.iter().map(String::as_str).collect::<Vec<_>>(), 2);
        assert!(err.contains("--init"), "{err}");
    }
    let missing = s.p("missing.p2qm");
    let args = with(&["--init", &missing]);
    let err = fails(&args.iter().map(String::as_str).collect::<Vec<_>>(), 1);
    assert!(err.contains("missing.p2qm"), "{err}");
    // --sign-free-normals: a fresh model that reads normals without their signs; with
    // --init or --resume (their file holds the config) a usage error.
    let args = with(&["--sign-free-normals", "--max-candidates", "300"]);
    ok(&args.iter().map(String::as_str).collect::<Vec<_>>());
    let sf = point2quad::pipeline::model::Model::load(Path::new(&tuned)).unwrap();
    assert!(sf.config().sign_free_normals && !a.config().sign_free_normals);
    let ckpt = format!("{tuned}.ckpt");
    for extra in
        [vec!["--sign-free-normals", "--init", &model], vec!["--sign-free-normals", "--resume", &ckpt]]
    {
        let args = with(&extra);
        let err = fails(&args.iter().map(String::as_str).collect::<Vec<_>>(), 2);
        assert!(err.contains("--sign-free-normals"), "{err}");
    }
}

/// `--hold-out` puts the named samples in validation for both `train` and `refine`
/// (the split the two share); a name no sample carries, or an empty name, is a usage
/// error that writes nothing.
#[test]
fn hold_out_names_whole_samples_for_train_and_refine() {
    let s = Scratch::new("holdout");
    let model = trained(&s);
    let data = s.p("data");
    let held = s.p("held.p2qm");
    let base = ["train", "--data", &data, "--out", &held, "--epochs", "1", "--max-candidates", "300"];
    let out = ok(&[&base[..], &["--val-fraction", "0", "--hold-out", "b_torus"]].concat());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("2 training / 1 validation samples"), "{err}");
    let out = ok(&[&base[..], &["--val-fraction", "0", "--hold-out", "a_sphere, c_tube"]].concat());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("1 training / 2 validation samples"), "{err}");
    let refined = s.p("r.p2qm");
    let refine =
        ["refine", "--data", &data, "--model", &model, "--out", &refined, "--widths", "4", "--epochs", "1"];
    let out = ok(&[&refine[..], &["--val-fraction", "0", "--hold-out", "c_tube"]].concat());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("2 training / 1 validation samples"), "{err}");
    let never = s.p("never.p2qm");
    for bad in ["d_cone", "a_sphere,,b_torus", ""] {
        for cmd in [&base[..], &refine[..]] {
            let mut args: Vec<&str> = cmd.to_vec();
            let o = args.iter().position(|a| *a == "--out").unwrap();
            args[o + 1] = &never;
            args.extend(["--hold-out", bad]);
            let err = fails(&args, 2);
            assert!(err.contains("--hold-out"), "{bad}: {err}");
            if bad == "d_cone" {
                assert!(err.contains("d_cone"), "{err}");
            }
        }
    }
    assert!(!Path::new(&never).exists());
}

/// `train --fold I/K` holds out one fold of the samples (a hash of the name, beside the
/// validation split), and `refine --fold-models` scores each training sample with the
/// model of its fold. The three samples fall into folds (of 3) 1, 2, 1; of 2, all in 1.
#[test]
fn folds_hold_out_samples_and_route_refinement_scoring() {
    let s = Scratch::new("folds");
    let model = trained(&s);
    let data = s.p("data");
    let other = s.p("other.p2qm");
    let base = ["train", "--data", &data, "--out", &other, "--epochs", "1", "--max-candidates", "300"];
    for (fold, want) in [
        ("0/3", "3 training / 0 validation samples"),
        ("1/3", "1 training / 2 validation samples"),
        ("2/3", "2 training / 1 validation samples"),
    ] {
        let out = ok(&[&base[..], &["--val-fraction", "0", "--fold", fold]].concat());
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(want), "--fold {fold}: {err}");
    }
    // A second classifier (another seed, all samples) for the routing check.
    ok(&[&base[..], &["--val-fraction", "0", "--seed", "9"]].concat());
    let refine = |out: &str, folds: Option<String>| {
        let mut args = vec!["refine", "--data", &data, "--model", &model, "--out", out];
        args.extend(["--widths", "4", "--epochs", "1", "--val-fraction", "0"]);
        let f;
        if let Some(v) = folds {
            f = v;
            args.extend(["--fold-models", &f]);
        }
        ok(&args);
        std::fs::read(out).unwrap()
    };
    let plain = refine(&s.p("plain.p2qm"), None);
    // Every sample is in fold 1 of 2: scored by the second model only.
    let same = refine(&s.p("same.p2qm"), Some(format!("{other},{model}")));
    assert_eq!(plain, same, "fold 1's model is BASE: the rounds must be those of a plain refine");
    let routed = refine(&s.p("routed.p2qm"), Some(format!("{model},{other}")));
    assert_ne!(plain, routed, "fold 1's model was not used to score fold 1");
    let never = s.p("never.p2qm");
    let signfree = s.p("signfree.p2qm");
    let mut sf: Vec<&str> = base.to_vec();
    sf[4] = &signfree;
    ok(&[&sf[..], &["--val-fraction", "0", "--sign-free-normals"]].concat());
    for (bad, what) in [
        (model.clone(), "2 to 16"),
        (format!("{model},"), "2 to 16"),
        (format!("{model},{signfree}"), "different input"),
    ] {
        let err =
            fails(&["refine", "--data", &data, "--model", &model, "--out", &never, "--fold-models", &bad], 2);
        assert!(err.contains("--fold-models") && err.contains(what), "{bad}: {err}");
    }
    for bad in ["2/2", "0/1", "1/17", "a/2", "1"] {
        let mut args: Vec<&str> = base.to_vec();
        args[4] = &never;
        args.extend(["--fold", bad]);
        let err = fails(&args, 2);
        assert!(err.contains("--fold"), "{bad}: {err}");
    }
    assert!(!Path::new(&never).exists());
}

/// `dataset --bumpy` writes samples under the same names, with
/// bent synthetic shapes; without it the files are those of the plain recipe.
#[test]
fn dataset_bumpy_switch_changes_only_the_synthetic_geometry() {
    let s = Scratch::new("bumpy");
    let (plain, bumpy, again) = (s.p("plain"), s.p("bumpy"), s.p("again"));
    ok(&["dataset", "--out", &plain, "--synthetic", "4", "--seed", "7"]);
    ok(&["dataset", "--out", &bumpy, "--synthetic", "4", "--seed", "7", "--bumpy"]);
    ok(&["dataset", "--out", &again, "--synthetic", "4", "--seed", "7"]);
    let files = sample_files;
    assert_eq!(files(&plain), files(&bumpy));
    let mut differ = 0;
    for f in files(&plain) {
        let read = |d: &str| std::fs::read(Path::new(d).join(&f)).unwrap();
        assert_eq!(read(&plain), read(&again), "{f}: not deterministic");
        if read(&plain) != read(&bumpy) {
            differ += 1;
        }
    }
    assert!(differ >= 1, "--bumpy changed no sample");
}

/// `dataset --coarsen F` adds a coarse copy `NAME@c` of each mesh (fewer faces, same
/// topology) after the plain samples, which stay byte for byte those of a run without
/// it; `train` holds a copy out with its mesh (`--hold-out NAME`), and bad values are
/// usage errors.
#[test]
fn dataset_coarsen_adds_coarse_copies_that_split_with_their_meshes() {
    let s = Scratch::new("coarsen");
    let meshes = s.p("meshes");
    write_meshes(&meshes);
    let (plain, coarse) = (s.p("plain"), s.p("coarse"));
    ok(&["dataset", "--meshes", &meshes, "--out", &plain, "--seed", "3"]);
    ok(&["dataset", "--meshes", &meshes, "--out", &coarse, "--seed", "3", "--coarsen", "0.5"]);
    let files = sample_files;
    let (pf, cf) = (files(&plain), files(&coarse));
    let load = |d: &str, f: &str| point2quad::pipeline::dataset::load_sample(&Path::new(d).join(f)).unwrap();
    for f in &pf {
        let read = |d: &str| std::fs::read(Path::new(d).join(f)).unwrap();
        assert_eq!(read(&plain), read(&coarse), "{f}: a plain sample changed with --coarsen");
    }
    let copies: Vec<&String> = cf.iter().filter(|f| !pf.contains(f)).collect();
    assert!(copies.iter().any(|f| f.as_str() == "b_torus@c.p2qs"), "{cf:?}");
    for f in &copies {
        let parent = f.replace("@c", "");
        assert!(pf.contains(&parent), "{f} has no mesh sample");
        let (c, p) = (load(&coarse, f), load(&plain, &parent));
        assert_eq!(c.name, f.trim_end_matches(".p2qs"));
        assert!(
            c.gt_faces.len() < p.gt_faces.len(),
            "{f}: {} faces, its mesh {}",
            c.gt_faces.len(),
            p.gt_faces.len()
        );
        let h = HalfedgeMesh::from_quads(c.n_mesh_vertices as usize, &c.gt_faces).unwrap();
        let hp = HalfedgeMesh::from_quads(p.n_mesh_vertices as usize, &p.gt_faces).unwrap();
        assert_eq!(h.euler_characteristic(), hp.euler_characteristic(), "{f}");
    }
    held_out_with_b_torus(&coarse, &s.p("m.p2qm"), cf.len(), 2);
    // A second share adds NAME@c2 copies; the first share's copies stay as they were.
    let two = s.p("two");
    ok(&["dataset", "--meshes", &meshes, "--out", &two, "--seed", "3", "--coarsen", "0.5,0.3"]);
    let tf = files(&two);
    for f in &cf {
        let read = |d: &str| std::fs::read(Path::new(d).join(f)).unwrap();
        assert_eq!(read(&coarse), read(&two), "{f}: changed by a second share");
    }
    let seconds: Vec<&String> = tf.iter().filter(|f| f.contains("@c2.")).collect();
    assert!(seconds.iter().any(|f| f.as_str() == "b_torus@c2.p2qs"), "{tf:?}");
    assert_eq!(tf.len(), cf.len() + seconds.len(), "{tf:?}");
    for f in &seconds {
        let (c2, c1) = (load(&two, f), load(&two, &f.replace("@c2", "@c")));
        assert!(c2.gt_faces.len() < c1.gt_faces.len(), "{f}: 0.3 of the faces should be fewer than 0.5");
    }
    held_out_with_b_torus(&two, &s.p("m2.p2qm"), tf.len(), 3);
    let bad = ["0", "1", "-0.5", "nan", "x", "0.5,,0.3", "0.5,2", "0.9,0.8,0.7,0.6,0.5,0.4,0.3,0.2,0.1"];
    copy_option_refuses(&s, &meshes, "--coarsen", &bad, "0.5");
}

/// `train --hold-out b_torus` on `data` (`total` samples): `b_torus` and its
/// `held` − 1 copies go to validation, the rest to training.
fn held_out_with_b_torus(data: &str, model: &str, total: usize, held: usize) {
    let args = ["train", "--data", data, "--out", model, "--epochs", "1", "--max-candidates", "300"];
    let out = ok(&[&args[..], &["--val-fraction", "0", "--hold-out", "b_torus"]].concat());
    let err = String::from_utf8_lossy(&out.stderr);
    let want = format!("{} training / {held} validation samples", total - held);
    assert!(err.contains(&want), "b_torus and its copies held out: want {want:?} in {err}");
}

/// `dataset FLAG VALUE` refuses every value of `bad` (usage error naming the flag) and
/// a good value without `--meshes`, and makes no folder.
fn copy_option_refuses(s: &Scratch, meshes: &str, flag: &str, bad: &[&str], good: &str) {
    let never = s.p("never");
    for b in bad {
        let err = fails(&["dataset", "--meshes", meshes, "--out", &never, flag, b], 2);
        assert!(err.contains(flag), "{b}: {err}");
    }
    let err = fails(&["dataset", "--synthetic", "2", "--out", &never, flag, good], 2);
    assert!(err.contains("--meshes"), "{err}");
    assert!(!Path::new(&never).exists());
}

/// `dataset --stretch F` adds a stretched copy `NAME@s` of each mesh (same faces, edge
/// lengths changed by up to F between directions) after the plain samples and the
/// coarse copies, all of which stay byte for byte as without it; a copy is held out
/// with its mesh, and bad values are usage errors.
#[test]
fn dataset_stretch_adds_stretched_copies_that_split_with_their_meshes() {
    let s = Scratch::new("stretch");
    let meshes = s.p("meshes");
    write_meshes(&meshes);
    let (coarse, both) = (s.p("coarse"), s.p("both"));
    ok(&["dataset", "--meshes", &meshes, "--out", &coarse, "--seed", "3", "--coarsen", "0.5"]);
    ok(&[
        "dataset",
        "--meshes",
        &meshes,
        "--out",
        &both,
        "--seed",
        "3",
        "--coarsen",
        "0.5",
        "--stretch",
        "2",
    ]);
    let (cf, bf) = (sample_files(&coarse), sample_files(&both));
    for f in &cf {
        let read = |d: &str| std::fs::read(Path::new(d).join(f)).unwrap();
        assert_eq!(read(&coarse), read(&both), "{f}: changed by --stretch");
    }
    let copies: Vec<&String> = bf.iter().filter(|f| f.contains("@s.")).collect();
    assert_eq!(bf.len(), cf.len() + copies.len(), "{bf:?}");
    assert!(copies.iter().any(|f| f.as_str() == "b_torus@s.p2qs"), "{bf:?}");
    let load = |d: &str, f: &str| point2quad::pipeline::dataset::load_sample(&Path::new(d).join(f)).unwrap();
    for f in &copies {
        let (c, p) = (load(&both, f), load(&both, &f.replace("@s", "")));
        assert_eq!(c.gt_faces, p.gt_faces, "{f}: the faces must not change");
        assert_eq!(c.n_mesh_vertices, p.n_mesh_vertices);
        // Edge length ratios copy / mesh (both in their normalised frames, so up to one
        // scale): spread by the stretch, but by at most its largest factor.
        let len = |pts: &[[f32; 3]], a: u32, b: u32| {
            let (x, y) = (pts[a as usize], pts[b as usize]);
            ((x[0] - y[0]).powi(2) + (x[1] - y[1]).powi(2) + (x[2] - y[2]).powi(2)).sqrt()
        };
        let ratios: Vec<f32> = p
            .gt_faces
            .iter()
            .flat_map(|q| (0..4).map(move |i| (q[i], q[(i + 1) % 4])))
            .map(|(a, b)| len(&c.points, a, b) / len(&p.points, a, b))
            .collect();
        let (lo, hi) = ratios.iter().fold((f32::MAX, 0.0f32), |(l, h), &r| (l.min(r), h.max(r)));
        assert!(hi / lo > 1.001 && hi / lo <= 2.0 + 1e-3, "{f}: edge ratios {lo}..{hi}");
    }
    held_out_with_b_torus(&both, &s.p("m.p2qm"), bf.len(), 3);
    let bad = ["1", "0.5", "10.5", "nan", "x", "2,,3", "2,2,2,2,2,2,2,2,2"];
    copy_option_refuses(&s, &meshes, "--stretch", &bad, "2");
}

/// A `.csv` cloud with a header row reads as the same points as its `.xyz` form, so
/// `reconstruct` writes the same mesh; `synth` refuses to write space-separated text
/// under a `.csv` name.
#[test]
fn a_csv_cloud_with_a_header_reads_like_its_xyz() {
    let s = Scratch::new("csv");
    let xyz = s.p("cloud.xyz");
    ok(&["synth", "--shape", "torus", "--seed", "3", "-o", &xyz]);
    let text = std::fs::read_to_string(&xyz).unwrap();
    let rows: Vec<String> =
        text.lines().map(|l| l.split_whitespace().collect::<Vec<_>>().join(",")).collect();
    let csv = s.write("cloud.csv", format!("\"x\",\"y\",\"z\"\r\n{}\r\n", rows.join("\r\n")).as_bytes());
    let (a, b) = (s.p("a.obj"), s.p("b.obj"));
    ok(&["reconstruct", &xyz, "-o", &a]);
    ok(&["reconstruct", &csv, "-o", &b]);
    let (ma, mb) = (std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
    assert!(ma.len() > 1000 && String::from_utf8_lossy(&ma).contains("\nf "), "no faces written");
    assert_eq!(ma, mb, "the .csv cloud gave another mesh than its .xyz form");
    let err = fails(&["synth", "--shape", "torus", "-o", &s.p("c.csv")], 2);
    assert!(err.contains("c.csv") && err.contains(".xyz, .txt or .pts"), "{err}");
    assert!(!s.path("c.csv").exists());
}

/// `train --kp-spacing-cells F` sets the point encoder's spacing scale in the saved
/// config (and reconstruct runs with it); it is refused without a point encoder, for a
/// non-positive value and with --resume. `--kp-input-cell F` likewise.
#[test]
fn train_kp_spacing_cells_reaches_the_model_and_is_checked() {
    let s = Scratch::new("kpspacing");
    let data = three_mesh_data(&s);
    let model = s.p("kp.p2qm");
    let base = ["train", "--data", &data, "--out", &model, "--epochs", "1", "--max-candidates", "200"];
    let with = |extra: &[&str]| -> Vec<String> { base.iter().chain(extra).map(|x| x.to_string()).collect() };
    let e = fails(&argv(&with(&["--kp-spacing-cells", "1.5"])), 2);
    assert!(e.contains("no point encoder"), "{e}");
    for bad in ["0", "-2", "nan"] {
        let e = fails(&argv(&with(&["--config", "default_kp", "--kp-spacing-cells", bad])), 2);
        assert!(e.contains("--kp-spacing-cells"), "{e}");
    }
    assert!(!Path::new(&model).exists());
    ok(&argv(&with(&["--config", "default_kp", "--kp-spacing-cells", "1.5"])));
    let m = point2quad::pipeline::model::Model::load(Path::new(&model)).unwrap();
    assert_eq!(m.config().point_encoder.as_ref().map(|k| k.spacing_cells), Some(1.5));
    let ckpt = format!("{model}.ckpt");
    let e = fails(&argv(&with(&["--resume", &ckpt, "--kp-spacing-cells", "1.5"])), 2);
    assert!(e.contains("--resume"), "{e}");
    // The same guard covers --sign-free-normals.
    for from_file in [["--resume", ckpt.as_str()], ["--init", model.as_str()]] {
        let e = fails(&argv(&with(&[from_file[0], from_file[1], "--sign-free-normals"])), 2);
        assert!(e.contains("--sign-free-normals cannot be combined"), "{e}");
    }
    let (cloud, out) = (s.p("c.xyz"), s.p("c.obj"));
    ok(&["synth", "--from", &s.p("meshes/b_torus.obj"), "-o", &cloud, "--seed", "2"]);
    ok(&["reconstruct", &cloud, "-o", &out, "--model", &model, "--threshold", "0.3"]);
    assert!(Path::new(&out).is_file());
    // `--kp-input-cell` the same way (level 0 on voxels).
    let e = fails(&argv(&with(&["--kp-input-cell", "0.5"])), 2);
    assert!(e.contains("no point encoder"), "{e}");
    for bad in ["0", "-2", "nan", "1.5"] {
        let e = fails(&argv(&with(&["--config", "default_kp", "--kp-input-cell", bad])), 2);
        assert!(e.contains("--kp-input-cell"), "{e}");
    }
    let e = fails(&argv(&with(&["--resume", &ckpt, "--kp-input-cell", "0.5"])), 2);
    assert!(e.contains("--kp-input-cell cannot be combined"), "{e}");
    let voxels = s.p("kp_voxels.p2qm");
    let base = ["train", "--data", &data, "--out", &voxels, "--epochs", "1", "--max-candidates", "200"];
    ok(&base.iter().copied().chain(["--config", "default_kp", "--kp-input-cell", "0.5"]).collect::<Vec<_>>());
    let m = point2quad::pipeline::model::Model::load(Path::new(&voxels)).unwrap();
    assert_eq!(m.config().point_encoder.as_ref().map(|k| k.input_cell), Some(0.5));
    let out2 = s.p("c2.obj");
    ok(&["reconstruct", &cloud, "-o", &out2, "--model", &voxels, "--threshold", "0.3"]);
    assert!(Path::new(&out2).is_file());
}

fn argv(v: &[String]) -> Vec<&str> {
    v.iter().map(String::as_str).collect()
}

/// Points scattered at random over a sphere (no quad layout) give a sparse result and
/// a warning that says why; the vertices of a quad sphere give neither. The warning
/// counts points that are corners of a face, so it must not fire on the quad sphere.
#[test]
fn reconstruct_warns_when_most_points_are_no_faces_corner() {
    let s = Scratch::new("cli_scatter");
    let mut rng = point2quad::rng::Rng::new(1);
    let mut text = String::new();
    for _ in 0..3000 {
        let z = 2.0 * rng.f64() - 1.0;
        let t = std::f64::consts::TAU * rng.f64();
        let r = (1.0 - z * z).sqrt();
        text.push_str(&format!("{} {} {z}\n", r * t.cos(), r * t.sin()));
    }
    let scattered = s.write("scattered.xyz", text.as_bytes());
    let err =
        String::from_utf8_lossy(&ok(&["reconstruct", &scattered, "-o", &s.p("a.obj")]).stderr).to_string();
    assert!(err.contains("warning") && err.contains("points are corners of a face"), "{err}");
    assert!(err.contains("scattered.xyz"), "{err}");
    assert!(!err.contains("--per-point"), "{err}");
    // With a candidate budget the shipped weights never saw, the warning names it
    // (session 30's audit: `--per-point 64` kept 124 of a cloud's 1,848 faces).
    let err = String::from_utf8_lossy(
        &ok(&["reconstruct", &scattered, "-o", &s.p("a.obj"), "--per-point", "64"]).stderr,
    )
    .to_string();
    assert!(
        err.contains("points are corners of a face") && err.contains("--per-point 64 (default 32)"),
        "{err}"
    );
    let quad = s.p("quad.xyz");
    ok(&["synth", "--shape", "cube_sphere", "--seed", "1", "--noise", "0", "-o", &quad]);
    let err = String::from_utf8_lossy(&ok(&["reconstruct", &quad, "-o", &s.p("b.obj")]).stderr).to_string();
    assert!(!err.contains("warning"), "{err}");
    // --quiet drops the summary and timing lines, never a warning, and changes no byte.
    assert!(err.contains("reconstruct: time:"), "{err}");
    let err = String::from_utf8_lossy(&ok(&["reconstruct", &quad, "-o", &s.p("q.obj"), "--quiet"]).stderr)
        .to_string();
    assert!(err.is_empty(), "--quiet: {err}");
    assert_eq!(std::fs::read(s.p("b.obj")).unwrap(), std::fs::read(s.p("q.obj")).unwrap());
    let err =
        String::from_utf8_lossy(&ok(&["reconstruct", "--quiet", &scattered, "-o", &s.p("a.obj")]).stderr)
            .to_string();
    assert!(err.starts_with("reconstruct: warning:") && err.lines().count() == 1, "--quiet: {err}");
}

/// `dataset --noise-variants N`: the plain samples stay byte for byte, each gets N − 1
/// more draws `NAME~v` of the same mesh with other noise points; `train` counts them
/// apart, holds them out with their mesh and validates on the first draw only; `refine`
/// leaves them out. Bad counts are usage errors naming the option.
#[test]
fn dataset_noise_variants_draw_the_noise_again_and_split_with_their_mesh() {
    let s = Scratch::new("variants");
    let meshes = s.p("meshes");
    write_meshes(&meshes);
    let (plain, var) = (s.p("plain"), s.p("var"));
    ok(&["dataset", "--meshes", &meshes, "--synthetic", "1", "--out", &plain, "--seed", "3"]);
    ok(&[
        "dataset",
        "--meshes",
        &meshes,
        "--synthetic",
        "1",
        "--out",
        &var,
        "--seed",
        "3",
        "--noise-variants",
        "3",
    ]);
    let (pf, vf) = (sample_files(&plain), sample_files(&var));
    assert_eq!(vf.len(), 3 * pf.len(), "{vf:?}");
    let load = |d: &str, f: &str| point2quad::pipeline::dataset::load_sample(&Path::new(d).join(f)).unwrap();
    for f in &pf {
        let read = |d: &str| std::fs::read(Path::new(d).join(f)).unwrap();
        assert_eq!(read(&plain), read(&var), "{f}: a plain sample changed with --noise-variants");
        let p = load(&plain, f);
        let stem = f.trim_end_matches(".p2qs");
        for v in [2, 3] {
            let d = load(&var, &format!("{stem}~{v}.p2qs"));
            assert_eq!(d.name, format!("{stem}~{v}"));
            // The same mesh, other noise points.
            assert_eq!(d.gt_faces, p.gt_faces, "{stem}~{v}");
            assert_eq!(d.n_mesh_vertices, p.n_mesh_vertices);
            assert_ne!(
                d.points[d.n_mesh_vertices as usize..],
                p.points[p.n_mesh_vertices as usize..],
                "{stem}~{v}"
            );
        }
    }
    // Held out with its mesh: b_torus and its two draws leave training; validation reads one.
    let model = s.p("m.p2qm");
    let args = ["train", "--data", &var, "--out", &model, "--epochs", "1", "--max-candidates", "300"];
    let out = ok(&[&args[..], &["--val-fraction", "0", "--hold-out", "b_torus"]].concat());
    let err = String::from_utf8_lossy(&out.stderr);
    let want = format!("{} training (and {} more noise draws of them", pf.len() - 1, 2 * (pf.len() - 1));
    assert!(err.contains(&want), "want {want:?} in {err}");
    assert!(err.contains(" / 1 validation samples"), "{err}");
    // The candidates are counted per draw: an epoch reads the first draws' count or so.
    let count = |part: &str| -> usize {
        let at = err.find(part).unwrap_or_else(|| panic!("{part:?} not in {err}"));
        err[..at].rsplit(|c: char| !c.is_ascii_digit()).next().unwrap().parse().unwrap()
    };
    let (first, all) = (count(" training candidates in first draws"), count(" in all)"));
    assert!(first > 0 && all > first, "{first} / {all}: {err}");
    let out = ok(&[
        "refine",
        "--data",
        &var,
        "--model",
        &model,
        "--out",
        &s.p("r.p2qm"),
        "--rounds",
        "1",
        "--epochs",
        "1",
        "--hold-out",
        "b_torus",
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains(&format!("{} further noise draws", 2 * pf.len())), "{err}");
    assert!(err.contains(&format!("{} training / 1 validation samples", pf.len() - 1)), "{err}");
    // --draws all: the training part's draws all go to the rounds, validation's first only.
    let r2 = s.p("r2.p2qm");
    let base = ["refine", "--data", &var, "--model", &model, "--rounds", "1", "--epochs", "1"];
    let refine = |extra: &[&str]| -> Vec<String> {
        [&base[..], &["--hold-out", "b_torus", "--out", &r2], extra]
            .concat()
            .iter()
            .map(|x| x.to_string())
            .collect()
    };
    let args_all = refine(&["--draws", "all"]);
    let out = ok(&args_all.iter().map(String::as_str).collect::<Vec<_>>());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("2 further noise draws (NAME~2, ...) left out: validation"), "{err}");
    assert!(err.contains(&format!("{} training / 1 validation samples", 3 * (pf.len() - 1))), "{err}");
    let args_bad = refine(&["--draws", "some"]);
    let e = fails(&args_bad.iter().map(String::as_str).collect::<Vec<_>>(), 2);
    assert!(e.contains("--draws"), "{e}");
    let never = s.p("never");
    for b in ["0", "17", "x", "-1", "2.5"] {
        let e = fails(&["dataset", "--synthetic", "1", "--out", &never, "--noise-variants", b], 2);
        assert!(e.contains("--noise-variants"), "{b}: {e}");
    }
    assert!(!Path::new(&never).exists());
}

/// `train --draws first` (session 22): on a `--noise-variants` dataset it trains exactly
/// as on the dataset written without variants (the same weights, byte for byte), while
/// the default (`all`) reads another draw in epoch 2. Bad values are usage errors that
/// write nothing.
#[test]
fn train_draws_first_trains_as_the_plain_dataset() {
    let s = Scratch::new("train_draws");
    let meshes = s.p("meshes");
    write_meshes(&meshes);
    let (plain, var) = (s.p("plain"), s.p("var"));
    let data = |out: &str, extra: &[&str]| {
        ok(&[&["dataset", "--meshes", &meshes, "--synthetic", "1", "--out", out, "--seed", "5"][..], extra]
            .concat());
    };
    data(&plain, &[]);
    data(&var, &["--noise-variants", "2"]);
    let train = |d: &str, out: &str, extra: &[&str]| {
        let args =
            ["train", "--data", d, "--out", out, "--epochs", "2", "--max-candidates", "300", "--seed", "4"];
        ok(&[&args[..], extra].concat())
    };
    let (m_plain, m_first, m_all) = (s.p("plain.p2qm"), s.p("first.p2qm"), s.p("all.p2qm"));
    train(&plain, &m_plain, &[]);
    let out = train(&var, &m_first, &["--draws", "first"]);
    let err = String::from_utf8_lossy(&out.stderr);
    let n = sample_files(&plain).len();
    assert!(err.contains(&format!("{n} further noise draws (NAME~2, ...) left out")), "{err}");
    assert!(!err.contains("more noise draws of them"), "{err}");
    train(&var, &m_all, &[]);
    let read = |p: &str| std::fs::read(p).unwrap();
    assert_eq!(read(&m_first), read(&m_plain), "--draws first must train as the plain dataset");
    assert_ne!(read(&m_all), read(&m_plain), "the default reads the second draws in epoch 2");
    let never = s.p("never.p2qm");
    let e = fails(&["train", "--data", &var, "--out", &never, "--draws", "some"], 2);
    assert!(e.contains("--draws"), "{e}");
    // Checked before anything is read: a missing checkpoint or model is not reached.
    let missing = s.p("missing.p2qm");
    let e = fails(&["train", "--data", &var, "--out", &never, "--resume", &missing, "--draws", "x"], 2);
    assert!(e.contains("--draws"), "{e}");
    let e = fails(&["refine", "--data", &var, "--model", &missing, "--out", &never, "--draws", "x"], 2);
    assert!(e.contains("--draws"), "{e}");
    assert!(!Path::new(&never).exists());
}

/// Session 23: a checkpoint records its run's options and a fingerprint of its data.
/// Resumed with none of the options, a run ends byte for byte where the uninterrupted
/// run does; an option given with another value is refused, naming it and the recorded
/// value (`--lr` is taken, with a note); other data is refused; a checkpoint without a
/// record (an older build's) resumes with a note.
#[test]
fn resume_reads_the_run_from_the_checkpoint() {
    use point2quad::nn::checkpoint;
    let s = Scratch::new("resume_record");
    let meshes = s.p("meshes");
    write_meshes(&meshes);
    let (data, other) = (s.p("data"), s.p("other"));
    ok(&["dataset", "--meshes", &meshes, "--synthetic", "1", "--out", &data, "--seed", "5"]);
    ok(&["dataset", "--meshes", &meshes, "--synthetic", "1", "--out", &other, "--seed", "6"]);
    let opts = [
        "--max-candidates",
        "300",
        "--seed",
        "3",
        "--lr",
        "0.02",
        "--val-fraction",
        "0.3",
        "--hold-out",
        "b_torus,a_sphere",
        "--jitter",
        "0.02",
        "--scale",
        "0.8,1.2",
        "--no-rotate",
    ];
    let train = |out: &str, epochs: &str, extra: &[&str]| {
        ok(&[&["train", "--data", &data, "--out", out, "--epochs", epochs][..], extra].concat())
    };
    let (straight, part) = (s.p("straight.p2qm"), s.p("part.p2qm"));
    train(&straight, "2", &opts);
    train(&part, "1", &opts);
    let ckpt = format!("{part}.ckpt");
    let read = |p: &str| std::fs::read(p).unwrap();
    let saved = read(&ckpt);
    // Every option from the record: the same weights as the run that was not stopped.
    let out = train(&part, "2", &["--resume", &ckpt]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!err.contains("note"), "{err}");
    assert_eq!(read(&part), read(&straight), "a resume without the options must continue exactly");
    // The record is in the checkpoint, and the resumed run writes it again.
    let run = checkpoint::load(Path::new(&ckpt)).unwrap().train.unwrap().run;
    let get = |k: &str| run.iter().find(|(key, _)| key == k).map(|(_, v)| v.as_str());
    assert_eq!(
        (get("epochs"), get("seed"), get("lr"), get("hold-out"), get("scale"), get("rotate"), get("draws")),
        (
            Some("2"),
            Some("3"),
            Some("0.02"),
            Some("a_sphere,b_torus"),
            Some("0.8,1.2"),
            Some("no"),
            Some("all")
        )
    );
    assert!(get("data").is_some_and(|d| d.contains("samples")), "{run:?}");
    // The same options given again are no conflict; another value is refused, before
    // anything is written.
    std::fs::write(&ckpt, &saved).unwrap();
    let again = s.p("again.p2qm");
    train(&again, "2", &[&opts[..], &["--resume", &ckpt]].concat());
    assert_eq!(read(&again), read(&straight));
    let never = s.p("never.p2qm");
    let resume = |extra: &[&str], code| {
        fails(
            &[&["train", "--data", &data, "--out", &never, "--epochs", "2", "--resume", &ckpt][..], extra]
                .concat(),
            code,
        )
    };
    for (extra, names) in [
        (vec!["--config", "default_kp"], ["--config default_kp", "'default'"]),
        (vec!["--seed", "4"], ["--seed", "seed \"3\""]),
        (vec!["--fold", "0/2"], ["--fold", "fold \"\""]),
        (vec!["--scale", "0.9,1.1"], ["--scale", "\"0.8,1.2\""]),
        (vec!["--hold-out", "c_tube"], ["--hold-out", "\"a_sphere,b_torus\""]),
        (vec!["--val-fraction", "0.1"], ["--val-fraction", "\"0.3\""]),
        (vec!["--max-candidates", "200"], ["--max-candidates", "\"300\""]),
        (vec!["--draws", "first"], ["--draws", "\"all\""]),
        (vec!["--no-augment"], ["--no-augment", "scale"]),
        (vec!["--jitter", "0.01"], ["--jitter", "\"0.02\""]),
    ] {
        let e = resume(&extra, 2);
        assert!(names.iter().all(|n| e.contains(n)), "{extra:?}: {e}");
    }
    // The hold-out names in another order (or repeated) are the same split.
    let swapped = s.p("swapped.p2qm");
    let swap = [&opts[..9], &["a_sphere,b_torus,a_sphere"], &opts[10..]].concat();
    train(&swapped, "2", &[&swap[..], &["--resume", &ckpt]].concat());
    assert_eq!(read(&swapped), read(&straight));
    // Without --epochs the recorded count is the goal: the part run's checkpoint, its
    // record saying 2 (as an interrupted two-epoch run's would), ends where the
    // uninterrupted run does.
    let mut two = checkpoint::load(Path::new(&ckpt)).unwrap();
    let st = two.train.as_mut().unwrap();
    assert_eq!(st.run.iter().find(|(k, _)| k == "epochs").map(|(_, v)| v.as_str()), Some("1"));
    for (k, v) in st.run.iter_mut() {
        if k == "epochs" {
            *v = "2".into();
        }
    }
    let two_ckpt = s.p("two.ckpt");
    checkpoint::save(Path::new(&two_ckpt), &two).unwrap();
    let cont = s.p("cont.p2qm");
    ok(&["train", "--data", &data, "--out", &cont, "--resume", &two_ckpt]);
    assert_eq!(read(&cont), read(&straight));
    // Another dataset is refused.
    let e = fails(&["train", "--data", &other, "--out", &never, "--epochs", "2", "--resume", &ckpt], 2);
    assert!(e.contains("not those the run was trained on") && e.contains("other"), "{e}");
    assert!(!Path::new(&never).exists() && !Path::new(&format!("{never}.ckpt")).exists());
    // A new rate is taken, with a note naming the recorded one.
    let out = train(&s.p("lr.p2qm"), "2", &["--resume", &ckpt, "--lr", "0.005"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("note: --lr 0.005 with --resume") && err.contains("used --lr 0.02"), "{err}");
    assert_ne!(read(&s.p("lr.p2qm")), read(&straight));
    // A checkpoint without a record (as older builds wrote them) resumes, with a note,
    // from the options given.
    let mut old = checkpoint::load(Path::new(&ckpt)).unwrap();
    old.train.as_mut().unwrap().run.clear();
    let old_ckpt = s.p("old.ckpt");
    checkpoint::save(Path::new(&old_ckpt), &old).unwrap();
    let out = train(&s.p("old.p2qm"), "2", &[&opts[..], &["--resume", &old_ckpt]].concat());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("holds no record of its run's options"), "{err}");
    assert_eq!(read(&s.p("old.p2qm")), read(&straight));
}

/// `synth --from` [`write_meshes`]'s torus with `extra` options and seed 3: the source
/// file, the cloud file, the source mesh, the written ground truth and the cloud's points.
fn synth_from_torus(s: &Scratch, extra: &[&str]) -> (String, String, PolyMesh, PolyMesh, Vec<[f64; 3]>) {
    let meshes = s.p("meshes");
    write_meshes(&meshes);
    let src = s.p("meshes/b_torus.obj");
    let (cloud, gt) = (s.p("synth.xyz"), s.p("synth.obj"));
    let mut args = vec!["synth", "--from", &src, "-o", &cloud, "--gt", &gt, "--seed", "3"];
    args.extend(extra);
    ok(&args);
    let orig = point2quad::io::mesh_io::read_mesh(Path::new(&src)).unwrap();
    let written = point2quad::io::mesh_io::read_mesh(Path::new(&gt)).unwrap();
    let pts = point2quad::io::points::read_points(Path::new(&cloud)).unwrap();
    (src, cloud, orig, written, pts)
}

/// `synth --jitter F` (session 23): the ground truth is the moved mesh, the cloud starts
/// with its vertices (written back exactly), faces are the source's; `--jitter 0` writes
/// what no jitter writes.
#[test]
fn synth_jitter_moves_the_ground_truth_with_the_cloud() {
    let s = Scratch::new("synth_jitter");
    let (src, cloud, orig, moved, pts) = synth_from_torus(&s, &["--jitter", "0.05"]);
    assert_eq!(moved.faces, orig.faces);
    assert_eq!(&pts[..moved.vertices.len()], &moved.vertices[..]);
    assert!(pts.len() > moved.vertices.len(), "noise points follow");
    let used: std::collections::HashSet<u32> = orig.faces.iter().flatten().copied().collect();
    for (v, (a, b)) in orig.vertices.iter().zip(&moved.vertices).enumerate() {
        assert_eq!(a != b, used.contains(&(v as u32)), "vertex {v}");
    }
    let (plain, zero) = (s.p("plain.xyz"), s.p("zero.xyz"));
    ok(&["synth", "--from", &src, "-o", &plain, "--seed", "3"]);
    ok(&["synth", "--from", &src, "-o", &zero, "--seed", "3", "--jitter", "0"]);
    assert_eq!(std::fs::read(&plain).unwrap(), std::fs::read(&zero).unwrap());
    assert_ne!(std::fs::read(&plain).unwrap(), std::fs::read(&cloud).unwrap());
}

/// `synth --triangle-split` writes the mesh's conversion (the library's `triangle_split`,
/// tested against its definition in `shapes_props`): the input's vertices first, six
/// quads per quad, the cloud starting with the converted mesh's vertices.
#[test]
fn synth_triangle_split_converts_the_ground_truth() {
    let s = Scratch::new("synth_tri");
    let (src, _, orig, split, pts) = synth_from_torus(&s, &["--triangle-split"]);
    assert_eq!(split.faces.len(), 6 * orig.faces.len());
    assert_eq!(&split.vertices[..orig.vertices.len()], &orig.vertices[..]);
    assert_eq!(&pts[..split.vertices.len()], &split.vertices[..]);
    let want = point2quad::mesh::shapes::triangle_split(
        &orig.to_quads().unwrap(),
        &mut point2quad::rng::Rng::new(3),
    );
    let faces: Vec<Vec<u32>> = want.quads.iter().map(|q| q.to_vec()).collect();
    assert_eq!(split.faces, faces);
    // The shipped weights do not know the layout (session 39's audit): the second pass
    // takes the triangles' centres for noise, and `reconstruct` warns; a plain cloud of
    // the same mesh gets no such warning. (Weights trained on such meshes may keep the
    // centres; then the first half of this check has to go.)
    let (clean, plain, clean_gt) = (s.p("clean.xyz"), s.p("plain.xyz"), s.p("clean.obj"));
    ok(&[
        "synth",
        "--from",
        &src,
        "-o",
        &clean,
        "--gt",
        &clean_gt,
        "--triangle-split",
        "--noise",
        "0",
        "--seed",
        "3",
    ]);
    ok(&["synth", "--from", &src, "-o", &plain, "--seed", "3"]);
    let out_obj = s.p("out.obj");
    let precision = |mesh: &str| {
        let out = ok(&["eval", mesh, "--gt", &clean_gt, "--json"]);
        parse_json(String::from_utf8_lossy(&out.stdout).trim())
            .unwrap()
            .get("precision")
            .and_then(Json::num)
            .unwrap()
    };
    let err = String::from_utf8_lossy(&ok(&["reconstruct", &clean, "-o", &out_obj]).stderr).into_owned();
    assert!(err.contains("second pass left") && err.contains("triangle mesh split into quads"), "{err}");
    assert!(err.contains("point2quad-trisplit.p2qm"), "{err}");
    let shipped = precision(&out_obj);
    let err = String::from_utf8_lossy(&ok(&["reconstruct", &plain, "-o", &out_obj]).stderr).into_owned();
    assert!(!err.contains("second pass left"), "{err}");
    // The weights the warning names (`make train-trisplit`) find most of the kites where
    // the shipped ones find none (P 0.687 and 0.000 when written), and keep the centres.
    let specialist = concat!(env!("CARGO_MANIFEST_DIR"), "/fixtures/point2quad-trisplit.p2qm");
    let out = ok(&["reconstruct", &clean, "-o", &out_obj, "--model", specialist]);
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!err.contains("second pass left"), "{err}");
    let p = precision(&out_obj);
    assert!(shipped < 0.1 && p > 0.5, "shipped weights P {shipped}, tri-split weights P {p}");
}

/// Session 21's review: a held-out copy takes its noise draws with it; a noise draw cannot
/// be held out on its own; two files of one sample name are refused (splits and draw
/// groups go by that name); mesh files whose names sanitise alike get samples apart.
#[test]
fn draws_follow_held_out_copies_and_sample_names_are_unique() {
    let s = Scratch::new("draws_split");
    let meshes = s.p("meshes");
    write_meshes(&meshes);
    let data = s.p("data");
    ok(&[
        "dataset",
        "--meshes",
        &meshes,
        "--out",
        &data,
        "--seed",
        "3",
        "--coarsen",
        "0.5",
        "--noise-variants",
        "2",
    ]);
    let files = sample_files(&data);
    let bases = files.len() / 2;
    assert!(files.iter().any(|f| f == "b_torus@c~2.p2qs"), "{files:?}");
    let model = s.p("m.p2qm");
    let train = ["train", "--data", &data, "--out", &model, "--epochs", "1", "--max-candidates", "300"];
    let out = ok(&[&train[..], &["--val-fraction", "0", "--hold-out", "b_torus@c"]].concat());
    let err = String::from_utf8_lossy(&out.stderr);
    let want = format!("{} training (and {} more noise draws of them", bases - 1, bases - 1);
    assert!(err.contains(&want), "b_torus@c~2 must leave training with b_torus@c: want {want:?} in {err}");
    let e = fails(&[&train[..], &["--hold-out", "b_torus~2"]].concat(), 2);
    assert!(e.contains("hold out b_torus instead"), "{e}");
    // A copied sample file: one name twice.
    std::fs::copy(Path::new(&data).join("a_sphere.p2qs"), Path::new(&data).join("zz_copy.p2qs")).unwrap();
    let e = fails(&train, 2);
    assert!(e.contains("a_sphere.p2qs") && e.contains("zz_copy.p2qs") && e.contains("one name"), "{e}");
    // `x~2.obj` and `x_2.obj` both sanitise to `x_2`.
    let odd = s.p("odd");
    std::fs::create_dir_all(&odd).unwrap();
    for n in ["x~2", "x_2"] {
        std::fs::copy(Path::new(&meshes).join("b_torus.obj"), Path::new(&odd).join(format!("{n}.obj")))
            .unwrap();
    }
    let out_dir = s.p("odd_data");
    ok(&["dataset", "--meshes", &odd, "--out", &out_dir, "--seed", "3"]);
    // Same stem: the extension tells them apart first, then a number.
    assert_eq!(sample_files(&out_dir), vec!["x_2_obj.p2qs".to_string(), "x_2_obj_2.p2qs".to_string()]);
}

/// The files of `dir` (name, bytes), sorted by name.
fn folder_bytes(dir: &str) -> Vec<(String, Vec<u8>)> {
    let mut v: Vec<(String, Vec<u8>)> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| {
            let e = e.unwrap();
            (e.file_name().to_string_lossy().into_owned(), std::fs::read(e.path()).unwrap())
        })
        .collect();
    v.sort();
    v
}

#[test]
fn threads_and_quiet_options_change_no_result() {
    let s = Scratch::new("threads");
    let meshes = s.p("meshes");
    write_meshes(&meshes);
    // dataset, train (with its checkpoint), refine and reconstruct on 1 and 3 threads:
    // the same bytes, and reconstruct reports the pool it ran on.
    let mut runs = Vec::new();
    for t in ["1", "3"] {
        let (data, model, rounds, mesh) = (
            s.p(&format!("d{t}")),
            s.p(&format!("m{t}.p2qm")),
            s.p(&format!("r{t}.p2qm")),
            s.p(&format!("o{t}.obj")),
        );
        ok(&["dataset", "--meshes", &meshes, "--out", &data, "--seed", "3", "--threads", t]);
        train_tiny(&data, &model, &[&format!("--threads={t}")]);
        refine_tiny(&data, &model, &rounds, "1", &["--threads", t]);
        if t == "1" {
            // --quiet: no progress lines, the same weights.
            let quiet = s.p("quiet.p2qm");
            let err = String::from_utf8_lossy(&train_tiny(&data, &quiet, &["--quiet"]).stderr).to_string();
            assert!(err.is_empty(), "train --quiet: {err}");
            assert_eq!(std::fs::read(&quiet).unwrap(), std::fs::read(&model).unwrap());
        }
        let out =
            ok(&["reconstruct", "--threads", t, &s.p("meshes/b_torus.obj"), "-o", &mesh, "--model", &rounds]);
        let err = String::from_utf8_lossy(&out.stderr);
        let pool = if t == "1" { "1 thread)".to_string() } else { format!("{t} threads)") };
        assert!(err.contains(&pool), "--threads {t}: {err}");
        let files = [&model, &format!("{model}.ckpt"), &rounds, &mesh].map(|f| std::fs::read(f).unwrap());
        runs.push((folder_bytes(&data), files));
    }
    assert!(!runs[0].0.is_empty());
    assert!(runs[0] == runs[1], "a result depends on the thread count");
    // Bad values are usage errors that name the option; nothing is written.
    let out = s.p("bad.obj");
    let cloud = s.p("meshes/a_sphere.obj");
    for (bad, why) in [
        (&["--threads", "0"][..], "a whole number from 1 to 1024"),
        (&["--threads", "x"], "a whole number from 1 to 1024"),
        (&["--threads", "1025"], "a whole number from 1 to 1024"),
        (&["--threads=-2"], "a whole number from 1 to 1024"),
        (&["--threads"], "option --threads needs a value"),
    ] {
        let mut args = vec!["reconstruct", cloud.as_str(), "-o", out.as_str()];
        args.extend_from_slice(bad);
        let err = fails(&args, 2);
        assert!(err.contains("--threads") && err.contains(why), "{bad:?}: {err}");
    }
    // Before the command too.
    let before = ok(&["--threads", "2", "--quiet", "reconstruct", &cloud, "-o", &s.p("before.obj")]);
    assert!(before.stderr.is_empty(), "{}", String::from_utf8_lossy(&before.stderr));
    let help = String::from_utf8_lossy(&ok(&["eval", "--help"]).stdout).to_string();
    assert!(help.contains("--threads N") && help.contains("--quiet"), "{help}");
    let err = fails(&["eval", &cloud, "--threads", "2", "--threads", "2"], 2);
    assert!(err.contains("given twice"), "{err}");
    assert!(!Path::new(&out).exists());
    // A note or warning stays under --quiet, the progress lines go.
    std::fs::write(s.p("meshes/broken.obj"), "v 0 0 0\nf 1 2 3 4\n").unwrap();
    let err = String::from_utf8_lossy(
        &ok(&["dataset", "--meshes", &meshes, "--out", &s.p("dq"), "--seed", "3", "--quiet"]).stderr,
    )
    .to_string();
    assert!(err.contains("warning: skipping") && err.contains("broken.obj"), "{err}");
    assert!(!err.contains("coverage") && !err.contains("samples in"), "{err}");
    // After `--` it is a file name, not the option.
    let err = fails(&["eval", "--", "--threads"], 2);
    assert!(err.contains("--threads: unknown mesh format"), "{err}");
}

/// `reconstruct --progress` names every stage of the final time line as it ends
/// (the second pass's own stages under "second pass:"); a small cloud without it gets
/// none of those lines, and `--quiet` silences them.
#[test]
fn reconstruct_progress_names_each_stage_as_it_ends() {
    let s = Scratch::new("progress");
    let cloud = s.p("c.xyz");
    ok(&["synth", "--shape", "torus", "--seed", "2", "-o", &cloud]);
    let err =
        String::from_utf8_lossy(&ok(&["reconstruct", &cloud, "-o", &s.p("a.obj"), "--progress"]).stderr)
            .to_string();
    let time = err.lines().find_map(|l| l.strip_prefix("reconstruct: time: ")).expect("a time line");
    let stages: Vec<&str> = time
        .split(" (total")
        .next()
        .unwrap()
        .split(", ")
        .map(|st| st.rsplit_once(' ').unwrap().0.rsplit_once(' ').unwrap().0)
        .filter(|n| *n != "read" && *n != "write" && *n != "second pass")
        .collect();
    assert!(stages.len() >= 6, "{time}");
    let progress: Vec<&str> = err
        .lines()
        .filter_map(|l| l.strip_prefix("reconstruct: "))
        .filter(|l| l.ends_with(" s") && !l.starts_with("time:"))
        .map(|l| l.rsplit_once(' ').unwrap().0.rsplit_once(' ').unwrap().0)
        .filter(|n| !n.starts_with("second pass:"))
        .collect();
    assert_eq!(progress, stages, "{err}");
    assert!(err.contains("reconstruct: second pass: candidates "), "{err}");
    assert!(err.contains("points read from") && err.contains("c.xyz"), "{err}");
    let plain =
        String::from_utf8_lossy(&ok(&["reconstruct", &cloud, "-o", &s.p("b.obj")]).stderr).to_string();
    assert!(!plain.contains("stage times follow") && !plain.contains("reconstruct: candidates "), "{plain}");
    assert_eq!(std::fs::read(s.p("a.obj")).unwrap(), std::fs::read(s.p("b.obj")).unwrap());
    let quiet = ok(&["reconstruct", &cloud, "-o", &s.p("q.obj"), "--progress", "--quiet"]);
    assert!(quiet.stderr.is_empty(), "{}", String::from_utf8_lossy(&quiet.stderr));
    // Not a post-process switch: allowed with --no-postprocess.
    ok(&["reconstruct", &cloud, "-o", &s.p("r.obj"), "--progress", "--no-postprocess"]);
}

/// `reconstruct --watertight` (session 32): on a noisy cloud whose default
/// reconstruction leaves holes, the output is closed, valid and pure quad, its first
/// vertices are the input points, and the summary says what was done;
/// `--watertight-max-loop` without `--watertight` is a usage error that writes nothing.
/// `repair --watertight` closes a torus with faces taken out.
#[test]
fn reconstruct_and_repair_watertight() {
    let s = Scratch::new("watertight");
    let cloud = s.p("cloud.xyz");
    let (plain, closed) = (s.p("plain.obj"), s.p("closed.obj"));
    let border = |mesh: &str| valid_mesh_metric(mesh, "boundary_edges");
    let has_holes = |seed: &str| {
        ok(&["synth", "--shape", "random", "-o", &cloud, "--noise", "0.1", "--seed", seed]);
        ok(&["reconstruct", &cloud, "-o", &plain]);
        border(&plain) > 0.0
    };
    let seeds = ["1", "2", "3", "4", "5", "6", "7", "8", "9", "10", "11", "12", "13", "14", "15", "16"];
    assert!(seeds.iter().any(|seed| has_holes(seed)), "no case with holes among seeds {seeds:?}");
    let out = ok(&["reconstruct", &cloud, "-o", &closed, "--watertight"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("watertight:") && err.contains("0 loop(s) left open"), "{err}");
    assert_eq!(border(&closed), 0.0);
    assert_eq!(valid_mesh_metric(&closed, "watertightness"), 1.0);
    let pts = point2quad::io::points::read_points(Path::new(&cloud)).unwrap();
    let mesh = point2quad::io::mesh_io::read_mesh(Path::new(&closed)).unwrap();
    assert!(mesh.vertices.len() >= pts.len());
    assert!(pts.iter().zip(&mesh.vertices).all(|(a, b)| a == b));
    // The summary's new vertices (the post-process's) and the closing's add up to the
    // vertices the output has beyond the points (session 39's audit: the closing's were
    // counted on both lines).
    let number_before = |text: &str, tail: &str| -> usize {
        let head = &text[..text.find(tail).unwrap_or_else(|| panic!("no {tail:?} in {text}"))];
        let digits: String =
            head.chars().rev().skip_while(|c| *c == ' ').take_while(char::is_ascii_digit).collect();
        digits.chars().rev().collect::<String>().parse().unwrap_or_else(|_| panic!("{tail:?} in {text}"))
    };
    let (filled, closing) =
        (number_before(&err, "new vertices)"), number_before(&err, "new vertices in all"));
    assert!(closing > 0, "{err}");
    assert_eq!(filled + closing, mesh.vertices.len() - pts.len(), "{err}");
    let never = s.p("never.obj");
    let err = fails(&["reconstruct", &cloud, "-o", &never, "--watertight-max-loop", "8"], 2);
    assert!(err.contains("--watertight"), "{err}");
    assert!(!Path::new(&never).exists());

    let t = shapes::torus(16, 8, 3.0, 1.0);
    let kept: Vec<Vec<u32>> =
        t.quads.iter().enumerate().filter(|(i, _)| i % 7 != 3).map(|(_, q)| q.to_vec()).collect();
    let holed = s.p("holed.obj");
    point2quad::io::mesh_io::write_mesh(
        Path::new(&holed),
        &PolyMesh { vertices: t.vertices.clone(), faces: kept },
    )
    .unwrap();
    let repaired = s.p("repaired.obj");
    let out = ok(&["repair", &holed, "-o", &repaired, "--no-fill", "--watertight"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("watertight:") && err.contains("0 boundary loops"), "{err}");
    assert!(border(&holed) > 0.0);
    assert_eq!(border(&repaired), 0.0);
}
