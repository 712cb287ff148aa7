//! The `point2quad` command line: parses arguments, calls the library, maps errors
//! to a message on stderr and a non-zero exit code. Logic lives in the library.

mod args;
mod cmd_candidates;
mod cmd_dataset;
mod cmd_eval;
mod cmd_reconstruct;
mod cmd_render;
mod cmd_repair;
mod cmd_synth;
mod cmd_train;

use std::process::ExitCode;

/// A subcommand's entry point.
type RunFn = fn(&[String]) -> point2quad::Result<()>;

const USAGE: &str = "\
point2quad: point cloud -> pure-quad manifold mesh (Point2Quad, from scratch)

USAGE:
    point2quad <COMMAND> [ARGS...]        (point2quad <COMMAND> --help for details)

COMMANDS:
    reconstruct  INPUT -o OUT.{obj,ply,off} [--model FILE] [--svg PREVIEW.svg] [--no-postprocess]
    candidates   INPUT -o CAND.txt         candidate quads, 4 zero-based indices per line
    eval         PRED --gt GT [--json]     mesh quality and accuracy metrics
    dataset      --out DIR [--synthetic N] [--meshes DIR] [--noise 0.1] [--seed S]
    train        --data DIR --out MODEL [--config default|paper] [--epochs N] [--resume CKPT]
    repair       MESH -o OUT.{obj,ply,off} post-process and hole-fill a quad mesh or face soup
    render       MESH -o OUT.svg           shaded SVG picture of a mesh
    synth        -o CLOUD.xyz [--gt GT.obj] synthetic noisy cloud + ground-truth quad mesh
";

fn main() -> ExitCode {
    let argv: Vec<String> = std::env::args().skip(1).collect();
    let Some(cmd) = argv.first() else {
        eprint!("{USAGE}");
        return ExitCode::from(2);
    };
    let rest = &argv[1..];
    let (help, run): (&str, RunFn) = match cmd.as_str() {
        "-h" | "--help" | "help" => {
            print!("{USAGE}");
            return ExitCode::SUCCESS;
        }
        "-V" | "--version" => {
            println!("point2quad {}", env!("CARGO_PKG_VERSION"));
            return ExitCode::SUCCESS;
        }
        "reconstruct" => (cmd_reconstruct::HELP, cmd_reconstruct::run),
        "candidates" => (cmd_candidates::HELP, cmd_candidates::run),
        "eval" => (cmd_eval::HELP, cmd_eval::run),
        "dataset" => (cmd_dataset::HELP, cmd_dataset::run),
        "train" => (cmd_train::HELP, cmd_train::run),
        "repair" => (cmd_repair::HELP, cmd_repair::run),
        "render" => (cmd_render::HELP, cmd_render::run),
        "synth" => (cmd_synth::HELP, cmd_synth::run),
        other => {
            eprintln!("point2quad: unknown command {other:?}\n\n{USAGE}");
            return ExitCode::from(2);
        }
    };
    if rest.iter().any(|a| a == "-h" || a == "--help") {
        print!("{help}");
        return ExitCode::SUCCESS;
    }
    match run(rest) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("point2quad {cmd}: error: {e}");
            match e {
                point2quad::Error::Usage(_) => ExitCode::from(2),
                _ => ExitCode::from(1),
            }
        }
    }
}
