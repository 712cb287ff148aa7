//! `point2quad synth`: a synthetic quad mesh made by the project's own generators,
//! sampled as a noisy point cloud (its vertices plus noise points), with the mesh
//! written as ground truth. Used by `make demo` and handy for trying the tool.

use crate::args::{Args, Spec};
use point2quad::io::atomic::commit_all;
use point2quad::io::mesh_io::{prepare_mesh_with, read_mesh, MeshFormat, WriteOptions};
use point2quad::io::points::{prepare_points_xyz, PointFormat};
use point2quad::mesh::poly::PolyMesh;
use point2quad::mesh::shapes::{random_shape, random_shape_of, triangle_split, Family};
use point2quad::pipeline::noise::{jitter_vertices, noise_points, NoiseConfig};
use point2quad::rng::Rng;
use point2quad::{Error, Result};
use std::path::Path;

pub const HELP: &str = "\
point2quad synth: a synthetic quad mesh as a noisy point cloud + its ground truth

USAGE:
    point2quad synth -o CLOUD.xyz [--gt GT.{obj,ply,off}] [OPTIONS]
    point2quad synth --from MESH -o CLOUD.xyz [--gt GT] [--noise F] [--offset F] [--jitter F] [--seed S] [--triangle-split]

The cloud holds the mesh's vertices, then round(noise × #vertices) noise points, each
on a random face (area-weighted) moved along its normal by up to offset × the face's
mean edge length.

OPTIONS:
    -o CLOUD.xyz          output point cloud (required)
    --gt FILE             also write the ground-truth quad mesh
    --from MESH           use this pure-quad mesh (.obj/.off/.ply) instead of a generated one
    --shape NAME          random, grid, height_field, cube, cube_sphere, torus, tube,
                          cylinder, cage_smooth, cage_sharp [random]
    --seed S              random seed [0]
    --noise F             noise points per vertex [0.1]
    --offset F            noise distance along the normal, x mean edge length [0.1]
    --jitter F            move every mesh vertex first by a Gaussian step, F x the
                          mean length of its edges in each coordinate (scanner-like
                          positional noise, 0 <= F <= 1); --gt then writes the moved
                          mesh, whose vertices the cloud starts with [0]
    --triangle-split      first convert the mesh as a triangle mesh is usually made a
                          quad mesh: each quad cut into two triangles along a random
                          diagonal, each triangle into three quads around its centroid
                          (6 quads per quad; kites with valence-3 centres)
";

const SPEC: Spec = Spec {
    valued: &["-o", "--from", "--gt", "--shape", "--seed", "--noise", "--offset", "--jitter"],
    switches: &["--triangle-split"],
};

pub fn run(argv: &[String]) -> Result<()> {
    let cmd = "synth";
    let a = Args::parse(cmd, argv, &SPEC)?;
    a.expect_positional(cmd, 0, "no positional arguments")?;
    let out = a.required(cmd, "-o")?;
    // Check every output name before writing anything, so that a bad --gt does not
    // leave a cloud behind (and a .ply cloud is not written as .xyz text).
    let csv = Path::new(out).extension().is_some_and(|e| e.eq_ignore_ascii_case("csv"));
    if csv || PointFormat::from_path(Path::new(out))? != PointFormat::Xyz {
        return Err(Error::Usage(format!(
            "{cmd}: {out}: the cloud is written as text; use .xyz, .txt or .pts (see `point2quad {cmd} --help`)"
        )));
    }
    crate::output::check_output_path(Path::new(out))?;
    if let Some(gt) = a.value("--gt") {
        MeshFormat::from_path(Path::new(gt))?;
        crate::output::check_output_path(Path::new(gt))?;
    }
    if let Some(from) = a.value("--from") {
        for o in std::iter::once(out).chain(a.value("--gt")) {
            crate::output::check_not_input(cmd, Path::new(o), Path::new(from))?;
        }
    }
    let seed = a.parsed(cmd, "--seed", 0u64)?;
    let noise =
        NoiseConfig { fraction: a.parsed(cmd, "--noise", 0.1)?, offset: a.parsed(cmd, "--offset", 0.1)? };
    crate::cmd_dataset::check_noise(cmd, &noise)?;
    let jitter = a.parsed_in(cmd, "--jitter", 0.0f64, 0.0, 1.0, "a fraction of the mean edge length")?;
    let mut rng = Rng::new(seed);
    let shape = a.value("--shape").unwrap_or("random");
    // Errors about a mesh read from a file name it, once: not "invalid input: FILE:
    // invalid input: …" (session 37's audit: the noise step's "the mesh's area is 0"
    // named no file).
    let named = |e: Error| match (e, a.value("--from")) {
        (Error::InvalidInput(m), Some(from)) => Error::invalid(format!("{from}: {m}")),
        (other, _) => other,
    };
    let mesh = if let Some(from) = a.value("--from") {
        if a.value("--shape").is_some() {
            return Err(Error::Usage(format!("{cmd}: give --from or --shape, not both")));
        }
        let poly = read_mesh(Path::new(from))?;
        poly.to_quads().map_err(named)?
    } else if shape == "random" {
        random_shape(&mut rng)
    } else {
        let fam = Family::ALL.iter().copied().find(|f| f.name() == shape).ok_or_else(|| {
            Error::Usage(format!("{cmd}: unknown --shape {shape:?} (see `point2quad {cmd} --help`)"))
        })?;
        random_shape_of(fam, &mut rng)
    };
    // Drawn after the shape and before the jitter (without the switch, nothing is drawn).
    let mesh = if a.switch("--triangle-split") { triangle_split(&mesh, &mut rng) } else { mesh };
    // Drawn before the noise points (zero jitter draws nothing: the same cloud as without).
    let mesh = jitter_vertices(&mesh, jitter, &mut rng).map_err(named)?;
    let mut cloud = mesh.vertices.clone();
    cloud.extend(noise_points(&mesh, &noise, &mut rng).map_err(named)?);
    // Both files in full before either replaces its target: half a result is worse
    // than none, and a failed --gt must not cost the old content of -o.
    let mut staged = vec![prepare_points_xyz(Path::new(out), &cloud)?];
    if let Some(gt) = a.value("--gt") {
        staged.push(prepare_mesh_with(Path::new(gt), &PolyMesh::from(&mesh), &WriteOptions::default())?);
    }
    commit_all(staged)?;
    let shape = a.value("--from").unwrap_or(shape);
    crate::output::info(&format!(
        "synth: {shape} (seed {seed}): {} vertices, {} quads, {} noise points -> {out}\n",
        mesh.vertices.len(),
        mesh.quads.len(),
        cloud.len() - mesh.vertices.len()
    ));
    Ok(())
}
