//! LRTF correction mode: a low-dimensional, smooth correction of the lens's outgoing
//! (scene-side) rays, fitted to the captures and then baked into a corrected LRTF table.
//!
//! **Basis.** A ray on the scene side is described by where it crosses the entrance-pupil plane,
//! `P` (normalised by the entrance pupil's radius, so the rim is |P| = 1), and its slope
//! `w = (dx/dz, dy/dz)` (normalised by the tangent of the field angle at the sensor's corner, so
//! the corner is |H| = 1). The correction changes the slope, keeping the pupil point:
//! `w_corrected = w + 10⁻³ Σ c_k g_k(P, H)`, with `c_k` in milliradians of slope at the rim and
//! the corner, and `g_k` the pupil gradients of the Seidel wavefront terms and
//! their first fifth-order companions:
//!
//! | name | wavefront term | order |
//! |---|---|---|
//! | `correction.defocus` | W020 ρ² | focus |
//! | `correction.scale` | W111 (P·H) | image scale (focal length) |
//! | `correction.spherical` | W040 ρ⁴ | third (Seidel) |
//! | `correction.coma` | W131 ρ² (P·H) | third |
//! | `correction.astigmatism` | W222 (P·H)² | third |
//! | `correction.field_curvature` | W220 ρ² H² | third |
//! | `correction.distortion` | W311 H² (P·H) | third |
//! | `correction.spherical5` | W060 ρ⁶ | fifth |
//! | `correction.coma5` | W151 ρ⁴ (P·H) | fifth (linear coma) |
//! | `correction.oblique_spherical_tangential` | W242 ρ² (P·H)² | fifth |
//! | `correction.oblique_spherical_sagittal` | W240 ρ⁴ H² | fifth |
//! | `correction.cubic_coma` | W333 (P·H)³ | fifth (elliptical coma) |
//! | `correction.elliptical_coma` | W331 ρ² H² (P·H) | fifth (elliptical coma) |
//! | `correction.astigmatism5` | W422 H² (P·H)² | fifth |
//! | `correction.field_curvature5` | W420 ρ² H⁴ | fifth |
//! | `correction.distortion5` | W511 H⁴ (P·H) | fifth |
//!
//! | `correction.pupil_scale` | — | the pupil: parts per thousand |
//!
//! `pupil_scale` is the one term that changes which rays pass: the corrected lens's ray through
//! pupil point P is the start lens's ray through `P (1 + 10⁻³ pupil_scale)` (with the slope
//! change), so the stop cuts the corrected lens's pupil smaller or larger — the effective
//! aperture of a lens whose f-number scale or pupil magnification the start lens gets wrong
//! (without it, a start lens with a different focal length puts every stopped-down defocus disc
//! at the wrong size: 14–18 % residuals on those captures).
//!
//! Each term `ρ^{2a} (P·H)^b H^{2c}` contributes its pupil gradient
//! `H^{2c} (2a ρ^{2a−2} (P·H)^b P + b ρ^{2a} (P·H)^{b−1} H) / (2a + b)`, which is 1 at the rim
//! and the corner (P = H, |P| = 1); the table is every rotationally symmetric wavefront
//! monomial up to the sixth order that moves rays (H^{2c} alone is a piston). //! (ρ² = P·P, H² = H·H.) Why this basis: (1) it is
//! rotationally symmetric (every g turns with the ray), so the corrected lens still has a 3-D
//! LRTF; (2) every term is the gradient of a wavefront polynomial, so the correction is a
//! realisable aberration (curl-free, as a real lens's transverse ray errors are); (3) it is
//! ordered by the orders in which lenses differ (a different prescription of the same kind
//! shows mostly as defocus, scale, spherical, coma, astigmatism, field curvature and
//! distortion), so a handful of coefficients cover what a start lens gets wrong, and each has a
//! name a lens designer reads. It is monochromatic: lateral and axial colour are not in it.
//!
//! **Directions.** The forward model goes scene → film: a ray from the source through pupil point
//! `P` with slope `w'` is the corrected lens's ray; the start lens traces the ray through the
//! same `P` with slope `w' − Δ(P, H(w'))`, which is explicit. The corrected film → scene table is
//! baked with the inverse: a film ray whose start-lens scene ray has slope `w` leaves with the
//! `w'` solving `w' = w + Δ(P, H(w'))` (fixed-point iteration; Δ is small and smooth).
//!
//! **Why the forward model traces the start lens exactly.** A table always belongs to its lens
//! (its header carries the lens's hash), and the exact trace is the map the table samples, without
//! the table's interpolation error (0.3–1.2 px scene → film at 96³–192³, too coarse for
//! sub-pixel spot fitting); the baked start table (`[lens] table`) sets the output table's
//! resolution, film radius and wavelengths.

use glam::{DVec2, DVec3};
use petzval_optics::{pupil, Lens, Ray};
use std::str::FromStr;

/// One term of the correction basis (see the module's table), by its wavefront monomial
/// `ρ^{2a} (P·H)^b H^{2c}`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Term {
    /// Index into [`TERM_NAMES`] and [`Coefficients`].
    index: usize,
}

/// Number of terms: the slope terms of [`TERM_NAMES`], then `pupil_scale`.
pub const TERMS: usize = SLOPE_TERMS + 1;

/// Number of slope terms.
pub const SLOPE_TERMS: usize = 16;

/// The index of `pupil_scale` in [`Coefficients`].
const PUPIL_SCALE: usize = SLOPE_TERMS;

/// Every slope term: manifest name (after `correction.`) and exponents (a, b, c), in coefficient
/// order.
pub const TERM_NAMES: [(&str, [u32; 3]); SLOPE_TERMS] = [
    ("defocus", [1, 0, 0]),
    ("scale", [0, 1, 0]),
    ("spherical", [2, 0, 0]),
    ("coma", [1, 1, 0]),
    ("astigmatism", [0, 2, 0]),
    ("field_curvature", [1, 0, 1]),
    ("distortion", [0, 1, 1]),
    ("spherical5", [3, 0, 0]),
    ("coma5", [2, 1, 0]),
    ("oblique_spherical_tangential", [1, 2, 0]),
    ("oblique_spherical_sagittal", [2, 0, 1]),
    ("cubic_coma", [0, 3, 0]),
    ("elliptical_coma", [1, 1, 1]),
    ("astigmatism5", [0, 2, 1]),
    ("field_curvature5", [1, 0, 2]),
    ("distortion5", [0, 1, 2]),
];

impl Term {
    /// Every term, in coefficient order.
    pub fn all() -> impl Iterator<Item = Term> {
        (0..TERMS).map(|index| Term { index })
    }

    /// Index into [`Coefficients`].
    pub fn index(self) -> usize {
        self.index
    }

    /// The manifest name after `correction.`.
    pub fn name(self) -> &'static str {
        TERM_NAMES.get(self.index).map_or("pupil_scale", |t| t.0)
    }

    /// The term's normalised pupil gradient at pupil point `p` and field `h` (zero for
    /// `pupil_scale`, which is no slope term).
    fn gradient(self, p: DVec2, h: DVec2) -> DVec2 {
        let Some(&(_, [a, b, c])) = TERM_NAMES.get(self.index) else { return DVec2::ZERO };
        let (rho2, q, h2) = (p.length_squared(), p.dot(h), h.length_squared());
        let field = h2.powi(c as i32);
        let along_p = if a > 0 { 2.0 * a as f64 * rho2.powi(a as i32 - 1) * q.powi(b as i32) } else { 0.0 };
        let along_h = if b > 0 { b as f64 * rho2.powi(a as i32) * q.powi(b as i32 - 1) } else { 0.0 };
        (p * along_p + h * along_h) * (field / (2 * a + b) as f64)
    }
}

impl FromStr for Term {
    type Err = String;
    fn from_str(s: &str) -> Result<Term, String> {
        if s == "pupil_scale" {
            return Ok(Term { index: PUPIL_SCALE });
        }

        TERM_NAMES.iter().position(|(n, _)| *n == s).map(|index| Term { index }).ok_or_else(|| {
            format!(
                "unknown correction term '{s}': expected one of {}, pupil_scale",
                TERM_NAMES.map(|(n, _)| n).join(", ")
            )
        })
    }
}

/// The coefficients: milliradians of slope at the rim and the corner, in [`TERM_NAMES`] order,
/// then `pupil_scale` in parts per thousand.
pub type Coefficients = [f64; TERMS];

/// The normalisation of the basis, fixed from the start lens for a whole fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Basis {
    /// The entrance-pupil plane (lens frame z).
    pub pupil_z_mm: f64,
    /// The fully open entrance pupil's radius.
    pub pupil_radius_mm: f64,
    /// tan of the field angle at the sensor's corner (the slope that is |H| = 1).
    pub corner_slope: f64,
}

impl Basis {
    /// The basis of a start lens with a sensor of half-diagonal `corner_mm` (focused at infinity).
    pub fn new(lens: &Lens, corner_mm: f64) -> Basis {
        let open = lens.with_stop_semi_diameter(lens.max_stop_semi_diameter_mm()).unwrap_or_else(|_| lens.clone());
        let px = open.paraxial();
        let film_z = lens.last_vertex_z_mm() + lens.design_back_focus_mm();
        let circle = pupil::image_circle_radius_mm(lens, film_z, corner_mm);
        let angle_deg = pupil::field_angle_deg(lens, circle.min(corner_mm) * 0.999, 0.0, film_z).unwrap_or(20.0);
        Basis {
            pupil_z_mm: px.entrance_pupil_z_mm,
            pupil_radius_mm: (0.5 * px.entrance_pupil_diameter_mm).max(1e-3),
            corner_slope: angle_deg.clamp(1.0, 85.0).to_radians().tan(),
        }
    }
}

/// A correction: the basis and its coefficients.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Correction {
    /// Normalisation.
    pub basis: Basis,
    /// Coefficients (mrad).
    pub coefficients: Coefficients,
}

impl Correction {
    /// Whether every coefficient is zero (the start lens itself).
    pub fn is_zero(&self) -> bool {
        self.coefficients.iter().all(|c| *c == 0.0)
    }

    /// `1 + pupil_scale`: the start lens's pupil point of the corrected lens's ray through P is
    /// `P · (1 + pupil_scale)`.
    fn pupil_factor(&self) -> f64 {
        1.0 + 1e-3 * self.coefficients[PUPIL_SCALE]
    }

    /// Δ, the change of slope of the ray through pupil point `p_mm` (on the pupil plane) with
    /// slope `slope`.
    pub fn delta_slope(&self, p_mm: DVec2, slope: DVec2) -> DVec2 {
        let b = &self.basis;
        let (p, h) = (p_mm / b.pupil_radius_mm, slope / b.corner_slope);
        let sum = Term::all().take(SLOPE_TERMS).zip(&self.coefficients).fold(DVec2::ZERO, |acc, (t, c)| {
            if *c == 0.0 {
                acc
            } else {
                acc + t.gradient(p, h) * *c
            }
        });
        sum * 1e-3
    }

    /// Scene → film: the start-lens ray that stands for the corrected lens's ray from `origin`
    /// along `direction` (heading towards the film, +z): same pupil point, slope minus Δ, starting
    /// at the origin's depth.
    pub fn uncorrect_incoming(&self, origin: DVec3, direction: DVec3) -> Option<Ray> {
        if !(direction.z > 0.0) {
            return None;
        }
        let slope = DVec2::new(direction.x, direction.y) / direction.z;
        let t = (self.basis.pupil_z_mm - origin.z) / direction.z;
        let p = DVec2::new(origin.x, origin.y) + slope * (t * direction.z);
        let w = slope - self.delta_slope(p, slope);
        let p0 = p * self.pupil_factor();
        let back = self.basis.pupil_z_mm - origin.z;
        let start = DVec3::new(p0.x - w.x * back, p0.y - w.y * back, origin.z);
        Some(Ray::new(start, DVec3::new(w.x, w.y, 1.0)))
    }

    /// Film → scene: the corrected lens's outgoing ray for the start lens's outgoing `ray`
    /// (heading towards the scene, −z): same pupil point, the slope solving `w' = w + Δ(P, w')`.
    /// The returned ray starts 1 m behind the pupil point (film side), on the same line.
    pub fn correct_outgoing(&self, ray: &Ray) -> Option<Ray> {
        let d = ray.direction;
        if !(d.z < 0.0) {
            return None;
        }
        let w = DVec2::new(d.x, d.y) / d.z;
        let t = (self.basis.pupil_z_mm - ray.origin.z) / d.z;
        let p3 = ray.origin + d * t;
        let p = DVec2::new(p3.x, p3.y) / self.pupil_factor();
        // fixed point: Δ is a small, smooth function of the slope
        let mut wc = w;
        for _ in 0..8 {
            let next = w + self.delta_slope(p, wc);
            let converged = (next - wc).length() < 1e-15;
            wc = next;
            if converged {
                break;
            }
        }
        let dir = -DVec3::new(wc.x, wc.y, 1.0).normalize();
        (wc.is_finite()).then(|| Ray::new(DVec3::new(p.x, p.y, self.basis.pupil_z_mm) - dir * 1000.0, dir))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn correction() -> Correction {
        Correction {
            basis: Basis { pupil_z_mm: 30.0, pupil_radius_mm: 9.0, corner_slope: 0.45 },
            coefficients: [0.3, -0.2, 0.5, 0.4, -0.3, 0.2, 0.6, -0.1, 0.2, 0.1, -0.2, 0.3, 0.1, -0.1, 0.2, 0.1, 4.0],
        }
    }

    #[test]
    fn terms_are_one_at_the_rim_and_the_corner() {
        let (p, h) = (DVec2::new(0.6, 0.8), DVec2::new(0.6, 0.8));
        for t in Term::all().take(SLOPE_TERMS) {
            assert!((t.gradient(p, h).length() - 1.0).abs() < 1e-12, "{}", t.name());
            assert_eq!(t.name().parse::<Term>().unwrap(), t);
        }
    }

    #[test]
    fn the_basis_turns_with_the_ray() {
        let rot = glam::DMat2::from_angle(0.7);
        let (p, h) = (DVec2::new(0.3, -0.5), DVec2::new(0.7, 0.2));
        for t in Term::all() {
            let a = rot * t.gradient(p, h);
            let b = t.gradient(rot * p, rot * h);
            assert!((a - b).length() < 1e-12, "{}", t.name());
        }
    }

    #[test]
    fn terms_are_gradients_of_their_wavefronts() {
        // central differences of ρ^{2a} (P·H)^b H^{2c} in P, over (2a + b)
        let (p, h) = (DVec2::new(0.3, -0.5), DVec2::new(0.7, 0.2));
        for (k, t) in Term::all().take(SLOPE_TERMS).enumerate() {
            let [a, b, c] = TERM_NAMES[k].1;
            let w = |p: DVec2| {
                p.length_squared().powi(a as i32) * p.dot(h).powi(b as i32) * h.length_squared().powi(c as i32)
                    / (2 * a + b) as f64
            };
            let e = 1e-6;
            let g = DVec2::new(
                (w(p + DVec2::X * e) - w(p - DVec2::X * e)) / (2.0 * e),
                (w(p + DVec2::Y * e) - w(p - DVec2::Y * e)) / (2.0 * e),
            );
            assert!((g - t.gradient(p, h)).length() < 1e-8, "{}", t.name());
        }
    }

    #[test]
    fn outgoing_correction_inverts_the_incoming_one() {
        // a corrected outgoing ray, reversed and un-corrected, is the start-lens ray again
        let c = correction();
        for k in 0..50 {
            let a = k as f64 * 0.37;
            let origin = DVec3::new(3.0 * a.cos(), 2.0 * a.sin(), 10.0);
            let dir = DVec3::new(0.2 * (1.3 * a).sin(), 0.15 * (0.7 * a).cos(), -1.0).normalize();
            let start = Ray::new(origin, dir);
            let corrected = c.correct_outgoing(&start).unwrap();
            let back_origin = corrected.origin + corrected.direction * 2000.0;
            let un = c.uncorrect_incoming(back_origin, -corrected.direction).unwrap();
            // the same line as the start-lens ray (reversed)
            let s = DVec2::new(start.direction.x, start.direction.y) / start.direction.z;
            let u = DVec2::new(un.direction.x, un.direction.y) / un.direction.z;
            assert!((s - u).length() < 1e-12, "slope {s} vs {u}");
            let t = (30.0 - un.origin.z) / un.direction.z;
            let pu = un.origin + un.direction * t;
            let ts = (30.0 - start.origin.z) / start.direction.z;
            let ps = start.origin + start.direction * ts;
            assert!((pu - ps).length() < 1e-9, "pupil point {pu} vs {ps}");
        }
    }
}
