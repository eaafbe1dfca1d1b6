//! The COLLADA loader on every shipped scene, and bad input through the CLI.

mod common;

use pathtracer::scene::{Surface, LightKind};
use std::path::{Path, PathBuf};
use std::process::Command;

/// BVH primitive counts from the CS184 notes (triangles + spheres).
const COUNTS: [(&str, usize, usize); 20] = [
    ("beetle", 7_558, 0),
    ("cow", 5_856, 0),
    ("maxplanck", 50_801, 0),
    ("teapot", 2_464, 0),
    ("cube", 12, 0),
    ("plane", 2, 0),
    ("CBbunny", 28_588, 0),
    ("CBbunny_microfacet_cu", 28_588, 0),
    ("CBcoil", 7_884, 0),
    ("CBempty", 12, 0),
    ("CBgems", 252, 0),
    ("CBspheres", 12, 2),
    ("CBspheres_lambertian", 12, 2),
    ("CBspheres_microfacet_al_ag", 12, 2),
    ("CBspheres_refract", 12, 2),
    ("CBspheres_tex", 12, 2),
    ("bunny", 33_696, 0),
    ("bunny_microfacet_cu", 33_696, 0),
    ("bunny_microfacet_cu_unlit", 33_696, 0),
    ("bunny_unlit", 33_696, 0),
];

#[test]
fn every_shipped_scene_loads_with_the_documented_counts() {
    let scenes = common::shipped_scenes();
    for (name, tris, spheres) in COUNTS {
        let path = scenes.iter().find(|p| p.file_stem().unwrap() == name).unwrap_or_else(|| panic!("{name}.dae missing"));
        let s = common::load(path);
        assert_eq!((s.triangle_count(), s.sphere_count()), (tris, spheres), "{name}");
        assert_eq!(s.shapes.len(), s.objects.len());
        for shape in &s.shapes {
            if let pathtracer::scene::Shape::Mesh(m) = shape {
                assert_eq!(m.normals.len(), m.positions.len());
                assert!(m.normals.iter().all(|n| n.is_finite()));
            }
        }
    }
}

#[test]
fn cornell_box_materials_lights_and_spheres_are_as_in_the_notes() {
    let s = common::load(&common::scene_path("sky", "CBspheres_lambertian"));
    let spheres: Vec<_> = s
        .shapes
        .iter()
        .filter_map(|sh| if let pathtracer::scene::Shape::Sphere { center, radius } = sh { Some((*center, *radius)) } else { None })
        .collect();
    let mut centers: Vec<[i32; 3]> = spheres.iter().map(|(c, _)| (*c * 1000.0).round().as_ivec3().to_array()).collect();
    centers.sort();
    assert_eq!(centers, vec![[-400, 300, -300], [400, 300, 300]]);
    assert!(spheres.iter().all(|(_, r)| (r - 0.3).abs() < 1e-6));
    let kinds: Vec<&str> = s.objects.iter().map(|o| s.materials[o.material].surface.kind()).collect();
    assert_eq!(kinds.iter().filter(|k| **k == "emission").count(), 1);
    assert!(s.materials.iter().any(|m| m.surface == Surface::Diffuse { albedo: glam::Vec3::new(0.6, 0.2, 0.2) }));
    assert_eq!(s.lights.len(), 1);
    assert_eq!(s.lights[0].kind, LightKind::Area);
    assert_eq!(s.lights[0].radiance, glam::Vec3::splat(10.0));
    // Other scenes keep the materials later issues render.
    let s = common::load(&common::scene_path("sky", "CBspheres"));
    let kinds: Vec<&str> = s.materials.iter().map(|m| m.surface.kind()).collect();
    assert!(kinds.contains(&"mirror") && kinds.contains(&"glass"), "{kinds:?}");
    let s = common::load(&common::scene_path("sky", "CBempty"));
    assert_eq!(s.lights[0].kind, LightKind::Point);
    let s = common::load(&common::scene_path("sky", "bunny"));
    assert_eq!(s.lights[0].kind, LightKind::Ambient);
    let s = common::load(&common::scene_path("meshedit", "cow"));
    assert_eq!(s.lights[0].kind, LightKind::Directional);
}

fn bin() -> &'static str {
    env!("CARGO_BIN_EXE_pathtracer")
}

fn scratch(name: &str) -> common::Scratch {
    common::Scratch::new("loader", name)
}

/// Run the CLI on `scene` and expect a clean one-line failure naming `scene`
/// and containing `expect`, with no output file written.
fn expect_failure(dir: &Path, scene: &Path, expect: &str) {
    let out_png = dir.join("out.png");
    let out = Command::new(bin()).arg("-r").arg("16").arg("12").arg("-f").arg(&out_png).arg(scene).current_dir(dir).output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{}: expected failure, got success", scene.display());
    assert_ne!(out.status.code(), Some(101), "{}: panicked: {stderr}", scene.display());
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert_eq!(stderr.trim_end().lines().count(), 1, "not one line: {stderr}");
    let name = scene.file_name().unwrap().to_string_lossy();
    assert!(stderr.contains(&*name), "error does not name the file: {stderr}");
    assert!(stderr.contains(expect), "expected '{expect}' in: {stderr}");
    let files: Vec<_> = std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name()).collect();
    let stray: Vec<_> = files.iter().filter(|f| f.to_string_lossy() != name).collect();
    assert!(stray.is_empty(), "output left behind: {stray:?}");
}

fn corrupt(dir: &Path, file: &str, edit: impl Fn(String) -> String) -> PathBuf {
    let src = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/cs184/sky/CBspheres_lambertian.dae")).unwrap();
    let edited = edit(src.clone());
    assert_ne!(edited, src, "the corruption for {file} changed nothing");
    let p = dir.join(file);
    std::fs::write(&p, edited).unwrap();
    p
}

#[test]
fn bad_input_fails_cleanly_in_one_line() {
    let d = scratch("missing");
    expect_failure(&d, &d.join("no_such_scene.dae"), "cannot read");

    let d = scratch("truncated");
    let p = corrupt(&d, "truncated.dae", |s| s[..s.len() / 2].to_string());
    expect_failure(&d, &p, "malformed XML");

    let d = scratch("nan");
    // The ceiling's first vertex.
    let p = corrupt(&d, "nan.dae", |s| s.replacen("count=\"12\">1 1.5 -1", "count=\"12\">NaN 1.5 -1", 1));
    expect_failure(&d, &p, "non-finite");

    let d = scratch("index");
    let p = corrupt(&d, "index.dae", |s| {
        let i = s.find("<p>").unwrap() + 3;
        format!("{}99999{}", &s[..i], &s[i + 1..])
    });
    expect_failure(&d, &p, "out of range");

    let d = scratch("empty");
    let p = corrupt(&d, "empty.dae", |s| {
        let (a, b) = (s.find("<p>").unwrap(), s.find("</p>").unwrap());
        let vc = s.find("<vcount>").unwrap();
        let vce = s.find("</vcount>").unwrap();
        format!("{}<vcount></vcount>{}<p></p>{}", &s[..vc], &s[vce + 9..a], &s[b + 4..])
    });
    expect_failure(&d, &p, "empty mesh");

    let d = scratch("cgl");
    let p = corrupt(&d, "cgl.dae", |s| s.replacen("<emission>\n            <radiance>", "<hg>\n            <radiance>", 1).replacen("</radiance>\n          </emission>", "</radiance>\n          </hg>", 1));
    expect_failure(&d, &p, "unknown CGL material element <hg>");

    let d = scratch("light");
    let p = corrupt(&d, "light.dae", |s| s.replacen("<area>", "<laser>", 1).replacen("</area>", "</laser>", 1));
    expect_failure(&d, &p, "unknown light type <laser>");

    let d = scratch("notdae");
    let p = d.join("notdae.dae");
    std::fs::write(&p, "<html><body/></html>").unwrap();
    expect_failure(&d, &p, "not a COLLADA file");
}

#[test]
fn absurd_flags_fail_cleanly() {
    let d = scratch("flags");
    for args in [
        vec!["-r", "0", "10"],
        vec!["-r", "-5", "10"],
        vec!["-r", "100000", "10"],
        vec!["-s", "0"],
        vec!["-t", "100000"],
        vec!["-a", "0", "0.05"],
        vec!["-a", "32", "-1"],
        vec!["-a", "32", "nan"],
        vec!["-p", "790", "0", "20", "20"],
        vec!["--backend", "optix"],
        vec!["-q"],
    ] {
        let out = Command::new(bin()).args(&args).arg("-f").arg(d.join("x.png")).current_dir(&d).output().unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{args:?} succeeded");
        assert_ne!(out.status.code(), Some(101), "{args:?} panicked: {stderr}");
        assert_eq!(stderr.trim_end().lines().count(), 1, "{args:?}: not one line: {stderr}");
        assert!(std::fs::read_dir(&d).unwrap().next().is_none(), "{args:?} left a file behind");
    }
}

#[test]
fn obj_and_ply_bad_input_fails_cleanly_in_one_line() {
    let d = scratch("obj-missing");
    expect_failure(&d, &d.join("no_such_mesh.obj"), "cannot read");

    let header = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";
    let binary_header = header.replace("ascii", "binary_little_endian").into_bytes();
    let mut truncated = binary_header.clone();
    truncated.extend([0u8; 20]); // 36 bytes of vertices needed
    // ASCII PLY has no spelling for NaN; a binary file does.
    let mut nan = binary_header.clone();
    for x in [0.0f32, 0.0, 0.0, 1.0, f32::NAN, 0.0, 0.0, 1.0, 0.0] {
        nan.extend(x.to_le_bytes());
    }
    nan.push(3);
    for k in [0i32, 1, 2] {
        nan.extend(k.to_le_bytes());
    }
    let cases: [(&str, Vec<u8>, &str); 13] = [
        ("index.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99\n".to_vec(), "not a valid OBJ file: face vertex index out of bounds"),
        ("nan.obj", b"v 0 0 0\nv NaN 0 0\nv 0 1 0\nf 1 2 3\n".to_vec(), "vertex 1 has a non-finite coordinate"),
        ("garbage.obj", b"v 0 zero 0\n".to_vec(), "not a valid OBJ file"),
        ("points.obj", b"v 0 0 0\nv 1 0 0\np 1\nl 1 2\n".to_vec(), "no triangles"),
        ("huge.obj", b"v 0 0 0\nv 3e38 0 0\nv 0 1 0\nf 1 2 3\n".to_vec(), "beyond the"),
        ("index.ply", format!("{header}0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n").into_bytes(), "face 0 uses vertex 7, but there are 3 vertices"),
        ("negative.ply", format!("{header}0 0 0\n1 0 0\n0 1 0\n3 0 -1 2\n").into_bytes(), "face 0 uses vertex -1"),
        ("two.ply", format!("{header}0 0 0\n1 0 0\n0 1 0\n2 0 1\n").into_bytes(), "face 0 has 2 vertices"),
        (
            "noface.ply",
            b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n".to_vec(),
            "no 'face' element",
        ),
        ("header.ply", b"plyx\nformat ascii 1.0\nend_header\n".to_vec(), "not a valid PLY header"),
        ("truncated.ply", truncated, "bad 'vertex' data"),
        ("nan.ply", nan, "vertex 1 has a missing or non-finite coordinate"),
        ("mesh.stl", b"solid x\nendsolid x\n".to_vec(), "unknown scene format '.stl': scenes are COLLADA (.dae), Wavefront OBJ (.obj) or PLY (.ply) files"),
    ];
    for (file, bytes, expect) in cases {
        // Each case in its own folder: `expect_failure` checks nothing else is left there.
        let d = scratch(&format!("bad-{file}"));
        let p = d.join(file);
        std::fs::write(&p, bytes).unwrap();
        expect_failure(&d, &p, expect);
    }
}

#[test]
fn an_obj_renders_from_the_command_line_and_a_ply_benchmarks() {
    let d = scratch("obj-render");
    let obj = d.join("quad.obj");
    std::fs::write(&obj, "mtllib quad.mtl\nv -1 0 -1\nv 1 0 -1\nv 1 0 1\nv -1 0 1\nv 0 0.5 0\nf 1 2 5\nf 2 3 5\nf 3 4 5\nf 4 1 5\n").unwrap();
    let png = d.join("quad.png");
    let out = Command::new(bin()).args(["-r", "32", "24", "-s", "4", "-m", "1", "-f"]).arg(&png).arg(&obj).current_dir(&d).output().unwrap();
    let (stdout, stderr) = (String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "{stdout}{stderr}");
    assert!(stderr.contains("OBJ materials (quad.mtl) are not read"), "the ignored mtllib is not reported: {stderr}");
    assert!(stdout.contains("4 primitives"), "{stdout}");
    let img = image::open(&png).unwrap().to_rgb8();
    assert!(img.pixels().any(|p| p.0 != [0, 0, 0]), "black image");

    let ply = d.join("pyramid.ply");
    std::fs::write(&ply, "ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nproperty float y\nproperty float z\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n-1 0 -1\n1 0 -1\n1 0 1\n-1 0 1\n0 1 0\n4 0 1 2 3\n3 0 1 4\n").unwrap();
    let out = Command::new(bin()).args(["bench", "--rays", "4096", "--no-render", "--backends", "native"]).arg(&ply).current_dir(&d).output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}{}", String::from_utf8_lossy(&out.stderr));
    assert!(stdout.contains("| pyramid | 3 | native |"), "{stdout}");
}
