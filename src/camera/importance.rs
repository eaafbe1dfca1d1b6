//! The camera as a sensor that light paths can reach: its importance W_e,
//! the density with which it sends rays, and the sampling of a lens point
//! toward a point of the scene (light tracing, the `t = 1` strategies of
//! bidirectional path tracing).
//!
//! Model (pbrt-v4's `PerspectiveCamera::We/PDF_We/SampleWi`, on CS184's
//! camera): the film is the image plane z = −1 of camera space, of area
//! A = 4·tan(hfov/2)·tan(vfov/2), covering the whole frame (the screen, so a
//! `-p` cell is a part of it); the lens is a disk of area L = π·r² at the
//! camera (a pinhole: L = 1, one point). A ray leaving lens point ℓ along a
//! direction at angle θ to the view axis carries
//!
//!   W_e = 1 / (A · L · cos⁴θ),   pdf_pos = 1/L,   pdf_dir = 1/(A · cos³θ),
//!
//! (cos³θ is the Jacobian from film area to solid angle), inside the film and
//! 0 outside, so that a camera ray through a uniformly chosen film point has
//! W_e·cosθ/(pdf_pos·pdf_dir) = 1: the camera rays the image loop traces are
//! the same estimator. A direction maps to the film point where the ray meets
//! the plane in focus (z = −focal_distance; z = −1 for a pinhole), projected
//! through the lens centre, as `Camera::generate_ray_thin_lens` builds rays.
//!
//! CS184 has no importance function; nothing differs from CS184's camera.

use super::Camera;
use glam::Vec3;
use std::f32::consts::PI;

/// A lens point chosen toward a point of the scene (`Sensor::sample_toward`).
#[derive(Clone, Copy, Debug)]
pub struct LensSample {
    /// The lens point, in world space.
    pub lens: Vec3,
    /// Unit direction from the scene point to the lens point.
    pub wi: Vec3,
    pub dist: f32,
    /// Normalised image coordinates `(x, y)` in `[0, 1)²`, (0, 0) at the
    /// bottom left, where the path lands on the film.
    pub film: (f32, f32),
    /// W_e / pdf, with pdf the solid-angle density of `wi` at the scene
    /// point: 1/(A · cos³θ · dist²), the factor a light-tracing contribution
    /// takes (times the scene point's cosine toward the lens).
    pub weight: f32,
}

/// The camera's constants for importance queries, computed once
/// (`Sensor::of`): a light tracer asks for them several times per light
/// vertex, and a matrix inverse and two tangents per query were 5 % of a
/// BDPT render.
#[derive(Clone, Copy, Debug)]
pub struct Sensor {
    pos: Vec3,
    c2w: glam::Mat3,
    w2c: glam::Mat3,
    axis: Vec3,
    tan_x: f32,
    tan_y: f32,
    film_area: f32,
    lens_radius: f32,
    /// The plane in focus: z = −`focus` (1 for a pinhole).
    focus: f32,
    near: f32,
    far: f32,
}

impl Sensor {
    pub fn of(cam: &Camera) -> Sensor {
        let tan_x = (cam.hfov_deg.to_radians() / 2.0).tan();
        let tan_y = (cam.vfov_deg.to_radians() / 2.0).tan();
        Sensor {
            pos: cam.pos,
            c2w: cam.c2w,
            w2c: cam.c2w.inverse(),
            axis: (cam.c2w * Vec3::NEG_Z).normalize(),
            tan_x,
            tan_y,
            film_area: 4.0 * tan_x * tan_y,
            lens_radius: if cam.has_lens() { cam.lens_radius } else { 0.0 },
            focus: if cam.has_lens() { cam.focal_distance } else { 1.0 },
            near: cam.near,
            far: cam.far,
        }
    }

    /// The unit view axis (camera −z) in world space.
    pub fn view_axis(&self) -> Vec3 {
        self.axis
    }

    /// A: the area of the film on the plane z = −1.
    pub fn film_area(&self) -> f32 {
        self.film_area
    }

    /// Where the ray leaving lens point `origin` along `dir` (world space)
    /// lands on the film: normalised image coordinates in `[0, 1)²`, or
    /// `None` outside the film or behind the camera.
    pub fn film_point(&self, origin: Vec3, dir: Vec3) -> Option<(f32, f32)> {
        let o = self.w2c * (origin - self.pos);
        let d = self.w2c * dir;
        if !(d.z < 0.0) {
            return None;
        }
        // The plane in focus, z = −focus, then through the lens centre to z = −1.
        let t = (-self.focus - o.z) / d.z;
        let f = (o + d * t) / self.focus;
        let (x, y) = ((f.x / self.tan_x + 1.0) * 0.5, (f.y / self.tan_y + 1.0) * 0.5);
        ((0.0..1.0).contains(&x) && (0.0..1.0).contains(&y)).then_some((x, y))
    }

    /// pdf_dir: the solid-angle density of camera rays along `dir` (unit,
    /// world) from lens point `origin`; 0 where such rays do not reach the film.
    pub fn pdf_dir(&self, origin: Vec3, dir: Vec3) -> f32 {
        let cos = dir.dot(self.axis);
        if !(cos > 0.0) || self.film_point(origin, dir).is_none() {
            return 0.0;
        }
        1.0 / (self.film_area * cos * cos * cos)
    }

    /// A lens point toward scene point `p` (`u` picks it on the lens, as
    /// camera rays do): `None` where the camera cannot see `p` (off the film,
    /// behind the camera, outside the clip range).
    pub fn sample_toward(&self, p: Vec3, u: (f32, f32)) -> Option<LensSample> {
        let lens = if self.lens_radius > 0.0 {
            let r = self.lens_radius * u.0.sqrt();
            let phi = 2.0 * PI * u.1;
            self.pos + self.c2w * Vec3::new(r * phi.cos(), r * phi.sin(), 0.0)
        } else {
            self.pos
        };
        let d = lens - p;
        let dist = d.length();
        if !(dist > self.near && dist <= self.far) {
            return None;
        }
        let wi = d / dist;
        let cos = (-wi).dot(self.axis);
        if !(cos > 0.0) {
            return None;
        }
        let film = self.film_point(lens, -wi)?;
        let weight = 1.0 / (self.film_area * cos * cos * cos * dist * dist);
        weight.is_finite().then_some(LensSample { lens, wi, dist, film, weight })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::builtin;

    fn camera(lens: bool) -> Camera {
        let mut cam = Camera::from_scene(&builtin::load().unwrap());
        cam.set_screen_size(64, 48);
        if lens {
            cam.lens_radius = 0.2;
            cam.focal_distance = 4.0;
        }
        cam
    }

    #[test]
    fn film_points_invert_camera_rays() {
        for lens in [false, true] {
            let cam = camera(lens);
            for (x, y) in [(0.5, 0.5), (0.03, 0.9), (0.97, 0.11)] {
                for u in [(0.0, 0.0), (0.7, 0.2), (0.3, 0.9)] {
                    let r = if lens { cam.generate_ray_thin_lens(x, y, u) } else { cam.generate_ray(x, y) };
                    let (fx, fy) = Sensor::of(&cam).film_point(r.origin, r.dir).expect("on the film");
                    assert!((fx - x).abs() < 1e-4 && (fy - y).abs() < 1e-4, "lens {lens}: ({x}, {y}) -> ({fx}, {fy})");
                    // And the lens point chosen toward a point on that ray
                    // with the same draw is the ray's origin.
                    let s = Sensor::of(&cam).sample_toward(r.at(3.0), u).expect("visible");
                    assert!((s.lens - r.origin).length() < 1e-5 && (s.film.0 - x).abs() < 1e-4 && (s.film.1 - y).abs() < 1e-4);
                }
            }
        }
    }

    #[test]
    fn importance_integrates_to_one_over_the_film() {
        // ∫ pdf_dir dω over the film's directions = 1: a Monte Carlo check
        // over uniform directions in the cone around the axis, with the
        // standard error from the samples (fixed seed, 5 sigma).
        let cam = camera(false);
        let sensor = Sensor::of(&cam);
        let axis = sensor.view_axis();
        let frame = crate::sampling::Frame::new(axis);
        let cos_max = 0.8f32; // wider than the 49°x38° field of view
        let mut rng = crate::rng::Rng::new(7, 1);
        let n = 200_000;
        let (mut s1, mut s2) = (0.0f64, 0.0f64);
        for _ in 0..n {
            let (u1, u2) = rng.uniform2();
            let z = 1.0 - u1 * (1.0 - cos_max);
            let r = (1.0 - z * z).max(0.0).sqrt();
            let d = frame.to_world(Vec3::new(r * (2.0 * PI * u2).cos(), r * (2.0 * PI * u2).sin(), z));
            let v = (sensor.pdf_dir(cam.pos, d) * 2.0 * PI * (1.0 - cos_max)) as f64;
            s1 += v;
            s2 += v * v;
        }
        let mean = s1 / n as f64;
        let se = ((s2 / n as f64 - mean * mean) / n as f64).sqrt();
        assert!((mean - 1.0).abs() < 5.0 * se, "{mean} ± {se}");
    }
}
