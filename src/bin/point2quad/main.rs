//! The `point2quad` command line: parses arguments, calls the library, maps errors
//! to a message on stderr and a non-zero exit code. Logic lives in the library.

mod args;
mod cmd_candidates;
mod cmd_dataset;
mod cmd_eval;
mod cmd_reconstruct;
mod cmd_refine;
mod cmd_render;
mod cmd_repair;
mod cmd_synth;
mod cmd_train;
mod output;

use std::process::ExitCode;

/// Appended to every command's `--help`.
const GLOBAL_HELP: &str = "
Also on every command: --threads N (worker threads, 1 to 1024; the same results for any
count) and --quiet (no progress or summary lines); see `point2quad --help`.
";

/// A subcommand's entry point.
type RunFn = fn(&[String]) -> point2quad::Result<()>;

const USAGE: &str = "\
point2quad: point cloud -> pure-quad manifold mesh (Point2Quad, from scratch)

USAGE:
    point2quad <COMMAND> [ARGS...]
    point2quad help <COMMAND>             the command's details (as point2quad <COMMAND> --help)

OPTIONS (every command, before or after it):
    --threads N  worker threads, 1 to 1024 [all cores, or RAYON_NUM_THREADS, which it
                 overrides]; results do not depend on it
    --quiet      no progress or summary lines on stderr; notes, warnings and errors stay

COMMANDS:
    reconstruct  INPUT -o OUT.{obj,ply,off} [--model FILE] [--svg PREVIEW.svg] [--no-postprocess]
    candidates   INPUT -o CAND.txt         candidate quads, 4 zero-based indices per line
    eval         PRED --gt GT [--json]     mesh quality and accuracy metrics
    dataset      --out DIR [--synthetic N] [--meshes DIR] [--noise 0.1] [--seed S]
    train        --data DIR --out MODEL [--config default|default_kp|paper] [--epochs N] [--resume CKPT]
    refine       --data DIR --model BASE --out MODEL [--rounds 6]   train refinement rounds
    repair       MESH -o OUT.{obj,ply,off} post-process and hole-fill a quad mesh or face soup
    render       MESH -o OUT.svg           shaded SVG picture of a mesh
    synth        -o CLOUD.xyz [--gt GT.obj] synthetic noisy cloud + ground-truth quad mesh
";

/// A command's help text and entry point, by name.
fn command(name: &str) -> Option<(&'static str, RunFn)> {
    Some(match name {
        "reconstruct" => (cmd_reconstruct::HELP, cmd_reconstruct::run),
        "candidates" => (cmd_candidates::HELP, cmd_candidates::run),
        "eval" => (cmd_eval::HELP, cmd_eval::run),
        "dataset" => (cmd_dataset::HELP, cmd_dataset::run),
        "train" => (cmd_train::HELP, cmd_train::run),
        "refine" => (cmd_refine::HELP, cmd_refine::run),
        "repair" => (cmd_repair::HELP, cmd_repair::run),
        "render" => (cmd_render::HELP, cmd_render::run),
        "synth" => (cmd_synth::HELP, cmd_synth::run),
        _ => return None,
    })
}

fn main() -> ExitCode {
    // `std::env::args` panics on an argument that is not valid Unicode (a file name
    // with Latin-1 bytes, say); refuse it with a message instead.
    let mut argv: Vec<String> = Vec::new();
    for (i, a) in std::env::args_os().skip(1).enumerate() {
        match a.into_string() {
            Ok(s) => argv.push(s),
            Err(raw) => {
                output::stderr(&format!(
                    "point2quad: argument {} ({}) is not valid UTF-8; rename the file or use another path to it\n",
                    i + 1,
                    raw.to_string_lossy()
                ));
                return ExitCode::from(2);
            }
        }
    }
    // The global options may also come before the command.
    let mut at = 0;
    while let Some(a) = argv.get(at) {
        match a.as_str() {
            "--quiet" => at += 1,
            "--threads" => at += 2,
            a if a.starts_with("--threads=") => at += 1,
            _ => break,
        }
    }
    let Some(cmd) = argv.get(at) else {
        output::stderr(USAGE);
        return ExitCode::from(2);
    };
    let rest: Vec<String> = argv[..at].iter().chain(&argv[at + 1..]).cloned().collect();
    let rest = &rest[..];
    let (help, run): (&str, RunFn) = match cmd.as_str() {
        "-h" | "--help" | "help" => {
            // `point2quad help COMMAND` is `point2quad COMMAND --help`: the first word after
            // `help` that is no global option or its value (help with a bad global option
            // is the overview).
            let after = take_globals(cmd, &argv[at + 1..]).map(|(_, _, rest)| rest).unwrap_or_default();
            let topic = after.iter().find(|a| !a.starts_with('-')).map(String::as_str);
            return match topic.map(|t| (t, command(t))) {
                None => {
                    let _ = output::stdout(USAGE);
                    ExitCode::SUCCESS
                }
                Some((_, Some((help, _)))) => {
                    let _ = output::stdout(&format!("{help}{GLOBAL_HELP}"));
                    ExitCode::SUCCESS
                }
                Some((t, None)) => {
                    output::stderr(&format!("point2quad help: unknown command {t:?}\n\n{USAGE}\n"));
                    ExitCode::from(2)
                }
            };
        }
        "-V" | "--version" => {
            let _ = output::stdout(&format!("point2quad {}\n", env!("CARGO_PKG_VERSION")));
            return ExitCode::SUCCESS;
        }
        name => match command(name) {
            Some(c) => c,
            None => {
                output::stderr(&format!("point2quad: unknown command {name:?}\n\n{USAGE}\n"));
                return ExitCode::from(2);
            }
        },
    };
    if rest.iter().any(|a| a == "-h" || a == "--help") {
        let _ = output::stdout(&format!("{help}{GLOBAL_HELP}"));
        return ExitCode::SUCCESS;
    }
    let rest = match take_globals(cmd, rest) {
        Ok((threads, quiet, rest)) => {
            output::set_quiet(quiet);
            if let Some(n) = threads {
                match point2quad::par::set_threads(n) {
                    Ok(m) if m != n => output::stderr(&format!(
                        "point2quad {cmd}: note: --threads {n}: this build has no multi-threading (the `parallel` feature is off); it runs on {m}\n"
                    )),
                    Ok(_) => {}
                    Err(e) => {
                        output::stderr(&format!("point2quad {cmd}: error: {e}\n"));
                        return ExitCode::from(2);
                    }
                }
            }
            rest
        }
        Err(e) => {
            output::stderr(&format!("point2quad {cmd}: error: {e}\n"));
            return ExitCode::from(2);
        }
    };
    match run(&rest) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            output::stderr(&format!("point2quad {cmd}: error: {e}\n"));
            match e {
                point2quad::Error::Usage(_) => ExitCode::from(2),
                _ => ExitCode::from(1),
            }
        }
    }
}

/// Most worker threads `--threads` accepts.
const MAX_THREADS: usize = 1024;

/// A command's arguments without the global options, and those options' values.
type Globals = (Option<usize>, bool, Vec<String>);

/// Takes the global `--threads N` (or `--threads=N`) and `--quiet` out of a command's
/// arguments (up to a `--`, after which everything is positional).
fn take_globals(cmd: &str, argv: &[String]) -> point2quad::Result<Globals> {
    let usage = |m: String| point2quad::Error::Usage(format!("{cmd}: {m}"));
    let mut threads = None;
    let mut quiet = false;
    let mut rest = Vec::with_capacity(argv.len());
    let mut i = 0;
    while i < argv.len() {
        let a = &argv[i];
        if a == "--" {
            rest.extend(argv[i..].iter().cloned());
            break;
        }
        if a == "--quiet" {
            if quiet {
                return Err(usage("option --quiet given twice".into()));
            }
            quiet = true;
            i += 1;
            continue;
        }
        let value = if a == "--threads" {
            i += 1;
            Some(argv.get(i).ok_or_else(|| usage("option --threads needs a value".into()))?.clone())
        } else {
            a.strip_prefix("--threads=").map(str::to_string)
        };
        match value {
            Some(v) => {
                if threads.is_some() {
                    return Err(usage("option --threads given twice".into()));
                }
                let n: usize =
                    v.trim().parse().ok().filter(|n| (1..=MAX_THREADS).contains(n)).ok_or_else(|| {
                        usage(format!("--threads {v:?}: expected a whole number from 1 to {MAX_THREADS}"))
                    })?;
                threads = Some(n);
            }
            None => rest.push(a.clone()),
        }
        i += 1;
    }
    Ok((threads, quiet, rest))
}
