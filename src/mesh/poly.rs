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
}
