//! Aperture stop shapes: circle, straight or curved blades, anamorphic ratio, image mask.
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `shape` | [`ApertureShape`] | — | circle |
//! | `rotation_rad` | f64: blades put the middle of an edge at this angle (Blender's `aperture_rotation`); rotates a mask | radians | 0 |
//! | `anamorphic_ratio` | f64: height / width of the opening; x is divided by it (Blender's `aperture_ratio`) | — | 1 |
//!
//! The opening is given by its circumradius `R` (the stop semi-diameter at the current
//! f-number): a circle of radius R, a regular polygon with vertices on the circle of radius R,
//! or a mask image spanning the square [−R, R]².

use crate::error::{Error, Result};
use std::path::Path;
use std::sync::Arc;

/// A grey-level transmission mask (row 0 = top = +y).
#[derive(Debug, Clone, PartialEq)]
pub struct ApertureMask {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Transmission per pixel in [0, 1], row-major from the top.
    pub transmission: Vec<f32>,
    /// Where it came from (for metadata).
    pub path: String,
}

impl ApertureMask {
    /// Loads a PNG (luminance, or alpha when present and not opaque) or EXR (luminance) mask.
    pub fn load(path: &Path) -> Result<Self> {
        let err = |m: String| Error::ApertureImage { path: path.to_path_buf(), message: m };
        if !path.is_file() {
            return Err(err("not a regular file (missing, or a folder, device or pipe)".into()));
        }
        let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
        let (width, height, transmission) = if ext == "exr" {
            let img = exr::prelude::read_first_rgba_layer_from_file(
                path,
                |res, _| (res.width(), res.height(), vec![0f32; res.width() * res.height()]),
                |(w, _, px), pos, (r, g, b, _a): (f32, f32, f32, f32)| {
                    px[pos.y() * *w + pos.x()] = 0.2126 * r + 0.7152 * g + 0.0722 * b;
                },
            )
            .map_err(|e| err(e.to_string()))?;
            let (w, h, px) = img.layer_data.channel_data.pixels;
            (w, h, px)
        } else {
            let img = image::open(path).map_err(|e| err(e.to_string()))?;
            let rgba = img.to_rgba32f();
            let (w, h) = (rgba.width() as usize, rgba.height() as usize);
            let has_alpha = rgba.pixels().any(|p| p.0[3] < 1.0);
            let px = rgba
                .pixels()
                .map(|p| {
                    let [r, g, b, a] = p.0;
                    if has_alpha {
                        a
                    } else {
                        0.2126 * r + 0.7152 * g + 0.0722 * b
                    }
                })
                .collect();
            (w, h, px)
        };
        if width == 0 || height == 0 {
            return Err(err("empty image".into()));
        }
        let transmission: Vec<f32> =
            transmission.into_iter().map(|v| if v.is_finite() { v.clamp(0.0, 1.0) } else { 0.0 }).collect();
        if transmission.iter().all(|v| *v <= 0.0) {
            return Err(err("the mask is entirely black: no light would pass".into()));
        }
        Ok(ApertureMask { width, height, transmission, path: path.display().to_string() })
    }

    /// Transmission at normalised coordinates u, v in [−1, 1] (v up); 0 outside.
    pub fn lookup(&self, u: f64, v: f64) -> f64 {
        if !(-1.0..=1.0).contains(&u) || !(-1.0..=1.0).contains(&v) {
            return 0.0;
        }
        let x = (((u + 1.0) * 0.5 * self.width as f64) as usize).min(self.width - 1);
        let y = (((1.0 - v) * 0.5 * self.height as f64) as usize).min(self.height - 1);
        self.transmission[y * self.width + x] as f64
    }
}

/// The shape of the stop opening.
#[derive(Debug, Clone, PartialEq)]
pub enum ApertureShape {
    /// A circle.
    Circle,
    /// A regular polygon of `count` blades; `curvature` 0 = straight, 1 = circular arcs.
    Blades {
        /// Number of blades (≥ 3).
        count: u32,
        /// Blade curvature in [0, 1].
        curvature: f64,
    },
    /// A transmission mask spanning [−R, R]².
    Mask(Arc<ApertureMask>),
}

/// The stop opening: shape, rotation and anamorphic squeeze.
#[derive(Debug, Clone, PartialEq)]
pub struct Aperture {
    /// Shape.
    pub shape: ApertureShape,
    /// Rotation (radians, counter-clockwise seen from the film).
    pub rotation_rad: f64,
    /// Height / width of the opening.
    pub anamorphic_ratio: f64,
}

impl Default for Aperture {
    fn default() -> Self {
        Aperture { shape: ApertureShape::Circle, rotation_rad: 0.0, anamorphic_ratio: 1.0 }
    }
}

impl Aperture {
    /// Transmission in [0, 1] of the point (x, y) on the stop plane for circumradius `radius_mm`.
    #[inline]
    pub fn transmission(&self, x: f64, y: f64, radius_mm: f64) -> f64 {
        // 1. Undo the anamorphic squeeze and normalise by the circumradius.
        let u = x * self.anamorphic_ratio / radius_mm;
        let v = y / radius_mm;
        match &self.shape {
            ApertureShape::Circle => {
                if u * u + v * v <= 1.0 {
                    1.0
                } else {
                    0.0
                }
            }
            ApertureShape::Blades { count, curvature } => {
                if inside_blades(u, v, *count, *curvature, self.rotation_rad) {
                    1.0
                } else {
                    0.0
                }
            }
            ApertureShape::Mask(mask) => {
                let (s, c) = self.rotation_rad.sin_cos();
                // rotate the point into the mask's frame
                mask.lookup(c * u + s * v, -s * u + c * v)
            }
        }
    }

    /// How far (mm) the point (x, y) on the stop plane is inside the opening of circumradius
    /// `radius_mm` (negative outside; measured in the unsqueezed frame, so exact in its sign
    /// and approximate in size for an anamorphic opening), with the grey level that stays in
    /// the transmission (a mask's, whose clearance is +∞; 1 for circles and blades). Continuous
    /// in (x, y): the soft-clipping trace ([`crate::Lens::trace_soft`]) weights rays by it.
    pub fn clearance_mm(&self, x: f64, y: f64, radius_mm: f64) -> (f64, f64) {
        let u = x * self.anamorphic_ratio / radius_mm;
        let v = y / radius_mm;
        match &self.shape {
            ApertureShape::Circle => ((1.0 - (u * u + v * v).sqrt()) * radius_mm, 1.0),
            ApertureShape::Blades { count, curvature } => {
                (blade_clearance(u, v, *count, *curvature, self.rotation_rad) * radius_mm, 1.0)
            }
            ApertureShape::Mask(_) => (f64::INFINITY, self.transmission(x, y, radius_mm)),
        }
    }

    /// Whether the opening is symmetric under every rotation about the axis.
    pub fn is_circular(&self) -> bool {
        matches!(self.shape, ApertureShape::Circle) && self.anamorphic_ratio == 1.0
    }

    /// Radius of a circle that contains the whole opening, as a multiple of the circumradius.
    pub fn bounding_radius_factor(&self) -> f64 {
        let base = match self.shape {
            ApertureShape::Mask(_) => std::f64::consts::SQRT_2,
            _ => 1.0,
        };
        base * (1.0 / self.anamorphic_ratio).max(1.0)
    }
}

/// Point-in-polygon for a regular N-gon of circumradius 1 with an edge middle at `rotation`,
/// with blade edges bowed outwards into circular arcs by `curvature`.
fn inside_blades(u: f64, v: f64, count: u32, curvature: f64, rotation: f64) -> bool {
    let r2 = u * u + v * v;
    if r2 > 1.0 {
        return false;
    }
    let n = count as f64;
    let half = std::f64::consts::PI / n;
    // 1. Angle to the nearest edge normal: edge middles lie at rotation + k·2π/N (Blender's
    //    aperture_rotation), vertices halfway between.
    let phi = v.atan2(u) - rotation;
    let sector = (phi / (2.0 * half)).round();
    let alpha = phi - sector * 2.0 * half;
    let r = r2.sqrt();
    let along = r * alpha.cos(); // distance along the edge normal
    let apothem = half.cos();
    if curvature <= 0.0 {
        return along <= apothem;
    }
    // 2. Curved blade: an arc of radius 1/curvature through both vertices.
    let rho = 1.0 / curvature;
    let s = half.sin();
    let d = apothem - (rho * rho - s * s).sqrt(); // arc centre along the normal
    let across = r * alpha.sin();
    (along - d).powi(2) + across * across <= rho * rho
}

/// The signed distance (in circumradii, positive inside) of (u, v) from the blade opening of
/// [`inside_blades`]: from the nearest straight edge's line, or for curved blades the smaller
/// of the arc's and the circumcircle's clearance. Continuous across sectors.
fn blade_clearance(u: f64, v: f64, count: u32, curvature: f64, rotation: f64) -> f64 {
    let r = (u * u + v * v).sqrt();
    let half = std::f64::consts::PI / count as f64;
    // 1. Angle to the nearest edge normal, as in `inside_blades`.
    let phi = v.atan2(u) - rotation;
    let alpha = phi - (phi / (2.0 * half)).round() * 2.0 * half;
    let along = r * alpha.cos();
    let apothem = half.cos();
    if curvature <= 0.0 {
        return apothem - along;
    }
    // 2. Curved blade: inside the arc of radius 1/curvature and inside the circumcircle.
    let rho = 1.0 / curvature;
    let s = half.sin();
    let d = apothem - (rho * rho - s * s).sqrt();
    let across = r * alpha.sin();
    (rho - ((along - d).powi(2) + across * across).sqrt()).min(1.0 - r)
}

impl Aperture {
    /// Samples a point of the opening for circumradius 1 from `u` in [0,1)²: returns the point
    /// and its density per unit area. The caller multiplies by [`Aperture::transmission`], which
    /// is 1 for straight blades and circles sampled here and carries curved blades and masks.
    pub fn sample_unit(&self, u: glam::DVec2) -> (glam::DVec2, f64) {
        use glam::DVec2;
        let (p, pdf) = match &self.shape {
            ApertureShape::Circle => (concentric_disk(u), 1.0 / std::f64::consts::PI),
            ApertureShape::Blades { count, curvature } if *curvature == 0.0 => {
                // uniform over the polygon: choose a triangle, then a point in it
                let n = *count as f64;
                let k = (u.x * n).floor().min(n - 1.0);
                let ux = u.x * n - k;
                // vertices halfway between edge middles (which sit at the rotation)
                let a0 = self.rotation_rad + std::f64::consts::PI / n + 2.0 * std::f64::consts::PI * k / n;
                let a1 = a0 + 2.0 * std::f64::consts::PI / n;
                let (v0, v1) = (DVec2::new(a0.cos(), a0.sin()), DVec2::new(a1.cos(), a1.sin()));
                let su = ux.sqrt();
                let p = v0 * (su * (1.0 - u.y)) + v1 * (su * u.y);
                let area = 0.5 * n * (2.0 * std::f64::consts::PI / n).sin();
                (p, 1.0 / area)
            }
            ApertureShape::Blades { .. } => (concentric_disk(u), 1.0 / std::f64::consts::PI),
            ApertureShape::Mask(_) => (DVec2::new(2.0 * u.x - 1.0, 2.0 * u.y - 1.0), 0.25),
        };
        // anamorphic squeeze: x is divided by the ratio, density scales by it
        (DVec2::new(p.x / self.anamorphic_ratio, p.y), pdf * self.anamorphic_ratio)
    }
}

/// Blade counts up to which [`PreparedAperture`] keeps per-blade tables (the nearest-edge search
/// is linear in the count); more blades use [`Aperture`]'s own formulas.
const MAX_TABLED_BLADES: u32 = 32;

/// Half-width of the band around a blade edge where [`PreparedAperture`]'s trigonometry-free
/// test defers to [`Aperture::transmission`] (in circumradii, or in units of ρ² + 1 for curved
/// blades): both compute the same edge distance to within ~10⁻¹⁵, so outside the band they agree.
const BLADE_EDGE_BAND: f64 = 1e-9;

/// How far inside its triangle's outer edge (a fraction of the apothem, which is at least 1/2)
/// a straight-blade sample must be for [`PreparedAperture::sample_scaled`] to skip the
/// transmission test: 500 × [`BLADE_EDGE_BAND`] and ~10⁹ × the rounding of the point, so the
/// test would give exactly 1. About one sample in 10⁶ is nearer and is tested.
const CLEAR_OF_EDGE: f64 = 1e-6;

/// An [`Aperture`] with its per-blade constants computed once (edge normals, triangle vertices,
/// polygon area, a mask's rotation), for the cameras' and the lens's per-ray tests. Its
/// [`PreparedAperture::transmission`] and [`PreparedAperture::sample_unit`] return the same
/// bits as [`Aperture`]'s, except that a mask's points are drawn in proportion to its
/// transmission ([`PreparedAperture::pdf_unit_at`] gives their density).
#[derive(Debug, Clone, PartialEq)]
pub struct PreparedAperture {
    aperture: Aperture,
    blades: Option<BladeTables>,
    /// A mask's rotation as (sin, cos).
    mask_rotation: (f64, f64),
    /// A mask's pixels as a sampling distribution (points drawn in proportion to transmission).
    mask_cdf: Option<MaskCdf>,
}

/// A mask's transmission as a discrete distribution over its pixels: points are drawn in a
/// pixel with probability proportional to its transmission, uniformly within it, so a lens
/// sample's weight (transmission over density) is the same everywhere in the opening.
#[derive(Debug, Clone, PartialEq)]
struct MaskCdf {
    /// Cumulative transmission over the pixels, row-major from the top (`cdf[i]`: pixels < i + 1).
    cdf: Vec<f64>,
    /// The sum of all pixels' transmission (> 0).
    total: f64,
}

impl MaskCdf {
    fn new(mask: &ApertureMask) -> Option<Self> {
        let mut acc = 0.0f64;
        let cdf: Vec<f64> = mask
            .transmission
            .iter()
            .map(|&t| {
                acc += f64::from(t.max(0.0));
                acc
            })
            .collect();
        (acc > 0.0 && acc.is_finite()).then_some(MaskCdf { cdf, total: acc })
    }
}

/// Per-blade constants of a regular polygon (edge middles at `rotation + k·2π/N`).
#[derive(Debug, Clone, PartialEq)]
struct BladeTables {
    /// Unit edge normals, one per blade.
    normals: Vec<glam::DVec2>,
    /// Each sampling triangle's two outer vertices (k and its successor, as `sample_unit` makes them).
    triangles: Vec<(glam::DVec2, glam::DVec2)>,
    /// Polygon area for circumradius 1.
    area: f64,
    /// cos(π/N).
    apothem: f64,
    /// Curved blades: arc centre along the normal and arc radius (d, ρ).
    arc: Option<(f64, f64)>,
}

impl PreparedAperture {
    /// Precomputes `aperture`'s per-ray constants.
    pub fn new(aperture: Aperture) -> Self {
        use glam::DVec2;
        use std::f64::consts::PI;
        let blades = match aperture.shape {
            ApertureShape::Blades { count, curvature } if (3..=MAX_TABLED_BLADES).contains(&count) => {
                let n = count as f64;
                let half = PI / n;
                let rotation = aperture.rotation_rad;
                // the same expressions as `sample_unit` and `inside_blades`, so the same bits
                let triangles = (0..count)
                    .map(|k| {
                        let a0 = rotation + PI / n + 2.0 * PI * k as f64 / n;
                        let a1 = a0 + 2.0 * PI / n;
                        (DVec2::new(a0.cos(), a0.sin()), DVec2::new(a1.cos(), a1.sin()))
                    })
                    .collect();
                let normals = (0..count)
                    .map(|k| {
                        let a = rotation + 2.0 * half * k as f64;
                        DVec2::new(a.cos(), a.sin())
                    })
                    .collect();
                let apothem = half.cos();
                let arc = (curvature > 0.0).then(|| {
                    let rho = 1.0 / curvature;
                    let s = half.sin();
                    (apothem - (rho * rho - s * s).sqrt(), rho)
                });
                Some(BladeTables { normals, triangles, area: 0.5 * n * (2.0 * PI / n).sin(), apothem, arc })
            }
            _ => None,
        };
        let mask_rotation = aperture.rotation_rad.sin_cos();
        let mask_cdf = match &aperture.shape {
            ApertureShape::Mask(m) => MaskCdf::new(m),
            _ => None,
        };
        PreparedAperture { aperture, blades, mask_rotation, mask_cdf }
    }

    /// The aperture it was made from.
    pub fn aperture(&self) -> &Aperture {
        &self.aperture
    }

    /// [`Aperture::transmission`], with the blade and mask constants precomputed.
    #[inline]
    pub fn transmission(&self, x: f64, y: f64, radius_mm: f64) -> f64 {
        match (&self.aperture.shape, &self.blades) {
            (ApertureShape::Blades { .. }, Some(t)) => {
                // 1. Undo the squeeze and normalise, as `Aperture::transmission` does.
                let u = x * self.aperture.anamorphic_ratio / radius_mm;
                let v = y / radius_mm;
                if !(u * u + v * v <= 1.0) {
                    return 0.0; // outside the circumcircle, or NaN (closed, as `Aperture` has it)
                }
                // 2. The nearest edge is the one whose normal has the largest projection.
                let p = glam::DVec2::new(u, v);
                let (mut along, mut k_best) = (f64::NEG_INFINITY, 0);
                for (k, n) in t.normals.iter().enumerate() {
                    let a = p.dot(*n);
                    if a > along {
                        (along, k_best) = (a, k);
                    }
                }
                // 3. Signed distance past the edge (or the arc), and the exact test near it.
                let past = match t.arc {
                    None => along - t.apothem,
                    Some((d, rho)) => {
                        let across = t.normals[k_best].perp_dot(p);
                        ((along - d).powi(2) + across * across - rho * rho) / (rho * rho + 1.0)
                    }
                };
                if past.abs() <= BLADE_EDGE_BAND {
                    self.aperture.transmission(x, y, radius_mm)
                } else if past < 0.0 {
                    1.0
                } else {
                    0.0
                }
            }
            (ApertureShape::Mask(mask), _) => {
                let u = x * self.aperture.anamorphic_ratio / radius_mm;
                let v = y / radius_mm;
                let (s, c) = self.mask_rotation;
                mask.lookup(c * u + s * v, -s * u + c * v)
            }
            _ => self.aperture.transmission(x, y, radius_mm),
        }
    }

    /// [`Aperture::sample_unit`], with the straight-blade triangles precomputed.
    #[inline]
    pub fn sample_unit(&self, u: glam::DVec2) -> (glam::DVec2, f64) {
        let (p, pdf, _) = self.sample_unit_clear(u);
        (p, pdf)
    }

    /// [`PreparedAperture::sample_unit`] scaled to circumradius `radius_mm`: the point (mm),
    /// its density per unit area of the unit aperture, and the transmission there
    /// ([`PreparedAperture::transmission`]). A straight-bladed polygon's point clear of its edge
    /// passes without the test (the test would give exactly 1 there).
    #[inline]
    pub fn sample_scaled(&self, u: glam::DVec2, radius_mm: f64) -> (glam::DVec2, f64, f64) {
        let (q, pdf_unit, clear) = self.sample_unit_clear(u);
        let p = glam::DVec2::new(q.x * radius_mm, q.y * radius_mm);
        let transmission = if clear && radius_mm > 0.0 && radius_mm.is_finite() {
            1.0
        } else {
            self.transmission(p.x, p.y, radius_mm)
        };
        (p, pdf_unit, transmission)
    }

    /// [`PreparedAperture::sample_unit`], and whether the point is certainly inside a straight
    /// blade polygon: its triangle's outer edge is at least [`CLEAR_OF_EDGE`] of the apothem
    /// away, far beyond rounding and [`BLADE_EDGE_BAND`], so the transmission test returns 1.
    #[inline]
    fn sample_unit_clear(&self, u: glam::DVec2) -> (glam::DVec2, f64, bool) {
        match (&self.aperture.shape, &self.blades) {
            (ApertureShape::Blades { count, curvature }, Some(t)) if *curvature == 0.0 => {
                // 1. Choose a triangle, then a point in it, as `Aperture::sample_unit` does.
                let n = *count as f64;
                let k = (u.x * n).floor().min(n - 1.0);
                let ux = u.x * n - k;
                let (v0, v1) = t.triangles[k as usize];
                let su = ux.sqrt();
                let p = v0 * (su * (1.0 - u.y)) + v1 * (su * u.y);
                // 2. The anamorphic squeeze.
                let ratio = self.aperture.anamorphic_ratio;
                // (the point lies at su × the apothem along its edge's normal)
                let clear = su <= 1.0 - CLEAR_OF_EDGE && u.y >= 0.0 && u.y <= 1.0;
                (glam::DVec2::new(p.x / ratio, p.y), (1.0 / t.area) * ratio, clear)
            }
            (ApertureShape::Mask(mask), _) if let Some(cdf) = &self.mask_cdf => {
                // 1. The pixel, in proportion to its transmission (u.x), and the remainder of
                //    u.x across it, u.y down it.
                let target = u.x.clamp(0.0, 1.0) * cdf.total;
                let i = cdf.cdf.partition_point(|&c| c <= target).min(cdf.cdf.len() - 1);
                let before = if i == 0 { 0.0 } else { cdf.cdf[i - 1] };
                let t_i = cdf.cdf[i] - before;
                let fx = if t_i > 0.0 { ((target - before) / t_i).clamp(0.0, 1.0) } else { 0.5 };
                let (px, py) = ((i % mask.width) as f64 + fx, (i / mask.width) as f64 + u.y.clamp(0.0, 1.0));
                // 2. Mask coordinates ([−1, 1]², v up), then the stop's: the mask's rotation undone
                //    (`transmission` turns the stop's point by it), then the squeeze.
                let (mu, mv) = (2.0 * px / mask.width as f64 - 1.0, 1.0 - 2.0 * py / mask.height as f64);
                let (s, c) = self.mask_rotation;
                let (x, y) = (c * mu - s * mv, s * mu + c * mv);
                let ratio = self.aperture.anamorphic_ratio;
                let pixel_area = 4.0 / (mask.width * mask.height) as f64;
                (glam::DVec2::new(x / ratio, y), t_i / (cdf.total * pixel_area) * ratio, false)
            }
            _ => {
                let (p, pdf) = self.aperture.sample_unit(u);
                (p, pdf, false)
            }
        }
    }

    /// The density of [`PreparedAperture::sample_unit`]'s point `q` (unit aperture, squeezed),
    /// per unit area of the unit aperture: uniform over the sampling domain (the polygon, the
    /// disc, or the square of a clear mask), which holds every point the stop transmits; for a
    /// mask, in proportion to its transmission at `q`.
    pub fn pdf_unit_at(&self, q: glam::DVec2) -> f64 {
        match (&self.aperture.shape, &self.mask_cdf) {
            (ApertureShape::Mask(mask), Some(cdf)) => {
                let pixel_area = 4.0 / (mask.width * mask.height) as f64;
                self.transmission(q.x, q.y, 1.0) / (cdf.total * pixel_area) * self.aperture.anamorphic_ratio
            }
            _ => self.sample_unit(glam::DVec2::splat(0.5)).1,
        }
    }

    /// [`Aperture::clearance_mm`].
    pub fn clearance_mm(&self, x: f64, y: f64, radius_mm: f64) -> (f64, f64) {
        match self.aperture.shape {
            ApertureShape::Mask(_) => (f64::INFINITY, self.transmission(x, y, radius_mm)),
            _ => self.aperture.clearance_mm(x, y, radius_mm),
        }
    }
}

/// Shirley–Chiu concentric mapping of [0,1)² to the unit disc.
pub fn concentric_disk(u: glam::DVec2) -> glam::DVec2 {
    let a = 2.0 * u.x - 1.0;
    let b = 2.0 * u.y - 1.0;
    if a == 0.0 && b == 0.0 {
        return glam::DVec2::ZERO;
    }
    let (r, theta) = if a.abs() > b.abs() {
        (a, std::f64::consts::FRAC_PI_4 * (b / a))
    } else {
        (b, std::f64::consts::FRAC_PI_2 - std::f64::consts::FRAC_PI_4 * (a / b))
    };
    glam::DVec2::new(r * theta.cos(), r * theta.sin())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hexagon_area_matches_formula() {
        let ap = Aperture {
            shape: ApertureShape::Blades { count: 6, curvature: 0.0 },
            rotation_rad: 0.3,
            anamorphic_ratio: 1.0,
        };
        let n = 800;
        let mut inside = 0usize;
        for i in 0..n {
            for j in 0..n {
                let x = -1.0 + 2.0 * (i as f64 + 0.5) / n as f64;
                let y = -1.0 + 2.0 * (j as f64 + 0.5) / n as f64;
                if ap.transmission(x, y, 1.0) > 0.0 {
                    inside += 1;
                }
            }
        }
        let area = 4.0 * inside as f64 / (n * n) as f64;
        let expected = 0.5 * 6.0 * (2.0 * std::f64::consts::PI / 6.0).sin();
        assert!((area - expected).abs() < 5e-3, "{area} vs {expected}");
    }

    #[test]
    fn fully_curved_blades_are_a_circle() {
        let ap = Aperture {
            shape: ApertureShape::Blades { count: 5, curvature: 1.0 },
            rotation_rad: 0.0,
            anamorphic_ratio: 1.0,
        };
        for k in 0..360 {
            let a = (k as f64).to_radians();
            assert!(ap.transmission(0.999 * a.cos(), 0.999 * a.sin(), 1.0) > 0.0);
        }
    }

    #[test]
    fn anamorphic_ratio_narrows_x() {
        let ap = Aperture { anamorphic_ratio: 2.0, ..Default::default() };
        assert_eq!(ap.transmission(0.6, 0.0, 1.0), 0.0);
        assert_eq!(ap.transmission(0.0, 0.9, 1.0), 1.0);
    }
}
