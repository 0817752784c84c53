//! Exit-pupil bounds for sampling (after pbrt-v4's `RealisticCamera::BoundExitPupil`) and
//! chief-ray aiming.
//!
//! For a film point at radius r, the rays from it that pass the lens cross the plane of the
//! rear vertex inside a small region. We bound that region per radial interval of the film
//! (for a film point on +x; other points rotate the bounds), found by tracing a grid of rays and
//! enlarging the box by two grid cells. Lenses or stops that are not rotationally symmetric
//! use one box valid for every film point (the union), tightened per film cell (below).
//!
//! Rotationally symmetric lenses also get the region's **outline** per interval (issue 14: the
//! boxes let 36–61 % of the sampled rays be absorbed): a star-shaped polygon about a point inside
//! the region, whose radius at each of [`OUTLINE_ANGLES`] angles is the farthest passing point
//! along that direction over the interval's film points (a coarse march, then bisection to the
//! failing side; for dispersive lenses also stepped on past that radius at the ends of the
//! spectral range, [`SPECTRAL_RANGE_NM`], since spectral renders sample the same domain at every
//! wavelength), grown by [`OUTLINE_GROWTH`] of the region's size. Rays are sampled uniformly in
//! the polygon (a triangle picked by area, then a point in it). Where the region is not
//! star-shaped about its centre for some film point of the interval, that interval keeps its box.
//!
//! Lenses without rotational symmetry (anamorphic, decentred), and stops that are not round
//! (blades, an aperture image, an anamorphic squeeze), get outlines per **film cell**
//! instead ([`CellOutlines`]): the film square is cut into [`FILM_CELLS`]² cells, the passing
//! region's centroid is found at every cell corner, and each film point's region is taken about
//! its own centre, the corners' centroids interpolated bilinearly. The region mostly slides with
//! the film point, so one outline about that moving centre (the farthest passing point per angle
//! over a 3 × 3 lattice of the cell's film points) fits every point of the cell far tighter than
//! the union box. Where the region changes shape between those film points (element rims and the
//! stop binding in turn near the rim of the image circle), it can reach past the outline there:
//! the outline is checked at the 5 × 5 lattice's other 16 film points and, where one's region
//! reaches [`CELL_OUTLINE_CHECK`] of it, traced again over all 25. On a tilted sensor whose plane
//! is known ([`ExitPupilBounds::compute_on_plane`]) each film point is traced at its own z. A
//! cell without an outline (at the rim of the image circle, where a corner or a film point's
//! centre is absorbed) gets the smallest of three domains: the box of the rays that pass from
//! its film points (3 × 3, then the 5 × 5 lattice's other 16), grown by two grid cells; the same
//! rays' box about each film point's chief-ray aim, the corners' aims interpolated (a small
//! region slides across the rear plane further than its own size within one cell); and the
//! outline, about that aim, of the region that passes the stop with the elements' rims ignored,
//! which holds the passing region (the rims only cut it). Radii where nothing passes at any
//! traced azimuth stay empty, except within a cell's reach ([`CellOutlines::reach_mm`]). Past
//! the last interval with passing rays, where the image circle ends, the regions can be smaller
//! than the grid's cells (at the spectral range's ends above all), so those intervals are traced
//! again on a grid four times finer until one has none.
//!
//! **Lenses stopped down far.** The rear grid's cells (1/16 of three rear semi-diameters: 0.56 mm
//! on wide-22mm) are larger than the passing region of a small stop (wide-22mm: about 0.6 mm
//! across at f/22, 0.13 mm at f/96), which the grid then finds only in part or not at all
//! (before this search: at f/32 wide-22mm, angenieux-double-gauss-100mm and
//! aspheric-fisheye-10mm lost every passing ray outside the defensive disc, and past f/96 the
//! camera could not be built). Where the grid finds fewer than [`NEAR_CHIEF_BELOW`] rays from the
//! film's centre, every film point is also searched on a fine grid (1/16 of the cell where the
//! grid found none, 1/4 where it found a few) about its chief ray's aim point on the rear plane
//! ([`chief_aim_from_film`]: at a small stop the region lies about it), grown while the region
//! reaches its edge; margins are then two fine cells (the grid's own points keep two grid
//! cells, except in the rim cells' sliding boxes, where grid points inside a fine search that
//! resolved the region add nothing). The radial outlines are taken about a centre that slides
//! with the film radius ([`Outline::drift_per_mm`], the chief rays' aim points at the interval's
//! ends), since the region moves further than its own size across an interval. On a tilted
//! sensor whose plane is known, such a lens takes the film cells traced on the plane instead
//! (its region also moves with each film point's z). The chief ray is aimed in the film
//! point's radial plane, and by Newton's method in both coordinates where the lens is not
//! rotationally symmetric.
//!
//! All of the above is found by tracing samples, so it can miss a sliver of the passing region
//! (the brute-force stress sweep found about one passing ray in 40 million outside it on bladed
//! stops and tilted sensors, and none in 83 million since the rim cells' rework of session 37).
//! Sampling therefore mixes in a **defensive disc**
//! ([`DEFENSIVE_FRACTION`] of the samples, after Hesterberg's defensive importance sampling): a
//! disc on the rear plane that provably holds every passing ray's crossing, derived from the
//! last surface's clear aperture, its sag and placement, and the film's extent (no tracing).
//! Every ray that can pass then has a positive density ([`ExitPupilBounds::pdf_area`]), so
//! renders stay unbiased wherever the traced bounds fall short; inside them the weights change
//! by the factor 1 − [`DEFENSIVE_FRACTION`] only.
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `intervals` | usize, radial intervals over the film | — | 64 |
//! | `film_samples` | usize, film points per interval | — | 16 |
//! | `grid` | usize, rear-plane grid per side | — | 48 |
//! | [`NEAR_CHIEF_BELOW`] | usize, rays from the film's centre below which the fine search runs | — | 16 |
//! | [`FILM_CELLS`] | usize, film cells per side (no rotational symmetry) | — | 16 |
//! | [`CELL_OUTLINE_CHECK`] | f64, share of a cell's outline that, reached between its film points, has it traced again | — | 0.99 |
//! | [`SPECTRAL_RANGE_NM`] | wavelengths the outlines of dispersive lenses also hold | nm | 380, 780 |
//! | [`DEFENSIVE_FRACTION`] | f64, share of samples drawn in the defensive disc | — | 1/128 |

use super::lens::{Lens, Ray, StopMode, TraceDirection};
use glam::{DVec2, DVec3, IVec2};
use rayon::prelude::*;

/// An axis-aligned box on the rear plane.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Box2 {
    /// Lower corner.
    pub min: DVec2,
    /// Upper corner.
    pub max: DVec2,
}

impl Box2 {
    const EMPTY: Box2 = Box2 { min: DVec2::splat(f64::INFINITY), max: DVec2::splat(f64::NEG_INFINITY) };

    /// Whether nothing is inside.
    pub fn is_empty(&self) -> bool {
        self.min.x > self.max.x || self.min.y > self.max.y
    }
    fn grow(&mut self, p: DVec2) {
        self.min = self.min.min(p);
        self.max = self.max.max(p);
    }
    fn union(a: Box2, b: Box2) -> Box2 {
        Box2 { min: a.min.min(b.min), max: a.max.max(b.max) }
    }
    /// Area.
    pub fn area(&self) -> f64 {
        if self.is_empty() {
            0.0
        } else {
            (self.max.x - self.min.x) * (self.max.y - self.min.y)
        }
    }
    /// Whether `p` is inside.
    pub fn contains(&self, p: DVec2) -> bool {
        p.x >= self.min.x && p.x <= self.max.x && p.y >= self.min.y && p.y <= self.max.y
    }
}

/// Directions of an outline (the polygon's vertices).
pub const OUTLINE_ANGLES: usize = 64;

/// How much an outline is grown, as a share of its largest radius (covers the chords between
/// vertices, film points between the sampled ones, and the region's shift with wavelength).
pub const OUTLINE_GROWTH: f64 = 0.03;

/// [`OUTLINE_GROWTH`] for the outlines of film cells, whose corners between directions are
/// raised first (the rest covers film points between the sampled ones and the interpolated
/// centres' error).
pub const CELL_OUTLINE_GROWTH: f64 = 0.025;

/// A film cell's outline is traced again over a 5 × 5 lattice of film points when, at a film
/// point between its 3 × 3 ones, the region reaches this share of the outline's vertices or
/// chord midpoints (the region slides and changes shape between film points by more than the
/// growth covers there: the rim of the image circle, where element rims and the stop bind in
/// turn).
pub const CELL_OUTLINE_CHECK: f64 = 0.99;

/// A film cell's outline traced again over the 5 × 5 lattice is grown by this share of its
/// largest radius more (between those film points the region still reached up to 1.1 % past
/// it: the anamorphic lens with 5 blades at f/8).
pub const CELL_OUTLINE_REFINED_GROWTH: f64 = 0.025;

/// The ends of the spectral renderer's wavelength range (nm): outlines of dispersive lenses
/// hold the passing region at these as well as at the primary wavelength.
pub const SPECTRAL_RANGE_NM: [f64; 2] = [380.0, 780.0];

/// Film cells per side of the square a lens without rotational symmetry is outlined over.
pub const FILM_CELLS: usize = 16;

/// Points each side of the chief ray's aim point in the fine search of a lens stopped down
/// beyond what the rear grid resolves (the module's "Lenses stopped down far").
pub const NEAR_CHIEF_HALF: usize = 16;

/// The fine search's spacing as a share of the rear grid's cell where the grid finds no ray from
/// the film's centre (four times that where it finds a few).
pub const NEAR_CHIEF_REFINE: f64 = 1.0 / 16.0;

/// Fine-search points at least across the passing region's paraxial diameter on the rear plane
/// (a stop far smaller than the rear grid's cell: the fine spacing follows it down).
pub const NEAR_CHIEF_POINTS_ACROSS: f64 = 8.0;

/// How far (in rear-grid cells) the fine search about the chief ray may grow: a larger region
/// has enough grid points of its own.
pub const NEAR_CHIEF_REACH_CELLS: f64 = 4.0;

/// The rear grid resolves the passing region when it finds at least this many rays from the
/// film's centre; below, the fine search about each film point's chief ray is used instead.
pub const NEAR_CHIEF_BELOW: usize = 16;

/// The share of pupil samples drawn uniformly in the defensive disc (which holds every passing
/// ray) instead of the traced bounds: every passing ray keeps a positive density. Each costs
/// about one more absorbed ray in 128 (the disc is mostly absorbed).
pub const DEFENSIVE_FRACTION: f64 = 1.0 / 128.0;

/// A star-shaped polygon about `centre`, sampled uniformly (radial intervals: in the frame of a
/// film point on +x; film cells: about the origin, moved to each film point's own centre).
#[derive(Debug, Clone, PartialEq)]
pub struct Outline {
    /// A point inside the region (radial intervals: on the x axis; film cells: the origin).
    pub centre: DVec2,
    /// Radius of vertex k at angle 2πk/[`OUTLINE_ANGLES`] about `centre`.
    pub radii: Vec<f64>,
    /// Cumulative triangle areas, normalised (len `OUTLINE_ANGLES + 1`, last = 1).
    cdf: Vec<f64>,
    /// Polygon area (mm²).
    pub area: f64,
    /// How far the centre moves along x per mm of film radius (radial intervals of a lens
    /// stopped down beyond what the rear grid resolves, whose region slides with the film point
    /// by more than its own size across an interval; 0 elsewhere): for a film point at radius r
    /// the outline lies about `centre + (drift_per_mm · r, 0)`.
    pub drift_per_mm: f64,
}

impl Outline {
    fn new(centre: DVec2, radii: Vec<f64>) -> Option<Outline> {
        let n = radii.len();
        let half_sin = (std::f64::consts::TAU / n as f64).sin() * 0.5;
        let tri: Vec<f64> = (0..n).map(|k| half_sin * radii[k] * radii[(k + 1) % n]).collect();
        let area: f64 = tri.iter().sum();
        if !(area > 0.0 && area.is_finite()) {
            return None;
        }
        let mut cdf = Vec::with_capacity(n + 1);
        let mut acc = 0.0;
        cdf.push(0.0);
        for t in &tri {
            acc += t / area;
            cdf.push(acc);
        }
        cdf[n] = 1.0;
        Some(Outline { centre, radii, cdf, area, drift_per_mm: 0.0 })
    }

    fn vertex(&self, k: usize) -> DVec2 {
        let n = self.radii.len();
        let phi = std::f64::consts::TAU * (k % n) as f64 / n as f64;
        self.centre + DVec2::new(phi.cos(), phi.sin()) * self.radii[k % n]
    }

    /// The offset of the outline for a film point at radius `r` (zero unless it drifts).
    fn shift(&self, r: f64) -> DVec2 {
        DVec2::new(self.drift_per_mm * r, 0.0)
    }

    /// Whether `p` (film point on +x frame) is inside.
    pub fn contains(&self, p: DVec2) -> bool {
        let d = p - self.centre;
        let n = self.radii.len();
        let a = d.y.atan2(d.x).rem_euclid(std::f64::consts::TAU);
        let k = ((a / std::f64::consts::TAU * n as f64) as usize).min(n - 1);
        // inside the triangle (centre, v_k, v_k+1): on the centre's side of the outer edge
        let (v0, v1) = (self.vertex(k), self.vertex(k + 1));
        let edge = v1 - v0;
        let side = |q: DVec2| edge.perp_dot(q - v0);
        side(p) * side(self.centre) >= 0.0
    }

    /// A uniform point in the polygon from `u` in [0,1)²: `u` goes to the unit disc by the
    /// concentric map (so (0.5, 0.5) is the centre and a stratified `u` stays stratified), the
    /// disc point's angle picks a triangle by area and the place along its outer edge, and its
    /// radius scales the way out to that edge.
    pub fn sample(&self, u: DVec2) -> DVec2 {
        // 1. The unit disc: radius ρ (density 2ρ) and the angle as a fraction a of a turn.
        let d = super::aperture::concentric_disk(u);
        let rho = d.length().min(1.0);
        let a = (d.y.atan2(d.x) / std::f64::consts::TAU).rem_euclid(1.0);
        // 2. The triangle, by area, and the place t along its outer edge.
        let k = self.cdf.partition_point(|&c| c <= a).saturating_sub(1).min(self.radii.len() - 1);
        let span = self.cdf[k + 1] - self.cdf[k];
        let t = if span > 0.0 { ((a - self.cdf[k]) / span).clamp(0.0, 1.0) } else { 0.5 };
        // 3. Uniform in the triangle (centre, v_k, v_k+1): ρ of the way to the edge point.
        let (v0, v1) = (self.vertex(k), self.vertex(k + 1));
        let edge_point = v0 + (v1 - v0) * t;
        self.centre + (edge_point - self.centre) * rho
    }
}

/// Outlines per film cell for lenses without rotational symmetry: each film point samples the
/// outline of its cell about its own centre, the bilinear interpolation of the passing
/// region's centroids at the cell's corners.
#[derive(Debug, Clone, PartialEq)]
pub struct CellOutlines {
    /// Half the side of the film square covered (mm): cells span [−h, h]².
    pub half_side_mm: f64,
    /// Cells per side.
    pub cells: usize,
    /// The passing region's centroid on the rear plane at each cell corner (row-major,
    /// `(cells + 1)²`); None where no traced ray passes.
    pub corner_centres: Vec<Option<DVec2>>,
    /// Per cell (row-major), the outline about the film point's centre (the outline's own
    /// centre is the origin), where one was found.
    pub outlines: Vec<Option<Outline>>,
    /// Per cell without an outline, the box of the rays from its film points that pass,
    /// grown by two rear-grid cells (empty: nothing passes there); unused where there is one.
    pub boxes: Vec<Box2>,
    /// The chief ray's aim point on the rear plane at each cell corner (row-major,
    /// `(cells + 1)²`; rims ignored, so it exists past the image circle too); None where it
    /// cannot be aimed.
    pub corner_aims: Vec<Option<DVec2>>,
    /// Per cell without an outline, where it is smaller than the cell's box: the box of the
    /// passing rays relative to each film point's interpolated chief-ray aim (the rim of the
    /// image circle, where a small region slides across the rear plane with the film point
    /// further than its own size within one cell).
    pub sliding_boxes: Vec<Option<Box2>>,
    /// Per cell without an outline, where it is smaller than the boxes: the outline of the
    /// region that passes the stop with the elements' rims ignored (which holds the passing
    /// region), about each film point's interpolated chief-ray aim.
    pub stop_outlines: Vec<Option<Outline>>,
    /// Per cell, the largest film radius among its traced film points with a passing ray (mm;
    /// −∞ where none passes). Where the radial intervals found no ray (their 4 film points at 8
    /// azimuths can miss the image circle's rim), a cell serves film points up to this radius
    /// and half the rim lattice's spacing (an eighth of its side) beyond.
    pub reach_mm: Vec<f64>,
}

/// The sampling domain of one film point of a [`CellOutlines`] cell.
#[derive(Debug, Clone, Copy)]
pub enum CellDomain<'a> {
    /// The cell's outline, about the film point's centre.
    Outline(&'a Outline, DVec2),
    /// The cell's box (empty when no ray passes there).
    Box(Box2),
    /// The cell's sliding box, about the film point's interpolated chief-ray aim.
    SlidingBox(Box2, DVec2),
}

impl CellDomain<'_> {
    /// The domain's area (mm²).
    pub fn area(&self) -> f64 {
        match self {
            CellDomain::Outline(o, _) => o.area,
            CellDomain::Box(b) | CellDomain::SlidingBox(b, _) => b.area(),
        }
    }

    /// Whether rear-plane point `p` is inside.
    pub fn contains(&self, p: DVec2) -> bool {
        match self {
            CellDomain::Outline(o, centre) => o.contains(p - *centre),
            CellDomain::Box(b) => b.contains(p),
            CellDomain::SlidingBox(b, aim) => b.contains(p - *aim),
        }
    }

    /// A uniform point of the domain from `u` in [0,1)² (None when it is empty).
    pub fn sample(&self, u: DVec2) -> Option<DVec2> {
        match self {
            CellDomain::Outline(o, centre) => Some(*centre + o.sample(u)),
            CellDomain::Box(b) => (!b.is_empty()).then(|| b.min + (b.max - b.min) * u),
            CellDomain::SlidingBox(b, aim) => Some(*aim + b.min + (b.max - b.min) * u),
        }
    }
}

impl CellOutlines {
    /// The cell of film point `film` and its place in it ([0, 1]²); None outside the square.
    fn cell(&self, film: DVec2) -> Option<(usize, usize, DVec2)> {
        let u = (film + DVec2::splat(self.half_side_mm)) / (2.0 * self.half_side_mm) * self.cells as f64;
        if !(u.x >= 0.0 && u.y >= 0.0 && u.x <= self.cells as f64 && u.y <= self.cells as f64) {
            return None;
        }
        let (i, j) = ((u.x as usize).min(self.cells - 1), (u.y as usize).min(self.cells - 1));
        Some((i, j, u - DVec2::new(i as f64, j as f64)))
    }

    /// The centre of film point `film`'s region: its cell corners' centroids, interpolated.
    fn centre_in(&self, i: usize, j: usize, t: DVec2) -> Option<DVec2> {
        bilinear(&self.corner_centres, self.cells + 1, i, j, t)
    }

    /// Film point `film`'s chief-ray aim: its cell corners' aims, interpolated.
    fn aim_in(&self, i: usize, j: usize, t: DVec2) -> Option<DVec2> {
        bilinear(&self.corner_aims, self.cells + 1, i, j, t)
    }

    /// Whether film point `film` lies within its cell's reach ([`CellOutlines::reach_mm`]).
    fn reaches(&self, film: DVec2) -> bool {
        let side = 2.0 * self.half_side_mm / self.cells as f64;
        self.cell(film).is_some_and(|(i, j, _)| film.length() <= self.reach_mm[j * self.cells + i] + 0.125 * side)
    }

    /// The domain serving film point `film`: its cell's outline about the point's centre, or the
    /// cell's box; None outside the square.
    pub fn at(&self, film: DVec2) -> Option<CellDomain<'_>> {
        let (i, j, t) = self.cell(film)?;
        let k = j * self.cells + i;
        Some(match (&self.outlines[k], self.centre_in(i, j, t)) {
            (Some(o), Some(centre)) => CellDomain::Outline(o, centre),
            _ => match (&self.stop_outlines[k], self.sliding_boxes[k], self.aim_in(i, j, t)) {
                (Some(o), _, Some(aim)) => CellDomain::Outline(o, aim),
                (None, Some(b), Some(aim)) => CellDomain::SlidingBox(b, aim),
                _ => CellDomain::Box(self.boxes[k]),
            },
        })
    }
}

/// One film cell's domains as [`ExitPupilBounds::film_cells`] finds them: the outline, the box,
/// the sliding box, the stop's outline and the reach (mm) of [`CellOutlines`].
type CellParts = (Option<Outline>, Box2, Option<Box2>, Option<Outline>, f64);

/// The bilinear interpolation at `t` ([0, 1]²) in cell (i, j) of corner values `corners`
/// (row-major, `n` per row); None unless all four corners have one.
fn bilinear(corners: &[Option<DVec2>], n: usize, i: usize, j: usize, t: DVec2) -> Option<DVec2> {
    let c = |a: usize, b: usize| corners[(j + b) * n + i + a];
    let (c00, c10, c01, c11) = (c(0, 0)?, c(1, 0)?, c(0, 1)?, c(1, 1)?);
    Some((c00 * (1.0 - t.x) + c10 * t.x) * (1.0 - t.y) + (c01 * (1.0 - t.x) + c11 * t.x) * t.y)
}

/// Per-radius bounds of the rays leaving the film that pass the lens.
#[derive(Debug, Clone)]
pub struct ExitPupilBounds {
    /// Film plane z (lens frame) the bounds were computed for.
    pub film_z_mm: f64,
    /// The sampling plane z (the rear vertex).
    pub rear_z_mm: f64,
    /// Film radius covered.
    pub max_film_radius_mm: f64,
    /// One box per radial interval (film point on +x).
    pub boxes: Vec<Box2>,
    /// True when the boxes hold for any film azimuth without rotation (asymmetric lenses).
    pub union_only: bool,
    /// The region's outline per interval (film point on +x), where one was found; sampling
    /// uses it instead of the box.
    pub outlines: Vec<Option<Outline>>,
    /// Lenses without rotational symmetry: outlines per film cell (sampling uses them instead
    /// of the union box where a cell has one).
    pub cells: Option<CellOutlines>,
    /// Wavelengths besides the primary one whose passing rays the bounds also hold (nm; empty
    /// for [`ExitPupilBounds::compute`]).
    pub wavelength_ends_nm: Vec<f64>,
    /// Radius (mm) of the disc about the axis on the rear plane that holds every passing ray
    /// from the film's extent ([`defensive_radius_mm`]); None when no such disc can be derived
    /// (a rear surface reaching the film), and then no defensive samples are drawn.
    pub defensive_radius_mm: Option<f64>,
}

/// A sampled point on the rear plane.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PupilSample {
    /// The point (lens frame) on the rear plane.
    pub point: DVec3,
    /// Density with respect to area on the rear plane (1/mm²).
    pub pdf_area: f64,
}

impl ExitPupilBounds {
    /// Computes bounds for a film plane at `film_z_mm` (lens frame, behind the last vertex) up to
    /// film radius `max_film_radius_mm`, with the lens's current stop. Tilted sensors pass the
    /// largest distance any film point has from the axis; the bounds are per radius, and a
    /// tilted film's z varies, so they are computed over the span `film_z_mm ± dz`.
    pub fn compute(lens: &Lens, film_z_mm: f64, film_dz_mm: f64, max_film_radius_mm: f64) -> Self {
        Self::compute_for(lens, film_z_mm, film_dz_mm, max_film_radius_mm, &[], None)
    }

    /// [`ExitPupilBounds::compute`] (with `spectral`, [`ExitPupilBounds::compute_spectral`]) for a
    /// sensor plane through (0, 0, `film_z_mm`) whose z changes by `film_slope` (dz/dx, dz/dy)
    /// across the film: the film cells then trace each film point at its own z instead of at
    /// z ± `film_dz_mm` (a third of the work, and tighter outlines on a tilted sensor).
    pub fn compute_on_plane(
        lens: &Lens,
        film_z_mm: f64,
        film_dz_mm: f64,
        film_slope: DVec2,
        max_film_radius_mm: f64,
        spectral: bool,
    ) -> Self {
        let ends: &[f64] = if spectral && lens.has_dispersion() { &SPECTRAL_RANGE_NM } else { &[] };
        Self::compute_for(lens, film_z_mm, film_dz_mm, max_film_radius_mm, ends, Some(film_slope))
    }

    /// [`ExitPupilBounds::compute`] for spectral renders: for a dispersive lens the bounds also
    /// hold every passing ray at the ends of the spectral range ([`SPECTRAL_RANGE_NM`]; the image
    /// circle and the passing region shift with the wavelength). Larger than the primary
    /// wavelength's bounds, so renders at one wavelength use those.
    pub fn compute_spectral(lens: &Lens, film_z_mm: f64, film_dz_mm: f64, max_film_radius_mm: f64) -> Self {
        let ends: &[f64] = if lens.has_dispersion() { &SPECTRAL_RANGE_NM } else { &[] };
        Self::compute_for(lens, film_z_mm, film_dz_mm, max_film_radius_mm, ends, None)
    }

    /// The bounds at the primary wavelength and at the wavelengths `ends`; `film_slope`: the
    /// sensor plane's, where known.
    fn compute_for(
        lens: &Lens,
        film_z_mm: f64,
        film_dz_mm: f64,
        max_film_radius_mm: f64,
        ends: &[f64],
        film_slope: Option<DVec2>,
    ) -> Self {
        let near_chief = near_chief_spacing_mm(lens, film_z_mm);
        let compute = |resolution, slope| {
            Self::compute_with_ends(
                lens,
                film_z_mm,
                film_dz_mm,
                max_film_radius_mm,
                resolution,
                ends,
                slope,
                near_chief,
            )
        };
        if radially_outlined(lens, film_dz_mm, film_slope, near_chief.is_some()) {
            compute([64, 16, 48], None)
        } else {
            // No rotational symmetry (the lens, or a bladed, masked or squeezed stop, whose
            // region does not turn with the film point; or a small stop on a tilted sensor,
            // whose region slides with each film point's z): one union box serves every film point
            // (16 intervals of 4 film points at 8 azimuths find it and the radii with passing
            // rays). Outlines per film cell then tighten it (a 5-blade stop at f/4 on
            // double-gauss-50mm: 14 % absorbed, 29 % in the circumscribed circle's radial
            // outlines).
            let mut bounds = compute([16, 4, 48], film_slope);
            bounds.cells = bounds.film_cells(lens, film_dz_mm, film_slope, FILM_CELLS, 48, near_chief);
            bounds
        }
    }

    /// [`ExitPupilBounds::compute`] with explicit resolution.
    pub fn compute_with(
        lens: &Lens,
        film_z_mm: f64,
        film_dz_mm: f64,
        max_film_radius_mm: f64,
        intervals: usize,
        film_samples: usize,
        grid: usize,
    ) -> Self {
        Self::compute_with_ends(
            lens,
            film_z_mm,
            film_dz_mm,
            max_film_radius_mm,
            [intervals, film_samples, grid],
            &[],
            None,
            None,
        )
    }

    /// [`ExitPupilBounds::compute_with`] also holding the wavelengths `ends`; `resolution` is
    /// (intervals, film samples per interval, rear grid per side); `film_slope`: the sensor
    /// plane, where known, on which the union box (no rotational symmetry) is traced;
    /// `near_chief`: each film point's region is also searched at this spacing (mm) about its
    /// chief ray ([`for_each_passing_near_chief`]) besides the rear grid, the margins become
    /// two such cells (the grid's own points keep two grid cells), and the radial outlines
    /// drift with the film radius.
    #[allow(clippy::too_many_arguments)]
    fn compute_with_ends(
        lens: &Lens,
        film_z_mm: f64,
        film_dz_mm: f64,
        max_film_radius_mm: f64,
        resolution: [usize; 3],
        spectral_ends: &[f64],
        film_slope: Option<DVec2>,
        near_chief: Option<f64>,
    ) -> Self {
        let [intervals, film_samples, grid] = resolution;
        let rear_z = lens.last_vertex_z_mm();
        let half = 1.5 * lens.rear_semi_diameter_mm();
        let tiny = near_chief.is_some();
        let grid_cell = 2.0 * half / grid as f64;
        let cell = near_chief.unwrap_or(grid_cell);
        // With the fine search the rear grid still runs (it finds regions the chief ray does
        // not reach, where an element's rim vignettes it); its points are grown so that with the
        // fine margin below they keep the grid's own (two grid cells).
        let grid_growth = DVec2::splat(2.0 * (grid_cell - cell));
        let reach = NEAR_CHIEF_REACH_CELLS * grid_cell;
        let wl = lens.primary_wavelength_nm();
        let symmetric = radially_outlined(lens, film_dz_mm, film_slope, tiny);
        // The union box over a known sensor plane needs its points only; else the z span.
        let on_plane = film_slope.filter(|_| !symmetric);
        let z_levels: Vec<f64> = if film_dz_mm > 0.0 && on_plane.is_none() {
            vec![film_z_mm - film_dz_mm, film_z_mm, film_z_mm + film_dz_mm]
        } else {
            vec![film_z_mm]
        };
        // 1. For each radial interval, trace a grid from film points in it.
        let mut traced: Vec<(Box2, Vec<DVec3>, DVec2)> = (0..intervals)
            .into_par_iter()
            .map(|k| {
                let r0 = max_film_radius_mm * k as f64 / intervals as f64;
                let r1 = max_film_radius_mm * (k + 1) as f64 / intervals as f64;
                let mut b = Box2::EMPTY;
                let mut all_pts = Vec::new();
                let (mut sum, mut count) = (DVec2::ZERO, 0usize);
                for &fz in &z_levels {
                    for f in 0..film_samples {
                        let r = r0 + (r1 - r0) * (f as f64 + 0.5) / film_samples as f64;
                        let mut film_pts = vec![DVec3::new(r, 0.0, fz)];
                        if f == 0 {
                            film_pts[0].x = r0;
                        }
                        if f + 1 == film_samples {
                            film_pts.push(DVec3::new(r1, 0.0, fz));
                        }
                        if !symmetric {
                            // Asymmetric: sample other azimuths too; the union box is used.
                            for a in 1..8 {
                                let phi = a as f64 * std::f64::consts::FRAC_PI_4;
                                film_pts.push(DVec3::new(r * phi.cos(), r * phi.sin(), fz));
                            }
                        }
                        for mut fp in film_pts {
                            if let Some(slope) = on_plane {
                                fp.z = film_z_mm + slope.x * fp.x + slope.y * fp.y;
                            }
                            all_pts.push(fp);
                            let grid_origin = [rear_z, -half, -half];
                            for_each_passing(lens, wl, fp, grid_origin, DVec2::splat(grid_cell), grid, |q| {
                                b.grow(q - grid_growth);
                                b.grow(q + grid_growth);
                                sum += q;
                                count += 1;
                            });
                            if tiny {
                                let _ = for_each_passing_near_chief(lens, wl, fp, [rear_z, cell, reach], |q| {
                                    b.grow(q);
                                    sum += q;
                                    count += 1;
                                });
                            }
                            // Dispersive lenses: the spectral range's ends on a grid of half the
                            // resolution (the image circle and the region shift with the
                            // wavelength), each passing point grown by half its cell (with the
                            // margin below, one and a half).
                            for &wl_end in spectral_ends {
                                let coarse = DVec2::splat(2.0 * grid_cell);
                                let grow = DVec2::splat(grid_cell) + grid_growth;
                                for_each_passing(lens, wl_end, fp, [rear_z, -half, -half], coarse, grid / 2, |q| {
                                    b.grow(q - grow);
                                    b.grow(q + grow);
                                });
                                if tiny {
                                    let _ = for_each_passing_near_chief(lens, wl_end, fp, [rear_z, cell, reach], |q| {
                                        b.grow(q - DVec2::splat(cell));
                                        b.grow(q + DVec2::splat(cell));
                                    });
                                }
                            }
                        }
                    }
                }
                (b, all_pts, if count > 0 { sum / count as f64 } else { DVec2::ZERO })
            })
            .collect();
        // 1b. The rim. The image circle ends inside an interval, and at the spectral range's
        //     ends it reaches a little further (lateral colour) in regions smaller than the
        //     grid's cells (aspheric-fisheye-10mm at f/8: 0.8 × 1.7 mm against 1.6 mm cells at
        //     380 nm). The intervals past the last one with passing rays are traced again on a
        //     grid four times finer over the previous interval's box, until one has none.
        //     (With the fine search too, this grid keeps the rear grid's scale.)
        let fine = grid_cell / 4.0;
        let mut k = traced.iter().rposition(|t| !t.0.is_empty()).map_or(traced.len(), |last| last + 1);
        while k < traced.len() && k > 0 {
            let prev = traced[k - 1].0;
            let reach = DVec2::splat(2.0 * grid_cell);
            let window = Box2 { min: prev.min - reach, max: prev.max + reach };
            let n = ((window.max - window.min).max_element() / fine).ceil().max(1.0) as usize;
            let step = (window.max - window.min) / n as f64;
            let found: Vec<Box2> = traced[k]
                .1
                .par_iter()
                .map(|&fp| {
                    let mut b = Box2::EMPTY;
                    for &w in std::iter::once(&wl).chain(spectral_ends) {
                        for_each_passing(lens, w, fp, [rear_z, window.min.x, window.min.y], step, n, |q| {
                            b.grow(q - (step + grid_growth));
                            b.grow(q + (step + grid_growth));
                        });
                    }
                    b
                })
                .collect();
            let b = found.into_iter().fold(Box2::EMPTY, |a, b| if b.is_empty() { a } else { Box2::union(a, b) });
            if b.is_empty() {
                break;
            }
            traced[k].0 = b;
            k += 1;
        }
        let boxes: Vec<Box2> = traced.iter().map(|t| t.0).collect();
        // 2. Enlarge by two cells (rays between grid points) and, for asymmetric systems, use
        //    the union for every interval.
        let margin = DVec2::splat(2.0 * cell);
        let mut boxes: Vec<Box2> = boxes
            .into_iter()
            .map(|b| if b.is_empty() { b } else { Box2 { min: b.min - margin, max: b.max + margin } })
            .collect();
        if !symmetric {
            let all = boxes.iter().fold(Box2::EMPTY, |a, b| if b.is_empty() { a } else { Box2::union(a, *b) });
            // symmetric about both axes (the film point may sit at any azimuth)
            let m = all.min.abs().max(all.max.abs());
            let m = DVec2::splat(m.x.max(m.y));
            // Radii where no traced film point at any of the 8 azimuths has a passing ray lie
            // beyond the image circle: they stay empty.
            boxes = boxes.iter().map(|b| if b.is_empty() { *b } else { Box2 { min: -m, max: m } }).collect();
        }
        // 3. Outlines (symmetric lenses): the region's polygon per interval.
        let outlines: Vec<Option<Outline>> = if symmetric {
            traced
                .par_iter()
                .zip(boxes.par_iter())
                .map(|((_, pts, centroid), b)| {
                    if b.is_empty() {
                        None
                    } else {
                        outline_of(lens, [wl, rear_z], *b, pts, DVec2::new(centroid.x, 0.0), spectral_ends, tiny)
                    }
                })
                .collect()
        } else {
            vec![None; boxes.len()]
        };
        ExitPupilBounds {
            film_z_mm,
            rear_z_mm: rear_z,
            max_film_radius_mm,
            boxes,
            union_only: !symmetric,
            outlines,
            cells: None,
            wavelength_ends_nm: spectral_ends.to_vec(),
            defensive_radius_mm: defensive_radius_mm(lens, film_z_mm, film_dz_mm, max_film_radius_mm),
        }
    }

    /// Outlines per film cell (see [`CellOutlines`]) for a lens whose bounds are the union box:
    /// `cells`² cells over the film square that holds the radii with passing rays, corner
    /// centroids from a `grid`² trace of the rear plane (`near_chief`: from the fine search of
    /// this spacing (mm) about each film point's chief ray, [`for_each_passing_near_chief`]).
    /// None when no ray passes.
    fn film_cells(
        &self,
        lens: &Lens,
        film_dz_mm: f64,
        film_slope: Option<DVec2>,
        cells: usize,
        grid: usize,
        near_chief: Option<f64>,
    ) -> Option<CellOutlines> {
        // The union box, and the square's half side: the largest radius with passing rays.
        let last = self.boxes.iter().rposition(|b| !b.is_empty())?;
        let union = self.boxes[last];
        let h = self.max_film_radius_mm * (last + 1) as f64 / self.boxes.len() as f64;
        let wl = lens.primary_wavelength_nm();
        let rear_z = self.rear_z_mm;
        let ends = &self.wavelength_ends_nm;
        let n = cells + 1;
        let film_xy = |i: f64, j: f64| DVec2::new(-h + 2.0 * h * i / cells as f64, -h + 2.0 * h * j / cells as f64);
        // The film points' z: on the sensor plane where it is known, else the span's ends and
        // middle.
        let z_levels = |f: DVec2| -> Vec<f64> {
            match film_slope {
                Some(slope) => vec![self.film_z_mm + slope.dot(f)],
                None if film_dz_mm > 0.0 => {
                    vec![self.film_z_mm - film_dz_mm, self.film_z_mm, self.film_z_mm + film_dz_mm]
                }
                None => vec![self.film_z_mm],
            }
        };
        // 1. The passing region's centroid at every cell corner (on the plane, or its middle z).
        let cell = (union.max - union.min) / grid as f64;
        // (the grid's points, and with `near_chief` the fine search's; the flag says which)
        let passing = |fp: DVec3, w: f64, take: &mut dyn FnMut(DVec2, bool)| {
            for_each_passing(lens, w, fp, [rear_z, union.min.x, union.min.y], cell, grid, |q| take(q, true));
            if let Some(fine) = near_chief {
                let reach = NEAR_CHIEF_REACH_CELLS * cell.max_element();
                let _ = for_each_passing_near_chief(lens, w, fp, [rear_z, fine, reach], |q| take(q, false));
            }
        };
        let corner_centres: Vec<Option<DVec2>> = (0..n * n)
            .into_par_iter()
            .map(|k| {
                let f = film_xy((k % n) as f64, (k / n) as f64);
                let fp = DVec3::new(f.x, f.y, film_slope.map_or(self.film_z_mm, |slope| self.film_z_mm + slope.dot(f)));
                // (the grid's points where they resolve the region, as without the fine search;
                // else the fine search's)
                let mut sums = [(DVec2::ZERO, 0usize); 2];
                passing(fp, wl, &mut |q, on_grid| {
                    let s = &mut sums[on_grid as usize];
                    s.0 += q;
                    s.1 += 1;
                });
                let (sum, count) = if sums[1].1 >= NEAR_CHIEF_BELOW || sums[0].1 == 0 { sums[1] } else { sums[0] };
                (count > 0).then(|| sum / count as f64)
            })
            .collect();
        // (and the chief ray's aim at every corner, for the rim's sliding boxes)
        let corner_aims: Vec<Option<DVec2>> = (0..n * n)
            .into_par_iter()
            .map(|k| {
                let f = film_xy((k % n) as f64, (k / n) as f64);
                let fp = DVec3::new(f.x, f.y, film_slope.map_or(self.film_z_mm, |slope| self.film_z_mm + slope.dot(f)));
                chief_aim_from_film(lens, fp, wl)
            })
            .collect();
        let mut grid_cells = CellOutlines {
            half_side_mm: h,
            cells,
            corner_centres,
            outlines: vec![None; cells * cells],
            boxes: vec![Box2::EMPTY; cells * cells],
            corner_aims,
            sliding_boxes: vec![None; cells * cells],
            stop_outlines: vec![None; cells * cells],
            reach_mm: vec![f64::NEG_INFINITY; cells * cells],
        };
        // 2. Each cell's outline about its film points' own centres: a 3 × 3 grid of them (its
        //    corners, edge midpoints and centre) per film z. A region bounded by several edges
        //    (blades, element rims) reaches further between two film points than at either when
        //    a different edge binds at each; corners and centre alone let a 5-blade stop on the
        //    anamorphic lens at f/4 lose 1.4 % of one film point's passing rays.
        let outlines: Vec<CellParts> = (0..cells * cells)
            .into_par_iter()
            .map(|k| {
                let (i, j) = (k % cells, k / cells);
                // (a cell wholly beyond the last radius with passing rays serves no film point)
                let (lo, hi) = (film_xy(i as f64, j as f64), film_xy(i as f64 + 1.0, j as f64 + 1.0));
                if DVec2::ZERO.clamp(lo, hi).length() > h {
                    return (None, Box2::EMPTY, None, None, f64::NEG_INFINITY);
                }
                // (film points at places (a, b) of the cell, at each of their z levels)
                let points = |places: &mut dyn Iterator<Item = DVec2>| -> (Vec<DVec3>, Vec<DVec2>) {
                    let (mut pts, mut at) = (Vec::new(), Vec::new());
                    for t in places {
                        let f = film_xy(i as f64 + t.x, j as f64 + t.y);
                        for z in z_levels(f) {
                            pts.push(DVec3::new(f.x, f.y, z));
                            at.push(t);
                        }
                    }
                    (pts, at)
                };
                let lattice =
                    |n: usize| (0..n * n).map(move |m| DVec2::new((m % n) as f64, (m / n) as f64) / (n - 1) as f64);
                let (pts, places) = points(&mut lattice(3));
                // (the cell's points, those on its upper edges too, are placed in this cell)
                let centre_of = |fp: DVec3| {
                    let u = (DVec2::new(fp.x, fp.y) + DVec2::splat(h)) / (2.0 * h) * cells as f64;
                    grid_cells.centre_in(i, j, u - DVec2::new(i as f64, j as f64))
                };
                let (between, _) = points(&mut lattice(5).filter(|t| (t * 4.0).as_ivec2() % 2 != IVec2::ZERO));
                // The outline about `centre_of` over the 3 × 3 film points; `stop_only`: of the
                // region that passes the stop (rims ignored). 2b. Checked between those film
                // points, at the 5 × 5 lattice's other 16: where one's region reaches
                // [`CELL_OUTLINE_CHECK`] of the outline's vertices or chord midpoints, the outline
                // is traced again over all 25 (and grown by [`CELL_OUTLINE_REFINED_GROWTH`]).
                let checked_outline = |centre_of: &(dyn Fn(DVec3) -> Option<DVec2> + Sync), stop_only: bool| {
                    let outline = |pts: &[DVec3], extra_growth: f64| {
                        outline_radii(lens, [wl, rear_z], union, pts, centre_of, false, ends, stop_only).and_then(
                            |radii| {
                                let largest = radii.iter().cloned().fold(0.0, f64::max);
                                Outline::new(DVec2::ZERO, radii.iter().map(|r| r + extra_growth * largest).collect())
                            },
                        )
                    };
                    let weights = stop_only.then(|| stop_only_weights(lens));
                    let o = outline(&pts, 0.0)?;
                    let reaches = between.iter().any(|&fp| {
                        let Some(centre) = centre_of(fp) else { return true };
                        (0..2 * OUTLINE_ANGLES).any(|m| {
                            let (v0, v1) = (o.vertex(m / 2), o.vertex(m / 2 + 1));
                            let p = if m % 2 == 0 { v0 } else { 0.5 * (v0 + v1) };
                            let q = centre + CELL_OUTLINE_CHECK * p;
                            passes_lens(lens, &Ray::new(fp, DVec3::new(q.x, q.y, rear_z) - fp), wl, weights.as_deref())
                        })
                    });
                    if !reaches {
                        return Some(o);
                    }
                    let (all, _) = points(&mut lattice(5));
                    outline(&all, CELL_OUTLINE_REFINED_GROWTH)
                };
                if let Some(o) = checked_outline(&centre_of, false) {
                    // (every film point of an outlined cell has passing rays; the farthest is a
                    // corner, in either lattice)
                    let reach = pts.iter().map(|p| p.truncate().length()).fold(f64::NEG_INFINITY, f64::max);
                    return (Some(o), Box2::EMPTY, None, None, reach);
                }
                // 3. No outline (the rim of the image circle): the box of the passing rays, at
                //    the bounds' other wavelengths too; and the same rays' box about each film
                //    point's interpolated chief-ray aim, where every corner has one.
                //    First the 3 × 3 lattice of film points; then the 5 × 5 lattice's other 16,
                //    between them (where the region at the rim reaches further than at any of
                //    them: aspheric-fisheye-10mm with 5 blades lost 2–4 passing rays in 10³),
                //    traced over the first box grown by half its size (at least 4 grid cells), and
                //    over the whole grid where a passing point comes within a grid cell of that
                //    window's edge.
                let mut b = Box2::EMPTY;
                let mut sliding = Box2::EMPTY;
                let mut cell_reach = f64::NEG_INFINITY;
                let mut trace = |fp: DVec3, t: DVec2, b: &mut Box2, window: Option<Box2>| -> bool {
                    let aim = grid_cells.aim_in(i, j, t);
                    let mut near_edge = false;
                    let radius = fp.truncate().length();
                    for &w in std::iter::once(&wl).chain(ends) {
                        // (the box's points and the sliding box's, each grown by its own amount)
                        let mut take = |q: DVec2, grow: DVec2, sliding_grow: Option<DVec2>| {
                            cell_reach = cell_reach.max(radius);
                            b.grow(q - grow);
                            b.grow(q + grow);
                            if let (Some(aim), Some(grow)) = (aim, sliding_grow) {
                                sliding.grow(q - aim - grow);
                                sliding.grow(q - aim + grow);
                            }
                        };
                        // (with the fine search, the grid's points keep two grid cells with the
                        // margin below; in the sliding box, those inside a fine window that
                        // resolved the region add nothing)
                        let resolved = near_chief.and_then(|fine| {
                            let reach = NEAR_CHIEF_REACH_CELLS * cell.max_element();
                            let fine_point = |q| take(q, DVec2::ZERO, Some(DVec2::ZERO));
                            for_each_passing_near_chief(lens, w, fp, [rear_z, fine, reach], fine_point)
                        });
                        let grow = near_chief.map_or(DVec2::ZERO, |fine| 2.0 * (cell - fine));
                        let origin = [rear_z, union.min.x, union.min.y];
                        for_each_passing_in(lens, w, fp, origin, cell, grid, window, |q| {
                            near_edge |= window.is_some_and(|w| {
                                let inner = Box2 { min: w.min + cell, max: w.max - cell };
                                !inner.contains(q)
                            });
                            take(q, grow, (!resolved.is_some_and(|r| r.contains(q))).then_some(grow));
                        });
                    }
                    near_edge
                };
                for (&fp, &t) in pts.iter().zip(&places) {
                    trace(fp, t, &mut b, None);
                }
                let first = b;
                let reach = (0.5 * (first.max - first.min)).max(DVec2::splat(4.0 * cell.max_element()));
                let window = (!first.is_empty()).then(|| Box2 { min: first.min - reach, max: first.max + reach });
                let (between, between_places) =
                    points(&mut lattice(5).filter(|t| (t * 4.0).as_ivec2() % 2 != IVec2::ZERO));
                for (&fp, &t) in between.iter().zip(&between_places) {
                    let mut found = Box2::EMPTY;
                    if window.is_none() || trace(fp, t, &mut found, window) {
                        found = Box2::EMPTY;
                        trace(fp, t, &mut found, None);
                    }
                    if !found.is_empty() {
                        b = if b.is_empty() { found } else { Box2::union(b, found) };
                    }
                }
                let margin = near_chief.map_or(2.0 * cell, |fine| DVec2::splat(2.0 * fine));
                let grown = |b: Box2| if b.is_empty() { b } else { Box2 { min: b.min - margin, max: b.max + margin } };
                let (b, sliding) = (grown(b), grown(sliding));
                // (the sliding box where every film point has an aim and it is the smaller)
                let every_aim = grid_cells.aim_in(i, j, DVec2::ZERO).is_some();
                let sliding = (every_aim && !sliding.is_empty() && sliding.area() < b.area()).then_some(sliding);
                // 4. The region that passes the stop, the elements' rims ignored (the passing
                //    region is that one cut by rims), outlined about each film point's
                //    interpolated aim, where smaller than the boxes.
                let aim_of = |fp: DVec3| {
                    let u = (DVec2::new(fp.x, fp.y) + DVec2::splat(h)) / (2.0 * h) * cells as f64;
                    grid_cells.aim_in(i, j, u - DVec2::new(i as f64, j as f64))
                };
                let smallest = sliding.map_or(b.area(), |s| s.area());
                let speck = (every_aim && !b.is_empty())
                    .then(|| checked_outline(&aim_of, true))
                    .flatten()
                    .filter(|o| o.area < smallest);
                (None, b, sliding, speck, cell_reach)
            })
            .collect();
        for (k, (outline, b, sliding, speck, reach)) in outlines.into_iter().enumerate() {
            (grid_cells.outlines[k], grid_cells.boxes[k], grid_cells.sliding_boxes[k]) = (outline, b, sliding);
            (grid_cells.stop_outlines[k], grid_cells.reach_mm[k]) = (speck, reach);
        }
        Some(grid_cells)
    }

    /// The interval index of film radius `r` (None beyond the covered radius).
    fn interval(&self, r: f64) -> Option<usize> {
        if !(r >= 0.0) || r > self.max_film_radius_mm * (1.0 + 1e-9) {
            return None;
        }
        let k = ((r / self.max_film_radius_mm) * self.boxes.len() as f64) as usize;
        Some(k.min(self.boxes.len() - 1))
    }

    /// The sampling domain's area for a film point at radius `r` on +x (mm²; 0 outside the
    /// bounds). Lenses without rotational symmetry need the point: [`Self::domain_area_at`].
    pub fn domain_area(&self, r: f64) -> f64 {
        self.domain_area_at(DVec2::new(r, 0.0))
    }

    /// The sampling domain's area for film point `film` (mm²; 0 outside the bounds).
    pub fn domain_area_at(&self, film: DVec2) -> f64 {
        let Some(k) = self.interval(film.length()) else { return 0.0 };
        // (a film cell's domain stands where there is one, within its reach where the radial
        // interval found no ray: `cell_domain`)
        if let Some(d) = self.cell_domain(film) {
            return d.area();
        }
        if self.boxes[k].is_empty() {
            return 0.0;
        }
        self.outlines[k].as_ref().filter(|_| !self.union_only).map_or(self.boxes[k].area(), |o| o.area)
    }

    /// The film cell's domain serving `film` (lenses without rotational symmetry), inside the
    /// cells' square; where the film point's radial interval found no ray, only within the
    /// cell's reach (beyond it: an empty box).
    fn cell_domain(&self, film: DVec2) -> Option<CellDomain<'_>> {
        let cells = self.cells.as_ref().filter(|_| self.union_only)?;
        let domain = cells.at(film)?;
        let unseen = self.interval(film.length()).is_none_or(|k| self.boxes[k].is_empty());
        Some(if unseen && !cells.reaches(film) { CellDomain::Box(Box2::EMPTY) } else { domain })
    }

    /// The box for a film point at radius `r` on +x (empty beyond the covered radius).
    pub fn box_for_radius(&self, r: f64) -> Box2 {
        self.interval(r).map_or(Box2::EMPTY, |k| self.boxes[k])
    }

    /// Whether the rear-plane point `p` lies in the sampling domain for film point `film`.
    pub fn contains(&self, film: DVec2, p: DVec2) -> bool {
        let r = film.length();
        let Some(k) = self.interval(r) else { return false };
        let b = self.boxes[k];
        if self.union_only {
            return match self.cell_domain(film) {
                Some(d) => d.contains(p),
                None => !b.is_empty() && b.contains(p),
            };
        }
        // rotate p into the frame where the film point lies on +x
        let (s, c) = if r > 0.0 { (film.y / r, film.x / r) } else { (0.0, 1.0) };
        let q = DVec2::new(c * p.x + s * p.y, -s * p.x + c * p.y);
        match &self.outlines[k] {
            Some(o) if o.drift_per_mm != 0.0 => o.contains(q - o.shift(r)),
            Some(o) => o.contains(q),
            None => b.contains(q),
        }
    }

    /// Samples a rear-plane point for the film point `film` (x, y) from `u` in [0,1)²: with
    /// probability [`DEFENSIVE_FRACTION`] uniformly in the defensive disc, else in the traced
    /// bounds ([`Self::sample_bounds`]). The density is the mixture's, [`Self::pdf_area`]. None
    /// when the traced bounds are empty there and the defensive disc was not chosen.
    pub fn sample(&self, film: DVec2, u: DVec2) -> Option<PupilSample> {
        let Some(radius) = self.defensive_radius_mm else { return self.sample_bounds(film, u) };
        let eps = DEFENSIVE_FRACTION;
        // 1. The first share of u.x picks the disc; both parts keep u stratified.
        if u.x < eps {
            let p = super::aperture::concentric_disk(DVec2::new(u.x / eps, u.y)) * radius;
            let pdf_area = self.pdf_area(film, p);
            return Some(PupilSample { point: DVec3::new(p.x, p.y, self.rear_z_mm), pdf_area });
        }
        // 2. The rest: the traced bounds, and the disc's density where it holds the point.
        let u = DVec2::new(((u.x - eps) / (1.0 - eps)).min(1.0 - f64::EPSILON / 2.0), u.y);
        let s = self.sample_bounds(film, u)?;
        let disc = if s.point.truncate().length_squared() <= radius * radius { self.disc_pdf(radius) } else { 0.0 };
        Some(PupilSample { pdf_area: (1.0 - eps) * s.pdf_area + disc, ..s })
    }

    /// The density (1/mm²) with which [`Self::sample`] draws rear-plane point `p` for film point
    /// `film`: the traced bounds' uniform density where they hold `p` and the defensive disc's,
    /// mixed. Positive for every ray that passes the lens.
    pub fn pdf_area(&self, film: DVec2, p: DVec2) -> f64 {
        let bounds = if self.contains(film, p) {
            let area = self.domain_area_at(film);
            if area > 0.0 {
                1.0 / area
            } else {
                0.0
            }
        } else {
            0.0
        };
        match self.defensive_radius_mm {
            Some(radius) => {
                let disc = if p.length_squared() <= radius * radius { self.disc_pdf(radius) } else { 0.0 };
                (1.0 - DEFENSIVE_FRACTION) * bounds + disc
            }
            None => bounds,
        }
    }

    /// The defensive disc's share of the density inside it (1/mm²).
    fn disc_pdf(&self, radius: f64) -> f64 {
        DEFENSIVE_FRACTION / (std::f64::consts::PI * radius * radius)
    }

    /// Samples a rear-plane point uniformly in the traced bounds only (no defensive disc), for
    /// film point `film` (x, y) from `u` in [0,1)²; `pdf_area` is the bounds' own density.
    pub fn sample_bounds(&self, film: DVec2, u: DVec2) -> Option<PupilSample> {
        let r = film.length();
        let k = self.interval(r)?;
        if let Some(d) = self.cell_domain(film) {
            let p = d.sample(u)?;
            return Some(PupilSample { point: DVec3::new(p.x, p.y, self.rear_z_mm), pdf_area: 1.0 / d.area() });
        }
        let b = self.boxes[k];
        if b.is_empty() {
            return None;
        }
        let (q, area) = match (&self.outlines[k], self.union_only) {
            (Some(o), false) if o.drift_per_mm != 0.0 => (o.sample(u) + o.shift(r), o.area),
            (Some(o), false) => (o.sample(u), o.area),
            _ => (b.min + (b.max - b.min) * u, b.area()),
        };
        let p = if self.union_only || r == 0.0 {
            q
        } else {
            let (s, c) = (film.y / r, film.x / r);
            DVec2::new(c * q.x - s * q.y, s * q.x + c * q.y)
        };
        Some(PupilSample { point: DVec3::new(p.x, p.y, self.rear_z_mm), pdf_area: 1.0 / area })
    }
}

/// The radius (mm) of a disc about the axis on the rear vertex's plane that holds the crossing
/// of every ray that passes `lens` from a film point within `max_film_radius_mm` of the axis and
/// no nearer the lens than `film_z_mm − film_dz_mm`. No tracing: such a ray meets the last
/// surface inside its clear aperture, at a point s of a region bounded by a polar grid of the
/// aperture (radius `R_s`, z in `[z_lo, z_hi]`, with the element's placement); from film point
/// f the ray reaches the rear plane at `s + (λ − 1)(s − f)` with
/// `|λ − 1| = |s_z − z_rear| / (f_z − s_z)`, so the crossing lies within
/// `R_s + (R_s + r_film) · max|s_z − z_rear| / (f_z,min − z_hi)`. The grid's region is grown by
/// 1 % of the aperture (a sag between grid points). None when the film can come nearer than
/// the surface (no such disc).
pub fn defensive_radius_mm(lens: &Lens, film_z_mm: f64, film_dz_mm: f64, max_film_radius_mm: f64) -> Option<f64> {
    let s = lens.surfaces().last()?;
    let rim = if s.is_stop { s.housing_semi_diameter_mm } else { s.semi_diameter_mm };
    // 1. The clear aperture's extent in the lens frame: a polar grid of the surface.
    let (rings, spokes) = (32, 64);
    let (mut r_s, mut z_lo, mut z_hi) = (0.0f64, f64::INFINITY, f64::NEG_INFINITY);
    for i in 0..=rings {
        let r = rim * i as f64 / rings as f64;
        for j in 0..spokes {
            let phi = std::f64::consts::TAU * j as f64 / spokes as f64;
            let (x, y) = (r * phi.cos(), r * phi.sin());
            let sag = s.shape.sag(x, y)?;
            let p = DVec3::new(x, y, s.z_mm + sag);
            let p = s.placement.as_ref().map_or(p, |pl| pl.point_to_lens(p));
            r_s = r_s.max(DVec2::new(p.x, p.y).length());
            (z_lo, z_hi) = (z_lo.min(p.z), z_hi.max(p.z));
        }
    }
    let grow = 0.01 * rim;
    let (r_s, z_lo, z_hi) = (r_s + grow, z_lo - grow, z_hi + grow);
    // 2. The farthest crossing of the rear plane.
    let rear_z = lens.last_vertex_z_mm();
    let gap = film_z_mm - film_dz_mm.abs() - z_hi;
    if !(gap > 0.0) || !r_s.is_finite() {
        return None;
    }
    let dz = (z_hi - rear_z).abs().max((rear_z - z_lo).abs());
    let radius = r_s + (r_s + max_film_radius_mm) * dz / gap;
    (radius.is_finite() && radius > 0.0).then_some(radius)
}

/// The fine search's spacing (mm) for a lens whose rear grid (48 cells, as the bounds trace it)
/// finds fewer than [`NEAR_CHIEF_BELOW`] rays from the film's centre at `film_z_mm`: 1/16 of a
/// grid cell where it finds none, 1/4 where it finds a few; None where the grid resolves the
/// region (the module's "Lenses stopped down far").
fn near_chief_spacing_mm(lens: &Lens, film_z_mm: f64) -> Option<f64> {
    let half = 1.5 * lens.rear_semi_diameter_mm();
    let cell = 2.0 * half / 48.0;
    let rear_z = lens.last_vertex_z_mm();
    let (centre, origin) = (DVec3::new(0.0, 0.0, film_z_mm), [rear_z, -half, -half]);
    let mut passing = 0usize;
    for_each_passing(lens, lens.primary_wavelength_nm(), centre, origin, DVec2::splat(cell), 48, |_| passing += 1);
    let spacing = match passing {
        0 => cell * NEAR_CHIEF_REFINE,
        n if n < NEAR_CHIEF_BELOW => cell * NEAR_CHIEF_REFINE * 4.0,
        _ => return None,
    };
    // The region's paraxial size on the rear plane (the exit pupil's cone from the film's
    // centre, cut by the plane) sets the spacing where that is finer: a stop far smaller than
    // the grid's cell (f/2000 and beyond on double-gauss-50mm) keeps its points across.
    let p = lens.paraxial();
    let across_mm = p.exit_pupil_diameter_mm * ((film_z_mm - rear_z) / (film_z_mm - p.exit_pupil_z_mm)).abs();
    let scaled = across_mm / NEAR_CHIEF_POINTS_ACROSS;
    Some(if scaled.is_finite() && scaled > 0.0 { spacing.min(scaled) } else { spacing })
}

/// Whether the bounds are outlined per radial interval (a rotationally symmetric lens with a
/// round stop) rather than per film cell. A small stop (`near_chief`) on a tilted sensor whose
/// plane is known goes to the film cells, traced on the plane: its region is a speck that moves
/// with each film point's z as well as its radius, which one outline per radius cannot follow
/// (wide-22mm at f/32 tilted 5°: 82 % of the sampled rays absorbed, 11 % per film cell).
fn radially_outlined(lens: &Lens, film_dz_mm: f64, film_slope: Option<DVec2>, near_chief: bool) -> bool {
    let tilted = film_dz_mm > 0.0 && film_slope.is_some_and(|s| s != DVec2::ZERO);
    lens.is_rotationally_symmetric() && lens.aperture().is_circular() && !(near_chief && tilted)
}

/// The weights of [`Lens::trace_soft`] that count the stop's clearance only, for
/// [`passes_lens`]'s `stop_only`.
fn stop_only_weights(lens: &Lens) -> Vec<f64> {
    (0..lens.surfaces().len()).map(|i| if i == lens.stop_index() { 1.0 } else { 0.0 }).collect()
}

/// Whether `ray` from the film passes `lens` at `wl`; with `stop_only` ([`stop_only_weights`])
/// whether it passes the stop, the elements' rims ignored (the soft trace's clearance, weighting
/// the stop only, is non-negative exactly there).
fn passes_lens(lens: &Lens, ray: &Ray, wl: f64, stop_only: Option<&[f64]>) -> bool {
    match stop_only {
        Some(weights) => lens.trace_soft(ray, wl, TraceDirection::FilmToScene, weights).is_ok_and(|(_, c)| c >= 0.0),
        None => lens.trace_detailed(ray, wl, TraceDirection::FilmToScene, StopMode::Apply).is_ok(),
    }
}

/// Calls `pass` with every point of a `grid`² grid of cells `cell` on the rear plane (z, and the
/// grid's lower corner: `[rear_z, x0, y0]`; points at the cells' centres) whose ray from film
/// point `fp` passes the lens at `wl`.
fn for_each_passing(
    lens: &Lens,
    wl: f64,
    fp: DVec3,
    origin: [f64; 3],
    cell: DVec2,
    grid: usize,
    pass: impl FnMut(DVec2),
) {
    for_each_passing_in(lens, wl, fp, origin, cell, grid, None, pass);
}

/// [`for_each_passing`] over the grid's points inside `window` only (all where None).
#[allow(clippy::too_many_arguments)]
fn for_each_passing_in(
    lens: &Lens,
    wl: f64,
    fp: DVec3,
    [rear_z, x0, y0]: [f64; 3],
    cell: DVec2,
    grid: usize,
    window: Option<Box2>,
    mut pass: impl FnMut(DVec2),
) {
    for i in 0..grid {
        for j in 0..grid {
            let q = DVec2::new(x0, y0) + cell * DVec2::new(i as f64 + 0.5, j as f64 + 0.5);
            if window.is_some_and(|w| !w.contains(q)) {
                continue;
            }
            let ray = Ray::new(fp, DVec3::new(q.x, q.y, rear_z) - fp);
            if lens.trace_detailed(&ray, wl, TraceDirection::FilmToScene, StopMode::Apply).is_ok() {
                pass(q);
            }
        }
    }
}

/// Film points whose passing region the rear grid cannot resolve (a lens stopped down far,
/// where the region is a speck of the grid's cell): calls `pass` with every point of a grid of
/// spacing `fine` centred on the chief ray's aim point (itself a grid point) whose ray from
/// `fp` passes the lens at `wl`. The grid starts at ±[`NEAR_CHIEF_HALF`] points and doubles
/// while passing points touch its edge, as long as it stays within `reach_mm` of the aim point
/// (a larger region the coarse grid resolves itself). Nothing when the chief ray cannot be
/// aimed. Returns the grid's window (the box of its points) when the passing region lies
/// inside it (none of its rim points passes), else None.
fn for_each_passing_near_chief(
    lens: &Lens,
    wl: f64,
    fp: DVec3,
    [rear_z, fine, reach_mm]: [f64; 3],
    mut pass: impl FnMut(DVec2),
) -> Option<Box2> {
    let aim = chief_aim_from_film(lens, fp, wl)?;
    let mut h = NEAR_CHIEF_HALF;
    loop {
        // 1. The (2h + 1)² grid about the aim point; note whether its rim holds passing points.
        let mut found = Vec::new();
        let mut touches_rim = false;
        for i in 0..=2 * h {
            for j in 0..=2 * h {
                let q = aim + fine * DVec2::new(i as f64 - h as f64, j as f64 - h as f64);
                let ray = Ray::new(fp, DVec3::new(q.x, q.y, rear_z) - fp);
                if lens.trace_detailed(&ray, wl, TraceDirection::FilmToScene, StopMode::Apply).is_ok() {
                    found.push(q);
                    touches_rim |= i == 0 || j == 0 || i == 2 * h || j == 2 * h;
                }
            }
        }
        // 2. Done when the region lies inside, or the grid has grown as far as it may.
        if !touches_rim || (2 * h) as f64 * fine > reach_mm {
            found.into_iter().for_each(&mut pass);
            let half = DVec2::splat(h as f64 * fine);
            return (!touches_rim).then_some(Box2 { min: aim - half, max: aim + half });
        }
        h *= 2;
    }
}

/// The outline of the passing region over film points `film_pts` (on the +x half-plane's axis),
/// about `centre`, inside the box `b`; None when the region is not star-shaped about `centre`
/// for some film point (the centre does not pass), or degenerate. `tiny` (a lens stopped down
/// beyond what the rear grid resolves): about a centre that slides with the film radius, on the
/// line through the chief rays' aim points of the first and last film points.
fn outline_of(
    lens: &Lens,
    [wl, rear_z]: [f64; 2],
    b: Box2,
    film_pts: &[DVec3],
    centre: DVec2,
    ends: &[f64],
    tiny: bool,
) -> Option<Outline> {
    // Every fourth film point and the last (the interval's ends are first and last): the region
    // moves smoothly with the film radius, and the growth covers the points between.
    let stride = (film_pts.len() / 4).max(1);
    let mut chosen: Vec<DVec3> = film_pts.iter().step_by(stride).copied().collect();
    if !(film_pts.len() - 1).is_multiple_of(stride) {
        chosen.extend(film_pts.last());
    }
    if tiny {
        // The centre at film radius r: a + slope · r, from the chief rays of the interval's ends.
        let (first, last) = (*chosen.first()?, *chosen.last()?);
        let (a0, a1) = (chief_aim_from_film(lens, first, wl)?, chief_aim_from_film(lens, last, wl)?);
        let slope = if last.x > first.x { (a1.x - a0.x) / (last.x - first.x) } else { 0.0 };
        let at_axis = a0.x - slope * first.x;
        let centre_of = move |fp: DVec3| Some(DVec2::new(at_axis + slope * fp.x, 0.0));
        let radii = outline_radii(lens, [wl, rear_z], b, &chosen, &centre_of, true, ends, false)?;
        return Outline::new(DVec2::new(at_axis, 0.0), radii).map(|o| Outline { drift_per_mm: slope, ..o });
    }
    // The region is mirror-symmetric about the x axis.
    let radii = outline_radii(lens, [wl, rear_z], b, &chosen, &|_| Some(centre), true, ends, false)?;
    Outline::new(centre, radii)
}

/// The grown radii of an outline of the passing region over film points `film_pts`, each point's
/// region taken about its own centre `centre_of(point)`, inside the box `b`, at
/// [`OUTLINE_ANGLES`] angles (only the upper half traced when `mirror`: the region is symmetric
/// about the x axis). None when some film point's centre is missing or absorbed (the region is
/// not star-shaped about it). `stop_only`: of the region that passes the stop, the elements'
/// rims ignored (at the rim of the image circle the passing region is that one, cut by rims).
#[allow(clippy::too_many_arguments)]
fn outline_radii(
    lens: &Lens,
    [wl, rear_z]: [f64; 2],
    b: Box2,
    film_pts: &[DVec3],
    centre_of: &(dyn Fn(DVec3) -> Option<DVec2> + Sync),
    mirror: bool,
    extra_wavelengths: &[f64],
    stop_only: bool,
) -> Option<Vec<f64>> {
    const MARCH: usize = 8;
    const BISECT: usize = 10;
    /// Strides past the primary wavelength's radius, as shares of the way to the box's edge.
    const SPECTRAL_STEPS: [f64; 5] = [0.015, 0.03, 0.06, 0.12, 0.24];
    let weights = stop_only.then(|| stop_only_weights(lens));
    let passes_at = |fp: DVec3, q: DVec2, wl: f64| {
        passes_lens(lens, &Ray::new(fp, DVec3::new(q.x, q.y, rear_z) - fp), wl, weights.as_deref())
    };
    let passes = |fp: DVec3, q: DVec2| passes_at(fp, q, wl);
    let centres: Vec<DVec2> = film_pts.iter().map(|&fp| centre_of(fp)).collect::<Option<_>>()?;
    if !film_pts.iter().zip(&centres).all(|(&fp, &c)| passes(fp, c)) {
        return None;
    }
    let n = OUTLINE_ANGLES;
    let traced = if mirror { n / 2 + 1 } else { n };
    let half: Vec<f64> = (0..traced)
        .map(|k| {
            let phi = std::f64::consts::TAU * k as f64 / n as f64;
            let dir = DVec2::new(phi.cos(), phi.sin());
            let mut r_max = 0.0f64;
            for (&fp, &centre) in film_pts.iter().zip(&centres) {
                // distance from the centre to the box's edge along dir
                let exit = |lo: f64, hi: f64, c: f64, d: f64| {
                    if d > 1e-12 {
                        (hi - c) / d
                    } else if d < -1e-12 {
                        (lo - c) / d
                    } else {
                        f64::INFINITY
                    }
                };
                let t_far =
                    exit(b.min.x, b.max.x, centre.x, dir.x).min(exit(b.min.y, b.max.y, centre.y, dir.y)).max(0.0);
                // 1. March out to the last passing step; 2. bisect towards the failing side.
                let mut last = 0usize;
                for i in 1..=MARCH {
                    if passes(fp, centre + dir * (t_far * i as f64 / MARCH as f64)) {
                        last = i;
                    }
                }
                let r = if last == MARCH {
                    t_far
                } else {
                    let (mut lo, mut hi) =
                        (t_far * last as f64 / MARCH as f64, t_far * (last + 1) as f64 / MARCH as f64);
                    for _ in 0..BISECT {
                        let mid = 0.5 * (lo + hi);
                        if passes(fp, centre + dir * mid) {
                            lo = mid;
                        } else {
                            hi = mid;
                        }
                    }
                    hi
                };
                // 3. The spectral range's ends (dispersive lenses): the region shifts with the
                //    wavelength, so step on past r in growing strides, then bisect the last gap.
                let mut r = r;
                for &wl_end in extra_wavelengths {
                    let pass_end = |t: f64| passes_at(fp, centre + dir * t, wl_end);
                    let mut gap = None;
                    for (i, f) in SPECTRAL_STEPS.iter().enumerate() {
                        if pass_end(r + f * t_far) {
                            gap = Some(i);
                        }
                    }
                    if let Some(i) = gap {
                        let (mut lo, mut hi) = (r + SPECTRAL_STEPS[i] * t_far, r + SPECTRAL_STEPS[i] * t_far * 2.0);
                        for _ in 0..BISECT / 2 {
                            let mid = 0.5 * (lo + hi);
                            if pass_end(mid) {
                                lo = mid;
                            } else {
                                hi = mid;
                            }
                        }
                        r = hi;
                    }
                }
                r_max = r_max.max(r);
            }
            r_max
        })
        .collect();
    let radii: Vec<f64> =
        if mirror { (0..n).map(|k| half[if k <= n / 2 { k } else { n - k }]).collect() } else { half };
    // Film cells (bladed and masked stops, lenses without symmetry): corners between two
    // directions (a blade's, an element rim's crossing) are raised so that the chord between
    // them holds the corner a convex region could have there. (The radial outlines of round
    // stops on symmetric lenses, smooth regions, keep their radii: no brute-force run found a
    // passing ray outside them.)
    let (radii, growth) = if mirror { (radii, OUTLINE_GROWTH) } else { (with_corners(&radii), CELL_OUTLINE_GROWTH) };
    // Grown: each vertex takes its neighbours' radius too (a chord cannot cut the region), plus
    // a share of the largest radius.
    let largest = radii.iter().cloned().fold(0.0, f64::max);
    Some((0..n).map(|k| radii[(k + n - 1) % n].max(radii[k]).max(radii[(k + 1) % n]) + growth * largest).collect())
}

/// Outline radii (vertex k at angle 2πk/n) raised for the corners a convex region may have
/// between two vertices: between directions k and k + 1 its boundary stays inside the lines
/// through the boundary points k − 1, k and k + 2, k + 1, which meet at the farthest such corner.
/// Where they meet inside the sector, no further than a quarter beyond the two radii, both
/// vertices are scaled until their chord passes through that point (a bladed stop's corners
/// reach up to 2 % past the chord of 64 directions; the growth alone did not always cover it).
fn with_corners(radii: &[f64]) -> Vec<f64> {
    let n = radii.len();
    let dir = |k: usize| {
        let phi = std::f64::consts::TAU * k as f64 / n as f64;
        DVec2::new(phi.cos(), phi.sin())
    };
    let point = |k: usize| dir(k % n) * radii[k % n];
    let cross = |a: DVec2, b: DVec2| a.x * b.y - a.y * b.x;
    let mut out = radii.to_vec();
    for k in 0..n {
        let (a0, a1, b1, b0) = (point(k + n - 1), point(k), point(k + 1), point(k + 2));
        // 1. The two lines' meeting point x = a1 + t (a1 − a0).
        let (da, db) = (a1 - a0, b1 - b0);
        let den = cross(da, db);
        if den.abs() < 1e-12 {
            continue;
        }
        let t = cross(b1 - a1, db) / den;
        if !(t > 0.0) {
            continue;
        }
        let x = a1 + da * t;
        // 2. Inside the sector and not far out.
        let (u0, u1) = (dir(k), dir((k + 1) % n));
        if cross(u0, x) < 0.0 || cross(x, u1) < 0.0 || x.length() > 1.25 * radii[k].max(radii[(k + 1) % n]) {
            continue;
        }
        // 3. The chord's distance along x's direction, and the scale that brings it out to x.
        let dx = x.normalize();
        let den = cross(dx, b1 - a1);
        if den.abs() < 1e-12 {
            continue;
        }
        let along = cross(a1, b1 - a1) / den;
        if along > 0.0 && x.length() > along {
            let s = x.length() / along;
            out[k] = out[k].max(radii[k] * s);
            out[(k + 1) % n] = out[(k + 1) % n].max(radii[(k + 1) % n] * s);
        }
    }
    out
}

/// The chief ray from film point `film` (lens frame, x, y, z): the ray through the centre of
/// the stop, found by secant iteration on the aim point. Returns the ray leaving the front, or
/// `None` if the chief ray is vignetted or cannot be aimed.
pub fn chief_ray_from_film(lens: &Lens, film: DVec3, wavelength_nm: f64) -> Option<Ray> {
    let aim = chief_aim_from_film(lens, film, wavelength_nm)?;
    let aim = DVec3::new(aim.x, aim.y, lens.last_vertex_z_mm());
    lens.trace(&Ray::new(film, aim - film), wavelength_nm, TraceDirection::FilmToScene).map(|t| t.ray)
}

/// Where the chief ray from film point `film` (the ray through the centre of the stop, element
/// rims ignored) crosses the plane of the rear vertex; `None` if it cannot be aimed. The ray
/// itself may still be vignetted by an element.
pub fn chief_aim_from_film(lens: &Lens, film: DVec3, wavelength_nm: f64) -> Option<DVec2> {
    let radial = radial_chief_aim(lens, film, wavelength_nm);
    if lens.is_rotationally_symmetric() {
        return radial;
    }
    // Without rotational symmetry (cylindrical or decentred elements) the chief ray leaves the
    // film point's radial plane: Newton's method on both coordinates of the aim, from the
    // radial solution (or the paraxial guess).
    let start = radial.or_else(|| paraxial_aim(lens, film))?;
    let rear_z = lens.last_vertex_z_mm();
    let crossing =
        |a: DVec2| stop_crossing_from_film(lens, &Ray::new(film, DVec3::new(a.x, a.y, rear_z) - film), wavelength_nm);
    let h = 1e-6 * lens.rear_semi_diameter_mm().max(1e-3);
    let (mut a, mut g) = (start, crossing(start)?);
    for _ in 0..30 {
        if g.length() < 1e-12 {
            break;
        }
        // 1. The Jacobian by forward differences, 2. the Newton step J·d = −g.
        let (jx, jy) = ((crossing(a + DVec2::X * h)? - g) / h, (crossing(a + DVec2::Y * h)? - g) / h);
        let det = jx.x * jy.y - jy.x * jx.y;
        if !(det.abs() > 1e-300) {
            return None;
        }
        a += DVec2::new((jy.x * g.y - jy.y * g.x) / det, (jx.y * g.x - jx.x * g.y) / det);
        g = crossing(a)?;
    }
    (g.length() <= 1e-9).then_some(a)
}

/// The paraxial guess at the chief ray's aim point on the rear vertex's plane: toward the exit
/// pupil's centre.
fn paraxial_aim(lens: &Lens, film: DVec3) -> Option<DVec2> {
    let dz = film.z - lens.last_vertex_z_mm();
    let to_xp = film.z - lens.paraxial().exit_pupil_z_mm;
    let scale = if to_xp.abs() > 1e-9 { 1.0 - dz / to_xp } else { 0.0 };
    let aim = DVec2::new(film.x, film.y) * scale;
    aim.is_finite().then_some(aim)
}

/// [`chief_aim_from_film`] in the film point's radial plane (the chief ray of a rotationally
/// symmetric lens lies in it): secant iterations on the aim radius.
fn radial_chief_aim(lens: &Lens, film: DVec3, wavelength_nm: f64) -> Option<DVec2> {
    let rear_z = lens.last_vertex_z_mm();
    let p = lens.paraxial();
    let dz = film.z - rear_z;
    // 1. Paraxial first guess: aim at the exit pupil centre.
    let to_xp = film.z - p.exit_pupil_z_mm;
    let scale = if to_xp.abs() > 1e-9 { 1.0 - dz / to_xp } else { 0.0 };
    let radial = DVec2::new(film.x, film.y);
    let r = radial.length();
    let dir2 = if r > 0.0 { radial / r } else { DVec2::X };
    let stop_offset = |s: f64| -> Option<f64> {
        let aim = DVec3::new(dir2.x * s, dir2.y * s, rear_z);
        stop_crossing_from_film(lens, &Ray::new(film, aim - film), wavelength_nm).map(|p| p.dot(dir2))
    };
    // 2. Secant iterations on the aim radius.
    let mut s0 = r * scale;
    let mut f0 = stop_offset(s0)?;
    let mut s1 = s0 + 1e-3 * lens.rear_semi_diameter_mm().max(1e-3);
    let mut f1 = stop_offset(s1)?;
    for _ in 0..50 {
        if f1.abs() < 1e-12 {
            break;
        }
        let denom = f1 - f0;
        if denom.abs() < 1e-300 {
            return None;
        }
        let s2 = s1 - f1 * (s1 - s0) / denom;
        s0 = s1;
        f0 = f1;
        s1 = s2;
        f1 = stop_offset(s1)?;
    }
    if f1.abs() > 1e-9 {
        return None;
    }
    Some(dir2 * s1)
}

/// Real field angle (degrees) seen by film point (x, y) on the film plane at `film_z_mm`: the
/// angle of its chief ray in object space; `None` outside the image circle (no chief ray).
pub fn field_angle_deg(lens: &Lens, film_x_mm: f64, film_y_mm: f64, film_z_mm: f64) -> Option<f64> {
    let film = DVec3::new(film_x_mm, film_y_mm, film_z_mm);
    chief_ray_from_film(lens, film, lens.primary_wavelength_nm())
        .map(|ray| (-ray.direction.z).clamp(-1.0, 1.0).acos().to_degrees())
}

/// Radius of the image circle on the film plane at `film_z_mm`: the largest film radius whose
/// chief ray passes (searched up to `max_mm`).
pub fn image_circle_radius_mm(lens: &Lens, film_z_mm: f64, max_mm: f64) -> f64 {
    let ok = |r: f64| field_angle_deg(lens, r, 0.0, film_z_mm).is_some();
    if ok(max_mm) {
        return max_mm;
    }
    // scan, then bisect the first failure (vignetting can be non-monotonic near the edge)
    let steps = 64;
    let mut lo = 0.0;
    for k in 1..=steps {
        let r = max_mm * k as f64 / steps as f64;
        if ok(r) {
            lo = r;
        } else {
            let mut hi = r;
            for _ in 0..40 {
                let mid = 0.5 * (lo + hi);
                if ok(mid) {
                    lo = mid
                } else {
                    hi = mid
                }
            }
            return lo;
        }
    }
    lo
}

/// Where a ray from the film crosses the stop surface (in the stop's own frame, misaligned
/// elements placed), ignoring every clear aperture (for aiming: the rim of an element behind
/// the stop must not stop the search).
fn stop_crossing_from_film(lens: &Lens, ray: &Ray, wavelength_nm: f64) -> Option<DVec2> {
    let mut o = ray.origin;
    let mut d = ray.direction;
    for i in (lens.stop_index()..lens.surfaces().len()).rev() {
        let s = &lens.surfaces()[i];
        // (a misaligned element's surfaces in its own frame, as the trace has them)
        if let Some(pl) = &s.placement {
            o = pl.point_to_element(o);
            d = pl.rotation.transpose() * d;
        }
        let local = DVec3::new(o.x, o.y, o.z - s.z_mm);
        let t = s.shape.intersect(local, d)?;
        let p = local + t * d;
        if i == lens.stop_index() {
            return Some(DVec2::new(p.x, p.y));
        }
        let (n1, n2) = (lens.index_after(i, wavelength_nm), lens.index_before(i, wavelength_nm));
        if n1 != n2 {
            d = super::surface::refract(d, s.shape.normal(p)?, n1, n2)?;
        }
        o = DVec3::new(p.x, p.y, p.z + s.z_mm);
        if let Some(pl) = &s.placement {
            o = pl.point_to_lens(o);
            d = pl.rotation * d;
        }
    }
    None
}
