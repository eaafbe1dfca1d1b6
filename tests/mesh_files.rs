//! OBJ and PLY scenes: what the loaders read, the defaults they add, the
//! size limits every loader enforces, and that a scene renders the same at
//! any scale inside those limits.

mod common;

use glam::Vec3;
use pathtracer::accel;
use pathtracer::camera::Camera;
use pathtracer::light::Lights;
use pathtracer::render::{self, path::PathTracer, RenderSettings};
use pathtracer::scene::{obj, ply, Surface, LightKind, Scene, Shape};
use std::io::Cursor;

fn parse_obj(text: &str) -> pathtracer::error::Result<Scene> {
    obj::parse(&mut Cursor::new(text.as_bytes()), "t", "t.obj")
}

fn mesh(scene: &Scene, i: usize) -> &pathtracer::scene::TriangleMesh {
    match &scene.shapes[i] {
        Shape::Mesh(m) => m,
        s => panic!("shape {i} is {s:?}"),
    }
}

#[test]
fn obj_polygons_are_fanned_groups_are_meshes_and_file_normals_are_kept() {
    let text = "\
# a quad with (non-unit) normals, then a pentagon by negative indices
o quad
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
vn 0 0 2
f 1//1 2//1 3//1 4//1
o pentagon
v 0 0 1
v 1 0 1
v 1.5 0.5 1
v 1 1 1
v 0 1 1
f -5 -4 -3 -2 -1
l 1 2
p 3
";
    let s = parse_obj(text).unwrap();
    assert_eq!(s.shapes.len(), 2);
    assert_eq!(s.objects[0].name, "quad");
    assert_eq!(s.objects[1].name, "pentagon");
    let q = mesh(&s, 0);
    assert_eq!(q.triangles, vec![[0, 1, 2], [0, 2, 3]]);
    assert!(q.normals.iter().all(|&n| n == Vec3::Z), "file normals, normalised: {:?}", q.normals);
    let p = mesh(&s, 1);
    assert_eq!(p.triangles, vec![[0, 1, 2], [0, 2, 3], [0, 3, 4]]);
    assert_eq!(p.positions[2], Vec3::new(1.5, 0.5, 1.0));
    // No normals in the file: CS184's area-weighted ones (a flat face: +z).
    assert!(p.normals.iter().all(|n| (*n - Vec3::Z).length() < 1e-6), "{:?}", p.normals);
    // The documented defaults.
    assert_eq!(s.materials.len(), 1);
    assert_eq!(s.materials[0].surface, Surface::Diffuse { albedo: Vec3::splat(0.5) });
    assert!(s.objects.iter().all(|o| o.material == 0));
    assert_eq!(s.lights.len(), 1);
    assert_eq!((s.lights[0].kind, s.lights[0].radiance), (LightKind::Ambient, Vec3::ONE));
    assert_eq!((s.camera.znear, s.camera.zfar), (0.0, f32::INFINITY));
}

/// The same little mesh as a PLY of the given encoding: a quad and a
/// triangle, per-vertex normals, a colour property and an `edge` element
/// the loader must skip.
fn ply_bytes(format: &str) -> Vec<u8> {
    let verts: [([f32; 3], [f32; 3]); 5] =
        [([0., 0., 0.], [0., 0., 1.]), ([1., 0., 0.], [0., 0., 1.]), ([1., 1., 0.], [0., 0., 1.]), ([0., 1., 0.], [0., 0., 1.]), ([0.5, 0.5, 1.], [0., 1., 0.])];
    let faces: [&[i32]; 2] = [&[0, 1, 2, 3], &[2, 3, 4]];
    let mut out = format!(
        "ply\nformat {format} 1.0\ncomment test\nelement vertex 5\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float ny\nproperty float nz\nproperty uchar red\nelement face 2\nproperty list uchar int vertex_indices\nelement edge 1\nproperty int vertex1\nproperty int vertex2\nend_header\n"
    )
    .into_bytes();
    let be = format == "binary_big_endian";
    let f = |x: f32, o: &mut Vec<u8>| o.extend(if be { x.to_be_bytes() } else { x.to_le_bytes() });
    let i = |x: i32, o: &mut Vec<u8>| o.extend(if be { x.to_be_bytes() } else { x.to_le_bytes() });
    if format == "ascii" {
        for (p, n) in verts {
            out.extend(format!("{} {} {} {} {} {} 200\n", p[0], p[1], p[2], n[0], n[1], n[2]).bytes());
        }
        for face in faces {
            out.extend(format!("{} {}\n", face.len(), face.iter().map(|k| k.to_string()).collect::<Vec<_>>().join(" ")).bytes());
        }
        out.extend(b"0 1\n");
    } else {
        for (p, n) in verts {
            for x in p.iter().chain(&n) {
                f(*x, &mut out);
            }
            out.push(200);
        }
        for face in faces {
            out.push(face.len() as u8);
            for &k in face {
                i(k, &mut out);
            }
        }
        i(0, &mut out);
        i(1, &mut out);
    }
    out
}

#[test]
fn ply_ascii_and_both_binary_byte_orders_read_the_same_mesh() {
    let mut seen = Vec::new();
    for format in ["ascii", "binary_little_endian", "binary_big_endian"] {
        let s = ply::parse(Cursor::new(ply_bytes(format)), "t", "t.ply").unwrap_or_else(|e| panic!("{format}: {e}"));
        let m = mesh(&s, 0).clone();
        assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3], [2, 3, 4]], "{format}");
        assert_eq!(m.positions[4], Vec3::new(0.5, 0.5, 1.0), "{format}");
        assert_eq!(m.normals[4], Vec3::Y, "{format}: the file's normal");
        seen.push((m.positions, m.triangles, m.normals));
    }
    assert!(seen.windows(2).all(|w| w[0] == w[1]));
}

#[test]
fn ply_without_normals_and_with_vertex_index_lists_gets_computed_normals() {
    let text = "ply\nformat ascii 1.0\nelement vertex 3\nproperty double x\nproperty double y\nproperty double z\nelement face 1\nproperty list uchar uint vertex_index\nend_header\n0 0 0\n2 0 0\n0 0 -2\n3 0 1 2\n";
    let s = ply::parse(Cursor::new(text), "t", "t.ply").unwrap();
    let m = mesh(&s, 0);
    assert_eq!(m.triangles, vec![[0, 1, 2]]);
    assert!(m.normals.iter().all(|n| (*n - Vec3::Y).length() < 1e-6), "{:?}", m.normals);
}

/// Counts in a PLY header are checked against the file's size before the
/// reader reserves room for them (a damaged count of 2^32 faces once made
/// it reserve 200 GB and be killed by the kernel).
#[test]
fn ply_counts_the_file_cannot_hold_are_refused() {
    for format in ["ascii", "binary_little_endian", "binary_big_endian"] {
        let good = ply_bytes(format);
        let text = String::from_utf8_lossy(&good).into_owned();
        let bad: Vec<u8> = if format == "ascii" {
            text.replacen("element face 2", "element face 4294967296", 1).into_bytes()
        } else {
            let at = good.windows(14).position(|w| w == b"element face 2").unwrap();
            [&good[..at], b"element face 4294967296".as_slice(), &good[at + 14..]].concat()
        };
        assert_ne!(bad, good, "{format}");
        let e = ply::parse(Cursor::new(bad), "t", "t.ply").unwrap_err().0;
        assert!(e.starts_with("t.ply: element 'face' announces 4294967296 entries"), "{format}: {e}");
    }
}

#[test]
fn scenes_beyond_what_f32_ray_arithmetic_carries_are_refused_by_every_loader() {
    let tri = |s: f32| format!("v 0 0 0\nv {s} 0 0\nv 0 {s} 0\nf 1 2 3\n");
    let e = parse_obj(&tri(3e38)).unwrap_err().0;
    assert!(e.starts_with("t.obj: mesh 'object 0' reaches 3e38") && e.contains("rescale"), "{e}");
    let e = parse_obj(&tri(1e13)).unwrap_err().0;
    assert!(e.contains("reaches 1e13"), "{e}");
    let e = parse_obj(&tri(1e-10)).unwrap_err().0;
    assert!(e.contains("1e-10 across"), "{e}");
    parse_obj(&tri(1e11)).unwrap();
    parse_obj(&tri(1e-8)).unwrap();
    let ply_text = |s: &str| format!("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n{s} 0 0\n0 1 0\n3 0 1 2\n");
    let e = ply::parse(Cursor::new(ply_text("-2e12")), "t", "t.ply").unwrap_err().0;
    assert!(e.starts_with("t.ply:") && e.contains("reaches 2e12"), "{e}");

    // COLLADA: a vertex at 3e38 (a render was silently black before), a
    // sphere of radius 1e30 (SAH cost NaN).
    let dae = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/cs184/sky/CBspheres_lambertian.dae")).unwrap();
    let far = dae.replacen("count=\"12\">1 1.5 -1", "count=\"12\">3e38 1.5 -1", 1);
    assert_ne!(far, dae);
    let e = pathtracer::scene::collada::parse(&far, "x", "x.dae").unwrap_err().0;
    assert!(e.starts_with("x.dae: mesh") && e.contains("reaches 3e38"), "{e}");
    let i = dae.find("<radius>").expect("a CGL sphere") + "<radius>".len();
    let j = i + dae[i..].find("</radius>").unwrap();
    let big = format!("{}1e30{}", &dae[..i], &dae[j..]);
    let e = pathtracer::scene::collada::parse(&big, "x", "x.dae").unwrap_err().0;
    assert!(e.starts_with("x.dae: sphere") && e.contains("e29") || e.contains("e30"), "{e}");
}

/// A lat-long sphere resting on a ground quad, every coordinate times `s`.
fn scaled_scene_obj(s: f32) -> String {
    let m = pathtracer::scene::generated::lat_long_sphere(24, 12);
    let mut t = String::new();
    for p in &m.positions {
        let p = (*p + Vec3::Y) * s;
        t += &format!("v {:e} {:e} {:e}\n", p.x, p.y, p.z);
    }
    for f in &m.triangles {
        t += &format!("f {} {} {}\n", f[0] + 1, f[1] + 1, f[2] + 1);
    }
    t += "o ground\n";
    for (x, z) in [(-4.0, -4.0), (4.0, -4.0), (4.0, 4.0), (-4.0, 4.0)] {
        t += &format!("v {:e} 0 {:e}\n", x * s, z * s);
    }
    let n = m.positions.len();
    t += &format!("f {} {} {} {}\n", n + 4, n + 3, n + 2, n + 1);
    t
}

/// Scaling by a power of two scales every f32 operation exactly, so inside
/// the accepted range the path-traced image (sky light, two bounces) must
/// be the same to the last bit at 2^-26 (1.5e-8), 1 and 2^36 (6.9e10) —
/// on every backend. Before the f64 face normals and the scaled SAH, the
/// copies at 1e-10 and 1e12 rendered black, and the BVH's SAH cost at 1e18
/// was double.
#[test]
fn a_scene_renders_the_same_image_at_any_scale_inside_the_limits() {
    for kind in common::backends() {
        let mut images = Vec::new();
        for s in [1.0f32, (2.0f32).powi(-26), (2.0f32).powi(36)] {
            let scene = parse_obj(&scaled_scene_obj(s)).unwrap();
            let built = accel::build(kind, &scene.shapes, 0).unwrap();
            let lights = Lights::from_scene(&scene).unwrap();
            let mut cam = Camera::from_scene(&scene);
            cam.set_screen_size(48, 36);
            let guide = common::guide(&scene);
            let integ = PathTracer { scene: &scene, lights: &lights, guide: guide.as_ref(), max_depth: 2, accumulate: true, hemisphere: false, light_samples: 1, russian_roulette: false };
            let out = render::render(&cam, built.accel.as_ref(), &integ, &RenderSettings::new(48, 36, 4, 7));
            images.push((s, out.image.pixels));
        }
        let (_, base) = &images[0];
        let lit = base.iter().filter(|p| p.x > 0.05).count();
        assert!(lit > base.len() / 4, "{kind}: the unscaled image is mostly dark ({lit} lit pixels)");
        for (s, img) in &images[1..] {
            let differ = base.iter().zip(img).filter(|(a, b)| a != b).count();
            assert_eq!(differ, 0, "{kind}: scale {s:e}: {differ} of {} pixels differ from scale 1", base.len());
        }
    }
}
