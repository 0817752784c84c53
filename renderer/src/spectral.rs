//! Wavelength sampling for lenses with dispersion: each camera ray carries one wavelength,
//! drawn uniformly over 380–780 nm, and its RGB radiance is weighted by the CIE 1931 colour
//! matching functions (Wyman, Sloan and Shirley's 2013 multi-lobe fit) converted to linear
//! Rec.709 and normalised so the expected weight is exactly (1, 1, 1): colours keep their mean
//! and only the dispersion of the lens moves light between pixels.

use glam::Vec3;
use std::sync::OnceLock;

/// Shortest sampled wavelength.
pub const LAMBDA_MIN_NM: f32 = 380.0;
/// Longest sampled wavelength.
pub const LAMBDA_MAX_NM: f32 = 780.0;

fn g(x: f32, mu: f32, s1: f32, s2: f32) -> f32 {
    let t = (x - mu) / if x < mu { s1 } else { s2 };
    (-0.5 * t * t).exp()
}

/// CIE 1931 2° colour matching functions (multi-lobe Gaussian fit).
pub fn cie_xyz(lambda_nm: f32) -> Vec3 {
    let l = lambda_nm;
    let x = 1.056 * g(l, 599.8, 37.9, 31.0) + 0.362 * g(l, 442.0, 16.0, 26.7) - 0.065 * g(l, 501.1, 20.4, 26.2);
    let y = 0.821 * g(l, 568.8, 46.9, 40.5) + 0.286 * g(l, 530.9, 16.3, 31.1);
    let z = 1.217 * g(l, 437.0, 11.8, 36.0) + 0.681 * g(l, 459.0, 26.0, 13.8);
    Vec3::new(x, y, z)
}

/// CIE XYZ to linear Rec.709 (D65).
pub fn xyz_to_rgb(c: Vec3) -> Vec3 {
    Vec3::new(
        3.240_454_2 * c.x - 1.537_138_5 * c.y - 0.498_531_4 * c.z,
        -0.969_266 * c.x + 1.876_010_8 * c.y + 0.041_556 * c.z,
        0.055_643_4 * c.x - 0.204_025_9 * c.y + 1.057_225_2 * c.z,
    )
}

fn normalisation() -> Vec3 {
    static N: OnceLock<Vec3> = OnceLock::new();
    *N.get_or_init(|| {
        let n = 4000;
        let mut sum = Vec3::ZERO;
        for i in 0..n {
            let l = LAMBDA_MIN_NM + (LAMBDA_MAX_NM - LAMBDA_MIN_NM) * (i as f32 + 0.5) / n as f32;
            sum += xyz_to_rgb(cie_xyz(l));
        }
        sum / n as f32
    })
}

/// A wavelength from `u` in [0,1) and the RGB weight of a ray carrying it (mean (1,1,1)).
pub fn sample_wavelength(u: f32) -> (f32, Vec3) {
    let l = LAMBDA_MIN_NM + (LAMBDA_MAX_NM - LAMBDA_MIN_NM) * u;
    (l, xyz_to_rgb(cie_xyz(l)) / normalisation())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weights_average_to_white() {
        let n = 10_000;
        let mut s = Vec3::ZERO;
        for i in 0..n {
            s += sample_wavelength((i as f32 + 0.5) / n as f32).1;
        }
        let m = s / n as f32;
        assert!((m - Vec3::ONE).abs().max_element() < 1e-3, "{m}");
        // green peaks near 550 nm, blue near 450, red near 600
        assert!(sample_wavelength((550.0 - 380.0) / 400.0).1.y > 2.0);
    }
}
