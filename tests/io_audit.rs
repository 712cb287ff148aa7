//! The reader gaps an input audit found, each now an error naming the file and the
//! line (and the property or face), while the valid neighbours of each bad input
//! still read the same values: decimal commas in .xyz, ASCII PLY values that do not
//! fit their declared type, a PLY property declared twice, a second `format` line
//! or a version other than 1.0, OBJ texture/normal indices that are not integers,
//! and the face number in the OBJ forward-index error.

#[path = "common/scratch.rs"]
mod scratch;

use point2quad::io::mesh_io::read_mesh;
use point2quad::io::points::read_points;
use point2quad::mesh::poly::PolyMesh;
use scratch::Scratch;

/// Writes `src` as `file` in `dir` and reads it as points: the error message.
fn points_err(dir: &Scratch, file: &str, src: &str) -> String {
    let p = dir.write(file, src.as_bytes());
    match read_points(std::path::Path::new(&p)) {
        Ok(pts) => panic!("{file}: read {} points, want an error; input:\n{src}", pts.len()),
        Err(e) => e.to_string(),
    }
}

/// Writes `src` as `file` in `dir` and reads it as a mesh: the error message.
fn mesh_err(dir: &Scratch, file: &str, src: &str) -> String {
    let p = dir.write(file, src.as_bytes());
    match read_mesh(std::path::Path::new(&p)) {
        Ok(m) => panic!("{file}: read {} faces, want an error; input:\n{src}", m.faces.len()),
        Err(e) => e.to_string(),
    }
}

/// Writes `src` as `file` in `dir` and reads it as a mesh, which must succeed.
fn mesh_ok(dir: &Scratch, file: &str, src: &str) -> PolyMesh {
    let p = dir.write(file, src.as_bytes());
    read_mesh(std::path::Path::new(&p)).unwrap_or_else(|e| panic!("{file}: {e}; input:\n{src}"))
}

/// Asserts that `err` starts with `PATH:LINE: ` of `file` in `dir` and holds `want`.
fn assert_at(err: &str, dir: &Scratch, file: &str, line: usize, want: &str) {
    let at = format!("{}:{line}: ", dir.p(file));
    assert!(err.starts_with(&at), "got '{err}', want it to start with '{at}'");
    assert!(err.contains(want), "got '{err}', want '{want}'");
}

// ---- 1. .xyz / .txt: decimal commas ----

/// Case comma_decimal_xyz (one line) and comma_decimal_all_xyz (every line): read as
/// commas-and-spaces columns, `1,5 2,5 3,5` was the point (1, 5, 2).
#[test]
fn decimal_commas_in_xyz_are_an_error_naming_the_line() {
    let dir = Scratch::new("io_audit_comma");
    let cases: &[(&str, &str, usize, &str)] = &[
        (
            "one.xyz",
            "0 0 0\n1 0 0\n1,5 2,5 3,5\n0 1 0\n",
            3,
            "point 2: '1,5 2,5 3,5' looks like decimal commas",
        ),
        (
            "all.txt",
            "0,92 9,18 10,81\n0,93 9,16 10,82\n",
            1,
            "point 0: '0,92 9,18 10,81' looks like decimal commas",
        ),
        ("tabs.xyz", "# scan\n\n1,5\t2,5\t3,5\n", 3, "point 0: '1,5\\t2,5\\t3,5' looks like decimal commas"),
        ("comment.xyz", "1 2 3\n1,5 2,5 3,5 # c, d\n", 2, "point 1: '1,5 2,5 3,5' looks like decimal commas"),
        // Commas and spaces as separators on one line: which is the column?
        ("mixed.csv", "1, 2, 3\n4, 5, 6 7\n", 2, "point 1: '4, 5, 6 7' looks like decimal commas"),
        // After a CSV header too.
        ("header.csv", "x,y,z\n1,5 2,5 3,5\n", 2, "point 0: '1,5 2,5 3,5' looks like decimal commas"),
    ];
    for &(file, src, line, want) in cases {
        let e = points_err(&dir, file, src);
        assert_at(&e, &dir, file, line, want);
        assert!(e.contains("write decimals with a '.'"), "{e}");
    }
}

/// Plain CSV (with or without spaces after the commas, with a header), whitespace
/// columns with extra columns, and commas inside a comment read as before.
#[test]
fn csv_and_whitespace_columns_still_read_the_same_points() {
    let dir = Scratch::new("io_audit_csv");
    let want = vec![[1.0, 2.0, 3.0], [4.5, -5.25, 6e-3]];
    for (file, src) in [
        ("a.csv", "1.0,2.0,3.0\n4.5,-5.25,6e-3\n"),
        ("b.csv", "1.0, 2.0, 3.0\n4.5, -5.25, 6e-3\n"),
        ("c.csv", "1.0 , 2.0 , 3.0\n 4.5 ,-5.25,\t6e-3 \n"),
        ("d.csv", "x,y,z\n1.0,2.0,3.0\n4.5,-5.25,6e-3\n"),
        ("e.csv", "x, y, z, intensity\n1.0, 2.0, 3.0, 7\n4.5, -5.25, 6e-3, 7\n"),
        ("f.xyz", "1.0 2.0 3.0 0 0 1 255 0 0\n4.5\t-5.25  6e-3\n"),
        ("g.xyz", "# x, y, z\n1.0 2.0 3.0 # first, a comment\n4.5 -5.25 6e-3\n"),
        ("h.txt", "1.0,2.0,3.0 # a, b c\r\n4.5,-5.25,6e-3\r\n"),
        ("i.pts", "2\n1.0 2.0 3.0\n4.5,-5.25,6e-3\n"),
        // Spaces or commas in the ignored columns (review, session 20: refused for a while).
        ("j.csv", "x,y,z,time\n1.0,2.0,3.0,2024-05-01 10:00:00\n4.5,-5.25,6e-3,2024-05-01 10:00:01\n"),
        ("k.csv", "1.0,2.0,3.0,red car\n4.5,-5.25,6e-3,blue car\n"),
        ("l.xyz", "1.0 2.0 3.0 0.5,0.2\n4.5 -5.25 6e-3 0.5,0.2\n"),
    ] {
        let p = dir.write(file, src.as_bytes());
        let got = read_points(std::path::Path::new(&p)).unwrap_or_else(|e| panic!("{file}: {e}"));
        assert_eq!(got, want, "{file}");
    }
}

// ---- 2. ASCII PLY values against their declared types ----

/// An ASCII PLY of two vertices whose x has type `ty`, y and z float; the second
/// vertex's x (on line 9) is `x1`.
fn ply_typed_x(ty: &str, x1: &str) -> String {
    format!(
        "ply\nformat ascii 1.0\nelement vertex 2\nproperty {ty} x\nproperty float y\nproperty float z\n\
         end_header\n0 0 0\n{x1} 1 2\n"
    )
}

/// Cases ply_uchar_300, ply_uchar_neg, ply_char_200, ply_int_float_text,
/// ply_float_1e39, ply_uchar_overflow: each value was accepted as written.
#[test]
fn ascii_ply_values_must_fit_their_declared_type() {
    let dir = Scratch::new("io_audit_plytype");
    let cases: &[(&str, &str, &str)] = &[
        ("uchar", "300", "property 'x' is uchar: '300' is out of range (0 to 255)"),
        ("uchar", "-1", "property 'x' is uchar: '-1' is out of range (0 to 255)"),
        ("uint8", "256", "property 'x' is uchar: '256' is out of range (0 to 255)"),
        ("char", "200", "property 'x' is char: '200' is out of range (-128 to 127)"),
        ("char", "-129", "property 'x' is char: '-129' is out of range (-128 to 127)"),
        ("short", "32768", "property 'x' is short: '32768' is out of range (-32768 to 32767)"),
        ("ushort", "65536", "property 'x' is ushort: '65536' is out of range (0 to 65535)"),
        ("int", "0.7", "property 'x' is int: '0.7' is not an integer"),
        ("int", "1.0", "property 'x' is int: '1.0' is not an integer"),
        (
            "int",
            "2147483648",
            "property 'x' is int: '2147483648' is out of range (-2147483648 to 2147483647)",
        ),
        ("int", "99999999999999999999", "property 'x' is int: '99999999999999999999' is out of range"),
        ("uint", "4294967296", "property 'x' is uint: '4294967296' is out of range (0 to 4294967295)"),
        ("uchar", "1e2", "property 'x' is uchar: '1e2' is not an integer"),
        ("float", "1e39", "property 'x' is float: '1e39' is out of range (at most ±3.4028235e38)"),
        ("float", "-3.5e38", "property 'x' is float: '-3.5e38' is out of range"),
        (
            "double",
            "1e400",
            "property 'x' is double: '1e400' is out of range (at most ±1.7976931348623157e308)",
        ),
    ];
    for &(ty, x1, want) in cases {
        let e = mesh_err(&dir, "t.ply", &ply_typed_x(ty, x1));
        assert_at(&e, &dir, "t.ply", 9, &format!("vertex 1 of 2 declared: {want}"));
        // The same file read as points gives the same error.
        let e2 = points_err(&dir, "t.ply", &ply_typed_x(ty, x1));
        assert_eq!(e2, e, "{ty} {x1}");
    }
    // Unchanged: garbage is a bad number, and nan/inf (spelt out) are non-finite.
    let e = mesh_err(&dir, "t.ply", &ply_typed_x("float", "x"));
    assert_at(&e, &dir, "t.ply", 9, "vertex 1 of 2 declared: bad number 'x'");
    let e = mesh_err(&dir, "t.ply", &ply_typed_x("float", "inf"));
    assert_at(&e, &dir, "t.ply", 9, "vertex 1: non-finite coordinate");
    let e = mesh_err(&dir, "t.ply", &ply_typed_x("double", "nan"));
    assert_at(&e, &dir, "t.ply", 9, "vertex 1: non-finite coordinate");
}

/// The limits of each type are still values of it, and a float is read as written
/// (not rounded to f32), as before.
#[test]
fn ascii_ply_values_at_their_type_limits_read_as_written() {
    let dir = Scratch::new("io_audit_plylimits");
    let cases: &[(&str, &str, f64)] = &[
        ("uchar", "255", 255.0),
        ("uchar", "0", 0.0),
        ("char", "-128", -128.0),
        ("char", "127", 127.0),
        ("short", "-32768", -32768.0),
        ("ushort", "65535", 65535.0),
        ("int", "-2147483648", -2147483648.0),
        ("int", "+7", 7.0),
        ("uint", "4294967295", 4294967295.0),
        ("float", "3.4028235e38", 3.4028235e38),
        ("float", "-3.4028235e38", -3.4028235e38),
        ("float", "0.9208871791574181", 0.9208871791574181),
        ("float", "1e-50", 1e-50),
        ("double", "1.7976931348623157e308", f64::MAX),
        ("double", "-0", -0.0),
    ];
    for &(ty, x1, want) in cases {
        let m = mesh_ok(&dir, "t.ply", &ply_typed_x(ty, x1));
        assert_eq!(m.vertices.len(), 2, "{ty} {x1}");
        assert_eq!(m.vertices[1][0].to_bits(), want.to_bits(), "{ty} {x1}");
        assert_eq!(&m.vertices[1][1..], &[1.0, 2.0], "{ty} {x1}");
    }
}

/// List counts and indices are checked against their types too (a `uchar` count of
/// 300, a `uchar` index of 256), and so are skipped properties; a negative count
/// keeps its message.
#[test]
fn ascii_ply_list_counts_indices_and_skipped_values_fit_their_types() {
    let dir = Scratch::new("io_audit_plylist");
    let ply = |count: &str, index: &str, extra: &str, face: &str| {
        format!(
            "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n\
             property {extra} red\nelement face 1\nproperty list {count} {index} vertex_indices\nend_header\n\
             0 0 0 1\n1 0 0 2\n1 1 0 3\n0 1 0 4\n{face}\n"
        )
    };
    let want_faces = vec![vec![0, 1, 2, 3]];
    let m = mesh_ok(&dir, "ok.ply", &ply("uchar", "int", "uchar", "4 0 1 2 3"));
    assert_eq!(m.faces, want_faces);
    assert_eq!(m.vertices[3], [0.0, 1.0, 0.0]);
    let m = mesh_ok(&dir, "ok.ply", &ply("uint8", "uchar", "float", "4 0 1 2 3"));
    assert_eq!(m.faces, want_faces);
    let cases: Vec<(String, usize, &str)> = vec![
        (
            ply("uchar", "int", "uchar", "300 0 1 2 3"),
            15,
            "face 0 of 1 declared: the list count of property 'vertex_indices' is uchar: '300' is out of range (0 to 255)",
        ),
        (
            ply("uchar", "int", "uchar", "4.0 0 1 2 3"),
            15,
            "face 0 of 1 declared: the list count of property 'vertex_indices' is uchar: '4.0' is not an integer",
        ),
        (ply("uchar", "int", "uchar", "-4 0 1 2 3"), 15, "face 0 of 1 declared: negative list length -4"),
        (
            ply("uchar", "uchar", "uchar", "4 0 1 2 256"),
            15,
            "face 0 of 1 declared: property 'vertex_indices' is uchar: '256' is out of range (0 to 255)",
        ),
        (
            ply("uchar", "int", "uchar", "4 0 1 2.5 3"),
            15,
            "face 0 of 1 declared: property 'vertex_indices' is int: '2.5' is not an integer",
        ),
        (ply("uchar", "int", "uchar", "4 0 1 x 3"), 15, "face 0 of 1 declared: bad integer 'x'"),
        // Unchanged: an integer in its type's range but not a vertex.
        (ply("uchar", "int", "uchar", "4 0 1 2 4"), 15, "face 0: vertex index 4 out of range (4 vertices)"),
    ];
    for (src, line, want) in &cases {
        let e = mesh_err(&dir, "t.ply", src);
        assert_at(&e, &dir, "t.ply", *line, want);
    }
    // A skipped property: `red` is not read, but 300 is no uchar.
    let src = ply("uchar", "int", "uchar", "4 0 1 2 3").replace("1 1 0 3\n", "1 1 0 300\n");
    let e = mesh_err(&dir, "t.ply", &src);
    assert_at(
        &e,
        &dir,
        "t.ply",
        13,
        "vertex 2 of 4 declared: property 'red' is uchar: '300' is out of range",
    );
    let e = points_err(&dir, "t.ply", &src);
    assert_at(
        &e,
        &dir,
        "t.ply",
        13,
        "vertex 2 of 4 declared: property 'red' is uchar: '300' is out of range",
    );
    let src = ply("uchar", "int", "float", "4 0 1 2 3").replace("1 1 0 3\n", "1 1 0 zz\n");
    let e = mesh_err(&dir, "t.ply", &src);
    assert_at(&e, &dir, "t.ply", 13, "vertex 2 of 4 declared: property 'red': bad number 'zz'");
    // A skipped float may be nan (scanners write nan normals); the points are kept.
    let src = ply("uchar", "int", "float", "4 0 1 2 3").replace("1 1 0 3\n", "1 1 0 nan\n");
    assert_eq!(mesh_ok(&dir, "t.ply", &src).faces, want_faces);
    // Counts in a skipped list element are checked too (when reading points, faces are
    // skipped like any other element).
    let src = ply("uchar", "int", "uchar", "300 0 1 2 3");
    let e = points_err(&dir, "t.ply", &src);
    assert_at(
        &e,
        &dir,
        "t.ply",
        15,
        "the list count of property 'vertex_indices' is uchar: '300' is out of range",
    );
}

// ---- 3. PLY: a property declared twice ----

/// Case ply_dup_x: the first `x` was used silently.
#[test]
fn ply_property_declared_twice_is_an_error_naming_the_header_line() {
    let dir = Scratch::new("io_audit_plydup");
    let src = "ply\nformat ascii 1.0\nelement vertex 1\nproperty double x\nproperty double x\n\
               property double y\nproperty double z\nend_header\n0 1 2 3\n";
    let e = mesh_err(&dir, "t.ply", src);
    assert_at(&e, &dir, "t.ply", 5, "property 'x' declared twice in element 'vertex'");
    let e = points_err(&dir, "t.ply", src);
    assert_at(&e, &dir, "t.ply", 5, "property 'x' declared twice in element 'vertex'");
    let src = "ply\nformat binary_little_endian 1.0\nelement vertex 0\nproperty float x\nproperty float y\n\
               property float z\nelement face 0\nproperty list uchar int vertex_indices\nproperty uchar red\n\
               property uchar red\nend_header\n";
    let e = mesh_err(&dir, "t.ply", src);
    assert_at(&e, &dir, "t.ply", 10, "property 'red' declared twice in element 'face'");
    // The same name in two elements is fine.
    let src =
        "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n\
               property uchar id\nelement edge 1\nproperty uchar id\nend_header\n1 2 3 0\n5\n";
    assert_eq!(mesh_ok(&dir, "t.ply", src).vertices, vec![[1.0, 2.0, 3.0]]);
}

// ---- 4. PLY: the format line ----

/// Cases ply_two_formats (the later line won, then "28193 bytes after the last
/// element") and ply_version2 (accepted).
#[test]
fn ply_format_line_only_once_and_only_version_1_0() {
    let dir = Scratch::new("io_audit_plyformat");
    let tail = "element vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n";
    let cases: &[(&str, usize, &str)] = &[
        (
            "ply\nformat ascii 1.0\nformat binary_little_endian 1.0\n",
            3,
            "a second 'format' line (the first is on line 2)",
        ),
        (
            "ply\ncomment x\nformat ascii 1.0\nformat ascii 1.0\n",
            4,
            "a second 'format' line (the first is on line 3)",
        ),
        ("ply\nformat ascii 2.0\n", 2, "unsupported PLY version '2.0' (only 1.0 is defined)"),
        ("ply\nformat binary_big_endian 1.1\n", 2, "unsupported PLY version '1.1'"),
        ("ply\nformat ascii\n", 2, "format line without a version"),
    ];
    for &(head, line, want) in cases {
        let e = mesh_err(&dir, "t.ply", &format!("{head}{tail}"));
        assert_at(&e, &dir, "t.ply", line, want);
    }
    // Version 1.0 in every encoding still reads.
    let m = mesh_ok(&dir, "t.ply", &format!("ply\nformat ascii 1.0\n{tail}"));
    assert_eq!(m.vertices, vec![[1.0, 2.0, 3.0]]);
    // So does 1.0 written `1` or `1.00` (review, session 20).
    for v in ["1", "1.00"] {
        let m = mesh_ok(&dir, "t.ply", &format!("ply\nformat ascii {v}\n{tail}"));
        assert_eq!(m.vertices, vec![[1.0, 2.0, 3.0]], "version {v}");
    }
    for (fmt, bytes) in [
        ("binary_little_endian", [1f32, 2., 3.].map(f32::to_le_bytes).concat()),
        ("binary_big_endian", [1f32, 2., 3.].map(f32::to_be_bytes).concat()),
    ] {
        let mut src = format!("ply\nformat {fmt} 1.0\n{tail}").into_bytes();
        src.truncate(src.len() - "1 2 3\n".len());
        src.extend_from_slice(&bytes);
        let p = dir.write("b.ply", &src);
        let m = read_mesh(std::path::Path::new(&p)).unwrap_or_else(|e| panic!("{fmt}: {e}"));
        assert_eq!(m.vertices, vec![[1.0, 2.0, 3.0]], "{fmt}");
    }
}

// ---- 5. and 6. OBJ face corners and the forward-index message ----

const QUAD_VERTS: &str = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvn 0 0 1\n";

/// Case badslash_obj_*: `f 1/ 2/x 3 4` was accepted.
#[test]
fn obj_texture_and_normal_indices_must_be_integers() {
    let dir = Scratch::new("io_audit_objslash");
    let cases: &[(&str, &str)] = &[
        ("f 1/ 2/x 3 4", "face 0: bad texture index 'x' in '2/x'"),
        ("f 1/1/1 2/2/1 3/1/n 4", "face 0: bad normal index 'n' in '3/1/n'"),
        ("f 1//1 2//1.5 3//1 4//1", "face 0: bad normal index '1.5' in '2//1.5'"),
        ("f 1/1/1/1 2 3 4", "face 0: '1/1/1/1' has more than 3 parts (v/vt/vn)"),
    ];
    for &(face, want) in cases {
        // The bad face is the second one, on line 9.
        let src = format!("{QUAD_VERTS}f 1 2 3 4\n{face}\n");
        let e = mesh_err(&dir, "t.obj", &src);
        assert_at(&e, &dir, "t.obj", 9, &want.replace("face 0", "face 1"));
    }
    // Unchanged: a bad vertex part.
    let e = mesh_err(&dir, "t.obj", &format!("{QUAD_VERTS}f x/1 2 3 4\n"));
    assert_at(&e, &dir, "t.obj", 8, "face 0: bad vertex index 'x/1'");
    // Every valid form, negative indices included, gives the same faces as before.
    let src = format!(
        "{QUAD_VERTS}f 1 2 3 4\nf 1/1 2/2 3/1 4/2\nf 1/1/1 2/2/1 3/1/1 4/2/1\nf 1//1 2//1 3//1 4//1\n\
         f -4/-2/-1 -3//-1 -2/-1 -1\nf 1/ 2/ 3// 4//\n"
    );
    let m = mesh_ok(&dir, "t.obj", &src);
    assert_eq!(m.faces, vec![vec![0, 1, 2, 3]; 6]);
    // Reading the OBJ as points does not look at faces.
    let p = dir.write("p.obj", format!("{QUAD_VERTS}f 1/ 2/x 3 4\n").as_bytes());
    assert_eq!(read_points(std::path::Path::new(&p)).unwrap().len(), 4);
}

/// Case oob_obj_*: `oob.obj:62: vertex index 999 out of range` did not name the face,
/// while the negative-index message did.
#[test]
fn obj_index_out_of_range_names_the_face_either_way() {
    let dir = Scratch::new("io_audit_objoob");
    let src = format!("{QUAD_VERTS}f 1 2 3 4\nf 4 3 2 1\nf 1 2 3 999\nf 1 2 3 4\n");
    let e = mesh_err(&dir, "oob.obj", &src);
    assert_at(&e, &dir, "oob.obj", 10, "vertex index 999 out of range in face 2 (the file has 4 vertices)");
    // The largest index is the one reported, with its own face and line.
    let src = format!("{QUAD_VERTS}f 1 2 3 7\nf 1 2 3 9\nf 1 2 3 8\n");
    let e = mesh_err(&dir, "oob.obj", &src);
    assert_at(&e, &dir, "oob.obj", 9, "vertex index 9 out of range in face 1 (the file has 4 vertices)");
    let src = format!("{QUAD_VERTS}f 1 2 3 4\nf 1 2 3 -9\n");
    let e = mesh_err(&dir, "oob.obj", &src);
    assert_at(&e, &dir, "oob.obj", 9, "face 1: vertex index -9 out of range (4 vertices so far)");
    // A forward reference that the file does define still loads.
    let m = mesh_ok(&dir, "fwd.obj", "f 1 2 3 4\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n");
    assert_eq!(m.faces, vec![vec![0, 1, 2, 3]]);
}

/// Session 37's audit: a PLY whose vertex properties are `X`, `Y`, `Z` was refused ("no
/// property 'x'"), while the text readers take any case. Any case reads the same points
/// as lower case, ascii and binary; an exact lower-case name wins over another case.
#[test]
fn ply_coordinate_names_in_any_case() {
    let dir = Scratch::new("io_audit_plycase");
    let read = |file: &str, src: &[u8]| {
        let p = dir.write(file, src);
        read_points(std::path::Path::new(&p)).unwrap_or_else(|e| panic!("{file}: {e}"))
    };
    let header = |fmt: &str, names: [&str; 3]| {
        format!(
            "ply\nformat {fmt} 1.0\nelement vertex 2\nproperty double {}\nproperty double {}\nproperty double {}\nend_header\n",
            names[0], names[1], names[2]
        )
    };
    let body = "1 2 3\n4.5 -5 6\n";
    let lower = read("l.ply", (header("ascii", ["x", "y", "z"]) + body).as_bytes());
    assert_eq!(lower, vec![[1.0, 2.0, 3.0], [4.5, -5.0, 6.0]]);
    for names in [["X", "Y", "Z"], ["x", "Y", "z"]] {
        assert_eq!(read("u.ply", (header("ascii", names) + body).as_bytes()), lower, "{names:?}");
        let mut bin = header("binary_little_endian", names).into_bytes();
        for v in [1.0f64, 2.0, 3.0, 4.5, -5.0, 6.0] {
            bin.extend(v.to_le_bytes());
        }
        assert_eq!(read("b.ply", &bin), lower, "binary {names:?}");
    }
    // `X` first, then `x`: the exact name is the coordinate.
    let src = "ply\nformat ascii 1.0\nelement vertex 1\nproperty double X\nproperty double x\n\
               property double y\nproperty double z\nend_header\n9 1 2 3\n";
    assert_eq!(read("both.ply", src.as_bytes()), vec![[1.0, 2.0, 3.0]]);
}
