//! File formats: points (.xyz .txt .ply .obj .off), meshes (.obj .off .ply), SVG pictures; atomic writes. Parsers also work on in-memory bytes so embedders need no file system.

pub mod atomic;
pub mod mesh_io;
pub mod obj;
pub mod off;
pub mod ply;
pub mod points;
pub mod svg;
pub(crate) mod text;

/// Reads a whole input file. Only regular files (or links to them): a device such as
/// `/dev/zero` never ends and was read until the machine ran out of memory, and a
/// pipe cannot be told from one.
///
/// # Errors
/// `Io` naming `path` when it is missing, unreadable or not a regular file.
pub fn read_input_file(path: &std::path::Path) -> crate::Result<Vec<u8>> {
    let meta = std::fs::metadata(path).map_err(|e| crate::Error::io(path, e))?;
    if meta.is_dir() {
        return Err(crate::Error::io(path, std::io::Error::other("is a directory, not a file")));
    }
    if !meta.is_file() {
        return Err(crate::Error::io(
            path,
            std::io::Error::other("not a regular file (a device, pipe or socket); give a file"),
        ));
    }
    std::fs::read(path).map_err(|e| crate::Error::io(path, e))
}
