//! `point2quad render`: a shaded SVG picture of a mesh (painter's order, back faces
//! dimmed, boundary edges red, non-manifold edges blue).

use std::path::Path;

use crate::args::{Args, Spec};
use point2quad::io::mesh_io::read_mesh;
use point2quad::io::svg::{write_svg, RenderOptions};
use point2quad::{Error, Result};

/// The text of `point2quad render --help`.
pub const HELP: &str = "\
point2quad render: shaded SVG picture of a mesh

USAGE:
    point2quad render MESH -o OUT.svg [--view AZ,EL] [--up y|z] [--width W] [--height H] [--no-edges]

ARGS:
    MESH           mesh to draw (.obj .ply .off; any polygons)
    -o OUT.svg     picture to write
    --view AZ,EL   viewer azimuth around the up axis and elevation, degrees (default 30,20)
    --up y|z       which axis points up in the picture (default y)
    --width W      width in pixels (default 800)
    --height H     height in pixels (default: fit the mesh)
    --no-edges     do not draw face edges (boundary and non-manifold edges still are)

Faces are drawn back to front with Lambert shading; back faces are dimmed; boundary
edges red, non-manifold edges blue, drawn on top.
";

/// Runs `point2quad render` on its arguments (after the subcommand name).
///
/// # Errors
/// `Usage` for bad arguments; read, parse and write errors naming the file.
pub fn run(argv: &[String]) -> Result<()> {
    let spec = Spec { valued: &["-o", "--view", "--up", "--width", "--height"], switches: &["--no-edges"] };
    let args = Args::parse("render", argv, &spec)?;
    let input = &args.expect_positional("render", 1, "one mesh MESH")?[0];
    let out = args.required("render", "-o")?;
    let is_svg = Path::new(out).extension().is_some_and(|e| e.eq_ignore_ascii_case("svg"));
    if !is_svg {
        return Err(Error::Usage(format!(
            "render: {out}: the picture is SVG; the output name must end in .svg (see `point2quad render --help`)"
        )));
    }
    let mut opts = RenderOptions::default();
    if let Some(v) = args.value("--view") {
        let parsed: Option<(f64, f64)> = v
            .split_once(',')
            .and_then(|(a, e)| Some((a.trim().parse().ok()?, e.trim().parse().ok()?)))
            .filter(|(a, e): &(f64, f64)| a.is_finite() && e.is_finite());
        let (az, el) = parsed.ok_or_else(|| {
            Error::Usage(format!(
                "render: --view: expected AZ,EL in degrees, got {v:?} (see `point2quad render --help`)"
            ))
        })?;
        (opts.azimuth_deg, opts.elevation_deg) = (az, el);
    }
    opts.z_up = match args.value("--up").unwrap_or("y") {
        "y" | "Y" => false,
        "z" | "Z" => true,
        other => {
            return Err(Error::Usage(format!(
                "render: --up: expected y or z, got {other:?} (see `point2quad render --help`)"
            )))
        }
    };
    opts.width = args.parsed("render", "--width", opts.width)?;
    if args.value("--height").is_some() {
        opts.height = Some(args.parsed("render", "--height", 0u32)?);
    }
    for (name, v) in [("--width", Some(opts.width)), ("--height", opts.height)] {
        if let Some(v) = v {
            if !(16..=20_000).contains(&v) {
                return Err(Error::Usage(format!("render: {name} must be between 16 and 20000, got {v}")));
            }
        }
    }
    opts.face_edges = !args.switch("--no-edges");
    let mesh = read_mesh(Path::new(input))?;
    crate::output::check_output_path(Path::new(out))?;
    crate::output::check_not_input("render", Path::new(out), Path::new(input))?;
    write_svg(Path::new(out), &mesh, &opts)
}
