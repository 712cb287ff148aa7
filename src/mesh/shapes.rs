//! Synthetic pure-quad meshes: parametric grids (plane, height field, cube, cube-sphere,
//! torus, tube and capped cylinder), boundary surfaces of random voxel sets, Catmull–Clark
//! subdivision, random poses, and `random_shape`, which draws from all of them. Every
//! generator returns a manifold, consistently oriented quad mesh (outward for closed shapes)
//! without unreferenced or coincident vertices; they serve as test fixtures and training data.

use std::collections::HashMap;

use crate::math::{add, cross, dot, mat_vec, norm, scale, sub};
use crate::mesh::poly::QuadMesh;
use crate::rng::Rng;

/// A flat open grid of `nu × nv` quads covering `[0, size_u] × [0, size_v]` in the plane
/// z = 0, normals +z. Counts below 1 are treated as 1.
pub fn grid(nu: usize, nv: usize, size_u: f64, size_v: f64) -> QuadMesh {
    let (nu, nv) = (nu.max(1), nv.max(1));
    let mut m =
        param_grid(nu, nv, false, |i, j| [size_u * i as f64 / nu as f64, size_v * j as f64 / nv as f64, 0.0]);
    m.vertices.shrink_to_fit();
    m
}

/// An open `nu × nv` quad grid over the unit square, lifted to z = `f(x, y)`
/// (x, y ∈ [0, 1]); normals point towards +z. Counts below 1 are treated as 1.
pub fn height_field(nu: usize, nv: usize, f: impl Fn(f64, f64) -> f64) -> QuadMesh {
    let (nu, nv) = (nu.max(1), nv.max(1));
    param_grid(nu, nv, false, |i, j| {
        let (x, y) = (i as f64 / nu as f64, j as f64 / nv as f64);
        [x, y, f(x, y)]
    })
}

/// The cube [−1, 1]³ with `n × n` quads per side (sharp edges, outward normals).
/// `n` below 1 is treated as 1.
pub fn cube(n: usize) -> QuadMesh {
    let n = n.max(1);
    lattice_cube(n, |p| p)
}

/// The cube of [`cube`] projected onto the unit sphere. The projection is equiangular
/// (each cube coordinate goes through tan(π/4·x) first), so quads stay close to square.
/// `n` below 1 is treated as 1.
pub fn cube_sphere(n: usize) -> QuadMesh {
    let n = n.max(1);
    let q = std::f64::consts::FRAC_PI_4;
    lattice_cube(n, |p| {
        let t = [(q * p[0]).tan(), (q * p[1]).tan(), (q * p[2]).tan()];
        scale(t, 1.0 / norm(t))
    })
}

/// A torus around the z axis: `nu` quads around the axis, `nv` around the tube, tube
/// radius `minor` at distance `major` from the axis (take `minor < major`, else the
/// surface self-intersects). Counts below 3 are treated as 3.
pub fn torus(nu: usize, nv: usize, major: f64, minor: f64) -> QuadMesh {
    let (nu, nv) = (nu.max(3), nv.max(3));
    let tau = std::f64::consts::TAU;
    param_grid_wrapped(nu, nv, true, |i, j| {
        let (t, p) = (tau * i as f64 / nu as f64, tau * j as f64 / nv as f64);
        let r = major + minor * p.cos();
        [r * t.cos(), r * t.sin(), minor * p.sin()]
    })
}

/// A cylinder around the z axis from z = 0 to z = `height`: `nu` quads around, `nv` along.
/// Open (a tube, two boundary loops) or, with `capped`, closed by two pure-quad disks:
/// an inner square grid joined to the rim by rings of quads (no pole). Capping needs `nu`
/// to be a multiple of 4 and rounds it up. Counts below 3 (around) / 1 (along) are raised.
pub fn cylinder(nu: usize, nv: usize, radius: f64, height: f64, capped: bool) -> QuadMesh {
    let nu = if capped { nu.max(4).div_ceil(4) * 4 } else { nu.max(3) };
    let nv = nv.max(1);
    let tau = std::f64::consts::TAU;
    let angle = |i: usize| std::f64::consts::FRAC_PI_4 + tau * i as f64 / nu as f64;
    let mut m = QuadMesh::default();
    for j in 0..=nv {
        for i in 0..nu {
            let a = angle(i);
            m.vertices.push([radius * a.cos(), radius * a.sin(), height * j as f64 / nv as f64]);
        }
    }
    let id = |i: usize, j: usize| (j * nu + i % nu) as u32;
    for j in 0..nv {
        for i in 0..nu {
            m.quads.push([id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    if capped {
        let bottom: Vec<u32> = (0..nu).map(|i| id(i, 0)).collect();
        let top: Vec<u32> = (0..nu).map(|i| id(i, nv)).collect();
        add_disk_cap(&mut m, &bottom, radius, 0.0, false);
        add_disk_cap(&mut m, &top, radius, height, true);
    }
    m
}

/// Closes the circular rim `ring` (4m vertices at angles π/4 + 2πk/4m, radius `radius`,
/// height `z`) with a quad disk: an m × m square grid, then rings interpolating from the
/// square's perimeter to the circle. `up`: normals +z (else −z).
fn add_disk_cap(m: &mut QuadMesh, ring: &[u32], radius: f64, z: f64, up: bool) {
    let n = ring.len();
    let k = n / 4;
    let s = 0.5 * radius;
    // Perimeter of the square, CCW from the corner at 45°, as (a, b) grid indices.
    let corners = [[k, k], [0, k], [0, 0], [k, 0]];
    let perimeter = |p: usize| -> [usize; 2] {
        let (side, t) = (p / k, p % k);
        let c = corners[side % 4];
        match side % 4 {
            0 => [c[0] - t, c[1]],
            1 => [c[0], c[1] - t],
            2 => [c[0] + t, c[1]],
            _ => [c[0], c[1] + t],
        }
    };
    let grid_pos =
        |a: usize, b: usize| [s * (2.0 * a as f64 / k as f64 - 1.0), s * (2.0 * b as f64 / k as f64 - 1.0)];
    let layers = (k as f64 * 0.35).round().max(1.0) as usize;
    // rings[l][p]: vertex of layer l (0 = square perimeter, layers = rim) at perimeter slot p.
    let mut rings: Vec<Vec<u32>> = Vec::with_capacity(layers + 1);
    for l in 0..layers {
        let t = l as f64 / layers as f64;
        let mut r = Vec::with_capacity(n);
        for p in 0..n {
            let [a, b] = perimeter(p);
            let sq = grid_pos(a, b);
            let ang = std::f64::consts::FRAC_PI_4 + std::f64::consts::TAU * p as f64 / n as f64;
            let ci = [radius * ang.cos(), radius * ang.sin()];
            r.push(m.vertices.len() as u32);
            m.vertices.push([sq[0] + t * (ci[0] - sq[0]), sq[1] + t * (ci[1] - sq[1]), z]);
        }
        rings.push(r);
    }
    rings.push(ring.to_vec());
    // Square grid: perimeter vertices come from layer 0, interior ones are new.
    let mut gid = vec![u32::MAX; (k + 1) * (k + 1)];
    for (p, &v) in rings[0].iter().enumerate() {
        let [a, b] = perimeter(p);
        gid[b * (k + 1) + a] = v;
    }
    for b in 1..k {
        for a in 1..k {
            let g = grid_pos(a, b);
            gid[b * (k + 1) + a] = m.vertices.len() as u32;
            m.vertices.push([g[0], g[1], z]);
        }
    }
    let mut push = |q: [u32; 4]| m.quads.push(if up { q } else { [q[0], q[3], q[2], q[1]] });
    for b in 0..k {
        for a in 0..k {
            let g = |a: usize, b: usize| gid[b * (k + 1) + a];
            push([g(a, b), g(a + 1, b), g(a + 1, b + 1), g(a, b + 1)]);
        }
    }
    for l in 0..layers {
        for p in 0..n {
            let q = (p + 1) % n;
            // Radial step then CCW step: normal +z.
            push([rings[l][p], rings[l + 1][p], rings[l + 1][q], rings[l][q]]);
        }
    }
}

/// `(nu+1) × (nv+1)` vertices from `pos(i, j)`, quads CCW in (i, j) (normal ∂i × ∂j).
fn param_grid(nu: usize, nv: usize, _wrap: bool, pos: impl Fn(usize, usize) -> [f64; 3]) -> QuadMesh {
    let mut m = QuadMesh::default();
    for j in 0..=nv {
        for i in 0..=nu {
            m.vertices.push(pos(i, j));
        }
    }
    let id = |i: usize, j: usize| (j * (nu + 1) + i) as u32;
    for j in 0..nv {
        for i in 0..nu {
            m.quads.push([id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    m
}

/// Like [`param_grid`] but periodic in i and (when `wrap_v`) in j.
fn param_grid_wrapped(
    nu: usize,
    nv: usize,
    wrap_v: bool,
    pos: impl Fn(usize, usize) -> [f64; 3],
) -> QuadMesh {
    let rows = if wrap_v { nv } else { nv + 1 };
    let mut m = QuadMesh::default();
    for j in 0..rows {
        for i in 0..nu {
            m.vertices.push(pos(i, j));
        }
    }
    let id = |i: usize, j: usize| ((j % rows) * nu + i % nu) as u32;
    for j in 0..nv {
        for i in 0..nu {
            m.quads.push([id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    m
}

/// Surface of the integer lattice cube [0, n]³, vertices mapped to [−1, 1]³ and then
/// through `map`; outward orientation.
fn lattice_cube(n: usize, map: impl Fn([f64; 3]) -> [f64; 3]) -> QuadMesh {
    let mut b = LatticeBuilder::default();
    for axis in 0..3 {
        for side in [0usize, n] {
            for i in 0..n {
                for j in 0..n {
                    b.face(axis, side, i, j, side == n);
                }
            }
        }
    }
    let inv = 2.0 / n as f64;
    b.finish(|p| map([p[0] as f64 * inv - 1.0, p[1] as f64 * inv - 1.0, p[2] as f64 * inv - 1.0]))
}

/// Collects axis-aligned unit squares of the integer lattice, sharing their corners.
#[derive(Default)]
struct LatticeBuilder {
    ids: HashMap<[usize; 3], u32>,
    points: Vec<[usize; 3]>,
    quads: Vec<[u32; 4]>,
}

impl LatticeBuilder {
    fn vertex(&mut self, p: [usize; 3]) -> u32 {
        let next = self.points.len() as u32;
        *self.ids.entry(p).or_insert_with(|| {
            self.points.push(p);
            next
        })
    }

    /// The unit square in the plane x_axis = `level`, spanning lattice cells (i, j) in
    /// the two other axes (b, c) with e_b × e_c = e_axis; `positive`: normal +e_axis.
    fn face(&mut self, axis: usize, level: usize, i: usize, j: usize, positive: bool) {
        let (b, c) = ((axis + 1) % 3, (axis + 2) % 3);
        let corner = |di: usize, dj: usize| {
            let mut p = [0usize; 3];
            p[axis] = level;
            p[b] = i + di;
            p[c] = j + dj;
            p
        };
        let v = [corner(0, 0), corner(1, 0), corner(1, 1), corner(0, 1)].map(|p| self.vertex(p));
        self.quads.push(if positive { v } else { [v[0], v[3], v[2], v[1]] });
    }

    fn finish(self, pos: impl Fn([usize; 3]) -> [f64; 3]) -> QuadMesh {
        QuadMesh { vertices: self.points.into_iter().map(pos).collect(), quads: self.quads }
    }
}

/// A set of voxels in a `dims` box (x fastest), the input of [`voxel_boundary`].
#[derive(Clone, Debug, PartialEq)]
pub struct VoxelSet {
    /// Box size in voxels along x, y, z.
    pub dims: [usize; 3],
    /// `filled[x + dims[0] * (y + dims[1] * z)]`.
    pub filled: Vec<bool>,
}

impl VoxelSet {
    /// An empty set in a `dims` box.
    pub fn new(dims: [usize; 3]) -> Self {
        VoxelSet { dims, filled: vec![false; dims[0] * dims[1] * dims[2]] }
    }

    /// Whether voxel `(x, y, z)` is filled; coordinates outside the box (including
    /// negative ones, given as `isize`) are empty.
    pub fn get(&self, p: [isize; 3]) -> bool {
        match self.index(p) {
            Some(i) => self.filled[i],
            None => false,
        }
    }

    fn index(&self, p: [isize; 3]) -> Option<usize> {
        let d = self.dims;
        if (0..3).all(|a| p[a] >= 0 && (p[a] as usize) < d[a]) {
            Some(p[0] as usize + d[0] * (p[1] as usize + d[1] * p[2] as usize))
        } else {
            None
        }
    }

    /// Fills voxel `p` (ignored outside the box).
    pub fn set(&mut self, p: [isize; 3]) {
        if let Some(i) = self.index(p) {
            self.filled[i] = true;
        }
    }

    /// Number of filled voxels.
    pub fn count(&self) -> usize {
        self.filled.iter().filter(|&&f| f).count()
    }

    /// First lattice point (or lattice edge, given as its lower end and axis) where the
    /// boundary surface would not be manifold, with a voxel to fill that helps.
    /// Edge defect: two voxels sharing only this edge. Vertex defect: the filled or the
    /// empty voxels among the 8 around the point are not face-connected.
    fn first_defect(&self) -> Option<[isize; 3]> {
        let d = self.dims.map(|x| x as isize);
        for z in 0..=d[2] {
            for y in 0..=d[1] {
                for x in 0..=d[0] {
                    // The 8 voxels around lattice point (x, y, z): bit 0 x, bit 1 y, bit 2 z.
                    let cell = |k: usize| {
                        [
                            x - 1 + (k & 1) as isize,
                            y - 1 + ((k >> 1) & 1) as isize,
                            z - 1 + ((k >> 2) & 1) as isize,
                        ]
                    };
                    let mut mask = 0u8;
                    for k in 0..8 {
                        if self.get(cell(k)) {
                            mask |= 1 << k;
                        }
                    }
                    if mask == 0 || mask == 0xff {
                        continue;
                    }
                    if !block_is_manifold(mask) {
                        // Fill an empty in-box voxel of the block; filling never disconnects
                        // the set and ends at the full box, so the repair loop terminates.
                        // Take one next to a filled voxel of the block so the set stays
                        // face-connected (the in-box voxels form a box, so one exists).
                        let fix = (0..8).find(|&k| {
                            mask >> k & 1 == 0
                                && self.index(cell(k)).is_some()
                                && (0..3).any(|a| mask >> (k ^ (1 << a)) & 1 == 1)
                        });
                        return Some(cell(fix.expect("internal error: a defect block has a fillable voxel")));
                    }
                }
            }
        }
        None
    }
}

/// Whether the boundary of the filled voxels of a 2×2×2 block is a single disk at its
/// centre: no two filled (or two empty) voxels meet only along an edge of the block's
/// centre lines with the other two opposite, and filled and empty voxels are each
/// face-connected within the block.
fn block_is_manifold(mask: u8) -> bool {
    let filled = |k: usize| mask >> k & 1 == 1;
    // The four voxels around each of the 6 half-axes through the centre: diagonal pattern.
    for axis in 0..3 {
        let (b, c) = (1usize << ((axis + 1) % 3), 1usize << ((axis + 2) % 3));
        for side in [0, 1usize << axis] {
            let ring = [side, side | b, side | b | c, side | c];
            let f = ring.map(filled);
            if f[0] == f[2] && f[1] == f[3] && f[0] != f[1] {
                return false;
            }
        }
    }
    let connected = |want: bool| {
        let members: Vec<usize> = (0..8).filter(|&k| filled(k) == want).collect();
        let mut seen = 1u8 << members[0];
        let mut stack = vec![members[0]];
        while let Some(k) = stack.pop() {
            for a in 0..3 {
                let nb = k ^ (1 << a);
                if filled(nb) == want && seen >> nb & 1 == 0 {
                    seen |= 1 << nb;
                    stack.push(nb);
                }
            }
        }
        seen.count_ones() as usize == members.len()
    };
    connected(true) && connected(false)
}

/// The boundary surface of the filled voxels, as unit squares on the integer lattice
/// (vertex (x, y, z) at those coordinates), outward-oriented.
///
/// The result is manifold only when the set has no edge or vertex defect; use
/// [`repair_voxels`] first (as [`voxel_cage`] does).
pub fn voxel_boundary(set: &VoxelSet) -> QuadMesh {
    let d = set.dims.map(|x| x as isize);
    let mut b = LatticeBuilder::default();
    for z in 0..d[2] {
        for y in 0..d[1] {
            for x in 0..d[0] {
                let p = [x, y, z];
                if !set.get(p) {
                    continue;
                }
                for axis in 0..3 {
                    for dir in [-1isize, 1] {
                        let mut q = p;
                        q[axis] += dir;
                        if set.get(q) {
                            continue;
                        }
                        let (bx, cx) = ((axis + 1) % 3, (axis + 2) % 3);
                        let level = (p[axis] + (dir > 0) as isize) as usize;
                        b.face(axis, level, p[bx] as usize, p[cx] as usize, dir > 0);
                    }
                }
            }
        }
    }
    b.finish(|p| [p[0] as f64, p[1] as f64, p[2] as f64])
}

/// Makes the voxel set's boundary a closed connected manifold: fills enclosed cavities
/// (empty voxels not face-connected to the outside) and fills voxels until no lattice
/// edge or point is a defect. Only ever adds voxels, so a face-connected set stays so.
/// Returns how many voxels were added.
pub fn repair_voxels(set: &mut VoxelSet) -> usize {
    let before = set.count();
    loop {
        fill_cavities(set);
        match set.first_defect() {
            Some(c) => set.set(c),
            None => break,
        }
    }
    set.count() - before
}

/// Fills every empty voxel that the outside cannot reach through empty face-neighbours.
fn fill_cavities(set: &mut VoxelSet) {
    let d = set.dims.map(|x| x as isize);
    let padded = |p: [isize; 3]| ((p[0] + 1) + (d[0] + 2) * ((p[1] + 1) + (d[1] + 2) * (p[2] + 1))) as usize;
    let mut outside = vec![false; ((d[0] + 2) * (d[1] + 2) * (d[2] + 2)) as usize];
    let mut stack = vec![[-1isize, -1, -1]];
    outside[padded([-1, -1, -1])] = true;
    while let Some(p) = stack.pop() {
        for axis in 0..3 {
            for dir in [-1isize, 1] {
                let mut q = p;
                q[axis] += dir;
                if (0..3).any(|a| q[a] < -1 || q[a] > d[a]) || set.get(q) || outside[padded(q)] {
                    continue;
                }
                outside[padded(q)] = true;
                stack.push(q);
            }
        }
    }
    for z in 0..d[2] {
        for y in 0..d[1] {
            for x in 0..d[0] {
                if !outside[padded([x, y, z])] {
                    set.set([x, y, z]);
                }
            }
        }
    }
}

/// The boundary surface of a random face-connected set of about `fill` × (box volume)
/// voxels in a `dims` box (each at least 1), made manifold by [`repair_voxels`]; any
/// genus (random bars crossing leave tunnels). Vertices on the integer lattice, centred
/// on the origin; outward orientation; one connected closed surface.
pub fn voxel_cage(rng: &mut Rng, dims: [usize; 3], fill: f64) -> QuadMesh {
    let dims = dims.map(|x| x.max(1));
    let mut set = VoxelSet::new(dims);
    let total = dims[0] * dims[1] * dims[2];
    let target = ((fill.clamp(0.0, 1.0) * total as f64).round() as usize).clamp(1, total);
    let start = dims.map(|x| rng.below(x) as isize);
    set.set(start);
    let mut filled = vec![start];
    // Grow by straight bars from random filled voxels: crossing bars enclose tunnels.
    let mut attempts = 0;
    while set.count() < target && attempts < 100 * total {
        attempts += 1;
        let mut p = filled[rng.below(filled.len())];
        let axis = rng.below(3);
        let dir = if rng.below(2) == 0 { -1 } else { 1 };
        let len = 1 + rng.below(dims[axis].max(2));
        for _ in 0..len {
            p[axis] += dir;
            if set.index(p).is_none() || set.count() >= target {
                break;
            }
            if !set.get(p) {
                set.set(p);
                filled.push(p);
            }
        }
    }
    repair_voxels(&mut set);
    let mut m = voxel_boundary(&set);
    let c = dims.map(|x| x as f64 / 2.0);
    for v in &mut m.vertices {
        *v = sub(*v, c);
    }
    m
}

/// Catmull–Clark subdivision, `levels` times, of a quad mesh with or without boundary.
///
/// Boundary edges are creases (edge point = midpoint; boundary vertex (6v + a + b)/8;
/// a vertex with a single face is a corner and stays). With `sharp`, interior edges whose
/// two face normals differ by more than 30° are creases too, and stay creased on every
/// level (crease vertex: two crease edges, crease rule; three or more: corner). Preserves
/// orientation and Euler characteristic; the result is pure-quad. Faces whose indices are
/// out of range are dropped (the input is assumed manifold, as every generator here is).
pub fn catmull_clark(mesh: &QuadMesh, levels: usize, sharp: bool) -> QuadMesh {
    let mut m = mesh.clone();
    let nv = m.vertices.len() as u32;
    m.quads.retain(|q| q.iter().all(|&v| v < nv));
    let mut creases: Option<Vec<bool>> = None;
    for _ in 0..levels {
        let edges = EdgeTable::new(&m);
        let crease: Vec<bool> = match creases.take() {
            Some(c) => c,
            None => (0..edges.ends.len())
                .map(|e| {
                    let f = &edges.faces[e];
                    f.len() != 2
                        || (sharp
                            && dot(face_normal(&m, f[0]), face_normal(&m, f[1])) < 30f64.to_radians().cos())
                })
                .collect(),
        };
        let (next, next_crease) = subdivide_once(&m, &edges, &crease);
        m = next;
        creases = Some(next_crease);
    }
    m
}

/// Unit normal of quad `f` (diagonal cross product), zero when degenerate.
fn face_normal(m: &QuadMesh, f: usize) -> [f64; 3] {
    let q = m.quads[f].map(|v| m.vertices[v as usize]);
    let n = cross(sub(q[2], q[0]), sub(q[3], q[1]));
    let l = norm(n);
    if l > 0.0 {
        scale(n, 1.0 / l)
    } else {
        n
    }
}

/// Undirected edges of a quad mesh: ends, incident faces, and each face's 4 edge ids
/// (edge k of a face joins its corners k and k+1).
struct EdgeTable {
    ends: Vec<[u32; 2]>,
    faces: Vec<Vec<usize>>,
    face_edges: Vec<[usize; 4]>,
}

impl EdgeTable {
    fn new(m: &QuadMesh) -> Self {
        let mut ids: HashMap<(u32, u32), usize> = HashMap::with_capacity(m.quads.len() * 2);
        let mut t =
            EdgeTable { ends: Vec::new(), faces: Vec::new(), face_edges: Vec::with_capacity(m.quads.len()) };
        for (fi, q) in m.quads.iter().enumerate() {
            let mut fe = [0; 4];
            for k in 0..4 {
                let (a, b) = (q[k], q[(k + 1) % 4]);
                let key = (a.min(b), a.max(b));
                let e = *ids.entry(key).or_insert_with(|| {
                    t.ends.push([key.0, key.1]);
                    t.faces.push(Vec::new());
                    t.ends.len() - 1
                });
                t.faces[e].push(fi);
                fe[k] = e;
            }
            t.face_edges.push(fe);
        }
        t
    }
}

/// One Catmull–Clark step; returns the refined mesh and the crease flags of its edges
/// (in the order an [`EdgeTable`] of the result enumerates them).
fn subdivide_once(m: &QuadMesh, t: &EdgeTable, crease: &[bool]) -> (QuadMesh, Vec<bool>) {
    let (nv, ne, nf) = (m.vertices.len(), t.ends.len(), m.quads.len());
    let p = |v: u32| m.vertices[v as usize];
    let face_pts: Vec<[f64; 3]> =
        m.quads.iter().map(|q| scale(add(add(p(q[0]), p(q[1])), add(p(q[2]), p(q[3]))), 0.25)).collect();
    let edge_pts: Vec<[f64; 3]> = (0..ne)
        .map(|e| {
            let [a, b] = t.ends[e];
            let mid = scale(add(p(a), p(b)), 0.5);
            if crease[e] {
                mid
            } else {
                let f = &t.faces[e];
                scale(add(mid, scale(add(face_pts[f[0]], face_pts[f[1]]), 0.5)), 0.5)
            }
        })
        .collect();
    // Per vertex: sums of adjacent face points and edge midpoints, valences, crease neighbours.
    let mut fsum = vec![[0.0; 3]; nv];
    let mut fcount = vec![0usize; nv];
    for (fi, q) in m.quads.iter().enumerate() {
        for &v in q {
            fsum[v as usize] = add(fsum[v as usize], face_pts[fi]);
            fcount[v as usize] += 1;
        }
    }
    let mut esum = vec![[0.0; 3]; nv];
    let mut ecount = vec![0usize; nv];
    let mut crease_nb: Vec<Vec<u32>> = vec![Vec::new(); nv];
    for (e, &[a, b]) in t.ends.iter().enumerate() {
        let mid = scale(add(p(a), p(b)), 0.5);
        for (v, o) in [(a, b), (b, a)] {
            esum[v as usize] = add(esum[v as usize], mid);
            ecount[v as usize] += 1;
            if crease[e] {
                crease_nb[v as usize].push(o);
            }
        }
    }
    let mut vertices: Vec<[f64; 3]> = (0..nv)
        .map(|v| {
            let pv = m.vertices[v];
            let nc = crease_nb[v].len();
            if fcount[v] == 0 || fcount[v] == 1 && nc >= 2 || nc >= 3 {
                pv
            } else if nc == 2 {
                let (a, b) = (p(crease_nb[v][0]), p(crease_nb[v][1]));
                scale(add(scale(pv, 6.0), add(a, b)), 0.125)
            } else {
                let n = ecount[v] as f64;
                let f = scale(fsum[v], 1.0 / fcount[v] as f64);
                let r = scale(esum[v], 1.0 / ecount[v] as f64);
                scale(add(add(f, scale(r, 2.0)), scale(pv, n - 3.0)), 1.0 / n)
            }
        })
        .collect();
    vertices.extend(edge_pts);
    vertices.extend(face_pts);
    let ev = |e: usize| (nv + e) as u32;
    let fv = |f: usize| (nv + ne + f) as u32;
    let mut quads = Vec::with_capacity(4 * nf);
    for (fi, q) in m.quads.iter().enumerate() {
        let fe = t.face_edges[fi];
        for k in 0..4 {
            // Corner k: its outgoing edge k and incoming edge k−1.
            quads.push([q[k], ev(fe[k]), fv(fi), ev(fe[(k + 3) % 4])]);
        }
    }
    let out = QuadMesh { vertices, quads };
    // Child edges of a crease edge are creases; edges to face points never are.
    let child = EdgeTable::new(&out);
    let flags = child
        .ends
        .iter()
        .map(|&[a, b]| {
            let (old, new) = if (a as usize) < nv { (a, b) } else { (b, a) };
            let e = new as usize;
            (old as usize) < nv && e >= nv && e < nv + ne && crease[e - nv]
        })
        .collect();
    (out, flags)
}

/// A randomly posed copy: uniformly random rotation, uniform scale 10^U(−2, 3), and a
/// translation of up to 10 × that scale along each axis.
pub fn random_pose(mesh: &QuadMesh, rng: &mut Rng) -> QuadMesh {
    let r = rng.rotation();
    let s = 10f64.powf(rng.uniform(-2.0, 3.0));
    let t = [rng.uniform(-10.0, 10.0) * s, rng.uniform(-10.0, 10.0) * s, rng.uniform(-10.0, 10.0) * s];
    QuadMesh {
        vertices: mesh.vertices.iter().map(|&v| add(scale(mat_vec(&r, v), s), t)).collect(),
        quads: mesh.quads.clone(),
    }
}

/// The shape families of [`random_shape`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Family {
    /// Flat open grid.
    Grid,
    /// Open height field (sum of random bumps and waves).
    HeightField,
    /// Cube (sharp edges).
    Cube,
    /// Cube projected to the sphere.
    CubeSphere,
    /// Torus.
    Torus,
    /// Open tube.
    Tube,
    /// Capped cylinder.
    Cylinder,
    /// Catmull–Clark smoothed voxel cage.
    CageSmooth,
    /// Catmull–Clark subdivided voxel cage with creased cage edges.
    CageSharp,
}

impl Family {
    /// Every family, in a fixed order.
    pub const ALL: [Family; 9] = [
        Family::Grid,
        Family::HeightField,
        Family::Cube,
        Family::CubeSphere,
        Family::Torus,
        Family::Tube,
        Family::Cylinder,
        Family::CageSmooth,
        Family::CageSharp,
    ];

    /// Whether the family's surfaces are closed.
    pub fn is_closed(self) -> bool {
        !matches!(self, Family::Grid | Family::HeightField | Family::Tube)
    }

    /// Short lowercase name (used in sample names).
    pub fn name(self) -> &'static str {
        match self {
            Family::Grid => "grid",
            Family::HeightField => "height_field",
            Family::Cube => "cube",
            Family::CubeSphere => "cube_sphere",
            Family::Torus => "torus",
            Family::Tube => "tube",
            Family::Cylinder => "cylinder",
            Family::CageSmooth => "cage_smooth",
            Family::CageSharp => "cage_sharp",
        }
    }
}

/// A random member of a random family (see [`random_shape_of`]), randomly posed.
pub fn random_shape(rng: &mut Rng) -> QuadMesh {
    let family = Family::ALL[rng.below(Family::ALL.len())];
    random_shape_of(family, rng)
}

/// A random member of `family` with random parameters, about 200–5000 vertices,
/// sometimes anisotropic (quads elongated down to an edge ratio of about 0.2), randomly
/// posed with [`random_pose`].
pub fn random_shape_of(family: Family, rng: &mut Rng) -> QuadMesh {
    random_shape_with_aspect(family, rng, DEFAULT_MIN_ASPECT)
}

/// The smallest aspect factor [`random_shape_of`] draws for its elongated third of the
/// shapes (quads elongated up to about 4:1).
pub const DEFAULT_MIN_ASPECT: f64 = 0.25;

/// [`random_shape_of`] with the elongated third of the shapes drawing their aspect factor
/// from `[min_aspect, 1)` instead of `[0.25, 1)` (`dataset --min-aspect`; session 20's
/// experiment). The same random stream as [`random_shape_of`]: with `min_aspect` 0.25
/// the shapes are identical, otherwise only the elongated ones differ.
pub fn random_shape_with_aspect(family: Family, rng: &mut Rng, min_aspect: f64) -> QuadMesh {
    // Aspect factor for elongated quads (1 most of the time).
    let aspect = if rng.below(3) == 0 { rng.uniform(min_aspect, 1.0) } else { 1.0 };
    let mut m = match family {
        Family::Grid | Family::HeightField => {
            let nu = 12 + rng.below(50);
            let nv = ((rng.uniform(200.0, 4500.0) / (nu + 1) as f64) as usize).clamp(10, 4900 / (nu + 1) - 1);
            if family == Family::Grid {
                grid(nu, nv, 1.0, aspect * nv as f64 / nu as f64)
            } else {
                let bumps: Vec<[f64; 4]> = (0..1 + rng.below(5))
                    .map(|_| {
                        // Height at most ~0.6 × width: slopes stay moderate, so quads are
                        // not stretched beyond the edge ratios real meshes show (~0.2).
                        let w = rng.uniform(0.08, 0.3);
                        [rng.f64(), rng.f64(), w, rng.uniform(-0.6, 0.6) * w]
                    })
                    .collect();
                let (fx, fy) = (rng.uniform(0.5, 3.0), rng.uniform(0.5, 3.0));
                let amp = rng.uniform(0.0, 0.4) / (std::f64::consts::TAU * fx.max(fy));
                let mut h = height_field(nu, nv, |x, y| {
                    let mut z =
                        amp * (std::f64::consts::TAU * fx * x).sin() * (std::f64::consts::TAU * fy * y).cos();
                    for b in &bumps {
                        let d2 = (x - b[0]).powi(2) + (y - b[1]).powi(2);
                        z += b[3] * (-d2 / (b[2] * b[2])).exp();
                    }
                    z
                });
                let sy = aspect * nv as f64 / nu as f64;
                for v in &mut h.vertices {
                    v[1] *= sy;
                }
                h
            }
        }
        Family::Cube | Family::CubeSphere => {
            let n = 6 + rng.below(23);
            let mut c = if family == Family::Cube { cube(n) } else { cube_sphere(n) };
            for v in &mut c.vertices {
                v[2] *= aspect;
            }
            c
        }
        Family::Torus => {
            let minor_ratio = rng.uniform(0.15, 0.6);
            let nu = 24 + rng.below(76);
            let nv_ideal = (nu as f64 * minor_ratio / aspect).round() as usize;
            let nv = nv_ideal.clamp(9, (5000 / nu).max(9));
            torus(nu, nv, 1.0, minor_ratio)
        }
        Family::Tube | Family::Cylinder => {
            let nu = 24 + rng.below(52);
            let h = rng.uniform(0.5, 4.0);
            let circ = std::f64::consts::TAU / nu as f64;
            let capped = family == Family::Cylinder;
            // Vertices of the two caps (as `add_disk_cap` builds them) count towards the budget.
            let (nu, caps) = if capped {
                let (nu4, k) = (nu.div_ceil(4) * 4, nu.div_ceil(4));
                let layers = (k as f64 * 0.35).round().max(1.0) as usize;
                (nu4, 2 * ((k - 1) * (k - 1) + layers * nu4))
            } else {
                (nu, 0)
            };
            let max_nv = (4800usize.saturating_sub(caps) / nu).saturating_sub(1).max(8);
            let nv = ((h / (circ / aspect)).round() as usize).clamp(8, max_nv);
            cylinder(nu, nv, 1.0, h, capped)
        }
        Family::CageSmooth | Family::CageSharp => {
            let dims = [2 + rng.below(5), 2 + rng.below(5), 1 + rng.below(4)];
            let fill = rng.uniform(0.3, 0.8);
            let cage = voxel_cage(rng, dims, fill);
            let mut levels = 1;
            while levels < 3 && cage.vertices.len() * 4usize.pow(levels as u32 + 1) <= 5000 {
                levels += 1;
            }
            let mut c = catmull_clark(&cage, levels, family == Family::CageSharp);
            for v in &mut c.vertices {
                v[2] *= aspect;
            }
            c
        }
    };
    m.vertices.shrink_to_fit();
    random_pose(&m, rng)
}

/// Per vertex, the sum of its quads' diagonal cross products (p2 − p0) × (p3 − p1): an
/// area-weighted normal, zero for a vertex without faces.
fn vertex_normal_sums(mesh: &QuadMesh) -> Vec<[f64; 3]> {
    let mut normal = vec![[0.0f64; 3]; mesh.vertices.len()];
    for q in &mesh.quads {
        let p = q.map(|i| mesh.vertices[i as usize]);
        let c = cross(sub(p[2], p[0]), sub(p[3], p[1]));
        for &v in q {
            normal[v as usize] = add(normal[v as usize], c);
        }
    }
    normal
}

/// Scaled Jacobian of quad `q` over `verts` (the metric code's definition).
fn quad_sj(verts: &[[f64; 3]], q: &[u32; 4]) -> f64 {
    crate::mesh::quality::quad_shape(&q.map(|i| verts[i as usize])).scaled_jacobian
}

/// A triangle mesh's usual conversion to quads, applied to `mesh` (session 39): every quad
/// is first cut into two triangles along a random diagonal (one draw from `rng` per quad),
/// then every triangle (a, b, c) into three quads around its centroid g,
/// (a, m_ab, g, m_ca), (b, m_bc, g, m_ab), (c, m_ca, g, m_bc), with m_xy the midpoint of
/// edge xy, shared by the triangles on both sides. The result keeps `mesh`'s vertices
/// (first, same indices) and orientation, adds one vertex per edge of the triangle mesh
/// and one per triangle, and has six quads per quad of `mesh`: kites, with a valence-3
/// vertex at every centroid, valence 4 at interior midpoints, and the triangle mesh's
/// valence (6 on average inside) at its corners, where the ground truth of a converted
/// triangle mesh differs most from a remeshed one.
pub fn triangle_split(mesh: &QuadMesh, rng: &mut Rng) -> QuadMesh {
    let mut vertices = mesh.vertices.clone();
    let mut mids: std::collections::HashMap<(u32, u32), u32> = std::collections::HashMap::new();
    let mut quads = Vec::with_capacity(6 * mesh.quads.len());
    let avg = |p: &[[f64; 3]]| -> [f64; 3] {
        let k = p.len() as f64;
        std::array::from_fn(|d| p.iter().map(|v| v[d]).sum::<f64>() / k)
    };
    for q in &mesh.quads {
        let tris = if rng.below(2) == 0 {
            [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]
        } else {
            [[q[1], q[2], q[3]], [q[1], q[3], q[0]]]
        };
        for [a, b, c] in tris {
            let mut mid = |x: u32, y: u32, vertices: &mut Vec<[f64; 3]>| -> u32 {
                *mids.entry((x.min(y), x.max(y))).or_insert_with(|| {
                    vertices.push(avg(&[vertices[x as usize], vertices[y as usize]]));
                    (vertices.len() - 1) as u32
                })
            };
            let (ab, bc, ca) = (mid(a, b, &mut vertices), mid(b, c, &mut vertices), mid(c, a, &mut vertices));
            vertices.push(avg(&[vertices[a as usize], vertices[b as usize], vertices[c as usize]]));
            let g = (vertices.len() - 1) as u32;
            quads.extend([[a, ab, g, ca], [b, bc, g, ab], [c, ca, g, bc]]);
        }
    }
    QuadMesh { vertices, quads }
}

/// An irregular copy of `mesh`: every vertex, in index order, moves within its tangent
/// plane (normal: the sum of its quads' diagonal cross products) by a random offset drawn
/// uniformly from the disk of radius `amount` × its shortest incident edge (as it was
/// before any move). A move is kept only if every quad at that vertex keeps a scaled
/// Jacobian of at least `min(min_sj, its scaled Jacobian before the move)`; otherwise the
/// vertex stays. Connectivity is unchanged, so the result is as manifold and as
/// consistently oriented as `mesh`, with faces that are no longer rectangles.
///
/// Real quad meshes of organic shapes (remeshed scans) have faces with scaled Jacobians
/// of 0.8–0.95 and uneven corners, where the parametric families are nearly square. (As
/// training data it did not pay: session 7 measured it in docs/EXPERIMENTS.md, "Training experiments".
/// It stays as a test-shape utility.)
/// Two draws from `rng` per vertex whatever is kept, so the stream does not depend on
/// the geometry. Vertices without a face or a tangent plane stay.
pub fn irregularize(mesh: &QuadMesh, amount: f64, min_sj: f64, rng: &mut Rng) -> QuadMesh {
    let n = mesh.vertices.len();
    let normal = vertex_normal_sums(mesh);
    let mut incident: Vec<Vec<usize>> = vec![Vec::new(); n];
    let mut shortest = vec![f64::INFINITY; n];
    for (f, q) in mesh.quads.iter().enumerate() {
        let p = q.map(|i| mesh.vertices[i as usize]);
        for k in 0..4 {
            let (a, b) = (q[k] as usize, q[(k + 1) % 4] as usize);
            let l = norm(sub(p[(k + 1) % 4], p[k]));
            shortest[a] = shortest[a].min(l);
            shortest[b] = shortest[b].min(l);
            incident[a].push(f);
        }
    }
    let sj_of = |verts: &[[f64; 3]], f: usize| quad_sj(verts, &mesh.quads[f]);
    let mut out = mesh.clone();
    for v in 0..n {
        let (angle, radius) = (rng.uniform(0.0, std::f64::consts::TAU), rng.f64().sqrt());
        let Some(nz) = crate::math::normalize(normal[v]) else { continue };
        if incident[v].is_empty() || !shortest[v].is_finite() {
            continue;
        }
        let helper = if nz[0].abs() < 0.9 { [1.0, 0.0, 0.0] } else { [0.0, 1.0, 0.0] };
        let Some(t1) = crate::math::normalize(cross(nz, helper)) else { continue };
        let t2 = cross(nz, t1);
        let r = amount * shortest[v] * radius;
        let step = add(scale(t1, r * angle.cos()), scale(t2, r * angle.sin()));
        let before: Vec<f64> = incident[v].iter().map(|&f| sj_of(&out.vertices, f)).collect();
        let old = out.vertices[v];
        out.vertices[v] = add(old, step);
        let ok = incident[v].iter().zip(&before).all(|(&f, &sj0)| sj_of(&out.vertices, f) >= min_sj.min(sj0));
        if !ok {
            out.vertices[v] = old;
        }
    }
    out
}

/// A bumpy copy of `mesh`: every vertex moves along its normal (the sum of its quads'
/// diagonal cross products) by h(v) = Σ_k a_k·sin(w_k·v + φ_k) over `waves` plane waves in
/// random directions, with wavelengths of U(`wavelength.0`, `wavelength.1`) mean edge
/// lengths and amplitudes of U(0, `amplitude`) mean edge lengths over √waves. Surfaces then
/// bend by tens of degrees from one face to the next, as coarse meshes of organic shapes
/// (a cat in a thousand faces) do, where the parametric families bend by a few degrees.
/// If a face's scaled Jacobian would fall below `min(min_sj, its value before)`, the
/// amplitudes are halved and the whole displacement is tried again (at most 6 times;
/// then `mesh` is returned unchanged). Connectivity is unchanged.
pub fn add_bumps(
    mesh: &QuadMesh,
    waves: usize,
    wavelength: (f64, f64),
    amplitude: f64,
    min_sj: f64,
    rng: &mut Rng,
) -> QuadMesh {
    let normal = vertex_normal_sums(mesh);
    let (mut total, mut count) = (0.0f64, 0usize);
    for q in &mesh.quads {
        let p = q.map(|i| mesh.vertices[i as usize]);
        for k in 0..4 {
            total += norm(sub(p[(k + 1) % 4], p[k]));
            count += 1;
        }
    }
    let edge = if count > 0 { total / count as f64 } else { 0.0 };
    let waves = waves.max(1);
    let params: Vec<([f64; 3], f64, f64)> = (0..waves)
        .map(|_| {
            let r = rng.rotation();
            let lambda = rng.uniform(wavelength.0, wavelength.1) * edge;
            let k = if lambda > 0.0 { std::f64::consts::TAU / lambda } else { 0.0 };
            let a = rng.uniform(0.0, amplitude) * edge / (waves as f64).sqrt();
            (scale(r[0], k), rng.uniform(0.0, std::f64::consts::TAU), a)
        })
        .collect();
    let before: Vec<f64> = mesh.quads.iter().map(|q| quad_sj(&mesh.vertices, q)).collect();
    let mut factor = 1.0;
    for _ in 0..6 {
        let mut out = mesh.clone();
        for (v, p) in out.vertices.iter_mut().enumerate() {
            let Some(nv) = crate::math::normalize(normal[v]) else { continue };
            let h: f64 = params.iter().map(|(w, phi, a)| a * (dot(*w, *p) + phi).sin()).sum();
            *p = add(*p, scale(nv, factor * h));
        }
        if out.quads.iter().zip(&before).all(|(q, &s0)| quad_sj(&out.vertices, q) >= min_sj.min(s0)) {
            return out;
        }
        factor *= 0.5;
    }
    mesh.clone()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn euler(m: &QuadMesh) -> i64 {
        let e = EdgeTable::new(m);
        m.vertices.len() as i64 - e.ends.len() as i64 + m.quads.len() as i64
    }

    #[test]
    fn counts_of_simple_shapes() {
        let g = grid(3, 2, 1.0, 1.0);
        assert_eq!((g.vertices.len(), g.quads.len(), euler(&g)), (12, 6, 1));
        let c = cube(2);
        assert_eq!((c.vertices.len(), c.quads.len(), euler(&c)), (26, 24, 2));
        let t = torus(5, 4, 2.0, 0.5);
        assert_eq!((t.vertices.len(), euler(&t)), (20, 0));
        let cy = cylinder(8, 3, 1.0, 2.0, true);
        assert_eq!(euler(&cy), 2);
        assert_eq!(euler(&cylinder(7, 3, 1.0, 2.0, false)), 0);
    }

    #[test]
    fn single_voxel_and_ring() {
        let mut s = VoxelSet::new([1, 1, 1]);
        s.set([0, 0, 0]);
        let m = voxel_boundary(&s);
        assert_eq!((m.vertices.len(), m.quads.len(), euler(&m)), (8, 6, 2));
        let mut r = VoxelSet::new([3, 3, 1]);
        for x in 0..3 {
            for y in 0..3 {
                if (x, y) != (1, 1) {
                    r.set([x, y, 0]);
                }
            }
        }
        assert_eq!(repair_voxels(&mut r), 0);
        assert_eq!(euler(&voxel_boundary(&r)), 0);
    }

    #[test]
    fn diagonal_voxels_get_repaired() {
        let mut s = VoxelSet::new([2, 2, 2]);
        s.set([0, 0, 0]);
        s.set([1, 1, 0]);
        assert!(repair_voxels(&mut s) >= 1);
        let mut c = VoxelSet::new([2, 2, 2]);
        c.set([0, 0, 0]);
        c.set([1, 1, 1]);
        assert!(repair_voxels(&mut c) >= 1);
        assert!(c.first_defect().is_none());
    }
}
