//! Point clouds: read from .xyz/.txt/.pts/.csv (text columns), .ply, .obj and .off
//! (their vertices), write as .xyz with round-trip-exact coordinates.

use super::atomic::{prepare_atomic, Staged};
use super::text::{self, coord, out_err, parse_i64, show, Lines, Tokens};
use super::{obj, off, ply};
use crate::error::{Error, Result};
use std::io::Write;
use std::path::Path;

/// A point file format.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum PointFormat {
    /// Text columns `x y z [more…]` (`.xyz`, `.txt`, `.pts`, `.csv`).
    Xyz,
    /// Stanford PLY, the `vertex` element.
    Ply,
    /// Wavefront OBJ, the `v` lines.
    Obj,
    /// OFF, the vertices.
    Off,
}

impl PointFormat {
    /// The format named by `path`'s extension (case-insensitive): `.xyz`, `.txt`,
    /// `.pts`, `.csv` → `Xyz`; `.ply`, `.obj`, `.off`.
    ///
    /// # Errors
    /// `Usage` naming the path and listing the supported extensions.
    pub fn from_path(path: &Path) -> Result<PointFormat> {
        let ext = path.extension().map(|e| e.to_string_lossy().to_ascii_lowercase());
        match ext.as_deref() {
            Some("xyz" | "txt" | "pts" | "csv") => Ok(PointFormat::Xyz),
            Some("ply") => Ok(PointFormat::Ply),
            Some("obj") => Ok(PointFormat::Obj),
            Some("off") => Ok(PointFormat::Off),
            _ => Err(Error::Usage(format!(
                "{}: unknown point format; supported extensions: .xyz .txt .pts .csv .ply .obj .off",
                path.display()
            ))),
        }
    }
}

/// Reads a point cloud, choosing the format by extension.
///
/// # Errors
/// `Usage` for an unknown extension, `Io` when the file cannot be read, and the
/// errors of [`parse_points`].
pub fn read_points(path: &Path) -> Result<Vec<[f64; 3]>> {
    let format = PointFormat::from_path(path)?;
    let bytes = crate::io::read_input_file(path)?;
    parse_points(&bytes, format, &path.display().to_string())
}

/// Parses a point cloud held in memory; `name` stands for the file in error messages.
///
/// `.xyz`: one point per line, columns separated by whitespace or by commas (with or
/// without spaces around them); `#`
/// starts a comment; blank lines are skipped; columns after the third (normals,
/// colours…) are ignored. A first data line holding a single integer is a point
/// count (the `.pts` convention) and must match the number of points. A first data
/// line of at least 3 column names (each starting with a letter or `_`, none of them a
/// number, so `nan` or `inf` are not names) is a CSV-style header: columns it names `x`,
/// `y` and `z` (any case) are read wherever they are (`id,x,y,z`), otherwise the first
/// three (see `header_columns` for the headers refused). A data line that mixes the two
/// separators, `1,5 2,5 3,5`, or whose whitespace-separated coordinates hold a comma
/// between digits, `0 0 0,5` (decimal commas), is an error, not the point (1, 5, 2) or
/// (0, 0, 0). For mesh
/// formats only the vertices are taken (faces are not read, except that PLY
/// still checks every element's length).
///
/// # Errors
/// `Parse` naming `name` and the line (or, in binary PLY, the vertex) for a line
/// with fewer than 3 columns, a bad or non-finite number, a line that looks like
/// decimal commas (comma and whitespace separators mixed), any error of the mesh
/// format's parser, and when the file holds no points.
pub fn parse_points(bytes: &[u8], format: PointFormat, name: &str) -> Result<Vec<[f64; 3]>> {
    let points = match format {
        PointFormat::Xyz => parse_xyz(bytes, name)?,
        PointFormat::Ply => ply::parse_ply_with(bytes, name, false)?.vertices,
        PointFormat::Obj => obj::parse_obj_with(bytes, name, false)?.vertices,
        PointFormat::Off => off::parse_off_with(bytes, name, false)?.vertices,
    };
    if points.is_empty() {
        return Err(Error::parse(name, 0, "contains no points"));
    }
    Ok(points)
}

fn parse_xyz(bytes: &[u8], name: &str) -> Result<Vec<[f64; 3]>> {
    let bytes = &*text::cr_lines(bytes);
    let mut points = Vec::with_capacity(bytes.len() / 24);
    let mut declared: Option<(usize, usize)> = None;
    let mut first = true;
    // Columns of x, y and z: the first three, or those a header names so; `upto`: how
    // many leading values give the coordinates (at least 3).
    let mut columns = [0usize, 1, 2];
    let mut upto = 3;
    for (ln, raw) in Lines::new(bytes) {
        let mut toks = Tokens::with_commas(raw);
        let Some(t0) = toks.next() else { continue };
        if first {
            first = false;
            if is_column_header(raw) {
                columns = header_columns(raw).map_err(|m| Error::parse(name, ln, m))?;
                upto = columns.iter().max().map_or(3, |&c| (c + 1).max(3));
                continue;
            }
            if toks.clone().next().is_none() {
                // A lone first value: the `.pts` point count.
                match parse_i64(t0).and_then(|n| usize::try_from(n).ok()) {
                    Some(n) => {
                        declared = Some((n, ln));
                        continue;
                    }
                    _ => {
                        return Err(Error::parse(
                            name,
                            ln,
                            format!("expected 'x y z' or a point count, found '{}'", show(t0)),
                        ))
                    }
                }
            }
        }
        let i = points.len();
        if let Some(data) = decimal_comma_line(raw, upto) {
            return Err(Error::parse(
                name,
                ln,
                format!(
                    "point {i}: '{}' looks like decimal commas (commas and spaces both separate \
                     its values); write decimals with a '.' (1.5, not 1,5)",
                    show(data)
                ),
            ));
        }
        let mut p = [0.0; 3];
        if columns == [0, 1, 2] {
            // A CSV row (its coordinates not all before the first comma) with an empty
            // field among the first three: the merged separators would read the next
            // column in its place (`,1,2,3` gave (1, 2, 3); session 34's audit).
            let data = without_comment(raw);
            if text::find_byte(data, b',').is_some() {
                let first = data.split(|&b| b == b',').next().unwrap_or_default();
                if first.split(|&b| text::is_space(b)).filter(|t| !t.is_empty()).count() < 3 {
                    if let Some(k) = fields(raw).iter().take(3).position(|f| f.is_empty()) {
                        return Err(Error::parse(name, ln, format!("point {i}: field {} is empty", k + 1)));
                    }
                }
            }
            p[0] = coord(t0, name, ln, &format_args!("point {i}"))?;
            for (axis, c) in p.iter_mut().enumerate().skip(1) {
                let tok = toks.next().ok_or_else(|| {
                    // `0,,1`: three fields, one empty (session 27's audit: it read "found 2").
                    match fields(raw).iter().take(3).position(|f| f.is_empty()) {
                        Some(k) if text::find_byte(raw, b',').is_some() => {
                            Error::parse(name, ln, format!("point {i}: field {} is empty", k + 1))
                        }
                        _ => Error::parse(name, ln, format!("point {i}: needs 3 coordinates, found {axis}")),
                    }
                })?;
                *c = coord(tok, name, ln, &format_args!("point {i}"))?;
            }
        } else {
            // Columns found by name are counted with every field, empty ones too
            // (`1,,0.5,1,2`): merging separators as above would shift them.
            let row = fields(raw);
            for (c, &col) in p.iter_mut().zip(&columns) {
                let tok = row.get(col).ok_or_else(|| {
                    Error::parse(
                        name,
                        ln,
                        format!(
                            "point {i}: the header puts a coordinate in column {}, the line has {}",
                            col + 1,
                            row.len()
                        ),
                    )
                })?;
                *c = coord(tok, name, ln, &format_args!("point {i}"))?;
            }
        }
        points.push(p);
    }
    if let Some((n, ln)) = declared {
        if n != points.len() {
            return Err(Error::parse(
                name,
                ln,
                format!("the header declares {n} points but the file holds {}", points.len()),
            ));
        }
    }
    Ok(points)
}

/// The fields of `line` (without its `#` comment) for columns found by name: split at
/// every comma, each trimmed, when it holds one (so an empty field keeps its place),
/// else at runs of whitespace.
fn fields(line: &[u8]) -> Vec<&[u8]> {
    let data = without_comment(line);
    if text::find_byte(data, b',').is_some() {
        data.split(|&b| b == b',').map(trim_space).collect()
    } else {
        data.split(|&b| text::is_space(b)).filter(|t| !t.is_empty()).collect()
    }
}

/// The data of `line` (without its `#` comment, trimmed) when it mixes the two column
/// separators in its first `upto` values (at least 3: those that give the coordinates):
/// one of its first `upto` comma-separated fields,
/// trimmed, still holds whitespace, and the three coordinates do not all come before
/// the first comma (`1 2 3 0.5,0.2` is a whitespace line with a comma in an ignored
/// column). That is the mark of decimal commas, `1,5 2,5 3,5`,
/// which read as commas-and-spaces columns gives the point (1, 5, 2), silently. Plain
/// CSV, with or without spaces after the commas (`1.0, 2.0, 3.0`), never mixes them.
fn decimal_comma_line(line: &[u8], upto: usize) -> Option<&[u8]> {
    text::find_byte(line, b',')?;
    let data = without_comment(line);
    text::find_byte(data, b',')?;
    // Only the values that give the coordinates count: extra columns are ignored, so a
    // CSV's fourth field may hold spaces (`1,2,3,red car`), and a whitespace-separated
    // line may hold commas after its third column (`1 2 3 0.5,0.2`).
    let mixed =
        data.split(|&b| b == b',').take(upto).any(|f| trim_space(f).iter().any(|&b| text::is_space(b)));
    let first = data.split(|&b| b == b',').next().unwrap_or_default();
    let coords_before_commas = first.split(|&b| text::is_space(b)).filter(|t| !t.is_empty()).count() >= upto;
    // `0 0 0,5`: whitespace separates the columns and one of the first three values holds
    // a comma between digits, while no value starts or ends with a comma (so commas are
    // not separators here, as in `1, 2, 3`). Read with commas as separators it gives the
    // point (0, 0, 0) and an ignored 5, silently.
    let words: Vec<&[u8]> = data.split(|&b| text::is_space(b)).filter(|t| !t.is_empty()).take(upto).collect();
    // Each of those words must read as a number once its comma is a point (`1,2,3,a b`
    // is a CSV row with a spaced fourth field, not decimals); `1e-3 0 0,5` is one too.
    let as_decimal = |w: &&[u8]| {
        let commas = w.iter().filter(|&&b| b == b',').count();
        let dotted: Vec<u8> = w.iter().map(|&b| if b == b',' { b'.' } else { b }).collect();
        commas <= 1 && text::parse_f64(&dotted).is_some()
    };
    let decimal_word =
        |w: &&[u8]| w.windows(3).any(|t| t[0].is_ascii_digit() && t[1] == b',' && t[2].is_ascii_digit());
    let glued_commas = words.len() >= upto
        && words.iter().all(|w| w.first() != Some(&b',') && w.last() != Some(&b','))
        && words.iter().all(as_decimal)
        && words.iter().any(decimal_word);
    ((mixed && !coords_before_commas) || glued_commas).then(|| trim_space(data))
}

/// `line` up to its `#` comment.
fn without_comment(line: &[u8]) -> &[u8] {
    match text::find_byte(line, b'#') {
        Some(i) => &line[..i],
        None => line,
    }
}

/// `f` without leading and trailing whitespace.
fn trim_space(f: &[u8]) -> &[u8] {
    let start = f.iter().position(|&b| !text::is_space(b)).unwrap_or(f.len());
    let end = f.iter().rposition(|&b| !text::is_space(b)).map_or(start, |e| e + 1);
    &f[start..end]
}

/// Where a header row (see [`is_column_header`]) puts x, y and z: the columns named
/// `x`, `y` and `z` (case-insensitive, quotes dropped) wherever they are, so `id,x,y,z`
/// and `z,y,x` read right; the first three columns when it names none of them
/// (`_x, pos_y, z1`) or names only some, each in its place among the first three
/// (`lon,lat,z`, `E,N,Z`, `x,y,height`). A header that names some but not all three
/// with one out of its place (`id,x,y`) is refused (the message), as is one that
/// names one twice.
fn header_columns(line: &[u8]) -> std::result::Result<[usize; 3], String> {
    let mut found: [Option<usize>; 3] = [None; 3];
    let names: Vec<String> = fields(line)
        .into_iter()
        .map(|tok| {
            let tok = match tok {
                [b'"', inner @ .., b'"'] => inner,
                _ => tok,
            };
            String::from_utf8_lossy(tok).to_ascii_lowercase()
        })
        .collect();
    for (col, n) in names.iter().enumerate() {
        if let Some(axis) = ["x", "y", "z"].iter().position(|a| a == n) {
            if found[axis].is_some() {
                return Err(format!("the header names column '{n}' twice"));
            }
            found[axis] = Some(col);
        }
    }
    match found {
        [Some(x), Some(y), Some(z)] => Ok([x, y, z]),
        _ if found.iter().enumerate().all(|(axis, f)| f.map_or(true, |c| c == axis)) => Ok([0, 1, 2]),
        _ => {
            // Only some named, and one of those not in its own column (x first, y
            // second, z third), so the others cannot be taken from their places.
            let axes = ["x", "y", "z"];
            let named: Vec<String> = axes
                .iter()
                .zip(&found)
                .filter_map(|(a, f)| f.map(|c| format!("{a} in column {}", c + 1)))
                .collect();
            let missing: Vec<&str> =
                axes.iter().zip(&found).filter(|(_, f)| f.is_none()).map(|(a, _)| *a).collect();
            Err(format!(
                "the header names {} but not {}; without all three named, named ones must be in \
                 their own columns (x first, y second, z third); name the three columns x, y and z, \
                 or give no header (the first three columns are then x, y, z)",
                named.join(" and "),
                missing.join(" or ")
            ))
        }
    }
}

/// A line of at least 3 column names, `x,y,z`, `"x","y","z"` or `X Y Z nx ny nz`: every
/// token (without its double quotes) starts with an ASCII letter or `_` and none parses
/// as a number (`nan`, `inf` do).
fn is_column_header(line: &[u8]) -> bool {
    let mut count = 0;
    for tok in Tokens::with_commas(line) {
        let tok = match tok {
            [b'"', inner @ .., b'"'] => inner,
            _ => tok,
        };
        let named = tok.first().is_some_and(|&c| c.is_ascii_alphabetic() || c == b'_');
        if !named || text::parse_f64(tok).is_some() {
            return false;
        }
        count += 1;
    }
    count >= 3
}

/// Writes points as `.xyz` text (`x y z` per line), atomically; every coordinate
/// reads back bit-exactly (sign of zero, subnormals and extremes included).
///
/// # Errors
/// `InvalidInput` naming the first non-finite point (nothing is written); `Io`
/// naming the path.
pub fn write_points_xyz(path: &Path, points: &[[f64; 3]]) -> Result<()> {
    prepare_points_xyz(path, points)?.commit()
}

/// [`write_points_xyz`] up to the rename (see [`crate::io::atomic::prepare_atomic`]).
///
/// # Errors
/// As [`write_points_xyz`].
pub fn prepare_points_xyz(path: &Path, points: &[[f64; 3]]) -> Result<Staged> {
    if let Some(i) = points.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
        return Err(Error::invalid(format!("point {i} has a non-finite coordinate {:?}", points[i])));
    }
    prepare_atomic(path, |w| write_xyz(w, points))
}

/// Writes points as `.xyz` text to any writer (see [`write_points_xyz`]).
///
/// # Errors
/// `Io` from the writer.
pub fn write_xyz(w: &mut dyn Write, points: &[[f64; 3]]) -> Result<()> {
    let run = |w: &mut dyn Write| -> std::io::Result<()> {
        for p in points {
            text::write_xyz_line(w, *p)?;
        }
        Ok(())
    };
    run(w).map_err(out_err)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn formats_by_extension() {
        for (p, f) in [
            ("a.XYZ", PointFormat::Xyz),
            ("a.txt", PointFormat::Xyz),
            ("a.Pts", PointFormat::Xyz),
            ("a.CSV", PointFormat::Xyz),
            ("a.ply", PointFormat::Ply),
            ("a.obj", PointFormat::Obj),
            ("a.OFF", PointFormat::Off),
        ] {
            assert_eq!(PointFormat::from_path(Path::new(p)).unwrap(), f, "{p}");
        }
        let e = PointFormat::from_path(Path::new("x.las")).unwrap_err().to_string();
        assert!(e.contains("x.las") && e.contains(".xyz .txt .pts .csv .ply .obj .off"), "{e}");
    }

    #[test]
    fn xyz_columns_comments_commas() {
        let src = b"# header\n\n1 2 3\n4,5,6 # trailing\n 7\t8  9 0.1 0.2 0.3 255\r\n-0 1e-3 .5\n";
        let p = parse_points(src, PointFormat::Xyz, "t.xyz").unwrap();
        assert_eq!(p, vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [7.0, 8.0, 9.0], [-0.0, 1e-3, 0.5]]);
        assert!(p[3][0].is_sign_negative());
        // Commas as separators, however spaced, and a comma in a column after the third,
        // are not decimal commas.
        let src = b"1, 2,3\n1.0, 2.0, 3.0\n1 2 3 0.5,0.2\n1 ,2 ,3\n1,2,3,a b\n1,2,3,a b c\n";
        let p = parse_points(src, PointFormat::Xyz, "t.xyz").unwrap();
        assert_eq!(p, vec![[1.0, 2.0, 3.0]; 6]);
    }

    /// Regression: a CR-only .xyz file read as one line with extra columns: one point
    /// instead of all of them, silently.
    #[test]
    fn cr_only_line_endings_keep_every_point() {
        let p = parse_points(b"0 0 0\r1 0 0\r1 1 0\r", PointFormat::Xyz, "t.xyz").unwrap();
        assert_eq!(p, vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0]]);
    }

    /// A CSV-style first line of column names is a header (only the first data line, and
    /// only when every token is a name): it names the coordinate columns or is skipped.
    #[test]
    fn a_column_header_row_is_skipped() {
        let want = vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]];
        for src in [
            &b"x,y,z\n1,2,3\n4,5,6\n"[..],
            b"# scan 3\n\nX Y Z nx ny nz\n1 2 3 0 0 1\n4 5 6 0 0 1\n",
            b"\"x\",\"y\",\"z\"\n1,2,3\n4,5,6\n",
            b"_x, pos_y, z1, intensity\n1, 2, 3, 7\n4, 5, 6, 7\n",
        ] {
            let got = parse_points(src, PointFormat::Xyz, "t.csv");
            assert_eq!(got.unwrap(), want, "{}", String::from_utf8_lossy(src));
        }
        // Named columns are read by name (session 24's audit: `id,x,y,z` read the ids as
        // x and dropped z; `z,y,x` swapped x and z).
        for src in [
            &b"id,x,y,z\n0,1,2,3\n1,4,5,6\n"[..],
            b"z,y,x\n3,2,1\n6,5,4\n",
            b"\"Z\" \"nx\" \"X\" \"Y\"\n3 0 1 2\n6 0 4 5\n",
            // Empty fields keep their place (merged, x would be read from `name`'s place).
            b"id,name,x,y,z,w\n1,,1,2,3,9\n2,b,4,5,6,9\n",
            // Some axes named, each in its place among the first three: the first three.
            b"lon,lat,z\n1,2,3\n4,5,6\n",
            b"E N Z\n1 2 3\n4 5 6\n",
            b"x,y,height\n1,2,3\n4,5,6\n",
        ] {
            let got = parse_points(src, PointFormat::Xyz, "t.csv");
            assert_eq!(got.unwrap(), want, "{}", String::from_utf8_lossy(src));
        }
        for (src, want) in [
            (
                &b"id,x,y\n1,2,3\n"[..],
                "t.csv:1: the header names x in column 2 and y in column 3 but not z; without all three named",
            ),
            (b"lat,z\n1,2,3\n", "t.csv:1: point 0: bad number 'lat'"),
            // Decimal commas in a named column after the third (it was (1, 2, 3)).
            (b"id x y z\n7 1 2 3,5\n", "t.csv:2: point 0: '7 1 2 3,5' looks like decimal commas"),
            (b"x,x,y,z\n1,2,3,4\n", "t.csv:1: the header names column 'x' twice"),
            (b"b,x,c\n1,2,3\n", "t.csv:1: the header names x in column 2 but not y or z;"),
            (
                b"id,x,y,z\n1,2,3\n",
                "t.csv:2: point 0: the header puts a coordinate in column 4, the line has 3",
            ),
        ] {
            let e = parse_points(src, PointFormat::Xyz, "t.csv").unwrap_err().to_string();
            assert!(e.contains(want), "got '{e}', want '{want}'");
        }
        // Not headers: an empty quoted name, a quoted number.
        for (src, want) in [
            (&b"\"\",y,z\n1,2,3\n"[..], "t.csv:1: point 0: bad number '\"\"'"),
            (b"\"1\",y,z\n1,2,3\n", "t.csv:1: point 0: bad number '\"1\"'"),
        ] {
            let e = parse_points(src, PointFormat::Xyz, "t.csv").unwrap_err().to_string();
            assert!(e.contains(want), "got '{e}', want '{want}'");
        }
    }

    #[test]
    fn pts_count_header_is_checked() {
        let p = parse_points(b"2\n1 2 3\n4 5 6\n", PointFormat::Xyz, "t.pts").unwrap();
        assert_eq!(p.len(), 2);
        let e = parse_points(b"3\n1 2 3\n4 5 6\n", PointFormat::Xyz, "t.pts").unwrap_err().to_string();
        assert!(e.contains("t.pts:1: the header declares 3 points but the file holds 2"), "{e}");
    }

    #[test]
    fn xyz_errors_name_file_and_line() {
        let cases: &[(&[u8], &str)] = &[
            (b"1 2 3\n4 5\n", "t.xyz:2: point 1: needs 3 coordinates, found 2"),
            (b"1 2 3\n4\n", "t.xyz:2: point 1: needs 3 coordinates, found 1"),
            // An empty field is named as such (session 27's audit), with or without a
            // header; a short comma line still counts its values.
            (b"x,y,z\n0.0,,0.0\n", "t.xyz:2: point 0: field 2 is empty"),
            (b"1,2,3\n,2,3\n", "t.xyz:2: point 1: field 1 is empty"),
            // Still with three values after it (session 34's audit: read as (1, 2, 3)).
            (b",1,2,3\n", "t.xyz:1: point 0: field 1 is empty"),
            (b"0,0,0\n1,,2,3\n", "t.xyz:2: point 1: field 2 is empty"),
            (b"0,0,0\n1,2,,3\n", "t.xyz:2: point 1: field 3 is empty"),
            (b"0,0,0\n1, ,2,3\n", "t.xyz:2: point 1: field 2 is empty"),
            (b"1,2,3\n1,2\n", "t.xyz:2: point 1: needs 3 coordinates, found 2"),
            (b"1 2 3\nx y z\n", "t.xyz:2: point 1: bad number 'x'"),
            (b"x y\n1 2 3\n", "t.xyz:1: point 0: bad number 'x'"),
            (b"x 2 z\n1 2 3\n", "t.xyz:1: point 0: bad number 'x'"),
            (b"x y 3z\n1 2 3\n", "t.xyz:1: point 0: bad number 'x'"),
            (b"nan nan nan\n1 2 3\n", "t.xyz:1: point 0: non-finite"),
            (b"x,y,z\n", "t.xyz: contains no points"),
            (b"1 2 3\n\n1 nan 3\n", "t.xyz:3: point 1: non-finite"),
            (b"1 2 3\n1 2 -inf\n", "t.xyz:2: point 1: non-finite"),
            (b"# only a comment\n\n", "t.xyz: contains no points"),
            (b"", "t.xyz: contains no points"),
            (b"1.5\n", "t.xyz:1: expected 'x y z' or a point count"),
            (b"1 2 3\n1,5 2,5 3,5\n", "t.xyz:2: point 1: '1,5 2,5 3,5' looks like decimal commas"),
            // Whole x and y, a decimal comma in z only (session 24's audit): read as
            // commas-and-spaces columns it was (0, 0, 0) and an ignored 5.
            (b"0 0 0,5\n", "t.xyz:1: point 0: '0 0 0,5' looks like decimal commas"),
            (b"1e-3 0 0,5\n", "t.xyz:1: point 0: '1e-3 0 0,5' looks like decimal commas"),
            (b"0 0 0,5 255,\n", "t.xyz:1: point 0: '0 0 0,5 255,' looks like decimal commas"),
            (b"1 2 3\n1\t0,25 7\n", "t.xyz:2: point 1: '1\\t0,25 7' looks like decimal commas"),
            (
                b"1\t2\t3\n1,5\t2,5\t3,5 # c\n",
                "t.xyz:2: point 1: '1,5\\t2,5\\t3,5' looks like decimal commas",
            ),
        ];
        for (src, want) in cases {
            let e = parse_points(src, PointFormat::Xyz, "t.xyz").unwrap_err().to_string();
            assert!(e.contains(want), "got '{e}', want '{want}'");
        }
    }

    #[test]
    fn mesh_formats_give_their_vertices() {
        let obj = b"v 1 2 3 1\nvn 0 0 1\nv 4 5 6\nf 1 2 1\n";
        assert_eq!(
            parse_points(obj, PointFormat::Obj, "a.obj").unwrap(),
            vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]
        );
        let off = b"NOFF\n2 0 0\n1 2 3 0 0 1\n4 5 6 0 0 1\n";
        assert_eq!(
            parse_points(off, PointFormat::Off, "a.off").unwrap(),
            vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]
        );
        let ply = b"ply\nformat ascii 1.0\nelement vertex 1\nproperty double z\nproperty double y\nproperty double x\nend_header\n1 2 3\n";
        assert_eq!(parse_points(ply, PointFormat::Ply, "a.ply").unwrap(), vec![[3.0, 2.0, 1.0]]);
        let e = parse_points(b"OFF\n0 0 0\n", PointFormat::Off, "a.off").unwrap_err().to_string();
        assert!(e.contains("a.off: contains no points"), "{e}");
    }

    #[test]
    fn write_read_bit_exact_and_refuses_nan() {
        let pts = vec![[-0.0, 5e-324, 1e300], [f64::MAX, f64::MIN_POSITIVE, -1e-310], [0.1, 0.2, 0.3]];
        let dir = std::env::temp_dir().join(format!("p2q_points_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("p.xyz");
        write_points_xyz(&p, &pts).unwrap();
        let back = read_points(&p).unwrap();
        let bits = |v: &[[f64; 3]]| v.iter().flatten().map(|c| c.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&back), bits(&pts));
        let e = write_points_xyz(&dir.join("n.xyz"), &[[0.0, f64::INFINITY, 0.0]]).unwrap_err().to_string();
        assert!(e.contains("point 0"), "{e}");
        assert!(!dir.join("n.xyz").exists());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
