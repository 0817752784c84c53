//! Paraxial (first-order) analysis with 2×2 ray-transfer matrices on reduced angles (n·u):
//! cardinal points, pupils, f-numbers, Petzval sum, focusing and the thick-lens approximation.
//!
//! All z positions are in the lens frame: millimetres from the first surface's vertex, positive
//! towards the film. Object space is air; image space is the medium after the last surface
//! (air, or a glass or liquid: an eye's vitreous), whose index n′ scales the image-side
//! distances (back focal length n′/φ, rear focal length n′·EFL, exit pupil, image distances).
//! The y–z meridian is used; for anamorphic lenses the x–z meridian is reported separately
//! (`efl_x_mm`).

use super::lens::Lens;
use super::prescription::CylinderAxis;
use crate::error::{Error, Result};
use serde::Serialize;

/// A 2×2 paraxial matrix acting on (y, n·u).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Abcd {
    /// y ← A y + B ω
    pub a: f64,
    /// see `a`
    pub b: f64,
    /// ω ← C y + D ω
    pub c: f64,
    /// see `c`
    pub d: f64,
}

impl Abcd {
    /// The identity.
    pub const IDENTITY: Abcd = Abcd { a: 1.0, b: 0.0, c: 0.0, d: 1.0 };

    /// `self` followed by `next` (next · self).
    pub fn then(self, next: Abcd) -> Abcd {
        Abcd {
            a: next.a * self.a + next.b * self.c,
            b: next.a * self.b + next.b * self.d,
            c: next.c * self.a + next.d * self.c,
            d: next.c * self.b + next.d * self.d,
        }
    }

    /// Refraction with power φ.
    pub fn refraction(power: f64) -> Abcd {
        Abcd { a: 1.0, b: 0.0, c: -power, d: 1.0 }
    }

    /// Transfer over thickness t in a medium of index n.
    pub fn transfer(t: f64, n: f64) -> Abcd {
        Abcd { a: 1.0, b: t / n, c: 0.0, d: 1.0 }
    }

    /// Applies to (y, ω).
    pub fn apply(&self, y: f64, w: f64) -> (f64, f64) {
        (self.a * y + self.b * w, self.c * y + self.d * w)
    }
}

/// Which meridian to analyse.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Meridian {
    /// y–z plane.
    Y,
    /// x–z plane.
    X,
}

/// Paraxial curvature of surface `i` in a meridian.
fn meridian_curvature(lens: &Lens, i: usize, m: Meridian) -> f64 {
    let s = &lens.surfaces()[i].shape;
    match (s.cylinder, m) {
        (None, _) => s.paraxial_curvature_per_mm(),
        (Some(CylinderAxis::X), Meridian::X) | (Some(CylinderAxis::Y), Meridian::Y) => s.paraxial_curvature_per_mm(),
        _ => 0.0,
    }
}

/// Matrix of surfaces `from..to` (refraction at each, transfer after each except the last).
/// With `transfer_after_last`, also the transfer after surface `to - 1`.
pub fn matrix(lens: &Lens, from: usize, to: usize, wavelength_nm: f64, m: Meridian, transfer_after_last: bool) -> Abcd {
    let mut out = Abcd::IDENTITY;
    for i in from..to {
        let n1 = lens.index_before(i, wavelength_nm);
        let n2 = lens.index_after(i, wavelength_nm);
        out = out.then(Abcd::refraction(meridian_curvature(lens, i, m) * (n2 - n1)));
        if i + 1 < to || transfer_after_last {
            out = out.then(Abcd::transfer(lens.surfaces()[i].thickness_mm, n2));
        }
    }
    out
}

/// First-order properties of a lens (y–z meridian, one wavelength), as `petzval lens info` prints.
#[derive(Debug, Clone, Default, Serialize, PartialEq)]
pub struct ParaxialData {
    /// Wavelength of the analysis.
    pub wavelength_nm: f64,
    /// Effective focal length.
    pub efl_mm: f64,
    /// x–z meridian focal length (differs from `efl_mm` for anamorphic lenses).
    pub efl_x_mm: f64,
    /// Back focal length: last vertex to rear focal point.
    pub bfl_mm: f64,
    /// Front focal length: front focal point to first vertex (positive when the focal point
    /// lies in front of the lens).
    pub ffl_mm: f64,
    /// Front focal point z.
    pub front_focal_z_mm: f64,
    /// Rear focal point z.
    pub rear_focal_z_mm: f64,
    /// Front principal plane z.
    pub front_principal_z_mm: f64,
    /// Rear principal plane z.
    pub rear_principal_z_mm: f64,
    /// Front nodal point z (equals the principal point in air).
    pub front_nodal_z_mm: f64,
    /// Rear nodal point z.
    pub rear_nodal_z_mm: f64,
    /// Entrance pupil z.
    pub entrance_pupil_z_mm: f64,
    /// Entrance pupil diameter at the current stop opening.
    pub entrance_pupil_diameter_mm: f64,
    /// Exit pupil z.
    pub exit_pupil_z_mm: f64,
    /// Exit pupil diameter.
    pub exit_pupil_diameter_mm: f64,
    /// EFL / entrance pupil diameter.
    pub f_number: f64,
    /// Petzval sum Σ φᵢ / (nᵢ nᵢ').
    pub petzval_sum_per_mm: f64,
}

/// Computes the first-order properties at `wavelength_nm`.
pub fn analyse(lens: &Lens, wavelength_nm: f64) -> ParaxialData {
    let n = lens.surfaces().len();
    let last_z = lens.surfaces()[n - 1].z_mm;
    let sys = matrix(lens, 0, n, wavelength_nm, Meridian::Y, false);
    let sys_x = matrix(lens, 0, n, wavelength_nm, Meridian::X, false);
    // 1. Cardinal points from the system matrix (infinite for an afocal system such as a plate).
    // Image space index n′: reduced angles ω = n′u there, so image-side distances are n′·y/ω.
    let n_img = lens.index_after(n - 1, wavelength_nm);
    let afocal = sys.c.abs() < 1e-15;
    let efl = if afocal { f64::INFINITY } else { -1.0 / sys.c };
    let efl_x = if sys_x.c.abs() < 1e-15 { f64::INFINITY } else { -1.0 / sys_x.c };
    let bfl = if afocal { f64::INFINITY } else { -n_img * sys.a / sys.c };
    let front_focal_z = if afocal { f64::NEG_INFINITY } else { sys.d / sys.c };
    let rear_focal_z = last_z + bfl;
    // 2. Pupils: images of the stop through the groups in front of and behind it.
    let s = lens.stop_index();
    let stop_r = lens.stop_semi_diameter_mm();
    let front = matrix(lens, 0, s, wavelength_nm, Meridian::Y, true);
    let (ep_z, ep_d) = if s == 0 { (0.0, 2.0 * stop_r) } else { (front.b / front.a, 2.0 * stop_r / front.a.abs()) };
    let back = matrix(lens, s, n, wavelength_nm, Meridian::Y, false);
    let (xp_z, xp_d) = if back.d.abs() < 1e-15 {
        (f64::INFINITY, f64::INFINITY)
    } else {
        (last_z - n_img * back.b / back.d, 2.0 * stop_r / back.d.abs())
    };
    // 3. Petzval sum.
    let mut petzval = 0.0;
    for i in 0..n {
        let n1 = lens.index_before(i, wavelength_nm);
        let n2 = lens.index_after(i, wavelength_nm);
        petzval += lens.surfaces()[i].shape.paraxial_curvature_per_mm() * (n2 - n1) / (n1 * n2);
    }
    ParaxialData {
        wavelength_nm,
        efl_mm: efl,
        efl_x_mm: efl_x,
        bfl_mm: bfl,
        ffl_mm: -front_focal_z,
        front_focal_z_mm: front_focal_z,
        rear_focal_z_mm: rear_focal_z,
        // focal lengths f = EFL (object side, air) and f′ = n′·EFL; nodal points swap them
        front_principal_z_mm: front_focal_z + efl,
        rear_principal_z_mm: rear_focal_z - n_img * efl,
        front_nodal_z_mm: front_focal_z + n_img * efl,
        rear_nodal_z_mm: rear_focal_z - efl,
        entrance_pupil_z_mm: ep_z,
        entrance_pupil_diameter_mm: ep_d,
        exit_pupil_z_mm: xp_z,
        exit_pupil_diameter_mm: xp_d,
        f_number: efl / ep_d,
        petzval_sum_per_mm: petzval,
    }
}

/// The stop semi-diameter that gives f-number `f_number` (paraxially, object at infinity).
pub fn stop_radius_for_f_number(lens: &Lens, f_number: f64) -> Result<f64> {
    let p = lens.paraxial();
    if !(f_number.is_finite() && f_number > 0.0) {
        return Err(Error::Optics(format!("f-number must be positive, got {f_number}")));
    }
    let epd = p.efl_mm.abs() / f_number;
    let s = lens.stop_index();
    let front = matrix(lens, 0, s, lens.primary_wavelength_nm(), Meridian::Y, true);
    let scale = if s == 0 { 1.0 } else { front.a.abs() };
    Ok(0.5 * epd * scale)
}

/// Paraxial image distance (from the last vertex) of an axial object at `object_z_mm`
/// (lens frame, in front of the first vertex). Errors when the image is virtual.
pub fn image_distance_mm(lens: &Lens, object_z_mm: f64, wavelength_nm: f64) -> Result<f64> {
    let n = lens.surfaces().len();
    let sys = matrix(lens, 0, n, wavelength_nm, Meridian::Y, false);
    // A ray from the axial object point with unit slope reaches the first vertex at y = −z_o.
    let (y, w) = sys.apply(-object_z_mm, 1.0);
    if !(w < -1e-15) {
        return Err(Error::Optics(format!(
            "cannot focus: an object {:.1} mm in front of the lens forms no real image (it is inside the front focal distance)",
            -object_z_mm
        )));
    }
    Ok(-lens.index_after(n - 1, wavelength_nm) * y / w)
}

/// Working f-number 1 / (2 n' sin u') for an axial object at `object_z_mm` (None = infinity),
/// from the paraxial marginal ray.
pub fn working_f_number(lens: &Lens, object_z_mm: Option<f64>) -> f64 {
    let p = lens.paraxial();
    match object_z_mm {
        None => p.f_number,
        Some(zo) => {
            // marginal ray aimed at the entrance pupil edge
            let h = 0.5 * p.entrance_pupil_diameter_mm;
            let u = h / (p.entrance_pupil_z_mm - zo);
            let n = lens.surfaces().len();
            let sys = matrix(lens, 0, n, lens.primary_wavelength_nm(), Meridian::Y, false);
            let (_, w) = sys.apply(-zo * u, u);
            1.0 / (2.0 * w.abs())
        }
    }
}
