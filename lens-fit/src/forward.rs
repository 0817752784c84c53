//! The forward model: the image of a point source through the lens on the sensor, traced
//! exactly (scene → film) with a fixed sample pattern, each ray's light integrated over the
//! pixels its footprint covers.
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `rays` | traced rays per wavelength per capture (a grid's corners on the disc) | — | 8 192 |
//! | `subsamples` | points per grid cell side, interpolated from the cell's corners (twice as many near a rim); 0 = a spiral of `rays` points, each traced with hard rims | — | 2 |
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
//! small box whose overlap with each pixel is integrated exactly, so no ray jumps between
//! pixels. With the grid pattern no point switches on or off at a rim either: corners are
//! traced with soft rims ([`Lens::trace_soft`]: every rim lowers a clearance instead of
//! stopping the ray), each point's light is weighted by its coverage, a ramp in its signed
//! distance from the aperture's outline, and a cell's points change from coarse to fine near
//! a rim by a linear blend. The model image is then a continuous function of every parameter;
//! what is left is the trace's rounding (about 1e-8 of Σr² near a fit's end).

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
    /// A square grid of `cells × cells` over [−1, 1]², its corners traced with soft rims. A
    /// cell's points are interpolated bilinearly from its corners (landing, light and distance
    /// from the aperture's outline: the pupil → sensor map is smooth across the rims when they
    /// do not stop the rays), `sub × sub` of them inside the aperture and `edge_sub × edge_sub`
    /// near an edge of it (the stop, a vignetting rim), each weighted by its coverage
    /// ([`land`]). A cell with a corner that misses a surface is traced point by point.
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
/// A spiral traces every point with hard rims; a grid traces its corners with soft rims
/// ([`Lens::trace_soft`]) and weights each point by its smooth coverage ([`land_grid`]).
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
    // per-surface weights turning a rim clearance (mm on the surface) into mm on the aim plane
    let rim_weights = match pattern {
        Pattern::Grid { .. } => rim_weights(lens, s, aim, wavelength_nm),
        Pattern::Spiral(_) => Vec::new(),
    };
    // one ray: its image pixel, its light per mm² of the aim plane and its signed distance
    // from the aperture's outline on the aim plane (mm, +∞ for a hard trace)
    let trace = |u: DVec2| -> Option<(DVec2, f64, f64)> {
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
        let (out, inside_mm) = if rim_weights.is_empty() {
            (lens.trace(&ray, wavelength_nm, TraceDirection::SceneToFilm)?, f64::INFINITY)
        } else {
            lens.trace_soft(&ray, wavelength_nm, TraceDirection::SceneToFilm, &rim_weights).ok()?
        };
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
        (col.is_finite() && row.is_finite() && w.is_finite() && !inside_mm.is_nan()).then_some((
            DVec2::new(col, row),
            w,
            inside_mm,
        ))
    };
    let mut landing = Landing::default();
    match pattern {
        Pattern::Spiral(points) => {
            let cell_area = std::f64::consts::PI * aim.radius_mm * aim.radius_mm / points.len() as f64;
            let traced: Vec<Option<(DVec2, f64, f64)>> = points.par_iter().map(|u| trace(*u)).collect();
            for (p, w, _) in traced.into_iter().flatten() {
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

/// Per-surface weights `1 / gᵢ` that turn a rim clearance on surface `i` (mm) into a distance
/// on the aim plane (mm), where `gᵢ` is how far the beam's crossing point on surface `i` moves
/// per mm of aim point: the mean of `|pᵢ(+δ) − pᵢ(−δ)| / 2δ` along x and y about the aim
/// centre, δ a quarter of the aim radius, traced without rims; `gᵢ` within [1e-3, 1e3]. The
/// outline (clearance 0) does not depend on them, only how wide a rim's soft edge is. All ones
/// when one of the four rays misses a surface.
pub fn rim_weights(lens: &Lens, source_mm: DVec3, aim: &Aim, wavelength_nm: f64) -> Vec<f64> {
    let delta = 0.25 * aim.radius_mm;
    let hits = |offset: DVec2| {
        let target = DVec3::new(aim.centre_mm.x + offset.x, aim.centre_mm.y + offset.y, aim.z_mm);
        lens.trace_unclipped_hits(&Ray::new(source_mm, target - source_mm), wavelength_nm, TraceDirection::SceneToFilm)
            .ok()
    };
    let n = lens.surfaces().len();
    let rays = [DVec2::X, -DVec2::X, DVec2::Y, -DVec2::Y].map(|e| hits(e * delta));
    let [Some(xp), Some(xm), Some(yp), Some(ym)] = rays else { return vec![1.0; n] };
    (0..n)
        .map(|i| {
            let g = ((xp[i] - xm[i]).length() + (yp[i] - ym[i]).length()) / (4.0 * delta);
            1.0 / g.clamp(1e-3, 1e3)
        })
        .collect()
}

/// One landed point: pixel position, light, and its footprint's half-widths (zero: from the
/// landing's density, [`auto_footprint_px`]).
type Point = (DVec2, f64, DVec2);

/// One traced pupil point: pixel position, light per mm² of the aim plane, and the signed
/// distance (mm on the aim plane, positive inside) from the aperture's outline.
type Corner = (DVec2, f64, f64);

/// The half-widths of a box with the second moments of the parallelogram spanned by `e1` and
/// `e2` (a point's share of the pupil, mapped onto the image): `½ √(e1ₓ² + e2ₓ²)` per axis.
fn box_half_widths(e1: DVec2, e2: DVec2) -> DVec2 {
    DVec2::new((e1.x * e1.x + e2.x * e2.x).sqrt(), (e1.y * e1.y + e2.y * e2.y).sqrt()) * 0.5
}

/// The coverage of a point whose pupil square has side `h` (mm on the aim plane) at signed
/// distance `inside_mm` from the outline: a linear ramp from 0 at `−h/2` to 1 at `+h/2`
/// (exact for a straight rim parallel to a side; continuous everywhere).
fn coverage(inside_mm: f64, h: f64) -> f64 {
    (0.5 + inside_mm / h).clamp(0.0, 1.0)
}

/// The grid pattern's landings (in a fixed order, whatever the threads). Corners are traced
/// with soft rims, so every corner near the aperture has a landing and a signed distance from
/// the outline, and the pupil → sensor map is smooth across the rims. Each cell's points are
/// interpolated bilinearly from its corners (position, light and distance), each weighted by
/// its coverage ([`coverage`]): `sub × sub` points where the cell lies inside the outline by
/// more than one cell, `edge_sub × edge_sub` near it, both blended linearly over one cell's
/// width in between; a cell with a corner that misses a surface is traced point by point. Each
/// point's footprint is its share of the pupil mapped onto the image, so adjacent footprints
/// tile the image as the pupil cells tile the pupil. The image is a continuous function of
/// every parameter: no point switches on or off, or between interpolated and traced, at a rim.
fn land_grid(
    trace: &(dyn Fn(DVec2) -> Option<Corner> + Sync),
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
    let corners: Vec<Option<Corner>> = (0..(n + 1) * (n + 1))
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
    // 2. Each cell's points: light per point = density × its share of the cell's area × coverage.
    let cell_mm = radius_mm * step;
    let (h_in, h_edge) = (cell_mm / sub as f64, cell_mm / edge_sub as f64);
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
                if let [Some(c00), Some(c10), Some(c01), Some(c11)] = c {
                    let q = [c00, c10, c01, c11];
                    let d_max = q.iter().map(|c| c.2).fold(f64::NEG_INFINITY, f64::max);
                    let d_min = q.iter().map(|c| c.2).fold(f64::INFINITY, f64::min);
                    // every interpolated distance is a mix of the corners': none can be covered
                    if d_max <= -0.5 * h_edge {
                        continue;
                    }
                    // the share of the coarse points: 0 within h_in/2 of the outline, 1 a cell further in
                    let coarse = ((d_min - 0.5 * h_in) / cell_mm).clamp(0.0, 1.0);
                    if coarse > 0.0 {
                        bilinear_points(&mut out, q, sub, h_in, coarse);
                    }
                    if coarse < 1.0 {
                        bilinear_points(&mut out, q, edge_sub, h_edge, 1.0 - coarse);
                    }
                } else {
                    // a corner missed a surface: trace the cell's points, unless all are far out
                    let near = c.iter().flatten().any(|c| c.2 > -0.5 * h_edge - 1.5 * cell_mm);
                    if near {
                        out.extend(traced_cell(trace, corner_u(i, j), step, edge_sub, h_edge));
                    }
                }
            }
            out
        })
        .collect();
    rows.into_iter().flatten().collect()
}

/// Appends a cell's `sub × sub` points, interpolated bilinearly from its corners
/// `[c00, c10, c01, c11]`, each with light `share × density × (h²) × coverage(distance, h)`
/// (`h` the point's side on the aim plane) and its footprint from the bilinear map's derivatives.
fn bilinear_points(out: &mut Vec<Point>, q: [Corner; 4], sub: usize, h: f64, share: f64) {
    let [c00, c10, c01, c11] = q;
    let inv = 1.0 / sub as f64;
    let area = h * h * share;
    for b in 0..sub {
        for a in 0..sub {
            let (fa, fb) = ((a as f64 + 0.5) * inv, (b as f64 + 0.5) * inv);
            let (w00, w10, w01, w11) = ((1.0 - fa) * (1.0 - fb), fa * (1.0 - fb), (1.0 - fa) * fb, fa * fb);
            let inside = c00.2 * w00 + c10.2 * w10 + c01.2 * w01 + c11.2 * w11;
            let cover = coverage(inside, h);
            if cover <= 0.0 {
                continue;
            }
            let p = c00.0 * w00 + c10.0 * w10 + c01.0 * w01 + c11.0 * w11;
            let density = c00.1 * w00 + c10.1 * w10 + c01.1 * w01 + c11.1 * w11;
            let da = ((c10.0 - c00.0) * (1.0 - fb) + (c11.0 - c01.0) * fb) * inv;
            let db = ((c01.0 - c00.0) * (1.0 - fa) + (c11.0 - c10.0) * fa) * inv;
            out.push((p, density * area * cover, box_half_widths(da, db)));
        }
    }
}

/// A cell's `sub × sub` points, each traced (a corner of the cell missed a surface) and
/// weighted by its coverage; a point's footprint from the differences to its traced
/// neighbours (forward, at the last point backward; else at right angles to the other
/// direction; else from the landing's density).
fn traced_cell(
    trace: &(dyn Fn(DVec2) -> Option<Corner> + Sync),
    origin: DVec2,
    step: f64,
    sub: usize,
    h: f64,
) -> Vec<Point> {
    let inv = 1.0 / sub as f64;
    let traced: Vec<Option<Corner>> = (0..sub * sub)
        .map(|k| {
            let (a, b) = (k % sub, k / sub);
            trace(origin + DVec2::new((a as f64 + 0.5) * inv, (b as f64 + 0.5) * inv) * step)
        })
        .collect();
    let pos = |a: usize, b: usize| traced[b * sub + a].map(|t| t.0);
    let mut out = Vec::new();
    for b in 0..sub {
        for a in 0..sub {
            let Some((p, density, inside)) = traced[b * sub + a] else { continue };
            let cover = coverage(inside, h);
            if cover <= 0.0 {
                continue;
            }
            let along = |fwd: Option<DVec2>, back: Option<DVec2>| fwd.map(|q| q - p).or_else(|| back.map(|q| p - q));
            let da = along((a + 1 < sub).then(|| pos(a + 1, b)).flatten(), (a > 0).then(|| pos(a - 1, b)).flatten());
            let db = along((b + 1 < sub).then(|| pos(a, b + 1)).flatten(), (b > 0).then(|| pos(a, b - 1)).flatten());
            let half = match (da, db) {
                (Some(da), Some(db)) => box_half_widths(da, db),
                // one direction known: the other as long, at right angles
                (Some(e), None) | (None, Some(e)) => box_half_widths(e, e.perp()),
                (None, None) => DVec2::ZERO,
            };
            out.push((p, density * h * h * cover, half));
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

/// The overlap of [x − h, x + h] with each pixel [i, i + 1], divided by 2h: (first pixel, three
/// weights, h ≤ 1). A box of width 2h ≤ 2 starting in pixel `first` ends before pixel
/// `first + 3`, so three weights hold all of it. Continuous in x.
fn overlaps(x: f64, h: f64) -> (i64, [f64; 3]) {
    let lo = x - h;
    // floor without a libm call (baseline x86-64 has no SSE4.1 rounding): exact for |lo| < 2⁶³,
    // and `splat` passes |x| < 10¹⁵
    let truncated = lo as i64;
    let first = if (truncated as f64) > lo { truncated - 1 } else { truncated };
    let first_f = first as f64;
    let mut w = [0.0; 3];
    for (k, wk) in w.iter_mut().enumerate() {
        let a = first_f + k as f64;
        let overlap = ((a + 1.0).min(x + h) - a.max(lo)).max(0.0);
        *wk = overlap / (2.0 * h);
    }
    (first, w)
}

/// Whether `splat` uses the rays' own half-widths, and the square's half-width where a ray has
/// none (the density pass only then).
fn footprints(landing: &Landing, footprint_px: f64) -> (bool, DVec2) {
    let own = footprint_px <= 0.0 && landing.half_widths_px.len() == landing.positions_px.len();
    let square = if footprint_px > 0.0 {
        footprint_px
    } else if !own || landing.half_widths_px.contains(&DVec2::ZERO) {
        auto_footprint_px(landing)
    } else {
        1.0
    };
    (own, DVec2::splat(0.5 * square.clamp(1e-3, 2.0)))
}

/// The model image (row-major, top row first) of a landing shifted by `shift_px`: each ray's
/// box footprint integrated over the pixels it covers. The footprint is a square of
/// `footprint_px` when that is positive, else the ray's own (`half_widths_px`), else a square
/// from the landing's density ([`auto_footprint_px`]); own half-widths within [0.0005, 1] px.
pub fn splat(landing: &Landing, shift_px: DVec2, footprint_px: f64, width: usize, height: usize) -> Vec<f64> {
    let (own, square) = footprints(landing, footprint_px);
    let mut img = vec![0.0; width * height];
    for (k, (p, &w)) in landing.positions_px.iter().zip(&landing.weights).enumerate() {
        let p = *p + shift_px;
        // far outside the image (or not a number): no pixel to add to
        if !(p.x.abs() < 1e15 && p.y.abs() < 1e15) {
            continue;
        }
        let h = if own && landing.half_widths_px[k] != DVec2::ZERO {
            landing.half_widths_px[k].clamp(DVec2::splat(5e-4), DVec2::ONE)
        } else {
            square
        };
        let (x0, wx) = overlaps(p.x, h.x);
        let (y0, wy) = overlaps(p.y, h.y);
        // the footprint's cells inside the image
        let (i_lo, i_hi) = ((-x0).clamp(0, 3) as usize, (width as i64 - x0).clamp(0, 3) as usize);
        let (j_lo, j_hi) = ((-y0).clamp(0, 3) as usize, (height as i64 - y0).clamp(0, 3) as usize);
        for (j, &wyj) in wy.iter().enumerate().take(j_hi).skip(j_lo) {
            if wyj == 0.0 {
                continue;
            }
            let row = (y0 + j as i64) as usize * width;
            for (i, &wxi) in wx.iter().enumerate().take(i_hi).skip(i_lo) {
                if wxi != 0.0 {
                    img[row + (x0 + i as i64) as usize] += w * wxi * wyj;
                }
            }
        }
    }
    img
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The splat as it was before it kept three weights per axis (five, each cell checked; the
    /// footprint choice is the same): the reference the faster one must match bit for bit.
    fn splat_five_weights(
        landing: &Landing,
        shift_px: DVec2,
        footprint_px: f64,
        width: usize,
        height: usize,
    ) -> Vec<f64> {
        let (own, square) = footprints(landing, footprint_px);
        let five = |x: f64, h: f64| {
            let lo = x - h;
            let first = lo.floor();
            let mut w = [0.0; 5];
            for (k, wk) in w.iter_mut().enumerate() {
                let a = first + k as f64;
                *wk = ((a + 1.0).min(x + h) - a.max(lo)).max(0.0) / (2.0 * h);
            }
            (first as i64, w)
        };
        let mut img = vec![0.0; width * height];
        for (k, (p, &w)) in landing.positions_px.iter().zip(&landing.weights).enumerate() {
            let p = *p + shift_px;
            let h = if own && landing.half_widths_px[k] != DVec2::ZERO {
                landing.half_widths_px[k].clamp(DVec2::splat(5e-4), DVec2::ONE)
            } else {
                square
            };
            let ((x0, wx), (y0, wy)) = (five(p.x, h.x), five(p.y, h.y));
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

    #[test]
    fn splat_matches_the_five_weight_splat_bit_for_bit() {
        // rays inside, across the borders and far outside a 13 × 9 image; own footprints from
        // 0.0001 px (clamped) to 1.3 px (clamped), some zero (the square from the density)
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        for case in 0..40 {
            let n = 200;
            let mut landing = Landing { positions_px: vec![], weights: vec![], half_widths_px: vec![] };
            for k in 0..n {
                let spread = if k % 17 == 0 { 1e6 } else { 20.0 };
                landing.positions_px.push(DVec2::new(next() * spread - 3.5, next() * spread - 5.25));
                landing.weights.push(next() + 1e-3);
                let hw = if case % 3 == 0 && k % 11 == 0 { DVec2::ZERO } else { DVec2::new(next(), next()) * 1.3 };
                landing.half_widths_px.push(hw);
            }
            if case % 4 == 1 {
                landing.half_widths_px.clear();
            }
            let footprint = [0.0, 0.4, 1.0, 2.7][case % 4];
            let shift = DVec2::new(next() - 0.5, next() - 0.5) * 3.0;
            let fast = splat(&landing, shift, footprint, 13, 9);
            let reference = splat_five_weights(&landing, shift, footprint, 13, 9);
            for (a, b) in fast.iter().zip(&reference) {
                assert_eq!(a.to_bits(), b.to_bits(), "case {case}");
            }
        }
    }

    #[test]
    fn overlaps_sum_to_one_and_are_continuous() {
        for &h in &[1.0, 0.5, 0.3, 0.05] {
            let mut prev = overlaps(3.0, h);
            for k in 1..2000 {
                let x = 3.0 + k as f64 * 1e-3;
                let (first, w) = overlaps(x, h);
                assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-12);
                // continuity: the weight on every pixel changes by at most dx / 2h
                for px in first.min(prev.0)..=(first.max(prev.0) + 2) {
                    let get = |(f, w): (i64, [f64; 3])| if px >= f && px < f + 3 { w[(px - f) as usize] } else { 0.0 };
                    assert!((get((first, w)) - get(prev)).abs() <= 1e-3 / (2.0 * h) + 1e-12);
                }
                prev = (first, w);
            }
        }
    }
}
