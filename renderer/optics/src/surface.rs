//! Surface geometry: sag, normal and numerically stable ray intersection for plane, spherical,
//! conic / even- and odd-aspheric and cylindrical surfaces, in the surface's local frame (vertex at the
//! origin, +z towards the film).

use super::prescription::CylinderAxis;
use glam::DVec3;

/// Most Newton iterations for an aspheric intersection before the ray is absorbed.
const MAX_NEWTON_ITERATIONS: usize = 32;
/// Newton convergence tolerance on the ray parameter (mm).
const NEWTON_TOLERANCE_MM: f64 = 1e-13;

/// The shape of one surface.
#[derive(Debug, Clone, PartialEq)]
pub struct Shape {
    /// Curvature 1/R (0 = plane).
    pub curvature_per_mm: f64,
    /// Conic constant k.
    pub conic: f64,
    /// Coefficient A2 of r² (Zemax EVENASPH PARM 1); adds 2·A2 to the paraxial curvature.
    pub a2: f64,
    /// Aspheric coefficients A4, A6, ... of r⁴, r⁶, ...
    pub aspheric: Vec<f64>,
    /// Odd aspheric coefficients B1, B3, B5, ... of r¹, r³, r⁵, ... (Zemax ODDASPHE); they do
    /// not enter the paraxial curvature.
    pub aspheric_odd: Vec<f64>,
    /// Cylindrical: curved only along this axis.
    pub cylinder: Option<CylinderAxis>,
}

impl Shape {
    /// A plane.
    pub fn plane() -> Self {
        Shape {
            curvature_per_mm: 0.0,
            conic: 0.0,
            a2: 0.0,
            aspheric: Vec::new(),
            aspheric_odd: Vec::new(),
            cylinder: None,
        }
    }

    /// Whether the shape is a plane.
    pub fn is_plane(&self) -> bool {
        self.curvature_per_mm == 0.0 && !self.has_polynomial()
    }

    /// Whether polynomial (A2, A4, ..., or odd B1, B3, ...) terms are present.
    #[inline]
    pub fn has_polynomial(&self) -> bool {
        self.a2 != 0.0 || self.aspheric.iter().any(|a| *a != 0.0) || self.aspheric_odd.iter().any(|b| *b != 0.0)
    }

    /// Paraxial curvature c + 2·A2.
    pub fn paraxial_curvature_per_mm(&self) -> f64 {
        self.curvature_per_mm + 2.0 * self.a2
    }

    /// Whether the surface is rotationally symmetric about the axis.
    pub fn is_rotationally_symmetric(&self) -> bool {
        self.cylinder.is_none() || self.is_plane()
    }

    /// The squared radial coordinate that the sag depends on.
    #[inline]
    fn r2(&self, x: f64, y: f64) -> f64 {
        match self.cylinder {
            None => x * x + y * y,
            Some(CylinderAxis::X) => x * x,
            Some(CylinderAxis::Y) => y * y,
        }
    }

    /// Sag z(r²) and its derivative dz/d(r²); `None` where the conic is undefined.
    #[inline]
    pub fn sag_and_slope(&self, r2: f64) -> Option<(f64, f64)> {
        let c = self.curvature_per_mm;
        let k1 = 1.0 + self.conic;
        let radicand = 1.0 - k1 * c * c * r2;
        if radicand < 0.0 {
            return None;
        }
        let root = radicand.sqrt();
        // c r² / (1 + √(1 − (1+k)c²r²)): no cancellation for small c.
        let mut sag = c * r2 / (1.0 + root) + self.a2 * r2;
        let mut slope = if root > 0.0 { 0.5 * c / root } else { f64::INFINITY } + self.a2;
        let mut power = r2; // r^(2j) for j = 1 → multiply before use
        for (j, a) in self.aspheric.iter().enumerate() {
            // term A_{2(j+2)} r^{2(j+2)} = A (r²)^(j+2)
            let order = (j + 2) as f64;
            slope += a * order * power; // d/d(r²) of (r²)^(j+2) = (j+2) (r²)^(j+1)
            power *= r2;
            sag += a * power;
        }
        if !self.aspheric_odd.is_empty() {
            // term B_i r^i (i = 1, 3, 5, ...): d/d(r²) = (i/2) r^(i−2). On the axis itself the
            // r¹ term (a cone point) has no slope; it is taken as 0 there.
            let r = r2.sqrt();
            let mut power = r; // r^i
            for (j, b) in self.aspheric_odd.iter().enumerate() {
                let i = (2 * j + 1) as f64;
                sag += b * power;
                if r2 > 0.0 {
                    slope += b * 0.5 * i * power / r2;
                }
                power *= r2;
            }
        }
        Some((sag, slope))
    }

    /// Sag at (x, y); `None` outside the conic's domain.
    pub fn sag(&self, x: f64, y: f64) -> Option<f64> {
        self.sag_and_slope(self.r2(x, y)).map(|(s, _)| s)
    }

    /// Unit normal at a point on the surface (pointing towards +z on axis).
    pub fn normal(&self, p: DVec3) -> Option<DVec3> {
        if self.conic == 0.0 && !self.has_polynomial() && self.cylinder.is_none() {
            // Sphere: (−c x, −c y, 1 − c z) is already unit length on the surface, since
            // c(x² + y² + z²) − 2z = 0 there.
            let c = self.curvature_per_mm;
            return Some(DVec3::new(-c * p.x, -c * p.y, 1.0 - c * p.z));
        }
        let (_, slope) = self.sag_and_slope(self.r2(p.x, p.y))?;
        let (gx, gy) = match self.cylinder {
            None => (2.0 * p.x * slope, 2.0 * p.y * slope),
            Some(CylinderAxis::X) => (2.0 * p.x * slope, 0.0),
            Some(CylinderAxis::Y) => (0.0, 2.0 * p.y * slope),
        };
        let n = DVec3::new(-gx, -gy, 1.0);
        let len = n.length();
        if !len.is_finite() || len == 0.0 {
            return None;
        }
        Some(n / len)
    }

    /// Intersects the ray `o + t d` (local frame, |d| = 1) with the surface. Returns the
    /// parameter t ≥ 0 of the hit on the vertex-side sheet, or `None` (miss, grazing beyond the
    /// domain, or Newton failure). The caller clips by semi-diameter.
    pub fn intersect(&self, o: DVec3, d: DVec3) -> Option<f64> {
        if self.is_plane() {
            if d.z.abs() < 1e-300 {
                return None;
            }
            let t = -o.z / d.z;
            return (t >= 0.0).then_some(t);
        }
        // 1. Closed form for the quadric: c(ρ² + (1+k) z²) − 2z = 0, with ρ² the radial term.
        let c = self.curvature_per_mm;
        let k1 = 1.0 + self.conic;
        let (ox, oy, dx, dy) = match self.cylinder {
            None => (o.x, o.y, d.x, d.y),
            Some(CylinderAxis::X) => (o.x, 0.0, d.x, 0.0),
            Some(CylinderAxis::Y) => (0.0, o.y, 0.0, d.y),
        };
        let a = c * (dx * dx + dy * dy + k1 * d.z * d.z);
        let b = c * (ox * dx + oy * dy + k1 * o.z * d.z) - d.z;
        let cc = c * (ox * ox + oy * oy + k1 * o.z * o.z) - 2.0 * o.z;
        let disc = b * b - a * cc;
        let mut t = if disc < 0.0 {
            if !self.has_polynomial() {
                return None;
            }
            // The base conic is missed but the asphere may not be: start from the vertex plane.
            if d.z.abs() < 1e-300 {
                return None;
            }
            -o.z / d.z
        } else {
            // Both roots in stable form, t₁ = C / q and t₂ = q / A with q = −B − sign(B)√disc;
            // keep the nearest one ahead of the ray on the sheet through the vertex
            // ((1+k)·c·z ≤ 1). A ray starting beyond the centre of curvature meets the other
            // sheet first, so the choice cannot be made from the sign of B alone.
            let q = -b - b.signum() * disc.sqrt();
            let on_vertex_sheet = |t: f64| t.is_finite() && t >= 0.0 && k1 * c * (o.z + t * d.z) <= 1.0 + 1e-12;
            let t1 = if q != 0.0 { cc / q } else { f64::INFINITY };
            let t2 = if a != 0.0 { q / a } else { f64::INFINITY };
            match (on_vertex_sheet(t1), on_vertex_sheet(t2)) {
                (true, true) => t1.min(t2),
                (true, false) => t1,
                (false, true) => t2,
                (false, false) => {
                    if !self.has_polynomial() {
                        return None;
                    }
                    if d.z.abs() < 1e-300 {
                        return None;
                    }
                    -o.z / d.z
                }
            }
        };
        // 2. Polynomial terms: Newton on f(t) = z(t) − sag(ρ²(t)).
        if self.has_polynomial() {
            let mut converged = false;
            for _ in 0..MAX_NEWTON_ITERATIONS {
                let p = o + t * d;
                let r2 = self.r2(p.x, p.y);
                let (sag, slope) = self.sag_and_slope(r2)?;
                let dr2_dt = match self.cylinder {
                    None => 2.0 * (p.x * d.x + p.y * d.y),
                    Some(CylinderAxis::X) => 2.0 * p.x * d.x,
                    Some(CylinderAxis::Y) => 2.0 * p.y * d.y,
                };
                let f = p.z - sag;
                let df = d.z - slope * dr2_dt;
                if !df.is_finite() || df.abs() < 1e-15 {
                    return None;
                }
                let step = f / df;
                t -= step;
                if !t.is_finite() {
                    return None;
                }
                if step.abs() < NEWTON_TOLERANCE_MM {
                    converged = true;
                    break;
                }
            }
            if !converged {
                return None;
            }
        }
        // 3. The hit must lie ahead and on the sheet through the vertex (|c z| < 1 side).
        if t < 0.0 || !t.is_finite() {
            return None;
        }
        Some(t)
    }
}

/// Refracts unit direction `d` at unit normal `n` from index `n1` into `n2`. `None` on total
/// internal reflection.
#[inline]
pub fn refract(d: DVec3, n: DVec3, n1: f64, n2: f64) -> Option<DVec3> {
    // Orient the normal against the incoming ray.
    let (n, cos_i) = {
        let c = -n.dot(d);
        if c < 0.0 {
            (-n, -c)
        } else {
            (n, c)
        }
    };
    let eta = n1 / n2;
    let sin2_t = eta * eta * (1.0 - cos_i * cos_i).max(0.0);
    if sin2_t >= 1.0 {
        return None;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    // Unit length by construction (to rounding) when d and n are unit vectors.
    Some(eta * d + (eta * cos_i - cos_t) * n)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sphere(r: f64) -> Shape {
        Shape { curvature_per_mm: 1.0 / r, conic: 0.0, a2: 0.0, aspheric: vec![], aspheric_odd: vec![], cylinder: None }
    }

    #[test]
    fn sphere_hit_matches_geometry() {
        let s = sphere(50.0);
        let o = DVec3::new(3.0, 4.0, -10.0);
        let d = DVec3::new(0.0, 0.0, 1.0);
        let t = s.intersect(o, d).unwrap();
        let p = o + t * d;
        // point on sphere centred at (0,0,50) radius 50, on the vertex side
        assert!(((p - DVec3::new(0.0, 0.0, 50.0)).length() - 50.0).abs() < 1e-12);
        assert!(p.z < 1.0);
    }

    #[test]
    fn huge_radius_is_stable() {
        let s = sphere(1e5);
        let o = DVec3::new(10.0, 0.0, -1.0);
        let d = DVec3::new(0.0, 0.0, 1.0);
        let t = s.intersect(o, d).unwrap();
        // sag written without cancellation: r² / (R + √(R² − r²))
        let expected = 1.0 + 100.0 / (1e5 + (1e10f64 - 100.0).sqrt());
        assert!((t - expected).abs() < 1e-15, "{t} vs {expected}");
    }

    #[test]
    fn negative_sphere_backwards_ray() {
        let s = sphere(-20.0);
        let o = DVec3::new(1.0, 0.5, 30.0);
        let d = DVec3::new(0.0, 0.0, -1.0);
        let t = s.intersect(o, d).unwrap();
        let p = o + t * d;
        assert!(((p - DVec3::new(0.0, 0.0, -20.0)).length() - 20.0).abs() < 1e-12);
        assert!(p.z > -1.0);
    }

    #[test]
    fn origin_beyond_the_centre_of_curvature() {
        // R < 0, ray starting more than |R| in front of the vertex
        let s = sphere(-101.3);
        let t = s.intersect(DVec3::new(0.0, 5.0, -150.0), DVec3::Z).unwrap();
        let z = -150.0 + t;
        let expected = -(101.3 - (101.3f64 * 101.3 - 25.0).sqrt());
        assert!((z - expected).abs() < 1e-12, "{z} vs {expected}");
        // R > 0, traced backwards from more than R behind the vertex
        let s = sphere(40.0);
        let t = s.intersect(DVec3::new(0.0, 3.0, 90.0), DVec3::NEG_Z).unwrap();
        let z = 90.0 - t;
        let expected = 40.0 - (1600.0f64 - 9.0).sqrt();
        assert!((z - expected).abs() < 1e-12, "{z} vs {expected}");
    }

    #[test]
    fn asphere_sag_and_intersection_agree() {
        let s = Shape {
            curvature_per_mm: 1.0 / 19.865,
            conic: 0.0,
            a2: 0.0,
            aspheric: vec![-1.5313e-05, 9.4893e-08, -1.8128e-09, 8.7528e-12],
            aspheric_odd: vec![],
            cylinder: None,
        };
        let o = DVec3::new(2.0, -3.0, -5.0);
        let d = DVec3::new(0.05, 0.02, 1.0).normalize();
        let t = s.intersect(o, d).unwrap();
        let p = o + t * d;
        assert!((p.z - s.sag(p.x, p.y).unwrap()).abs() < 1e-12);
    }

    /// Odd terms (r¹, r³, r⁵): the sag is the sum written out, the hit lies on it, and the
    /// normal is the sag's numerical gradient, for the round surface and a cylinder.
    #[test]
    fn odd_asphere_sag_normal_and_intersection_agree() {
        for cylinder in [None, Some(CylinderAxis::Y)] {
            let s = Shape {
                curvature_per_mm: 1.0 / 30.0,
                conic: -0.5,
                a2: 0.0,
                aspheric: vec![2e-6],
                aspheric_odd: vec![1e-3, 1e-5, -2e-8],
                cylinder,
            };
            let (x, y) = (1.2, -2.5);
            let r2: f64 = if cylinder.is_none() { x * x + y * y } else { y * y };
            let r: f64 = r2.sqrt();
            let c = 1.0 / 30.0;
            let conic = c * r2 / (1.0 + (1.0 - 0.5 * c * c * r2).sqrt());
            let expected = conic + 2e-6 * r2 * r2 + 1e-3 * r + 1e-5 * r * r2 - 2e-8 * r * r2 * r2;
            assert!((s.sag(x, y).unwrap() - expected).abs() < 1e-15, "{cylinder:?}");
            let h = 1e-6;
            let gx = (s.sag(x + h, y).unwrap() - s.sag(x - h, y).unwrap()) / (2.0 * h);
            let gy = (s.sag(x, y + h).unwrap() - s.sag(x, y - h).unwrap()) / (2.0 * h);
            let n = s.normal(DVec3::new(x, y, expected)).unwrap();
            let g = DVec3::new(-gx, -gy, 1.0).normalize();
            assert!((n - g).length() < 1e-8, "{cylinder:?}: {n} vs {g}");
            let o = DVec3::new(2.0, -3.0, -5.0);
            let d = DVec3::new(0.05, 0.02, 1.0).normalize();
            let p = o + s.intersect(o, d).unwrap() * d;
            assert!((p.z - s.sag(p.x, p.y).unwrap()).abs() < 1e-12, "{cylinder:?}");
            // on the axis the cone point has a finite sag and the axial normal
            assert_eq!(s.sag(0.0, 0.0), Some(0.0));
            assert_eq!(s.normal(DVec3::ZERO), Some(DVec3::Z));
        }
    }

    #[test]
    fn snell_law_holds() {
        let d = DVec3::new(0.3, 0.0, 1.0).normalize();
        let n = DVec3::new(0.0, 0.0, 1.0);
        let t = refract(d, n, 1.0, 1.5).unwrap();
        let sin_i = d.x;
        let sin_t = t.x;
        assert!((sin_i - 1.5 * sin_t).abs() < 1e-15);
        assert!(refract(DVec3::new(0.8, 0.0, 0.6), n, 1.5, 1.0).is_none(), "TIR");
    }
}
