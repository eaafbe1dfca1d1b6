//! The primitive soup the native and brute backends test rays against.

use super::Hit;
use crate::geometry::{intersect_sphere, intersect_triangle, Aabb, RayTransform};
use crate::scene::{MeshFetch, Shape};
use glam::Vec3;
use rayon::prelude::*;

/// Sphere primitives are flagged in the top bit of `Prim::geom_id`.
const SPHERE_FLAG: u32 = 1 << 31;

/// One primitive, self-contained so a leaf touches one cache line per primitive.
/// Triangles store their three vertices; spheres store the centre in `v[0]`
/// and the radius in `v[1].x`.
#[derive(Clone, Copy, Debug)]
pub struct Prim {
    pub v: [Vec3; 3],
    geom_id: u32,
    pub prim_id: u32,
}

impl Prim {
    #[inline]
    pub fn geom_id(&self) -> u32 {
        self.geom_id & !SPHERE_FLAG
    }

    #[inline]
    pub fn is_sphere(&self) -> bool {
        self.geom_id & SPHERE_FLAG != 0
    }

    pub fn bounds(&self) -> Aabb {
        if self.is_sphere() {
            let r = Vec3::splat(self.v[1].x);
            Aabb { min: self.v[0] - r, max: self.v[0] + r }
        } else {
            let mut b = Aabb::from_point(self.v[0]);
            b.grow(self.v[1]);
            b.grow(self.v[2]);
            b
        }
    }

    /// `(t, u, v)` for a hit with `tmin < t <= tmax`.
    #[inline]
    pub fn intersect(&self, rt: &RayTransform, dir: Vec3, tmin: f32, tmax: f32) -> Option<(f32, f32, f32)> {
        if self.is_sphere() {
            if self.v[1].x <= 0.0 {
                return None;
            }
            intersect_sphere(rt.origin, dir, self.v[0], self.v[1].x, tmin, tmax).map(|t| (t, 0.0, 0.0))
        } else {
            intersect_triangle(rt, self.v[0], self.v[1], self.v[2], tmin, tmax)
        }
    }

    #[inline]
    pub fn hit(&self, t: f32, u: f32, v: f32) -> Hit {
        Hit { t, u, v, geom_id: self.geom_id(), prim_id: self.prim_id }
    }
}

/// The scene's primitives in shape order, made on demand from the shapes
/// instead of copied: the native build reads each primitive only twice
/// (its bounds, then its leaf), and a copy of a 1M-triangle scene was 44 MB
/// of fresh memory to fault in and fill, 5-10 % of the build.
pub struct PrimTable<'a> {
    shapes: &'a [Shape],
    /// `starts[g]`: index of shape `g`'s first primitive; last, the total.
    starts: Vec<u32>,
}

impl<'a> PrimTable<'a> {
    pub fn new(shapes: &'a [Shape]) -> Self {
        let mut starts = Vec::with_capacity(shapes.len() + 1);
        let mut n = 0u64;
        for s in shapes {
            starts.push(n as u32);
            n += if let Shape::Mesh(m) = s { m.triangles.len() as u64 } else { 1 };
        }
        assert!(n < u32::MAX as u64, "more than 2^32 primitives");
        starts.push(n as u32);
        PrimTable { shapes, starts }
    }

    pub fn len(&self) -> usize {
        *self.starts.last().unwrap() as usize
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Primitive `i`.
    #[inline]
    pub fn get(&self, i: u32) -> Prim {
        let g = self.shape_of(i);
        self.of_shape(g, i - self.starts[g])
    }

    /// Start loading primitive `i` ahead of `get`: its vertex indices, or
    /// with `vertices` (once the indices are near) its three vertices.
    #[inline]
    pub fn prefetch(&self, i: u32, vertices: bool) {
        let g = self.shape_of(i);
        if let Shape::Mesh(m) = &self.shapes[g] {
            m.prefetch((i - self.starts[g]) as usize, if vertices { MeshFetch::Positions } else { MeshFetch::Indices });
        }
    }

    /// Whether primitive `i` is a sphere.
    #[inline]
    pub fn is_sphere(&self, i: u32) -> bool {
        matches!(self.shapes[self.shape_of(i)], Shape::Sphere { .. })
    }

    /// The shape primitive `i` belongs to.
    #[inline]
    fn shape_of(&self, i: u32) -> usize {
        self.starts.partition_point(|&s| s <= i) - 1
    }

    /// Primitive `j` of shape `g`.
    #[inline]
    fn of_shape(&self, g: usize, j: u32) -> Prim {
        match &self.shapes[g] {
            Shape::Mesh(m) => {
                let t = m.triangles[j as usize];
                Prim { v: t.map(|k| m.positions[k as usize]), geom_id: g as u32, prim_id: j }
            }
            Shape::Sphere { center, radius } => Prim { v: [*center, Vec3::new(*radius, 0.0, 0.0), Vec3::ZERO], geom_id: g as u32 | SPHERE_FLAG, prim_id: 0 },
        }
    }

    /// The triangles in runs of at most `chunk` within each mesh, in
    /// order, as (first primitive, count, summed area); spheres have no
    /// runs, and degenerate or non-finite triangles count no area. Read from
    /// the meshes' own arrays, runs in parallel (each summed in order: the
    /// same sums at any thread count): primitive by primitive through
    /// `get`, a 5M-triangle scene took 70 ms on 2 threads, this way 10.
    pub fn area_runs(&self, chunk: usize) -> Vec<(u32, u32, f64)> {
        // The runs listed first, then summed in one parallel pass: a scene
        // of many small meshes is not a parallel pass per mesh.
        let mut runs: Vec<(usize, usize)> = Vec::new();
        for (g, shape) in self.shapes.iter().enumerate() {
            if let Shape::Mesh(m) = shape {
                runs.extend((0..m.triangles.len()).step_by(chunk).map(|first| (g, first)));
            }
        }
        runs.par_iter()
            .map(|&(g, first)| {
                let Shape::Mesh(m) = &self.shapes[g] else { unreachable!("runs are listed from meshes") };
                let tris = &m.triangles[first..(first + chunk).min(m.triangles.len())];
                let area = tris.iter().map(|t| triangle_area(t.map(|k| m.positions[k as usize]))).sum();
                (self.starts[g] + first as u32, tris.len() as u32, area)
            })
            .collect()
    }

    /// `f(i, primitive i)` for every primitive, in parallel, collected in order.
    pub fn par_map<T: Send>(&self, out: &mut Vec<T>, f: impl Fn(u32, Prim) -> T + Sync + Send) {
        for g in 0..self.shapes.len() {
            let (start, end) = (self.starts[g], self.starts[g + 1]);
            out.par_extend((0..end - start).into_par_iter().map(|j| f(start + j, self.of_shape(g, j))));
        }
    }
}

/// A triangle's area; none for a degenerate or non-finite one.
#[inline]
pub fn triangle_area([a, b, c]: [Vec3; 3]) -> f64 {
    let area = 0.5 * (b - a).cross(c - a).length() as f64;
    if area.is_finite() {
        area
    } else {
        0.0
    }
}

/// Every primitive of every shape, in shape order.
pub fn collect(shapes: &[Shape]) -> Vec<Prim> {
    let table = PrimTable::new(shapes);
    let mut out = Vec::with_capacity(table.len());
    table.par_map(&mut out, |_, p| p);
    out
}

/// Keep `best` the closest hit, breaking exact ties towards the lower id.
#[inline]
pub fn closer(candidate: Hit, best: &Option<Hit>) -> bool {
    match best {
        None => true,
        Some(b) => candidate.t < b.t || (candidate.t == b.t && candidate.key() < b.key()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::TriangleMesh;

    fn mesh(n: usize, seed: u64) -> Shape {
        let mut rng = crate::rng::Rng::new(seed, 3);
        let positions: Vec<Vec3> = (0..n * 3).map(|_| Vec3::new(rng.uniform(), rng.uniform(), rng.uniform())).collect();
        let triangles = (0..n as u32).map(|t| [3 * t, 3 * t + 1, 3 * t + 2]).collect();
        Shape::Mesh(TriangleMesh { positions, triangles, normals: Vec::new() })
    }

    /// The runs cover every triangle once, in order, none across two
    /// meshes or over a sphere, each with its triangles' summed area; the
    /// same at 1 and 3 threads.
    #[test]
    fn area_runs_sum_each_meshs_triangles_in_order() {
        let shapes = vec![mesh(300, 1), Shape::Sphere { center: Vec3::ZERO, radius: 1.0 }, mesh(5, 2), mesh(0, 3), mesh(128, 4)];
        let prims = PrimTable::new(&shapes);
        let runs = |threads: usize| rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap().install(|| prims.area_runs(128));
        let got = runs(1);
        let spans: Vec<(u32, u32)> = got.iter().map(|r| (r.0, r.1)).collect();
        assert_eq!(spans, [(0, 128), (128, 128), (256, 44), (301, 5), (306, 128)]);
        for &(first, count, area) in &got {
            let want: f64 = (first..first + count).map(|i| triangle_area(prims.get(i).v)).sum();
            assert_eq!(area, want, "run at {first}");
        }
        assert_eq!(got, runs(3));
    }
}
