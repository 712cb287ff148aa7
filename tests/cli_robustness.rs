//! The compiled `point2quad` binary against bad input: damaged and lying files,
//! NaN/inf coordinates, out-of-range and negative indices, non-UTF-8 bytes,
//! directories and missing files, unwritable or misnamed outputs, bad options, and
//! degenerate meshes. Every failure must exit non-zero (2 for usage, 1 for data),
//! name the file (and the line or element), never print a panic, and leave no output
//! or temporary file behind. Degenerate meshes must give finite numbers.

#[path = "common/cli.rs"]
mod cli;
#[path = "common/quality.rs"]
mod quality_common;
#[path = "common/scratch.rs"]
mod scratch;

use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use cli::{assert_fails, run_with_closed_pipe, stderr, Pipe};
use quality_common::{check_xml, parse_json, Json};
use scratch::Scratch;

/// Subcommands that exist in the binary (landed or not): each must answer `--help`.
const COMMANDS: [&str; 8] =
    ["reconstruct", "candidates", "eval", "dataset", "train", "repair", "render", "synth"];

/// Runs the binary with a time limit (a hang is a bug, not a stuck test run).
fn p2q(args: &[&str]) -> Output {
    p2q_in(None, args)
}

/// As [`p2q`], in folder `cwd` when given.
fn p2q_in(cwd: Option<&Path>, args: &[&str]) -> Output {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_point2quad"));
    if let Some(d) = cwd {
        cmd.current_dir(d);
    }
    let mut child = cmd
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("test: run the binary");
    let start = Instant::now();
    loop {
        if child.try_wait().expect("test: wait").is_some() {
            return child.wait_with_output().expect("test: collect output");
        }
        if start.elapsed() > Duration::from_secs(30) {
            let _ = child.kill();
            let out = child.wait_with_output().expect("test: collect output");
            panic!("point2quad {args:?} still running after 30 s (hang); stderr: {}", stderr(&out));
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// Deterministic "random" bytes covering every byte value.
fn garbage(n: usize, seed: u64) -> Vec<u8> {
    let mut s = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
    (0..n)
        .map(|_| {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (s >> 56) as u8
        })
        .collect()
}

const PLY_HEAD: &str = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
                        property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";

/// A binary little-endian PLY: 3 float vertices, `faces` triangles (uchar count,
/// `idx` uint indices), declaring `declared_faces`.
fn binary_ply(verts: &[[f32; 3]], faces: &[[u32; 3]], declared_faces: usize) -> Vec<u8> {
    let mut b = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty float x\nproperty float y\n\
         property float z\nelement face {declared_faces}\nproperty list uchar uint vertex_indices\nend_header\n",
        verts.len()
    )
    .into_bytes();
    for v in verts {
        for c in v {
            b.extend_from_slice(&c.to_le_bytes());
        }
    }
    for f in faces {
        b.push(3);
        for i in f {
            b.extend_from_slice(&i.to_le_bytes());
        }
    }
    b
}

const TRI: [[f32; 3]; 3] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];

/// (file name, content, what stderr must name besides the file: line or element).
fn malformed_meshes() -> Vec<(&'static str, Vec<u8>, Vec<&'static str>)> {
    let ok_bin = binary_ply(&TRI, &[[0, 1, 2]], 1);
    let hdr = ok_bin.windows(11).position(|w| w == b"end_header\n").expect("test: header") + 11;
    let mut nan_bin = ok_bin.clone();
    nan_bin[hdr + 12 + 4..hdr + 12 + 8].copy_from_slice(&f32::NAN.to_le_bytes());
    let mut inf_bin = ok_bin.clone();
    inf_bin[hdr + 24..hdr + 28].copy_from_slice(&f32::NEG_INFINITY.to_le_bytes());
    vec![
        // Empty and garbage.
        ("empty.off", vec![], vec!["empty file"]),
        ("empty.ply", vec![], vec![":1: header not terminated"]),
        ("garbage.ply", garbage(600, 1), vec![":1: not a PLY file"]),
        ("garbage.off", garbage(600, 2), vec![":1:"]),
        // (A zero-byte .obj is an empty mesh: `eval` scores it, quality_cli.rs tests that.)
        ("garbage.obj", garbage(600, 3), vec!["contains no vertices"]),
        ("nul.obj", vec![0; 64], vec!["contains no vertices"]),
        // Truncated, and headers that lie about the counts.
        (
            "trunc_ascii.ply",
            format!("{PLY_HEAD}0 0 0\n1 0 0\n").into_bytes(),
            vec!["truncated", "vertex 2 of 3"],
        ),
        (
            "trunc_face.ply",
            format!("{PLY_HEAD}0 0 0\n1 0 0\n0 1 0\n3 0 1\n").into_bytes(),
            vec!["truncated", "face 0 of 1"],
        ),
        ("trunc_bin.ply", ok_bin[..ok_bin.len() - 5].to_vec(), vec!["truncated", "face 0 of 1"]),
        ("trunc_bin_v.ply", ok_bin[..hdr + 17].to_vec(), vec!["truncated", "vertex 1 of 3"]),
        ("lying_faces.ply", binary_ply(&TRI, &[[0, 1, 2]], 5), vec!["truncated", "face 1 of 5"]),
        (
            "lying_more.ply",
            binary_ply(&TRI, &[[0, 1, 2], [0, 2, 1]], 1),
            vec!["bytes after the last element"],
        ),
        (
            "lying_huge.ply",
            binary_ply(&TRI, &[[0, 1, 2]], 4_000_000_000),
            vec!["truncated", "face 1 of 4000000000"],
        ),
        ("lying.off", b"OFF\n100 1 0\n0 0 0\n1 0 0\n0 1 0\n".to_vec(), vec!["truncated", "vertex 3 of 100"]),
        ("lying_faces.off", b"OFF\n3 9 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n".to_vec(), vec!["face 1 of 9"]),
        (
            "lying_more.off",
            b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 0 1 2\n".to_vec(),
            vec![":7: data after the last face"],
        ),
        (
            "lying_count.off",
            b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n4000000000 0 1 2\n".to_vec(),
            vec![":6: face 0"],
        ),
        // NaN and inf.
        ("nan.obj", b"v 0 0 0\nv 0 nan 0\nv 1 1 1\nf 1 2 3\n".to_vec(), vec![":2: vertex 1: non-finite"]),
        ("inf.obj", b"v 0 0 0\nv 0 0 -inf\nv 1 1 1\nf 1 2 3\n".to_vec(), vec![":2: vertex 1: non-finite"]),
        (
            "overflow.off",
            b"OFF\n3 1 0\n0 0 0\n1e999 0 0\n0 1 0\n3 0 1 2\n".to_vec(),
            vec![":4: vertex 1: non-finite"],
        ),
        (
            "nan_ascii.ply",
            format!("{PLY_HEAD}0 0 0\nNaN 0 0\n0 1 0\n3 0 1 2\n").into_bytes(),
            vec![":11: vertex 1"],
        ),
        ("nan_bin.ply", nan_bin, vec!["vertex 1: non-finite"]),
        ("inf_bin.ply", inf_bin, vec!["vertex 2: non-finite"]),
        // Huge and negative indices.
        (
            "huge.obj",
            b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99999999999\n".to_vec(),
            vec![":4:", "99999999999 out of range"],
        ),
        (
            "huge2.obj",
            b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99999999999999999999999\n".to_vec(),
            vec![":4: face 0: bad vertex index"],
        ),
        (
            "neg.obj",
            b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 -9\n".to_vec(),
            vec![":4: face 0: vertex index -9 out of range"],
        ),
        ("zero.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n".to_vec(), vec![":4: face 0: vertex index 0"]),
        (
            "huge.off",
            b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 4294967296\n".to_vec(),
            vec![":6: face 0: vertex index 4294967296 out of range"],
        ),
        (
            "neg.off",
            b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 -1 2\n".to_vec(),
            vec![":6: face 0: vertex index -1 out of range"],
        ),
        ("neg_count.off", b"OFF\n-3 1 0\n".to_vec(), vec![":2: bad vertex count '-3'"]),
        (
            "neg_ascii.ply",
            format!("{PLY_HEAD}0 0 0\n1 0 0\n0 1 0\n3 0 -1 2\n").into_bytes(),
            vec![":13: face 0: vertex index -1 out of range"],
        ),
        (
            "huge_bin.ply",
            binary_ply(&TRI, &[[0, u32::MAX, 2]], 1),
            vec!["face 0: vertex index 4294967295 out of range"],
        ),
        (
            "neg_list.ply",
            format!("{PLY_HEAD}0 0 0\n1 0 0\n0 1 0\n-3 0 1 2\n").into_bytes(),
            vec![":13: face 0 of 1 declared: negative list length"],
        ),
        ("two.obj", b"v 0 0 0\nv 1 0 0\nf 1 2\n".to_vec(), vec![":3: face 0: has 2 vertices"]),
        // Non-UTF-8 bytes where numbers belong, and in headers.
        ("utf.obj", b"v 0 0 0\nv 1 0 \xff\xfe\n".to_vec(), vec![":2: vertex 1: bad number"]),
        ("utf.off", b"\xffOFF\n3 1 0\n".to_vec(), vec![":1:", "OFF header"]),
        (
            "utf.ply",
            b"ply\nformat ascii 1.0\nelement vertex 1\nproperty \xff\xfe x\nend_header\n".to_vec(),
            vec![":4: unknown property type"],
        ),
        // Structurally wrong headers.
        (
            "nox.ply",
            b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float y\nproperty float z\nend_header\n0 0\n"
                .to_vec(),
            vec![":3: element vertex has no property 'x'"],
        ),
        ("noformat.ply", b"ply\nelement vertex 1\nend_header\n".to_vec(), vec!["no 'format' line"]),
        (
            "fmt.ply",
            b"ply\nformat binary_middle_endian 1.0\nend_header\n".to_vec(),
            vec![":2: unknown PLY format"],
        ),
        ("4d.off", b"4OFF\n1 0 0\n0 0 0 0\n".to_vec(), vec![":1:", "4-D"]),
        ("binoff.off", b"OFF BINARY\n".to_vec(), vec!["binary OFF is not supported"]),
    ]
}

#[test]
fn malformed_meshes_fail_cleanly_naming_file_and_location() {
    let dir = Scratch::new("malformed");
    for (name, bytes, needles) in malformed_meshes() {
        let input = dir.write(name, &bytes);
        let before = dir.entries();
        let out_svg = dir.path("out.svg").display().to_string();
        let mut must = vec![input.as_str()];
        must.extend(needles.iter().copied());
        for args in
            [vec!["eval", &input, "--json"], vec!["eval", &input], vec!["render", &input, "-o", &out_svg]]
        {
            let out = p2q(&args);
            assert_fails(&out, 1, &must, &format!("{args:?}"));
            assert_eq!(dir.entries(), before, "{args:?}: files left behind");
        }
        // As ground truth the same file fails the same way, naming it.
        let good = dir.write("good.obj", b"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n");
        let out = p2q(&["eval", &good, "--gt", &input]);
        assert_fails(&out, 1, &must, &format!("eval --gt {name}"));
        std::fs::remove_file(&input).expect("test: remove input");
    }
}

/// Regression: an element with no properties and a count of 10^18 (a 200-byte file)
/// made the PLY reader loop forever; it occupies no bytes and must be skipped.
#[test]
fn ply_propertyless_huge_element_does_not_hang() {
    let dir = Scratch::new("hang");
    let src = "ply\nformat ascii 1.0\nelement junk 1000000000000000000\nelement vertex 4\nproperty float x\n\
               property float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\n\
               end_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n";
    let input = dir.write("hang.ply", src.as_bytes());
    let out = p2q(&["eval", &input, "--json"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let j = parse_json(&String::from_utf8_lossy(&out.stdout)).expect("test: eval prints JSON");
    assert_eq!(j.get("faces").and_then(Json::num), Some(1.0));
}

#[test]
fn file_system_errors_name_the_path() {
    let dir = Scratch::new("fs");
    let good = dir.write("good.obj", b"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n");
    std::fs::create_dir(dir.path("folder.obj")).expect("test: mkdir");
    let folder = dir.path("folder.obj").display().to_string();
    let missing = dir.path("missing.obj").display().to_string();
    let unknown = dir.write("mesh.stl", b"solid x\n");
    let no_dir_svg = dir.path("no_such_dir/out.svg").display().to_string();
    let no_dir_xyz = dir.path("no_such_dir/c.xyz").display().to_string();
    let no_dir_gt = dir.path("no_such_dir/g.obj").display().to_string();
    let xyz = dir.path("c.xyz").display().to_string();
    let png = dir.path("out.png").display().to_string();
    let noext = dir.path("out").display().to_string();
    let before = dir.entries();
    let cases: Vec<(Vec<&str>, i32, Vec<&str>)> = vec![
        // Inputs.
        (vec!["eval", &missing], 1, vec![&missing]),
        (vec!["eval", &folder], 1, vec![&folder]),
        (vec!["eval", &unknown], 2, vec![&unknown, ".obj .off .ply"]),
        (vec!["eval", &good, "--gt", &missing], 1, vec![&missing]),
        (vec!["eval", &good, "--gt", &folder], 1, vec![&folder]),
        (vec!["render", &missing, "-o", &no_dir_svg], 1, vec![&missing]),
        (vec!["render", &folder, "-o", &noext], 2, vec![&noext]),
        // Outputs: a missing folder, a folder, an unknown or missing extension.
        (vec!["render", &good, "-o", &no_dir_svg], 1, vec![&no_dir_svg]),
        (vec!["render", &good, "-o", &png], 2, vec![&png, ".svg"]),
        (vec!["render", &good, "-o", &noext], 2, vec![&noext, ".svg"]),
        (vec!["synth", "-o", &no_dir_xyz], 1, vec![&no_dir_xyz]),
        (vec!["synth", "-o", &png], 2, vec![&png]),
        (vec!["synth", "-o", &folder], 2, vec![&folder]),
        (vec!["synth", "-o", &good], 2, vec![&good]),
        (vec!["synth", "-o", &xyz, "--gt", &unknown], 2, vec![&unknown]),
        // Regression: the cloud was written before the ground truth failed.
        (vec!["synth", "-o", &xyz, "--gt", &no_dir_gt], 1, vec![&no_dir_gt]),
        (vec!["synth", "-o", &xyz, "--gt", &folder], 1, vec![&folder]),
    ];
    for (args, code, needles) in &cases {
        let out = p2q(args);
        assert_fails(&out, *code, needles, &format!("{args:?}"));
        assert_eq!(dir.entries(), before, "{args:?}: files left behind");
    }
    // A directory as the render target: an error naming it; the folder is untouched.
    std::fs::create_dir(dir.path("pic.svg")).expect("test: mkdir");
    let pic = dir.path("pic.svg").display().to_string();
    let out = p2q(&["render", &good, "-o", &pic]);
    assert_fails(&out, 1, &[&pic], "render -o folder");
    assert!(dir.path("pic.svg").is_dir());
    assert_eq!(std::fs::read_dir(dir.path("pic.svg")).expect("test: list").count(), 0);
}

#[test]
fn usage_errors_exit_2_and_say_what() {
    let dir = Scratch::new("usage");
    let good = dir.write("good.obj", b"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n");
    let svg = dir.path("o.svg").display().to_string();
    let xyz = dir.path("o.xyz").display().to_string();
    let before = dir.entries();
    let cases: Vec<(Vec<&str>, Vec<&str>)> = vec![
        (vec![], vec!["USAGE"]),
        (vec!["frobnicate"], vec!["unknown command", "frobnicate"]),
        (vec!["eval"], vec!["eval", "expected one mesh"]),
        (vec!["eval", &good, &good], vec!["got 2 argument"]),
        (vec!["eval", &good, "--bogus"], vec!["unknown option --bogus"]),
        (vec!["eval", &good, "--json=yes"], vec!["unknown option --json=yes"]),
        (vec!["eval", &good, "--gt"], vec!["--gt needs a value"]),
        (vec!["eval", &good, "--seed"], vec!["--seed needs a value"]),
        (vec!["eval", &good, "--seed", "-1"], vec!["--seed", "-1"]),
        (vec!["eval", &good, "--seed=1e3"], vec!["--seed", "1e3"]),
        (vec!["render", &good], vec!["missing -o"]),
        (vec!["render", &good, "-o"], vec!["-o needs a value"]),
        (vec!["render", &good, "-o="], vec!["-o needs a non-empty value"]),
        (vec!["render", &good, "-o", ""], vec!["-o needs a non-empty value"]),
        (vec!["render", "-o", &svg], vec!["expected one mesh"]),
        (vec!["render", &good, "-o", &svg, "--width", "0"], vec!["--width", "0"]),
        (vec!["render", &good, "-o", &svg, "--width", "99999999999"], vec!["--width"]),
        (vec!["render", &good, "-o", &svg, "--height", "-5"], vec!["--height"]),
        (vec!["render", &good, "-o", &svg, "--view", "nan,1"], vec!["--view"]),
        (vec!["render", &good, "-o", &svg, "--view", "10"], vec!["--view"]),
        (vec!["render", &good, "-o", &svg, "--up", "x"], vec!["--up"]),
        (vec!["render", &good, "-o", &svg, "--no-edges=1"], vec!["--no-edges=1"]),
        (vec!["synth"], vec!["missing -o"]),
        (vec!["synth", "-o", &xyz, "extra"], vec!["no positional"]),
        (vec!["synth", "-o", &xyz, "--shape", "klein_bottle"], vec!["klein_bottle"]),
        (vec!["synth", "-o", &xyz, "--noise"], vec!["--noise needs a value"]),
        (vec!["synth", "-o", &xyz, "--noise", "lots"], vec!["--noise", "lots"]),
        (vec!["synth", "-o", &xyz, "--seed", "18446744073709551616"], vec!["--seed"]),
        (vec!["synth", "-o", &xyz, "-x"], vec!["unknown option -x"]),
    ];
    for (args, needles) in &cases {
        let out = p2q(args);
        assert_fails(&out, 2, needles, &format!("{args:?}"));
        assert_eq!(dir.entries(), before, "{args:?}: files left behind");
    }
    // Not-yet-landed subcommands may refuse, but only as a clean usage or data error.
    for cmd in COMMANDS {
        let out = p2q(&[cmd, "--definitely-not-an-option"]);
        let code = out.status.code();
        assert!(code == Some(1) || code == Some(2), "{cmd}: {code:?} {}", stderr(&out));
        assert_fails(&out, code.unwrap_or(-1), &[cmd], cmd);
    }
}

/// Bad values that parse: refused with no output and no abort; since session 20 as
/// usage errors naming the option, as `dataset` refuses them (they were data errors, exit
/// 1, naming no option).
#[test]
fn bad_values_are_data_errors_without_output() {
    let dir = Scratch::new("values");
    let xyz = dir.path("c.xyz").display().to_string();
    let gt = dir.path("g.obj").display().to_string();
    let before = dir.entries();
    for (flag, value) in [
        ("--noise", "nan"),
        ("--noise", "-1"),
        ("--noise", "inf"),
        // Regression: 1e9 noise points per vertex aborted on an 11.6 TB allocation.
        ("--noise", "1e9"),
        ("--offset", "nan"),
        ("--offset", "-0.5"),
        ("--jitter", "nan"),
        ("--jitter", "-0.1"),
        ("--jitter", "1.5"),
    ] {
        let out = p2q(&["synth", "-o", &xyz, "--gt", &gt, flag, value]);
        assert_fails(&out, 2, &[flag], &format!("synth {flag} {value}"));
        assert_eq!(dir.entries(), before, "synth {flag} {value}: files left behind");
    }
}

#[test]
fn help_for_every_subcommand() {
    for args in [vec!["--help"], vec!["-h"], vec!["help"]] {
        let out = p2q(&args);
        assert_eq!(out.status.code(), Some(0), "{args:?}");
        let text = String::from_utf8_lossy(&out.stdout);
        for cmd in COMMANDS {
            assert!(text.contains(cmd), "{args:?} lists {cmd}: {text}");
        }
    }
    for cmd in COMMANDS {
        for flag in ["--help", "-h"] {
            // Help wins over anything else on the line, even a bad option.
            for args in [vec![cmd, flag], vec![cmd, "--bogus", flag]] {
                let out = p2q(&args);
                assert_eq!(out.status.code(), Some(0), "{args:?}: {}", stderr(&out));
                let text = String::from_utf8_lossy(&out.stdout);
                assert!(text.contains(cmd), "{args:?}: help does not name the command: {text}");
                assert!(stderr(&out).is_empty(), "{args:?}");
            }
        }
        // `help COMMAND` prints what `COMMAND --help` prints (not the overview).
        let own = p2q(&[cmd, "--help"]);
        for args in [
            vec!["help", cmd],
            vec!["--quiet", "help", cmd],
            vec!["--threads", "2", "help", cmd],
            vec!["help", "--threads", "2", cmd],
            vec!["help", "--threads=2", cmd],
        ] {
            let out = p2q(&args);
            assert_eq!(out.status.code(), Some(0), "{args:?}: {}", stderr(&out));
            assert_eq!(out.stdout, own.stdout, "{args:?}");
        }
    }
    assert_fails(&p2q(&["help", "frobnicate"]), 2, &["unknown command", "frobnicate"], "help frobnicate");
    // Global options before `help` or `--help` are not its topic: the overview.
    for args in
        [vec!["--threads", "4", "--help"], vec!["--threads", "4", "help"], vec!["help", "--threads", "4"]]
    {
        let out = p2q(&args);
        assert_eq!(out.status.code(), Some(0), "{args:?}: {}", stderr(&out));
        assert!(String::from_utf8_lossy(&out.stdout).contains("COMMANDS:"), "{args:?}");
    }
}

/// Every number in an `eval --json` object, checked finite (no `null` standing in
/// for a NaN); returns the object.
fn finite_json(out: &Output, what: &str) -> Json {
    assert!(out.status.success(), "{what}: {}", stderr(out));
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    for bad in ["NaN", "nan", "inf", "null"] {
        assert!(!text.contains(bad), "{what}: {bad} in {text}");
    }
    parse_json(&text).unwrap_or_else(|e| panic!("{what}: {e}: {text}"))
}

fn get(j: &Json, k: &str) -> f64 {
    j.get(k).and_then(Json::num).unwrap_or_else(|| panic!("key {k} missing"))
}

fn obj_text(vertices: &[[f64; 3]], faces: &[&[u32]]) -> Vec<u8> {
    let mut s = String::new();
    for v in vertices {
        s.push_str(&format!("v {:e} {:e} {:e}\n", v[0], v[1], v[2]));
    }
    for f in faces {
        s.push('f');
        for i in *f {
            s.push_str(&format!(" {}", i + 1));
        }
        s.push('\n');
    }
    s.into_bytes()
}

const SQUARE: [[f64; 3]; 4] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]];

#[test]
fn degenerate_meshes_give_finite_numbers_or_clean_errors() {
    let dir = Scratch::new("degenerate");
    let scaled = |k: f64| SQUARE.map(|p| p.map(|c| c * k));
    let cases: Vec<(&str, Vec<u8>)> = vec![
        ("same.obj", obj_text(&[[1.0; 3]; 4], &[&[0, 1, 2, 3]])),
        (
            "collinear.obj",
            obj_text(&[[0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0], [3.0, 0.0, 0.0]], &[&[0, 1, 2, 3]]),
        ),
        ("zero_area.obj", obj_text(&SQUARE, &[&[0, 1, 2, 3], &[0, 1, 0, 1], &[0, 0, 0], &[2, 3, 2]])),
        ("repeated.obj", obj_text(&SQUARE, &[&[0, 1, 1, 2]])),
        ("one_face.obj", obj_text(&SQUARE, &[&[0, 1, 2, 3]])),
        ("one_tri.obj", obj_text(&SQUARE[..3], &[&[0, 1, 2]])),
        (
            "unreferenced.obj",
            obj_text(&[SQUARE[0], SQUARE[1], SQUARE[2], SQUARE[3], [9.0, 9.0, 9.0]], &[&[0, 1, 2, 3]]),
        ),
        ("no_faces.obj", obj_text(&SQUARE, &[])),
        ("one_point.obj", obj_text(&[[1.0, 2.0, 3.0]], &[])),
        ("bowtie.obj", obj_text(&[SQUARE[0], SQUARE[2], SQUARE[1], SQUARE[3]], &[&[0, 1, 2, 3]])),
        ("huge.obj", obj_text(&scaled(1e300), &[&[0, 1, 2, 3]])),
        ("tiny.obj", obj_text(&scaled(1e-300), &[&[0, 1, 2, 3]])),
        ("far.obj", obj_text(&SQUARE.map(|p| [p[0] + 1e15, p[1] - 1e15, p[2]]), &[&[0, 1, 2, 3]])),
        ("big_ngon.obj", obj_text(&SQUARE, &[&[0, 1, 2, 3, 0, 1, 2, 3, 0, 1, 2, 3]])),
    ];
    for (name, bytes) in &cases {
        let input = dir.write(name, bytes);
        let j = finite_json(&p2q(&["eval", &input, "--json"]), name);
        for k in ["watertightness", "manifoldness"] {
            assert!((0.0..=1.0).contains(&get(&j, k)), "{name}: {k}");
        }
        assert!((-1.0..=1.0).contains(&get(&j, "scaled_jacobian")), "{name}");
        // Against itself: finite numbers, or a clean error naming the file.
        let out = p2q(&["eval", &input, "--gt", &input, "--json"]);
        if out.status.success() {
            let j = finite_json(&out, &format!("{name} vs itself"));
            for k in ["chamfer", "precision", "recall"] {
                assert!(get(&j, k) >= 0.0, "{name}: {k}");
            }
        } else {
            assert_fails(&out, 1, &[&input], &format!("{name} vs itself"));
        }
        let svg_path = dir.path(&format!("{name}.svg"));
        let out = p2q(&["render", &input, "-o", &svg_path.display().to_string()]);
        assert!(out.status.success(), "render {name}: {}", stderr(&out));
        let svg = std::fs::read_to_string(&svg_path).expect("test: read svg");
        check_xml(&svg).unwrap_or_else(|e| panic!("render {name}: {e}"));
        assert!(!svg.contains("NaN") && !svg.contains("inf"), "render {name}: {svg}");
    }
    // Regression: a unit square scaled to 1e300 or 1e-300 was called degenerate
    // (scaled Jacobian 0: squared lengths overflowed or underflowed), and a 1e300
    // ground truth had a "non-finite diagonal". A square is perfect at any scale.
    for name in ["one_face.obj", "huge.obj", "tiny.obj", "far.obj"] {
        let input = dir.path(name).display().to_string();
        let j = finite_json(&p2q(&["eval", &input, "--gt", &input, "--json"]), name);
        assert!((get(&j, "scaled_jacobian") - 1.0).abs() < 1e-12, "{name}");
        assert!((get(&j, "edge_ratio") - 1.0).abs() < 1e-12, "{name}");
        assert_eq!(
            (get(&j, "precision"), get(&j, "recall"), get(&j, "degenerate_quads")),
            (1.0, 1.0, 0.0),
            "{name}"
        );
    }
    // A ground truth without extent cannot normalise the Chamfer distance: an error
    // naming both files, not NaN.
    let same = dir.path("same.obj").display().to_string();
    let one = dir.path("one_face.obj").display().to_string();
    assert_fails(&p2q(&["eval", &one, "--gt", &same]), 1, &[&one, &same, "diagonal"], "gt without extent");
    let no_faces = dir.path("no_faces.obj").display().to_string();
    assert_fails(&p2q(&["eval", &one, "--gt", &no_faces]), 1, &[&no_faces, "no faces"], "gt without faces");
}

/// Control bytes of a garbage file are escaped in the message (no terminal escapes).
#[test]
fn garbage_is_not_echoed_raw_to_the_terminal() {
    let dir = Scratch::new("escape");
    let input = dir.write("esc.off", b"\x1b[2J\x1b]0;pwned\x07OFF\n");
    let out = p2q(&["eval", &input]);
    assert_fails(&out, 1, &[&input, ":1:"], "escape");
    let err = stderr(&out);
    assert!(!err.contains('\x1b') && !err.contains('\x07'), "{err:?}");
}

#[test]
fn paths_with_odd_characters_are_named_as_given() {
    let dir = Scratch::new("odd names");
    let input = dir.write("a mesh ü (1).obj", b"v 0 0 0\nv 1 0 0\nf 1 2 3\n");
    assert_fails(&p2q(&["eval", &input]), 1, &[&input, ":3:"], "odd name");
    dir.write("-dash.obj", b"v 0 0 0\n");
    // A name that starts with a dash is an option unless it comes after `--`.
    assert_fails(&p2q_in(Some(&dir.0), &["eval", "-dash.obj"]), 2, &["unknown option -dash.obj"], "dash");
    let j = finite_json(&p2q_in(Some(&dir.0), &["eval", "--json", "--", "-dash.obj"]), "after --");
    assert_eq!(get(&j, "vertices"), 1.0);
}

/// Regression: `point2quad eval x.obj | true` panicked ("failed printing to stdout:
/// Broken pipe"). The reader closes its end before eval has read its (large) input,
/// so the write meets a broken pipe; the output must end quietly, without a panic.
#[test]
fn closed_stdout_pipe_is_not_a_panic() {
    let dir = Scratch::new("pipe");
    let n = 200u32;
    let mut s = String::new();
    for j in 0..=n {
        for i in 0..=n {
            s.push_str(&format!("v {i} {j} 0\n"));
        }
    }
    for j in 0..n {
        for i in 0..n {
            let v = |a: u32, b: u32| b * (n + 1) + a + 1;
            s.push_str(&format!("f {} {} {} {}\n", v(i, j), v(i + 1, j), v(i + 1, j + 1), v(i, j + 1)));
        }
    }
    let input = dir.write("big.obj", s.as_bytes());
    for args in [vec!["eval", input.as_str()], vec!["eval", input.as_str(), "--json"], vec!["eval", "--help"]]
    {
        let out = run_with_closed_pipe(&args, Pipe::Stdout);
        let err = stderr(&out);
        assert!(!err.contains("panicked") && !err.contains("Broken pipe"), "{args:?}: {err}");
        assert_eq!(out.status.code(), Some(0), "{args:?}: {err}");
    }
}

/// Regression: classic Mac line endings (CR only) made an OBJ one long line: one
/// vertex, no face, and no error.
#[test]
fn cr_only_line_endings_read_every_line() {
    let dir = Scratch::new("cr");
    let obj = dir.write("cr.obj", b"v 0 0 0\rv 1 0 0\rv 1 1 0\rv 0 1 0\rf 1 2 3 4\r");
    let off = dir.write("cr.off", b"OFF\r4 1 0\r0 0 0\r1 0 0\r1 1 0\r0 1 0\r4 0 1 2 3\r");
    for input in [obj, off] {
        let j = finite_json(&p2q(&["eval", &input, "--json"]), &input);
        assert_eq!(
            (get(&j, "vertices"), get(&j, "faces"), get(&j, "scaled_jacobian")),
            (4.0, 1.0, 1.0),
            "{input}"
        );
    }
}

/// Regression: a mesh with a split seam (repeated positions, as exporters write at UV
/// seams) scored precision and recall 0.5 against itself.
#[test]
fn split_seam_mesh_matches_itself() {
    let dir = Scratch::new("seam");
    let seam = [
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
        [0.0, 1.0, 0.0],
        [1.0, 0.0, 0.0],
        [2.0, 0.0, 0.0],
        [2.0, 1.0, 0.0],
        [1.0, 1.0, 0.0],
    ];
    let input = dir.write("seam.obj", &obj_text(&seam, &[&[0, 1, 2, 3], &[4, 5, 6, 7]]));
    let j = finite_json(&p2q(&["eval", &input, "--gt", &input, "--json"]), "seam");
    assert_eq!((get(&j, "precision"), get(&j, "recall")), (1.0, 1.0));
}

/// Regression: a file name that is not valid UTF-8 made `std::env::args` panic.
#[cfg(unix)]
#[test]
fn non_utf8_argument_is_a_usage_error() {
    use std::os::unix::ffi::OsStrExt;
    let dir = Scratch::new("argv");
    let name = std::ffi::OsStr::from_bytes(b"\xffmesh.obj");
    let path = dir.0.join(name);
    if std::fs::write(&path, b"v 0 0 0\n").is_err() {
        return; // a file system that refuses such names cannot hold this case
    }
    let out = Command::new(env!("CARGO_BIN_EXE_point2quad"))
        .arg("eval")
        .arg(&path)
        .output()
        .expect("test: run the binary");
    assert_fails(&out, 2, &["argument 2", "mesh.obj", "not valid UTF-8"], "non-UTF-8 argument");
}
