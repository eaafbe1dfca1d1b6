//! Generated scenes: deterministic geometry that stresses what separates
//! BVH builders, at any size. Each is named `KIND:N` (N triangles, `k`/`M`
//! suffixes allowed) — on the `bench` command line and as a scene argument
//! of the renderer (`pathtracer arch:1M`) — and gets the OBJ/PLY defaults
//! of `scene::mesh_scene` (diffuse 0.5, sky light) with a camera direction
//! chosen to look at the interesting part. `subdiv:NAME:N` refines a scene
//! file found by name; the caller says where names are looked up.
//!
//! * `sphere:N` — a lat-long unit sphere: evenly sized, well-shaped
//!   triangles, the easiest input there is (the poles are degenerate, as in
//!   Embree's measurements).
//! * `arch:N` — architecture: a 240 m ground plane and floor slabs of two
//!   triangles each crossing everything, walls as long thin strips
//!   (500:1), columns as tall thin slivers, tessellated arches and vaults,
//!   and the rest (above the structure's ~80k triangles) in millimetre-to-centimetre
//!   ornaments on the facades — triangle sizes over five orders of magnitude, large ones
//!   overlapping many small ones (what spatial splits are for).
//! * `grass:N` — thin strands: blades 2–6 mm wide and 0.2–0.8 m long,
//!   leaning up to 60° in random directions and curving, 6 triangles each,
//!   on a 20 m field. Long diagonal slivers: their boxes are mostly empty.
//! * `stadium:N` — the teapot in a stadium: a 400 m bowl of tiers, stands
//!   and a roof ring in large triangles (about 20k), and nearly all N
//!   triangles in a bumpy 0.5 m object at the centre (on 500 m of ground). Rays that miss the
//!   small object cross a huge sparse tree.
//! * `subdiv:NAME:N` — a CS184 scan (bunny, maxplanck, cow, ...) refined by
//!   Loop subdivision (smooth, as a denser scan would be) until it has at
//!   least N triangles: the scanned-mesh case at millions of triangles.

use crate::error::{Error, Result};
use crate::rng::Rng;
use crate::scene::mesh_scene::{self, NamedMesh};
use crate::scene::{Scene, TriangleMesh};
use glam::Vec3;
use std::collections::HashMap;
use std::f32::consts::{PI, TAU};
use std::path::PathBuf;

/// Where `subdiv:NAME:N` finds the scene file `NAME` names.
pub type FindScene<'a> = &'a dyn Fn(&str) -> Result<PathBuf>;

/// The kinds, for `--help` and error messages.
pub const KINDS: &str = "sphere:N, arch:N, grass:N, stadium:N, subdiv:NAME:N";

/// The scene names a generator spec reads (`subdiv:NAME:N` reads `NAME`,
/// the other generators nothing), or `None` when `spec` is not a
/// generator's (a file name).
pub fn inputs(spec: &str) -> Option<Vec<&str>> {
    let (kind, rest) = spec.split_once(':')?;
    match kind {
        "sphere" | "arch" | "grass" | "stadium" => Some(Vec::new()),
        "subdiv" => Some(rest.rsplit_once(':').map(|(name, _)| name).into_iter().collect()),
        _ => None,
    }
}

/// A generator spec's scene, or `None` when `spec` is not one (a file name);
/// `find` resolves the scene names `subdiv:NAME:N` refines.
pub fn generate(spec: &str, find: FindScene) -> Option<Result<Scene>> {
    let (kind, rest) = spec.split_once(':')?;
    let run = |n: Result<usize>, f: fn(usize) -> Vec<NamedMesh>, c_dir: Vec3| -> Result<Scene> {
        let n = n?;
        let mut s = mesh_scene::from_meshes(&spec.replace(':', "_"), &format!("<generated {spec}>"), f(n))?;
        s.camera.c_dir = c_dir.normalize();
        Ok(s)
    };
    Some(match kind {
        "sphere" => run(count(spec, rest), |n| vec![named("sphere", sphere(n))], Vec3::Z),
        "arch" => run(count(spec, rest), arch, Vec3::new(0.5, 0.15, 1.0)),
        "grass" => run(count(spec, rest), |n| vec![named("grass", grass(n))], Vec3::new(0.0, 0.25, 1.0)),
        "stadium" => run(count(spec, rest), stadium, Vec3::new(0.3, 0.5, 1.0)),
        "subdiv" => subdiv_scene(spec, rest, find),
        _ => return None,
    })
}

/// `N`, `Nk` or `NM` as a triangle count between 8 and 2e8.
fn count(spec: &str, n: &str) -> Result<usize> {
    let (digits, scale) = match n.chars().last() {
        Some('k' | 'K') => (&n[..n.len() - 1], 1e3),
        Some('m' | 'M') => (&n[..n.len() - 1], 1e6),
        _ => (n, 1.0),
    };
    let v: f64 = digits.parse().map_err(|_| Error::new(format!("{spec}: expected a triangle count such as 500k or 2M (generators: {KINDS})")))?;
    let v = v * scale;
    if !(8.0..=2.0e8).contains(&v) {
        crate::bail!("{spec}: triangle count must be between 8 and 2e8");
    }
    Ok(v as usize)
}

fn named(name: &str, mesh: TriangleMesh) -> NamedMesh {
    NamedMesh { name: name.to_string(), mesh }
}

/// Triangles appended to one mesh.
#[derive(Default)]
struct Builder {
    m: TriangleMesh,
}

impl Builder {
    fn vertex(&mut self, p: Vec3) -> u32 {
        self.m.positions.push(p);
        (self.m.positions.len() - 1) as u32
    }
    fn quad(&mut self, a: Vec3, b: Vec3, c: Vec3, d: Vec3) {
        let i = self.vertex(a);
        for p in [b, c, d] {
            self.vertex(p);
        }
        self.m.triangles.push([i, i + 1, i + 2]);
        self.m.triangles.push([i, i + 2, i + 3]);
    }
    /// An axis-aligned box, 12 triangles.
    fn cuboid(&mut self, lo: Vec3, hi: Vec3) {
        let c = |x: bool, y: bool, z: bool| Vec3::new(if x { hi.x } else { lo.x }, if y { hi.y } else { lo.y }, if z { hi.z } else { lo.z });
        let (f, t) = (false, true);
        self.quad(c(f, f, f), c(f, t, f), c(t, t, f), c(t, f, f));
        self.quad(c(f, f, t), c(t, f, t), c(t, t, t), c(f, t, t));
        self.quad(c(f, f, f), c(f, f, t), c(f, t, t), c(f, t, f));
        self.quad(c(t, f, f), c(t, t, f), c(t, t, t), c(t, f, t));
        self.quad(c(f, f, f), c(t, f, f), c(t, f, t), c(f, f, t));
        self.quad(c(f, t, f), c(f, t, t), c(t, t, t), c(t, t, f));
    }
    /// A grid surface `f(u, v)`, u in [0,1] with `nu` cells, v likewise:
    /// 2·nu·nv triangles sharing vertices.
    fn grid(&mut self, nu: u32, nv: u32, f: impl Fn(f32, f32) -> Vec3) {
        let base = self.m.positions.len() as u32;
        for j in 0..=nv {
            for i in 0..=nu {
                self.m.positions.push(f(i as f32 / nu as f32, j as f32 / nv as f32));
            }
        }
        let row = nu + 1;
        for j in 0..nv {
            for i in 0..nu {
                let (a, b, c, d) = (base + j * row + i, base + j * row + i + 1, base + (j + 1) * row + i, base + (j + 1) * row + i + 1);
                self.m.triangles.push([a, b, d]);
                self.m.triangles.push([a, d, c]);
            }
        }
    }
    fn len(&self) -> usize {
        self.m.triangles.len()
    }
}

/// A lat-long unit sphere of about `n` triangles (2 · segments · rings).
pub fn sphere(n: usize) -> TriangleMesh {
    let rings = ((n as f64 / 4.0).sqrt().max(2.0)) as u32;
    lat_long_sphere(2 * rings, rings)
}

/// A sphere-like blob of radius about `r` at `c` with `n` triangles (a
/// grid over longitude/latitude), its surface displaced by `bumps`.
fn blob(b: &mut Builder, c: Vec3, r: f32, n: usize, bumps: f32) {
    let rings = ((n as f64 / 4.0).sqrt().max(2.0)) as u32;
    b.grid(2 * rings, rings, |u, v| {
        let (phi, th) = (TAU * u, PI * v);
        let d = Vec3::new(th.sin() * phi.cos(), th.cos(), th.sin() * phi.sin());
        let bump = 1.0 + bumps * ((7.0 * phi).sin() * (5.0 * th).sin() + 0.5 * (17.0 * phi + 3.0).sin() * (13.0 * th).cos());
        c + d * (r * bump)
    });
}

fn arch(n: usize) -> Vec<NamedMesh> {
    let mut rng = Rng::new(0xA4C, 1);
    let mut big = Builder::default();
    // Ground: a 240 m square, two triangles under everything.
    big.quad(Vec3::new(-120.0, 0.0, -120.0), Vec3::new(-120.0, 0.0, 120.0), Vec3::new(120.0, 0.0, 120.0), Vec3::new(120.0, 0.0, -120.0));
    // A 100 m x 60 m building of 6 storeys of 5 m: slabs are two triangles
    // each; walls are 0.2 m thick strips (top/bottom edges 100 m x 0.2 m).
    let (w, d, storey, floors) = (50.0f32, 30.0f32, 5.0f32, 6);
    for f in 0..=floors {
        let y = f as f32 * storey;
        big.quad(Vec3::new(-w, y, -d), Vec3::new(-w, y, d), Vec3::new(w, y, d), Vec3::new(w, y, -d));
        big.quad(Vec3::new(-w, y + 0.3, -d), Vec3::new(w, y + 0.3, -d), Vec3::new(w, y + 0.3, d), Vec3::new(-w, y + 0.3, d));
        if f < floors {
            // Back and side walls as thin boxes; the front is an arcade.
            big.cuboid(Vec3::new(-w, y, -d), Vec3::new(w, y + storey, -d + 0.2));
            big.cuboid(Vec3::new(-w, y, -d), Vec3::new(-w + 0.2, y + storey, d));
            big.cuboid(Vec3::new(w - 0.2, y, -d), Vec3::new(w, y + storey, d));
            // Interior partitions: long thin walls every 10 m.
            for k in 1..5 {
                let z = -d + k as f32 * 12.0;
                big.cuboid(Vec3::new(-w + 0.2, y + 0.3, z), Vec3::new(w - 0.2, y + storey, z + 0.1));
            }
        }
    }
    let mut columns = Builder::default();
    // Front arcade: columns (32 segments, one tall ring: 5 m x 8 cm slivers)
    // and semicircular arches between them, on every storey.
    let (span, radius) = (5.0f32, 0.4f32);
    let cols = (2.0 * w / span) as i32;
    for f in 0..floors {
        let y = f as f32 * storey + 0.3;
        for k in 0..=cols {
            let x = -w + k as f32 * span;
            let c = Vec3::new(x, y, d - 1.0);
            columns.grid(32, 1, |u, v| c + Vec3::new(radius * (TAU * u).cos(), v * (storey - 1.5), radius * (TAU * u).sin()));
            if k < cols {
                // The arch: a half annulus band (48 x 2 cells) whose crown
                // meets the vault, and its soffit.
                let centre = Vec3::new(x + span / 2.0, y + storey - 1.5 - span / 2.0, d - 1.0);
                columns.grid(48, 2, |u, v| {
                    let (a, r) = (PI * u, span / 2.0 - v * 0.5);
                    centre + Vec3::new(-r * a.cos(), r * a.sin(), 0.4)
                });
                columns.grid(48, 1, |u, v| {
                    let (a, r) = (PI * u, span / 2.0 - 0.5);
                    centre + Vec3::new(-r * a.cos(), r * a.sin(), 0.4 - 0.8 * v)
                });
            }
        }
        // A barrel vault over the arcade walk.
        let y0 = y + storey - 1.5;
        columns.grid(200, 16, |u, v| Vec3::new(-w + 2.0 * w * u, y0 + 0.6 * (PI * v).sin(), d - 1.4 + 1.2 * v));
    }
    // Fine detail: the rest of the budget as ornaments on the facade and the
    // slab edges — small bumpy rosettes (0.4-4.4 cm) and balusters (thin boxes).
    let mut detail = Builder::default();
    let budget = n.saturating_sub(big.len() + columns.len());
    while detail.len() + 12 <= budget {
        let f = (rng.uniform() * floors as f32).floor();
        let y = f * storey + 0.3 + rng.uniform() * (storey - 0.4);
        let x = -w + 2.0 * w * rng.uniform();
        let z = d - 0.6 + 0.05 * rng.uniform();
        if rng.uniform() < 0.5 {
            let r = 0.004 + 0.04 * rng.uniform();
            let tris = (budget - detail.len()).min(64 + (rng.uniform() * 192.0) as usize);
            blob(&mut detail, Vec3::new(x, y, z), r, tris, 0.15);
        } else {
            // A baluster: 2 cm square, 10-60 cm tall, standing on a slab edge.
            let h = 0.1 + 0.5 * rng.uniform();
            let y = f * storey + 0.3;
            detail.cuboid(Vec3::new(x, y, d - 0.3), Vec3::new(x + 0.02, y + h, d - 0.28));
        }
    }
    vec![named("structure", big.m), named("arcade", columns.m), named("ornaments", detail.m)]
}

fn grass(n: usize) -> TriangleMesh {
    let mut rng = Rng::new(0x6A55, 2);
    let mut b = Builder::default();
    b.quad(Vec3::new(-10.0, 0.0, -10.0), Vec3::new(-10.0, 0.0, 10.0), Vec3::new(10.0, 0.0, 10.0), Vec3::new(10.0, 0.0, -10.0));
    const SEGMENTS: u32 = 3; // 2 triangles per segment
    while b.len() + 2 * SEGMENTS as usize <= n {
        let root = Vec3::new(20.0 * rng.uniform() - 10.0, 0.0, 20.0 * rng.uniform() - 10.0);
        let height = 0.2 + 0.6 * rng.uniform();
        let width = 0.002 + 0.004 * rng.uniform();
        let lean = (PI / 3.0) * rng.uniform();
        let azimuth = TAU * rng.uniform();
        let curl = 0.5 * rng.uniform();
        let facing = TAU * rng.uniform();
        let dir = Vec3::new(azimuth.cos(), 0.0, azimuth.sin());
        let side = Vec3::new(facing.cos(), 0.0, facing.sin()) * width;
        // The blade's spine leans and bends further towards `dir`; it
        // tapers to a point.
        let spine = |t: f32| {
            let a = lean + curl * t;
            root + (dir * a.sin() * t + Vec3::Y * a.cos() * t) * height
        };
        b.grid(1, SEGMENTS, |u, v| spine(v) + side * ((u - 0.5) * (1.0 - 0.9 * v)));
    }
    b.m
}

fn stadium(n: usize) -> Vec<NamedMesh> {
    let mut s = Builder::default();
    // Pitch and surroundings: 500 m of ground.
    s.quad(Vec3::new(-250.0, 0.0, -250.0), Vec3::new(-250.0, 0.0, 250.0), Vec3::new(250.0, 0.0, 250.0), Vec3::new(250.0, 0.0, -250.0));
    // The bowl: 40 tiers of steps between radius 80 and 200 m, 128 segments
    // around, each step a riser and a tread (large, thin-ish quads).
    let (tiers, around) = (40u32, 128u32);
    for t in 0..tiers {
        let r0 = 80.0 + 3.0 * t as f32;
        let (y0, y1) = (1.2 * t as f32, 1.2 * (t + 1) as f32);
        s.grid(around, 1, |u, v| Vec3::new(r0 * (TAU * u).cos(), y0 + v * (y1 - y0), r0 * (TAU * u).sin()));
        s.grid(around, 1, |u, v| {
            let r = r0 + 3.0 * v;
            Vec3::new(r * (TAU * u).cos(), y1, r * (TAU * u).sin())
        });
    }
    // Outer wall and a roof ring on 64 thin pylons.
    let top = 1.2 * tiers as f32;
    s.grid(around, 4, |u, v| Vec3::new(200.0 * (TAU * u).cos(), v * (top + 20.0), 200.0 * (TAU * u).sin()));
    s.grid(around, 2, |u, v| {
        let r = 200.0 - 70.0 * v;
        Vec3::new(r * (TAU * u).cos(), top + 20.0 + 5.0 * v, r * (TAU * u).sin())
    });
    for k in 0..64 {
        let a = TAU * k as f32 / 64.0;
        let c = Vec3::new(135.0 * a.cos(), 0.0, 135.0 * a.sin());
        s.grid(8, 1, |u, v| c + Vec3::new(0.5 * (TAU * u).cos(), v * (top + 25.0), 0.5 * (TAU * u).sin()));
    }
    let mut teapot = Builder::default();
    blob(&mut teapot, Vec3::new(0.0, 0.3, 0.0), 0.25, n.saturating_sub(s.len()).max(8), 0.08);
    vec![named("stadium", s.m), named("teapot", teapot.m)]
}

fn subdiv_scene(spec: &str, rest: &str, find: FindScene) -> Result<Scene> {
    let (name, n) = rest.rsplit_once(':').ok_or_else(|| Error::new(format!("{spec}: expected subdiv:NAME:N, e.g. subdiv:bunny:2M")))?;
    let n = count(spec, n)?;
    let base = crate::scene::load_file(&find(name)?)?;
    let mut meshes: Vec<NamedMesh> = base
        .shapes
        .iter()
        .zip(&base.objects)
        .filter_map(|(s, o)| match s {
            crate::scene::Shape::Mesh(m) => Some(NamedMesh { name: o.name.clone(), mesh: TriangleMesh { positions: m.positions.clone(), triangles: m.triangles.clone(), normals: Vec::new() } }),
            _ => None,
        })
        .collect();
    // Refine the largest mesh (the scan) until the scene has n triangles.
    let largest = (0..meshes.len()).max_by_key(|&i| meshes[i].mesh.triangles.len()).ok_or_else(|| Error::new(format!("{spec}: '{name}' has no meshes")))?;
    let total = |ms: &[NamedMesh]| ms.iter().map(|m| m.mesh.triangles.len()).sum::<usize>();
    while total(&meshes) < n {
        meshes[largest].mesh = loop_subdivide(&meshes[largest].mesh);
    }
    let mut s = mesh_scene::from_meshes(&spec.replace(':', "_"), &format!("<generated {spec}>"), meshes)?;
    s.camera = base.camera;
    s.lights = base.lights;
    s.materials = base.materials;
    let objects = base.objects.iter().zip(&base.shapes).filter(|(_, s)| matches!(s, crate::scene::Shape::Mesh(_))).map(|(o, _)| o.clone());
    s.objects = objects.collect();
    Ok(s)
}

/// One step of Loop subdivision (each triangle into four): edge points at
/// 3/8 of their endpoints + 1/8 of the two opposite vertices, old vertices
/// moved to (1 − nβ)v + βΣ neighbours (Warren's β). Boundary and
/// non-manifold edges take plain midpoints and their vertices stay put, so
/// holes in a scan are kept, not closed.
pub fn loop_subdivide(m: &TriangleMesh) -> TriangleMesh {
    let nv = m.positions.len();
    // Each undirected edge, numbered in the order the triangles first use
    // it: its endpoints, the (up to two) opposite vertices and its uses;
    // its new vertex is `nv` + its number. The map only finds an edge's
    // number: iterating it would visit the edges in an order that differs
    // between runs, and the neighbour sums below would round differently.
    let mut number: HashMap<(u32, u32), u32> = HashMap::with_capacity(m.triangles.len() * 3 / 2 + 16);
    let mut edges: Vec<((u32, u32), [u32; 2], u8)> = Vec::with_capacity(m.triangles.len() * 3 / 2 + 16);
    for t in &m.triangles {
        for k in 0..3 {
            let (a, b, c) = (t[k], t[(k + 1) % 3], t[(k + 2) % 3]);
            let key = (a.min(b), a.max(b));
            let j = *number.entry(key).or_insert_with(|| {
                edges.push((key, [u32::MAX; 2], 0));
                (edges.len() - 1) as u32
            });
            let e = &mut edges[j as usize];
            if (e.2 as usize) < 2 {
                e.1[e.2 as usize] = c;
            }
            e.2 = e.2.saturating_add(1);
        }
    }
    let p = &m.positions;
    let mut out = vec![Vec3::ZERO; nv + edges.len()];
    let mut neighbours = vec![Vec3::ZERO; nv];
    let mut valence = vec![0u32; nv];
    let mut boundary = vec![false; nv];
    for (e, &((a, b), opp, uses)) in edges.iter().enumerate() {
        let i = (nv + e) as u32;
        let (pa, pb) = (p[a as usize], p[b as usize]);
        out[i as usize] = if uses == 2 { 0.375 * (pa + pb) + 0.125 * (p[opp[0] as usize] + p[opp[1] as usize]) } else { 0.5 * (pa + pb) };
        if uses != 2 {
            boundary[a as usize] = true;
            boundary[b as usize] = true;
        }
        neighbours[a as usize] += pb;
        neighbours[b as usize] += pa;
        valence[a as usize] += 1;
        valence[b as usize] += 1;
    }
    for v in 0..nv {
        let k = valence[v];
        out[v] = if boundary[v] || k < 3 {
            p[v]
        } else {
            let beta = if k == 3 { 3.0 / 16.0 } else { 3.0 / (8.0 * k as f32) };
            (1.0 - k as f32 * beta) * p[v] + beta * neighbours[v]
        };
    }
    let mut triangles = Vec::with_capacity(m.triangles.len() * 4);
    let mid = |a: u32, b: u32| nv as u32 + number[&(a.min(b), a.max(b))];
    for &[a, b, c] in &m.triangles {
        let (ab, bc, ca) = (mid(a, b), mid(b, c), mid(c, a));
        triangles.extend([[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]);
    }
    TriangleMesh { positions: out, triangles, normals: Vec::new() }
}

/// A closed lat-long unit sphere with `2 * segments * rings` triangles
/// (the pole triangles are degenerate, as in Embree's measurements).
pub fn lat_long_sphere(segments: u32, rings: u32) -> TriangleMesh {
    let mut m = TriangleMesh::default();
    for j in 0..=rings {
        let th = PI * j as f32 / rings as f32;
        for i in 0..=segments {
            let ph = 2.0 * PI * (i % segments) as f32 / segments as f32;
            m.positions.push(Vec3::new(th.sin() * ph.cos(), th.cos(), th.sin() * ph.sin()));
        }
    }
    let row = segments + 1;
    for j in 0..rings {
        for i in 0..segments {
            let (a, b, c, d) = (j * row + i, j * row + i + 1, (j + 1) * row + i, (j + 1) * row + i + 1);
            m.triangles.push([a, c, b]);
            m.triangles.push([b, c, d]);
        }
    }
    m.compute_normals();
    m
}

/// The `sphere:n` scene: a lat-long sphere of about `n` triangles seen
/// from +z.
pub fn sphere_scene(n: usize) -> Scene {
    generate(&format!("sphere:{n}"), &|name| Err(Error::new(format!("{name}: no scene names in sphere:N")))).expect("sphere is a generator").expect("a valid sphere count")
}

/// The repository's CS184 scene of that name (`scenes/cs184/*/NAME.dae`),
/// for tests of the library, which run without the command line's search.
#[cfg(test)]
pub(crate) fn in_repository(name: &str) -> Result<PathBuf> {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("scenes/cs184");
    ["sky", "meshedit", "simple"].iter().map(|d| root.join(d).join(format!("{name}.dae"))).find(|p| p.exists()).ok_or_else(|| Error::new(format!("{name}: not among the repository's scenes")))
}

/// A generated scene for the library's tests (`subdiv:NAME:N` finds NAME
/// among the repository's scenes).
#[cfg(test)]
pub(crate) fn for_tests(spec: &str) -> Scene {
    generate(spec, &in_repository).expect("a generator").unwrap_or_else(|e| panic!("{spec}: {e}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scene(spec: &str) -> Scene {
        for_tests(spec)
    }

    #[test]
    fn inputs_name_what_a_generator_reads() {
        assert_eq!(inputs("subdiv:bunny:1.5M"), Some(vec!["bunny"]));
        assert_eq!(inputs("subdiv:dir/a:b.dae:2M"), Some(vec!["dir/a:b.dae"]));
        assert_eq!(inputs("arch:2M"), Some(vec![]));
        assert_eq!(inputs("CBbunny"), None);
        assert_eq!(inputs("C:scene.dae"), None);
    }

    #[test]
    fn generators_are_deterministic_and_near_their_size() {
        for spec in ["arch:200k", "grass:30k", "stadium:50k", "sphere:20k"] {
            let (a, b) = (scene(spec), scene(spec));
            let n = a.triangle_count();
            assert!((0.9..=1.1).contains(&(n as f64 / spec.split(':').nth(1).unwrap().trim_end_matches('k').parse::<f64>().unwrap() / 1e3)), "{spec}: {n} triangles");
            let pa: Vec<_> = a.shapes.iter().map(|s| format!("{s:?}")).collect();
            let pb: Vec<_> = b.shapes.iter().map(|s| format!("{s:?}")).collect();
            assert_eq!(pa, pb, "{spec} is not deterministic");
        }
    }

    #[test]
    fn arch_spans_five_orders_of_magnitude_and_grass_is_thin() {
        let edge_range = |s: &Scene| {
            let (mut lo, mut hi) = (f32::INFINITY, 0.0f32);
            for sh in &s.shapes {
                if let crate::scene::Shape::Mesh(m) = sh {
                    for t in &m.triangles {
                        let [a, b, c] = t.map(|i| m.positions[i as usize]);
                        let e = (b - a).length().max((c - b).length()).max((a - c).length());
                        if e > 0.0 {
                            lo = lo.min(e);
                            hi = hi.max(e);
                        }
                    }
                }
            }
            (lo, hi)
        };
        let (lo, hi) = edge_range(&scene("arch:100k"));
        assert!(hi / lo > 1e5, "arch edges {lo}..{hi}");
        // Grass blades: longest edge over twice-area/longest edge (the
        // height on it) above 20 for most blades.
        let g = scene("grass:12k");
        let crate::scene::Shape::Mesh(m) = &g.shapes[0] else { panic!() };
        let thin = m.triangles[2..].iter().filter(|t| {
            let [a, b, c] = t.map(|i| m.positions[i as usize]);
            let e = (b - a).length().max((c - b).length()).max((a - c).length());
            let h = crate::geometry::triangle::area(a, b, c) * 2.0 / e;
            e / h > 20.0
        });
        assert!(thin.count() > m.triangles.len() / 2);
    }

    #[test]
    fn loop_subdivision_quadruples_and_smooths_a_closed_mesh() {
        // An octahedron: after subdivision every vertex moves towards the
        // centre (Loop shrinks convex shapes), the mesh stays closed.
        let mut m = TriangleMesh::default();
        m.positions = vec![Vec3::X, -Vec3::X, Vec3::Y, -Vec3::Y, Vec3::Z, -Vec3::Z];
        m.triangles = vec![[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]];
        let s = loop_subdivide(&m);
        assert_eq!(s.triangles.len(), 32);
        assert_eq!(s.positions.len(), 6 + 12);
        // Old vertices: valence 4, β = 3/32: (1 − 4β)·1 + β·0 = 0.625.
        assert!((s.positions[0] - Vec3::X * 0.625).length() < 1e-6, "{}", s.positions[0]);
        // Edge points: 3/8 (X + Y) + 1/8 (Z − Z) = (0.375, 0.375, 0).
        assert!(s.positions[6..].iter().any(|p| (*p - Vec3::new(0.375, 0.375, 0.0)).length() < 1e-6));
        // Closed: every edge used twice.
        let mut uses: HashMap<(u32, u32), u32> = HashMap::new();
        for t in &s.triangles {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                *uses.entry((a.min(b), a.max(b))).or_default() += 1;
            }
        }
        assert!(uses.values().all(|&u| u == 2));
    }

    /// The same mesh subdivides to the same bits every time: the neighbour
    /// sums once followed a hash map's per-run order, so the generated
    /// subdivided scenes (and their trees and images) changed between runs.
    #[test]
    fn loop_subdivision_is_the_same_in_every_run() {
        let m = lat_long_sphere(24, 12);
        let bits = |s: &TriangleMesh| s.positions.iter().flat_map(|p| p.to_array().map(f32::to_bits)).collect::<Vec<_>>();
        let first = bits(&loop_subdivide(&m));
        // A fresh map per call has a fresh random order: a few calls meet
        // several orders.
        for _ in 0..8 {
            assert_eq!(bits(&loop_subdivide(&m)), first);
        }
    }

    #[test]
    fn bad_specs_are_refused_and_file_names_are_not_specs() {
        assert!(generate("bunny.dae", &in_repository).is_none());
        assert!(generate("/tmp/x:y.obj", &in_repository).is_none());
        for (spec, msg) in [("arch:lots", "expected a triangle count"), ("grass:3", "between 8 and 2e8"), ("subdiv:bunny", "expected subdiv:NAME:N")] {
            let e = generate(spec, &in_repository).unwrap().unwrap_err().0;
            assert!(e.contains(msg), "{spec}: {e}");
        }
    }
}
