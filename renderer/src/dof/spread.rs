//! PSF spreading (scattering) of depth-peeled [`Layers`]: every texel of every layer spreads its
//! radiance onto the sensor as its point spread function, slice by slice in inverse depth, and
//! the slices are composited front to back (partial occlusion: the layers hidden behind a near
//! out-of-focus object show through its blurred edges).
//!
//! * **PSF of a texel** (world point X = texel direction × depth). Thin lens, tilted and shifted
//!   sensors included: every ray from X through the aperture passes the conjugate point X′, so
//!   the PSF is the aperture outline (circle, blade polygon, curved blades or a mask's convex
//!   outline) projected centrally from X′ onto the sensor plane, computed in homogeneous
//!   coordinates (X′ may be at infinity, or virtual). Under tilt that is a projectively
//!   distorted polygon (a conic section for a circular stop). Real lenses (exact trace, LRTF
//!   table, thick lens): a table of PSF outlines over (field radius on the sensor, inverse depth)
//!   made by tracing real rays: for a point X and a G × G grid of pupil samples u, Newton's
//!   method (2-D, finite-difference Jacobian; the samples solved outwards from the grid's
//!   centre, each from its neighbour's solution) finds the film point whose ray for u passes
//!   through X; vignetted samples drop out (the cat's eye towards the corners) and the convex
//!   hull of the solutions, stored as radii about its centroid, is the outline; the lens is
//!   rotationally symmetric, so a radial table suffices, looked up bilinearly. For the exact
//!   and LRTF models u is a fixed point of the rear plane, traced exactly through the lens (the
//!   cameras' own lens sample u maps to the exit pupil piecewise over film radius and turned
//!   with the film azimuth, so `generate_ray(s, u)` jumps as s moves and Newton stalls); the
//!   thick lens uses its own `generate_ray` (smooth in s). The chief map (object tangent →
//!   sensor radius) follows the ray through the entrance pupil's centre. A pinhole's PSF is a
//!   point.
//! * **Energy**. A texel of radiance L gives its PSF the energy L · w̄(p) · J: w̄ the mean camera
//!   ray weight at its chief film point p (exposure, natural and mechanical vignetting; a table
//!   over the film), J the texel's footprint on the sensor in pixels (≈ 1 on a rectilinear
//!   image), so a flat field stays flat. The energy is spread uniformly over the polygon and
//!   rasterised exactly (signed-area accumulation of the edges and a prefix sum along each row,
//!   as font rasterisers do: exact pixel coverage and exact energy). A PSF smaller than a pixel
//!   is a one-pixel square at its centre: a bilinear splat.
//! * **Slices**. Texels are binned by inverse depth w = 1/z into S slices of equal width in w
//!   (the circle of confusion is affine in w, so each slice spans the same range of blur); S is
//!   the blur range over the layers' depths divided by [`SpreadSettings::slice_blur_px`]
//!   (clamped to 1..=[`SpreadSettings::max_slices`]): an in-focus scene is one slice, a strongly
//!   defocused one gets the most. The environment (depth +inf) is the farthest slice. Each slice
//!   spreads into its own premultiplied RGB + coverage (+ depth) buffer; the colour of a slice
//!   is normalised by its coverage where that exceeds 1 (two layers of one slice overlapping),
//!   and the slices are composited front to back with [`Composite`] (`over` by default).
//! * **Batch shape**. Per slice: a PSF kernel over its texels (flat vertex and splat arrays),
//!   binning of the splats into bands of rows, rasterisation per band, a row scan and the
//!   composite; no per-pixel allocation. Every stage runs in parallel (rayon) over fixed chunks
//!   in a fixed order, so the image is identical for any thread count.
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `slice_blur_px` | f64: blur range (circle-of-confusion diameter) per depth slice | px | 2 |
//! | `max_slices` | usize: most depth slices (plus the environment's) | — | 32 |
//! | `composite` | [`Composite`]: `over` or `saturate` | — | `over` |
//! | `table_radii` | usize: field radii of a real lens's PSF table | — | 12 |
//! | `table_depths` | usize: inverse depths of a real lens's PSF table | — | 16 |
//! | `pupil_grid` | usize: pupil samples per side (G², solved by Newton) per table entry | — | 24 |
//!
//! * **Layers as they come**: each texel's surfaces carry their own radiance and coverage (see
//!   [`super::layers`]), so a splat carries radiance × coverage and adds coverage to its slice;
//!   hidden texels the layers did not shade (no lens ray reaches them) are skipped, and a
//!   deeper layer's texel that the first layer hides from every point of the aperture (its
//!   parallax against the first layer is smaller than the occluder around it) is dropped, so the
//!   back of a closed double-sided object does not add to its front.
//!
//! Limits: texels outside the layer frame are lost (the frame's margin must cover the blur);
//! within one slice the layers are not ordered (hidden texels that are visible from part of the
//! aperture mix into the visible surface of their slice); a real lens with a tilted sensor is
//! refused (its PSFs are not rotationally symmetric); the intensity inside a PSF is uniform (no
//! aberration structure); a real lens's PSF energy uses the mean ray weight at its chief point,
//! exact in focus, approximate for a defocused point whose bundle the rims cut differently.

use super::layers::Layers;
use crate::camera::{Camera, Sensor};
use crate::error::{Error, Result};
use crate::film::Image;
use crate::integrator::RenderScene;
use crate::optics::aperture::{Aperture, ApertureShape};
use crate::render::{Progress, RenderResult, RenderSettings};
use glam::{DMat3, DVec2, DVec3};
use rayon::prelude::*;
use std::f64::consts::TAU;
use std::time::Instant;

/// How the depth slices are composited front to back.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Composite {
    /// Porter–Duff "over": `C += (1 − A)·c`, `A += (1 − A)·a`.
    #[default]
    Over,
    /// Saturating addition (OpenGL's `SRC_ALPHA_SATURATE`): a slice adds until the coverage
    /// reaches 1, so the blurred edges of one surface split over two slices leave no seam.
    Saturate,
}

/// Settings of PSF spreading (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpreadSettings {
    /// Blur range per depth slice (circle-of-confusion diameter, pixels).
    pub slice_blur_px: f64,
    /// Most depth slices (the environment's comes on top).
    pub max_slices: usize,
    /// Slice compositing.
    pub composite: Composite,
    /// Field radii of a real lens's PSF table.
    pub table_radii: usize,
    /// Inverse depths of a real lens's PSF table.
    pub table_depths: usize,
    /// Pupil samples per side per table entry.
    pub pupil_grid: usize,
}

impl Default for SpreadSettings {
    fn default() -> Self {
        SpreadSettings {
            slice_blur_px: 2.0,
            max_slices: 32,
            composite: Composite::Over,
            table_radii: 12,
            table_depths: 16,
            pupil_grid: 24,
        }
    }
}

impl SpreadSettings {
    /// Checks the settings.
    pub fn validate(&self) -> Result<()> {
        let bad = |f: &str, m: String| Err(Error::settings(f, m));
        if !(self.slice_blur_px.is_finite() && self.slice_blur_px > 0.0) {
            return bad("slice_blur_px", format!("{} must be a positive number", self.slice_blur_px));
        }
        if !(1..=256).contains(&self.max_slices) {
            return bad("max_slices", format!("{} must be in 1..=256", self.max_slices));
        }
        if !(2..=64).contains(&self.table_radii) || !(2..=64).contains(&self.table_depths) {
            return bad("table", format!("{}×{} entries: each must be in 2..=64", self.table_radii, self.table_depths));
        }
        if !(3..=64).contains(&self.pupil_grid) {
            return bad("pupil_grid", format!("{} must be in 3..=64", self.pupil_grid));
        }
        Ok(())
    }
}

/// Vertices of a circular aperture outline.
const CIRCLE_VERTICES: usize = 64;
/// Angles of a real lens's tabulated PSF outline.
const TABLE_ANGLES: usize = 32;
/// Rows per rasterisation band.
const BAND_ROWS: usize = 8;
/// Texels per PSF-kernel chunk.
const CHUNK: usize = 4096;
/// Weight-table nodes per side, over film coordinates [−WEIGHT_MARGIN, 1 + WEIGHT_MARGIN].
const WEIGHT_NODES: usize = 25;
/// Margin of the weight table beyond the frame (film units; the layers' default margin is
/// 0.15 of the frame, beyond it the table's edge is used).
const WEIGHT_MARGIN: f64 = 0.25;
/// Depth standing in for infinity in the real-lens table (m).
const FAR_M: f64 = 1e6;

/// Spreads `layers` (made of `scene`, which, if given, supplies the environment behind the
/// silhouettes of the deeper layers) through `camera` into an image of `settings`' size (and
/// crop window).
/// `progress` sees the fraction of slices done and may cancel (the result is then incomplete).
pub fn render_spread(
    layers: &Layers,
    scene: Option<&RenderScene>,
    camera: &Camera,
    settings: &RenderSettings,
    spread: &SpreadSettings,
    progress: Progress,
) -> Result<RenderResult> {
    settings.validate()?;
    spread.validate()?;
    let n = layers.count.checked_mul(layers.frame.texels());
    if n != Some(layers.depth_m.len())
        || n != Some(layers.radiance.len())
        || !layers.frame.tan_min.is_finite()
        || !layers.frame.tan_max.is_finite()
    {
        return Err(Error::settings(
            "layers",
            format!(
                "{} layers of {}×{} texels do not match {} depths and {} radiances (or the frame is not finite)",
                layers.count,
                layers.frame.width,
                layers.frame.height,
                layers.depth_m.len(),
                layers.radiance.len()
            ),
        ));
    }
    let start = Instant::now();
    let (w, h) = (settings.width, settings.height);
    let [x0, y0, x1, y1] = settings.crop.unwrap_or([0, 0, w, h]);
    let view = View { size: DVec2::new(w as f64, h as f64), origin: DVec2::new(x0 as f64, y0 as f64) };
    let (cw, ch) = ((x1 - x0) as usize, (y1 - y0) as usize);
    // 1. Depth range over the layers, the optics (PSF model), the weight table.
    let (mut w_lo, mut w_hi) = (f64::INFINITY, 0.0f64);
    for &z in &layers.depth_m {
        if z.is_finite() && z > 0.0 {
            let wi = 1.0 / z as f64;
            w_lo = w_lo.min(wi);
            w_hi = w_hi.max(wi);
        }
    }
    let has_geometry = w_lo.is_finite();
    if !has_geometry {
        (w_lo, w_hi) = (0.0, 0.0);
    }
    let optics = Optics::new(camera, layers, w_hi, view.size, spread)?;
    let weights = WeightTable::new(camera);
    // 2. Slices: equal steps of inverse depth, as many as the blur range needs.
    let slope = if has_geometry { optics.blur_slope_px(&view, w_lo.min(1.0 / FAR_M), w_hi) } else { 0.0 };
    let blur_range = slope * (w_hi - w_lo);
    let slices = ((blur_range / spread.slice_blur_px).ceil() as usize).clamp(1, spread.max_slices);
    let slice_of = |z: f32| -> usize {
        if !z.is_finite() {
            return slices; // the environment
        }
        let wi = 1.0 / z as f64;
        let t = if w_hi > w_lo { (w_hi - wi) / (w_hi - w_lo) } else { 0.0 };
        ((t * slices as f64) as usize).min(slices - 1)
    };
    // 3. Texels into slices (counting sort; nearest slice first). Of a column of texels that
    //    have left the scene only the first counts (the others repeat the environment).
    let depth = &layers.depth_m;
    let occluded = Occluders::new(layers);
    let texels = layers.frame.texels();
    let mut keep = Vec::with_capacity(depth.len());
    for k in 0..layers.count {
        for t in 0..texels {
            let z = depth[k * texels + t];
            let repeated = k > 0 && !z.is_finite() && !depth[(k - 1) * texels + t].is_finite();
            let usable = !z.is_nan()
                && z > 0.0
                && !repeated
                && layers.radiance[k * texels + t].is_finite()
                && layers.shaded[k * texels + t]
                && !(k > 0 && occluded.hidden(t, z, layers.depth_m[t], slope));
            keep.push(usable);
        }
    }
    let mut counts = vec![0usize; slices + 2];
    for (i, &z) in depth.iter().enumerate() {
        if keep[i] {
            counts[slice_of(z) + 1] += 1;
        }
    }
    for s in 1..counts.len() {
        counts[s] += counts[s - 1];
    }
    let mut order = vec![0u32; counts[slices + 1]];
    let mut fill = counts.clone();
    for (i, &z) in depth.iter().enumerate() {
        if keep[i] {
            let s = slice_of(z);
            order[fill[s]] = i as u32;
            fill[s] += 1;
        }
    }
    // 4. Per slice: PSFs → bands → raster → scan → composite.
    let stride = cw + 2;
    let mut acc = vec![[0.0f64; 5]; stride * ch];
    let mut out = vec![[0.0f64; 3]; cw * ch];
    let mut cover = vec![0.0f64; cw * ch];
    let mut depth_sum = vec![0.0f64; cw * ch];
    let mut depth_weight = vec![0.0f64; cw * ch];
    let mut alpha_geometry = vec![0.0f64; cw * ch];
    let mut complete = true;
    let _ = scene;
    let ctx = Kernel { layers, radiance: &layers.radiance, depth, optics: &optics, weights: &weights, view: &view };
    for s in 0..=slices {
        if !progress(s as f32 / (slices + 1) as f32) {
            complete = false;
            break;
        }
        if s == slices {
            alpha_geometry.copy_from_slice(&cover);
        }
        let ids = &order[counts[s]..counts[s + 1]];
        if ids.is_empty() {
            continue;
        }
        // 4a. PSF kernel over fixed chunks, concatenated in order.
        let parts: Vec<(Vec<Splat>, Vec<[f32; 2]>)> = ids.par_chunks(CHUNK).map(|c| ctx.splats(c)).collect();
        let mut splats = Vec::with_capacity(parts.iter().map(|p| p.0.len()).sum());
        let mut verts = Vec::with_capacity(parts.iter().map(|p| p.1.len()).sum());
        for (sp, vs) in parts {
            let base = verts.len() as u32;
            splats.extend(sp.into_iter().map(|mut q| {
                q.first += base;
                q
            }));
            verts.extend(vs);
        }
        // 4b. Bands of rows (CSR lists of the splats meeting each band, in splat order).
        let bands = ch.div_ceil(BAND_ROWS);
        let band_range = |q: &Splat| -> Option<(usize, usize)> {
            if q.y1 < 0.0 || q.y0 >= ch as f32 {
                return None;
            }
            let b0 = (q.y0.max(0.0) as usize / BAND_ROWS).min(bands - 1);
            let b1 = (q.y1.min(ch as f32 - 1e-3).max(0.0) as usize / BAND_ROWS).min(bands - 1);
            Some((b0, b1))
        };
        let mut band_start = vec![0usize; bands + 1];
        for q in &splats {
            if let Some((b0, b1)) = band_range(q) {
                for b in b0..=b1 {
                    band_start[b + 1] += 1;
                }
            }
        }
        for b in 1..=bands {
            band_start[b] += band_start[b - 1];
        }
        let mut band_list = vec![0u32; band_start[bands]];
        let mut band_fill = band_start.clone();
        for (i, q) in splats.iter().enumerate() {
            if let Some((b0, b1)) = band_range(q) {
                for b in b0..=b1 {
                    band_list[band_fill[b]] = i as u32;
                    band_fill[b] += 1;
                }
            }
        }
        // 4c. Raster per band, 4d. scan and composite per row.
        acc.par_chunks_mut(BAND_ROWS * stride).enumerate().for_each(|(b, chunk)| {
            chunk.fill([0.0; 5]);
            let row0 = b * BAND_ROWS;
            let rows = chunk.len() / stride;
            for &i in &band_list[band_start[b]..band_start[b + 1]] {
                let q = &splats[i as usize];
                let vs = &verts[q.first as usize..(q.first + q.count) as usize];
                for e in 0..vs.len() {
                    let (a, c) = (vs[e], vs[(e + 1) % vs.len()]);
                    draw_edge(chunk, stride, row0, row0 + rows, cw as f32, a, c, &q.value);
                }
            }
        });
        let composite = spread.composite;
        let environment = s == slices;
        acc.par_chunks(stride)
            .zip(out.par_chunks_mut(cw))
            .zip(cover.par_chunks_mut(cw))
            .zip(depth_sum.par_chunks_mut(cw).zip(depth_weight.par_chunks_mut(cw)))
            .for_each(|(((arow, orow), crow), (dsum, dw))| {
                let mut run = [0.0f64; 5];
                for x in 0..cw {
                    for (r, a) in run.iter_mut().zip(arow[x]) {
                        *r += a;
                    }
                    let a = run[3];
                    if a <= 1e-9 {
                        continue;
                    }
                    let norm = if a > 1.0 { 1.0 / a } else { 1.0 };
                    let (c, a_s) = ([run[0] * norm, run[1] * norm, run[2] * norm], a * norm);
                    let z = run[4] / a;
                    let t = (1.0 - crow[x]).max(0.0);
                    let (gain, taken) = match composite {
                        Composite::Over => (t, t * a_s),
                        Composite::Saturate => {
                            let take = a_s.min(t);
                            (take / a_s, take)
                        }
                    };
                    for ch in 0..3 {
                        orow[x][ch] += gain * c[ch];
                    }
                    crow[x] += taken;
                    if !environment {
                        dsum[x] += taken * z;
                        dw[x] += taken;
                    }
                }
            });
    }
    // 5. The image.
    let n = cw * ch;
    let image = Image {
        width: cw as u32,
        height: ch as u32,
        rgba: (0..n)
            .map(|i| {
                let [r, g, b] = out[i];
                [r as f32, g as f32, b as f32, alpha_geometry[i].clamp(0.0, 1.0) as f32]
            })
            .collect(),
        depth: (0..n)
            .map(|i| if depth_weight[i] > 1e-6 { (depth_sum[i] / depth_weight[i]) as f32 } else { f32::INFINITY })
            .collect(),
        normal: vec![[0.0; 3]; n],
        albedo: vec![[0.0; 3]; n],
    };
    Ok(RenderResult {
        image,
        spp_done: if complete { settings.spp } else { 0 },
        complete,
        seconds: start.elapsed().as_secs_f64(),
        camera_rays: optics.rays_traced() + weights.rays,
        light_paths: 0,
        light_paths_landed: 0,
        dropped_samples: 0,
    })
}

/// Where the first layer hides the layers behind it from every point of the aperture: the
/// first layer's largest depth over squares of radius 0, 1, 2, 4, … texels.
struct Occluders {
    /// Per radius: the square-window maximum of the first layer's depth.
    max_depth: Vec<(usize, Vec<f32>)>,
}

impl Occluders {
    fn new(layers: &Layers) -> Occluders {
        let f = layers.frame;
        let (w, h) = (f.width, f.height);
        let base: Vec<f32> = layers.depth_m[..f.texels()].to_vec();
        let mut max_depth = vec![(0usize, base.clone())];
        for r in [1usize, 2, 4, 8, 16] {
            let mut rows = vec![0.0f32; w * h];
            for y in 0..h {
                for x in 0..w {
                    let mut m = 0.0f32;
                    for xx in x.saturating_sub(r)..(x + r + 1).min(w) {
                        m = m.max(base[y * w + xx]);
                    }
                    rows[y * w + x] = m;
                }
            }
            let mut out = vec![0.0f32; w * h];
            for y in 0..h {
                for x in 0..w {
                    let mut m = 0.0f32;
                    for yy in y.saturating_sub(r)..(y + r + 1).min(h) {
                        m = m.max(rows[yy * w + x]);
                    }
                    // Beyond the frame nothing is known to occlude.
                    if x < r || y < r || x + r >= w || y + r >= h {
                        m = f32::INFINITY;
                    }
                    out[y * w + x] = m;
                }
            }
            max_depth.push((r, out));
        }
        Occluders { max_depth }
    }

    /// Whether the point of a deeper layer at texel `t`, depth `z` (m), behind the first
    /// layer's `z0` is hidden from every aperture point: seen from the aperture's rim it moves
    /// against the first layer by half the change of blur diameter (`slope` px per 1/m of
    /// inverse depth, texels ≈ pixels), and every first-layer texel within that reach is nearer.
    fn hidden(&self, t: usize, z: f32, z0: f32, slope: f64) -> bool {
        if !(z0 < z) || !z.is_finite() {
            return false;
        }
        // The ray through the texel's centre stays in it for a shift below half a texel.
        let reach = 0.5 * slope * (1.0 / z0 as f64 - 1.0 / z as f64) - 0.5;
        match self.max_depth.iter().find(|(r, _)| *r as f64 >= reach) {
            Some((_, m)) => m[t] < z * (1.0 - 1e-3),
            None => false,
        }
    }
}

/// Whether spreading supports `camera`: every model, but a real lens (exact, LRTF, thick)
/// only with an untilted sensor (its PSF table relies on rotational symmetry).
pub fn check_camera(camera: &Camera) -> Result<()> {
    let s = camera.sensor();
    let real = matches!(camera, Camera::Thick(_) | Camera::Exact(_) | Camera::Lrtf(_));
    if real && (s.tilt_x_deg != 0.0 || s.tilt_y_deg != 0.0) {
        return Err(Error::settings(
            "method",
            "spread: a real lens with a tilted sensor is not supported (its PSFs are not rotationally symmetric); use --lens-model thin, or --method mc or ibrt",
        ));
    }
    Ok(())
}

/// The image window: full-frame pixel size and the crop's top-left pixel.
#[derive(Debug, Clone, Copy)]
struct View {
    size: DVec2,
    origin: DVec2,
}

impl View {
    /// Pixel coordinates (of the crop window) of film coordinates `f`.
    fn px(&self, f: DVec2) -> DVec2 {
        f * self.size - self.origin
    }
}

/// One PSF ready to rasterise: `count` vertices from `first` (pixels of the window), the
/// value per unit area (premultiplied RGB energy, coverage, coverage × depth) and its rows.
#[derive(Debug, Clone, Copy)]
struct Splat {
    first: u32,
    count: u32,
    value: [f64; 5],
    y0: f32,
    y1: f32,
}

/// What the PSF kernel reads.
struct Kernel<'a> {
    layers: &'a Layers,
    /// Radiance as spread (the layers').
    radiance: &'a [glam::Vec3],
    /// Depths as spread (the layers').
    depth: &'a [f32],
    optics: &'a Optics,
    weights: &'a WeightTable,
    view: &'a View,
}

impl Kernel<'_> {
    /// The splats of texels `ids` (indices into the layers), in order.
    fn splats(&self, ids: &[u32]) -> (Vec<Splat>, Vec<[f32; 2]>) {
        let frame = self.layers.frame;
        let texels = frame.texels();
        let mut splats = Vec::with_capacity(ids.len());
        let mut verts: Vec<[f32; 2]> = Vec::with_capacity(ids.len() * 8);
        let mut poly: Vec<DVec2> = Vec::with_capacity(CIRCLE_VERTICES);
        for &i in ids {
            let i = i as usize;
            let t = i % texels;
            let (x, y) = ((t % frame.width) as f64 + 0.5, (t / frame.width) as f64 + 0.5);
            let z = self.depth[i] as f64;
            let dir = frame.direction(DVec2::new(x, y));
            // Footprint: the chief images of the texel's edges.
            let Some(centre) = self.optics.chief(dir) else { continue };
            let edge = |dx: f64, dy: f64| self.optics.chief(frame.direction(DVec2::new(x + dx, y + dy)));
            let (Some(l), Some(r), Some(u), Some(d)) =
                (edge(-0.5, 0.0), edge(0.5, 0.0), edge(0.0, -0.5), edge(0.0, 0.5))
            else {
                continue;
            };
            let (ex, ey) = (self.view.px(r) - self.view.px(l), self.view.px(d) - self.view.px(u));
            let footprint = ex.perp_dot(ey).abs();
            let w_bar = self.weights.at(centre);
            if !(footprint.is_finite() && footprint > 0.0 && w_bar.is_finite() && w_bar >= 0.0) {
                continue;
            }
            // The PSF polygon in window pixels; a sub-pixel one is the one-pixel square.
            poly.clear();
            if !self.optics.psf(dir, z, &mut poly) {
                continue;
            }
            for p in poly.iter_mut() {
                *p = self.view.px(*p);
            }
            let mut area = signed_area(&poly);
            if !area.is_finite() || poly.iter().any(|p| !p.is_finite()) {
                continue;
            }
            if area.abs() < 1.0 {
                let c = poly.iter().copied().sum::<DVec2>() / poly.len().max(1) as f64;
                let c = if c.is_finite() { c } else { self.view.px(centre) };
                poly.clear();
                poly.extend([
                    c + DVec2::new(-0.5, -0.5),
                    c + DVec2::new(-0.5, 0.5),
                    c + DVec2::new(0.5, 0.5),
                    c + DVec2::new(0.5, -0.5),
                ]);
                area = signed_area(&poly);
            }
            // Edges accumulate +1 inside for negative shoelace area (y down): fix the sign.
            let scale = -1.0 / area;
            let radiance = self.radiance[i];
            // The surface covers this share of its texel (the rest shows what lies behind).
            let coverage = self.layers.coverage.get(i).copied().unwrap_or(1.0).clamp(0.0, 1.0) as f64;
            let energy = w_bar * footprint * coverage;
            let depth = if z.is_finite() { z } else { 0.0 };
            let value = [
                radiance.x as f64 * energy * scale,
                radiance.y as f64 * energy * scale,
                radiance.z as f64 * energy * scale,
                footprint * coverage * scale,
                footprint * coverage * depth * scale,
            ];
            let (y0, y1) = poly.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| (a.min(p.y), b.max(p.y)));
            splats.push(Splat {
                first: verts.len() as u32,
                count: poly.len() as u32,
                value,
                y0: y0 as f32,
                y1: y1 as f32,
            });
            verts.extend(poly.iter().map(|p| [p.x as f32, p.y as f32]));
        }
        (splats, verts)
    }
}

/// Shoelace area (positive counter-clockwise in y-up axes).
fn signed_area(p: &[DVec2]) -> f64 {
    let n = p.len();
    (0..n).map(|i| p[i].perp_dot(p[(i + 1) % n])).sum::<f64>() * 0.5
}

/// Accumulates the signed area of edge `a → b` (window pixels, y down) into the rows
/// `row0..row1` of `acc` (`stride` = width + 2; row-local indices), times `value`: a prefix sum
/// along each row then gives every pixel's exact coverage by the closed polygon. x is clamped
/// to [0, `width`]: what lies left of the image still covers it, what lies right does not.
/// (The signed-area accumulation of font-rs, R. Levien, 2016.)
#[allow(clippy::too_many_arguments)]
fn draw_edge(
    acc: &mut [[f64; 5]],
    stride: usize,
    row0: usize,
    row1: usize,
    width: f32,
    a: [f32; 2],
    b: [f32; 2],
    value: &[f64; 5],
) {
    if (a[1] - b[1]).abs() <= f32::EPSILON * (a[1].abs() + 1.0) {
        return;
    }
    let (dir, p0, p1) = if a[1] < b[1] { (1.0f64, a, b) } else { (-1.0f64, b, a) };
    let (p0, p1) = ([p0[0] as f64, p0[1] as f64], [p1[0] as f64, p1[1] as f64]);
    let dxdy = (p1[0] - p0[0]) / (p1[1] - p0[1]);
    let ys = p0[1].floor().max(row0 as f64);
    let ye = p1[1].ceil().min(row1 as f64);
    if ye <= ys {
        return;
    }
    let wmax = width as f64;
    let mut add = |idx: usize, k: f64| {
        let cell = &mut acc[idx];
        for (c, v) in cell.iter_mut().zip(value) {
            *c += k * v;
        }
    };
    for y in ys as usize..ye as usize {
        let top = (y as f64).max(p0[1]);
        let bot = ((y + 1) as f64).min(p1[1]);
        let dy = bot - top;
        if dy <= 0.0 {
            continue;
        }
        let xa = (p0[0] + (top - p0[1]) * dxdy).clamp(0.0, wmax);
        let xb = (p0[0] + (bot - p0[1]) * dxdy).clamp(0.0, wmax);
        let d = dy * dir;
        let line = (y - row0) * stride;
        let (x0, x1) = if xa < xb { (xa, xb) } else { (xb, xa) };
        let x0f = x0.floor();
        let x0i = x0f as usize;
        let x1c = x1.ceil();
        let x1i = x1c as usize;
        if x1i <= x0i + 1 {
            let xmf = 0.5 * (xa + xb) - x0f;
            add(line + x0i, d * (1.0 - xmf));
            add(line + x0i + 1, d * xmf);
        } else {
            let s = 1.0 / (x1 - x0);
            let x0r = x0 - x0f;
            let a0 = 0.5 * s * (1.0 - x0r) * (1.0 - x0r);
            let x1r = x1 - x1c + 1.0;
            let am = 0.5 * s * x1r * x1r;
            add(line + x0i, d * a0);
            if x1i == x0i + 2 {
                add(line + x0i + 1, d * (1.0 - a0 - am));
            } else {
                let a1 = s * (1.5 - x0r);
                add(line + x0i + 1, d * (a1 - a0));
                for xi in x0i + 2..x1i - 1 {
                    add(line + xi, d * s);
                }
                let a2 = a1 + (x1i - x0i - 3) as f64 * s;
                add(line + x1i - 1, d * (1.0 - a2 - am));
            }
            add(line + x1i, d * am);
        }
    }
}

/// Mean camera-ray weight over the lens on a grid of film points (bilinear look-up).
struct WeightTable {
    values: Vec<f64>,
    rays: u64,
}

impl WeightTable {
    fn new(camera: &Camera) -> WeightTable {
        let n = WEIGHT_NODES;
        // A real lens's weights (its pupil sampling has a wide spread of weights) need 32 × 32
        // lens samples for 1%; the other models' are smooth.
        let lens: usize = if camera.real_lens().is_some() { 32 } else { 8 };
        let wavelength = primary_wavelength(camera);
        let values = (0..n * n)
            .into_par_iter()
            .map(|i| {
                let film = Self::node(i % n, i / n);
                let mut sum = 0.0;
                for j in 0..lens * lens {
                    let u =
                        DVec2::new(((j % lens) as f64 + 0.5) / lens as f64, ((j / lens) as f64 + 0.5) / lens as f64);
                    sum += camera.generate_ray(film, u, wavelength).map_or(0.0, |r| r.weight);
                }
                let v = sum / (lens * lens) as f64;
                if v.is_finite() {
                    v
                } else {
                    0.0
                }
            })
            .collect();
        WeightTable { values, rays: (n * n * lens * lens) as u64 }
    }

    fn node(i: usize, j: usize) -> DVec2 {
        let step = (1.0 + 2.0 * WEIGHT_MARGIN) / (WEIGHT_NODES - 1) as f64;
        DVec2::new(-WEIGHT_MARGIN + i as f64 * step, -WEIGHT_MARGIN + j as f64 * step)
    }

    fn at(&self, film: DVec2) -> f64 {
        let n = WEIGHT_NODES;
        let g = (film + DVec2::splat(WEIGHT_MARGIN)) / (1.0 + 2.0 * WEIGHT_MARGIN) * (n - 1) as f64;
        let g = g.clamp(DVec2::ZERO, DVec2::splat((n - 1) as f64 - 1e-9));
        let (i, j) = (g.x as usize, g.y as usize);
        let (fx, fy) = (g.x - i as f64, g.y - j as f64);
        let v = |a: usize, b: usize| self.values[b.min(n - 1) * n + a.min(n - 1)];
        (v(i, j) * (1.0 - fx) + v(i + 1, j) * fx) * (1.0 - fy) + (v(i, j + 1) * (1.0 - fx) + v(i + 1, j + 1) * fx) * fy
    }
}

fn primary_wavelength(camera: &Camera) -> f64 {
    camera.real_lens().map_or(crate::optics::glass::WAVELENGTH_D_NM, |l| l.primary_wavelength_nm())
}

/// Film geometry of the models whose chief ray passes the origin undeviated (pinhole, thin
/// lens): lens frame in mm, film pivot at z = `film_z`.
#[derive(Debug, Clone, Copy)]
struct Plane {
    sensor: Sensor,
    film_z: f64,
    rotation: DMat3,
    normal: DVec3,
}

impl Plane {
    fn new(sensor: Sensor, film_z: f64) -> Plane {
        Plane { sensor, film_z, rotation: sensor.rotation(), normal: sensor.normal() }
    }

    /// Film coordinates of lens-frame point `q` on the sensor plane (inverse of
    /// [`Sensor::film_point`]).
    fn film_of(&self, q: DVec3) -> DVec2 {
        let v = self.rotation.transpose() * (q - DVec3::new(0.0, 0.0, self.film_z));
        let (sx, sy) = (-v.x, -v.y);
        DVec2::new(
            (sx - self.sensor.shift_mm.x) / self.sensor.width_mm + 0.5,
            0.5 - (sy - self.sensor.shift_mm.y) / self.sensor.height_mm,
        )
    }

    /// Where the line through `l` along `d` meets the sensor (film coordinates).
    fn hit(&self, l: DVec3, d: DVec3) -> Option<DVec2> {
        let den = self.normal.dot(d);
        if den.abs() < 1e-12 * d.length() {
            return None;
        }
        let t = self.normal.dot(DVec3::new(0.0, 0.0, self.film_z) - l) / den;
        let f = self.film_of(l + d * t);
        f.is_finite().then_some(f)
    }
}

/// The PSF model of a camera.
enum Optics {
    /// A point at the chief image.
    Pinhole(Plane),
    /// The aperture outline (lens frame, mm, z = 0) projected from the conjugate point.
    Thin { plane: Plane, lens_focal_mm: f64, outline: Vec<DVec3> },
    /// A traced radial table (real lenses).
    Table(Box<PsfTable>),
}

impl Optics {
    fn new(camera: &Camera, layers: &Layers, w_max: f64, view_size: DVec2, spread: &SpreadSettings) -> Result<Optics> {
        Ok(match camera {
            Camera::Pinhole(c) => Optics::Pinhole(Plane::new(*c.sensor(), c.focal_length_mm())),
            Camera::Thin(c) => Optics::Thin {
                plane: Plane::new(*c.sensor(), c.film_distance_mm()),
                lens_focal_mm: c.lens_focal_length_mm(),
                outline: aperture_outline(c.aperture(), c.aperture_radius_mm()),
            },
            Camera::Thick(_) | Camera::Exact(_) | Camera::Lrtf(_) => {
                check_camera(camera)?;
                Optics::Table(Box::new(PsfTable::new(camera, layers, w_max, view_size, spread)?))
            }
            Camera::Orthographic(_) => {
                return Err(Error::settings(
                    "method",
                    "spread: an orthographic camera is not supported (its depth of field is rendered by --method mc)",
                ))
            }
        })
    }

    fn rays_traced(&self) -> u64 {
        match self {
            Optics::Table(t) => t.rays,
            _ => 0,
        }
    }

    /// Film coordinates of the chief image of camera-space direction `dir` (z = −1).
    fn chief(&self, dir: DVec3) -> Option<DVec2> {
        match self {
            Optics::Pinhole(p) | Optics::Thin { plane: p, .. } => p.hit(DVec3::ZERO, dir),
            Optics::Table(t) => t.chief(dir),
        }
    }

    /// Appends the PSF outline (film coordinates) of the point at planar depth `z` (m, may be
    /// +inf) along `dir` (z = −1) to `out`; false if there is none.
    fn psf(&self, dir: DVec3, z: f64, out: &mut Vec<DVec2>) -> bool {
        match self {
            Optics::Pinhole(p) => match p.hit(DVec3::ZERO, dir) {
                Some(c) => {
                    out.push(c);
                    true
                }
                None => false,
            },
            Optics::Thin { plane, lens_focal_mm, outline } => {
                // Conjugate in homogeneous coordinates: X′ = X·f / (X_z + f) with X = dir·z_mm;
                // divided by z_mm: P = dir·f, weight w = f/z_mm − 1 (−1 at infinity).
                let f = *lens_focal_mm;
                let p = dir * f;
                let wgt = if z.is_finite() { f / (z * 1e3) - 1.0 } else { -1.0 };
                let mut sign = 0.0;
                for &l in outline {
                    let d = p - l * wgt;
                    let den = plane.normal.dot(d);
                    // Every outline ray must meet the sensor on the same side of X′ (else the
                    // plane through X′ parallel to the sensor cuts the aperture).
                    if sign == 0.0 {
                        sign = den.signum();
                    } else if den.signum() != sign {
                        return false;
                    }
                    match plane.hit(l, d) {
                        Some(q) => out.push(q),
                        None => return false,
                    }
                }
                out.len() >= 3
            }
            Optics::Table(t) => t.psf(dir, z, out),
        }
    }

    /// Largest rate of change of the blur (PSF diameter, pixels) with inverse depth (per
    /// 1/m) over [w_lo, w_hi], from the PSF at the image centre at nine inverse depths (it is
    /// affine in inverse depth for a thin lens).
    fn blur_slope_px(&self, view: &View, w_lo: f64, w_hi: f64) -> f64 {
        if w_hi <= w_lo {
            return 0.0;
        }
        let dir = DVec3::new(0.0, 0.0, -1.0);
        let mut poly = Vec::new();
        let diam = |wi: f64, poly: &mut Vec<DVec2>| -> Option<f64> {
            poly.clear();
            if !self.psf(dir, 1.0 / wi, poly) {
                return None;
            }
            let px: Vec<DVec2> = poly.iter().map(|p| *p * view.size).collect();
            let (lo, hi) = px.iter().fold((DVec2::INFINITY, DVec2::NEG_INFINITY), |(a, b), p| (a.min(*p), b.max(*p)));
            Some((hi - lo).max_element())
        };
        let n = 9;
        let step = (w_hi - w_lo) / (n - 1) as f64;
        let mut slope: f64 = 0.0;
        let mut prev: Option<f64> = None;
        for i in 0..n {
            let d = diam((w_lo + step * i as f64).max(1e-9), &mut poly);
            if let (Some(a), Some(b)) = (prev, d) {
                slope = slope.max((b - a).abs() / step);
            }
            prev = d;
        }
        slope
    }
}

/// The stop outline (lens frame, mm, z = 0) for circumradius `radius_mm`: the exact vertices of
/// a circle's 64-gon or straight blades; the boundary of curved blades and masks found along
/// 64 rays from the centre (a mask's outline is its convex hull).
fn aperture_outline(aperture: &Aperture, radius_mm: f64) -> Vec<DVec3> {
    let ratio = aperture.anamorphic_ratio;
    let at = |u: f64, v: f64| DVec3::new(u * radius_mm / ratio, v * radius_mm, 0.0);
    match &aperture.shape {
        ApertureShape::Circle => (0..CIRCLE_VERTICES)
            .map(|k| {
                let a = TAU * k as f64 / CIRCLE_VERTICES as f64;
                at(a.cos(), a.sin())
            })
            .collect(),
        ApertureShape::Blades { count, curvature } if *curvature <= 0.0 => {
            let n = (*count).max(3) as f64;
            (0..(*count).max(3))
                .map(|k| {
                    let a = aperture.rotation_rad + std::f64::consts::PI / n + TAU * k as f64 / n;
                    at(a.cos(), a.sin())
                })
                .collect()
        }
        _ => {
            // Largest radius along each direction with light passing (bisection on a march).
            let bound = aperture.bounding_radius_factor();
            let pts: Vec<DVec2> = (0..CIRCLE_VERTICES)
                .filter_map(|k| {
                    let a = TAU * k as f64 / CIRCLE_VERTICES as f64;
                    let e = DVec2::new(a.cos(), a.sin());
                    let steps = 256;
                    let mut best = None;
                    for s in 1..=steps {
                        let r = bound * s as f64 / steps as f64;
                        let (u, v) = (e.x * r, e.y * r);
                        if aperture.transmission(u * radius_mm / ratio, v * radius_mm, radius_mm) > 0.0 {
                            best = Some(DVec2::new(u, v));
                        }
                    }
                    best
                })
                .collect();
            let hull = convex_hull(pts);
            if hull.len() < 3 {
                return aperture_outline(&Aperture { shape: ApertureShape::Circle, ..aperture.clone() }, radius_mm);
            }
            hull.into_iter().map(|p| at(p.x, p.y)).collect()
        }
    }
}

/// Convex hull (Andrew's monotone chain), counter-clockwise, without collinear points.
fn convex_hull(mut pts: Vec<DVec2>) -> Vec<DVec2> {
    pts.retain(|p| p.is_finite());
    pts.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
    pts.dedup();
    if pts.len() < 3 {
        return pts;
    }
    let cross = |o: DVec2, a: DVec2, b: DVec2| (a - o).perp_dot(b - o);
    let mut hull: Vec<DVec2> = Vec::with_capacity(pts.len() * 2);
    for pass in 0..2 {
        let start = hull.len();
        let iter: Box<dyn Iterator<Item = &DVec2>> =
            if pass == 0 { Box::new(pts.iter()) } else { Box::new(pts.iter().rev()) };
        for &p in iter {
            while hull.len() >= start + 2 && cross(hull[hull.len() - 2], hull[hull.len() - 1], p) <= 0.0 {
                hull.pop();
            }
            hull.push(p);
        }
        hull.pop();
    }
    hull
}

/// A PSF outline: its centroid's offset from the chief point (mm; radial, tangential) and its
/// radii about the centroid at [`TABLE_ANGLES`] angles.
type Outline = (DVec2, [f64; TABLE_ANGLES]);

/// A real lens's PSF outlines over (field radius on the sensor, inverse depth), traced (see the
/// module docs), and its chief-ray map (object tangent → sensor radius).
struct PsfTable {
    sensor: Sensor,
    /// Film coordinates of the optical axis.
    axis: DVec2,
    /// Chief map: sensor radii (mm, upright) and the object tangents of their chief rays.
    chief_r: Vec<f64>,
    chief_tan: Vec<f64>,
    /// Table nodes: sensor radii (mm) and inverse depths (1/m).
    radii: Vec<f64>,
    inv_depth: Vec<f64>,
    /// Per (radius, depth) entry, radius-major: the outline's centroid offset from the chief
    /// point (mm, radial/tangential) and its radii at [`TABLE_ANGLES`] angles about it; None
    /// where every pupil sample is vignetted.
    entries: Vec<Option<Outline>>,
    rays: u64,
}

impl PsfTable {
    fn new(
        camera: &Camera,
        layers: &Layers,
        w_max: f64,
        view_size: DVec2,
        settings: &SpreadSettings,
    ) -> Result<PsfTable> {
        let sensor = *camera.sensor();
        let axis = sensor.axis_film_coord();
        let wavelength = primary_wavelength(camera);
        let frame = layers.frame;
        let tan_max = [
            frame.tan_min,
            frame.tan_max,
            DVec2::new(frame.tan_min.x, frame.tan_max.y),
            DVec2::new(frame.tan_max.x, frame.tan_min.y),
        ]
        .iter()
        .map(|t| t.length())
        .fold(0.0f64, f64::max);
        // 1. Chief map along +x (upright) from the axis outwards until the chief rays reach the
        //    frame's largest tangent (or fail). A real lens's: rays through the entrance pupil's
        //    centre traced from the scene to the film (the rays of the cameras' own central lens
        //    sample miss that centre where the rims vignette). A thick lens's: its own.
        let (mut chief_r, mut chief_tan) = (vec![0.0], vec![0.0]);
        let steps = 512;
        let exact = match camera {
            Camera::Exact(c) => Some(c),
            Camera::Lrtf(c) => Some(c.exact()),
            _ => None,
        };
        if let Some(c) = exact {
            let z_ep = c.lens().paraxial().entrance_pupil_z_mm;
            for k in 1..=steps {
                let t = 1.05 * tan_max * k as f64 / steps as f64;
                let dir_in = DVec3::new(-t, 0.0, 1.0).normalize();
                let start = DVec3::new(0.0, 0.0, z_ep) - dir_in * ((z_ep + 500.0) / dir_in.z);
                let ray = crate::optics::lens::Ray::new(start, dir_in);
                let Some(out) = c.lens().trace(&ray, wavelength, crate::optics::lens::TraceDirection::SceneToFilm)
                else {
                    break;
                };
                let (o, d) = (out.ray.origin, out.ray.direction);
                if d.z <= 1e-9 {
                    break;
                }
                let r = -(o.x + d.x * (c.film_z_mm() - o.z) / d.z);
                if !(r > *chief_r.last().unwrap_or(&0.0)) {
                    break;
                }
                chief_r.push(r);
                chief_tan.push(t);
            }
        } else {
            let chief_tangent = |film: DVec2| -> Option<f64> {
                let tries = [DVec2::splat(0.5), DVec2::new(0.5, 0.45), DVec2::new(0.45, 0.5), DVec2::new(0.5, 0.55)];
                let ray = tries.iter().find_map(|&u| camera.generate_ray(film, u, wavelength))?;
                let d = ray.direction;
                (d.z < -1e-9).then(|| d.x.hypot(d.y) / -d.z)
            };
            let reach = 2.0 * sensor.extent().0 + 1.0;
            for k in 1..=steps {
                let r = reach * k as f64 / steps as f64;
                let Some(t) = chief_tangent(axis + DVec2::new(r / sensor.width_mm, 0.0)) else { break };
                if t <= *chief_tan.last().unwrap_or(&0.0) {
                    break;
                }
                chief_r.push(r);
                chief_tan.push(t);
                if t > tan_max {
                    break;
                }
            }
        }
        if chief_r.len() < 3 {
            return Err(Error::settings("method", "spread: the lens's chief rays could not be traced off the axis"));
        }
        let r_max = *chief_r.last().unwrap_or(&1.0);
        let (nr, nd, g) = (settings.table_radii, settings.table_depths, settings.pupil_grid);
        // (The first node half a step off the axis: on it the film azimuth, which turns the pupil
        // sampling, is undefined.)
        let radii: Vec<f64> = (0..nr).map(|i| r_max * (i as f64).max(0.5) / (nr - 1) as f64).collect();
        let w_top = w_max.max(1e-3);
        let inv_depth: Vec<f64> = (0..nd).map(|j| w_top * j as f64 / (nd - 1) as f64).collect();
        // 2. Entries: Newton solves per pupil sample (to 1/1000 of a pixel), in parallel over
        //    entries.
        let tol = 1e-3 / (view_size.x.max(view_size.y)).max(1.0);
        let tol_f = 1e-3 * frame.texel_size().min_element();
        let sampler = PupilRays::new(camera, wavelength);
        let entries: Vec<(Option<Outline>, u64)> = (0..nr * nd)
            .into_par_iter()
            .map(|e| {
                let (i, j) = (e / nd, e % nd);
                let chief_film = axis + DVec2::new(radii[i] / sensor.width_mm, 0.0);
                let tan = interp(&chief_r, &chief_tan, radii[i]);
                let z = if inv_depth[j] > 0.0 { 1.0 / inv_depth[j] } else { FAR_M };
                let x = DVec3::new(tan * z, 0.0, -z);
                let mut rays = 0u64;
                // Pupil samples in breadth-first order from the grid's centre, each started
                // from its parent's solution (continuation: short Newton paths); one that fails
                // restarts from a ring at the extent of the outline so far.
                let mut queue = std::collections::VecDeque::with_capacity(g * g);
                let c = (g / 2) * g + g / 2;
                let mut seen = vec![false; g * g];
                seen[c] = true;
                queue.push_back((c, chief_film));
                let mut pts = Vec::with_capacity(g * g);
                let mut extent = 0.0f64;
                while let Some((m, from)) = queue.pop_front() {
                    let u = DVec2::new(((m % g) as f64 + 0.5) / g as f64, ((m / g) as f64 + 0.5) / g as f64);
                    let ray_at = |s: DVec2| sampler.ray(s, u);
                    let mut solved = solve_film(&ray_at, x, from, tol, tol_f, &mut rays);
                    if solved.is_none() && extent > 0.0 {
                        solved = (0..8).find_map(|a| {
                            let ang = TAU * a as f64 / 8.0;
                            let s0 = chief_film + DVec2::new(ang.cos(), ang.sin()) * extent;
                            solve_film(&ray_at, x, s0, tol, tol_f, &mut rays)
                        });
                    }
                    if let Some(s) = solved {
                        extent = extent.max((s - chief_film).length());
                        let o = s - chief_film;
                        pts.push(DVec2::new(o.x * sensor.width_mm, -o.y * sensor.height_mm));
                    }
                    let (mx, my) = ((m % g) as i64, (m / g) as i64);
                    for (dx, dy) in [(1i64, 0i64), (-1, 0), (0, 1), (0, -1)] {
                        let (nx, ny) = (mx + dx, my + dy);
                        if nx >= 0 && ny >= 0 && nx < g as i64 && ny < g as i64 {
                            let n = ny as usize * g + nx as usize;
                            if !seen[n] {
                                seen[n] = true;
                                queue.push_back((n, solved.unwrap_or(from)));
                            }
                        }
                    }
                }
                (radial_outline(&convex_hull(pts)), rays)
            })
            .collect();
        let rays = entries.iter().map(|e| e.1).sum::<u64>() + chief_r.len() as u64;
        Ok(PsfTable {
            sensor,
            axis,
            chief_r,
            chief_tan,
            radii,
            inv_depth,
            entries: entries.into_iter().map(|e| e.0).collect(),
            rays,
        })
    }

    /// Radial unit vector (upright film mm) and sensor radius of direction `dir`.
    fn polar(&self, dir: DVec3) -> Option<(DVec2, f64)> {
        if dir.z >= 0.0 {
            return None;
        }
        let t = DVec2::new(dir.x / -dir.z, dir.y / -dir.z);
        let rho = t.length();
        if rho > *self.chief_tan.last()? * 1.0001 {
            return None;
        }
        let e = if rho > 1e-12 { t / rho } else { DVec2::X };
        Some((e, interp(&self.chief_tan, &self.chief_r, rho)))
    }

    fn film(&self, offset_mm: DVec2) -> DVec2 {
        self.axis + DVec2::new(offset_mm.x / self.sensor.width_mm, -offset_mm.y / self.sensor.height_mm)
    }

    fn chief(&self, dir: DVec3) -> Option<DVec2> {
        let (e, r) = self.polar(dir)?;
        Some(self.film(e * r))
    }

    fn psf(&self, dir: DVec3, z: f64, out: &mut Vec<DVec2>) -> bool {
        let Some((e, r)) = self.polar(dir) else { return false };
        let w = if z.is_finite() { 1.0 / z } else { 0.0 };
        // Bilinear in (radius, inverse depth) over the valid corners.
        let cell = |nodes: &[f64], v: f64| -> (usize, f64) {
            let n = nodes.len();
            let step = nodes[n - 1] / (n - 1) as f64;
            let g = (v / step).clamp(0.0, (n - 1) as f64 - 1e-9);
            (g as usize, g - g.floor())
        };
        let (i, fi) = cell(&self.radii, r);
        let (j, fj) = cell(&self.inv_depth, w);
        let nd = self.inv_depth.len();
        let mut sum_w = 0.0;
        let mut centre = DVec2::ZERO;
        let mut radii = [0.0f64; TABLE_ANGLES];
        for (di, wi) in [(0, 1.0 - fi), (1, fi)] {
            for (dj, wj) in [(0, 1.0 - fj), (1, fj)] {
                let wgt = wi * wj;
                if wgt <= 0.0 {
                    continue;
                }
                if let Some((c, rs)) = &self.entries[(i + di) * nd + j + dj] {
                    sum_w += wgt;
                    centre += *c * wgt;
                    for (a, b) in radii.iter_mut().zip(rs) {
                        *a += b * wgt;
                    }
                }
            }
        }
        if sum_w < 0.5 {
            return false;
        }
        centre /= sum_w;
        let chief = e * r;
        let et = DVec2::new(-e.y, e.x);
        for (k, rad) in radii.iter().enumerate() {
            let a = TAU * k as f64 / TABLE_ANGLES as f64;
            let local = centre + DVec2::new(a.cos(), a.sin()) * (rad / sum_w);
            out.push(self.film(chief + e * local.x + et * local.y));
        }
        true
    }
}

/// Rays of a real lens's camera by film point and a pupil parameter u ∈ [0, 1]² that stays
/// fixed while the film point moves (Newton needs rays smooth in the film point): for the
/// exact trace and the LRTF model (whose table stands for the same lens) a point on a square
/// over the exit-pupil bounds on the rear plane, traced exactly (the cameras' own pupil
/// sampling is piecewise over film radius and turns with the film azimuth); for the thick
/// lens its own lens sample (a fixed point of its aperture).
enum PupilRays<'a> {
    Camera { camera: &'a Camera, wavelength: f64 },
    Rear { camera: &'a crate::camera::ExactCamera, half: f64, wavelength: f64 },
}

impl<'a> PupilRays<'a> {
    fn new(camera: &'a Camera, wavelength: f64) -> PupilRays<'a> {
        let exact = match camera {
            Camera::Exact(c) => Some(c),
            Camera::Lrtf(c) => Some(c.exact()),
            _ => None,
        };
        match exact {
            Some(c) => {
                let half = c
                    .pupil()
                    .boxes
                    .iter()
                    .filter(|b| b.min.is_finite() && b.max.is_finite())
                    .map(|b| b.min.abs().max(b.max.abs()).max_element())
                    .fold(0.0f64, f64::max);
                PupilRays::Rear { camera: c, half, wavelength }
            }
            None => PupilRays::Camera { camera, wavelength },
        }
    }

    /// Camera-space ray (origin m, unit direction) from film point `film` for parameter `u`.
    fn ray(&self, film: DVec2, u: DVec2) -> Option<(DVec3, DVec3)> {
        match self {
            PupilRays::Camera { camera, wavelength } => {
                camera.generate_ray(film, u, *wavelength).map(|r| (r.origin, r.direction))
            }
            PupilRays::Rear { camera, half, wavelength } => {
                let p = camera.sensor().film_point(film, camera.film_z_mm());
                let q = DVec3::new((2.0 * u.x - 1.0) * half, (2.0 * u.y - 1.0) * half, camera.pupil().rear_z_mm);
                let ray = crate::optics::lens::Ray::new(p, q - p);
                let out = camera.lens().trace(&ray, *wavelength, crate::optics::lens::TraceDirection::FilmToScene)?;
                let z_ep = camera.lens().paraxial().entrance_pupil_z_mm;
                let o = out.ray.origin;
                Some((DVec3::new(o.x, o.y, o.z - z_ep) * 1e-3, out.ray.direction))
            }
        }
    }
}

/// Linear interpolation of `ys` over increasing `xs` at `x` (clamped).
fn interp(xs: &[f64], ys: &[f64], x: f64) -> f64 {
    let n = xs.len();
    if x <= xs[0] {
        return ys[0];
    }
    if x >= xs[n - 1] {
        return ys[n - 1];
    }
    let k = xs.partition_point(|&v| v <= x).clamp(1, n - 1);
    let t = (x - xs[k - 1]) / (xs[k] - xs[k - 1]);
    ys[k - 1] + (ys[k] - ys[k - 1]) * t
}

/// The film point whose ray (`ray_at(film)`: origin in metres, direction; camera space)
/// passes through camera-space point `x`: Newton's method in 2-D with a finite-difference
/// Jacobian from `start`, converged when the step is below `tol` (film units) and the miss
/// below `tol_f` (tangent units); None when the ray is blocked or it does not converge.
fn solve_film(
    ray_at: &dyn Fn(DVec2) -> Option<(DVec3, DVec3)>,
    x: DVec3,
    start: DVec2,
    tol: f64,
    tol_f: f64,
    rays: &mut u64,
) -> Option<DVec2> {
    let z = -x.z;
    let target = DVec2::new(x.x / z, x.y / z);
    let mut residual = |s: DVec2| -> Option<DVec2> {
        *rays += 1;
        let (o, d) = ray_at(s)?;
        if d.z >= -1e-12 {
            return None;
        }
        let t = (-z - o.z) / d.z;
        let p = o + d * t;
        Some(DVec2::new(p.x / z, p.y / z) - target)
    };
    let h = (tol * 10.0).min(1e-5);
    let mut s = start;
    for _ in 0..20 {
        let f = residual(s)?;
        let fx = (residual(s + DVec2::new(h, 0.0))? - f) / h;
        let fy = (residual(s + DVec2::new(0.0, h))? - f) / h;
        let det = fx.perp_dot(fy);
        if !(det.abs() > 1e-300) {
            return None;
        }
        // Solve [fx fy]·δ = −f (Cramer).
        let delta = DVec2::new(fy.perp_dot(f) / det, f.perp_dot(fx) / det);
        let step = delta.length();
        let delta = if step > 0.05 { delta * (0.05 / step) } else { delta };
        s += delta;
        if !s.is_finite() {
            return None;
        }
        if step < tol {
            return (residual(s)?.length() < tol_f).then_some(s);
        }
    }
    None
}

/// A convex outline as its centroid and radii at [`TABLE_ANGLES`] angles about it; None for
/// fewer than three points.
fn radial_outline(hull: &[DVec2]) -> Option<Outline> {
    if hull.is_empty() {
        return None;
    }
    let area = signed_area(hull);
    let centroid = if hull.len() >= 3 && area.abs() > 1e-18 {
        let n = hull.len();
        let mut c = DVec2::ZERO;
        for k in 0..n {
            let (a, b) = (hull[k], hull[(k + 1) % n]);
            c += (a + b) * a.perp_dot(b);
        }
        c / (6.0 * area)
    } else {
        hull.iter().copied().sum::<DVec2>() / hull.len() as f64
    };
    let mut radii = [0.0f64; TABLE_ANGLES];
    if hull.len() >= 3 && area.abs() > 1e-18 {
        for (k, r) in radii.iter_mut().enumerate() {
            let a = TAU * k as f64 / TABLE_ANGLES as f64;
            let d = DVec2::new(a.cos(), a.sin());
            // Farthest crossing of the ray centroid + t·d with the hull's edges.
            let n = hull.len();
            let mut best: f64 = 0.0;
            for e in 0..n {
                let (p, q) = (hull[e] - centroid, hull[(e + 1) % n] - centroid);
                let edge = q - p;
                let den = d.perp_dot(edge);
                if den.abs() < 1e-300 {
                    continue;
                }
                let t = p.perp_dot(edge) / den;
                let s = p.perp_dot(d) / den;
                if (-1e-9..=1.0 + 1e-9).contains(&s) && t > 0.0 {
                    best = best.max(t);
                }
            }
            *r = best;
        }
    }
    Some((centroid, radii))
}

/// Radiance-free geometry for tests: the PSF outline (film coordinates) of the point at depth
/// `depth_m` (+inf allowed) along camera-space direction `dir` through a pinhole or thin-lens
/// `camera`; None for other models or where there is none.
pub fn thin_psf(camera: &Camera, dir: DVec3, depth_m: f64) -> Option<Vec<DVec2>> {
    let optics = match camera {
        Camera::Pinhole(c) => Optics::Pinhole(Plane::new(*c.sensor(), c.focal_length_mm())),
        Camera::Thin(c) => Optics::Thin {
            plane: Plane::new(*c.sensor(), c.film_distance_mm()),
            lens_focal_mm: c.lens_focal_length_mm(),
            outline: aperture_outline(c.aperture(), c.aperture_radius_mm()),
        },
        _ => return None,
    };
    let d = DVec3::new(dir.x / -dir.z, dir.y / -dir.z, -1.0);
    if !(dir.z < 0.0) || !d.is_finite() {
        return None;
    }
    let mut out = Vec::new();
    optics.psf(d, depth_m, &mut out).then_some(out)
}
