//! File formats: points (.xyz .txt .ply .obj .off), meshes (.obj .off .ply), SVG pictures; atomic writes. Parsers also work on in-memory bytes so embedders need no file system.

pub mod atomic;
pub mod mesh_io;
pub mod obj;
pub mod off;
pub mod ply;
pub mod points;
pub mod svg;
pub(crate) mod text;
