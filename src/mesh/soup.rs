//! Face soups: quads that may overlap, repeat or be non-manifold, with the undirected
//! edge valences the paper's post-process scores them by. A light structure over a
//! borrowed `&[[u32; 4]]`: no orientation, no manifold assumption.

use std::collections::HashMap;

/// Edge valences of a quad soup. Edges are undirected vertex pairs; a face repeating a
/// vertex contributes its edges as they come (a repeated pair counts twice).
#[derive(Clone, Debug)]
pub struct FaceSoup<'a> {
    faces: &'a [[u32; 4]],
    /// Per face, the edge index of each side `(v_i, v_{i+1})`.
    face_edges: Vec<[u32; 4]>,
    /// Per edge, its two vertices (smaller first).
    edge_verts: Vec<(u32, u32)>,
    /// CSR: faces of edge `e` are `edge_faces[edge_start[e]..edge_start[e + 1]]`
    /// (a face listed once per side on that edge).
    edge_start: Vec<u32>,
    edge_faces: Vec<u32>,
}

impl<'a> FaceSoup<'a> {
    /// Indexes the edges of `faces`.
    pub fn new(faces: &'a [[u32; 4]]) -> Self {
        let mut ids: HashMap<(u32, u32), u32> = HashMap::with_capacity(faces.len() * 2);
        let mut edge_verts = Vec::new();
        let mut face_edges = Vec::with_capacity(faces.len());
        for f in faces {
            let mut fe = [0u32; 4];
            for i in 0..4 {
                let (a, b) = (f[i], f[(i + 1) % 4]);
                let key = (a.min(b), a.max(b));
                let next = edge_verts.len() as u32;
                let id = *ids.entry(key).or_insert(next);
                if id == next {
                    edge_verts.push(key);
                }
                fe[i] = id;
            }
            face_edges.push(fe);
        }
        let mut edge_start = vec![0u32; edge_verts.len() + 1];
        for fe in &face_edges {
            for &e in fe {
                edge_start[e as usize + 1] += 1;
            }
        }
        for i in 0..edge_verts.len() {
            edge_start[i + 1] += edge_start[i];
        }
        let mut fill = edge_start.clone();
        let mut edge_faces = vec![0u32; 4 * faces.len()];
        for (fi, fe) in face_edges.iter().enumerate() {
            for &e in fe {
                edge_faces[fill[e as usize] as usize] = fi as u32;
                fill[e as usize] += 1;
            }
        }
        FaceSoup { faces, face_edges, edge_verts, edge_start, edge_faces }
    }

    /// The faces this soup indexes.
    pub fn faces(&self) -> &'a [[u32; 4]] {
        self.faces
    }
    /// Number of distinct undirected edges.
    pub fn n_edges(&self) -> usize {
        self.edge_verts.len()
    }
    /// The two vertices of edge `e` (smaller first).
    pub fn edge_vertices(&self, e: usize) -> (u32, u32) {
        self.edge_verts[e]
    }
    /// The edge index of each side of face `f`.
    pub fn face_edges(&self, f: usize) -> [u32; 4] {
        self.face_edges[f]
    }
    /// The faces on edge `e` (a face once per side it has on `e`).
    pub fn edge_faces(&self, e: usize) -> &[u32] {
        &self.edge_faces[self.edge_start[e] as usize..self.edge_start[e + 1] as usize]
    }
    /// How many face sides lie on edge `e`.
    pub fn valence(&self, e: usize) -> usize {
        (self.edge_start[e + 1] - self.edge_start[e]) as usize
    }
    /// Boundary edges (valence 1) among the sides of face `f`.
    pub fn boundary_edges_of(&self, f: usize) -> usize {
        self.face_edges[f].iter().filter(|&&e| self.valence(e as usize) == 1).count()
    }
    /// Non-manifold edges (valence > 2) among the sides of face `f`.
    pub fn nonmanifold_edges_of(&self, f: usize) -> usize {
        self.face_edges[f].iter().filter(|&&e| self.valence(e as usize) > 2).count()
    }
    /// Number of boundary edges (valence 1) in the soup.
    pub fn n_boundary_edges(&self) -> usize {
        (0..self.n_edges()).filter(|&e| self.valence(e) == 1).count()
    }
    /// Number of non-manifold edges (valence > 2) in the soup.
    pub fn n_nonmanifold_edges(&self) -> usize {
        (0..self.n_edges()).filter(|&e| self.valence(e) > 2).count()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn valences_on_a_fin() {
        // Three quads on edge (0, 1): a non-manifold fin; plus a separate quad.
        let faces = [[0, 1, 2, 3], [1, 0, 4, 5], [0, 1, 6, 7], [8, 9, 10, 11]];
        let s = FaceSoup::new(&faces);
        assert_eq!(s.n_edges(), 4 + 3 + 3 + 4);
        let e = s.face_edges(0)[0] as usize;
        assert_eq!(s.edge_vertices(e), (0, 1));
        assert_eq!(s.valence(e), 3);
        assert_eq!(s.edge_faces(e), &[0, 1, 2]);
        assert_eq!((s.boundary_edges_of(0), s.nonmanifold_edges_of(0)), (3, 1));
        assert_eq!(s.boundary_edges_of(3), 4);
        assert_eq!(s.n_nonmanifold_edges(), 1);
        assert_eq!(s.n_boundary_edges(), 13);
    }
}
