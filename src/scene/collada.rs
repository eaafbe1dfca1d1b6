//! The CS184 COLLADA (`.dae`) loader, following CS184's rules precisely:
//! up-axis fix, node matrices, `<polylist>`/`<triangles>`, CGL spheres,
//! materials and lights (the CGL profile wins over `technique_common`),
//! and the perspective camera.
//!
//! Every error names the file and what is wrong with it, in one line.

use super::{material::Surface, CameraDesc, LightDesc, LightKind, Material, Object, Scene, Shape, TriangleMesh};
use crate::error::{Error, Result};
use glam::{Mat4, Vec3, Vec4};
use roxmltree::{Document, Node};
use std::collections::HashMap;
use std::path::Path;

/// Load a scene file.
pub fn load_file(path: &Path) -> Result<Scene> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::new(format!("{}: cannot read: {}", path.display(), e)))?;
    let name = super::name_of(path);
    parse(&text, &name, &path.display().to_string())
}

/// Parse COLLADA text; `source` names it in error messages.
pub fn parse(text: &str, name: &str, source: &str) -> Result<Scene> {
    let fail = |msg: String| Error::new(format!("{source}: {msg}"));
    let doc = Document::parse(text).map_err(|e| fail(format!("malformed XML: {e}")))?;
    Loader { doc: &doc, ids: HashMap::new() }.load(name, source).map_err(|e| fail(e.0))
}

struct Loader<'a, 'input> {
    doc: &'a Document<'input>,
    ids: HashMap<&'a str, Node<'a, 'input>>,
}

fn child<'a, 'i>(n: Node<'a, 'i>, tag: &str) -> Option<Node<'a, 'i>> {
    n.children().find(|c| c.is_element() && c.tag_name().name() == tag)
}

fn children<'a, 'i: 'a>(n: Node<'a, 'i>, tag: &'a str) -> impl Iterator<Item = Node<'a, 'i>> + 'a {
    n.children().filter(move |c| c.is_element() && c.tag_name().name() == tag)
}

fn first_element<'a, 'i>(n: Node<'a, 'i>) -> Option<Node<'a, 'i>> {
    n.children().find(|c| c.is_element())
}

/// `<extra><technique profile="CGL">` of an element, if any.
fn cgl_technique<'a, 'i>(n: Node<'a, 'i>) -> Option<Node<'a, 'i>> {
    children(n, "extra").flat_map(|e| children(e, "technique")).find(|t| t.attribute("profile") == Some("CGL"))
}

fn floats(n: Node, what: &str) -> Result<Vec<f32>> {
    let text = n.text().unwrap_or("");
    text.split_ascii_whitespace()
        .map(|w| w.parse::<f32>().map_err(|_| Error::new(format!("{what}: '{w}' is not a number"))))
        .collect()
}

fn finite(v: Vec<f32>, what: &str) -> Result<Vec<f32>> {
    if let Some(x) = v.iter().find(|x| !x.is_finite()) {
        crate::bail!("{what}: non-finite value {x}");
    }
    Ok(v)
}

fn float_of(n: Node, tag: &str, what: &str) -> Result<Option<f32>> {
    match child(n, tag) {
        None => Ok(None),
        Some(c) => {
            let v = finite(floats(c, what)?, what)?;
            v.first().copied().map(Some).ok_or_else(|| Error::new(format!("{what}: <{tag}> is empty")))
        }
    }
}

fn rgb(n: Node, what: &str) -> Result<Vec3> {
    let v = finite(floats(n, what)?, what)?;
    if v.len() < 3 {
        crate::bail!("{what}: expected an RGB colour, got {} numbers", v.len());
    }
    Ok(Vec3::new(v[0], v[1], v[2]))
}

fn rgb_of(n: Node, tag: &str, what: &str) -> Result<Vec3> {
    let c = child(n, tag).ok_or_else(|| Error::new(format!("{what}: missing <{tag}>")))?;
    rgb(c, &format!("{what} <{tag}>"))
}

fn url_id(url: &str) -> &str {
    url.strip_prefix('#').unwrap_or(url)
}

impl<'a, 'i> Loader<'a, 'i> {
    fn load(mut self, name: &str, source: &str) -> Result<Scene> {
        let root = self.doc.root_element();
        if root.tag_name().name() != "COLLADA" {
            crate::bail!("not a COLLADA file (root element <{}>)", root.tag_name().name());
        }
        for n in self.doc.descendants().filter(|n| n.is_element()) {
            if let Some(id) = n.attribute("id") {
                self.ids.insert(id, n);
            }
        }
        let up = child(root, "asset").and_then(|a| child(a, "up_axis")).and_then(|u| u.text()).unwrap_or("Y_UP").trim();
        let global = match up {
            // CS184's entry matrix: the renderer is Y-up.
            "Z_UP" => Mat4::from_cols(Vec4::new(-1.0, 0.0, 0.0, 0.0), Vec4::new(0.0, 0.0, 1.0, 0.0), Vec4::new(0.0, 1.0, 0.0, 0.0), Vec4::W),
            "X_UP" => Mat4::from_cols(Vec4::new(0.0, 1.0, 0.0, 0.0), Vec4::new(1.0, 0.0, 0.0, 0.0), Vec4::new(0.0, 0.0, -1.0, 0.0), Vec4::W),
            "Y_UP" => Mat4::IDENTITY,
            other => crate::bail!("unknown <up_axis> '{other}'"),
        };
        let visual = self.visual_scene(root)?;
        let mut scene = Scene {
            name: name.to_string(),
            source: source.to_string(),
            shapes: Vec::new(),
            objects: Vec::new(),
            materials: Vec::new(),
            lights: Vec::new(),
            camera: CameraDesc::default(),
        };
        let mut material_index: HashMap<String, usize> = HashMap::new();
        let mut camera_found = false;
        let mut stack: Vec<(Node, Mat4)> = children(visual, "node").map(|n| (n, global)).collect();
        stack.reverse();
        while let Some((node, parent)) = stack.pop() {
            let node_name = node.attribute("name").or(node.attribute("id")).unwrap_or("unnamed").to_string();
            let xf = parent * self.node_transform(node, &node_name)?;
            for inst in children(node, "instance_geometry") {
                self.instance_geometry(inst, xf, &node_name, &mut scene, &mut material_index)?;
            }
            for inst in children(node, "instance_light") {
                scene.lights.push(self.light(inst, xf, &node_name)?);
            }
            for inst in children(node, "instance_camera") {
                if !camera_found {
                    scene.camera = self.camera(inst, xf)?;
                    camera_found = true;
                }
            }
            let mut kids: Vec<_> = children(node, "node").map(|n| (n, xf)).collect();
            kids.reverse();
            stack.extend(kids);
        }
        if scene.shapes.is_empty() {
            crate::bail!("the scene has no geometry");
        }
        scene.check_extents()?;
        Ok(scene)
    }

    fn lookup(&self, url: &str, tag: &str, what: &str) -> Result<Node<'a, 'i>> {
        match self.ids.get(url_id(url)) {
            Some(n) if n.tag_name().name() == tag => Ok(*n),
            Some(n) => crate::bail!("{what}: '{url}' is a <{}>, expected <{tag}>", n.tag_name().name()),
            None => crate::bail!("{what}: '{url}' not found"),
        }
    }

    fn visual_scene(&self, root: Node<'a, 'i>) -> Result<Node<'a, 'i>> {
        if let Some(url) = child(root, "scene").and_then(|s| child(s, "instance_visual_scene")).and_then(|i| i.attribute("url")) {
            return self.lookup(url, "visual_scene", "<instance_visual_scene>");
        }
        child(root, "library_visual_scenes")
            .and_then(|l| child(l, "visual_scene"))
            .ok_or_else(|| Error::new("no <visual_scene>"))
    }

    /// The node's local matrix: `<matrix>` (row-major), `<translate>`,
    /// `<rotate>` (axis, degrees) and `<scale>`, composed in document order.
    fn node_transform(&self, node: Node, name: &str) -> Result<Mat4> {
        let mut m = Mat4::IDENTITY;
        for c in node.children().filter(|c| c.is_element()) {
            let what = format!("node '{name}' <{}>", c.tag_name().name());
            let local = match c.tag_name().name() {
                "matrix" => {
                    let v = finite(floats(c, &what)?, &what)?;
                    // CBgems' camera matrix has 15 numbers; CS184 leaves the
                    // missing entries 0 and so do we (only the camera uses it,
                    // through its first three rows).
                    if v.len() < 15 || v.len() > 16 {
                        crate::bail!("{what}: expected 16 numbers, got {}", v.len());
                    }
                    let mut a = [0.0f32; 16];
                    a[..v.len()].copy_from_slice(&v);
                    Mat4::from_cols_array(&a).transpose()
                }
                "translate" => {
                    let v = finite(floats(c, &what)?, &what)?;
                    if v.len() != 3 {
                        crate::bail!("{what}: expected 3 numbers");
                    }
                    Mat4::from_translation(Vec3::new(v[0], v[1], v[2]))
                }
                "scale" => {
                    let v = finite(floats(c, &what)?, &what)?;
                    if v.len() != 3 {
                        crate::bail!("{what}: expected 3 numbers");
                    }
                    Mat4::from_scale(Vec3::new(v[0], v[1], v[2]))
                }
                "rotate" => {
                    let v = finite(floats(c, &what)?, &what)?;
                    if v.len() != 4 {
                        crate::bail!("{what}: expected 4 numbers");
                    }
                    let axis = Vec3::new(v[0], v[1], v[2]).normalize_or_zero();
                    if axis == Vec3::ZERO {
                        crate::bail!("{what}: zero rotation axis");
                    }
                    Mat4::from_axis_angle(axis, v[3].to_radians())
                }
                "lookat" | "skew" => crate::bail!("{what}: not supported"),
                _ => continue,
            };
            m *= local;
        }
        Ok(m)
    }

    fn instance_geometry(
        &self,
        inst: Node<'a, 'i>,
        xf: Mat4,
        node_name: &str,
        scene: &mut Scene,
        material_index: &mut HashMap<String, usize>,
    ) -> Result<()> {
        let url = inst.attribute("url").unwrap_or("");
        let geom = self.lookup(url, "geometry", &format!("node '{node_name}' <instance_geometry>"))?;
        let gname = geom.attribute("name").or(geom.attribute("id")).unwrap_or("unnamed");
        // symbol -> material id, from <bind_material>.
        let bindings: Vec<(String, String)> = children(inst, "bind_material")
            .flat_map(|b| children(b, "technique_common"))
            .flat_map(|t| children(t, "instance_material"))
            .map(|m| (m.attribute("symbol").unwrap_or("").to_string(), url_id(m.attribute("target").unwrap_or("")).to_string()))
            .collect();
        let mut resolve = |symbol: Option<&str>, scene: &mut Scene| -> Result<usize> {
            let target = symbol
                .and_then(|s| bindings.iter().find(|(sym, _)| sym == s))
                .or(bindings.first())
                .map(|(_, t)| t.clone());
            let key = target.clone().unwrap_or_default();
            if let Some(&i) = material_index.get(&key) {
                return Ok(i);
            }
            let mat = match target {
                None => Material::default_diffuse(),
                Some(t) => self.material(&t)?,
            };
            scene.materials.push(mat);
            material_index.insert(key, scene.materials.len() - 1);
            Ok(scene.materials.len() - 1)
        };

        if let Some(mesh) = child(geom, "mesh") {
            let what = format!("geometry '{gname}'");
            let positions = self.positions(mesh, xf, &what)?;
            let mut added = 0;
            for prim in mesh.children().filter(|c| c.is_element()) {
                let tag = prim.tag_name().name();
                let triangles = match tag {
                    "polylist" | "triangles" => self.triangles(prim, positions.len(), &format!("{what} <{tag}>"))?,
                    "polygons" | "lines" | "linestrips" | "trifans" | "tristrips" => {
                        crate::bail!("{what}: <{tag}> is not supported (use <polylist> or <triangles>)")
                    }
                    _ => continue,
                };
                if triangles.is_empty() {
                    continue;
                }
                let material = resolve(prim.attribute("material"), scene)?;
                let mut m = TriangleMesh { positions: positions.clone(), triangles, normals: Vec::new() };
                m.compute_normals();
                scene.shapes.push(Shape::Mesh(m));
                scene.objects.push(Object { name: node_name.to_string(), material });
                added += 1;
            }
            if added == 0 {
                crate::bail!("{what}: empty mesh (no triangles)");
            }
            return Ok(());
        }
        let sphere = cgl_technique(geom).and_then(|t| child(t, "sphere"));
        if let Some(s) = sphere {
            let what = format!("geometry '{gname}' <sphere>");
            let r = float_of(s, "radius", &what)?.ok_or_else(|| Error::new(format!("{what}: missing <radius>")))?;
            if !(r > 0.0) {
                crate::bail!("{what}: radius must be positive, got {r}");
            }
            let center = xf.transform_point3(Vec3::ZERO);
            let radius = r * xf.transform_vector3(Vec3::X).length();
            if !center.is_finite() || !radius.is_finite() || radius <= 0.0 {
                crate::bail!("{what}: transformed sphere is degenerate");
            }
            let material = resolve(None, scene)?;
            scene.shapes.push(Shape::Sphere { center, radius });
            scene.objects.push(Object { name: node_name.to_string(), material });
            return Ok(());
        }
        crate::bail!("geometry '{gname}': neither a <mesh> nor a CGL <sphere>")
    }

    /// World-space positions of a mesh (`<vertices><input semantic="POSITION">`).
    fn positions(&self, mesh: Node<'a, 'i>, xf: Mat4, what: &str) -> Result<Vec<Vec3>> {
        let verts = child(mesh, "vertices").ok_or_else(|| Error::new(format!("{what}: missing <vertices>")))?;
        let src = children(verts, "input")
            .find(|i| i.attribute("semantic") == Some("POSITION"))
            .and_then(|i| i.attribute("source"))
            .ok_or_else(|| Error::new(format!("{what}: <vertices> has no POSITION input")))?;
        let source = self.lookup(src, "source", what)?;
        let arr = child(source, "float_array").ok_or_else(|| Error::new(format!("{what}: position source has no <float_array>")))?;
        let vals = floats(arr, &format!("{what} positions"))?;
        if let Some(i) = vals.iter().position(|x| !x.is_finite()) {
            crate::bail!("{what}: vertex {} has a non-finite coordinate ({})", i / 3, vals[i]);
        }
        let stride = child(source, "technique_common")
            .and_then(|t| child(t, "accessor"))
            .and_then(|a| a.attribute("stride"))
            .map(|s| s.parse::<usize>().map_err(|_| Error::new(format!("{what}: bad accessor stride '{s}'"))))
            .transpose()?
            .unwrap_or(3);
        if stride < 3 {
            crate::bail!("{what}: position stride {stride} < 3");
        }
        let pts: Vec<Vec3> = vals
            .chunks_exact(stride)
            .map(|c| {
                let p = xf * Vec4::new(c[0], c[1], c[2], 1.0);
                p.truncate() / p.w
            })
            .collect();
        if pts.is_empty() {
            crate::bail!("{what}: empty mesh (no vertices)");
        }
        if pts.iter().any(|p| !p.is_finite()) {
            crate::bail!("{what}: a vertex is not finite after its node transform");
        }
        Ok(pts)
    }

    /// Triangles of a `<polylist>` or `<triangles>`, as position indices.
    /// Polygons with more than three vertices are split as a fan.
    fn triangles(&self, prim: Node, n_positions: usize, what: &str) -> Result<Vec<[u32; 3]>> {
        let inputs: Vec<Node> = children(prim, "input").collect();
        let vertex_input = inputs
            .iter()
            .find(|i| i.attribute("semantic") == Some("VERTEX"))
            .ok_or_else(|| Error::new(format!("{what}: no VERTEX input")))?;
        let offset_of = |i: &Node| i.attribute("offset").unwrap_or("0").parse::<usize>();
        let voff = offset_of(vertex_input).map_err(|_| Error::new(format!("{what}: bad input offset")))?;
        let mut stride = 1;
        for i in &inputs {
            stride = stride.max(offset_of(i).map_err(|_| Error::new(format!("{what}: bad input offset")))? + 1);
        }
        let p = child(prim, "p").map(|p| p.text().unwrap_or("")).unwrap_or("");
        let idx: Vec<i64> = p
            .split_ascii_whitespace()
            .map(|w| w.parse::<i64>().map_err(|_| Error::new(format!("{what}: index '{w}' is not an integer"))))
            .collect::<Result<_>>()?;
        let counts: Vec<usize> = if prim.tag_name().name() == "polylist" {
            let vc = child(prim, "vcount").map(|v| v.text().unwrap_or("")).unwrap_or("");
            vc.split_ascii_whitespace()
                .map(|w| w.parse::<usize>().map_err(|_| Error::new(format!("{what}: vcount '{w}' is not a count"))))
                .collect::<Result<_>>()?
        } else {
            vec![3; idx.len() / (3 * stride)]
        };
        let needed: usize = counts.iter().sum::<usize>() * stride;
        if needed != idx.len() {
            crate::bail!("{what}: <p> has {} indices, the polygon counts need {}", idx.len(), needed);
        }
        let vertex = |k: usize| -> Result<u32> {
            let i = idx[k * stride + voff];
            if i < 0 || i as usize >= n_positions {
                crate::bail!("{what}: vertex index {i} out of range (mesh has {n_positions} vertices)");
            }
            Ok(i as u32)
        };
        let mut tris = Vec::with_capacity(counts.len());
        let mut k = 0;
        for &c in &counts {
            if c < 3 {
                crate::bail!("{what}: a polygon has {c} vertices");
            }
            let first = vertex(k)?;
            for j in 1..c - 1 {
                tris.push([first, vertex(k + j)?, vertex(k + j + 1)?]);
            }
            k += c;
        }
        Ok(tris)
    }

    fn material(&self, id: &str) -> Result<Material> {
        let what = format!("material '{id}'");
        let mat = self.lookup(id, "material", &what)?;
        let effect_url = child(mat, "instance_effect")
            .and_then(|e| e.attribute("url"))
            .ok_or_else(|| Error::new(format!("{what}: no <instance_effect>")))?;
        let effect = self.lookup(effect_url, "effect", &what)?;
        let surface = if let Some(t) = cgl_technique(effect) {
            let kind = first_element(t).ok_or_else(|| Error::new(format!("{what}: empty CGL technique")))?;
            let w = format!("{what} <{}>", kind.tag_name().name());
            let scalar = |tag: &str| -> Result<f32> {
                float_of(kind, tag, &w)?.ok_or_else(|| Error::new(format!("{w}: missing <{tag}>")))
            };
            match kind.tag_name().name() {
                "emission" => Surface::Emission { radiance: rgb_of(kind, "radiance", &w)? },
                "mirror" => Surface::Mirror { reflectance: rgb_of(kind, "reflectance", &w)? },
                "glass" => Surface::Glass {
                    reflectance: rgb_of(kind, "reflectance", &w)?,
                    transmittance: rgb_of(kind, "transmittance", &w)?,
                    roughness: scalar("roughness")?,
                    ior: scalar("ior")?,
                },
                "refraction" => Surface::Refraction {
                    transmittance: rgb_of(kind, "transmittance", &w)?,
                    roughness: scalar("roughness")?,
                    ior: scalar("ior")?,
                },
                "microfacet" => Surface::Microfacet { alpha: scalar("alpha")?, eta: rgb_of(kind, "eta", &w)?, k: rgb_of(kind, "k", &w)? },
                other => crate::bail!("{what}: unknown CGL material element <{other}>"),
            }
        } else {
            let shader = child(effect, "profile_COMMON")
                .and_then(|p| child(p, "technique"))
                .and_then(|t| ["phong", "lambert", "blinn"].iter().find_map(|s| child(t, s)));
            match shader.and_then(|s| child(s, "diffuse")).and_then(|d| child(d, "color")) {
                Some(c) => Surface::Diffuse { albedo: rgb(c, &format!("{what} diffuse colour"))? },
                None => Material::default_diffuse().surface,
            }
        };
        if let Surface::Diffuse { albedo } = surface {
            if albedo.min_element() < 0.0 || albedo.max_element() > 1.0 {
                crate::bail!("{what}: diffuse albedo {albedo} is outside [0, 1]");
            }
        }
        let emission = if let Surface::Emission { radiance } = surface { radiance } else { Vec3::ZERO };
        if !(emission.min_element() >= 0.0) {
            crate::bail!("{what}: negative emission {emission}");
        }
        Ok(Material { name: id.to_string(), surface, emission })
    }

    fn light(&self, inst: Node, xf: Mat4, node_name: &str) -> Result<LightDesc> {
        let url = inst.attribute("url").unwrap_or("");
        let what = format!("node '{node_name}' light");
        let light = self.lookup(url, "light", &what)?;
        let tech = cgl_technique(light)
            .or_else(|| child(light, "technique_common"))
            .ok_or_else(|| Error::new(format!("{what}: no CGL technique or <technique_common>")))?;
        let kind_node = first_element(tech).ok_or_else(|| Error::new(format!("{what}: empty light technique")))?;
        let kind = match kind_node.tag_name().name() {
            "ambient" => LightKind::Ambient,
            "directional" => LightKind::Directional,
            "area" => LightKind::Area,
            "point" => LightKind::Point,
            "spot" => LightKind::Spot,
            other => crate::bail!("{what}: unknown light type <{other}>"),
        };
        let radiance = rgb_of(kind_node, "color", &format!("{what} <{}>", kind.as_str()))?;
        Ok(LightDesc { name: node_name.to_string(), kind, radiance, transform: xf })
    }

    fn camera(&self, inst: Node, xf: Mat4) -> Result<CameraDesc> {
        let url = inst.attribute("url").unwrap_or("");
        let cam = self.lookup(url, "camera", "<instance_camera>")?;
        let persp = child(cam, "optics")
            .and_then(|o| child(o, "technique_common"))
            .and_then(|t| child(t, "perspective"))
            .ok_or_else(|| Error::new("camera: only <perspective> cameras are supported"))?;
        let w = "camera <perspective>";
        let xfov = float_of(persp, "xfov", w)?;
        let yfov = float_of(persp, "yfov", w)?;
        let aspect = float_of(persp, "aspect_ratio", w)?;
        let hfov = xfov.unwrap_or(50.0);
        let vfov = match (yfov, aspect) {
            (Some(y), _) => y,
            (None, Some(a)) if a > 0.0 => 2.0 * ((hfov.to_radians() / 2.0).tan() / a).atan().to_degrees(),
            _ => 35.0,
        };
        if !(hfov > 0.0 && hfov < 180.0 && vfov > 0.0 && vfov < 180.0) {
            crate::bail!("camera: field of view {hfov}x{vfov} degrees is not in (0, 180)");
        }
        let znear = float_of(persp, "znear", w)?.unwrap_or(0.001);
        let zfar = float_of(persp, "zfar", w)?.unwrap_or(1000.0);
        if !(znear >= 0.0 && zfar > znear) {
            crate::bail!("camera: clip range [{znear}, {zfar}] is empty");
        }
        let d = (xf * Vec4::new(0.0, 0.0, -1.0, 1.0)).truncate();
        let c_dir = d.normalize_or_zero();
        if c_dir == Vec3::ZERO || !c_dir.is_finite() {
            crate::bail!("camera: its node transform gives no view direction");
        }
        Ok(CameraDesc { hfov_deg: hfov, vfov_deg: vfov, znear, zfar, c_dir })
    }
}
