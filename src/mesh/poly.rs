//! Plain indexed meshes: `PolyMesh` (any polygons, what files hold) and `QuadMesh`
//! (pure quads, what the pipeline produces). No connectivity here; the half-edge
//! structure in `halfedge.rs` is built from these.

use crate::error::{Error, Result};

/// A polygon mesh as read from or written to a file: positions and faces as lists
/// of zero-based vertex indices.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PolyMesh {
    /// Vertex positions, exactly as read.
    pub vertices: Vec<[f64; 3]>,
    /// Faces, each a cyclic list of vertex indices (< `vertices.len()`).
    pub faces: Vec<Vec<u32>>,
}

/// A pure-quad mesh: positions and quads (4 vertex indices in cyclic order).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct QuadMesh {
    /// Vertex positions.
    pub vertices: Vec<[f64; 3]>,
    /// Quads, each 4 vertex indices in cyclic (counter-clockwise seen from outside) order.
    pub quads: Vec<[u32; 4]>,
}

impl PolyMesh {
    /// True when every face has exactly four vertices.
    pub fn is_quad_only(&self) -> bool {
        self.faces.iter().all(|f| f.len() == 4)
    }

    /// Converts to a [`QuadMesh`].
    ///
    /// # Errors
    /// `InvalidInput` naming the first face that is not a quad.
    pub fn to_quads(&self) -> Result<QuadMesh> {
        let mut quads = Vec::with_capacity(self.faces.len());
        for (i, f) in self.faces.iter().enumerate() {
            if f.len() != 4 {
                return Err(Error::invalid(format!("face {i} has {} vertices, not 4", f.len())));
            }
            quads.push([f[0], f[1], f[2], f[3]]);
        }
        Ok(QuadMesh { vertices: self.vertices.clone(), quads })
    }

    /// Converts to a [`QuadMesh`], dropping faces that are not quads; returns the
    /// mesh and how many faces were dropped.
    pub fn to_quads_lossy(&self) -> (QuadMesh, usize) {
        let quads: Vec<[u32; 4]> =
            self.faces.iter().filter(|f| f.len() == 4).map(|f| [f[0], f[1], f[2], f[3]]).collect();
        let dropped = self.faces.len() - quads.len();
        (QuadMesh { vertices: self.vertices.clone(), quads }, dropped)
    }
}

impl QuadMesh {
    /// The mesh over the vertices its quads use, in their original order, and for each
    /// kept vertex its index in `self` (strictly increasing). Vertices no quad uses
    /// (the noise points a reconstruction leaves, for one) are dropped; quads keep their
    /// order and corner order, renumbered. An index out of range is the caller's bug
    /// and panics, as indexing does.
    pub fn without_unused(&self) -> (QuadMesh, Vec<u32>) {
        self.without_unused_from(0)
    }

    /// As [`QuadMesh::without_unused`], but the first `start` vertices all stay, used or
    /// not: only vertices from `start` on that no quad uses are dropped (the vertices a
    /// hole filling added whose quads a later step took out, after the input's points).
    pub fn without_unused_from(&self, start: usize) -> (QuadMesh, Vec<u32>) {
        let mut new_index = vec![u32::MAX; self.vertices.len()];
        new_index.iter_mut().take(start).for_each(|s| *s = 0);
        for q in &self.quads {
            for &v in q {
                new_index[v as usize] = 0;
            }
        }
        let (mut vertices, mut kept) = (Vec::new(), Vec::new());
        for (i, slot) in new_index.iter_mut().enumerate() {
            if *slot == 0 {
                *slot = vertices.len() as u32;
                vertices.push(self.vertices[i]);
                kept.push(i as u32);
            }
        }
        let quads = self.quads.iter().map(|q| q.map(|v| new_index[v as usize])).collect();
        (QuadMesh { vertices, quads }, kept)
    }
}

impl From<&QuadMesh> for PolyMesh {
    fn from(q: &QuadMesh) -> Self {
        PolyMesh { vertices: q.vertices.clone(), faces: q.quads.iter().map(|f| f.to_vec()).collect() }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn quad_conversion_names_the_bad_face() {
        let mut m = PolyMesh { vertices: vec![[0.0; 3]; 5], faces: vec![vec![0, 1, 2, 3], vec![0, 1, 4]] };
        let err = m.to_quads().unwrap_err().to_string();
        assert!(err.contains("face 1"), "{err}");
        let (q, dropped) = m.to_quads_lossy();
        assert_eq!((q.quads.len(), dropped), (1, 1));
        m.faces.pop();
        assert!(m.is_quad_only());
        assert_eq!(PolyMesh::from(&m.to_quads().unwrap()), m);
    }

    #[test]
    fn without_unused_keeps_the_used_vertices_in_order() {
        let v = |i: u32| [i as f64, 0.0, 0.0];
        let m = QuadMesh { vertices: (0..8).map(v).collect(), quads: vec![[6, 1, 3, 4], [1, 6, 7, 3]] };
        let (c, kept) = m.without_unused();
        assert_eq!(kept, vec![1, 3, 4, 6, 7]);
        assert_eq!(c.vertices, vec![v(1), v(3), v(4), v(6), v(7)]);
        assert_eq!(c.quads, vec![[3, 0, 1, 2], [0, 3, 4, 1]]);
        let empty = QuadMesh { vertices: vec![[0.0; 3]; 3], quads: vec![] };
        assert_eq!(empty.without_unused(), (QuadMesh::default(), vec![]));
    }
}
