//! `pathtracer export`: the loaded scene, after CS184's loader rules, light
//! merging and camera placement, as a renderer-neutral description for the
//! validation harness: `scene.json` plus one OBJ per mesh (world space, with
//! our vertex normals). Reference renderers must see exactly our scene, so
//! the exporters in `validation/` read this, never the .dae.

use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::light::{Light, Lights};
use crate::scene::{Surface, Scene, Shape};
use serde_json::{json, Value};
use std::fmt::Write as _;
use std::path::Path;

fn v3(v: glam::Vec3) -> Value {
    json!([v.x, v.y, v.z])
}

/// Write `dir/scene.json` and `dir/mesh_<id>.obj` for every mesh.
pub fn export(scene: &Scene, camera: &Camera, lights: &Lights, dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| Error::new(format!("{}: cannot create: {e}", dir.display())))?;
    let mut shapes = Vec::new();
    for (id, (shape, obj)) in scene.shapes.iter().zip(&scene.objects).enumerate() {
        let m = &scene.materials[obj.material];
        // `albedo` stays the diffuse colour (0 for everything else), so
        // exporters that know only diffuse surfaces can refuse the rest by `bsdf`.
        let (albedo, bsdf) = match m.surface {
            Surface::Diffuse { albedo } => (albedo, json!({"type": "diffuse", "albedo": v3(albedo), "two_sided": true})),
            Surface::Emission { .. } => (glam::Vec3::ZERO, json!({"type": "emission"})),
            Surface::Mirror { reflectance } => (glam::Vec3::ZERO, json!({"type": "mirror", "reflectance": v3(reflectance), "two_sided": true})),
            Surface::Glass { reflectance, transmittance, ior, roughness } => (
                glam::Vec3::ZERO,
                json!({"type": "glass", "reflectance": v3(reflectance), "transmittance": v3(transmittance), "ior": ior, "roughness": roughness,
                       "fresnel": "exact dielectric", "radiance_scale": "(eta_i/eta_t)^2 on transmission"}),
            ),
            Surface::Refraction { transmittance, ior, roughness } => (
                glam::Vec3::ZERO,
                json!({"type": "refraction", "transmittance": v3(transmittance), "ior": ior, "roughness": roughness,
                       "fresnel": "none (everything transmitted, total internal reflection absorbs)", "radiance_scale": "(eta_i/eta_t)^2"}),
            ),
            Surface::Microfacet { alpha, eta, k } => (
                glam::Vec3::ZERO,
                json!({"type": "microfacet", "distribution": "beckmann", "alpha": alpha, "eta": v3(eta), "k": v3(k),
                       "masking": "separable Smith G1(wo) G1(wi), exact Beckmann lambda", "fresnel": "exact conductor at wi.h", "two_sided": false}),
            ),
        };
        let mut entry = json!({
            "id": id,
            "name": obj.name,
            "material": m.name,
            // Diffuse reflection from both sides; emission from the side the
            // geometric normal (triangle winding, sphere outward) points to.
            "albedo": v3(albedo),
            "bsdf": bsdf,
            "emission": v3(m.emission),
            "bsdf_two_sided": true,
            "emission_one_sided": true,
            // The flat colour of `--integrator object-id`.
            "id_colour": v3(crate::render::aov::id_colour(id as u32)),
        });
        match shape {
            Shape::Mesh(mesh) => {
                let file = format!("mesh_{id}.obj");
                let mut text = String::with_capacity(mesh.positions.len() * 64);
                let _ = writeln!(text, "# {} (shape {id}), world space, CS184 area-weighted vertex normals", obj.name);
                for p in &mesh.positions {
                    let _ = writeln!(text, "v {:e} {:e} {:e}", p.x, p.y, p.z);
                }
                for n in &mesh.normals {
                    let _ = writeln!(text, "vn {:e} {:e} {:e}", n.x, n.y, n.z);
                }
                for t in &mesh.triangles {
                    let _ = writeln!(text, "f {0}//{0} {1}//{1} {2}//{2}", t[0] + 1, t[1] + 1, t[2] + 1);
                }
                crate::image_io::write_text(&dir.join(&file), &text)?;
                entry["type"] = json!("mesh");
                entry["file"] = json!(file);
                entry["triangles"] = json!(mesh.triangles.len());
            }
            Shape::Sphere { center, radius } => {
                entry["type"] = json!("sphere");
                entry["center"] = v3(*center);
                entry["radius"] = json!(radius);
            }
        }
        shapes.push(entry);
    }
    let mut light_list = Vec::new();
    for (k, l) in lights.lights.iter().enumerate() {
        light_list.push(match l {
            Light::Point(crate::light::PointLight { position, intensity }) => json!({"type": "point", "position": v3(*position), "intensity": v3(*intensity)}),
            Light::Directional(crate::light::DirectionalLight { to_light, irradiance }) => json!({"type": "directional", "to_light": v3(*to_light), "irradiance": v3(*irradiance)}),
            Light::Hemisphere(crate::light::HemisphereLight { radiance, .. }) => json!({"type": "hemisphere", "up": [0.0, 1.0, 0.0], "radiance": v3(*radiance)}),
            Light::Rect(crate::light::RectLight { corner, ex, ey, normal, radiance, .. }) => {
                json!({"type": "rect", "corner": v3(*corner), "ex": v3(*ex), "ey": v3(*ey), "normal": v3(*normal), "radiance": v3(*radiance), "visible": false})
            }
            Light::Environment(e) => {
                // Our texels (negative ones already clamped) in a lossless
                // file of our own: the references see exactly what we see.
                let img = crate::image_io::Rgb { width: e.width as u32, height: e.height as u32, pixels: e.texels.clone() };
                crate::image_io::write_exr(&dir.join("environment.exr"), &img)?;
                json!({"type": "environment", "file": "environment.exr", "source": e.path, "width": e.width, "height": e.height,
                       "mapping": "cs184 lat-long: theta = acos(d.y) from row 0 at the top, phi = atan2(-d.z, d.x) + pi, u = phi/2pi; texel centres at half-integers",
                       "filter": "bilinear, wrapping in u, clamped in v"})
            }
            // Emissive shapes are described with the shape itself.
            Light::Mesh(_) | Light::Sphere(_) => json!({"type": "emissive_shape", "shape": lights.of_geometry.iter().position(|g| *g == Some(k))}),
        });
    }
    let c2w = camera.c2w;
    let doc = json!({
        "format": "pathtracer-scene/1",
        "name": scene.name,
        "source": scene.source,
        "notes": lights.notes,
        "camera": {
            "origin": v3(camera.pos),
            // Camera looks down -z of its frame; x right, y up in the image.
            "right": v3(c2w.x_axis),
            "up": v3(c2w.y_axis),
            "forward": v3(-c2w.z_axis),
            "fov_x_deg": camera.hfov_deg,
            "fov_y_deg": camera.vfov_deg,
            "width": camera.screen_w,
            "height": camera.screen_h,
            "near": camera.near,
            "far": camera.far,
            "pixel_filter": "box, 1 pixel",
            // Thin lens (CS184): a disk of this radius at the camera, the
            // plane in focus at this distance along the view axis; 0 = pinhole.
            "lens_radius": camera.lens_radius,
            "focal_distance": camera.focal_distance,
        },
        "shapes": shapes,
        "lights": light_list,
    });
    let text = serde_json::to_string_pretty(&doc).map_err(|e| Error::new(format!("scene.json: {e}")))?;
    crate::image_io::write_text(&dir.join("scene.json"), &text)
}
