//! Lens ray transfer function (LRTF): the lens's film → scene ray map sampled into a table and
//! evaluated in O(1) instead of tracing every surface.
//!
//! A ray from the film meets the *input dome*, a hemisphere over the rear element (base on the
//! rear element's film-most point, radius just over its clear semi-diameter; a flatter
//! spherical cap when the film sits too close for a hemisphere). Its key is (u, σx, σy):
//! u = ρ/R is the radial position of that point, and σ = s/s_max the
//! stereographic projection s = (dx, dy)/(1 − dz) of its direction, taken in the frame rotated
//! so that the point lies on +x. Rotational symmetry reduces the 4-D ray space to these three
//! axes (and the mirror symmetry y → −y halves σy). Each entry stores where the ray leaves the
//! *output sphere* around the front element (its stereographic coordinates w, seen from the
//! film-side pole), its outgoing direction (stereographic e, beyond the unit disc for fisheye
//! rays that leave backwards), where it crossed the stop plane, and a signed margin: the
//! smallest relative distance to any element rim (negative when a rim clips the ray). Tables
//! are baked with the stop open, so any stop size and shape applies at lookup from the stored
//! stop crossing; the margin, interpolated, decides vignetting by the rims.
//!
//! Lookup runs in f32 without trigonometry (the key's rotation uses the dome point's
//! (x, y)/ρ; each stereographic map costs one division), reads a cell's eight corners as four
//! σy-adjacent pairs of 32-byte entries (columns padded to whole cache lines) and blends them
//! as 4-lane vectors. The file stores the same entries (format version 1).
//!
//! | name | type | unit | default |
//! |---|---|---|---|
//! | `resolution` | u32: samples along u and σx (σy gets resolution/2 + 1) | — | 96 |
//! | `max_film_radius_mm` | f64: film points covered | mm | 30 |
//! | `min_film_distance_mm` | f64: nearest film plane behind the input dome | mm | the lens's back focal length − 5 |
//! | `wavelengths_nm` | list of f64: one table each (one for lenses without dispersion) | nm | primary |

use super::lens::{Lens, Ray};
use super::surface::refract;
use crate::error::{Error, Result};
use glam::{DVec2, DVec3, Vec4};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::Path;

/// File magic.
const MAGIC: &[u8; 8] = b"PZLRTF\0\0";
/// File format version.
pub const LRTF_VERSION: u32 = 2;
/// A cell that a rim boundary crosses is traced exactly where its interpolated margin lies within
/// this many times the cell's non-linearity of zero. The non-linearity is the spread of the
/// corners' margin over the cell's four diagonals (m₀₀₀ + m₁₁₁, m₁₀₀ + m₀₁₁, …), which are
/// equal for a margin linear in the cell: it is large where two rims trade the minimum (a kink
/// that trilinear interpolation rounds off) and small where one rim clips smoothly, where the
/// interpolated margin is accurate. Measured at 96³ on camera rays (400 000 per lens; the
/// share traced exactly, then the rays whose rim classification is wrong), against the
/// earlier band of a tenth of the corners' margin spread:
/// double-gauss-50mm 1.59 %, 0.038 % (band: 2.92 %, 0.055 %); nikon-normal-52mm 1.31 %,
/// 0.002 % (2.98 %, 0.018 %); wide-22mm 5.49 %, 0.006 % (6.90 %, 0.014 %); fisheye-10mm 6.58 %,
/// 0.118 % (5.03 %, 0.382 %). At 1.0: 1.31 %, 0.054 % on double-gauss-50mm.
const BOUNDARY_NONLINEARITY: f32 = 1.25;
/// Channels per entry: w.x, w.y, e.x, e.y, stop.x, stop.y, margin, validity.
const CHANNELS: usize = 8;

/// Largest magnitude of a stored table value. Baked tables stay below ~2·10¹¹ (extrapolated
/// entries of failed traces; double-gauss-50mm 1.3·10¹⁰, wide-22mm 1.8·10¹¹); the lookup squares
/// stereographic coordinates in f32, which overflows past ~10¹⁹ and turns lookups into NaN.
const MAX_ENTRY: f32 = 1e15;

/// Everything about a table except its data.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct LrtfHeader {
    /// Format version.
    pub version: u32,
    /// Name of the lens it was baked for.
    pub lens_name: String,
    /// Hash of that lens's prescription (FNV-1a 64 of its TOML).
    pub lens_hash: u64,
    /// Samples along u and σx.
    pub resolution: u32,
    /// Samples along |σy|.
    pub resolution_y: u32,
    /// One table per wavelength.
    pub wavelengths_nm: Vec<f64>,
    /// Input dome: the cap of a sphere over the rear element; z of its base plane (the rear
    /// element's film-most point).
    pub in_base_z_mm: f64,
    /// Radius of the dome's base circle (just over the rear clear semi-diameter).
    pub in_base_radius_mm: f64,
    /// Centre z of the dome's sphere.
    pub in_centre_z_mm: f64,
    /// Radius of the dome's sphere (equal to the base radius for a hemisphere; larger for a
    /// flatter cap when the film sits close to the lens).
    pub in_radius_mm: f64,
    /// Half-width of the σ domain in stereographic units.
    pub s_max: f64,
    /// Output sphere centre z.
    pub out_centre_z_mm: f64,
    /// Output sphere radius.
    pub out_radius_mm: f64,
    /// Film radius the table covers.
    pub max_film_radius_mm: f64,
    /// Nearest film distance behind the dome centre the table covers.
    pub min_film_distance_mm: f64,
    /// FNV-1a 64 of the table data as stored (little-endian f32s after the header); set by
    /// [`LrtfTable::save`], checked by [`LrtfTable::load`] (format version 2).
    pub data_checksum: u64,
}

/// The largest LRTF file read (8 GiB; a 256³ table of one wavelength is 0.5 GiB): only regular
/// files are read, so a device or pipe named as a table is refused instead of read without bound.
pub const MAX_TABLE_FILE_BYTES: u64 = 8 << 30;

impl LrtfHeader {
    /// The checks every table passes before it is written and after it is read: sizes in range,
    /// geometry finite and positive where it must be, wavelengths visible.
    fn check(&self) -> std::result::Result<(), String> {
        let (n, ny, nw) = (self.resolution as usize, self.resolution_y as usize, self.wavelengths_nm.len());
        if n < 2 || ny < 2 || nw == 0 || n > 4096 || ny > 4096 || nw > 64 {
            return Err(format!("implausible table size in the header ({nw} wavelengths × {n}² × {ny})"));
        }
        if let Some(w) = self.wavelengths_nm.iter().find(|w| !(w.is_finite() && (300.0..=1000.0).contains(*w))) {
            return Err(format!("wavelength {w} nm in the header is outside 300..1000 nm"));
        }
        for (field, v, positive) in [
            ("in_base_z_mm", self.in_base_z_mm, false),
            ("in_base_radius_mm", self.in_base_radius_mm, true),
            ("in_centre_z_mm", self.in_centre_z_mm, false),
            ("in_radius_mm", self.in_radius_mm, true),
            ("s_max", self.s_max, true),
            ("out_centre_z_mm", self.out_centre_z_mm, false),
            ("out_radius_mm", self.out_radius_mm, true),
            ("max_film_radius_mm", self.max_film_radius_mm, true),
            ("min_film_distance_mm", self.min_film_distance_mm, true),
        ] {
            if !v.is_finite() || (positive && !(v > 0.0)) {
                return Err(format!(
                    "header field {field} = {v} must be finite{}",
                    if positive { " and positive" } else { "" }
                ));
            }
        }
        Ok(())
    }
}

/// A baked table.
///
/// In memory the entries are 32-byte pairs of 4-lane vectors, two to a 64-byte line, each
/// (u, σx) column padded to whole lines: a cell's eight corners are four σy-adjacent pairs.
/// (Storing every entry twice, so each pair is exactly one line, measured no faster: lookups
/// of large tables are bound by cache misses, and doubling the memory adds misses.)
#[derive(Debug, Clone)]
pub struct LrtfTable {
    /// Header.
    pub header: LrtfHeader,
    lines: Vec<Line>,
    key: Key,
}

/// One entry: (w.x, w.y, e.x, e.y) and (stop.x, stop.y, margin, validity).
type Entry = [Vec4; 2];

/// Two consecutive entries of a column, aligned to a cache line.
#[derive(Debug, Clone, Copy, Default)]
#[repr(C, align(64))]
struct Line([Entry; 2]);

/// Constants of the lookup's key computation (f32, relative to the input dome's centre).
#[derive(Debug, Clone, Copy)]
struct Key {
    in_centre_z: f64,
    in_radius_sq: f32,
    /// Lowest z of the dome (its base plane), relative to its centre.
    base_dz: f32,
    /// u → cells.
    scale_u: f32,
    /// σx → cells: fx = sx·scale_x + half.
    scale_x: f32,
    half: f32,
    /// |σy| → cells.
    scale_y: f32,
    /// Largest cell coordinate along u and σx, and along σy.
    max_x: f32,
    max_y: f32,
    n: usize,
    ny: usize,
    /// Index of the last cell along u and σx, and along σy.
    last_cell: i32,
    last_cell_y: i32,
    /// Entry strides along σx (the column, padded to an even count), u and wavelength.
    stride_x: usize,
    stride_u: usize,
    stride_w: usize,
    out_centre_z: f64,
    out_radius: f32,
}

impl Key {
    fn new(h: &LrtfHeader) -> Key {
        let (n, ny) = (h.resolution as usize, h.resolution_y as usize);
        Key {
            in_centre_z: h.in_centre_z_mm,
            in_radius_sq: (h.in_radius_mm * h.in_radius_mm) as f32,
            base_dz: (h.in_base_z_mm - h.in_centre_z_mm - 1e-9) as f32,
            scale_u: ((n - 1) as f64 / h.in_base_radius_mm) as f32,
            scale_x: (0.5 * (n - 1) as f64 / h.s_max) as f32,
            half: (0.5 * (n - 1) as f64) as f32,
            scale_y: ((ny - 1) as f64 / h.s_max) as f32,
            max_x: (n - 1) as f32,
            max_y: (ny - 1) as f32,
            n,
            ny,
            last_cell: n as i32 - 2,
            last_cell_y: ny as i32 - 2,
            stride_x: ny + ny % 2,
            stride_u: n * (ny + ny % 2),
            stride_w: n * n * (ny + ny % 2),
            out_centre_z: h.out_centre_z_mm,
            out_radius: h.out_radius_mm as f32,
        }
    }
}

/// Σ_k w[k]·e[k][c]: half `c` of the eight corner entries, weighted (a function, not a
/// closure, so that it is inlined).
#[inline(always)]
fn blend(e: &[&Entry; 8], w: &[f32; 8], c: usize) -> Vec4 {
    ((e[0][c] * w[0] + e[1][c] * w[1]) + (e[2][c] * w[2] + e[3][c] * w[3]))
        + ((e[4][c] * w[4] + e[5][c] * w[5]) + (e[6][c] * w[6] + e[7][c] * w[7]))
}

/// The instruction set the LRTF lookup runs with on this CPU.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SimdLevel {
    /// The build's baseline (SSE2 on x86-64).
    Baseline,
    /// x86-64 with AVX2 and FMA.
    Avx2Fma,
}

/// Detected once per process; `PETZVAL_SIMD=baseline` forces the baseline.
static SIMD_LEVEL: std::sync::LazyLock<SimdLevel> = std::sync::LazyLock::new(|| {
    if std::env::var("PETZVAL_SIMD").is_ok_and(|v| v == "baseline") {
        return SimdLevel::Baseline;
    }
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma") {
        return SimdLevel::Avx2Fma;
    }
    SimdLevel::Baseline
});

/// The instruction set [`LrtfTable::lookup`] uses on this CPU (detected at its first call).
pub fn simd_level() -> SimdLevel {
    *SIMD_LEVEL
}

/// [`blend`] of both halves at once, in 8-lane AVX operations: each lane's products and sums
/// in [`blend`]'s order (no fused operations), so the result is bit-identical to it.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
fn blend_both_avx(e: &[&Entry; 8], w: &[f32; 8]) -> (Vec4, Vec4) {
    use std::arch::x86_64::{_mm256_add_ps, _mm256_loadu_ps, _mm256_mul_ps, _mm256_set1_ps, _mm256_storeu_ps};
    // an entry's two Vec4s are 8 contiguous f32s
    let term = |k: usize| {
        // SAFETY: `Entry` is `[Vec4; 2]`, 32 contiguous bytes.
        let v = unsafe { _mm256_loadu_ps(e[k].as_ptr() as *const f32) };
        _mm256_mul_ps(v, _mm256_set1_ps(w[k]))
    };
    let s01 = _mm256_add_ps(term(0), term(1));
    let s23 = _mm256_add_ps(term(2), term(3));
    let s45 = _mm256_add_ps(term(4), term(5));
    let s67 = _mm256_add_ps(term(6), term(7));
    let sum = _mm256_add_ps(_mm256_add_ps(s01, s23), _mm256_add_ps(s45, s67));
    let mut out = [0.0f32; 8];
    // SAFETY: `out` holds 8 f32s.
    unsafe { _mm256_storeu_ps(out.as_mut_ptr(), sum) };
    (Vec4::new(out[0], out[1], out[2], out[3]), Vec4::new(out[4], out[5], out[6], out[7]))
}

/// Rays per [`LrtfTable::lookup_batch`].
pub const LRTF_BATCH: usize = 8;

/// A ray's cell: the entry indices of its four σy-adjacent corner pairs and the interpolation
/// weights along (u, σx, σy).
#[derive(Debug, Clone, Copy, Default)]
struct Cell {
    idx: [usize; 4],
    t: [f32; 3],
}

/// The keys of `N` rays as a structure of arrays, one lane per ray (so that the batched lookup
/// runs its lanes as vectors): cell coordinates along (u, σx, σy), the key frame's rotation,
/// the mirror of σy, and whether the ray missed the input dome or left the baked domain.
#[derive(Debug, Clone, Copy)]
struct Keys<const N: usize> {
    f: [[f32; N]; 3],
    cs: [f32; N],
    sn: [f32; N],
    /// −1 where σy was mirrored, else 1.
    sign: [f32; N],
    missed: [bool; N],
    inside: [bool; N],
}

/// What a lookup returns.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LrtfRay {
    /// The ray leaving the lens (lens frame; origin on the output sphere).
    pub ray: Ray,
    /// Where it crossed the stop plane.
    pub stop_point: DVec2,
    /// Interpolated rim margin (> 0: passes every rim).
    pub margin: f64,
}

/// The outcome of a lookup.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LrtfLookup {
    /// Every corner of the cell passes: the interpolated ray.
    Hit(LrtfRay),
    /// Every corner is clipped (or the ray misses the input dome).
    Miss,
    /// The cell straddles a vignetting boundary or a failed entry: trace exactly.
    Uncertain,
}

/// FNV-1a 64 of table entries as stored (little-endian f32s).
fn data_checksum(data: &[f32]) -> u64 {
    fnv1a64_bytes(data.iter().flat_map(|v| v.to_le_bytes()))
}

/// FNV-1a 64-bit hash (stable across builds, unlike `std`'s hasher).
pub fn fnv1a64(bytes: &[u8]) -> u64 {
    fnv1a64_bytes(bytes.iter().copied())
}

/// FNV-1a 64 over a byte stream.
fn fnv1a64_bytes(bytes: impl Iterator<Item = u8>) -> u64 {
    bytes.fold(0xcbf2_9ce4_8422_2325, |h, b| (h ^ b as u64).wrapping_mul(0x0100_0000_01b3))
}

/// The hash identifying a lens's optics (its prescription).
pub fn lens_hash(lens: &Lens) -> u64 {
    fnv1a64(super::prescription::to_toml(lens.prescription()).as_bytes())
}

/// Stereographic projection of a unit vector from the +z pole.
#[inline]
fn stereo(v: DVec3) -> DVec2 {
    let k = 1.0 / (1.0 - v.z).max(1e-12);
    DVec2::new(v.x * k, v.y * k)
}

/// Inverse of [`stereo`].
#[inline]
fn unstereo(s: DVec2) -> DVec3 {
    let s2 = s.length_squared();
    let k = 1.0 / (1.0 + s2);
    DVec3::new(2.0 * s.x * k, 2.0 * s.y * k, (s2 - 1.0) * k)
}

/// Result of an unclipped trace.
struct Unclipped {
    /// The ray leaving the front, when the trace got through every surface.
    ray: Option<Ray>,
    /// Where it crossed the stop.
    stop: DVec2,
    /// Smallest relative distance to a rim seen so far (negative: clipped). When the trace
    /// fails (missed surface, TIR) after a rim already clipped it, this stays a smooth negative
    /// number, so interpolation across the vignetting boundary remains accurate; a failure with
    /// every rim passed so far (TIR inside the lens) is −1.
    margin: f64,
}

/// Exact film → scene trace that records, instead of clipping, the smallest relative distance
/// to a rim (clear aperture or stop housing), and where the ray crossed the stop.
fn trace_unclipped(lens: &Lens, ray: &Ray, wavelength_nm: f64) -> Unclipped {
    let mut o = ray.origin;
    let mut d = ray.direction;
    let mut margin = f64::INFINITY;
    let mut stop = DVec2::ZERO;
    let surfaces = lens.surfaces();
    let fail =
        |margin: f64, stop: DVec2| Unclipped { ray: None, stop, margin: if margin < 0.0 { margin } else { -1.0 } };
    for i in (0..surfaces.len()).rev() {
        let s = &surfaces[i];
        let local = DVec3::new(o.x, o.y, o.z - s.z_mm);
        let Some(t) = s.shape.intersect(local, d) else { return fail(margin, stop) };
        let p = local + t * d;
        let r = p.x.hypot(p.y);
        let rim = if s.is_stop { s.housing_semi_diameter_mm } else { s.semi_diameter_mm };
        margin = margin.min((rim - r) / rim);
        if s.is_stop {
            stop = DVec2::new(p.x, p.y);
        }
        let (n1, n2) = (lens.index_after(i, wavelength_nm), lens.index_before(i, wavelength_nm));
        if n1 != n2 {
            let Some(nrm) = s.shape.normal(p) else { return fail(margin, stop) };
            let Some(nd) = refract(d, nrm, n1, n2) else { return fail(margin, stop) };
            d = nd;
        }
        o = DVec3::new(p.x, p.y, p.z + s.z_mm);
    }
    if !(o.is_finite() && d.is_finite()) {
        return fail(margin, stop);
    }
    Unclipped { ray: Some(Ray { origin: o, direction: d }), stop, margin }
}

/// The two parameters at which the ray `o + t·d` (|d| = 1) meets a sphere, nearest first.
#[inline]
fn sphere_hits(o: DVec3, d: DVec3, centre: DVec3, radius: f64) -> Option<(f64, f64)> {
    let oc = o - centre;
    let b = oc.dot(d);
    let disc = b * b - (oc.length_squared() - radius * radius);
    if disc < 0.0 {
        return None;
    }
    let root = disc.sqrt();
    Some((-b - root, -b + root))
}

/// Where a ray starting inside a sphere leaves it (or `None`).
pub fn exit_sphere(o: DVec3, d: DVec3, centre: DVec3, radius: f64) -> Option<DVec3> {
    let (_, t) = sphere_hits(o, d, centre, radius)?;
    (t >= 0.0).then(|| o + d * t)
}

/// A correction of a lens's outgoing (scene-side) rays, applied while baking
/// ([`LrtfTable::bake_mapped`]); `None` absorbs the ray.
pub type OutgoingMap<'a> = dyn Fn(&Ray) -> Option<Ray> + Sync + 'a;

/// Bake options.
#[derive(Debug, Clone)]
pub struct BakeOptions {
    /// Samples along u and σx.
    pub resolution: u32,
    /// Film radius to cover.
    pub max_film_radius_mm: f64,
    /// Nearest film distance behind the input dome centre to cover (None: BFL − 5 mm).
    pub min_film_distance_mm: Option<f64>,
    /// Wavelengths (None: the primary one, or the design wavelengths for dispersive lenses).
    pub wavelengths_nm: Option<Vec<f64>>,
}

impl Default for BakeOptions {
    fn default() -> Self {
        BakeOptions { resolution: 96, max_film_radius_mm: 30.0, min_film_distance_mm: None, wavelengths_nm: None }
    }
}

impl LrtfTable {
    /// Builds the in-memory table from entries laid out as in the file (per wavelength, u, σx,
    /// σy, then the channels).
    fn from_entries(mut header: LrtfHeader, data: &[f32]) -> Self {
        // the checksum of the data as stored, so a table in memory and its file agree
        header.data_checksum = data_checksum(data);
        let key = Key::new(&header);
        let (n, ny) = (key.n, key.ny);
        let nw = header.wavelengths_nm.len();
        let mut lines = vec![Line::default(); nw * key.stride_w / 2];
        for wi in 0..nw {
            for iu in 0..n {
                for ix in 0..n {
                    for iy in 0..ny {
                        let e = &data[(((wi * n + iu) * n + ix) * ny + iy) * CHANNELS..][..CHANNELS];
                        let i = wi * key.stride_w + iu * key.stride_u + ix * key.stride_x + iy;
                        lines[i / 2].0[i % 2] = [Vec4::new(e[0], e[1], e[2], e[3]), Vec4::new(e[4], e[5], e[6], e[7])];
                    }
                }
            }
        }
        LrtfTable { header, lines, key }
    }

    /// The entries as laid out in the file (inverse of [`Self::from_entries`]).
    fn entries(&self) -> Vec<f32> {
        let k = &self.key;
        let (n, ny) = (k.n, k.ny);
        let nw = self.header.wavelengths_nm.len();
        let mut data = Vec::with_capacity(nw * n * n * ny * CHANNELS);
        for wi in 0..nw {
            for iu in 0..n {
                for ix in 0..n {
                    for iy in 0..ny {
                        let i = wi * k.stride_w + iu * k.stride_u + ix * k.stride_x + iy;
                        let [a, b] = self.lines[i / 2].0[i % 2];
                        data.extend_from_slice(&a.to_array());
                        data.extend_from_slice(&b.to_array());
                    }
                }
            }
        }
        data
    }

    /// Bytes of table data in memory.
    pub fn data_bytes(&self) -> usize {
        self.lines.len() * std::mem::size_of::<Line>()
    }

    /// Bakes the table for `lens` (rotationally symmetric lenses only). `progress` gets the
    /// fraction done.
    pub fn bake(lens: &Lens, options: &BakeOptions, progress: &(dyn Fn(f64) + Sync)) -> Result<LrtfTable> {
        Self::bake_mapped(lens, options, None, progress)
    }

    /// Bakes the table of `lens` with every outgoing (scene-side) ray passed through
    /// `outgoing`, a correction of the lens's ray transfer (lens-fit's LRTF correction mode). The
    /// map must keep rotational symmetry (the table is 3-D) and may return any point on the
    /// corrected ray's line; `None` absorbs the ray. The header is that of `lens`, so the table
    /// loads with it; where a lookup is uncertain (a vignetting rim) the renderer traces `lens`
    /// itself, uncorrected.
    pub fn bake_mapped(
        lens: &Lens,
        options: &BakeOptions,
        outgoing: Option<&OutgoingMap<'_>>,
        progress: &(dyn Fn(f64) + Sync),
    ) -> Result<LrtfTable> {
        lens.check_forms_image()?;
        if !lens.is_rotationally_symmetric() {
            return Err(Error::Optics(format!(
                "lens '{}' has cylindrical surfaces or misaligned elements: its ray transfer is not rotationally symmetric, so a 3-D LRTF cannot represent it (use the exact model)",
                lens.name()
            )));
        }
        let n = options.resolution.clamp(8, 512);
        let ny = n / 2 + 1;
        // 1. Domes: the input hemisphere over the rear element, the output sphere around the front.
        let surfaces = lens.surfaces();
        let last = surfaces.last().ok_or_else(|| Error::Optics("empty lens".into()))?;
        let first = &surfaces[0];
        let samples = 64;
        let (mut z_rear_max, mut z_rear_min, mut z_front, mut r_out) =
            (f64::NEG_INFINITY, f64::INFINITY, f64::INFINITY, 0.0f64);
        let rear_z_at = |r: f64| {
            (last.z_mm + last.shape.sag(r, 0.0).unwrap_or(0.0)).max(last.z_mm + last.shape.sag(0.0, r).unwrap_or(0.0))
        };
        for k in 0..=samples {
            let r = last.semi_diameter_mm * k as f64 / samples as f64;
            z_rear_max = z_rear_max.max(rear_z_at(r));
            z_rear_min = z_rear_min.min(
                (last.z_mm + last.shape.sag(r, 0.0).unwrap_or(0.0))
                    .min(last.z_mm + last.shape.sag(0.0, r).unwrap_or(0.0)),
            );
            let rf = first.semi_diameter_mm * k as f64 / samples as f64;
            z_front = z_front.min(first.z_mm + first.shape.sag(rf, 0.0).unwrap_or(0.0));
        }
        for k in 0..=samples {
            let rf = first.semi_diameter_mm * k as f64 / samples as f64;
            let z = first.z_mm + first.shape.sag(rf, 0.0).unwrap_or(0.0);
            r_out = r_out.max(rf.hypot(z - z_front));
        }
        let out_radius = r_out * 1.02 + 1e-6;
        // 2. The input dome stands on the plane through the rear element's scene-most point (so a
        //    ray from the film, whose z only decreases, crosses the dome before any point of the
        //    rear surface) and must cover that surface; it is a hemisphere when the film leaves
        //    room, else a flatter cap reaching at most 40 % of the way to the film.
        let min_film = options
            .min_film_distance_mm
            .unwrap_or((lens.paraxial().bfl_mm + lens.last_vertex_z_mm() - z_rear_max) - 5.0);
        if !(min_film > 0.5) {
            return Err(Error::Optics(format!(
                "the film ({min_film:.2} mm behind the rear element) is too close to the lens for a table"
            )));
        }
        let depth = z_rear_max - z_rear_min;
        let mut dome = None;
        let mut base_radius = last.semi_diameter_mm * 1.02;
        for _ in 0..40 {
            let cap_height = base_radius.min(depth + 0.4 * min_film);
            let radius = (base_radius * base_radius + cap_height * cap_height) / (2.0 * cap_height);
            let centre_z = z_rear_min + cap_height - radius;
            let covers = (0..=samples).all(|k| {
                let r = last.semi_diameter_mm * k as f64 / samples as f64;
                centre_z + (radius * radius - r * r).max(0.0).sqrt() > rear_z_at(r) + 1e-6
            });
            if covers {
                dome = Some((cap_height, radius, centre_z));
                break;
            }
            base_radius *= 1.05;
        }
        let Some((cap_height, in_radius, in_centre_z)) = dome else {
            return Err(Error::Optics(format!(
                "no input dome fits between the rear element and the film ({min_film:.2} mm)"
            )));
        };
        let z_rear = z_rear_min;
        let min_film = min_film + depth; // from the dome's base plane
        let alpha_max =
            ((options.max_film_radius_mm + base_radius) / (min_film - cap_height)).atan().min(89f64.to_radians());
        let s_max = (0.5 * alpha_max).tan() * 1.02;
        let wavelengths = match &options.wavelengths_nm {
            Some(w) if !w.is_empty() => w.clone(),
            _ if lens.has_dispersion() => lens.wavelengths_nm().to_vec(),
            _ => vec![lens.primary_wavelength_nm()],
        };
        let header = LrtfHeader {
            version: LRTF_VERSION,
            lens_name: lens.name().to_string(),
            lens_hash: lens_hash(lens),
            resolution: n,
            resolution_y: ny,
            wavelengths_nm: wavelengths.clone(),
            in_base_z_mm: z_rear,
            in_base_radius_mm: base_radius,
            in_centre_z_mm: in_centre_z,
            in_radius_mm: in_radius,
            s_max,
            out_centre_z_mm: z_front,
            out_radius_mm: out_radius,
            max_film_radius_mm: options.max_film_radius_mm,
            min_film_distance_mm: min_film,
            data_checksum: 0,
        };
        // 3. Trace every entry (rows of u in parallel).
        let (n, ny) = (n as usize, ny as usize);
        let row = n * ny * CHANNELS;
        let mut data = vec![0f32; wavelengths.len() * n * row];
        let done = std::sync::atomic::AtomicUsize::new(0);
        let total = wavelengths.len() * n;
        for (wi, &wl) in wavelengths.iter().enumerate() {
            let block = &mut data[wi * n * row..(wi + 1) * n * row];
            block.par_chunks_mut(row).enumerate().for_each(|(iu, out)| {
                let u = iu as f64 / (n - 1) as f64;
                let rho = u * base_radius;
                let p = DVec3::new(rho, 0.0, in_centre_z + (in_radius * in_radius - rho * rho).max(0.0).sqrt());
                for ix in 0..n {
                    for iy in 0..ny {
                        let sx = (-1.0 + 2.0 * ix as f64 / (n - 1) as f64) * s_max;
                        let sy = (iy as f64 / (ny - 1) as f64) * s_max;
                        // direction towards the lens (z < 0 inside the unit disc)
                        let d = unstereo(DVec2::new(sx, sy));
                        let e = &mut out[(ix * ny + iy) * CHANNELS..(ix * ny + iy + 1) * CHANNELS];
                        let u = trace_unclipped(lens, &Ray { origin: p, direction: d.normalize() }, wl);
                        let out_ray = u.ray.and_then(|r| {
                            let r = match outgoing {
                                Some(map) => map(&r)?,
                                None => r,
                            };
                            Some((
                                exit_sphere(r.origin, r.direction, DVec3::new(0.0, 0.0, z_front), out_radius)?,
                                r.direction,
                            ))
                        });
                        let margin = u.margin.max(-1.0) as f32;
                        match out_ray {
                            Some((q, dir)) => {
                                let w = stereo((q - DVec3::new(0.0, 0.0, z_front)) / out_radius);
                                let es = stereo(dir);
                                e.copy_from_slice(&[
                                    w.x as f32,
                                    w.y as f32,
                                    es.x as f32,
                                    es.y as f32,
                                    u.stop.x as f32,
                                    u.stop.y as f32,
                                    margin,
                                    1.0,
                                ]);
                            }
                            None => e.copy_from_slice(&[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, margin.min(-1e-6), 0.0]),
                        }
                    }
                }
                let k = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
                progress(k as f64 / total as f64);
            });
        }
        fill_invalid(&header, &mut data);
        Ok(LrtfTable::from_entries(header, &data))
    }
}

/// Entries whose trace failed (TIR, missed surface) get the outputs of their nearest valid
/// neighbours, so interpolation next to them stays smooth; their margin stays negative.
fn fill_invalid(header: &LrtfHeader, data: &mut [f32]) {
    let n = header.resolution as usize;
    let ny = header.resolution_y as usize;
    let index = |wi: usize, iu: usize, ix: usize, iy: usize| ((wi * n + iu) * n + ix) * ny * CHANNELS + iy * CHANNELS;
    for wi in 0..header.wavelengths_nm.len() {
        for _pass in 0..(2 * n) {
            let mut changed = false;
            let mut updates = Vec::new();
            for iu in 0..n {
                for ix in 0..n {
                    for iy in 0..ny {
                        let i = index(wi, iu, ix, iy);
                        if data[i + 7] != 0.0 {
                            continue;
                        }
                        // linear extrapolation from two valid entries along each axis
                        // (the continuation of the smooth map), else their neighbour
                        let mut acc = [0f32; 6];
                        let mut cnt = 0;
                        let mut near = [0f32; 6];
                        let mut near_cnt = 0;
                        for (du, dx, dy) in
                            [(1i64, 0i64, 0i64), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1)]
                        {
                            let at = |k: i64| -> Option<usize> {
                                let (a, b, c) = (iu as i64 + du * k, ix as i64 + dx * k, iy as i64 + dy * k);
                                if a < 0 || b < 0 || c < 0 || a >= n as i64 || b >= n as i64 || c >= ny as i64 {
                                    return None;
                                }
                                let j = index(wi, a as usize, b as usize, c as usize);
                                (data[j + 7] != 0.0).then_some(j)
                            };
                            if let Some(j1) = at(1) {
                                for k in 0..6 {
                                    near[k] += data[j1 + k];
                                }
                                near_cnt += 1;
                                if let Some(j2) = at(2) {
                                    for k in 0..6 {
                                        acc[k] += 2.0 * data[j1 + k] - data[j2 + k];
                                    }
                                    cnt += 1;
                                }
                            }
                        }
                        if cnt == 0 && near_cnt > 0 {
                            acc = near;
                            cnt = near_cnt;
                        }
                        if cnt > 0 {
                            updates.push((i, acc.map(|v| v / cnt as f32)));
                        }
                    }
                }
            }
            for (i, v) in updates {
                data[i..i + 6].copy_from_slice(&v);
                data[i + 7] = 0.5; // filled: valid for interpolation, margin stays negative
                changed = true;
            }
            if !changed {
                break;
            }
        }
    }
}

impl LrtfTable {
    /// Looks up the ray leaving the lens for a ray from the film (lens frame).
    ///
    /// Returns [`LrtfLookup::Uncertain`] when the ray's cell straddles a vignetting boundary
    /// (its corners disagree on passing) or touches an entry whose trace failed: there the
    /// caller traces exactly, so interpolation never invents or loses a ray at a rim.
    ///
    /// The lookup runs in f32 (the table's precision): no trigonometry (the rotation into the
    /// key's frame uses the dome point's (x, y)/ρ; the stereographic maps need one division
    /// each), four cache-line reads, and the blend as 4-lane products.
    ///
    /// On x86-64 CPUs with AVX2 and FMA (detected once, at the first lookup; [`simd_level`])
    /// the same code runs compiled for them; the results are bit-identical to
    /// [`LrtfTable::lookup_baseline`]'s (no operation is fused), so images do not depend on the
    /// machine.
    #[inline]
    pub fn lookup(&self, ray: &Ray, wavelength_nm: f64) -> LrtfLookup {
        #[cfg(target_arch = "x86_64")]
        if *SIMD_LEVEL == SimdLevel::Avx2Fma {
            // SAFETY: the CPU was checked for AVX2 and FMA (`SIMD_LEVEL`).
            return unsafe { self.lookup_avx2(ray, wavelength_nm) };
        }
        self.lookup_body::<false>(ray, wavelength_nm)
    }

    /// [`LrtfTable::lookup`] compiled for the baseline target only (SSE2 on x86-64), whatever
    /// the CPU: for benchmarks and checks.
    pub fn lookup_baseline(&self, ray: &Ray, wavelength_nm: f64) -> LrtfLookup {
        self.lookup_body::<false>(ray, wavelength_nm)
    }

    /// The lookup compiled with AVX2 and FMA enabled.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn lookup_avx2(&self, ray: &Ray, wavelength_nm: f64) -> LrtfLookup {
        self.lookup_body::<true>(ray, wavelength_nm)
    }

    /// The lookup's body (inlined into each instruction-set build): the batched lookup's steps
    /// for one lane.
    #[inline(always)]
    fn lookup_body<const AVX: bool>(&self, ray: &Ray, wavelength_nm: f64) -> LrtfLookup {
        let keys = self.ray_keys(std::array::from_ref(ray));
        let cell = match self.cell_at(&keys, 0, wavelength_nm) {
            Ok(c) => c,
            Err(outcome) => return outcome,
        };
        match self.blend_cell::<AVX>(&cell) {
            Ok(b) => {
                let [(ray, stop_point, margin)] = self.unmap_lanes(&keys, &[b]);
                LrtfLookup::Hit(LrtfRay { ray, stop_point, margin })
            }
            Err(outcome) => outcome,
        }
    }

    /// Looks up [`LRTF_BATCH`] rays at once: the same results, bit for bit, as
    /// [`LrtfTable::lookup`] of each (the same two steps per ray), but every ray's cell is found
    /// and its cache lines are prefetched before the first cell is read, so the table's memory
    /// latencies overlap instead of adding up. Pad a short batch with any ray and ignore its
    /// result.
    #[inline]
    pub fn lookup_batch(
        &self,
        rays: &[Ray; LRTF_BATCH],
        wavelengths_nm: &[f64; LRTF_BATCH],
    ) -> [LrtfLookup; LRTF_BATCH] {
        #[cfg(target_arch = "x86_64")]
        if *SIMD_LEVEL == SimdLevel::Avx2Fma {
            // SAFETY: the CPU was checked for AVX2 and FMA (`SIMD_LEVEL`).
            return unsafe { self.lookup_batch_avx2(rays, wavelengths_nm) };
        }
        self.lookup_batch_body::<false>(rays, wavelengths_nm)
    }

    /// [`LrtfTable::lookup_batch`] compiled for the baseline target only, whatever the CPU.
    pub fn lookup_batch_baseline(
        &self,
        rays: &[Ray; LRTF_BATCH],
        wavelengths_nm: &[f64; LRTF_BATCH],
    ) -> [LrtfLookup; LRTF_BATCH] {
        self.lookup_batch_body::<false>(rays, wavelengths_nm)
    }

    /// The batched lookup compiled with AVX2 and FMA enabled.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn lookup_batch_avx2(
        &self,
        rays: &[Ray; LRTF_BATCH],
        wavelengths_nm: &[f64; LRTF_BATCH],
    ) -> [LrtfLookup; LRTF_BATCH] {
        self.lookup_batch_body::<true>(rays, wavelengths_nm)
    }

    /// The batched lookup's body: every lane's key as vectors, every cell found and prefetched,
    /// then the blends lane by lane, then every lane's way back to the lens frame as vectors.
    #[inline(always)]
    fn lookup_batch_body<const AVX: bool>(
        &self,
        rays: &[Ray; LRTF_BATCH],
        wavelengths_nm: &[f64; LRTF_BATCH],
    ) -> [LrtfLookup; LRTF_BATCH] {
        const N: usize = LRTF_BATCH;
        // 1. Keys, all lanes at once (branch-free: the compiler runs the lanes as vectors).
        let keys = self.ray_keys(rays);
        // 2. Cells, and their lines fetched before the first is read.
        let mut out = [LrtfLookup::Miss; N];
        let mut cells = [Cell::default(); N];
        let mut live = [false; N];
        for i in 0..N {
            match self.cell_at(&keys, i, wavelengths_nm[i]) {
                Ok(c) => {
                    self.prefetch(&c);
                    (cells[i], live[i]) = (c, true);
                }
                Err(o) => out[i] = o,
            }
        }
        // 3. Blends, lane by lane (the corners' reads and margin tests).
        let mut blended = [(Vec4::ZERO, Vec4::ZERO); N];
        for i in 0..N {
            if live[i] {
                match self.blend_cell::<AVX>(&cells[i]) {
                    Ok(b) => blended[i] = b,
                    Err(o) => (out[i], live[i]) = (o, false),
                }
            }
        }
        // 4. The way back to the lens frame, all lanes at once.
        let rays = self.unmap_lanes(&keys, &blended);
        for i in 0..N {
            if live[i] {
                let (ray, stop_point, margin) = rays[i];
                out[i] = LrtfLookup::Hit(LrtfRay { ray, stop_point, margin });
            }
        }
        out
    }

    /// Asks the memory system for a cell's cache lines (a hint; no effect on results).
    #[inline(always)]
    fn prefetch(&self, c: &Cell) {
        #[cfg(target_arch = "x86_64")]
        for i in c.idx {
            use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
            // SAFETY: `cell_at` checked that every index of the cell lies inside `lines`;
            // prefetching never faults.
            unsafe {
                _mm_prefetch(self.lines.as_ptr().add(i / 2) as *const i8, _MM_HINT_T0);
                _mm_prefetch(self.lines.as_ptr().add(i.div_ceil(2)) as *const i8, _MM_HINT_T0);
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        let _ = c;
    }

    /// Steps 1–2 of a lookup for `N` rays, lane by lane in one straight-line loop (every step
    /// computed, selects instead of early returns, so the lanes run as vectors): where each ray
    /// enters the input dome and its key there.
    #[inline(always)]
    fn ray_keys<const N: usize>(&self, rays: &[Ray; N]) -> Keys<N> {
        let k = &self.key;
        let mut keys = Keys {
            f: [[0.0; N]; 3],
            cs: [0.0; N],
            sn: [0.0; N],
            sign: [1.0; N],
            missed: [false; N],
            inside: [false; N],
        };
        for (i, ray) in rays.iter().enumerate() {
            let (o, d) = (ray.origin, ray.direction);
            // relative to the input dome's centre, in f32 (the table's precision)
            let (ox, oy, oz) = (o.x as f32, o.y as f32, (o.z - k.in_centre_z) as f32);
            let (dx, dy, dz) = (d.x as f32, d.y as f32, d.z as f32);
            // 1. Where the ray enters the input dome.
            let b = ox * dx + oy * dy + oz * dz;
            let disc = b * b - (ox * ox + oy * oy + oz * oz - k.in_radius_sq);
            let t = -b - disc.sqrt();
            let (px, py, pz) = (ox + t * dx, oy + t * dy, oz + t * dz);
            keys.missed[i] = !(disc >= 0.0) || !(t >= 0.0) || pz < k.base_dz;
            // 2. Key: rotate the direction into the frame where the point lies on +x (cos φ,
            //    sin φ = (x, y)/ρ), stereographic projection, mirror σy ≥ 0.
            let rho2 = px * px + py * py;
            let inv_r = 1.0 / rho2.sqrt();
            let (cs, sn, rho) = if rho2 > 1e-20 { (px * inv_r, py * inv_r, rho2 * inv_r) } else { (1.0, 0.0, 0.0) };
            let inv = 1.0 / (1.0 - dz).max(1e-12);
            let sx = (cs * dx + sn * dy) * inv;
            let sy = (cs * dy - sn * dx) * inv;
            let f = [rho * k.scale_u, sx * k.scale_x + k.half, sy.abs() * k.scale_y];
            keys.inside[i] = f[0] <= k.max_x && f[1] >= 0.0 && f[1] <= k.max_x && f[2] <= k.max_y;
            (keys.f[0][i], keys.f[1][i], keys.f[2][i]) = (f[0], f[1], f[2]);
            (keys.cs[i], keys.sn[i]) = (cs, sn);
            keys.sign[i] = if sy < 0.0 { -1.0 } else { 1.0 };
        }
        keys
    }

    /// Step 3 of a lookup: lane `i`'s cell (four σy-adjacent pairs of entries, one or two cache
    /// lines each) and its interpolation weights, or its outcome when it never reaches a cell
    /// (missed the dome; outside the baked domain, where only the exact trace can say).
    #[inline(always)]
    fn cell_at<const N: usize>(
        &self,
        keys: &Keys<N>,
        i: usize,
        wavelength_nm: f64,
    ) -> std::result::Result<Cell, LrtfLookup> {
        if keys.missed[i] {
            return Err(LrtfLookup::Miss);
        }
        if !keys.inside[i] {
            return Err(LrtfLookup::Uncertain);
        }
        let k = &self.key;
        let [fu, fx, fy] = [keys.f[0][i], keys.f[1][i], keys.f[2][i]];
        let wi = self.nearest_wavelength(wavelength_nm);
        // (i32 conversions: one instruction each; the domain test excluded NaN and < 0)
        let (iu, ix, iy) = ((fu as i32).min(k.last_cell), (fx as i32).min(k.last_cell), (fy as i32).min(k.last_cell_y));
        let (tu, tx, ty) = (fu - iu as f32, fx - ix as f32, fy - iy as f32);
        let base = wi * k.stride_w + iu as usize * k.stride_u + ix as usize * k.stride_x + iy as usize;
        if (base + k.stride_u + k.stride_x + 1).div_ceil(2) >= self.lines.len() {
            return Err(LrtfLookup::Miss);
        }
        let idx = [base, base + k.stride_x, base + k.stride_u, base + k.stride_u + k.stride_x];
        Ok(Cell { idx, t: [tu, tx, ty] })
    }

    /// Step 6 of a lookup for `N` lanes at once, in one straight-line loop: the blended outputs
    /// (w, e) and (stop, margin) back in the lens frame (undo the mirror, the stereographic
    /// maps and the rotation of each lane's key): the outgoing ray, the stop crossing and the
    /// margin. Lanes without a blend give any value.
    #[inline(always)]
    fn unmap_lanes<const N: usize>(&self, keys: &Keys<N>, blended: &[(Vec4, Vec4); N]) -> [(Ray, DVec2, f64); N] {
        let k = &self.key;
        // 1. Channels as lanes.
        let mut c = [[0f32; N]; 7];
        for i in 0..N {
            let (a, st) = blended[i];
            (c[0][i], c[1][i], c[2][i], c[3][i]) = (a.x, a.y, a.z, a.w);
            (c[4][i], c[5][i], c[6][i]) = (st.x, st.y, st.z);
        }
        // 2. Inverse maps, every lane.
        let mut v = [[0f32; N]; 8];
        for i in 0..N {
            let (cs, sn, sign) = (keys.cs[i], keys.sn[i], keys.sign[i]);
            let (wx, ex, stx) = (c[0][i], c[2][i], c[4][i]);
            let (wy_, ey, sty) = (sign * c[1][i], sign * c[3][i], sign * c[5][i]);
            let (s2w, s2e) = (wx * wx + wy_ * wy_, ex * ex + ey * ey);
            let (kw, ke) = (k.out_radius / (1.0 + s2w), 1.0 / (1.0 + s2e));
            let (qx, qy, qz) = (2.0 * wx * kw, 2.0 * wy_ * kw, (s2w - 1.0) * kw);
            let (vx, vy, vz) = (2.0 * ex * ke, 2.0 * ey * ke, (s2e - 1.0) * ke);
            (v[0][i], v[1][i], v[2][i]) = (cs * qx - sn * qy, sn * qx + cs * qy, qz);
            (v[3][i], v[4][i], v[5][i]) = (cs * vx - sn * vy, sn * vx + cs * vy, vz);
            (v[6][i], v[7][i]) = (cs * stx - sn * sty, sn * stx + cs * sty);
        }
        // 3. Back to f64 (directions unit to f32 precision, ~1e-7).
        std::array::from_fn(|i| {
            (
                Ray {
                    origin: DVec3::new(v[0][i] as f64, v[1][i] as f64, v[2][i] as f64 + k.out_centre_z),
                    direction: DVec3::new(v[3][i] as f64, v[4][i] as f64, v[5][i] as f64),
                },
                DVec2::new(v[6][i] as f64, v[7][i] as f64),
                c[6][i] as f64,
            )
        })
    }

    /// Steps 4–5 of a lookup: the cell's corners read, tested and blended: the outputs
    /// (w, e) and (stop, margin, validity), or the outcome when the corners say so. `AVX`:
    /// the blend of both halves of the eight entries in 8-lane operations (the same products
    /// and sums in the same order, so the same bits).
    #[inline(always)]
    fn blend_cell<const AVX: bool>(&self, c: &Cell) -> std::result::Result<(Vec4, Vec4), LrtfLookup> {
        let at = |i: usize| &self.lines[i / 2].0[i % 2];
        let idx = c.idx;
        let e = [
            at(idx[0]),
            at(idx[0] + 1),
            at(idx[1]),
            at(idx[1] + 1),
            at(idx[2]),
            at(idx[2] + 1),
            at(idx[3]),
            at(idx[3] + 1),
        ];
        let [tu, tx, ty] = c.t;
        let (su, sx_, sy_) = (1.0 - tu, 1.0 - tx, 1.0 - ty);
        let w = [
            su * sx_ * sy_,
            su * sx_ * ty,
            su * tx * sy_,
            su * tx * ty,
            tu * sx_ * sy_,
            tu * sx_ * ty,
            tu * tx * sy_,
            tu * tx * ty,
        ];
        // 4. Corners must agree on passing (margin > 0; failed traces carry negative margins).
        let lo = e[0][1].min(e[1][1]).min(e[2][1].min(e[3][1])).min(e[4][1].min(e[5][1]).min(e[6][1].min(e[7][1])));
        let hi = e[0][1].max(e[1][1]).max(e[2][1].max(e[3][1])).max(e[4][1].max(e[5][1]).max(e[6][1].max(e[7][1])));
        let (m_min, m_max) = (lo.z, hi.z);
        if !(m_max > 0.0) {
            return Err(LrtfLookup::Miss);
        }
        #[cfg(target_arch = "x86_64")]
        let (a, st) = if AVX {
            // SAFETY: `AVX` is true only inside the AVX2 builds, on a CPU with AVX2 and FMA.
            unsafe { blend_both_avx(&e, &w) }
        } else {
            (Vec4::ZERO, blend(&e, &w, 1))
        };
        #[cfg(not(target_arch = "x86_64"))]
        let (a, st) = (Vec4::ZERO, blend(&e, &w, 1));
        // stop.x, stop.y, margin in `st`
        let margin = st.z;
        if !(m_min > 0.0) {
            // The rim boundary crosses this cell. Where one rim clips, the margin is smooth and
            // its interpolation decides; where the corners' diagonals disagree (two rims trade
            // the minimum, or an entry whose trace failed carries an extrapolated margin), the
            // exact trace decides within that disagreement of zero.
            let (d0, d1) = (e[0][1] + e[7][1], e[4][1] + e[3][1]);
            let (d2, d3) = (e[2][1] + e[5][1], e[1][1] + e[6][1]);
            let nonlinearity = d0.max(d1).max(d2.max(d3)).z - d0.min(d1).min(d2.min(d3)).z;
            if margin.abs() < BOUNDARY_NONLINEARITY * nonlinearity {
                return Err(LrtfLookup::Uncertain);
            }
            if margin <= 0.0 {
                return Err(LrtfLookup::Miss);
            }
        }
        // 5. Blend of the outputs.
        let a = if AVX { a } else { blend(&e, &w, 0) };
        Ok((a, st))
    }

    #[inline]
    fn nearest_wavelength(&self, wavelength_nm: f64) -> usize {
        let ws = &self.header.wavelengths_nm;
        if ws.len() == 1 {
            return 0;
        }
        let mut best = 0;
        for (i, w) in ws.iter().enumerate() {
            if (w - wavelength_nm).abs() < (ws[best] - wavelength_nm).abs() {
                best = i;
            }
        }
        best
    }

    /// Writes the table (temporary file, then rename).
    pub fn save(&self, path: &Path) -> Result<()> {
        // validated before anything is written: a table this build cannot read is never saved
        let bad = |m: String| Error::Optics(format!("{}: not written: {m}", path.display()));
        self.header.check().map_err(bad)?;
        let data = self.entries();
        if let Some(v) = data.iter().find(|v| !(v.abs() <= MAX_ENTRY)) {
            return Err(bad(format!("table value {v:e} is non-finite or beyond {MAX_ENTRY:e}")));
        }
        let mut bytes = Vec::with_capacity(data.len() * 4);
        for v in &data {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        let header = LrtfHeader { data_checksum: fnv1a64(&bytes), ..self.header.clone() };
        let header = serde_json::to_vec(&header).map_err(|e| Error::io(path, std::io::Error::other(e)))?;
        let mut buf = Vec::with_capacity(16 + header.len() + bytes.len());
        buf.extend_from_slice(MAGIC);
        buf.extend_from_slice(&LRTF_VERSION.to_le_bytes());
        buf.extend_from_slice(&(header.len() as u32).to_le_bytes());
        buf.write_all(&header).map_err(|e| Error::io(path, e))?;
        buf.extend_from_slice(&bytes);
        crate::write_atomic(path, &buf)
    }

    /// Reads a table and checks that it belongs to `lens` (same prescription hash).
    pub fn load(path: &Path, lens: &Lens) -> Result<LrtfTable> {
        let bytes = crate::io::read_input_file(path, MAX_TABLE_FILE_BYTES, "LRTF table")?;
        LrtfTable::from_bytes(&bytes, lens, &path.display().to_string())
    }

    /// A table from the bytes of an LRTF file (see [`LrtfTable::load`]); `file` names it in
    /// errors.
    pub fn from_bytes(bytes: &[u8], lens: &Lens, file: &str) -> Result<LrtfTable> {
        let bad = |m: String| Error::Optics(format!("{file}: {m}"));
        if bytes.len() < 16 || &bytes[..8] != MAGIC {
            return Err(bad("not a Petzval LRTF file (bad magic)".into()));
        }
        let version = u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]);
        if version != LRTF_VERSION {
            return Err(bad(format!("LRTF format version {version}, this build reads version {LRTF_VERSION}: re-bake it with `petzval lrtf bake`")));
        }
        let hlen = u32::from_le_bytes([bytes[12], bytes[13], bytes[14], bytes[15]]) as usize;
        let hend =
            16usize.checked_add(hlen).filter(|e| *e <= bytes.len()).ok_or_else(|| bad("truncated header".into()))?;
        let header: LrtfHeader = serde_json::from_slice(&bytes[16..hend]).map_err(|e| bad(format!("header: {e}")))?;
        let expect_hash = lens_hash(lens);
        if header.lens_hash != expect_hash || header.lens_name != lens.name() {
            return Err(bad(format!(
                "baked for lens '{}' (hash {:016x}), not for '{}' (hash {:016x}): the lens differs or changed; re-bake with `petzval lrtf bake {}`",
                header.lens_name,
                header.lens_hash,
                lens.name(),
                expect_hash,
                lens.name()
            )));
        }
        header.check().map_err(bad)?;
        let (n, ny, nw) = (header.resolution as usize, header.resolution_y as usize, header.wavelengths_nm.len());
        // sizes from the file: multiply without overflow, and compare with what is there
        let count = [n, n, ny, CHANNELS, 4].iter().try_fold(nw, |a, b| a.checked_mul(*b));
        let data_bytes = bytes.len() - hend;
        if count != Some(data_bytes) {
            return Err(bad(format!(
                "the header's table size ({nw} wavelengths × {n}² × {ny}) does not match the {data_bytes} bytes of table data"
            )));
        }
        if fnv1a64(&bytes[hend..]) != header.data_checksum {
            return Err(bad("the table data does not match its checksum (the file is corrupted)".into()));
        }
        let data: Vec<f32> =
            bytes[hend..].chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect();
        if let Some(v) = data.iter().find(|v| !(v.abs() <= MAX_ENTRY)) {
            return Err(bad(format!(
                "table value {v:e} is non-finite or beyond {MAX_ENTRY:e} (the file is corrupted: baked tables stay below 1e12, and larger values overflow the lookup)"
            )));
        }
        Ok(LrtfTable::from_entries(header, &data))
    }
}
