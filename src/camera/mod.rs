//! CS184's camera: placement from the scene bounds, field-of-view rules,
//! ray generation, and the six-line camera settings file.

pub mod importance;

use crate::error::{Error, Result};
use crate::ray::Ray;
use crate::scene::Scene;
use glam::{Mat3, Vec3};
use std::path::Path;

/// The window CS184 configures the camera for before `-r` is applied.
pub const DEFAULT_WIDTH: u32 = 800;
pub const DEFAULT_HEIGHT: u32 = 600;

#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    pub hfov_deg: f32,
    pub vfov_deg: f32,
    pub aspect: f32,
    pub near: f32,
    pub far: f32,
    pub pos: Vec3,
    pub target: Vec3,
    pub phi: f32,
    pub theta: f32,
    pub r: f32,
    pub min_r: f32,
    pub max_r: f32,
    /// Camera-to-world rotation; columns are the camera's X, Y, Z axes and
    /// the camera looks down -Z.
    pub c2w: Mat3,
    pub screen_w: u32,
    pub screen_h: u32,
    /// Distance to the image plane in pixels; `-r` keeps it fixed.
    pub screen_dist: f32,
    pub focal_distance: f32,
    pub lens_radius: f32,
}

impl Camera {
    /// CS184's `Application::load` + `Camera::configure` at 800x600: orbit
    /// the bounding-box centre at twice the canonical view distance, on the
    /// side the file's camera direction points to.
    pub fn from_scene(scene: &Scene) -> Camera {
        let desc = scene.camera;
        let b = scene.bounds();
        let target = b.center();
        let cvd = b.extent().length() / 2.0 * 1.5;
        let (min_r, max_r) = (cvd / 10.0, cvd * 20.0);
        let r = (2.0 * cvd).clamp(min_r, max_r);
        let mut phi = desc.c_dir.y.clamp(-1.0, 1.0).acos();
        if phi.sin() == 0.0 {
            phi += 1e-5;
        }
        let theta = desc.c_dir.x.atan2(desc.c_dir.z);
        let mut cam = Camera {
            hfov_deg: desc.hfov_deg,
            vfov_deg: desc.vfov_deg,
            aspect: DEFAULT_WIDTH as f32 / DEFAULT_HEIGHT as f32,
            near: desc.znear,
            far: desc.zfar,
            pos: Vec3::ZERO,
            target,
            phi,
            theta,
            r,
            min_r,
            max_r,
            c2w: Mat3::IDENTITY,
            screen_w: DEFAULT_WIDTH,
            screen_h: DEFAULT_HEIGHT,
            screen_dist: 0.0,
            focal_distance: 4.7,
            lens_radius: 0.0,
        };
        cam.compute_position();
        cam.configure(DEFAULT_WIDTH, DEFAULT_HEIGHT);
        cam
    }

    fn compute_position(&mut self) {
        let (sp, cp) = self.phi.sin_cos();
        let (st, ct) = self.theta.sin_cos();
        let to_camera = self.r * Vec3::new(sp * st, cp, sp * ct);
        self.pos = self.target + to_camera;
        let up = Vec3::new(0.0, sp.signum(), 0.0);
        let x = up.cross(to_camera).normalize();
        let y = to_camera.cross(x).normalize();
        self.c2w = Mat3::from_cols(x, y, to_camera.normalize());
    }

    /// CS184's `configure`: widen whichever field of view the window's aspect
    /// needs, then fix the pixel focal length.
    fn configure(&mut self, w: u32, h: u32) {
        let ar1 = (self.hfov_deg.to_radians() / 2.0).tan() / (self.vfov_deg.to_radians() / 2.0).tan();
        let ar = w as f32 / h as f32;
        self.aspect = ar;
        if ar1 < ar {
            self.hfov_deg = (2.0 * ((self.vfov_deg.to_radians() / 2.0).tan() * ar).atan()).to_degrees();
        } else if ar1 > ar {
            self.vfov_deg = (2.0 * ((self.hfov_deg.to_radians() / 2.0).tan() / ar).atan()).to_degrees();
        }
        self.screen_w = w;
        self.screen_h = h;
        self.screen_dist = h as f32 / (2.0 * (self.vfov_deg.to_radians() / 2.0).tan());
    }

    /// CS184's `set_screen_size` (what `-r` does): keep the pixel focal
    /// length, so a smaller frame is a crop of the 800x600 view, not a rescale.
    pub fn set_screen_size(&mut self, w: u32, h: u32) {
        self.screen_w = w;
        self.screen_h = h;
        self.aspect = w as f32 / h as f32;
        self.hfov_deg = (2.0 * (w as f32 / (2.0 * self.screen_dist)).atan()).to_degrees();
        self.vfov_deg = (2.0 * (h as f32 / (2.0 * self.screen_dist)).atan()).to_degrees();
    }

    /// Our alternative to `-r`'s crop: resize the frame and keep the
    /// horizontal field of view, so a small image shows the whole view.
    pub fn resize_keep_fov(&mut self, w: u32, h: u32) {
        self.screen_dist *= w as f32 / self.screen_w as f32;
        self.set_screen_size(w, h);
    }

    /// The ray through normalised image coordinates `(x, y)` in `[0,1]^2`,
    /// `(0,0)` at the bottom-left, with the clip range as its `t` range.
    #[inline]
    pub fn generate_ray(&self, x: f32, y: f32) -> Ray {
        self.generate_ray_on(self.image_plane(), x, y)
    }

    /// `generate_ray` with the image plane's tangents computed once by the
    /// caller (two `tan` per ray were 4 % of a render's instructions).
    #[inline]
    pub fn generate_ray_on(&self, plane: ImagePlane, x: f32, y: f32) -> Ray {
        Ray::with_range(self.pos, (self.c2w * plane.point(x, y)).normalize(), self.near, self.far)
    }

    /// The image plane z = −1 (camera space) of the current fields of view.
    #[inline]
    pub fn image_plane(&self) -> ImagePlane {
        ImagePlane { tan_x: (self.hfov_deg.to_radians() / 2.0).tan(), tan_y: (self.vfov_deg.to_radians() / 2.0).tan() }
    }

    /// CS184's thin lens (`-b`, `-d`): the ray through normalised image
    /// coordinates `(x, y)` and the lens point picked by `u`. The lens is a
    /// disk of radius `lens_radius` at the camera, sampled uniformly (radius
    /// √u.0, angle 2π u.1); the plane in focus is z = −`focal_distance` in
    /// camera space, where the pinhole ray through the same pixel meets it.
    #[inline]
    pub fn generate_ray_thin_lens(&self, x: f32, y: f32, u: (f32, f32)) -> Ray {
        self.generate_ray_thin_lens_on(self.image_plane(), x, y, u)
    }

    /// `generate_ray_thin_lens` with the image plane computed by the caller.
    #[inline]
    pub fn generate_ray_thin_lens_on(&self, plane: ImagePlane, x: f32, y: f32, u: (f32, f32)) -> Ray {
        let p = plane.point(x, y);
        let r = self.lens_radius * u.0.sqrt();
        let phi = 2.0 * std::f32::consts::PI * u.1;
        let lens = Vec3::new(r * phi.cos(), r * phi.sin(), 0.0);
        let focus = p * self.focal_distance;
        Ray::with_range(self.pos + self.c2w * lens, (self.c2w * (focus - lens)).normalize(), self.near, self.far)
    }

    /// Whether rays come from a lens (`-b` > 0) rather than a pinhole.
    pub fn has_lens(&self) -> bool {
        self.lens_radius > 0.0
    }

    /// CS184's camera settings file (`Camera::dump_settings`), six lines.
    pub fn to_settings(&self) -> String {
        let m = self.c2w;
        format!(
            "{} {} {} {} {}\n{} {} {} {} {} {}\n{} {} {} {} {}\n{} {} {} {} {} {} {} {} {}\n{} {} {}\n{} {}\n",
            self.hfov_deg, self.vfov_deg, self.aspect, self.near, self.far,
            self.pos.x, self.pos.y, self.pos.z, self.target.x, self.target.y, self.target.z,
            self.phi, self.theta, self.r, self.min_r, self.max_r,
            m.x_axis.x, m.y_axis.x, m.z_axis.x, m.x_axis.y, m.y_axis.y, m.z_axis.y, m.x_axis.z, m.y_axis.z, m.z_axis.z,
            self.screen_w, self.screen_h, self.screen_dist,
            self.focal_distance, self.lens_radius,
        )
    }

    /// Load a settings file: every value is overwritten (CS184's
    /// `load_settings`); the frame size is then taken from the caller.
    pub fn load_settings(&mut self, path: &Path) -> Result<()> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::new(format!("{}: cannot read: {e}", path.display())))?;
        self.parse_settings(&text).map_err(|e| Error::new(format!("{}: {}", path.display(), e.0)))
    }

    pub fn parse_settings(&mut self, text: &str) -> Result<()> {
        let v: Vec<f32> = text
            .split_ascii_whitespace()
            .map(|w| w.parse::<f32>().map_err(|_| Error::new(format!("camera settings: '{w}' is not a number"))))
            .collect::<Result<_>>()?;
        if v.len() != 30 {
            crate::bail!("camera settings: expected 30 numbers in 6 lines, got {}", v.len());
        }
        if let Some(x) = v.iter().find(|x| !x.is_finite()) {
            crate::bail!("camera settings: non-finite value {x}");
        }
        let (hfov, vfov) = (v[0], v[1]);
        if !(hfov > 0.0 && hfov < 180.0 && vfov > 0.0 && vfov < 180.0) {
            crate::bail!("camera settings: field of view {hfov}x{vfov} is not in (0, 180) degrees");
        }
        if !(v[3] >= 0.0 && v[4] > v[3]) {
            crate::bail!("camera settings: clip range [{}, {}] is empty", v[3], v[4]);
        }
        let c2w = Mat3::from_cols(Vec3::new(v[16], v[19], v[22]), Vec3::new(v[17], v[20], v[23]), Vec3::new(v[18], v[21], v[24]));
        if c2w.determinant().abs() < 1e-3 {
            crate::bail!("camera settings: the camera-to-world matrix is singular");
        }
        *self = Camera {
            hfov_deg: hfov,
            vfov_deg: vfov,
            aspect: v[2],
            near: v[3],
            far: v[4],
            pos: Vec3::new(v[5], v[6], v[7]),
            target: Vec3::new(v[8], v[9], v[10]),
            phi: v[11],
            theta: v[12],
            r: v[13],
            min_r: v[14],
            max_r: v[15],
            c2w,
            screen_w: v[25] as u32,
            screen_h: v[26] as u32,
            screen_dist: v[27],
            focal_distance: v[28],
            lens_radius: v[29],
        };
        Ok(())
    }
}

/// The camera's image plane z = −1 in camera space: the tangents of the
/// half fields of view.
#[derive(Clone, Copy, Debug)]
pub struct ImagePlane {
    tan_x: f32,
    tan_y: f32,
}

impl ImagePlane {
    /// The point at normalised image coordinates `(x, y)`.
    #[inline]
    fn point(self, x: f32, y: f32) -> Vec3 {
        Vec3::new((2.0 * x - 1.0) * self.tan_x, (2.0 * y - 1.0) * self.tan_y, -1.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::builtin;

    #[test]
    fn cornell_box_placement_matches_cs184() {
        let scene = builtin::load().unwrap();
        let cam = Camera::from_scene(&scene);
        assert!((cam.target - Vec3::new(0.0, 0.75, 0.0)).length() < 1e-4, "{}", cam.target);
        assert!((cam.r - 4.8023).abs() < 1e-3, "{}", cam.r);
        assert!((cam.pos - Vec3::new(0.0, 0.75, 4.8023)).length() < 1e-3, "{}", cam.pos);
        assert!((cam.hfov_deg - 49.134).abs() < 1e-2 && (cam.vfov_deg - 37.849).abs() < 1e-2);
        assert!((cam.screen_dist - 875.0).abs() < 0.5, "{}", cam.screen_dist);
        let mut c = cam.clone();
        c.set_screen_size(480, 360);
        assert!((c.hfov_deg - 30.67).abs() < 0.01 && (c.vfov_deg - 23.25).abs() < 0.01, "{} {}", c.hfov_deg, c.vfov_deg);
    }

    #[test]
    fn thin_lens_rays_meet_the_pinhole_ray_on_the_focal_plane() {
        let scene = builtin::load().unwrap();
        let mut cam = Camera::from_scene(&scene);
        cam.lens_radius = 0.3;
        cam.focal_distance = 3.5;
        let axis = -cam.c2w.z_axis;
        for (x, y) in [(0.5, 0.5), (0.1, 0.8), (0.93, 0.2)] {
            let pin = cam.generate_ray(x, y);
            let t = 3.5 / pin.dir.dot(axis);
            let on_plane = pin.origin + pin.dir * t;
            for u in [(0.0, 0.0), (0.999, 0.25), (0.5, 0.7), (0.2, 0.99)] {
                let r = cam.generate_ray_thin_lens(x, y, u);
                let off = (r.origin - cam.pos).length();
                assert!(off <= 0.3 * 1.0001 && (r.origin - cam.pos).dot(axis).abs() < 1e-5, "origin off the lens: {off}");
                let t = (on_plane - r.origin).dot(axis) / r.dir.dot(axis);
                assert!((r.origin + r.dir * t - on_plane).length() < 1e-4, "{x},{y} {u:?}");
            }
        }
        // The lens centre is the pinhole.
        let (a, b) = (cam.generate_ray(0.3, 0.6), cam.generate_ray_thin_lens(0.3, 0.6, (0.0, 0.0)));
        assert!((a.dir - b.dir).length() < 1e-6 && a.origin == b.origin);
    }

    #[test]
    fn settings_round_trip() {
        let scene = builtin::load().unwrap();
        let cam = Camera::from_scene(&scene);
        let mut back = cam.clone();
        back.hfov_deg = 1.0;
        back.parse_settings(&cam.to_settings()).unwrap();
        assert_eq!(back, cam);
        assert!(back.parse_settings("1 2 3").is_err());
    }
}
