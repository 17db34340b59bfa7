//! Fresnel reflectance: exact unpolarised dielectric and conductor (complex IOR) formulas, and
//! Snell refraction. Dielectric `eta` is always interior/exterior; a negative cosine means the
//! incident direction is inside.

use glam::Vec3;

/// Unpolarised Fresnel reflectance of a dielectric interface. `cos_i` is the cosine between the
/// incident direction and the normal (negative when coming from inside), `eta` interior/exterior.
/// Returns 1 under total internal reflection.
pub fn dielectric(cos_i: f32, eta: f32) -> f32 {
    let (cos_i, eta) = if cos_i < 0.0 { (-cos_i, 1.0 / eta) } else { (cos_i, eta) };
    let cos_i = cos_i.min(1.0);
    let sin2_i = (1.0 - cos_i * cos_i).max(0.0);
    let sin2_t = sin2_i / (eta * eta);
    if !(sin2_t < 1.0) {
        return 1.0;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    let r_parl = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    let r_perp = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    (0.5 * (r_parl * r_parl + r_perp * r_perp)).clamp(0.0, 1.0)
}

/// Minimal complex arithmetic for the conductor formula (f64: the intermediate terms of grazing
/// angles with large `k` lose too many digits in f32).
#[derive(Clone, Copy)]
struct C(f64, f64);

impl C {
    fn add(self, o: C) -> C {
        C(self.0 + o.0, self.1 + o.1)
    }
    fn sub(self, o: C) -> C {
        C(self.0 - o.0, self.1 - o.1)
    }
    fn mul(self, o: C) -> C {
        C(self.0 * o.0 - self.1 * o.1, self.0 * o.1 + self.1 * o.0)
    }
    fn scale(self, s: f64) -> C {
        C(self.0 * s, self.1 * s)
    }
    fn div(self, o: C) -> C {
        let d = o.0 * o.0 + o.1 * o.1;
        C((self.0 * o.0 + self.1 * o.1) / d, (self.1 * o.0 - self.0 * o.1) / d)
    }
    fn norm(self) -> f64 {
        self.0 * self.0 + self.1 * self.1
    }
    fn sqrt(self) -> C {
        let r = self.norm().sqrt();
        let re = (0.5 * (r + self.0)).max(0.0).sqrt();
        let im = (0.5 * (r - self.0)).max(0.0).sqrt();
        C(re, if self.1 < 0.0 { -im } else { im })
    }
}

/// Fresnel reflectance of one channel of a conductor with complex IOR `eta + i k`.
fn conductor_channel(cos_i: f64, eta: f64, k: f64) -> f64 {
    // A zero IOR would divide by zero; physically meaningless, so keep it a tiny positive value.
    let n = C(eta.max(1e-4), k.max(0.0));
    let sin2_i = 1.0 - cos_i * cos_i;
    let sin2_t = C(sin2_i, 0.0).div(n.mul(n));
    let cos_t = C(1.0, 0.0).sub(sin2_t).sqrt();
    let ci = C(cos_i, 0.0);
    let r_parl = n.scale(cos_i).sub(cos_t).div(n.scale(cos_i).add(cos_t));
    let r_perp = ci.sub(n.mul(cos_t)).div(ci.add(n.mul(cos_t)));
    let f = 0.5 * (r_parl.norm() + r_perp.norm());
    if f.is_finite() {
        f.clamp(0.0, 1.0)
    } else {
        1.0
    }
}

/// Conductor Fresnel reflectance per RGB channel; `cos_i` is clamped to [0, 1].
pub fn conductor(cos_i: f32, eta: Vec3, k: Vec3) -> Vec3 {
    let c = (cos_i as f64).clamp(0.0, 1.0);
    Vec3::new(
        conductor_channel(c, eta.x as f64, k.x as f64) as f32,
        conductor_channel(c, eta.y as f64, k.y as f64) as f32,
        conductor_channel(c, eta.z as f64, k.z as f64) as f32,
    )
}

/// Refract `w` (pointing away from the surface) through the interface with normal `n` and
/// relative IOR `eta` = η behind `n` (interior) / η on the side `n` points to (exterior). Returns the
/// transmitted direction and `etap` = η on the transmitted side / η on `w`'s side, or `None`
/// under total internal reflection.
pub fn refract(w: Vec3, n: Vec3, eta: f32) -> Option<(Vec3, f32)> {
    let mut cos_i = w.dot(n);
    let (mut eta, mut n) = (eta, n);
    if cos_i < 0.0 {
        eta = 1.0 / eta;
        cos_i = -cos_i;
        n = -n;
    }
    let sin2_i = (1.0 - cos_i * cos_i).max(0.0);
    let sin2_t = sin2_i / (eta * eta);
    if !(sin2_t < 1.0) {
        return None;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    let wt = -w / eta + (cos_i / eta - cos_t) * n;
    Some((wt.normalize_or_zero(), eta))
}
