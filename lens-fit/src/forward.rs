//! The forward model: the image of a point source through the lens on the sensor, traced
//! exactly (scene → film) with a fixed sample pattern, each ray's light integrated over the
//! pixels its footprint covers.
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `rays` | traced rays per wavelength per capture (a grid's corners on the disc) | — | 8 192 |
//! | `subsamples` | points per grid cell side, interpolated inside the aperture and traced on its edges; 0 = a spiral of `rays` points, each traced | — | 2 |
//! | `footprint_px` | width of each ray's square footprint on the sensor; 0 = from the ray density ([`auto_footprint_px`]) | px | 0 |
//! | `aim` | the sampling disc on the entrance-pupil plane: centre and radius | mm | found from the start lens, then fixed |
//!
//! Frames: the lens frame of `petzval-optics` (mm, z from the first vertex towards the film,
//! x right and y up looking from the camera towards the scene). A source at `source_m`
//! (x right, y up, z forward) is at `(1000 x, 1000 y, z_origin − 1000 z)`, where `z_origin` is
//! the sensor plane or the entrance pupil. The sensor plane passes through the axis point
//! `film_z_mm` with the renderer's tilt convention (`R = R_y(−tilt_y) · R_x(tilt_x)`); a
//! sensor point `(qx, qy)` (sensor frame) is on the upright image at column
//! `columns / 2 − qx / pitch`, row `rows / 2 + qy / pitch` (the image is inverted on the
//! sensor, and the camera writes it upright).
//!
//! Smoothness: the pattern of pupil points is fixed for a fit, and a ray's footprint is a
//! small square whose overlap with each pixel is integrated exactly, so the model image is a
//! continuous function of every parameter (no ray jumps between pixels).

use crate::correction::Correction;
use crate::manifest::{DistancesFrom, SensorSpec};
use crate::params::CameraParams;
use glam::{DMat3, DVec2, DVec3};
use petzval_optics::{Lens, Ray, TraceDirection};
use rayon::prelude::*;

/// Rays per wavelength of one capture, by default.
pub const DEFAULT_RAYS: usize = 8_192;

/// Where a capture's source is and how the lens is set, in the lens's terms.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Geometry {
    /// The source (lens frame, mm).
    pub source_mm: DVec3,
    /// Where the sensor plane meets the axis (lens frame z, mm).
    pub film_z_mm: f64,
}

impl Geometry {
    /// Puts the source and the sensor for a capture: the lens focused at `focus_m` (scaled by
    /// the camera's `focus_scale`; from the sensor or the entrance pupil), the sensor moved by
    /// `sensor_offset_mm`, the source at `source_m` from the same origin.
    pub fn new(
        lens: &Lens,
        camera: &CameraParams,
        source_m: [f64; 3],
        focus_m: f64,
        from: DistancesFrom,
    ) -> petzval_optics::Result<Geometry> {
        let ep_z = lens.paraxial().entrance_pupil_z_mm;
        let last = lens.last_vertex_z_mm();
        let focus_mm = focus_m * camera.focus_scale * 1e3;
        // 1. The focus distance from the entrance pupil (a distance from the sensor includes
        //    the lens-to-sensor length, which itself depends on the focus: fixed point).
        let d_ep = match from {
            DistancesFrom::EntrancePupil => focus_mm,
            DistancesFrom::Sensor => {
                let mut d = focus_mm - (last + lens.paraxial().bfl_mm - ep_z);
                for _ in 0..50 {
                    let film = last + lens.focus_image_distance_mm(Some(d.max(1e-3)))?;
                    let next = focus_mm - (film - ep_z);
                    if (next - d).abs() < 1e-9 {
                        break;
                    }
                    d = next;
                }
                d
            }
        };
        // 2. The sensor where the focus setting puts it, displaced by the offset.
        let film_z_mm = last + lens.focus_image_distance_mm(Some(d_ep))? + camera.sensor_offset_mm;
        // 3. The source from the same origin (the actual sensor plane, or the entrance pupil).
        let z_origin = match from {
            DistancesFrom::Sensor => film_z_mm,
            DistancesFrom::EntrancePupil => ep_z,
        };
        let source_mm = DVec3::new(source_m[0] * 1e3, source_m[1] * 1e3, z_origin - source_m[2] * 1e3);
        Ok(Geometry { source_mm, film_z_mm })
    }
}

/// The disc on the entrance-pupil plane that rays are aimed at (fixed during a fit).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Aim {
    /// Plane z (lens frame).
    pub z_mm: f64,
    /// Disc centre (x, y).
    pub centre_mm: DVec2,
    /// Disc radius.
    pub radius_mm: f64,
}

impl Aim {
    /// The smallest disc (with a 25 % margin) holding every ray from the source that passes
    /// the lens, found on a 64 × 64 grid over the front element.
    pub fn find(lens: &Lens, source_mm: DVec3, wavelength_nm: f64) -> Option<Aim> {
        let z = lens.paraxial().entrance_pupil_z_mm;
        let front = lens.surfaces()[0].semi_diameter_mm;
        // the front aperture seen from the source, projected onto the pupil plane
        let s = source_mm;
        let scale = (z - s.z) / (0.0 - s.z);
        let reach = front * scale.abs() * 1.5 + front;
        let centre0 = DVec2::new(s.x, s.y) * (1.0 - scale);
        let n = 64;
        let mut passed = Vec::new();
        for j in 0..n {
            for i in 0..n {
                let u = DVec2::new((i as f64 + 0.5) / n as f64 * 2.0 - 1.0, (j as f64 + 0.5) / n as f64 * 2.0 - 1.0);
                let p = centre0 + u * reach;
                let target = DVec3::new(p.x, p.y, z);
                let ray = Ray::new(s, target - s);
                if lens.trace(&ray, wavelength_nm, TraceDirection::SceneToFilm).is_some() {
                    passed.push(p);
                }
            }
        }
        if passed.is_empty() {
            return None;
        }
        let centre = passed.iter().copied().sum::<DVec2>() / passed.len() as f64;
        let r = passed.iter().map(|p| (*p - centre).length()).fold(0.0, f64::max);
        let cell = 2.0 * reach / n as f64;
        Some(Aim { z_mm: z, centre_mm: centre, radius_mm: (r + cell) * 1.25 })
    }
}

/// Points of a spiral pattern on the unit disc (a golden-angle spiral: even density, no
/// clumps, the same every time).
pub fn disc_pattern(count: usize) -> Vec<DVec2> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..count)
        .map(|k| {
            let r = ((k as f64 + 0.5) / count as f64).sqrt();
            let phi = k as f64 * golden;
            DVec2::new(r * phi.cos(), r * phi.sin())
        })
        .collect()
}

/// Interpolated points per grid cell side, by default (4 points per cell, 16 per edge cell).
pub const DEFAULT_SUBSAMPLES: usize = 2;

/// The fixed pupil sample pattern of a fit (points on the unit disc, scaled onto the aim disc).
#[derive(Debug, Clone, PartialEq)]
pub enum Pattern {
    /// Every point traced (a golden-angle spiral, [`disc_pattern`]).
    Spiral(Vec<DVec2>),
    /// A square grid of `cells × cells` over [−1, 1]², its corners traced. A cell whose four
    /// corners pass carries `sub × sub` points whose landings and light are interpolated
    /// bilinearly from the corners (the pupil → sensor map is smooth inside the aperture); a
    /// cell with one to three passing corners is on an edge of the aperture (the stop, a
    /// vignetting rim) and its `edge_sub × edge_sub` points are traced one by one.
    Grid {
        /// Cells per side.
        cells: usize,
        /// Points per cell side inside the aperture.
        sub: usize,
        /// Points per cell side on its edges.
        edge_sub: usize,
    },
}

impl Pattern {
    /// A spiral of `rays` points.
    pub fn spiral(rays: usize) -> Pattern {
        Pattern::Spiral(disc_pattern(rays))
    }

    /// A grid with about `rays` traced corners on the unit disc, `sub × sub` points per interior
    /// cell (`sub` = 0 or 1: one, at the cell's centre) and `2 sub × 2 sub` per edge cell.
    pub fn grid(rays: usize, sub: usize) -> Pattern {
        Pattern::grid_edges(rays, sub, 2 * sub.max(1))
    }

    /// A grid as [`Pattern::grid`] with `edge_sub × edge_sub` points per edge cell.
    pub fn grid_edges(rays: usize, sub: usize, edge_sub: usize) -> Pattern {
        let cells = ((4.0 * rays as f64 / std::f64::consts::PI).sqrt().round() as usize).saturating_sub(1).max(2);
        Pattern::Grid { cells, sub: sub.max(1), edge_sub: edge_sub.max(1) }
    }

    /// The fit's pattern: a grid for `subsamples` ≥ 1, else a spiral.
    pub fn for_fit(rays: usize, subsamples: usize) -> Pattern {
        if subsamples >= 1 {
            Pattern::grid(rays, subsamples)
        } else {
            Pattern::spiral(rays)
        }
    }

    /// The nominal traced rays (corners on the disc for a grid, before edge cells).
    pub fn rays(&self) -> usize {
        match self {
            Pattern::Spiral(points) => points.len(),
            Pattern::Grid { cells, .. } => {
                (std::f64::consts::PI / 4.0 * ((cells + 1) * (cells + 1)) as f64).round() as usize
            }
        }
    }
}

/// Where a capture's pixels are on the full sensor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frame {
    /// The full sensor.
    pub sensor: SensorSpec,
    /// Top-left pixel of the image on the full sensor.
    pub crop_origin_px: [i64; 2],
    /// Image width in pixels.
    pub width: usize,
    /// Image height in pixels.
    pub height: usize,
}

/// Where rays land on the image (continuous pixel coordinates, x right, y down, pixel (i, j)
/// covering [i, i+1] × [j, j+1]) with their light, before any sub-pixel shift.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Landing {
    /// Pixel position of each ray that reached the sensor.
    pub positions_px: Vec<DVec2>,
    /// Its light (solid angle of its pupil cell × stop transmission; the scale is fitted).
    pub weights: Vec<f64>,
    /// Half-widths of each ray's box footprint (its pupil cell on the image; empty, or zero
    /// for one ray: a square from the landing's density, [`auto_footprint_px`]).
    pub half_widths_px: Vec<DVec2>,
}

/// Traces the fixed pattern from the source through the lens onto the (tilted) sensor; with a
/// `correction` (LRTF correction mode), through the lens with its outgoing rays corrected.
#[allow(clippy::too_many_arguments)]
pub fn land(
    lens: &Lens,
    camera: &CameraParams,
    correction: Option<&Correction>,
    geometry: &Geometry,
    aim: &Aim,
    pattern: &Pattern,
    wavelength_nm: f64,
    frame: &Frame,
) -> Landing {
    let rotation = DMat3::from_rotation_y(-camera.sensor_tilt_y_deg.to_radians())
        * DMat3::from_rotation_x(camera.sensor_tilt_x_deg.to_radians());
    let normal = rotation * DVec3::Z;
    let pivot = DVec3::new(0.0, 0.0, geometry.film_z_mm);
    let (pitch_x, pitch_y) = frame.sensor.pitch_mm();
    let s = geometry.source_mm;
    // one ray: its image pixel and its light per mm² of the aim plane
    let trace = |u: DVec2| -> Option<(DVec2, f64)> {
        // 1. A ray from the source to its pupil point; light ∝ the solid angle per area.
        let target = DVec3::new(aim.centre_mm.x + u.x * aim.radius_mm, aim.centre_mm.y + u.y * aim.radius_mm, aim.z_mm);
        let to = target - s;
        let r2 = to.length_squared();
        let cos = to.z / r2.sqrt();
        // 2. Through the lens (in correction mode: the start-lens ray standing for this one).
        let ray = match correction {
            Some(c) if !c.is_zero() => c.uncorrect_incoming(s, to)?,
            _ => Ray::new(s, to),
        };
        let out = lens.trace(&ray, wavelength_nm, TraceDirection::SceneToFilm)?;
        // 3. Onto the sensor plane.
        let d = out.ray.direction;
        let denom = d.dot(normal);
        if !(denom > 1e-12) {
            return None;
        }
        let t = (pivot - out.ray.origin).dot(normal) / denom;
        let hit = out.ray.origin + d * t;
        let q = rotation.transpose() * (hit - pivot);
        // 4. Sensor point → upright image pixel (the image is inverted on the sensor).
        let col = frame.sensor.pixels[0] as f64 / 2.0 - q.x / pitch_x - frame.crop_origin_px[0] as f64;
        let row = frame.sensor.pixels[1] as f64 / 2.0 + q.y / pitch_y - frame.crop_origin_px[1] as f64;
        let w = cos / r2 * out.transmission;
        (col.is_finite() && row.is_finite() && w.is_finite()).then_some((DVec2::new(col, row), w))
    };
    let mut landing = Landing::default();
    match pattern {
        Pattern::Spiral(points) => {
            let cell_area = std::f64::consts::PI * aim.radius_mm * aim.radius_mm / points.len() as f64;
            let traced: Vec<Option<(DVec2, f64)>> = points.par_iter().map(|u| trace(*u)).collect();
            for (p, w) in traced.into_iter().flatten() {
                landing.positions_px.push(p);
                landing.weights.push(w * cell_area);
            }
        }
        Pattern::Grid { cells, sub, edge_sub } => {
            for (p, w, half) in land_grid(&trace, *cells, *sub, *edge_sub, aim.radius_mm) {
                landing.positions_px.push(p);
                landing.weights.push(w);
                landing.half_widths_px.push(half);
            }
        }
    }
    landing
}

/// One landed point: pixel position, light, and its footprint's half-widths (zero: from the
/// landing's density, [`auto_footprint_px`]).
type Point = (DVec2, f64, DVec2);

/// The half-widths of a box with the second moments of the parallelogram spanned by `e1` and
/// `e2` (a point's share of the pupil, mapped onto the image): `½ √(e1ₓ² + e2ₓ²)` per axis.
fn box_half_widths(e1: DVec2, e2: DVec2) -> DVec2 {
    DVec2::new((e1.x * e1.x + e2.x * e2.x).sqrt(), (e1.y * e1.y + e2.y * e2.y).sqrt()) * 0.5
}

/// The grid pattern's landings: corners traced, interior cells interpolated, edge cells traced
/// point by point (in a fixed order, whatever the threads). Each point's footprint is its share
/// of the pupil mapped onto the image (from the cell's bilinear map, or from its traced
/// neighbours on an edge), so adjacent footprints tile the image as the pupil cells tile the pupil.
fn land_grid(
    trace: &(dyn Fn(DVec2) -> Option<(DVec2, f64)> + Sync),
    cells: usize,
    sub: usize,
    edge_sub: usize,
    radius_mm: f64,
) -> Vec<Point> {
    let n = cells;
    let step = 2.0 / n as f64;
    let corner_u = |i: usize, j: usize| DVec2::new(-1.0 + i as f64 * step, -1.0 + j as f64 * step);
    // 1. Corners on (or within a cell's diagonal of) the unit disc are traced.
    let reach = 1.0 + step * std::f64::consts::SQRT_2;
    let corners: Vec<Option<(DVec2, f64)>> = (0..(n + 1) * (n + 1))
        .into_par_iter()
        .map(|k| {
            let u = corner_u(k % (n + 1), k / (n + 1));
            if u.length() <= reach {
                trace(u)
            } else {
                None
            }
        })
        .collect();
    // 2. Each cell's points: light per point = density × the point's share of the cell's area.
    let point_area = (radius_mm * step / sub as f64).powi(2);
    let edge_area = (radius_mm * step / edge_sub as f64).powi(2);
    let inv = 1.0 / sub as f64;
    let rows: Vec<Vec<Point>> = (0..n)
        .into_par_iter()
        .map(|j| {
            let mut out = Vec::new();
            for i in 0..n {
                let c = [
                    corners[j * (n + 1) + i],
                    corners[j * (n + 1) + i + 1],
                    corners[(j + 1) * (n + 1) + i],
                    corners[(j + 1) * (n + 1) + i + 1],
                ];
                match c {
                    [None, None, None, None] => {}
                    [Some(p00), Some(p10), Some(p01), Some(p11)] => {
                        // interior: bilinear in the cell, footprints from its derivatives
                        for b in 0..sub {
                            for a in 0..sub {
                                let (fa, fb) = ((a as f64 + 0.5) * inv, (b as f64 + 0.5) * inv);
                                let w00 = (1.0 - fa) * (1.0 - fb);
                                let (w10, w01, w11) = (fa * (1.0 - fb), (1.0 - fa) * fb, fa * fb);
                                let p = p00.0 * w00 + p10.0 * w10 + p01.0 * w01 + p11.0 * w11;
                                let density = p00.1 * w00 + p10.1 * w10 + p01.1 * w01 + p11.1 * w11;
                                let da = ((p10.0 - p00.0) * (1.0 - fb) + (p11.0 - p01.0) * fb) * inv;
                                let db = ((p01.0 - p00.0) * (1.0 - fa) + (p11.0 - p10.0) * fa) * inv;
                                out.push((p, density * point_area, box_half_widths(da, db)));
                            }
                        }
                    }
                    _ => out.extend(edge_cell(trace, corner_u(i, j), step, edge_sub, c, edge_area)),
                }
            }
            out
        })
        .collect();
    rows.into_iter().flatten().collect()
}

/// An edge cell's points, each traced; a point's footprint from the differences to its traced
/// neighbours in the cell (else the cell's passing corner edges; else the landing's density).
fn edge_cell(
    trace: &(dyn Fn(DVec2) -> Option<(DVec2, f64)> + Sync),
    origin: DVec2,
    step: f64,
    sub: usize,
    c: [Option<(DVec2, f64)>; 4],
    point_area: f64,
) -> Vec<Point> {
    let inv = 1.0 / sub as f64;
    let traced: Vec<Option<(DVec2, f64)>> = (0..sub * sub)
        .map(|k| {
            let (a, b) = (k % sub, k / sub);
            trace(origin + DVec2::new((a as f64 + 0.5) * inv, (b as f64 + 0.5) * inv) * step)
        })
        .collect();
    let pos = |a: usize, b: usize| traced[b * sub + a].map(|t| t.0);
    let corner_edge = |x: Option<(DVec2, f64)>, y: Option<(DVec2, f64)>| Some((y?.0 - x?.0) * inv);
    // the corner edges along a (00→10, 01→11) and along b (00→01, 10→11)
    let cell_a = corner_edge(c[0], c[1]).or_else(|| corner_edge(c[2], c[3]));
    let cell_b = corner_edge(c[0], c[2]).or_else(|| corner_edge(c[1], c[3]));
    let mut out = Vec::new();
    for b in 0..sub {
        for a in 0..sub {
            let Some((p, density)) = traced[b * sub + a] else { continue };
            let along = |fwd: Option<DVec2>, back: Option<DVec2>| fwd.map(|q| q - p).or_else(|| back.map(|q| p - q));
            let da = along((a + 1 < sub).then(|| pos(a + 1, b)).flatten(), (a > 0).then(|| pos(a - 1, b)).flatten())
                .or(cell_a);
            let db = along((b + 1 < sub).then(|| pos(a, b + 1)).flatten(), (b > 0).then(|| pos(a, b - 1)).flatten())
                .or(cell_b);
            let half = match (da, db) {
                (Some(da), Some(db)) => box_half_widths(da, db),
                // one direction known: the other as long, at right angles
                (Some(e), None) | (None, Some(e)) => box_half_widths(e, e.perp()),
                (None, None) => DVec2::ZERO,
            };
            out.push((p, density * point_area, half));
        }
    }
    out
}

/// A footprint of one and a half ray spacings: `1.5 √(A / N)` for N rays spread over the area A of
/// a disc of twice their rms radius, within [0.02, 2] px (a sharp spot keeps its caustics, a
/// wide defocus disc is covered without gaps; a 0.25 px floor measurably blurred sharp off-axis
/// spots against optiland, 1.9–2.1 % residual). It varies smoothly with the landing.
pub fn auto_footprint_px(landing: &Landing) -> f64 {
    let w: f64 = landing.weights.iter().sum();
    if !(w > 0.0) || landing.positions_px.len() < 2 {
        return 1.0;
    }
    let c = landing.positions_px.iter().zip(&landing.weights).fold(DVec2::ZERO, |a, (p, wt)| a + *p * *wt) / w;
    let r2 =
        landing.positions_px.iter().zip(&landing.weights).map(|(p, wt)| (*p - c).length_squared() * wt).sum::<f64>()
            / w;
    let area = std::f64::consts::PI * 4.0 * r2;
    (1.5 * (area / landing.positions_px.len() as f64).sqrt()).clamp(0.02, 2.0)
}

/// The overlap of [x − h, x + h] with each pixel [i, i + 1], divided by 2h: (first pixel, up to
/// five weights, h ≤ 1). Continuous in x.
fn overlaps(x: f64, h: f64) -> (i64, [f64; 5]) {
    let lo = x - h;
    let first = lo.floor();
    let mut w = [0.0; 5];
    for (k, wk) in w.iter_mut().enumerate() {
        let a = first + k as f64;
        let overlap = ((a + 1.0).min(x + h) - a.max(lo)).max(0.0);
        *wk = overlap / (2.0 * h);
    }
    (first as i64, w)
}

/// The model image (row-major, top row first) of a landing shifted by `shift_px`: each ray's
/// box footprint integrated over the pixels it covers. The footprint is a square of
/// `footprint_px` when that is positive, else the ray's own (`half_widths_px`), else a square
/// from the landing's density ([`auto_footprint_px`]); own half-widths within [0.0005, 1] px.
pub fn splat(landing: &Landing, shift_px: DVec2, footprint_px: f64, width: usize, height: usize) -> Vec<f64> {
    let own = footprint_px <= 0.0 && landing.half_widths_px.len() == landing.positions_px.len();
    // the square footprint, where some ray has none of its own (the density pass only then)
    let square = if footprint_px > 0.0 {
        footprint_px
    } else if !own || landing.half_widths_px.contains(&DVec2::ZERO) {
        auto_footprint_px(landing)
    } else {
        1.0
    };
    let square = DVec2::splat(0.5 * square.clamp(1e-3, 2.0));
    let mut img = vec![0.0; width * height];
    for (k, (p, &w)) in landing.positions_px.iter().zip(&landing.weights).enumerate() {
        let p = *p + shift_px;
        let h = if own && landing.half_widths_px[k] != DVec2::ZERO {
            landing.half_widths_px[k].clamp(DVec2::splat(5e-4), DVec2::ONE)
        } else {
            square
        };
        let (x0, wx) = overlaps(p.x, h.x);
        let (y0, wy) = overlaps(p.y, h.y);
        for (j, wyj) in wy.iter().enumerate() {
            let y = y0 + j as i64;
            if *wyj == 0.0 || y < 0 || y >= height as i64 {
                continue;
            }
            for (i, wxi) in wx.iter().enumerate() {
                let x = x0 + i as i64;
                if *wxi == 0.0 || x < 0 || x >= width as i64 {
                    continue;
                }
                img[y as usize * width + x as usize] += w * wxi * wyj;
            }
        }
    }
    img
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn overlaps_sum_to_one_and_are_continuous() {
        for &h in &[1.0, 0.5, 0.3, 0.05] {
            let mut prev = overlaps(3.0, h);
            for k in 1..2000 {
                let x = 3.0 + k as f64 * 1e-3;
                let (first, w) = overlaps(x, h);
                assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-12);
                // continuity: the weight on every pixel changes by at most dx / 2h
                for px in first.min(prev.0)..=(first.max(prev.0) + 4) {
                    let get = |(f, w): (i64, [f64; 5])| if px >= f && px < f + 5 { w[(px - f) as usize] } else { 0.0 };
                    assert!((get((first, w)) - get(prev)).abs() <= 1e-3 / (2.0 * h) + 1e-12);
                }
                prev = (first, w);
            }
        }
    }
}
