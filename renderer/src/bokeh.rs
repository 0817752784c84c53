//! Bokeh light paths: light traced from emissive triangles through the lens onto the film, and
//! combined with camera paths by multiple importance sampling, so that small bright emitters
//! seen out of focus (the demo's lamps, the lights of a night street) converge as fast as the
//! rest of the image. Camera paths find such an emitter only when a ray through the wide
//! aperture happens to hit it; a light path starts on the emitter and always lands somewhere in
//! its bokeh disc.
//!
//! One light path, scene → film:
//! 1. an emitter triangle chosen by `EmitterChoice` (flux into the lens, defocus share, the
//!    share the lens sees),
//! 2. a point p on a disc about the axis through which every ray that reaches the film passes
//!    ([`Camera::light_path_disc`]: the thin and thick lenses' opening at their principal plane;
//!    for real lenses the widest crossing of the camera plane by camera rays, measured), or,
//!    through a real lens, on the cells of that disc through which the chosen emitter's light
//!    reaches the film (`emitter_cells`: a corner emitter's cat's eye), and a point y on the
//!    emitter as light sampling places it from p (selection × solid-angle pdf at p),
//! 3. the object-space ray y → p traced through the lens ([`Camera::connect`]) onto the
//!    sensor, the segment from y to where the ray enters the lens tested for occlusion,
//! 4. a splat into every pixel whose filter covers the film point, weighted by that pixel's
//!    filter density.
//!
//! Both strategies' densities are expressed in the ray (étendue) measure, which the lens
//! conserves: the camera's is pdf(film point) · pdf(rear-plane point) / (cosθ cosθ' / d²), the
//! light path's pdf(p on the disc) · pdf_ω(y from p) / cosθ_p. The balance heuristic weights
//! each strategy by its density times its sample count (K light paths per sample per pixel of
//! the whole image against one camera sample per pixel). Only emission that the camera ray hits
//! directly is shared between the strategies; a path the disc cannot produce (p outside it, or
//! off the emitter's cells) is left wholly to the camera, so the combination is unbiased
//! whatever the disc's radius.
//!
//! Under adaptive sampling a pass traces only the first ⌈share · K⌉ of each sample's K light
//! paths, where share is the part of the splats so far that lies in pixels still sampled, and
//! the splats are divided by the light paths traced (in samples' worth) rather than by the
//! samples: each light path estimates the whole window on its own, and the MIS weights keep
//! the nominal K, so the image stays consistent (as adaptive stopping itself, the count depends
//! on earlier splats: a ratio bias of order 1/n) while the light paths' cost follows the pixels
//! that still need them instead of the slowest pixel.
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `MAX_EMITTER_CELLS` | constant: emitters given cells of their own through a real lens, those light paths choose most (the rest aim at the disc) | — | 256 |
//! | `DISC_GRID` | constant: cells across the disc's diameter | — | 20 |
//! | `bokeh_paths` | f32: light paths per pixel per sample (0 = off); every model with a lens (thin, thick, exact, LRTF), not the pinhole | — | 0 |

use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::film::{FilterSampler, PixelFilter};
use crate::integrator::{RenderScene, SurfaceHit};
use crate::optics::aperture::concentric_disk;
use crate::sampler::PixelSampler;
use crate::spectral;
use glam::{DAffine3, DVec2, DVec3, Vec2, Vec3};
use rayon::prelude::*;

/// The `auto` choice of light paths per pixel per sample: 1 where `camera` can trace light onto
/// its film (any model with a lens: thin, thick, exact or LRTF) and `scene` has emissive
/// triangles, else 0.
pub fn auto_paths(scene: &RenderScene, camera: &Camera) -> f32 {
    if camera.can_connect() && scene.has_emissive_triangles() {
        1.0
    } else {
        0.0
    }
}

/// Light paths traced per parallel task (a fixed split, so the image does not depend on the
/// thread count).
const CHUNK: u64 = 2048;
/// Tasks whose splats are gathered before they are added to the film, in task order.
const BATCH: u64 = 64;
/// The sampler row of light paths (camera samples use rows below the image height).
const LIGHT_ROW: u32 = 0xB0CE_0000;

/// Where a camera sample came from: what its density against light paths is computed from, only
/// for the samples that hit an emitter light paths serve ([`BokehTracer::camera_weight`]).
#[derive(Debug, Clone, Copy)]
pub(crate) struct FilmSample {
    /// Film position (image fractions).
    pub film: DVec2,
    /// Lens sample in [0, 1)².
    pub lens_u: DVec2,
    /// Filter offset from the pixel centre (px).
    pub offset: glam::Vec2,
}

/// What the light tracer takes from the render's settings.
#[derive(Debug, Clone, Copy)]
pub(crate) struct LightPathSettings {
    /// Light paths per pixel per sample (0 = none).
    pub paths: f32,
    /// The full frame (pixels).
    pub width: u32,
    /// The full frame (pixels).
    pub height: u32,
    /// The window rendered `[x0, y0, x1, y1)`.
    pub crop: [u32; 4],
    /// The pixel filter.
    pub filter: PixelFilter,
    /// One wavelength per path.
    pub spectral: bool,
    /// Seed.
    pub seed: u32,
    /// Clipping planes along the view axis (m).
    pub clip_m: (f64, f64),
}

/// The light tracer of one render (immutable once built).
pub(crate) struct BokehTracer<'a> {
    scene: &'a RenderScene,
    camera: &'a Camera,
    to_world: DAffine3,
    to_camera: DAffine3,
    /// The camera's viewing direction and origin (world).
    forward: Vec3,
    /// The plane of the discs light paths aim at (camera z, m).
    disc_z_m: f64,
    /// The disc every ray that reaches the film passes through.
    disc: Disc,
    /// Through a real lens, the part of it each emitter's light passes ([`emitter_cells`], per
    /// `EmitterChoice::emitters` entry; None: the whole disc).
    cells: Vec<Option<Cells>>,
    /// Light paths per sample per pixel over the whole window (K).
    paths_per_spp: u64,
    /// Area of one pixel on the sensor (mm²).
    px_area_mm2: f64,
    width: u32,
    height: u32,
    crop: [u32; 4],
    filter: FilterSampler,
    spectral: bool,
    primary_nm: f64,
    seed: u32,
    clip_m: (f64, f64),
    defocus: Defocus,
    emitters: EmitterChoice,
}

/// The disc light paths aim at, about the axis in the plane z = `BokehTracer::disc_z_m`
/// (camera space).
#[derive(Debug, Clone, Copy)]
struct Disc {
    /// Radius (m).
    radius_m: f64,
    /// Centre (world).
    centre_world: Vec3,
    /// Area density of a uniform point on it (mm⁻²).
    pdf_mm2: f64,
}

impl Disc {
    /// The disc of radius `radius_m` about the axis in the plane z = `disc_z_m`.
    fn new(radius_m: f64, disc_z_m: f64, to_world: &DAffine3) -> Disc {
        let radius_mm = radius_m * 1e3;
        Disc {
            radius_m,
            centre_world: to_world.transform_point3(DVec3::new(0.0, 0.0, disc_z_m)).as_vec3(),
            pdf_mm2: 1.0 / (std::f64::consts::PI * radius_mm * radius_mm),
        }
    }
}

/// Most emitters a real lens measures a domain of its own for (those light paths choose most);
/// the rest aim at the shared disc.
const MAX_EMITTER_CELLS: usize = 256;
/// Grid cells across the shared disc's diameter, of which an emitter's domain is made.
const DISC_GRID: usize = 20;

/// Where the light paths of one emitter aim through a real lens: the cells of a grid over the
/// shared disc (plane z = `BokehTracer::disc_z_m`) through which its light reaches the film,
/// and their neighbours; uniform over them.
#[derive(Debug, Clone)]
struct Cells {
    /// Cell side (m); the grid's corner is (−R, −R) for the shared disc's radius R.
    step_m: f64,
    /// The shared disc's radius R (m).
    big_m: f64,
    /// The cells (row-major index iy · DISC_GRID + ix), in order.
    list: Vec<u32>,
    /// Whether each cell of the grid is one of them.
    mask: Vec<bool>,
    /// Area density of a uniform point on them (mm⁻²).
    pdf_mm2: f64,
}

impl Cells {
    /// The point (camera x, y; m) of sample `u` in [0, 1)²: a cell by u.x, the point in it by
    /// the rest of u.x and by u.y.
    fn sample(&self, u: DVec2) -> DVec2 {
        let n = self.list.len();
        let x = u.x * n as f64;
        let k = (x as usize).min(n - 1);
        let c = self.list[k] as usize;
        let (ix, iy) = (c % DISC_GRID, c / DISC_GRID);
        DVec2::new(
            (ix as f64 + (x - k as f64)) * self.step_m - self.big_m,
            (iy as f64 + u.y) * self.step_m - self.big_m,
        )
    }

    /// The density (mm⁻²) at point `q` (camera x, y; m): 0 off the cells.
    fn pdf_mm2(&self, q: DVec2) -> f64 {
        let g = (q + DVec2::splat(self.big_m)) / self.step_m;
        if !(g.x >= 0.0 && g.y >= 0.0 && g.x < DISC_GRID as f64 && g.y < DISC_GRID as f64) {
            return 0.0;
        }
        if self.mask[g.y as usize * DISC_GRID + g.x as usize] {
            self.pdf_mm2
        } else {
            0.0
        }
    }
}

/// The cells of the shared disc (radius `big_m`, plane z = `disc_z_m`) through which light
/// from an emitter (bounds centre `centre_world`, radius `radius_m`) reaches the film of a
/// real lens: those whose centre a ray from the emitter's centre or from one of six points at
/// its radius along the camera axes passes through the lens to, with their eight neighbours.
/// None when no cell passes or they do not cover clearly less (under 0.8 of the cells of the
/// disc). Off the axis a real lens vignettes: light from a corner emitter passes only a cat's
/// eye of the pupil, and aiming at the whole disc loses most of its light paths. Any domain
/// keeps the combination unbiased (a path through a point off it is left wholly to the
/// camera); the neighbours only keep it from being a worse split near the outline.
fn emitter_cells(
    camera: &Camera,
    to_camera: &DAffine3,
    centre_world: Vec3,
    radius_m: f32,
    big_m: f64,
    disc_z_m: f64,
    wavelength_nm: f64,
) -> Option<Cells> {
    // 1. The emitter's centre and six points at its radius.
    let c = to_camera.transform_point3(centre_world.as_dvec3());
    let r = radius_m as f64;
    let points =
        [c, c + DVec3::X * r, c - DVec3::X * r, c + DVec3::Y * r, c - DVec3::Y * r, c + DVec3::Z * r, c - DVec3::Z * r];
    // 2. The cells (of those inside the disc) whose centre a ray from one of them passes to.
    let step = 2.0 * big_m / DISC_GRID as f64;
    let g = DISC_GRID as i64;
    let mut passes = vec![false; DISC_GRID * DISC_GRID];
    let mut in_disc = 0usize;
    for iy in 0..g {
        for ix in 0..g {
            let q = DVec2::new((ix as f64 + 0.5) * step - big_m, (iy as f64 + 0.5) * step - big_m);
            if q.length() > big_m {
                continue;
            }
            in_disc += 1;
            let p = q.extend(disc_z_m);
            passes[(iy * g + ix) as usize] =
                points.iter().any(|&y| y.z < 0.0 && camera.connect(y, p, wavelength_nm).is_some());
        }
    }
    // 3. With their neighbours, where they are clearly fewer.
    let mask: Vec<bool> = (0..g * g)
        .map(|i| {
            let (ix, iy) = (i % g, i / g);
            (iy - 1..=iy + 1)
                .any(|y| (ix - 1..=ix + 1).any(|x| x >= 0 && y >= 0 && x < g && y < g && passes[(y * g + x) as usize]))
        })
        .collect();
    let list: Vec<u32> = (0..mask.len() as u32).filter(|&i| mask[i as usize]).collect();
    if list.is_empty() || list.len() as f64 >= 0.8 * in_disc as f64 {
        return None;
    }
    let step_mm = step * 1e3;
    let pdf_mm2 = 1.0 / (list.len() as f64 * step_mm * step_mm);
    Some(Cells { step_m: step, big_m, list, mask, pdf_mm2 })
}

/// How light paths choose their emitter: among the emissive triangles that can blur into the
/// window ([`Defocus::alpha`] > 0 at a vertex, and the chief rays of their vertices landing on
/// the window grown by half their blur), in proportion to the flux they send into the lens
/// (power over squared distance: a tiny near lamp blurs as visibly as a large far one) times
/// the share α light paths take of them (no budget for emitters left mostly to camera paths,
/// such as the night street's lit windows next to its lamps) and the share of them the lens
/// sees ([`visible_share`]: little for the far side of a lamp's sphere). The
/// light tree that next-event estimation uses picks by power and distance from the lens alone,
/// so in a scene whose brightest emitters are out of view most light paths would land off the
/// film. Each triangle also carries the radius of its emitter ([`component_radii`]): the
/// connected set of emissive triangles it belongs to (triangles joined by a shared vertex
/// position, so flat-shaded meshes with split vertices stay one emitter).
#[derive(Debug, Clone)]
struct EmitterChoice {
    /// (light index, cumulative probability), in light order.
    cdf: Vec<(usize, f32)>,
    /// Probability of each light index (0 for lights never chosen).
    pmf: Vec<f32>,
    /// Radius (m, world) of the emitter each light index belongs to (0 for other lights).
    radius_m: Vec<f32>,
    /// The emitter (connected set) each light index belongs to, as an index into `emitters`
    /// (`u32::MAX` for other lights).
    emitter_of: Vec<u32>,
    /// Each emitter that light paths may choose: (centre of its bounds, world; its radius, m).
    emitters: Vec<(Vec3, f32)>,
}

/// Radius (m) of each connected set of triangles, per triangle (sets: triangles sharing a
/// vertex position, bit for bit; the radius: of the sphere with the set's area), the set's id
/// (its first triangle's index) and the centre of its bounds.
fn component_radii(tris: &[[Vec3; 3]]) -> Vec<(f32, usize, Vec3)> {
    // 1. Union-find over triangles, joined through their vertex positions.
    let mut parent: Vec<usize> = (0..tris.len()).collect();
    fn root(parent: &mut [usize], mut i: usize) -> usize {
        while parent[i] != i {
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        i
    }
    let mut owner: std::collections::HashMap<[u32; 3], usize> = std::collections::HashMap::new();
    for (t, v) in tris.iter().enumerate() {
        for p in v {
            let key = [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()];
            let other = *owner.entry(key).or_insert(t);
            let (a, b) = (root(&mut parent, t), root(&mut parent, other));
            if a != b {
                parent[a.max(b)] = a.min(b);
            }
        }
    }
    // 2. Each set's bounds and area: the radius of the sphere of the same area (exact for a
    //    ball, smaller for flat emitters), at most the bounds' half diagonal.
    let roots: Vec<usize> = (0..tris.len()).map(|t| root(&mut parent, t)).collect();
    let mut sets: std::collections::HashMap<usize, (Vec3, Vec3, f32)> = std::collections::HashMap::new();
    for (t, v) in tris.iter().enumerate() {
        let b = sets.entry(roots[t]).or_insert((Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY), 0.0));
        for p in v {
            b.0 = b.0.min(*p);
            b.1 = b.1.max(*p);
        }
        b.2 += 0.5 * (v[1] - v[0]).cross(v[2] - v[0]).length();
    }
    roots
        .iter()
        .map(|&r| {
            let (lo, hi, area) = sets[&r];
            ((area / (4.0 * std::f32::consts::PI)).sqrt().min(0.5 * (hi - lo).length()), r, 0.5 * (lo + hi))
        })
        .collect()
}

impl EmitterChoice {
    /// The choice for this render; None when no emitter qualifies.
    #[allow(clippy::too_many_arguments)]
    fn new(
        scene: &RenderScene,
        camera: &Camera,
        to_camera: &DAffine3,
        disc_world: &[Vec3; DISC_PROBES],
        defocus: &Defocus,
        settings: &LightPathSettings,
        wavelength_nm: f64,
    ) -> Option<EmitterChoice> {
        let (w, h) = (settings.width as f64, settings.height as f64);
        let [x0, y0, x1, y1] = settings.crop.map(|c| c as f64);
        let candidates: Vec<(usize, [Vec3; 3], f32)> = scene.emissive_triangles().collect();
        let components = component_radii(&candidates.iter().map(|c| c.1).collect::<Vec<_>>());
        let mut radius_m = vec![0.0f32; scene.light_count()];
        for (c, &(r, _, _)) in candidates.iter().zip(&components) {
            radius_m[c.0] = r;
        }
        // (light index, weight before the visible share, whether it is probed)
        let in_view: Vec<(usize, f64, bool)> = candidates
            .par_iter()
            .zip(components.par_iter())
            .filter_map(|(&(i, v, power), &(radius, _, _))| {
                if !(power > 0.0) {
                    return None;
                }
                // 1. Blurred enough, for its size, at some vertex.
                let y = v.map(|p| to_camera.transform_point3(p.as_dvec3()));
                let alpha = y.map(|p| if p.z < 0.0 { defocus.alpha(p, radius as f64) } else { 0.0 });
                if alpha.iter().all(|&a| a == 0.0) {
                    return None;
                }
                // 2. In view: the vertices' chief rays, their bounding box grown by the blur,
                //    overlapping the window (kept when a chief ray does not reach the film).
                let blur = y.iter().map(|&p| defocus.blur_px(p)).fold(0.0, f64::max);
                let (mut lo, mut hi) = (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY));
                for &p in &y {
                    let Some(c) = camera.connect(p, DVec3::ZERO, wavelength_nm) else {
                        return Some((i, power as f64, false));
                    };
                    let px = DVec2::new(c.film.x * w, c.film.y * h);
                    lo = lo.min(px);
                    hi = hi.max(px);
                }
                let m = 0.5 * blur + 2.0;
                let outside = hi.x + m < x0 || lo.x - m > x1 || hi.y + m < y0 || lo.y - m > y1;
                if outside {
                    return None;
                }
                // 3. Weighted by the flux it sends into the lens (power over squared distance)
                //    times the share light paths take of it (α, at the vertices on average) and
                //    (below) the share of it the lens sees.
                let d2 = ((y[0] + y[1] + y[2]) / 3.0).length_squared().max(1e-12);
                let share = (alpha[0] + alpha[1] + alpha[2]) / 3.0;
                Some((i, power as f64 / d2 * share, true))
            })
            .collect();
        // 4. The share the lens sees ([`visible_share`], at least one probe's), with the probes
        //    of the triangles in view within the budget.
        let probes = probes_per_triangle(in_view.iter().filter(|t| t.2).count());
        let kept: Vec<(usize, f32)> = in_view
            .par_iter()
            .map(|&(i, w, probed)| {
                if probed {
                    (i, (w * visible_share(scene, i, disc_world, probes).max(MIN_SEEN_SHARE)) as f32)
                } else {
                    (i, w as f32)
                }
            })
            .collect();
        let total: f64 = kept.iter().map(|&(_, p)| p as f64).sum();
        if kept.is_empty() || !(total > 0.0) || !total.is_finite() {
            return None;
        }
        let mut pmf = vec![0.0f32; scene.light_count()];
        let mut cdf = Vec::with_capacity(kept.len());
        let mut acc = 0.0f64;
        for &(i, p) in &kept {
            pmf[i] = (p as f64 / total) as f32;
            acc += p as f64 / total;
            cdf.push((i, acc as f32));
        }
        // The emitters of the kept triangles, in the order of their first kept triangle.
        let mut emitter_of = vec![u32::MAX; scene.light_count()];
        let mut emitters = Vec::new();
        let mut index_of = std::collections::HashMap::new();
        for (c, &(r, id, centre)) in candidates.iter().zip(&components) {
            if pmf[c.0] > 0.0 {
                let k = *index_of.entry(id).or_insert_with(|| {
                    emitters.push((centre, r));
                    emitters.len() as u32 - 1
                });
                emitter_of[c.0] = k;
            }
        }
        Some(EmitterChoice { cdf, pmf, radius_m, emitter_of, emitters })
    }

    /// The emitter for sample `u` in [0, 1): (light index, probability).
    fn pick(&self, u: f32) -> Option<(usize, f32)> {
        let k = self.cdf.partition_point(|&(_, c)| c <= u).min(self.cdf.len() - 1);
        let i = self.cdf[k].0;
        let p = self.pmf[i];
        (p > 0.0).then_some((i, p))
    }
}

/// The share of light paths an emitter triangle keeps when no probe of [`visible_share`] sees it
/// (one probe's worth). The probes can miss a triangle the lens sees in part, and camera paths
/// alone render those noisily. On tests/blender's street, 1/16 gives less noise at 128 spp
/// (0.0120) than none (0.0129), 1/64 (0.0124) or 1/4 (0.0129), and than keeping it only for
/// triangles next to seen ones (0.0126).
const MIN_SEEN_SHARE: f64 = 1.0 / 16.0;

/// Points of the light-path disc from which [`visible_share`] looks at an emitter: its centre
/// and three points at 0.7 of its radius, 120° apart.
const DISC_PROBES: usize = 4;
/// Points of an emitter triangle [`visible_share`] tests (barycentric samples for
/// [`RenderScene::sample_chosen_light`]: near the centroid and towards each vertex).
const TRIANGLE_PROBES: [(f32, f32); 4] = [(0.44, 0.5), (0.9, 0.1), (0.9, 0.9), (0.05, 0.5)];

/// The share of the segments between emissive triangle `light` and the light-path disc
/// (`disc_world`, its probe points) that are unoccluded, each made as a light path makes it
/// (the emitter point as light sampling places it, facing the disc point; a one-sided emitter
/// seen from behind counts as hidden), over the first `probes` of the 16 (triangle point,
/// disc point) pairs in [`probe_pair`]'s order. The emitter choice weighs each triangle by it
/// (at least [`MIN_SEEN_SHARE`]): the far side of a lamp's sphere or a lamp behind a wall takes
/// few light paths. Both strategies use the same choice, so the image stays unbiased whatever
/// the share.
fn visible_share(scene: &RenderScene, light: usize, disc_world: &[Vec3; DISC_PROBES], probes: usize) -> f64 {
    let mut seen = 0;
    for j in 0..probes {
        let (t, d) = probe_pair(j);
        let (u0, u1) = TRIANGLE_PROBES[t];
        let p = disc_world[d];
        let Some(y) = scene.sample_chosen_light(p, light, 1.0, Vec2::new(u0, u1)).and_then(|ls| ls.target) else {
            continue;
        };
        if !scene.occluded(y, p - y, 1.0 - 1e-4) {
            seen += 1;
        }
    }
    seen as f64 / probes as f64
}

/// Pair `j` of [`visible_share`]'s probes: (triangle point, disc point). Each run of four
/// takes every triangle point and every disc point once; all 16 are every pair once.
fn probe_pair(j: usize) -> (usize, usize) {
    (j % 4, (j % 4 + j / 4) % 4)
}

/// Most probe segments [`visible_share`] tests over the emitter triangles in view. Past it a
/// triangle gets fewer than all 16, at least one, so the set-up stays bounded: with 16 each, a
/// million emissive triangles in view took about 2 s on 2 threads.
const PROBE_BUDGET: usize = 1 << 18;

/// The probes each of `candidates` emissive triangles gets: all 16 within [`PROBE_BUDGET`]
/// (the street's 11 600), else the budget's share, at least one.
fn probes_per_triangle(candidates: usize) -> usize {
    (PROBE_BUDGET / candidates.max(1)).clamp(1, TRIANGLE_PROBES.len() * DISC_PROBES)
}

/// Ratios ρ = (blur + 1 px) / (the emitter's sharp image size) below which light paths take no
/// share of an emitter point, and above which they take their full balance-heuristic share.
const DEFOCUS_RATIO: (f64, f64) = (0.45, 0.9);

/// How blurred a scene point is against the size of its emitter (thin-lens estimates), for the
/// light strategy's share.
///
/// Density-based MIS weights do not see that camera samples are stratified over pixels: where
/// an emitter's blurred image is mostly its sharp image (an emitter large against its blur),
/// nearly every camera sample of a pixel inside it hits it, so camera paths alone have next to
/// no noise there, while light paths land a random number of times per pixel. Light paths pay
/// where an emitter is small against its blur disc (and the pixel), where camera rays find it
/// rarely. With ρ = (b + 1 px)/s, for blur diameter b and sharp image diameter s, the light
/// strategy's density is scaled by a factor α(ρ): 0 below [`DEFOCUS_RATIO`].0 (an emitter
/// larger than its blur), 1 above [`DEFOCUS_RATIO`].1, smooth between. (Measured on the night
/// street's 8 cm lamps: light paths already win at ρ ≈ 1.7, and tests/blender's large emitters,
/// ρ = 0.1 and 0.45, are better left to camera paths.) Any α keeps the combination unbiased (the weights still sum to 1
/// for every path, and both strategies compute the same α from the same point and emitter);
/// where α = 0 no light path is traced.
#[derive(Debug, Clone, Copy)]
struct Defocus {
    /// Aperture (entrance pupil) diameter (mm).
    aperture_mm: f64,
    /// Image distance over pixel pitch (px per unit slope).
    image_px: f64,
    /// The plane of sharp focus (camera space), None when unknown (then α = 1).
    plane: Option<crate::camera::FocusPlane>,
}

impl Defocus {
    /// Blur diameter (px) of camera-space point `y_m`: A·v·|1/z − 1/z_f| / pitch, with z the
    /// point's depth and z_f the focus plane's along the same line of sight.
    fn blur_px(&self, y_m: DVec3) -> f64 {
        let Some(plane) = self.plane else { return f64::INFINITY };
        let z = -y_m.z;
        if !(z > 0.0) {
            return f64::INFINITY; // behind the lens: never seen
        }
        let inv_zf = plane.intersect(DVec3::ZERO, y_m).map_or(0.0, |t| 1.0 / (t * z));
        self.aperture_mm * 1e-3 * self.image_px * (1.0 / z - inv_zf).abs()
    }

    /// The light strategy's share factor α for camera-space point `y_m` on an emitter of
    /// radius `radius_m`.
    fn alpha(&self, y_m: DVec3, radius_m: f64) -> f64 {
        let z = -y_m.z;
        let size_px = if z > 0.0 { 2.0 * radius_m / z * self.image_px } else { 0.0 };
        let rho = (self.blur_px(y_m) + 1.0) / size_px.max(1e-9);
        let t = ((rho - DEFOCUS_RATIO.0) / (DEFOCUS_RATIO.1 - DEFOCUS_RATIO.0)).clamp(0.0, 1.0);
        t * t * (3.0 - 2.0 * t)
    }
}

impl<'a> BokehTracer<'a> {
    /// The tracer for `settings.bokeh_paths` > 0 and a scene with emissive triangles; None when
    /// there is nothing to trace. An error when light paths are asked for a camera model that
    /// cannot trace light onto its film.
    pub(crate) fn new(
        scene: &'a RenderScene,
        camera: &'a Camera,
        to_world: DAffine3,
        settings: &LightPathSettings,
    ) -> Result<Option<Self>> {
        if settings.paths <= 0.0 {
            return Ok(None);
        }
        let Some(ep_radius_m) = camera.entrance_pupil_radius_m().filter(|_| camera.can_connect()) else {
            return Err(Error::settings(
                "bokeh_paths",
                format!(
                    "light paths need a lens to trace through (the thin, thick, exact or LRTF model); this camera is {}",
                    camera.model()
                ),
            ));
        };
        // (a real lens's disc is measured by tracing: only where there is light to trace)
        let Some((disc_z_m, radius_m)) = camera.light_path_disc().filter(|_| scene.has_emissive_triangles()) else {
            return Ok(None);
        };
        let (w, h) = (settings.width, settings.height);
        let crop = settings.crop;
        let window_px = (crop[2] - crop[0]) as f64 * (crop[3] - crop[1]) as f64;
        let sensor = camera.sensor();
        let to_camera = to_world.inverse();
        let defocus = Defocus {
            aperture_mm: 2e3 * ep_radius_m,
            image_px: crate::camera::thin_lens_data(camera).map_or(0.0, |d| d.1) / (sensor.width_mm / w as f64),
            plane: camera.focus_plane(),
        };
        let primary_nm =
            camera.real_lens().map_or(crate::optics::glass::WAVELENGTH_D_NM, |l| l.primary_wavelength_nm());
        let disc_world: [Vec3; DISC_PROBES] = std::array::from_fn(|k| {
            let (r, a) = if k == 0 { (0.0, 0.0) } else { (0.7 * radius_m, (k as f64) * std::f64::consts::TAU / 3.0) };
            to_world.transform_point3(DVec3::new(r * a.cos(), r * a.sin(), disc_z_m)).as_vec3()
        });
        let Some(emitters) = EmitterChoice::new(scene, camera, &to_camera, &disc_world, &defocus, settings, primary_nm)
        else {
            // No emitter blurred enough to share, or none in view: camera paths alone (the
            // camera's weight is then 1 everywhere, as without light paths).
            return Ok(None);
        };
        // The shared disc, and through a real lens each emitter's part of it (for the
        // MAX_EMITTER_CELLS emitters chosen most; the thin and thick lenses' opening is the
        // same from every point).
        let disc = Disc::new(radius_m, disc_z_m, &to_world);
        let cells: Vec<Option<Cells>> = if camera.real_lens().is_some() {
            // the emitters light paths choose most (their triangles' probabilities summed)
            let mut chosen = vec![0f64; emitters.emitters.len()];
            for (light, &e) in emitters.emitter_of.iter().enumerate() {
                if let Some(c) = chosen.get_mut(e as usize) {
                    *c += emitters.pmf[light] as f64;
                }
            }
            let mut order: Vec<usize> = (0..chosen.len()).collect();
            order.sort_by(|&a, &b| chosen[b].total_cmp(&chosen[a]).then(a.cmp(&b)));
            order.truncate(MAX_EMITTER_CELLS);
            let measured: Vec<(usize, Option<Cells>)> = order
                .par_iter()
                .map(|&k| {
                    let (c, r) = emitters.emitters[k];
                    (k, emitter_cells(camera, &to_camera, c, r, radius_m, disc_z_m, primary_nm))
                })
                .collect();
            let mut cells = vec![None; chosen.len()];
            for (k, c) in measured {
                cells[k] = c;
            }
            cells
        } else {
            Vec::new()
        };
        Ok(Some(BokehTracer {
            scene,
            camera,
            to_world,
            to_camera,
            forward: to_world.transform_vector3(DVec3::NEG_Z).normalize().as_vec3(),
            disc_z_m,
            disc,
            cells,
            paths_per_spp: (settings.paths as f64 * window_px).ceil().max(1.0) as u64,
            px_area_mm2: sensor.width_mm / w as f64 * (sensor.height_mm / h as f64),
            width: w,
            height: h,
            crop,
            filter: FilterSampler::new(settings.filter),
            spectral: settings.spectral,
            primary_nm,
            seed: settings.seed ^ 0x5bd1_e995,
            clip_m: settings.clip_m,
            defocus,
            emitters,
        }))
    }

    /// The camera strategy's density (mm⁻², ray measure) for the camera sample at image
    /// position `film` with lens sample `lens_u`, whose filter offset was `off` (px).
    fn camera_density(&self, film: DVec2, lens_u: DVec2, off: Vec2) -> f64 {
        let f = self.filter.pdf(off) as f64 / self.px_area_mm2;
        self.camera.sample_density(film, lens_u).map_or(0.0, |d| f * d)
    }

    /// The camera path's weight for the emission it hits directly at `hit`, along the world ray
    /// `origin` + t·`dir` (unit), for the camera sample `film`. Its density is found only where
    /// light paths could have made the path (elsewhere the weight is 1).
    pub(crate) fn camera_weight(&self, film: &FilmSample, origin: Vec3, dir: Vec3, hit: &SurfaceHit) -> f32 {
        let light = self.light_density(origin, dir, hit);
        if light == 0.0 {
            return 1.0;
        }
        let camera_density = self.camera_density(film.film, film.lens_u, film.offset);
        if camera_density + light > 0.0 {
            (camera_density / (camera_density + light)) as f32
        } else {
            1.0
        }
    }

    /// K times the light strategy's density (mm⁻² sr⁻¹, ray measure) for the ray `origin` +
    /// t·`dir` ending on the emitter at `hit` (0 when its line misses the disc), scaled by the
    /// point's defocus share α ([`Defocus`]).
    fn light_density(&self, origin: Vec3, dir: Vec3, hit: &SurfaceHit) -> f64 {
        let Some(light) = self.scene.triangle_light(hit.instance, hit.triangle) else { return 0.0 };
        let pmf = self.emitters.pmf.get(light).copied().unwrap_or(0.0);
        if pmf == 0.0 {
            return 0.0;
        }
        let radius_m = self.emitters.radius_m[light] as f64;
        let alpha = self.defocus.alpha(self.to_camera.transform_point3(hit.position.as_dvec3()), radius_m);
        if alpha == 0.0 {
            return 0.0;
        }
        // 1. Where the ray's line crosses the disc's plane (it may be behind the ray's origin,
        //    inside the lens), and the density of p there: on the disc, or on the emitter's
        //    cells.
        let centre = self.disc.centre_world;
        let cos_p = dir.dot(self.forward);
        if cos_p.abs() < 1e-6 {
            return 0.0;
        }
        let p = origin + dir * ((centre - origin).dot(self.forward) / cos_p);
        let pdf_mm2 = match self.cells_of(light) {
            None if (p - centre).length() as f64 > self.disc.radius_m => return 0.0,
            None => self.disc.pdf_mm2,
            Some(cells) => cells.pdf_mm2(self.to_camera.transform_point3(p.as_dvec3()).truncate()),
        };
        if pdf_mm2 == 0.0 {
            return 0.0;
        }
        // 2. The light paths' choice of this emitter point from p.
        let dist = (hit.position - p).length();
        let pdf_w = self.scene.triangle_light_pdf_with_pmf(pmf, hit, dir, dist) as f64;
        alpha * self.paths_per_spp as f64 * pdf_mm2 * pdf_w / cos_p.abs() as f64
    }

    /// The cells the light paths of emitter triangle `light` aim at (None: the whole disc).
    fn cells_of(&self, light: usize) -> Option<&Cells> {
        let e = *self.emitters.emitter_of.get(light)?;
        self.cells.get(e as usize)?.as_ref()
    }

    /// Traces the light paths of samples `spp` and adds their splats to `splat` (the window's
    /// pixels, row-major). `share` in (0, 1] is the part of each sample's light paths traced
    /// (its first ⌈share · K⌉ of K, at least one; 1: all): adaptive sampling traces fewer once
    /// the pixels they land in have stopped. Returns m, the light paths traced per sample; each
    /// sample adds m / K to the splats' sample count (their scale in the image is one over the
    /// sum): every light path is an estimate of the whole window on its own, so any fixed
    /// number of them is unbiased, and the MIS weights, made with the nominal K, still sum to
    /// one on every path.
    /// Also returns how many of the pass's light paths reached the window (added at least one
    /// splat).
    pub(crate) fn trace_pass(&self, spp: std::ops::Range<u32>, splat: &mut [Vec3], share: f64) -> (u64, u64) {
        let k = if share >= 1.0 {
            self.paths_per_spp
        } else {
            ((share.max(0.0) * self.paths_per_spp as f64).ceil() as u64).clamp(1, self.paths_per_spp)
        };
        let mut landed = 0;
        for s in spp {
            let mut start = 0;
            while start < k {
                let end = (start + CHUNK * BATCH).min(k);
                let chunks: Vec<u64> = (start..end).step_by(CHUNK as usize).collect();
                let parts: Vec<(Vec<(u32, Vec3)>, u64)> = chunks
                    .par_iter()
                    .map(|&c0| {
                        let (mut out, mut reached) = (Vec::new(), 0);
                        for i in c0..(c0 + CHUNK).min(end) {
                            let before = out.len();
                            self.trace_one(i, s, &mut out);
                            reached += (out.len() > before) as u64;
                        }
                        (out, reached)
                    })
                    .collect();
                for (out, reached) in parts {
                    landed += reached;
                    for (px, v) in out {
                        splat[px as usize] += v;
                    }
                }
                start = end;
            }
        }
        (k, landed)
    }

    /// K: the light paths of one sample over the whole window.
    pub(crate) fn paths_per_sample(&self) -> u64 {
        self.paths_per_spp
    }

    /// Light path `i` of sample `s`: its splats (window pixel index, radiance) into `out`.
    fn trace_one(&self, i: u64, s: u32, out: &mut Vec<(u32, Vec3)>) {
        // 1. Samples: disc point, emitter (pick, point), wavelength.
        let mut sampler = PixelSampler::new(i as u32, LIGHT_ROW ^ (i >> 32) as u32, s, self.seed);
        let u_disc = sampler.next_2d();
        let u_pick = sampler.next_1d();
        let u_light = sampler.next_2d();
        let u_lambda = sampler.next_1d();
        // 2. The emitter, a point p on its disc, and a point of it seen from p (punctual lights
        //    and the sky are not seen directly).
        let Some((light, pmf)) = self.emitters.pick(u_pick) else { return };
        let cells = self.cells_of(light);
        let q = match cells {
            None => concentric_disk(u_disc.as_dvec2()) * self.disc.radius_m,
            Some(c) => c.sample(u_disc.as_dvec2()),
        };
        let p_cam = DVec3::new(q.x, q.y, self.disc_z_m);
        let p_world = self.to_world.transform_point3(p_cam).as_vec3();
        let Some(ls) = self.scene.sample_chosen_light(p_world, light, pmf, u_light) else { return };
        let Some(y) = ls.target.filter(|_| !ls.delta) else { return };
        let (lambda, lambda_weight) =
            if self.spectral { spectral::sample_wavelength(u_lambda) } else { (self.primary_nm as f32, Vec3::ONE) };
        // 3. Only where the point is blurred enough to share it; through the lens onto the
        //    film; inside the clipping planes; unoccluded.
        let y_cam = self.to_camera.transform_point3(y.as_dvec3());
        let alpha = self.defocus.alpha(y_cam, self.emitters.radius_m[light] as f64);
        if alpha == 0.0 {
            return;
        }
        let Some(conn) = self.camera.connect(y_cam, p_cam, lambda as f64) else { return };
        let axial = conn.entry_m.z - y_cam.z;
        if !(axial >= self.clip_m.0 && axial <= self.clip_m.1) {
            return;
        }
        // 4. The window's pixels under the filter there (none: done, before the occlusion test).
        let (fx, fy) = (conn.film.x * self.width as f64, conn.film.y * self.height as f64);
        let r = self.filter.radius_px() as f64;
        let [x0, y0, x1, y1] = self.crop;
        let ix0 = ((fx - r - 0.5).ceil().max(x0 as f64)) as i64;
        let ix1 = ((fx + r - 0.5).floor().min(x1 as f64 - 1.0)) as i64;
        let iy0 = ((fy - r - 0.5).ceil().max(y0 as f64)) as i64;
        let iy1 = ((fy + r - 0.5).floor().min(y1 as f64 - 1.0)) as i64;
        let cw = (x1 - x0) as i64;
        let index = |ix: i64, iy: i64| ((iy - y0 as i64) * cw + (ix - x0 as i64)) as usize;
        if ix0 > ix1 || iy0 > iy1 {
            return;
        }
        let entry = self.to_world.transform_point3(conn.entry_m).as_vec3();
        if self.scene.occluded(y, entry - y, 1.0 - 1e-4) {
            return;
        }
        // 5. Density and value before the filter.
        let cos_p = (p_cam - y_cam).normalize().z.abs();
        if !(cos_p > 1e-9) {
            return;
        }
        let pdf_mm2 = cells.map_or(self.disc.pdf_mm2, |c| c.pdf_mm2);
        let light_density = alpha * self.paths_per_spp as f64 * pdf_mm2 * ls.pdf as f64 / cos_p;
        let base = ls.radiance * lambda_weight * conn.importance as f32;
        // 6. Splat into those pixels.
        // The filter is separable: its density along each axis, once per column and row (per
        // pixel for filters wider than MAX_SPAN px).
        const MAX_SPAN: usize = 8;
        let narrow = ix1 - ix0 < MAX_SPAN as i64 && iy1 - iy0 < MAX_SPAN as i64;
        let (mut f_cols, mut f_rows) = ([0f32; MAX_SPAN], [0f32; MAX_SPAN]);
        if narrow {
            for (k, ix) in (ix0..=ix1).enumerate() {
                f_cols[k] = self.filter.pdf_1d((fx - (ix as f64 + 0.5)) as f32);
            }
            for (k, iy) in (iy0..=iy1).enumerate() {
                f_rows[k] = self.filter.pdf_1d((fy - (iy as f64 + 0.5)) as f32);
            }
        }
        for iy in iy0..=iy1 {
            for ix in ix0..=ix1 {
                let f = if narrow {
                    f_cols[(ix - ix0) as usize] * f_rows[(iy - iy0) as usize]
                } else {
                    self.filter.pdf(Vec2::new((fx - (ix as f64 + 0.5)) as f32, (fy - (iy as f64 + 0.5)) as f32))
                } as f64
                    / self.px_area_mm2;
                if !(f > 0.0) {
                    continue;
                }
                let v = base * (alpha * f / (light_density + f * conn.camera_density)) as f32;
                if v.is_finite() {
                    out.push((index(ix, iy) as u32, v));
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// All 16 probes are every (triangle point, disc point) pair once, and each run of four
    /// takes every triangle point and every disc point once (so a budget of 4, 8 or 12 spreads
    /// over both).
    #[test]
    fn probe_pairs_cover_triangle_and_disc_points() {
        let all: std::collections::HashSet<_> = (0..16).map(probe_pair).collect();
        assert_eq!(all.len(), 16);
        for run in 0..4 {
            let pairs: Vec<_> = (4 * run..4 * run + 4).map(probe_pair).collect();
            for k in 0..4 {
                assert!(pairs.iter().any(|p| p.0 == k) && pairs.iter().any(|p| p.1 == k), "run {run}: {pairs:?}");
            }
        }
    }

    /// Within the budget every triangle gets all 16 probes; a million get one each.
    #[test]
    fn probes_stay_within_the_budget() {
        assert_eq!(probes_per_triangle(0), 16);
        assert_eq!(probes_per_triangle(11_600), 16);
        assert_eq!(probes_per_triangle(100_000), 2);
        assert_eq!(probes_per_triangle(1_000_000), 1);
        for n in [1, 16_384, 16_385, 50_000, 262_144, 5_000_000] {
            let k = probes_per_triangle(n);
            assert!((1..=16).contains(&k) && (k == 1 || n * k <= PROBE_BUDGET), "{n} triangles: {k} probes");
        }
    }
}
