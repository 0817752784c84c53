//! The glTF metallic-roughness BSDF (glTF 2.0 spec appendix B, with `KHR_materials_specular` /
//! `KHR_materials_ior` dielectric F0), and glass for `KHR_materials_transmission` ([`Glass`],
//! weighted by (1 − metallic)·transmission against everything below, which only reflects).
//!
//! ```text
//! f = (1 − m)·[ F_d(v·h)·(1 + F_ms,d·(1 − E(μo))/E(μo))·D·V  +  base/π·(1 − E_d(μo)) ]
//!   + m·F_m(v·h)·(1 + F_ms,m·(1 − E(μo))/E(μo))·D·V
//! F_d = exact dielectric Fresnel of η′, the index whose F0 is specular·((ior−1)/(ior+1))²
//!       (Cycles' Principled BSDF: Specular IOR Level × 2 = specular; η′ = ior at 1);
//!       with a Specular Tint t: t·F_d + (1 − t)·(F_d − F0)/(1 − F0) per channel
//!       ([`Bsdf::with_specular_tint`]; the base then under the layer's brightest channel)
//! F_m = Schlick(F0 = base colour, F90 = 1)                              (metal)
//!       − b·μ(1 − μ)⁶ with Cycles' F82 tint, or F0 at every angle ([`MetalFresnel`])
//! D = GGX / Trowbridge–Reitz, V = Smith height-correlated G2 / (4 μo μi), α = roughness² ≥ 1e-3
//!     (anisotropic: α_x along the tangent, α_y across, [`Bsdf::with_anisotropic_alphas`])
//! F_ms,m = F̄ Ē / (1 − F̄ (1 − Ē)),   F̄ = the metal Fresnel's hemispherical average
//!     (Schlick's F0 + (1 − F0)/21; Cycles' multiscatter GGX)
//! F_ms,d = F̄ Ē / (1 − F̄ (1 − Ē)),   F̄ = 2∫ F_d(μ) μ dμ (Cycles' multiscatter GGX)
//! E_d = the dielectric layer's albedo: ∫ F_d D V μi dωi · (1 + F_ms,d·(1 − E(μ))/E(μ))
//! ```
//!
//! The diffuse base is layered as Cycles layers its Principled BSDF: weighted by what the
//! dielectric layer does not reflect toward the viewer, `1 − E_d(μo)`, so the total albedo is
//! `E_d(μo) + base·(1 − E_d(μo)) ≤ 1`. This depends on the outgoing direction only (not
//! reciprocal), as does the dielectric lobe's multiple-scattering scale. The glTF spec's
//! `1 − F_d(v·h)` (`mix(diffuse, specular, F)`) would gain energy at grazing angles (a white
//! dielectric reflects up to ~1.36 of the incident energy at roughness 0.3, 89°). `E_d` is
//! tabulated per η′ (64 × 64 in √μ and roughness, rows built on first use;
//! `DielectricTable`). Until session 26 the dielectric layer used Schlick's Fresnel (F90 =
//! specular) and a reciprocal layering; a point light's reflection seen 56° off a glossy plane
//! was 0.75× Cycles' (docs/cycles-comparison.md, "Specular layers").
//!
//! Multiple scattering between microfacets: single-scatter GGX loses the energy of light that
//! bounces more than once, up to 70 % for a white metal at roughness 1 (Blender's Principled
//! BSDF, multiscatter GGX by default, loses none). As in Cycles (Turquin 2019, with the Fresnel
//! average over repeated bounces of Kulla & Conty 2017), each specular lobe is scaled by
//! 1 + F_ms·(1 − E(μo))/E(μo) (E = the lobe's albedo with F = 1, tabulated): a white metal then
//! reflects exactly 1 at every angle and roughness, and the lobe keeps its shape (not
//! reciprocal, as Cycles'). Until session 35 the metal's share came back as a broad, reciprocal
//! lobe (1 − E(μo))(1 − E(μi))/(π(1 − Ē)) (Kulla & Conty): the same energy, but spread away from
//! the highlight, so a rough metal under a small light was too bright off the highlight (a
//! glossy cylinder under a 2° sun: 4 % against Cycles).
//!
//! Sampling: the specular lobe (visible normals, Heitz 2018) or the cosine-weighted lobe that
//! serves the diffuse base, chosen with probability proportional to the Fresnel reflectance at
//! μo versus its albedo; `pdf` is the mixture, so sample/pdf/eval agree exactly.
//!
//! Glass: see [`Glass`] (a rough dielectric interface with Cycles' multiscatter energy
//! compensation). Lobes are chosen by weight, and `pdf` is the mixture's.
//!
//! Everything here is in the local shading frame (normal = +z); [`SurfaceBsdf`] handles the
//! world frame and the geometric-normal checks.

use std::f32::consts::{FRAC_1_PI, PI};
use std::sync::OnceLock;

use glam::{Vec2, Vec3};

use crate::scene::MetalFresnel;

/// Smallest GGX alpha (roughness² is clamped to this; keeps D finite).
pub const MIN_ALPHA: f32 = 1e-3;

/// Rec. 709 luminance.
#[inline]
pub fn luminance(c: Vec3) -> f32 {
    0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z
}

/// An orthonormal basis (t, b) with t × b = n (Duff et al. 2017).
#[inline]
pub fn orthonormal_basis(n: Vec3) -> (Vec3, Vec3) {
    let sign = 1.0f32.copysign(n.z);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    (Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x), Vec3::new(b, sign + n.y * n.y * a, -n.y))
}

/// A sampled direction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BsdfSample {
    /// Incident direction (local frame for [`Bsdf`], world for [`SurfaceBsdf`]).
    pub wi: Vec3,
    /// f·cos/pdf.
    pub weight: Vec3,
    /// Solid-angle pdf of `wi` (the mixture of both lobes).
    pub pdf: f32,
    /// Always false here (α ≥ [`MIN_ALPHA`] keeps every lobe non-delta).
    pub is_delta: bool,
}

#[inline]
fn schlick_weight(cos: f32) -> f32 {
    let m = (1.0 - cos).clamp(0.0, 1.0);
    let m2 = m * m;
    m2 * m2 * m
}

/// GGX normal distribution D(h) for `cos_h = h.z`.
#[inline]
fn ggx_d(cos_h: f32, a2: f32) -> f32 {
    let c2 = cos_h * cos_h;
    let d = c2 * (a2 - 1.0) + 1.0;
    a2 / (PI * d * d)
}

/// Smith Λ for GGX.
#[inline]
fn smith_lambda(cos: f32, a2: f32) -> f32 {
    let c2 = cos * cos;
    let t2 = (1.0 - c2).max(0.0) / c2.max(1e-12);
    0.5 * (-1.0 + (1.0 + a2 * t2).sqrt())
}

/// Anisotropic GGX D(h), `h` in the frame whose x axis is the tangent (roughness `ax` along
/// it, `ay` across).
#[inline]
fn ggx_d_aniso(h: Vec3, ax: f32, ay: f32) -> f32 {
    let (x, y) = (h.x / ax, h.y / ay);
    let d = x * x + y * y + h.z * h.z;
    1.0 / (PI * ax * ay * d * d)
}

/// Smith Λ for anisotropic GGX.
#[inline]
fn smith_lambda_aniso(w: Vec3, ax: f32, ay: f32) -> f32 {
    let z2 = (w.z * w.z).max(1e-12);
    let a2t2 = (ax * ax * w.x * w.x + ay * ay * w.y * w.y) / z2;
    0.5 * (-1.0 + (1.0 + a2t2).sqrt())
}

/// Anisotropic GGX's D(h)·G₂ / (4 μo μi) for `wo`, `wi`, `h` above the surface.
#[inline]
fn specular_dv_aniso(wo: Vec3, wi: Vec3, h: Vec3, ax: f32, ay: f32) -> f32 {
    let d = ggx_d_aniso(h, ax, ay);
    let g2 = 1.0 / (1.0 + smith_lambda_aniso(wo, ax, ay) + smith_lambda_aniso(wi, ax, ay));
    d * (g2 / (4.0 * wo.z * wi.z))
}

/// Anisotropic GGX's visible-normal density G₁(wo)·D(h) / (4 μo): the reflected direction's
/// pdf given the lobe.
#[inline]
fn specular_pdf_aniso(wo: Vec3, h: Vec3, ax: f32, ay: f32) -> f32 {
    let g1 = 1.0 / (1.0 + smith_lambda_aniso(wo, ax, ay));
    g1 * ggx_d_aniso(h, ax, ay) / (4.0 * wo.z)
}

/// Visible-normal sample (Heitz 2018, isotropic), `wo.z > 0`.
#[inline]
fn sample_vndf(wo: Vec3, alpha: f32, u: Vec2) -> Vec3 {
    sample_vndf_xy(wo, alpha, alpha, u)
}

/// Visible-normal sample of anisotropic GGX (Heitz 2018), `wo.z > 0`.
#[inline]
fn sample_vndf_xy(wo: Vec3, ax: f32, ay: f32, u: Vec2) -> Vec3 {
    let vh = Vec3::new(ax * wo.x, ay * wo.y, wo.z).normalize();
    let lensq = vh.x * vh.x + vh.y * vh.y;
    let t1 = if lensq > 1e-14 { Vec3::new(-vh.y, vh.x, 0.0) / lensq.sqrt() } else { Vec3::X };
    let t2 = vh.cross(t1);
    let r = u.x.sqrt();
    let phi = 2.0 * PI * u.y;
    let p1 = r * phi.cos();
    let mut p2 = r * phi.sin();
    let s = 0.5 * (1.0 + vh.z);
    p2 = (1.0 - s) * (1.0 - p1 * p1).max(0.0).sqrt() + s * p2;
    let nh = t1 * p1 + t2 * p2 + vh * (1.0 - p1 * p1 - p2 * p2).max(0.0).sqrt();
    Vec3::new(ax * nh.x, ay * nh.y, nh.z.max(0.0)).normalize_or(Vec3::Z)
}

/// Cosine-weighted hemisphere sample (concentric map).
#[inline]
pub fn sample_cosine_hemisphere(u: Vec2) -> Vec3 {
    let a = 2.0 * u - Vec2::ONE;
    let (r, phi) = if a.x == 0.0 && a.y == 0.0 {
        (0.0, 0.0)
    } else if a.x.abs() > a.y.abs() {
        (a.x, std::f32::consts::FRAC_PI_4 * (a.y / a.x))
    } else {
        (a.y, std::f32::consts::FRAC_PI_2 - std::f32::consts::FRAC_PI_4 * (a.x / a.y))
    };
    let (x, y) = (r * phi.cos(), r * phi.sin());
    Vec3::new(x, y, (1.0 - x * x - y * y).max(0.0).sqrt())
}

// ---------------------------------------------------------------------------------------------
// Directional albedo of the Schlick–GGX specular lobe: E(μ) = F0·E1(μ, r) + (F90 − F0)·E2(μ, r).

/// Table size per axis: roughness (linear) × √μ (nodes crowd near grazing, where smooth lobes
/// change within a width of about α).
const TABLE_N: usize = 64;

/// One roughness row of the tables, built on first use (a scene touches only the rows of its
/// materials' roughness values; a row costs 64 × 1024 visible-normal samples).
struct EnergyRow {
    /// ∫ D·V·μi dωi (F = 1) per μ node.
    e1: [f32; TABLE_N],
    /// ∫ (1 − v·h)^5·D·V·μi dωi per μ node.
    e2: [f32; TABLE_N],
    /// 2∫ E1(μ) μ dμ (of the interpolated row).
    e1_avg: f32,
    /// 2∫ E2(μ) μ dμ.
    e2_avg: f32,
}

fn radical_inverse_vdc(mut bits: u32) -> f32 {
    bits = bits.reverse_bits();
    bits as f32 * (1.0 / 4_294_967_296.0)
}

/// Row `ri` (roughness ri / (TABLE_N − 1)), computed once per process.
fn energy_row(ri: usize) -> &'static EnergyRow {
    static ROWS: [OnceLock<EnergyRow>; TABLE_N] = [const { OnceLock::new() }; TABLE_N];
    ROWS[ri].get_or_init(|| build_energy_row(ri))
}

fn build_energy_row(ri: usize) -> EnergyRow {
    let mut row = EnergyRow { e1: [0.0; TABLE_N], e2: [0.0; TABLE_N], e1_avg: 0.0, e2_avg: 0.0 };
    // 1. Directional albedos by 1024 visible-normal samples per μ node.
    const N: u32 = 1024;
    let r = ri as f32 / (TABLE_N - 1) as f32;
    let alpha = (r * r).max(MIN_ALPHA);
    let a2 = alpha * alpha;
    for mi in 0..TABLE_N {
        let x = mi as f32 / (TABLE_N - 1) as f32;
        let mu = (x * x).max(1e-5);
        let wo = Vec3::new((1.0 - mu * mu).max(0.0).sqrt(), 0.0, mu);
        let lo = smith_lambda(mu, a2);
        let (mut s1, mut s2) = (0.0f64, 0.0f64);
        for k in 0..N {
            let u = Vec2::new((k as f32 + 0.5) / N as f32, radical_inverse_vdc(k));
            let h = sample_vndf(wo, alpha, u);
            let voh = wo.dot(h);
            let wi = 2.0 * voh * h - wo;
            if wi.z <= 0.0 {
                continue;
            }
            // f·μi/pdf = G2/G1(wo)
            let w = (1.0 + lo) / (1.0 + lo + smith_lambda(wi.z, a2));
            s1 += w as f64;
            s2 += (w * schlick_weight(voh)) as f64;
        }
        row.e1[mi] = (s1 / N as f64) as f32;
        row.e2[mi] = (s2 / N as f64) as f32;
    }
    // 2. Averages of the interpolated curves (what eval uses), by midpoint quadrature.
    const M: usize = 2048;
    let (mut a1, mut a2) = (0.0f64, 0.0f64);
    for k in 0..M {
        let mu = (k as f32 + 0.5) / M as f32;
        let (x1, x2) = interp_mu(&row.e1, &row.e2, mu);
        a1 += (2.0 * x1 * mu) as f64;
        a2 += (2.0 * x2 * mu) as f64;
    }
    row.e1_avg = (a1 / M as f64) as f32;
    row.e2_avg = (a2 / M as f64) as f32;
    row
}

#[inline]
fn interp_mu(row1: &[f32; TABLE_N], row2: &[f32; TABLE_N], mu: f32) -> (f32, f32) {
    let x = mu.clamp(0.0, 1.0).sqrt() * (TABLE_N - 1) as f32;
    let i = (x as usize).min(TABLE_N - 2);
    let f = x - i as f32;
    (row1[i] + (row1[i + 1] - row1[i]) * f, row2[i] + (row2[i + 1] - row2[i]) * f)
}

/// The roughness node below `roughness` and the weight of the one above.
#[inline]
fn roughness_node(roughness: f32) -> (usize, f32) {
    let x = roughness.clamp(0.0, 1.0) * (TABLE_N - 1) as f32;
    let i = (x as usize).min(TABLE_N - 2);
    (i, x - i as f32)
}

// ---------------------------------------------------------------------------------------------
// Directional albedo of the dielectric specular layer with the exact Fresnel reflectance of
// its index η′: E_F(μ) = ∫ F(v·h; η′)·D·V·μi dωi, per η′ a table of roughness rows (built on
// first use), as Cycles tabulates it for its Principled BSDF (`ggx_gen_schlick_ior_s`).

/// One roughness row of a dielectric table: E_F per μ node (√μ spacing, as [`EnergyRow`]).
#[derive(Debug)]
struct DielectricRow([f32; TABLE_N]);

impl DielectricRow {
    /// E_F(μ), interpolated.
    #[inline]
    fn at(&self, mu: f32) -> f32 {
        interp_sqrt_mu(&self.0, mu)
    }
}

/// `row` (nodes at √μ = k/(N − 1)) at `mu`, linearly interpolated.
#[inline]
fn interp_sqrt_mu<const N: usize>(row: &[f32; N], mu: f32) -> f32 {
    let x = mu.clamp(0.0, 1.0).sqrt() * (N - 1) as f32;
    let i = (x as usize).min(N - 2);
    row[i] + (row[i + 1] - row[i]) * (x - i as f32)
}

/// The directional albedo ∫ F(v·h; η)·D·V·μi dωi of a GGX reflection of `alpha` at the √μ node
/// `x` (μ = x²), with the exact dielectric Fresnel of `eta`: 1024 visible-normal samples
/// (f·μi/pdf = F·G2/G1), as [`build_energy_row`].
fn fresnel_albedo(x: f32, alpha: f32, eta: f32) -> f32 {
    const N: u32 = 1024;
    let a2 = alpha * alpha;
    let mu = (x * x).max(1e-5);
    let wo = Vec3::new((1.0 - mu * mu).max(0.0).sqrt(), 0.0, mu);
    let lo = smith_lambda(mu, a2);
    let mut sum = 0.0f64;
    for k in 0..N {
        let u = Vec2::new((k as f32 + 0.5) / N as f32, radical_inverse_vdc(k));
        let h = sample_vndf(wo, alpha, u);
        let voh = wo.dot(h);
        let wi = 2.0 * voh * h - wo;
        if wi.z > 0.0 {
            let g = (1.0 + lo) / (1.0 + lo + smith_lambda(wi.z, a2));
            sum += (fresnel_dielectric(voh, eta) * g) as f64;
        }
    }
    (sum / N as f64) as f32
}

/// The rows of one index η′, and its hemispherical Fresnel average F̄ = 2∫ F(μ) μ dμ.
struct DielectricTable {
    eta: f32,
    f_avg: f32,
    rows: [OnceLock<DielectricRow>; TABLE_N],
}

impl DielectricTable {
    fn new(eta: f32) -> Self {
        const M: usize = 2048;
        let f_avg = (0..M)
            .map(|k| {
                let mu = (k as f32 + 0.5) / M as f32;
                (2.0 * fresnel_dielectric(mu, eta) * mu) as f64
            })
            .sum::<f64>()
            / M as f64;
        DielectricTable { eta, f_avg: f_avg as f32, rows: [const { OnceLock::new() }; TABLE_N] }
    }

    /// Row `ri` (roughness ri / (TABLE_N − 1)), built on first use.
    fn row(&'static self, ri: usize) -> &'static DielectricRow {
        self.rows[ri].get_or_init(|| {
            let r = ri as f32 / (TABLE_N - 1) as f32;
            let alpha = (r * r).max(MIN_ALPHA);
            DielectricRow(std::array::from_fn(|mi| fresnel_albedo(mi as f32 / (TABLE_N - 1) as f32, alpha, self.eta)))
        })
    }
}

/// The table of index `eta` (one per distinct value in the process, kept for its life; each
/// thread remembers the ones it has used, the last one first, so a BSDF finds its table without
/// a lock).
fn dielectric_table(eta: f32) -> &'static DielectricTable {
    use std::cell::RefCell;
    use std::collections::HashMap;
    use std::sync::Mutex;
    static ALL: Mutex<Vec<&'static DielectricTable>> = Mutex::new(Vec::new());
    type Seen = (Option<&'static DielectricTable>, HashMap<u32, &'static DielectricTable>);
    thread_local! {
        static SEEN: RefCell<Seen> = RefCell::new((None, HashMap::new()));
    }
    let key = eta.to_bits();
    SEEN.with(|seen| {
        let mut seen = seen.borrow_mut();
        if let Some(t) = seen.0.filter(|t| t.eta.to_bits() == key) {
            return t;
        }
        let t = match seen.1.get(&key) {
            Some(t) => *t,
            None => {
                let mut all = ALL.lock().unwrap_or_else(|e| e.into_inner());
                let t = match all.iter().find(|t| t.eta.to_bits() == key) {
                    Some(t) => *t,
                    None => {
                        let t: &'static DielectricTable = Box::leak(Box::new(DielectricTable::new(eta)));
                        all.push(t);
                        t
                    }
                };
                seen.1.insert(key, t);
                t
            }
        };
        seen.0 = Some(t);
        t
    })
}

/// The two roughness rows around a roughness, and the weight between them.
#[derive(Clone, Copy)]
struct RoughnessRow {
    lo: &'static EnergyRow,
    hi: &'static EnergyRow,
    f: f32,
}

impl std::fmt::Debug for RoughnessRow {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RoughnessRow").field("f", &self.f).finish_non_exhaustive()
    }
}

impl RoughnessRow {
    fn new(roughness: f32) -> Self {
        let (i, f) = roughness_node(roughness);
        RoughnessRow { lo: energy_row(i), hi: energy_row(i + 1), f }
    }

    /// (E1(μ), E2(μ)).
    fn e(&self, mu: f32) -> (f32, f32) {
        let (a1, a2) = interp_mu(&self.lo.e1, &self.lo.e2, mu);
        let (b1, b2) = interp_mu(&self.hi.e1, &self.hi.e2, mu);
        (a1 + (b1 - a1) * self.f, a2 + (b2 - a2) * self.f)
    }

    fn avg(&self) -> (f32, f32) {
        let (lo, hi) = (self.lo, self.hi);
        (lo.e1_avg + (hi.e1_avg - lo.e1_avg) * self.f, lo.e2_avg + (hi.e2_avg - lo.e2_avg) * self.f)
    }
}

/// Cycles' F82-tint factor b (`fresnel_f82tint_B`): Schlick's reflectance of `f0` at μ = 1/7
/// times (1 − tint), over μ(1 − μ)⁶ there, so that F(1/7) = tint × Schlick's.
#[inline]
fn f82_b(f0: Vec3, tint: Vec3) -> Vec3 {
    const F: f32 = 6.0 / 7.0;
    let f5 = F * F * F * F * F;
    (f0 + (Vec3::ONE - f0) * f5) * (7.0 / (f5 * F)) * (Vec3::ONE - tint)
}

/// A metal's Fresnel reflectance at `cos` (`w` = Schlick's weight (1 − cos)⁵ there). Out of
/// line, so that plain Schlick's (the common case) stays small where it is inlined.
#[inline(never)]
fn metal_fresnel(f: &MetalFresnel, f0: Vec3, cos: f32, w: f32) -> Vec3 {
    match *f {
        MetalFresnel::Constant => f0,
        MetalFresnel::F82 { tint } => {
            let s = (1.0 - cos).clamp(0.0, 1.0);
            let schlick = f0 + (Vec3::ONE - f0) * w;
            (schlick - f82_b(f0, tint) * (cos * w * s)).clamp(Vec3::ZERO, Vec3::ONE)
        }
    }
}

/// The hemispherical average 2∫F(μ)μ dμ of a metal's Fresnel (Cycles' `fresnel_f82_Fss`:
/// F0 + (1 − F0)/21 − b/126).
fn metal_fresnel_average(f: &MetalFresnel, f0: Vec3) -> Vec3 {
    match *f {
        MetalFresnel::Constant => f0,
        MetalFresnel::F82 { tint } => {
            (f0 + (Vec3::ONE - f0) / 21.0 - f82_b(f0, tint) / 126.0).clamp(Vec3::ZERO, Vec3::ONE)
        }
    }
}

/// The glTF metallic-roughness BSDF in its local frame (normal = +z).
#[derive(Debug, Clone, Copy)]
pub struct Bsdf<'a> {
    base: Vec3,
    metallic: f32,
    alpha: f32,
    a2: f32,
    /// The dielectric layer's index η′ (1: no layer).
    eta_d: f32,
    row: RoughnessRow,
    /// The dielectric layer's albedo rows around the roughness (weight `row.f`), where it has one.
    diel: Option<(&'static DielectricRow, &'static DielectricRow)>,
    /// (1 − m)·base / π, or zero.
    diffuse_scale: Vec3,
    /// F_ms,d: the dielectric layer's multiple-scattering colour (grey).
    fms_d: f32,
    /// F_ms,m = F̄·Ē/(1 − F̄·(1 − Ē)) of the metal's Fresnel average F̄: its lobe is scaled by
    /// 1 + F_ms,m·(1 − E(μo))/E(μo) (Cycles' multiscatter GGX); zero without a metal.
    fms_m: Vec3,
    /// The lobes read the albedo tables (a specular layer, or a metal's multiple scattering);
    /// false for a pure Lambertian base, whose lookups are then skipped.
    layered: bool,
    /// The glass lobe of a transmissive material and its weight (1 − m)·transmission; the
    /// opaque lobes above are weighted by the rest.
    glass: Option<(f32, Glass)>,
    /// A clear coat over everything above ([`Coat`]), where the material has one (built once
    /// per material, so the BSDF stays small).
    coat: Option<&'a Coat>,
    /// The metal's Fresnel where it is not plain Schlick (the material's, borrowed).
    metal_fresnel: Option<&'a MetalFresnel>,
    /// The dielectric layer's Specular Tint where it is not white (the material's, borrowed;
    /// [`Bsdf::with_specular_tint`]).
    spec_tint: Option<&'a Vec3>,
    /// The specular lobes' roughness (α_x along the frame's tangent, α_y across) where they
    /// are anisotropic ([`Bsdf::with_anisotropic_alphas`]); None: isotropic, `alpha`.
    aniso: Option<(f32, f32)>,
}

impl<'a> Bsdf<'a> {
    /// A BSDF from glTF parameters: linear base colour, metallic, perceptual roughness,
    /// `KHR_materials_specular` specularFactor and `KHR_materials_ior` ior.
    pub fn new(base_color: Vec3, metallic: f32, roughness: f32, specular: f32, ior: f32) -> Self {
        let base = base_color.clamp(Vec3::ZERO, Vec3::ONE);
        let metallic = if metallic.is_finite() { metallic.clamp(0.0, 1.0) } else { 0.0 };
        let roughness = if roughness.is_finite() { roughness.clamp(0.0, 1.0) } else { 1.0 };
        let specular = if specular.is_finite() { specular.max(0.0) } else { 1.0 };
        let ior = if ior.is_finite() && ior >= 1.0 { ior } else { 1.5 };
        // The dielectric layer as Cycles' Principled BSDF has it: F0 = F0(ior)·specular (Specular
        // IOR Level × 2), and the exact Fresnel of the index η′ with that F0.
        let r = (ior - 1.0) / (ior + 1.0);
        let f0_d = ((r * r) * specular).min(0.99);
        let eta_d = if f0_d <= 0.0 {
            1.0
        } else if specular == 1.0 {
            ior
        } else {
            (1.0 + f0_d.sqrt()) / (1.0 - f0_d.sqrt())
        };
        let alpha = (roughness * roughness).max(MIN_ALPHA);
        let row = RoughnessRow::new(roughness);
        let (a1, _) = row.avg();
        let table = (eta_d > 1.0).then(|| dielectric_table(eta_d));
        let ri = roughness_node(roughness).0;
        let diel = table.map(|t| (t.row(ri), t.row(ri + 1)));
        // 1. Multiple scattering, as Cycles' multiscatter GGX keeps it: each specular lobe is
        //    scaled by 1 + F_ms·(1 − E(μo))/E(μo), F_ms = F̄·Ē/(1 − F̄·(1 − Ē)) of its Fresnel
        //    average F̄ (none where single scattering keeps nearly everything).
        let has_ms = 1.0 - a1 > 1e-4;
        let fms = |f_avg: f32| f_avg * a1 / (1.0 - f_avg * (1.0 - a1));
        let fms_d = match table {
            Some(t) if has_ms => fms(t.f_avg),
            _ => 0.0,
        };
        // (a dielectric's metal part is multiplied by 0 below: skipped, the same bits)
        let fms_m = if has_ms && metallic > 0.0 {
            let f_avg = base + (Vec3::ONE - base) / 21.0;
            Vec3::new(fms(f_avg.x), fms(f_avg.y), fms(f_avg.z))
        } else {
            Vec3::ZERO
        };
        // 2. The diffuse base under the dielectric layer: what the layer does not reflect at μo
        //    (Cycles' layering of its Principled BSDF), so the albedo is E_d(μo) + base·(1 − E_d(μo)).
        let diffuse_scale = if metallic < 1.0 { base * ((1.0 - metallic) * FRAC_1_PI) } else { Vec3::ZERO };
        let layered = diel.is_some() || fms_m != Vec3::ZERO;
        Bsdf {
            base,
            metallic,
            alpha,
            a2: alpha * alpha,
            eta_d,
            row,
            diel,
            diffuse_scale,
            fms_d,
            fms_m,
            layered,
            glass: None,
            coat: None,
            metal_fresnel: None,
            spec_tint: None,
            aniso: None,
        }
    }

    /// The anisotropic roughness (α_x, α_y) of a perceptual `roughness` (α = roughness²) split
    /// by `kind`, and the roughness its albedo tables are read at, (α_x·α_y)^¼ (Cycles'
    /// `microfacet_ggx_preserve_energy`): `roughness` for Cycles' kinds unless a side saturated
    /// at 1, as Cycles' GGX set-up saturates it.
    pub fn anisotropic_alphas(roughness: f32, kind: crate::scene::AnisotropyKind) -> ((f32, f32), f32) {
        let r = if roughness.is_finite() { roughness.clamp(0.0, 1.0) } else { 1.0 };
        let alpha = r * r;
        let (ax, ay) = match kind {
            crate::scene::AnisotropyKind::Scale(s) => ((alpha * s.x).clamp(0.0, 1.0), (alpha * s.y).clamp(0.0, 1.0)),
            crate::scene::AnisotropyKind::Khr(strength) => (alpha + (1.0 - alpha) * strength * strength, alpha),
        };
        ((ax.max(MIN_ALPHA), ay.max(MIN_ALPHA)), (ax * ay).sqrt().sqrt())
    }

    /// The same BSDF with anisotropic specular lobes (metal and dielectric layer) of roughness
    /// `alphas` = (α_x, α_y) ([`Bsdf::anisotropic_alphas`]); build it with the table roughness
    /// that function gives. The frame's x axis is then the tangent
    /// ([`SurfaceBsdf::with_tangent`]). The glass and coat lobes stay isotropic, as in Cycles.
    pub fn with_anisotropic_alphas(self, alphas: (f32, f32)) -> Self {
        Bsdf { aniso: Some(alphas), ..self }
    }

    /// A half vector of the specular lobe by its visible normals.
    #[inline]
    fn sample_specular_h(&self, wo: Vec3, u2: Vec2) -> Vec3 {
        match self.aniso {
            None => sample_vndf(wo, self.alpha, u2),
            Some((ax, ay)) => sample_vndf_xy(wo, ax, ay, u2),
        }
    }

    /// Whether the specular lobes are anisotropic (the frame's tangent then matters).
    pub fn is_anisotropic(&self) -> bool {
        self.aniso.is_some()
    }

    /// [`Bsdf::new`] with another base colour, from a BSDF built with metallic 0 (whatever its
    /// base colour): the same bits. With metallic 0 the base colour enters only the base and
    /// the diffuse lobe's scale; every other field (the roughness row, the dielectric layer's
    /// tables, multiple scattering) is the material's own, so it is built once per material.
    #[inline]
    pub fn with_base(self, base_color: Vec3) -> Self {
        debug_assert!(self.metallic == 0.0, "with_base needs a BSDF with metallic 0");
        // Bsdf::new's expressions for these two fields
        let base = base_color.clamp(Vec3::ZERO, Vec3::ONE);
        let diffuse_scale = if self.metallic < 1.0 { base * ((1.0 - self.metallic) * FRAC_1_PI) } else { Vec3::ZERO };
        Bsdf { base, diffuse_scale, ..self }
    }

    /// The same BSDF with a metal Fresnel other than plain Schlick ([`MetalFresnel`]: Cycles'
    /// F82 tint, or the base colour at every angle); plain Schlick leaves it as it is.
    /// (Out of line: most materials have plain Schlick and do not call it.)
    #[inline(never)]
    pub fn with_metal_fresnel(self, f: &'a MetalFresnel) -> Self {
        if f.is_schlick() {
            return self;
        }
        let mut out = Bsdf { metal_fresnel: Some(f), ..self };
        // the multiple-scattering factor from this Fresnel's hemispherical average
        let (a1, _) = out.row.avg();
        if 1.0 - a1 > 1e-4 && out.metallic > 0.0 {
            let f_avg = metal_fresnel_average(f, out.base);
            let fms = |f: f32| f * a1 / (1.0 - f * (1.0 - a1));
            out.fms_m = Vec3::new(fms(f_avg.x), fms(f_avg.y), fms(f_avg.z));
            out.layered = out.diel.is_some() || out.fms_m != Vec3::ZERO;
        }
        out
    }

    /// The same BSDF with a coloured Specular Tint on its dielectric layer (Blender's Principled
    /// BSDF, a coloured `KHR_materials_specular` specularColorFactor). Cycles gives the layer
    /// F0·tint head-on and 1 at grazing, between them the exact Fresnel F of η′ remapped:
    /// `F_t = F0·t + (1 − F0·t)·s`, `s = (F − F0)/(1 − F0)`, i.e. `t·F + (1 − t)·s`, with the
    /// multiple-scattering colour of its average, and the base under the layer weighed by the
    /// largest channel of the layer's albedo (`closure_layering_weight`). A white tint, or no
    /// dielectric layer, leaves the BSDF as it is. (Out of line: most materials have none.)
    #[inline(never)]
    pub fn with_specular_tint(self, tint: &'a Vec3) -> Self {
        if *tint == Vec3::ONE || self.diel.is_none() || self.metallic >= 1.0 {
            return self;
        }
        Bsdf { spec_tint: Some(tint), ..self }
    }

    /// The dielectric layer's F0 (that of η′).
    #[inline]
    fn f0_d(&self) -> f32 {
        let r = (self.eta_d - 1.0) / (self.eta_d + 1.0);
        r * r
    }

    /// The tinted layer's Fresnel at `cos` with its multiple-scattering scale at a μo whose
    /// E(μo) is `e1o` (per channel; [`Bsdf::with_specular_tint`]).
    #[inline]
    fn tinted_fresnel(&self, tint: Vec3, cos: f32, e1o: f32) -> Vec3 {
        let f0 = self.f0_d();
        // F0·tint is a reflectance: at most 1 (Cycles saturates it)
        let tint = tint.min(Vec3::splat(1.0 / f0));
        let f = fresnel_dielectric(cos, self.eta_d);
        let s = ((f - f0) / (1.0 - f0)).clamp(0.0, 1.0);
        (tint * (f - s) + Vec3::splat(s)) * self.tinted_boost(tint, e1o)
    }

    /// Cycles' multiple-scattering scale of the tinted layer at E(μo) = `e1o`, per channel:
    /// 1 + F_ms·(1 − E)/E with F_ms from the remapped average F̄_t = F0·t + (1 − F0·t)·s̄,
    /// s̄ = (F̄ − F0)/(1 − F0).
    fn tinted_boost(&self, tint: Vec3, e1o: f32) -> Vec3 {
        if self.fms_d == 0.0 {
            return Vec3::ONE;
        }
        // F̄ back from F_ms,d = F̄·Ē/(1 − F̄·(1 − Ē))
        let (a1, _) = self.row.avg();
        let f_avg = self.fms_d / (a1 + self.fms_d * (1.0 - a1));
        let f0 = self.f0_d();
        let s_avg = ((f_avg - f0) / (1.0 - f0)).clamp(0.0, 1.0);
        let f0t = (tint * f0).min(Vec3::ONE);
        let fss = f0t + (Vec3::ONE - f0t) * s_avg;
        let fms = fss * a1 / (Vec3::ONE - fss * (1.0 - a1));
        Vec3::ONE + fms * ((1.0 - e1o).max(0.0) / e1o.max(1e-3))
    }

    /// The tinted layer's albedo, from the untinted one `e_f` (`e1` = E(μ) with F = 1), in its
    /// brightest channel, which weighs the base under it as Cycles' `closure_layering_weight`
    /// does.
    #[inline(never)]
    fn tinted_e_d(&self, tint: Vec3, e_f: f32, e1: f32) -> f32 {
        let f0 = self.f0_d();
        let t = tint.max_element().min(1.0 / f0);
        // ∫ s·D·V·μi = (E_F − F0·E1)/(1 − F0): the remap is linear in F
        let e_s = ((e_f - f0 * e1) / (1.0 - f0)).max(0.0);
        let boost = self.tinted_boost(Vec3::splat(t), e1).x;
        ((e_s + t * (e_f - e_s)) * boost).clamp(0.0, 1.0)
    }

    /// The same BSDF with glTF's `KHR_materials_transmission` (Blender's Transmission Weight):
    /// the dielectric part becomes glass by `transmission` in [0, 1] (a rough dielectric
    /// interface of the BSDF's roughness and ior whose refracted light is tinted by the square
    /// root of the base colour at each crossing, the base colour through a solid object). Metals do not transmit: the glass lobe weighs (1 − metallic)·transmission, and
    /// every opaque lobe the rest (exact for metallic 0 or 1).
    #[inline(always)]
    pub fn with_transmission(self, transmission: f32, ior: f32) -> Self {
        let t = if transmission.is_finite() { transmission.clamp(0.0, 1.0) } else { 0.0 };
        let weight = (1.0 - self.metallic) * t;
        if !(weight > 0.0) {
            return self;
        }
        let ior = if ior.is_finite() && ior >= 1.0 { ior } else { 1.5 };
        // each interface tints by √base, so light through a solid object (in and out) takes the
        // base colour, as in Cycles' Principled BSDF
        let tint = Vec3::new(self.base.x.sqrt(), self.base.y.sqrt(), self.base.z.sqrt());
        Bsdf { glass: Some((weight, Glass::new(self.alpha.sqrt(), ior, tint))), ..self }
    }

    /// The same BSDF under a clear coat ([`Coat`], Blender's Principled Coat); None leaves it
    /// uncoated.
    #[inline(always)]
    pub fn with_coat(self, coat: Option<&'a Coat>) -> Self {
        Bsdf { coat, ..self }
    }

    /// Whether the BSDF has a specular lobe (a dielectric layer, a metal, glass or a coat);
    /// false for a pure Lambertian base.
    #[inline]
    pub fn has_specular(&self) -> bool {
        self.layered || self.glass.is_some() || self.coat.is_some()
    }

    /// Whether the BSDF transmits (light from below the surface counts).
    #[inline]
    pub fn transmits(&self) -> bool {
        self.glass.is_some()
    }

    /// The BSDF seen from inside its object (`inside`: the outgoing direction is on the back of
    /// the surface), for the glass lobe's relative index of refraction.
    #[inline(always)]
    pub fn seen_from_inside(self, inside: bool) -> Self {
        match self.glass {
            Some((w, g)) => Bsdf { glass: Some((w, g.facing(inside))), ..self },
            None => self,
        }
    }

    /// The smallest GGX alpha (roughness², clamped) of its lobes: the base's, or the coat's
    /// where that is sharper.
    pub fn alpha(&self) -> f32 {
        let alpha = self.aniso.map_or(self.alpha, |(ax, ay)| ax.min(ay));
        self.coat.map_or(alpha, |c| alpha.min(c.alpha))
    }

    /// Directional albedo of the dielectric specular layer at `mu` (what the diffuse base
    /// loses), its multiple-scattering energy included; `e1` is the lobe's albedo E(μ) with F = 1.
    #[inline]
    fn e_d(&self, mu: f32, e1: f32) -> f32 {
        let Some((lo, hi)) = self.diel else { return 0.0 };
        let (a, b) = (lo.at(mu), hi.at(mu));
        if let Some(t) = self.spec_tint {
            return self.tinted_e_d(*t, a + (b - a) * self.row.f, e1);
        }
        ((a + (b - a) * self.row.f) * self.ms_boost(e1)).clamp(0.0, 1.0)
    }

    /// The dielectric lobe's scale for the energy single scattering loses at μo, whose E(μo)
    /// is `e1` (Cycles' multiscatter GGX).
    #[inline]
    fn ms_boost(&self, e1: f32) -> f32 {
        1.0 + self.fms_d * (1.0 - e1).max(0.0) / e1.max(1e-3)
    }

    /// Whether the cosine-sampled (diffuse) lobe is present.
    #[inline]
    fn has_cosine_lobes(&self) -> bool {
        self.diffuse_scale != Vec3::ZERO
    }

    /// The metal lobe's scale for the energy single scattering loses at μo, whose E(μo) is
    /// `e1` (Cycles' multiscatter GGX; 1 for `e1` = 1).
    #[inline]
    fn metal_boost(&self, e1: f32) -> Vec3 {
        Vec3::ONE + self.fms_m * ((1.0 - e1).max(0.0) / e1.max(1e-3))
    }

    /// Combined Fresnel (dielectric and metal, mixed by metallic) at `cos`.
    #[inline]
    fn fresnel(&self, cos: f32) -> Vec3 {
        self.fresnel_boosted(cos, 1.0)
    }

    /// [`Bsdf::fresnel`] with the dielectric part scaled for multiple scattering at a μo
    /// whose E(μo) is `e1o` (1: no scaling).
    #[inline(always)]
    fn fresnel_boosted(&self, cos: f32, e1o: f32) -> Vec3 {
        let fd = if self.diel.is_some() {
            if let Some(t) = self.spec_tint {
                return self.tinted_fresnel_mix(*t, cos, e1o);
            }
            fresnel_dielectric(cos, self.eta_d) * self.ms_boost(e1o)
        } else {
            0.0
        };
        let dielectric = Vec3::splat((1.0 - self.metallic) * fd);
        if self.metallic == 0.0 {
            // (+ fm·0 = + 0: the same bits)
            return dielectric;
        }
        dielectric + self.metal_fresnel_at(cos) * self.metal_boost(e1o) * self.metallic
    }

    /// The metal's Fresnel reflectance at `cos`.
    #[inline(always)]
    fn metal_fresnel_at(&self, cos: f32) -> Vec3 {
        let w = schlick_weight(cos);
        match self.metal_fresnel {
            None => self.base + (Vec3::ONE - self.base) * w,
            Some(f) => metal_fresnel(f, self.base, cos, w),
        }
    }

    /// [`Bsdf::fresnel_boosted`] with a tinted dielectric layer.
    #[inline(never)]
    fn tinted_fresnel_mix(&self, tint: Vec3, cos: f32, e1o: f32) -> Vec3 {
        let dielectric = self.tinted_fresnel(tint, cos, e1o) * (1.0 - self.metallic);
        if self.metallic == 0.0 {
            return dielectric;
        }
        dielectric + self.metal_fresnel_at(cos) * self.metal_boost(e1o) * self.metallic
    }

    /// Probability of choosing the specular lobe for `wo`.
    #[inline]
    fn spec_probability(&self, wo: Vec3) -> f32 {
        if self.diel.is_none() && self.metallic == 0.0 {
            // No specular lobe (a pure Lambertian base): its albedo below is exactly 0.
            return 0.0;
        }
        let (ws, wd) = self.lobe_albedos(wo);
        let sum = ws + wd;
        if sum > 0.0 {
            ws / sum
        } else {
            0.0
        }
    }

    /// The specular lobe's and the cosine lobes' albedo estimates at `wo` (luminance).
    #[inline]
    fn lobe_albedos(&self, wo: Vec3) -> (f32, f32) {
        let ws = luminance(self.fresnel(wo.z));
        let wd = if !self.layered {
            (1.0 - self.metallic) * luminance(self.base)
        } else if self.has_cosine_lobes() {
            // the diffuse lobe's albedo at μo: the base under the layer
            let e = self.row.e(wo.z);
            (1.0 - self.metallic) * luminance(self.base) * (1.0 - self.e_d(wo.z, e.0))
        } else {
            0.0
        };
        (ws, wd)
    }

    /// f(wo, wi)·|cos θi| (local frame, `wo` above the surface; `wi` below counts only for
    /// a transmissive BSDF).
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Vec3 {
        self.eval_bumped(wo, wi, None)
    }

    /// [`Bsdf::eval`] for a normal-mapped surface where `bump` is given (see [`Bump`]).
    fn eval_bumped(&self, wo: Vec3, wi: Vec3, bump: Option<Bump>) -> Vec3 {
        match self.coat {
            None => self.eval_under(wo, wi, bump),
            Some(c) => {
                let under = self.eval_under(wo, wi, bump);
                let under = if under == Vec3::ZERO { under } else { under * c.under_weight(wo.z) };
                under + Vec3::splat(c.eval(wo, wi))
            }
        }
    }

    /// Solid-angle pdf of [`Bsdf::sample`] producing `wi`.
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        self.pdf_bumped(wo, wi, None)
    }

    /// [`Bsdf::pdf`] for a normal-mapped surface where `bump` is given (its diffuse lobe is
    /// sampled about the mapped normal).
    fn pdf_bumped(&self, wo: Vec3, wi: Vec3, bump: Option<Bump>) -> f32 {
        match self.coat {
            None => self.pdf_under(wo, wi, bump),
            Some(c) => {
                let pc = self.coat_probability(c, wo);
                let under = if pc < 1.0 { self.pdf_under(wo, wi, bump) * (1.0 - pc) } else { 0.0 };
                under + if pc > 0.0 { c.pdf(wo, wi) * pc } else { 0.0 }
            }
        }
    }

    /// Samples wi: `u1` picks the lobe, `u2` the direction. None when the BSDF is black, the
    /// sample falls below the surface (through it, for an opaque BSDF), or its pdf is zero.
    pub fn sample(&self, wo: Vec3, u2: Vec2, u1: f32) -> Option<BsdfSample> {
        self.sample_bumped(wo, u2, u1, None)
    }

    /// [`Bsdf::sample`] with the bump shadowing of [`Bsdf::eval_bumped`] in the sample's value.
    fn sample_bumped(&self, wo: Vec3, u2: Vec2, u1: f32, bump: Option<Bump>) -> Option<BsdfSample> {
        let Some(c) = self.coat else { return self.sample_under(wo, u2, u1, bump) };
        // 1. The coat or what lies under it, by their albedos at μo (u1 reused within), 2. the
        //    mixture's pdf and value.
        let pc = self.coat_probability(c, wo);
        let wi = if u1 < pc {
            c.sample_direction(wo, u2)?
        } else {
            self.sample_under(wo, u2, ((u1 - pc) / (1.0 - pc)).min(ONE_BELOW), bump)?.wi
        };
        weighted_sample(wi, self.pdf_bumped(wo, wi, bump), || self.eval_bumped(wo, wi, bump))
    }

    /// The probability of sampling the coat for `wo`: its albedo against the rest's, as the
    /// coat leaves it.
    #[inline]
    fn coat_probability(&self, c: &Coat, wo: Vec3) -> f32 {
        if wo.z <= 0.0 {
            return 0.0;
        }
        let coat = c.albedo(wo.z);
        let under = luminance(c.under_weight(wo.z)) * self.albedo_estimate(wo);
        if coat + under > 0.0 {
            coat / (coat + under)
        } else {
            0.0
        }
    }

    /// A rough estimate of the albedo under the coat at `wo` (lobe selection only).
    fn albedo_estimate(&self, wo: Vec3) -> f32 {
        let (ws, wd) = self.lobe_albedos(wo);
        match &self.glass {
            None => ws + wd,
            Some((w, _)) => (ws + wd) * (1.0 - w) + w,
        }
    }

    /// f·|cos θi| of everything under the coat (all of it for an uncoated BSDF).
    fn eval_under(&self, wo: Vec3, wi: Vec3, bump: Option<Bump>) -> Vec3 {
        match &self.glass {
            None => self.eval_opaque(wo, wi, bump),
            Some((w, g)) => {
                let opaque =
                    if wi.z > 0.0 || bump.is_some() { self.eval_opaque(wo, wi, bump) * (1.0 - w) } else { Vec3::ZERO };
                opaque + g.eval(wo, wi) * *w
            }
        }
    }

    /// The pdf of [`Bsdf::sample_under`].
    fn pdf_under(&self, wo: Vec3, wi: Vec3, bump: Option<Bump>) -> f32 {
        match &self.glass {
            None => self.pdf_opaque(wo, wi, bump),
            // the lobes are chosen by their weights
            Some((w, g)) => {
                let opaque = if *w < 1.0 { self.pdf_opaque(wo, wi, bump) * (1.0 - w) } else { 0.0 };
                opaque + g.pdf(wo, wi) * w
            }
        }
    }

    /// Samples everything under the coat (all of it for an uncoated BSDF).
    fn sample_under(&self, wo: Vec3, u2: Vec2, u1: f32, bump: Option<Bump>) -> Option<BsdfSample> {
        let Some((w, g)) = &self.glass else { return self.sample_opaque(wo, u2, u1, bump) };
        // 1. A lobe by its weight (u1 reused within it), 2. the mixture's pdf and value.
        let wi = if u1 < *w {
            g.sample_direction(wo, u2, (u1 / w).min(ONE_BELOW))?
        } else {
            self.sample_opaque(wo, u2, ((u1 - w) / (1.0 - w)).min(ONE_BELOW), bump)?.wi
        };
        weighted_sample(wi, self.pdf_under(wo, wi, bump), || self.eval_under(wo, wi, bump))
    }

    /// The opaque lobes' f·cos θi; zero unless both directions are above the surface (for a
    /// normal-mapped surface see [`Bsdf::eval_opaque_mapped`]).
    fn eval_opaque(&self, wo: Vec3, wi: Vec3, bump: Option<Bump>) -> Vec3 {
        if let Some(b) = bump {
            return self.eval_opaque_mapped(wo, wi, b);
        }
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return Vec3::ZERO;
        }
        let mut f = Vec3::ZERO;
        // E(μo) with F = 1, where a table is read at all
        let mut e1o = 1.0;
        if !self.layered {
            f += self.diffuse_scale;
        } else {
            e1o = self.row.e(wo.z).0;
            // the diffuse base under the layer
            if self.diffuse_scale != Vec3::ZERO {
                f += self.diffuse_scale * (1.0 - self.e_d(wo.z, e1o));
            }
        }
        if let Some(s) = self.specular_lobe(wo, wi, e1o) {
            f += s;
        }
        let r = f * wi.z;
        if r.is_finite() {
            r
        } else {
            Vec3::ZERO
        }
    }

    /// The specular (GGX) lobe's f for `wo`, `wi` above the surface, with `e1o` = E(μo) for its
    /// boosted Fresnel; None where there is no lobe (a pure Lambertian base) or the half vector
    /// is below the surface.
    #[inline]
    fn specular_lobe(&self, wo: Vec3, wi: Vec3, e1o: f32) -> Option<Vec3> {
        let h = if self.diel.is_some() || self.metallic > 0.0 { (wo + wi).normalize_or_zero() } else { Vec3::ZERO };
        if !(h.z > 0.0) {
            return None;
        }
        let voh = wo.dot(h).max(0.0);
        let dv = match self.aniso {
            None => {
                let d = ggx_d(h.z, self.a2);
                let g2 = 1.0 / (1.0 + smith_lambda(wo.z, self.a2) + smith_lambda(wi.z, self.a2));
                let v = g2 / (4.0 * wo.z * wi.z);
                d * v
            }
            Some((ax, ay)) => specular_dv_aniso(wo, wi, h, ax, ay),
        };
        Some(self.fresnel_boosted(voh, e1o) * dv)
    }

    /// [`Bsdf::eval_opaque`] for a normal-mapped surface, as Cycles' Principled BSDF has it: the
    /// specular lobes (and M) on this frame's normal (the mapped normal, corrected by
    /// [`ensure_valid_specular_reflection`]), the diffuse lobe on the mapped normal itself
    /// (`b.mapped`, whose cosine it takes) times [`bump_shadowing`] against the smooth normal.
    fn eval_opaque_mapped(&self, wo: Vec3, wi: Vec3, b: Bump) -> Vec3 {
        let cos_diffuse = b.mapped.dot(wi);
        if wo.z <= 0.0 || (wi.z <= 0.0 && cos_diffuse <= 0.0) {
            return Vec3::ZERO;
        }
        // 1. The diffuse lobe (under the specular layer's albedo at μo, where there is one).
        let e1o = if self.layered { self.row.e(wo.z).0 } else { 1.0 };
        let mut r = Vec3::ZERO;
        if cos_diffuse > 0.0 && self.diffuse_scale != Vec3::ZERO {
            let layer = if self.layered { 1.0 - self.e_d(wo.z, e1o) } else { 1.0 };
            r += self.diffuse_scale * (layer * bump_shadowing(b.smooth, b.mapped, wi) * cos_diffuse);
        }
        if wi.z <= 0.0 {
            return if r.is_finite() { r } else { Vec3::ZERO };
        }
        // 2. The specular lobe, as in `eval_opaque`.
        let mut f = Vec3::ZERO;
        if let Some(s) = self.specular_lobe(wo, wi, e1o) {
            f += s;
        }
        let r = r + f * wi.z;
        if r.is_finite() {
            r
        } else {
            Vec3::ZERO
        }
    }

    /// The opaque lobes' pdf.
    fn pdf_opaque(&self, wo: Vec3, wi: Vec3, bump: Option<Bump>) -> f32 {
        // the diffuse lobe's cosine: about the mapped normal where there is a normal map
        let cos_diffuse = bump.map_or(wi.z, |b| b.mapped.dot(wi));
        if wo.z <= 0.0 || (wi.z <= 0.0 && cos_diffuse <= 0.0) {
            return 0.0;
        }
        let ps = self.spec_probability(wo);
        let mut pdf = if cos_diffuse > 0.0 { (1.0 - ps) * cos_diffuse * FRAC_1_PI } else { 0.0 };
        if ps > 0.0 && wi.z > 0.0 {
            let h = (wo + wi).normalize_or_zero();
            if h.z > 0.0 && wo.dot(h) > 0.0 {
                pdf += match self.aniso {
                    None => {
                        let g1 = 1.0 / (1.0 + smith_lambda(wo.z, self.a2));
                        ps * g1 * ggx_d(h.z, self.a2) / (4.0 * wo.z)
                    }
                    Some((ax, ay)) => ps * specular_pdf_aniso(wo, h, ax, ay),
                };
            }
        }
        if pdf.is_finite() {
            pdf
        } else {
            0.0
        }
    }

    /// Samples the opaque lobes.
    fn sample_opaque(&self, wo: Vec3, u2: Vec2, u1: f32, bump: Option<Bump>) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        let ps = self.spec_probability(wo);
        let (wi, above) = if u1 < ps {
            let h = self.sample_specular_h(wo, u2);
            let wi = 2.0 * wo.dot(h) * h - wo;
            (wi, wi.z > 0.0)
        } else {
            if !self.has_cosine_lobes() {
                return None;
            }
            // the diffuse lobe about its own normal: the mapped one where there is a normal map
            let local = sample_cosine_hemisphere(u2);
            match bump {
                None => (local, local.z > 0.0),
                Some(b) => {
                    let (t, bt) = orthonormal_basis(b.mapped);
                    let wi = t * local.x + bt * local.y + b.mapped * local.z;
                    (wi, b.mapped.dot(wi) > 0.0)
                }
            }
        };
        if !above {
            return None;
        }
        weighted_sample(wi, self.pdf_opaque(wo, wi, bump), || self.eval_opaque(wo, wi, bump))
    }
}

/// A clear coat: a GGX reflection of its own roughness over the rest of the BSDF, as in
/// Blender's Principled BSDF (Cycles' `svm_closure.h`, the coat layer):
///
/// ```text
/// f = w·F(v·h)·D_c·V_c  +  (1 − w·E_c(μo)) · mix(1, tint^(1/cos θt), w) · f_under
/// ```
///
/// `F` is the exact dielectric Fresnel reflectance at the coat's ior (as in Cycles); `E_c(μo)`
/// the coat lobe's own directional albedo, integrated once per material (so a coat over a
/// white base reflects exactly 1); θt the view ray's angle refracted into the coat (Beer's law
/// through a coat of unit thickness whose colour head-on is `tint`). Like Cycles, the layering
/// depends on the outgoing direction only, so a coated BSDF is not reciprocal. Not modelled:
/// Cycles' multiple-scattering compensation of the coat lobe (under 0.1 % of its albedo at
/// ior 1.5). A coated material's emission is dimmed by the same weight, as in Cycles
/// ([`super::RenderScene::emission`]). Built once per material
/// ([`super::RenderScene`] holds them) and borrowed by each hit's [`Bsdf`].
#[derive(Debug, Clone, Copy)]
pub struct Coat {
    weight: f32,
    alpha: f32,
    a2: f32,
    ior: f32,
    /// E_c at √μ nodes (single scattering, exact Fresnel).
    albedo: [f32; COAT_MU],
    /// ln(tint) (zero: no tint).
    log_tint: Vec3,
    /// 1/ior².
    inv_ior2: f32,
}

/// Nodes of a coat's albedo curve, in √μ.
const COAT_MU: usize = 32;

impl Coat {
    /// A coat of `weight` (0…1), perceptual `roughness`, `ior` and head-on `tint`; None when the
    /// weight is 0 (or not finite).
    pub fn new(weight: f32, roughness: f32, ior: f32, tint: Vec3) -> Option<Coat> {
        let weight = if weight.is_finite() { weight.clamp(0.0, 1.0) } else { 0.0 };
        if !(weight > 0.0) {
            return None;
        }
        let roughness = if roughness.is_finite() { roughness.clamp(0.0, 1.0) } else { 0.0 };
        let ior = if ior.is_finite() && ior >= 1.0 { ior } else { 1.5 };
        let alpha = (roughness * roughness).max(MIN_ALPHA);
        // a tint of 0 in a channel absorbs it entirely (ln → a large negative number)
        let log_tint =
            if tint.is_finite() { tint.clamp(Vec3::ZERO, Vec3::ONE).max(Vec3::splat(1e-12)) } else { Vec3::ONE };
        let log_tint = Vec3::new(log_tint.x.ln(), log_tint.y.ln(), log_tint.z.ln());
        let mut coat = Coat {
            weight,
            alpha,
            a2: alpha * alpha,
            ior,
            albedo: [0.0; COAT_MU],
            log_tint,
            inv_ior2: 1.0 / (ior * ior),
        };
        // The lobe's albedo per μ node.
        coat.albedo =
            std::array::from_fn(|mi| fresnel_albedo(mi as f32 / (COAT_MU - 1) as f32, alpha, ior).clamp(0.0, 1.0));
        Some(coat)
    }

    /// The coat's albedo at `mu`, weight included: w·E_c(μ).
    #[inline]
    fn albedo(&self, mu: f32) -> f32 {
        self.weight * interp_sqrt_mu(&self.albedo, mu)
    }

    /// What the coat lets through of the emission under it toward a direction at `mu` (cosine
    /// to the normal, either side): as it weights the layers under it.
    #[inline]
    pub(crate) fn emission_weight(&self, mu: f32) -> Vec3 {
        self.under_weight(mu.abs().min(1.0))
    }

    /// What reaches the layers under the coat and comes back, seen from `mu`.
    #[inline]
    fn under_weight(&self, mu: f32) -> Vec3 {
        let through = 1.0 - self.albedo(mu);
        if self.log_tint == Vec3::ZERO {
            return Vec3::splat(through);
        }
        // Beer's law along the refracted view ray, blended by the weight as Cycles does
        let cos_t = (1.0 - self.inv_ior2 * (1.0 - mu * mu)).max(1e-6).sqrt();
        let t = Vec3::new(
            (self.log_tint.x / cos_t).exp(),
            (self.log_tint.y / cos_t).exp(),
            (self.log_tint.z / cos_t).exp(),
        );
        (Vec3::ONE + (t - Vec3::ONE) * self.weight) * through
    }

    /// The coat lobe's f·cos θi, weight included.
    #[inline]
    fn eval(&self, wo: Vec3, wi: Vec3) -> f32 {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return 0.0;
        }
        let h = (wo + wi).normalize_or_zero();
        if h.z <= 0.0 {
            return 0.0;
        }
        let f = fresnel_dielectric(wo.dot(h).max(0.0), self.ior);
        let g2 = 1.0 / (1.0 + smith_lambda(wo.z, self.a2) + smith_lambda(wi.z, self.a2));
        let r = self.weight * f * ggx_d(h.z, self.a2) * g2 / (4.0 * wo.z);
        if r.is_finite() {
            r
        } else {
            0.0
        }
    }

    /// The pdf of [`Coat::sample_direction`] (visible normals).
    #[inline]
    fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return 0.0;
        }
        let h = (wo + wi).normalize_or_zero();
        if h.z <= 0.0 || wo.dot(h) <= 0.0 {
            return 0.0;
        }
        let g1 = 1.0 / (1.0 + smith_lambda(wo.z, self.a2));
        let pdf = g1 * ggx_d(h.z, self.a2) / (4.0 * wo.z);
        if pdf.is_finite() {
            pdf
        } else {
            0.0
        }
    }

    /// A reflected direction about a visible microfacet normal; None below the surface.
    #[inline]
    fn sample_direction(&self, wo: Vec3, u2: Vec2) -> Option<Vec3> {
        let h = sample_vndf(wo, self.alpha, u2);
        let wi = 2.0 * wo.dot(h) * h - wo;
        (wi.z > 0.0).then_some(wi)
    }
}

/// A normal-mapped surface's two extra normals, in the local frame of [`Bsdf`] (whose +z is
/// the mapped normal corrected for specular reflection): Cycles' diffuse closure uses the
/// mapped normal as it is, and masks it against the smooth normal.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bump {
    /// The interpolated vertex normal (before the normal map), unit.
    pub smooth: Vec3,
    /// The normal-mapped normal before the specular correction, unit.
    pub mapped: Vec3,
}

/// Cycles' bump shadowing term for a normal-mapped diffuse lobe (`bump_shadowing_term` with
/// Bump Map Correction, Blender's default: Conty Estevez et al., "A Microfacet-Based Shadowing
/// Function to Solve the Bump Terminator Problem", 2019), for the smooth normal Ns, the lobe's
/// normal N and light direction ωi (unit): 0 where Ns and N put ωi on different sides; else the
/// GGX masking G1(α², |Ns·ωi|) of a roughness α² = min(1, tan²θd / 8) from the angle θd
/// between N and Ns.
#[inline]
pub fn bump_shadowing(smooth: Vec3, n: Vec3, wi: Vec3) -> f32 {
    let (cos_ns_i, cos_ns_n, cos_n_i) = (smooth.dot(wi), smooth.dot(n), n.dot(wi));
    // 1. The light on different sides of the two normals: none.
    if cos_ns_i * cos_ns_n * cos_n_i < 0.0 {
        return 0.0;
    }
    // 2. GGX masking by the normals' deviation.
    let (cos_i, cos_d) = (cos_ns_i.abs(), cos_ns_n.abs());
    if cos_d >= 1.0 || cos_i >= 1.0 {
        return 1.0;
    }
    if cos_i < 1e-6 {
        return 0.0;
    }
    let tan2_d = 1.0 / (cos_d * cos_d) - 1.0;
    let alpha2 = (0.125 * tan2_d).clamp(0.0, 1.0);
    let tan2_i = 1.0 / (cos_i * cos_i) - 1.0;
    2.0 / (1.0 + (1.0 + alpha2 * tan2_i).sqrt())
}

/// Cycles' `ensure_valid_specular_reflection` (applied to normal-mapped normals with Bump Map
/// Correction): where the mapped normal `n` would reflect the view direction `wo` (unit, away
/// from the surface) below the geometric surface `ng` (on wo's side), `n` is turned toward `ng`
/// until the reflection leaves at min(0.9·(wo·ng), 0.01) above it.
pub fn ensure_valid_specular_reflection(ng: Vec3, wo: Vec3, n: Vec3) -> Vec3 {
    let r = 2.0 * n.dot(wo) * n - wo;
    let iz = wo.dot(ng);
    let threshold = (0.9 * iz).min(0.01);
    if ng.dot(r) >= threshold {
        return n;
    }
    // In the frame (X, ·, Ng) with n in the X–Ng plane, solve 4a·z⁴ − 2b·z² + c = 0 for the
    // new normal's z = N'·Ng so that the reflection's height is the threshold; the root
    // whose sign matches wo's X component is the one the unsquared equation holds for.
    let x = (n - n.dot(ng) * ng).try_normalize().unwrap_or(n);
    let ix = wo.dot(x);
    let a = ix * ix + iz * iz;
    let b = 2.0 * (a + iz * threshold);
    let c = (threshold + iz) * (threshold + iz);
    let root = (b * b - 4.0 * a * c).max(0.0).sqrt();
    let nz2 = if ix < 0.0 { 0.25 * (b + root) / a } else { 0.25 * (b - root) / a };
    let (nx, nz) = ((1.0 - nz2).max(0.0).sqrt(), nz2.max(0.0).sqrt());
    let out = nx * x + nz * ng;
    if out.is_finite() {
        out
    } else {
        n
    }
}

/// A sampled direction `wi` with its pdf and its f·|cos| (`eval`, called only for a positive
/// pdf) as a [`BsdfSample`]; None when the pdf is not positive or the weight is zero or not
/// finite.
#[inline]
fn weighted_sample(wi: Vec3, pdf: f32, eval: impl FnOnce() -> Vec3) -> Option<BsdfSample> {
    if !(pdf > 0.0) {
        return None;
    }
    let weight = eval() / pdf;
    if !weight.is_finite() || weight == Vec3::ZERO {
        return None;
    }
    Some(BsdfSample { wi, weight, pdf, is_delta: false })
}

/// The largest f32 below 1 (a remapped sample number stays in [0, 1)).
const ONE_BELOW: f32 = 1.0 - f32::EPSILON / 2.0;

/// Fresnel reflectance of a dielectric interface for unpolarised light, at `cos_i` (negative:
/// arriving from the inside) and relative index `eta` = n_inside / n_outside; 1 under total
/// internal reflection.
#[inline]
pub fn fresnel_dielectric(cos_i: f32, eta: f32) -> f32 {
    let (cos_i, eta) = if cos_i < 0.0 { (-cos_i.max(-1.0), 1.0 / eta) } else { (cos_i.min(1.0), eta) };
    let sin2_t = (1.0 - cos_i * cos_i) / (eta * eta);
    if sin2_t >= 1.0 {
        return 1.0;
    }
    let cos_t = (1.0 - sin2_t).max(0.0).sqrt();
    let r_parallel = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    let r_perpendicular = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    0.5 * (r_parallel * r_parallel + r_perpendicular * r_perpendicular)
}

/// Refracts `wi` (pointing away from the surface, on `n`'s side) through a surface of normal `n`
/// into a medium of relative index `eta`; None under total internal reflection.
#[inline]
fn refract(wi: Vec3, n: Vec3, eta: f32) -> Option<Vec3> {
    let cos_i = n.dot(wi);
    let sin2_t = (1.0 - cos_i * cos_i).max(0.0) / (eta * eta);
    if sin2_t >= 1.0 {
        return None;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    Some(-wi / eta + n * (cos_i / eta - cos_t))
}

// ---------------------------------------------------------------------------------------------
// Directional albedo of the single-scattering glass lobe (reflection + refraction, radiance
// scaling undone), for the energy compensation Cycles' multiscatter GGX glass applies.

/// Glass albedo table nodes: roughness (linear, 0…1), interface (x = (ior − 1)/(ior + 1),
/// linear over 0…0.5, i.e. ior 1…3), and √μ.
const GLASS_NR: usize = 16;
const GLASS_NI: usize = 16;
const GLASS_NMU: usize = 32;

/// One (roughness, ior) node's albedos E(μo) seen from outside (index 0) and inside (1).
struct GlassRow {
    e: [[f32; GLASS_NMU]; 2],
}

/// Row (`ri`, `ii`), computed once per process on first use.
fn glass_row(ri: usize, ii: usize) -> &'static GlassRow {
    static ROWS: [OnceLock<GlassRow>; GLASS_NR * GLASS_NI] = [const { OnceLock::new() }; GLASS_NR * GLASS_NI];
    ROWS[ri * GLASS_NI + ii].get_or_init(|| build_glass_row(ri, ii))
}

fn build_glass_row(ri: usize, ii: usize) -> GlassRow {
    // 1. The node's glass, single scattering (no compensation), untinted.
    let r = ri as f32 / (GLASS_NR - 1) as f32;
    let x = 0.5 * ii as f32 / (GLASS_NI - 1) as f32;
    let ior = (1.0 + x) / (1.0 - x);
    let mut row = GlassRow { e: [[1.0; GLASS_NMU]; 2] };
    for (side, inside) in [false, true].into_iter().enumerate() {
        let g = Glass::single_scatter((r * r).max(MIN_ALPHA), ior, Vec3::ONE).facing(inside);
        // 2. Per μ node: the mean of f·|cos|/pdf over stratified samples, refraction's 1/η′²
        //    taken back out (energy, not radiance).
        for mi in 0..GLASS_NMU {
            let s = mi as f32 / (GLASS_NMU - 1) as f32;
            let mu = (s * s).max(1e-4);
            let wo = Vec3::new((1.0 - mu * mu).max(0.0).sqrt(), 0.0, mu);
            const N: u32 = 2048;
            let mut sum = 0.0f64;
            for k in 0..N {
                let u2 = Vec2::new((k as f32 + 0.5) / N as f32, radical_inverse_vdc(k));
                // an additive golden-ratio sequence, independent of the Hammersley pair
                let u1 = ((k as f64 * 0.618_033_988_749_894_9 + 0.5).fract()) as f32;
                let Some(wi) = g.sample_direction(wo, u2, u1) else { continue };
                let pdf = g.pdf(wo, wi);
                if !(pdf > 0.0) {
                    continue;
                }
                let etap2 = if wi.z < 0.0 { g.eta * g.eta } else { 1.0 };
                sum += (g.eval(wo, wi).y / pdf * etap2) as f64;
            }
            row.e[side][mi] = ((sum / N as f64) as f32).clamp(0.05, 1.0);
        }
    }
    row
}

/// The glass albedo E(μ) for `roughness` and `ior`, from `inside` or outside, interpolated.
fn glass_albedo(roughness: f32, ior: f32, inside: bool, mu: f32) -> f32 {
    let rx = roughness.clamp(0.0, 1.0) * (GLASS_NR - 1) as f32;
    let r0 = (rx as usize).min(GLASS_NR - 2);
    let fr = rx - r0 as f32;
    let ix = ((ior - 1.0) / (ior + 1.0) / 0.5).clamp(0.0, 1.0) * (GLASS_NI - 1) as f32;
    let i0 = (ix as usize).min(GLASS_NI - 2);
    let fi = ix - i0 as f32;
    let mx = mu.clamp(0.0, 1.0).sqrt() * (GLASS_NMU - 1) as f32;
    let m0 = (mx as usize).min(GLASS_NMU - 2);
    let fm = mx - m0 as f32;
    let side = inside as usize;
    let at = |ri: usize, ii: usize| {
        let e = &glass_row(ri, ii).e[side];
        e[m0] + (e[m0 + 1] - e[m0]) * fm
    };
    let lo = at(r0, i0) + (at(r0, i0 + 1) - at(r0, i0)) * fi;
    let hi = at(r0 + 1, i0) + (at(r0 + 1, i0 + 1) - at(r0 + 1, i0)) * fi;
    lo + (hi - lo) * fr
}

/// A rough dielectric interface (glass): GGX microfacets reflecting by the exact Fresnel
/// equations and refracting the rest (Walter et al. 2007), sampled by visible normals and
/// choosing reflection or refraction by the Fresnel reflectance, as pbrt-v4's DielectricBxDF
/// does. Local frame, `wo` above the surface; refracted light is tinted and carries the
/// 1/η² of radiance crossing into a denser medium. The energy single scattering loses between
/// microfacets comes back as Cycles' multiscatter GGX brings it: f is divided by the lobe's
/// albedo E(μo) (tabulated per roughness, ior and side).
#[derive(Debug, Clone, Copy)]
pub struct Glass {
    /// Perceptual roughness (for the albedo table); negative: no compensation.
    roughness: f32,
    alpha: f32,
    a2: f32,
    /// n_inside / n_outside.
    ior: f32,
    /// The relative index for light going from `wo`'s side across: `ior` from outside, 1/ior
    /// from inside.
    eta: f32,
    /// Colour of the refracted light (the base colour).
    tint: Vec3,
}

impl Glass {
    /// Glass of perceptual `roughness` and `ior`, its refracted light tinted by `tint`, seen
    /// from outside, with the multiple-scattering compensation.
    pub fn new(roughness: f32, ior: f32, tint: Vec3) -> Self {
        let roughness = roughness.clamp(0.0, 1.0);
        Glass { roughness, ..Glass::single_scatter((roughness * roughness).max(MIN_ALPHA), ior, tint) }
    }

    /// Glass of GGX `alpha` without the compensation (what the albedo table integrates).
    fn single_scatter(alpha: f32, ior: f32, tint: Vec3) -> Self {
        let alpha = alpha.max(MIN_ALPHA);
        Glass { roughness: -1.0, alpha, a2: alpha * alpha, ior, eta: ior, tint }
    }

    /// 1 / E(μo): the compensation of energy lost between microfacets (1 without it).
    #[inline]
    fn energy_scale(&self, wo: Vec3) -> f32 {
        if self.roughness < 0.0 {
            return 1.0;
        }
        1.0 / glass_albedo(self.roughness, self.ior, self.eta < 1.0, wo.z)
    }

    /// The same glass seen from inside (`inside`) or outside.
    pub fn facing(self, inside: bool) -> Self {
        Glass { eta: if inside { 1.0 / self.ior } else { self.ior }, ..self }
    }

    /// The microfacet normal joining `wo` and `wi` (reflection or refraction), facing up, with
    /// η′ (1 for reflection, η for refraction); None where no microfacet can join them.
    #[inline]
    fn half_vector(&self, wo: Vec3, wi: Vec3) -> Option<(Vec3, f32)> {
        if wo.z <= 0.0 || wi.z == 0.0 {
            return None;
        }
        let etap = if wi.z > 0.0 { 1.0 } else { self.eta };
        let wm = (wi * etap + wo).normalize_or_zero();
        let wm = if wm.z < 0.0 { -wm } else { wm };
        // back-facing microfacets join nothing
        if wm == Vec3::ZERO || wm.dot(wi) * wi.z < 0.0 || wm.dot(wo) < 0.0 {
            return None;
        }
        Some((wm, etap))
    }

    /// f(wo, wi)·|cos θi|.
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Vec3 {
        let Some((wm, etap)) = self.half_vector(wo, wi) else { return Vec3::ZERO };
        let f = fresnel_dielectric(wo.dot(wm), self.eta);
        let d = ggx_d(wm.z, self.a2);
        let g = 1.0 / (1.0 + smith_lambda(wo.z, self.a2) + smith_lambda(wi.z, self.a2));
        let value = if wi.z > 0.0 {
            Vec3::splat(d * g * f / (4.0 * wo.z))
        } else {
            let denom = wi.dot(wm) + wo.dot(wm) / etap;
            let ft = d * (1.0 - f) * g * (wi.dot(wm) * wo.dot(wm) / (denom * denom * wo.z)).abs() / (etap * etap);
            self.tint * ft
        } * self.energy_scale(wo);
        if value.is_finite() {
            value
        } else {
            Vec3::ZERO
        }
    }

    /// Solid-angle pdf of [`Glass::sample_direction`] producing `wi`.
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        let Some((wm, etap)) = self.half_vector(wo, wi) else { return 0.0 };
        let r = fresnel_dielectric(wo.dot(wm), self.eta);
        // visible-normal density of wm, then its Jacobian to wi
        let vndf = ggx_d(wm.z, self.a2) * wo.dot(wm) / ((1.0 + smith_lambda(wo.z, self.a2)) * wo.z);
        let pdf = if wi.z > 0.0 {
            vndf / (4.0 * wo.dot(wm)) * r
        } else {
            let denom = wi.dot(wm) + wo.dot(wm) / etap;
            vndf * wi.dot(wm).abs() / (denom * denom) * (1.0 - r)
        };
        if pdf.is_finite() {
            pdf
        } else {
            0.0
        }
    }

    /// A direction: a visible microfacet normal from `u2`, then reflection or refraction by
    /// its Fresnel reflectance (`u1`).
    pub fn sample_direction(&self, wo: Vec3, u2: Vec2, u1: f32) -> Option<Vec3> {
        if wo.z <= 0.0 {
            return None;
        }
        let wm = sample_vndf(wo, self.alpha, u2);
        let r = fresnel_dielectric(wo.dot(wm), self.eta);
        let wi = if u1 < r { 2.0 * wo.dot(wm) * wm - wo } else { refract(wo, wm, self.eta)? };
        // reflection stays above, refraction goes below
        ((u1 < r) == (wi.z > 0.0) && wi.z != 0.0).then_some(wi.normalize())
    }
}

/// A [`Bsdf`] placed at a surface point: the shading frame (flipped to the side of wo — for
/// double-sided materials and, like Blender, for back faces of single-sided ones too, so back
/// faces shade as front faces), and the geometric normal that rejects directions through the
/// surface (no light leaks from shading normals).
#[derive(Debug, Clone, Copy)]
pub struct SurfaceBsdf<'a> {
    /// The local BSDF.
    pub bsdf: Bsdf<'a>,
    /// Shading normal on wo's side (bent so that wo is above it).
    pub n: Vec3,
    t: Vec3,
    b: Vec3,
    /// Geometric normal on wo's side.
    pub ng: Vec3,
    /// A normal map's smooth and mapped normals in the local frame
    /// ([`SurfaceBsdf::with_normal_map`]).
    bump: Option<Bump>,
}

impl<'a> SurfaceBsdf<'a> {
    /// Places `bsdf` with the given normals for outgoing direction `wo` (unit, world, pointing
    /// away from the surface). Normals may face either way.
    #[inline(always)]
    pub fn new(bsdf: Bsdf<'a>, geometric_normal: Vec3, shading_normal: Vec3, wo: Vec3) -> Self {
        let inside = geometric_normal.dot(wo) < 0.0;
        let bsdf = bsdf.seen_from_inside(inside);
        let ng = if inside { -geometric_normal } else { geometric_normal };
        let mut n = if shading_normal.dot(ng) >= 0.0 { shading_normal } else { -shading_normal };
        const EPS: f32 = 1e-4;
        let c = n.dot(wo);
        if c < EPS {
            // Shading normal turned away from the viewer: bend it until wo is just above.
            n = (n - wo * (c - EPS)).normalize_or(ng);
            if n.dot(wo) <= 0.0 {
                n = ng;
            }
        }
        let (t, b) = orthonormal_basis(n);
        SurfaceBsdf { bsdf, n, t, b, ng, bump: None }
    }

    /// The same placement with the frame's first axis along `tangent` (world; made
    /// perpendicular to the normal, as Cycles' `make_orthonormals_tangent`), for anisotropic
    /// lobes; unchanged where the tangent is along the normal. Before
    /// [`SurfaceBsdf::with_normal_map`].
    pub fn with_tangent(mut self, tangent: Vec3) -> Self {
        let b = self.n.cross(tangent).normalize_or_zero();
        if b != Vec3::ZERO && b.is_finite() {
            self.b = b;
            self.t = b.cross(self.n);
        }
        self
    }

    /// The same BSDF on a normal-mapped surface, whose shading normal (given to
    /// [`SurfaceBsdf::new`]) is the mapped normal corrected by
    /// [`ensure_valid_specular_reflection`]: `mapped` is the mapped normal before the
    /// correction and `smooth` the surface's smooth normal (world; either side). The diffuse lobe
    /// then uses `mapped` and Cycles' bump shadowing term ([`Bsdf::eval_opaque_mapped`]).
    pub fn with_normal_map(mut self, smooth: Vec3, mapped: Vec3) -> Self {
        let side = |v: Vec3| if v.dot(self.ng) >= 0.0 { v } else { -v };
        let smooth = self.to_local(side(smooth)).normalize_or_zero();
        let mapped = self.to_local(side(mapped)).normalize_or_zero();
        if smooth != Vec3::ZERO && mapped != Vec3::ZERO && smooth.is_finite() && mapped.is_finite() {
            self.bump = Some(Bump { smooth, mapped });
        }
        self
    }

    /// World → local.
    #[inline]
    pub fn to_local(&self, w: Vec3) -> Vec3 {
        Vec3::new(w.dot(self.t), w.dot(self.b), w.dot(self.n))
    }

    /// Local → world.
    #[inline]
    pub fn to_world(&self, w: Vec3) -> Vec3 {
        self.t * w.x + self.b * w.y + self.n * w.z
    }

    /// Whether world direction `wi` leaves on the side of the geometric surface that the
    /// shading frame puts it on (above for reflection, below for a transmissive BSDF's
    /// refraction); directions the two normals disagree on carry nothing.
    #[inline]
    fn consistent(&self, wi: Vec3, local: Vec3) -> bool {
        let geometric = wi.dot(self.ng);
        if self.bsdf.transmits() {
            (geometric > 0.0) == (local.z > 0.0) && geometric != 0.0
        } else {
            geometric > 0.0
        }
    }

    /// f·|cos| for world directions (zero when wi goes through the geometric surface, unless
    /// the BSDF transmits and wi is refracted).
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Vec3 {
        let local = self.to_local(wi);
        if !self.consistent(wi, local) {
            return Vec3::ZERO;
        }
        self.bsdf.eval_bumped(self.to_local(wo), local, self.bump)
    }

    /// f·cos for a light sample's direction: as [`SurfaceBsdf::eval`] without the geometric
    /// normal's test, as Cycles evaluates light samples. Near the terminator of a smooth-shaded
    /// mesh the light may lie below the flat triangle yet above the shading normal; the shadow
    /// ray then decides ([`super::accel::RenderScene::shadow_origin`]).
    pub fn eval_light(&self, wo: Vec3, wi: Vec3) -> Vec3 {
        self.bsdf.eval_bumped(self.to_local(wo), self.to_local(wi), self.bump)
    }

    /// The pdf that weights a light sample's direction against BSDF sampling (without the
    /// geometric normal's test, as [`SurfaceBsdf::eval_light`]).
    pub fn pdf_light(&self, wo: Vec3, wi: Vec3) -> f32 {
        self.bsdf.pdf_bumped(self.to_local(wo), self.to_local(wi), self.bump)
    }

    /// Pdf for world directions.
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        let local = self.to_local(wi);
        if !self.consistent(wi, local) {
            return 0.0;
        }
        self.bsdf.pdf_bumped(self.to_local(wo), local, self.bump)
    }

    /// Samples a world direction (None when it would go through the geometric surface, or,
    /// refracted, would not).
    pub fn sample(&self, wo: Vec3, u2: Vec2, u1: f32) -> Option<BsdfSample> {
        let s = self.bsdf.sample_bumped(self.to_local(wo), u2, u1, self.bump)?;
        let wi = self.to_world(s.wi).normalize_or_zero();
        if !self.consistent(wi, s.wi) {
            return None;
        }
        Some(BsdfSample { wi, ..s })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A normal-mapped BSDF's sampling covers its whole diffuse lobe: the lobe sits on the mapped
    /// normal, tilted 40° from the shading frame, so part of it lies below the frame's horizon.
    /// The importance-sampled estimate of the albedo (mean sample weight) equals the integral of
    /// f·cos over the sphere by uniform directions, within their Monte Carlo errors; sampling
    /// the diffuse lobe about the frame normal (as before) missed the part below the horizon.
    #[test]
    fn normal_mapped_sampling_covers_the_diffuse_lobe() {
        let bsdf = Bsdf::new(Vec3::new(0.8, 0.6, 0.4), 0.0, 0.5, 0.5, 1.5);
        let tilt = 40f32.to_radians();
        let mapped = Vec3::new(tilt.sin(), 0.0, tilt.cos());
        let bump = Some(Bump { smooth: mapped, mapped });
        let wo = Vec3::new(-0.3, 0.2, 0.9).normalize();
        let n = 400_000u32;
        let u = |i: u32, k: u32| {
            let mut h = (i as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ (k as u64).wrapping_mul(0xbf58_476d_1ce4_e5b9);
            h ^= h >> 31;
            h = h.wrapping_mul(0x94d0_49bb_1331_11eb);
            h ^= h >> 29;
            (h >> 40) as f32 / (1u64 << 24) as f32
        };
        // 1. Importance sampled: E[f·cos / pdf].
        let (mut sampled, mut sampled2) = (0.0f64, 0.0f64);
        for i in 0..n {
            let w =
                bsdf.sample_bumped(wo, Vec2::new(u(i, 0), u(i, 1)), u(i, 2), bump).map_or(0.0, |s| luminance(s.weight));
            sampled += w as f64;
            sampled2 += (w * w) as f64;
        }
        // 2. Uniform directions over the sphere: 4π · E[f·cos].
        let (mut uniform, mut uniform2) = (0.0f64, 0.0f64);
        for i in 0..n {
            let z = 1.0 - 2.0 * u(i, 3);
            let phi = 2.0 * PI * u(i, 4);
            let r = (1.0 - z * z).max(0.0).sqrt();
            let wi = Vec3::new(r * phi.cos(), r * phi.sin(), z);
            let f = 4.0 * PI * luminance(bsdf.eval_bumped(wo, wi, bump));
            uniform += f as f64;
            uniform2 += (f * f) as f64;
        }
        let mean = |s: f64, s2: f64| (s / n as f64, ((s2 / n as f64 - (s / n as f64).powi(2)) / n as f64).sqrt());
        let ((a, ea), (b, eb)) = (mean(sampled, sampled2), mean(uniform, uniform2));
        assert!((a - b).abs() < 4.0 * (ea * ea + eb * eb).sqrt(), "sampled {a} ± {ea}, integral {b} ± {eb}");
    }

    fn hash_u(i: u32, k: u32) -> f32 {
        let mut h = (i as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ (k as u64).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        h ^= h >> 31;
        h = h.wrapping_mul(0x94d0_49bb_1331_11eb);
        h ^= h >> 29;
        (h >> 40) as f32 / (1u64 << 24) as f32
    }

    /// Anisotropic GGX with α_x = α_y is the isotropic lobe (eval and pdf within 10⁻⁴ relative:
    /// the two forms of D round differently in f32 near a sharp peak, where the isotropic
    /// form's cos²θ·(α² − 1) + 1 cancels), for a metal and a dielectric, at 2 000 direction pairs.
    #[test]
    fn anisotropic_lobes_with_equal_alphas_are_isotropic() {
        for (metallic, roughness) in [(1.0, 0.3), (0.0, 0.5), (0.5, 0.8)] {
            let iso = Bsdf::new(Vec3::new(0.9, 0.6, 0.3), metallic, roughness, 1.0, 1.5);
            let a = iso.alpha;
            let aniso = iso.with_anisotropic_alphas((a, a));
            for i in 0..2000 {
                let dir = |k: u32| {
                    let z = hash_u(i, k).max(0.02);
                    let phi = 2.0 * PI * hash_u(i, k + 1);
                    let r = (1.0 - z * z).sqrt();
                    Vec3::new(r * phi.cos(), r * phi.sin(), z)
                };
                let (wo, wi) = (dir(0), dir(2));
                let (f0, f1) = (iso.eval(wo, wi), aniso.eval(wo, wi));
                let (p0, p1) = (iso.pdf(wo, wi), aniso.pdf(wo, wi));
                assert!((f0 - f1).abs().max_element() <= 1e-4 * f0.max_element().max(1e-3), "{f0} {f1}");
                assert!((p0 - p1).abs() <= 1e-4 * p0.max(1e-3), "{p0} {p1}");
            }
        }
    }

    /// An anisotropic metal samples what it evaluates: the mean sample weight (importance
    /// sampled) equals the integral of f·cos by uniform directions, within their Monte Carlo
    /// errors; and its highlight is broader along the rougher axis (α_x > α_y: a view tilted
    /// 25° along x reflects more than along y).
    #[test]
    fn anisotropic_metal_samples_its_lobe_and_stretches_along_the_rougher_axis() {
        let kind = crate::scene::AnisotropyKind::Scale(Vec2::new(1.0 / 0.55, 0.55));
        let ((ax, ay), r_table) = Bsdf::anisotropic_alphas(0.4, kind);
        assert!((r_table - 0.4).abs() < 1e-6, "{r_table}");
        let bsdf = Bsdf::new(Vec3::new(0.95, 0.8, 0.6), 1.0, r_table, 1.0, 1.5).with_anisotropic_alphas((ax, ay));
        let wo = Vec3::new(0.4, -0.3, 0.8).normalize();
        let n = 400_000u32;
        let (mut s, mut s2, mut q, mut q2) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
        for i in 0..n {
            let w = bsdf
                .sample(wo, Vec2::new(hash_u(i, 0), hash_u(i, 1)), hash_u(i, 2))
                .map_or(0.0, |x| luminance(x.weight));
            s += w as f64;
            s2 += (w * w) as f64;
            let z = hash_u(i, 3);
            let phi = 2.0 * PI * hash_u(i, 4);
            let r = (1.0 - z * z).max(0.0).sqrt();
            let f = 2.0 * PI * luminance(bsdf.eval(wo, Vec3::new(r * phi.cos(), r * phi.sin(), z)));
            q += f as f64;
            q2 += (f * f) as f64;
        }
        let mean = |s: f64, s2: f64| (s / n as f64, ((s2 / n as f64 - (s / n as f64).powi(2)) / n as f64).sqrt());
        let ((a, ea), (b, eb)) = (mean(s, s2), mean(q, q2));
        assert!((a - b).abs() < 4.0 * (ea * ea + eb * eb).sqrt(), "sampled {a} ± {ea}, integral {b} ± {eb}");
        let t = 25f32.to_radians();
        let up = Vec3::Z;
        let (along_x, along_y) = (Vec3::new(t.sin(), 0.0, t.cos()), Vec3::new(0.0, t.sin(), t.cos()));
        let (fx, fy) = (luminance(bsdf.eval(up, along_x)), luminance(bsdf.eval(up, along_y)));
        assert!(ax > ay && fx > 2.0 * fy, "α ({ax}, {ay}): along x {fx}, along y {fy}");
    }

    /// Cycles' Principled and Glossy anisotropy: the Principled aspect √(1 − 0.9 A) (A = 1: α
    /// along the tangent saturates at 1 for roughness ≥ 0.562, and the tables are then read at
    /// (α_x·α_y)^¼); the Glossy BSDF's 1 ∓ A.
    #[test]
    fn anisotropy_parameters_follow_cycles() {
        use crate::scene::{Anisotropy, AnisotropyKind::Scale, AnisotropyTangent::Radial};
        let p = Anisotropy::principled(1.0, 0.25, Radial(2)).unwrap();
        let aspect = 0.1f32.sqrt();
        let Scale(scale) = p.kind else { panic!("{p:?}") };
        assert!((scale - Vec2::new(1.0 / aspect, aspect)).abs().max_element() < 1e-6);
        assert!(Anisotropy::principled(0.0, 0.3, Radial(2)).is_none());
        let ((ax, ay), r) = Bsdf::anisotropic_alphas(0.8, p.kind);
        assert_eq!(ax, 1.0);
        assert!((ay - 0.64 * aspect).abs() < 1e-6 && (r - (ax * ay).sqrt().sqrt()).abs() < 1e-7 && r < 0.8);
        assert_eq!(Anisotropy::glossy(0.5, 0.0, Radial(2)).unwrap().kind, Scale(Vec2::new(0.5, 2.0)));
        assert_eq!(Anisotropy::glossy(-0.5, 0.0, Radial(2)).unwrap().kind, Scale(Vec2::new(2.0, 0.5)));
        assert!(Anisotropy::glossy(5e-5, 0.0, Radial(2)).is_none());
        // KHR_materials_anisotropy: α_t = mix(α, 1, s²), α_b = α; rotation in radians
        let k = Anisotropy::khr(0.5, std::f32::consts::FRAC_PI_2).unwrap();
        assert!((k.rotation_turns - 0.25).abs() < 1e-7);
        let ((at, ab), _) = Bsdf::anisotropic_alphas(0.5, k.kind);
        assert!((at - (0.25 + 0.75 * 0.25)).abs() < 1e-7 && ab == 0.25, "{at} {ab}");
    }

    /// Cycles' bump shadowing: 1 without a normal map (N = Ns), 0 with the light between the two
    /// normals' horizons, else GGX's G1 at α² = tan²θd / 8 (worked by hand for θd = 30°,
    /// cos θi = 0.5: α² = 1/24, tan² = 3, G1 = 2 / (1 + √(1 + 1/8)) = 0.97140), and it grows
    /// as the light rises.
    #[test]
    fn bump_shadowing_meets_its_definition() {
        let z = Vec3::Z;
        let ns = Vec3::new(0.5, 0.0, 0.75f32.sqrt()); // 30° from N = +z
        assert_eq!(bump_shadowing(z, z, Vec3::new(0.6, 0.0, 0.8)), 1.0);
        // above N, below Ns: none
        let between = Vec3::new(-0.9, 0.0, 0.3).normalize();
        assert!(between.z > 0.0 && ns.dot(between) < 0.0);
        assert_eq!(bump_shadowing(ns, z, between), 0.0);
        // cos θi (against Ns) = 0.5
        let wi = (ns * 0.5 + Vec3::Y * 0.75f32.sqrt()).normalize();
        let g = bump_shadowing(ns, z, wi);
        assert!((g - 2.0 / (1.0 + (1.0f32 + 1.0 / 8.0).sqrt())).abs() < 1e-5, "{g}");
        let mut last = 0.0;
        for k in 1..=20 {
            let c = k as f32 / 20.0;
            let w = (ns * c + Vec3::Y * (1.0 - c * c).max(0.0).sqrt()).normalize();
            let g = bump_shadowing(ns, z, w);
            assert!(g >= last && g <= 1.0, "not rising at cos {c}: {g} after {last}");
            last = g;
        }
    }

    /// Cycles' specular-reflection correction leaves a normal alone where the view reflects
    /// above the surface; elsewhere the new normal is unit, lies between the old one and the
    /// geometric normal, and reflects the view exactly min(0.9·(ωo·Ng), 0.01) above the surface.
    #[test]
    fn ensure_valid_specular_reflection_lifts_the_reflection_to_its_threshold() {
        let ng = Vec3::Z;
        let wo = Vec3::new(0.0, -0.95, 0.3).normalize();
        let kept = Vec3::new(0.0, -0.2, 1.0).normalize();
        assert_eq!(ensure_valid_specular_reflection(ng, wo, kept), kept);
        for tilt in [0.3f32, 0.6, 1.0, 1.3] {
            let n = Vec3::new(0.1 * tilt, tilt.sin(), tilt.cos()).normalize(); // away from the viewer
            let r = 2.0 * n.dot(wo) * n - wo;
            assert!(r.z < 0.01, "tilt {tilt}: the case does not need the correction");
            let m = ensure_valid_specular_reflection(ng, wo, n);
            assert!((m.length() - 1.0).abs() < 1e-5, "tilt {tilt}: |n'| = {}", m.length());
            let r2 = 2.0 * m.dot(wo) * m - wo;
            let t = (0.9 * wo.z).min(0.01);
            assert!((r2.z - t).abs() < 1e-4, "tilt {tilt}: reflection height {} not {t}", r2.z);
            assert!(m.z > n.z, "tilt {tilt}: not turned toward Ng");
            let plane = n.cross(ng).normalize();
            assert!(m.dot(plane).abs() < 1e-5, "tilt {tilt}: n' left the plane of n and Ng");
        }
    }

    /// Cycles' F82 tint: plain Schlick for a white tint (bit for bit), F0 head-on, 1 at grazing,
    /// `tint` × Schlick's at μ = 1/7; its closed-form hemispherical average against quadrature;
    /// the constant Fresnel is F0 everywhere.
    #[test]
    fn f82_tint_meets_its_definition() {
        let mu_bar = 1.0f32 / 7.0;
        for f0 in [Vec3::new(0.95, 0.64, 0.54), Vec3::splat(0.04), Vec3::new(0.617, 0.577, 0.540)] {
            for tint in [Vec3::ONE, Vec3::new(0.695, 0.726, 0.770), Vec3::new(0.5, 0.9, 1.0)] {
                let f = MetalFresnel::F82 { tint };
                for cos in [0.0f32, 0.05, 0.3, 0.7, 1.0] {
                    let w = schlick_weight(cos);
                    let got = metal_fresnel(&f, f0, cos, w);
                    if tint == Vec3::ONE {
                        assert_eq!(got, f0 + (Vec3::ONE - f0) * w, "white tint is Schlick's");
                    }
                    if cos == 1.0 {
                        assert!(got.distance(f0) < 1e-6, "head-on {got} vs F0 {f0}");
                    }
                    if cos == 0.0 {
                        assert!(got.distance(Vec3::ONE) < 1e-6, "grazing {got}");
                    }
                }
                let w = schlick_weight(mu_bar);
                let want = tint * (f0 + (Vec3::ONE - f0) * w);
                let got = metal_fresnel(&f, f0, mu_bar, w);
                assert!(got.distance(want) < 2e-5, "F(1/7) = {got}, want tint × Schlick = {want}");
                // 2∫F(μ)μ dμ by the midpoint rule
                let n = 20_000;
                let numeric = (0..n).fold(Vec3::ZERO, |acc, i| {
                    let mu = (i as f32 + 0.5) / n as f32;
                    acc + metal_fresnel(&f, f0, mu, schlick_weight(mu)) * (2.0 * mu / n as f32)
                });
                let avg = metal_fresnel_average(&f, f0);
                assert!(avg.distance(numeric) < 1e-4, "average {avg} vs quadrature {numeric}");
            }
            assert_eq!(metal_fresnel(&MetalFresnel::Constant, f0, 0.2, schlick_weight(0.2)), f0);
            assert_eq!(metal_fresnel_average(&MetalFresnel::Constant, f0), f0);
        }
    }
}
