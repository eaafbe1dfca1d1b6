//! Fresnel reflectance, exact (no Schlick): the unpolarised average of the
//! s and p reflectances of a smooth interface.
//!
//! CS184 uses Schlick's approximation with the outside angle for glass, which
//! inside the glass near the critical angle gives 0.035 where the exact value
//! is 0.43 (ior 1.45, 43 degrees), and the pbrt-v2 approximation for
//! conductors (about 1 % off for copper at 75 degrees).

use glam::Vec3;

/// Reflectance of a dielectric interface for light arriving at `cos_i`
/// (cosine to the normal, > 0 on the incident side) when the relative index
/// is `eta` = eta_transmitted / eta_incident. 1 under total internal
/// reflection.
pub fn dielectric(cos_i: f32, eta: f32) -> f32 {
    let cos_i = cos_i.clamp(0.0, 1.0) as f64;
    let eta = eta as f64;
    let sin2_t = (1.0 - cos_i * cos_i) / (eta * eta);
    if sin2_t >= 1.0 {
        return 1.0;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    let rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    let rp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    (0.5 * (rs * rs + rp * rp)) as f32
}

/// Cosine of the transmitted direction for `cos_i` and relative index `eta`
/// (= eta_t / eta_i), or `None` under total internal reflection.
pub fn cos_transmitted(cos_i: f32, eta: f32) -> Option<f32> {
    let sin2_t = (1.0 - cos_i * cos_i).max(0.0) / (eta * eta);
    (sin2_t < 1.0).then(|| (1.0 - sin2_t).sqrt())
}

#[derive(Clone, Copy, Debug)]
struct Complex {
    re: f64,
    im: f64,
}

impl Complex {
    fn new(re: f64, im: f64) -> Self {
        Complex { re, im }
    }
    fn add(self, o: Complex) -> Complex {
        Complex::new(self.re + o.re, self.im + o.im)
    }
    fn sub(self, o: Complex) -> Complex {
        Complex::new(self.re - o.re, self.im - o.im)
    }
    fn mul(self, o: Complex) -> Complex {
        Complex::new(self.re * o.re - self.im * o.im, self.re * o.im + self.im * o.re)
    }
    fn div(self, o: Complex) -> Complex {
        let d = o.re * o.re + o.im * o.im;
        Complex::new((self.re * o.re + self.im * o.im) / d, (self.im * o.re - self.re * o.im) / d)
    }
    fn norm2(self) -> f64 {
        self.re * self.re + self.im * self.im
    }
    /// The principal square root (non-negative real part).
    fn sqrt(self) -> Complex {
        let r = self.norm2().sqrt();
        let re = (0.5 * (r + self.re)).max(0.0).sqrt();
        let im = (0.5 * (r - self.re)).max(0.0).sqrt();
        Complex::new(re, if self.im < 0.0 { -im } else { im })
    }
}

/// Reflectance of a conductor of complex index `eta + i k` in vacuum, for
/// light arriving at `cos_i`: the exact unpolarised Fresnel equations.
pub fn conductor_channel(cos_i: f32, eta: f32, k: f32) -> f32 {
    let c = (cos_i as f64).clamp(0.0, 1.0);
    let n = Complex::new(eta as f64, k as f64);
    let sin2_i = Complex::new(1.0 - c * c, 0.0);
    let sin2_t = sin2_i.div(n.mul(n));
    let cos_t = Complex::new(1.0, 0.0).sub(sin2_t).sqrt();
    let ci = Complex::new(c, 0.0);
    let r_parl = n.mul(ci).sub(cos_t).div(n.mul(ci).add(cos_t));
    let r_perp = ci.sub(n.mul(cos_t)).div(ci.add(n.mul(cos_t)));
    (0.5 * (r_parl.norm2() + r_perp.norm2())) as f32
}

pub fn conductor(cos_i: f32, eta: Vec3, k: Vec3) -> Vec3 {
    Vec3::new(conductor_channel(cos_i, eta.x, k.x), conductor_channel(cos_i, eta.y, k.y), conductor_channel(cos_i, eta.z, k.z))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dielectric_matches_the_tabulated_values() {
        // Fresnel's equations for unpolarised light at ior 1.45, evaluated
        // independently (to 4 places) at 0, 40 and 80 degrees.
        let deg = |d: f32| d.to_radians().cos();
        assert!((dielectric(1.0, 1.45) - 0.0337).abs() < 1e-4);
        assert!((dielectric(deg(40.0), 1.45) - 0.0391).abs() < 2e-4);
        assert!((dielectric(deg(80.0), 1.45) - 0.3784).abs() < 2e-4);
        // Inside the glass near the critical angle (43.6 degrees).
        assert!((dielectric(deg(40.0), 1.0 / 1.45) - 0.1464).abs() < 2e-4);
        assert!((dielectric(deg(43.0), 1.0 / 1.45) - 0.4328).abs() < 5e-3, "{}", dielectric(deg(43.0), 1.0 / 1.45));
        assert_eq!(dielectric(deg(60.0), 1.0 / 1.45), 1.0);
        assert!(cos_transmitted(deg(60.0), 1.0 / 1.45).is_none());
        // Grazing: everything reflects.
        assert!((dielectric(0.0, 1.45) - 1.0).abs() < 1e-6);
    }

    #[test]
    fn conductor_reduces_to_the_dielectric_without_absorption_and_to_known_values() {
        for c in [1.0f32, 0.8, 0.5, 0.2, 0.05] {
            assert!((conductor_channel(c, 1.45, 0.0) - dielectric(c, 1.45)).abs() < 1e-5, "{c}");
        }
        // Normal incidence: ((n-1)^2 + k^2) / ((n+1)^2 + k^2).
        let (n, k) = (0.33228f32, 3.1646f32);
        let r0 = ((n - 1.0).powi(2) + k * k) / ((n + 1.0).powi(2) + k * k);
        assert!((conductor_channel(1.0, n, k) - r0).abs() < 1e-5);
        // Copper red channel at 75 degrees: the notes' exact value 0.8863.
        assert!((conductor_channel(75f32.to_radians().cos(), n, k) - 0.8863).abs() < 1e-3, "{}", conductor_channel(75f32.to_radians().cos(), n, k));
        assert!((conductor_channel(0.0, n, k) - 1.0).abs() < 1e-5);
    }
}
