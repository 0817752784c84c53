//! The environment: black, a constant colour, or an equirectangular HDR map (EXR), with
//! importance sampling.
//!
//! | parameter | type | unit | default |
//! |---|---|---|---|
//! | [`Environment::Constant`] | linear RGB | radiance (W/(m²·sr)) | — |
//! | `strength` ([`load_environment_exr`], [`EnvironmentMap::new`]) | f32 ≥ 0, multiplies the map | — | 1 |
//! | `rotation_rad` | f32, rotation of the map about world +y, right-handed (counter-clockwise seen from above) | radians | 0 |
//!
//! Mapping (the same image as Blender's Environment Texture node for the same file). Cycles
//! (`kernel/camera/projection.h`, `direction_to_equirectangular`) looks a Blender direction
//! `(x, y, z)` (+z up) up at `u = 0.5 − atan2(y, x) / 2π`, `v = 1 − acos(z) / π`, with `v = 0`
//! at the bottom row of the image. Blender's glTF exporter maps Blender `(x, y, z)` to glTF
//! `(x, z, −y)`, so for a world direction `(X, Y, Z)` here (+y up):
//!
//! `u = 0.5 + atan2(Z, X) / 2π`, `t = acos(Y) / π`,
//!
//! with `u` the column from the left edge of the file and `t` the row from the top. The image
//! centre lies towards +x, its left/right seam towards −x, `u = 0.25` towards −z (Blender +y).
//! A non-zero `rotation_rad` turns the map by that angle about +y: the radiance in direction
//! `d` is the unrotated map's at `R_y(−rotation_rad)·d`; that is Blender's Mapping node of
//! type *Texture* with Z rotation `rotation_rad` in front of the Environment Texture.
//! Look-ups are bilinear (Blender's default *Linear* interpolation), wrapping in `u` and
//! clamping in `t`. Non-finite or negative texels are read as 0.
//!
//! Sampling. A map is importance-sampled with a piecewise-constant 2D distribution over its
//! texels (marginal over rows, conditional over columns, as in pbrt) proportional to
//! luminance × sin θ of the texel centre, where the luminance of a texel is the largest of its
//! 3×3 neighbourhood, so every direction with non-zero bilinear radiance has a non-zero
//! density. A constant environment is sampled uniformly over the whole sphere
//! (pdf = 1/4π, no cosine factor). Black is never sampled.

use crate::{Error, Result};
use glam::{Vec2, Vec3};
use std::f32::consts::PI;
use std::path::Path;
use std::sync::Arc;

/// What the scene sees at infinity.
#[derive(Debug, Clone, PartialEq, Default)]
pub enum Environment {
    /// Black.
    #[default]
    Black,
    /// Uniform radiance.
    Constant(Vec3),
    /// An equirectangular map.
    Map(EnvironmentMap),
}

impl Environment {
    /// Radiance arriving from world direction `dir` (need not be normalized).
    pub fn radiance(&self, dir: Vec3) -> Vec3 {
        match self {
            Environment::Black => Vec3::ZERO,
            Environment::Constant(c) => *c,
            Environment::Map(m) => m.radiance(dir),
        }
    }

    /// Samples a direction from two uniform numbers in [0, 1): (unit direction, radiance,
    /// pdf per unit solid angle). None for a black environment.
    pub fn sample(&self, u: Vec2) -> Option<(Vec3, Vec3, f32)> {
        match self {
            Environment::Black => None,
            Environment::Constant(c) => {
                if !positive(c.max_element()) {
                    return None;
                }
                Some((uniform_sphere(u), *c, 1.0 / (4.0 * PI)))
            }
            Environment::Map(m) => m.sample(u),
        }
    }

    /// Density (per unit solid angle) with which [`Environment::sample`] picks `dir`.
    pub fn pdf(&self, dir: Vec3) -> f32 {
        match self {
            Environment::Black => 0.0,
            Environment::Constant(c) => {
                if c.max_element() > 0.0 {
                    1.0 / (4.0 * PI)
                } else {
                    0.0
                }
            }
            Environment::Map(m) => m.pdf(dir),
        }
    }

    /// Whether its radiance is the same in every direction: a constant, or a map whose texels
    /// are all equal.
    pub fn is_uniform(&self) -> bool {
        match self {
            Environment::Black | Environment::Constant(_) => true,
            Environment::Map(m) => m.uniform,
        }
    }

    /// Whether the environment emits nothing.
    pub fn is_black(&self) -> bool {
        match self {
            Environment::Black => true,
            Environment::Constant(c) => !positive(c.max_element()),
            Environment::Map(m) => m.distribution.marginal.integral <= 0.0 || !positive(m.strength),
        }
    }
}

/// `x > 0` (false for NaN).
fn positive(x: f32) -> bool {
    x > 0.0
}

fn uniform_sphere(u: Vec2) -> Vec3 {
    let z = 1.0 - 2.0 * u.x;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * PI * u.y;
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// Luminance of linear Rec.709 RGB.
fn luminance(c: Vec3) -> f32 {
    0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z
}

/// A piecewise-constant 1D distribution on [0, 1).
#[derive(Debug, Clone, PartialEq)]
struct Distribution1D {
    func: Vec<f32>,
    /// n + 1 entries, cdf[0] = 0, cdf[n] = 1.
    cdf: Vec<f32>,
    /// ∫ func over [0, 1).
    integral: f32,
}

impl Distribution1D {
    fn new(func: Vec<f32>) -> Self {
        let n = func.len();
        let mut cdf = Vec::with_capacity(n + 1);
        let mut acc = 0.0f64;
        cdf.push(0.0f64);
        for &f in &func {
            acc += f as f64 / n as f64;
            cdf.push(acc);
        }
        let integral = acc;
        let cdf = if integral > 0.0 {
            cdf.iter().map(|c| (c / integral) as f32).collect()
        } else {
            (0..=n).map(|i| i as f32 / n as f32).collect()
        };
        Distribution1D { func, cdf, integral: integral as f32 }
    }

    fn len(&self) -> usize {
        self.func.len()
    }

    /// (x in [0, 1), pdf, bin).
    fn sample(&self, u: f32) -> (f32, f32, usize) {
        let n = self.len();
        let u = u.clamp(0.0, 1.0 - f32::EPSILON);
        // Last bin whose cdf start is ≤ u (bins of zero width are never chosen for u < 1).
        let i = self.cdf[..n].partition_point(|&c| c <= u).saturating_sub(1).min(n - 1);
        let width = self.cdf[i + 1] - self.cdf[i];
        let du = if width > 0.0 { ((u - self.cdf[i]) / width).clamp(0.0, 1.0) } else { 0.5 };
        let pdf = if self.integral > 0.0 { self.func[i] / self.integral } else { 1.0 };
        let x = ((i as f32 + du) / n as f32).min(1.0 - f32::EPSILON);
        (x, pdf, i)
    }
}

/// Marginal (rows) and conditional (columns of each row) distributions.
#[derive(Debug, Clone, PartialEq)]
struct Distribution2D {
    rows: Vec<Distribution1D>,
    marginal: Distribution1D,
}

impl Distribution2D {
    fn new(weights: &[f32], width: usize, height: usize) -> Self {
        let rows: Vec<Distribution1D> =
            (0..height).map(|y| Distribution1D::new(weights[y * width..(y + 1) * width].to_vec())).collect();
        let marginal = Distribution1D::new(rows.iter().map(|r| r.integral).collect());
        Distribution2D { rows, marginal }
    }

    /// ((u, v), pdf over the unit square).
    fn sample(&self, u: Vec2) -> (Vec2, f32) {
        let (v, pdf_v, row) = self.marginal.sample(u.y);
        let (x, pdf_u, _) = self.rows[row].sample(u.x);
        (Vec2::new(x, v), pdf_v * pdf_u)
    }

    fn pdf(&self, col: usize, row: usize) -> f32 {
        if self.marginal.integral <= 0.0 {
            return 0.0;
        }
        self.rows[row].func[col] / self.marginal.integral
    }
}

/// An equirectangular environment map (see the module docs for the mapping).
#[derive(Clone, PartialEq)]
pub struct EnvironmentMap {
    name: String,
    width: usize,
    height: usize,
    /// Row-major, row 0 at the top of the image.
    texels: Arc<Vec<Vec3>>,
    strength: f32,
    rotation_rad: f32,
    /// cos and sin of the rotation.
    rot: (f32, f32),
    distribution: Arc<Distribution2D>,
    /// Largest texel component × strength.
    peak: f32,
    /// Every texel is the same (a constant colour stored as an image, as Blender's USD export
    /// writes a uniform world).
    uniform: bool,
}

impl std::fmt::Debug for EnvironmentMap {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("EnvironmentMap")
            .field("name", &self.name)
            .field("width", &self.width)
            .field("height", &self.height)
            .field("strength", &self.strength)
            .field("rotation_rad", &self.rotation_rad)
            .finish_non_exhaustive()
    }
}

impl EnvironmentMap {
    /// Builds a map from row-major linear RGB texels (row 0 = top of the image = +y).
    /// Non-finite or negative texel values become 0.
    pub fn new(
        name: &str,
        width: usize,
        height: usize,
        mut texels: Vec<Vec3>,
        strength: f32,
        rotation_rad: f32,
    ) -> Result<Self> {
        let err = |m: String| Error::scene(name, "environment", m);
        if width == 0 || height == 0 {
            return Err(err(format!("image is empty ({width}×{height})")));
        }
        if width.checked_mul(height) != Some(texels.len()) {
            return Err(err(format!("{} texels for a {width}×{height} image", texels.len())));
        }
        if !strength.is_finite() || strength < 0.0 {
            return Err(err(format!("strength {strength} must be finite and ≥ 0")));
        }
        if !rotation_rad.is_finite() {
            return Err(err(format!("rotation {rotation_rad} is not finite")));
        }
        for t in texels.iter_mut() {
            *t = Vec3::select(t.cmpge(Vec3::ZERO) & t.cmplt(Vec3::INFINITY), *t, Vec3::ZERO);
        }
        // Luminance dilated over the 3×3 neighbourhood (bilinear footprint) × sin θ.
        let lum: Vec<f32> = texels.iter().map(|&c| luminance(c)).collect();
        let mut weights = vec![0.0f32; width * height];
        for y in 0..height {
            let sin_theta = (PI * (y as f32 + 0.5) / height as f32).sin();
            for x in 0..width {
                let mut m = 0.0f32;
                for dy in -1i64..=1 {
                    let yy = (y as i64 + dy).clamp(0, height as i64 - 1) as usize;
                    for dx in -1i64..=1 {
                        let xx = (x as i64 + dx).rem_euclid(width as i64) as usize;
                        m = m.max(lum[yy * width + xx]);
                    }
                }
                weights[y * width + x] = m * sin_theta;
            }
        }
        let distribution = Arc::new(Distribution2D::new(&weights, width, height));
        let peak = texels.iter().fold(0.0f32, |m, t| m.max(t.max_element())) * strength;
        let uniform = texels.iter().all(|t| *t == texels[0]);
        Ok(EnvironmentMap {
            name: name.to_string(),
            width,
            height,
            texels: Arc::new(texels),
            strength,
            rotation_rad,
            rot: (rotation_rad.cos(), rotation_rad.sin()),
            distribution,
            peak,
            uniform,
        })
    }

    /// Name (file) for reports.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Width in texels.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Height in texels.
    pub fn height(&self) -> usize {
        self.height
    }

    /// The largest radiance in the map (its brightest texel component × strength).
    pub fn peak_radiance(&self) -> f32 {
        self.peak
    }

    /// Strength multiplier.
    pub fn strength(&self) -> f32 {
        self.strength
    }

    /// Rotation about +y, radians.
    pub fn rotation_rad(&self) -> f32 {
        self.rotation_rad
    }

    /// The texel at column `x`, row `y` (row 0 = top), without the strength.
    pub fn texel(&self, x: usize, y: usize) -> Vec3 {
        self.texels[y.min(self.height - 1) * self.width + x.min(self.width - 1)]
    }

    /// World direction → map direction (undoes the rotation).
    fn to_map(&self, d: Vec3) -> Vec3 {
        // R_y(−r)·d with R_y(a) = [[cos a, 0, sin a], [0, 1, 0], [−sin a, 0, cos a]].
        let (c, s) = self.rot;
        Vec3::new(c * d.x - s * d.z, d.y, s * d.x + c * d.z)
    }

    /// Map direction → world direction.
    fn to_world(&self, d: Vec3) -> Vec3 {
        let (c, s) = self.rot;
        Vec3::new(c * d.x + s * d.z, d.y, -s * d.x + c * d.z)
    }

    /// Image coordinates (u from the left, t from the top, both in [0, 1]) of a world
    /// direction.
    pub fn direction_to_uv(&self, dir: Vec3) -> Vec2 {
        let d = self.to_map(dir).normalize_or_zero();
        if d == Vec3::ZERO || !d.is_finite() {
            return Vec2::new(0.5, 0.5);
        }
        let u = 0.5 + d.z.atan2(d.x) / (2.0 * PI);
        let t = d.y.clamp(-1.0, 1.0).acos() / PI;
        Vec2::new(u, t)
    }

    /// World direction of image coordinates (u from the left, t from the top).
    pub fn uv_to_direction(&self, uv: Vec2) -> Vec3 {
        let theta = PI * uv.y;
        let phi = 2.0 * PI * (uv.x - 0.5);
        let (st, ct) = theta.sin_cos();
        self.to_world(Vec3::new(st * phi.cos(), ct, st * phi.sin()))
    }

    fn lookup(&self, uv: Vec2) -> Vec3 {
        let x = uv.x * self.width as f32 - 0.5;
        let y = uv.y * self.height as f32 - 0.5;
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let w = self.width as i64;
        let h = self.height as i64;
        let at = |xi: i64, yi: i64| {
            let xi = xi.rem_euclid(w) as usize;
            let yi = yi.clamp(0, h - 1) as usize;
            self.texels[yi * self.width + xi]
        };
        let (x0, y0) = (x0 as i64, y0 as i64);
        let a = at(x0, y0).lerp(at(x0 + 1, y0), fx);
        let b = at(x0, y0 + 1).lerp(at(x0 + 1, y0 + 1), fx);
        a.lerp(b, fy)
    }

    /// Radiance arriving from world direction `dir` (strength applied).
    pub fn radiance(&self, dir: Vec3) -> Vec3 {
        self.lookup(self.direction_to_uv(dir)) * self.strength
    }

    /// Samples a direction: (unit world direction, radiance, pdf per unit solid angle).
    pub fn sample(&self, u: Vec2) -> Option<(Vec3, Vec3, f32)> {
        if self.distribution.marginal.integral <= 0.0 || !positive(self.strength) {
            return None;
        }
        let (uv, pdf_uv) = self.distribution.sample(u);
        let sin_theta = (PI * uv.y).sin();
        if pdf_uv <= 0.0 || sin_theta <= 0.0 {
            return None;
        }
        let dir = self.uv_to_direction(uv);
        let pdf = pdf_uv / (2.0 * PI * PI * sin_theta);
        Some((dir, self.lookup(uv) * self.strength, pdf))
    }

    /// Density (per unit solid angle) with which [`EnvironmentMap::sample`] picks `dir`.
    pub fn pdf(&self, dir: Vec3) -> f32 {
        if self.distribution.marginal.integral <= 0.0 || !positive(self.strength) {
            return 0.0;
        }
        let uv = self.direction_to_uv(dir);
        let sin_theta = (PI * uv.y).sin();
        if sin_theta <= 0.0 {
            return 0.0;
        }
        let col = ((uv.x * self.width as f32) as i64).rem_euclid(self.width as i64) as usize;
        let row = ((uv.y * self.height as f32) as usize).min(self.height - 1);
        self.distribution.pdf(col, row) / (2.0 * PI * PI * sin_theta)
    }
}

/// Loads an equirectangular EXR (first layer with R, G, B channels; alpha ignored) as an
/// environment, scaled by `strength` and turned by `rotation_rad` about +y.
pub fn load_environment_exr(path: &Path, strength: f32, rotation_rad: f32) -> Result<Environment> {
    let file = path.display().to_string();
    if !path.is_file() {
        return Err(Error::io(path, std::io::Error::new(std::io::ErrorKind::NotFound, "no such file")));
    }
    let open = || std::fs::File::open(path).map(std::io::BufReader::new);
    let source = open().map_err(|e| Error::io(path, e))?;
    decode_environment_exr(source, &file, strength, rotation_rad)
}

/// [`load_environment_exr`] from the EXR file's bytes (a file inside a package, such as a USDZ
/// archive); `name` names it in errors.
pub fn load_environment_exr_bytes(bytes: &[u8], name: &str, strength: f32, rotation_rad: f32) -> Result<Environment> {
    decode_environment_exr(std::io::Cursor::new(bytes), name, strength, rotation_rad)
}

/// Decodes the EXR from `source` (buffered) into an environment map.
fn decode_environment_exr(
    source: impl std::io::Read + std::io::Seek,
    file: &str,
    strength: f32,
    rotation_rad: f32,
) -> Result<Environment> {
    use exr::prelude::traits::*;
    struct Pixels {
        width: usize,
        data: Vec<Vec3>,
    }
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        read()
            .no_deep_data()
            .largest_resolution_level()
            .rgba_channels(
                |size: exr::math::Vec2<usize>, _: &exr::prelude::RgbaChannels| Pixels {
                    width: size.width(),
                    data: vec![Vec3::ZERO; size.width() * size.height()],
                },
                |p: &mut Pixels, pos: exr::math::Vec2<usize>, (r, g, b, _a): (f32, f32, f32, f32)| {
                    if let Some(t) = p.data.get_mut(pos.y() * p.width + pos.x()) {
                        *t = Vec3::new(r, g, b);
                    }
                },
            )
            .first_valid_layer()
            .all_attributes()
            .from_buffered(source)
    }));
    let image = match result {
        Ok(Ok(img)) => img,
        Ok(Err(e)) => return Err(Error::scene(file, "", format!("cannot read the EXR environment: {e}"))),
        Err(_) => return Err(Error::scene(file, "", "cannot read the EXR environment: malformed file")),
    };
    let size = image.layer_data.size;
    let pixels = image.layer_data.channel_data.pixels;
    let map = EnvironmentMap::new(file, size.width(), size.height(), pixels.data, strength, rotation_rad)?;
    Ok(Environment::Map(map))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small deterministic generator for the tests.
    struct Lcg(u64);
    impl Lcg {
        fn next(&mut self) -> f32 {
            self.0 = self.0.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((self.0 >> 40) as f32) / (1u64 << 24) as f32
        }
        fn vec2(&mut self) -> Vec2 {
            Vec2::new(self.next(), self.next())
        }
    }

    /// A map with a smooth gradient, a bright spot and a black band.
    fn test_map(rotation: f32) -> EnvironmentMap {
        let (w, h) = (64, 32);
        let mut t = Vec::with_capacity(w * h);
        for y in 0..h {
            for x in 0..w {
                let u = (x as f32 + 0.5) / w as f32;
                let v = (y as f32 + 0.5) / h as f32;
                let mut c = Vec3::new(0.2 + u, 0.5 * (1.0 - v), 0.3 + 0.2 * (6.0 * u).sin().abs());
                if (10..14).contains(&x) && (8..11).contains(&y) {
                    c = Vec3::new(40.0, 30.0, 20.0);
                }
                if (20..30).contains(&y) && (40..60).contains(&x) {
                    c = Vec3::ZERO;
                }
                t.push(c);
            }
        }
        EnvironmentMap::new("test", w, h, t, 1.5, rotation).unwrap()
    }

    /// ∫ L dω by a fine midpoint rule over (u, t) with the sin θ Jacobian.
    fn brute_force(env: &Environment, n_u: usize, n_t: usize) -> Vec3 {
        let mut sum = Vec3::ZERO;
        for j in 0..n_t {
            let theta = PI * (j as f32 + 0.5) / n_t as f32;
            for i in 0..n_u {
                let phi = 2.0 * PI * (i as f32 + 0.5) / n_u as f32;
                let d = Vec3::new(theta.sin() * phi.cos(), theta.cos(), theta.sin() * phi.sin());
                sum += env.radiance(d) * theta.sin();
            }
        }
        sum * (2.0 * PI * PI / (n_u * n_t) as f32)
    }

    fn importance_sampled(env: &Environment, n: usize) -> Vec3 {
        let mut rng = Lcg(7);
        let mut sum = Vec3::ZERO;
        // Stratified in the row dimension to keep the test fast and stable.
        for k in 0..n {
            let u = Vec2::new(rng.next(), (k as f32 + rng.next()) / n as f32);
            if let Some((_, l, pdf)) = env.sample(u) {
                sum += l / pdf;
            }
        }
        sum / n as f32
    }

    #[test]
    fn sampled_pdf_matches_pdf_function() {
        for rot in [0.0, 1.1] {
            let env = Environment::Map(test_map(rot));
            let mut rng = Lcg(3);
            for _ in 0..20_000 {
                let (d, l, pdf) = env.sample(rng.vec2()).expect("map is not black");
                assert!((d.length() - 1.0).abs() < 1e-4);
                let p = env.pdf(d);
                assert!((p - pdf).abs() <= 2e-3 * pdf, "pdf {pdf} vs pdf() {p} at {d}");
                let r = env.radiance(d);
                assert!((r - l).abs().max_element() <= 1e-3 * (1.0 + l.max_element()), "{l} vs {r}");
            }
        }
    }

    #[test]
    fn pdf_integrates_to_one() {
        let env = Environment::Map(test_map(0.4));
        let (n_u, n_t) = (1024, 512);
        let mut sum = 0.0f64;
        for j in 0..n_t {
            let theta = PI * (j as f32 + 0.5) / n_t as f32;
            for i in 0..n_u {
                let phi = 2.0 * PI * (i as f32 + 0.5) / n_u as f32;
                let d = Vec3::new(theta.sin() * phi.cos(), theta.cos(), theta.sin() * phi.sin());
                sum += (env.pdf(d) * theta.sin()) as f64;
            }
        }
        let integral = sum * (2.0 * PI as f64 * PI as f64) / (n_u * n_t) as f64;
        assert!((integral - 1.0).abs() < 5e-3, "∫ pdf dω = {integral}");
    }

    #[test]
    fn importance_sampling_matches_brute_force() {
        for rot in [0.0, -2.3] {
            let env = Environment::Map(test_map(rot));
            let exact = brute_force(&env, 2048, 1024);
            let est = importance_sampled(&env, 200_000);
            let rel = ((est - exact) / exact).abs().max_element();
            assert!(rel < 0.01, "rotation {rot}: IS {est} vs brute force {exact} ({rel})");
        }
    }

    #[test]
    fn constant_map_equals_constant_environment() {
        let c = Vec3::new(0.3, 0.6, 1.2);
        let map = Environment::Map(EnvironmentMap::new("c", 32, 16, vec![c; 32 * 16], 2.0, 0.7).unwrap());
        let konst = Environment::Constant(c * 2.0);
        let mut rng = Lcg(11);
        for _ in 0..1000 {
            let d = uniform_sphere(rng.vec2());
            assert!((map.radiance(d) - konst.radiance(d)).abs().max_element() < 1e-5);
        }
        let exact = c * 2.0 * 4.0 * PI;
        for env in [&map, &konst] {
            let est = importance_sampled(env, 100_000);
            assert!(((est - exact) / exact).abs().max_element() < 0.01, "{est} vs {exact}");
            assert!(((brute_force(env, 256, 128) - exact) / exact).abs().max_element() < 0.01);
        }
        // The constant environment's sampler is uniform over the sphere.
        let (d, l, pdf) = konst.sample(Vec2::new(0.3, 0.8)).unwrap();
        assert!((d.length() - 1.0).abs() < 1e-5 && l == c * 2.0 && (pdf - 1.0 / (4.0 * PI)).abs() < 1e-7);
    }

    #[test]
    fn black_is_never_sampled() {
        assert!(Environment::Black.sample(Vec2::splat(0.5)).is_none());
        assert_eq!(Environment::Black.pdf(Vec3::Y), 0.0);
        let dark = EnvironmentMap::new("z", 4, 2, vec![Vec3::ZERO; 8], 1.0, 0.0).unwrap();
        assert!(Environment::Map(dark).sample(Vec2::splat(0.5)).is_none());
        assert!(Environment::Constant(Vec3::ZERO).sample(Vec2::splat(0.5)).is_none());
    }

    /// Cycles' `direction_to_equirectangular` (kernel/camera/projection.h), v = 0 at the
    /// bottom of the image.
    fn blender_uv(d: Vec3) -> Vec2 {
        let d = d.normalize();
        let u = (d.y.atan2(d.x) - PI) / (-2.0 * PI);
        let v = (d.z.acos() - PI) / (-PI);
        Vec2::new(u, v)
    }

    #[test]
    fn mapping_matches_blender() {
        let map = test_map(0.0);
        let mut rng = Lcg(5);
        for _ in 0..1000 {
            let g = uniform_sphere(rng.vec2());
            // glTF (X, Y, Z) = Blender (x, z, −y)  ⇒  Blender (x, y, z) = (X, −Z, Y).
            let b = blender_uv(Vec3::new(g.x, -g.z, g.y));
            let ours = map.direction_to_uv(g);
            let du = (ours.x - b.x).rem_euclid(1.0);
            assert!(du.min(1.0 - du) < 1e-5, "u {} vs Blender {}", ours.x, b.x);
            assert!((ours.y - (1.0 - b.y)).abs() < 1e-5, "t {} vs Blender 1 − v {}", ours.y, 1.0 - b.y);
        }
        // Landmarks: image centre towards +x, top row up, u = 0.25 towards −z.
        assert!((map.direction_to_uv(Vec3::X) - Vec2::new(0.5, 0.5)).length() < 1e-6);
        assert!(map.direction_to_uv(Vec3::Y).y < 1e-6);
        assert!((map.direction_to_uv(Vec3::NEG_Z).x - 0.25).abs() < 1e-6);
        // uv_to_direction inverts direction_to_uv.
        let rotated = test_map(0.9);
        for _ in 0..100 {
            let uv = Vec2::new(rng.next(), 0.02 + 0.96 * rng.next());
            let back = rotated.direction_to_uv(rotated.uv_to_direction(uv));
            assert!((back - uv).length() < 1e-4, "{uv} → {back}");
        }
    }

    #[test]
    fn rotation_turns_the_map_counter_clockwise_about_y() {
        let base = test_map(0.0);
        let turned = test_map(0.5);
        let r = glam::Quat::from_rotation_y(0.5);
        let mut rng = Lcg(9);
        for _ in 0..200 {
            let d = uniform_sphere(rng.vec2());
            // What the unrotated map shows at d is shown by the turned map at R_y(0.5)·d.
            assert!((base.radiance(d) - turned.radiance(r * d)).abs().max_element() < 1e-3);
        }
    }

    #[test]
    fn exr_round_trip_and_errors() {
        let dir = std::env::temp_dir().join(format!("petzval-env-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("env.exr");
        let (w, h) = (16usize, 8usize);
        let value = |x: usize, y: usize| (x as f32 * 0.25, y as f32 * 0.5, 1.0);
        exr::prelude::write_rgb_file(&path, w, h, value).unwrap();
        let env = load_environment_exr(&path, 2.0, 0.0).unwrap();
        let Environment::Map(m) = &env else { panic!("not a map") };
        assert_eq!((m.width(), m.height()), (w, h));
        assert_eq!(m.texel(3, 5), Vec3::new(0.75, 2.5, 1.0));
        // Texel (x, y)'s centre direction sees that texel × strength.
        let d = m.uv_to_direction(Vec2::new(3.5 / w as f32, 5.5 / h as f32));
        assert!((env.radiance(d) - Vec3::new(1.5, 5.0, 2.0)).abs().max_element() < 1e-4);

        let garbage = dir.join("garbage.exr");
        std::fs::write(&garbage, b"v/1\x01 this is not an exr file at all").unwrap();
        let e = load_environment_exr(&garbage, 1.0, 0.0).unwrap_err().to_string();
        assert!(e.contains("garbage.exr"), "{e}");
        assert!(load_environment_exr(&dir.join("missing.exr"), 1.0, 0.0).is_err());
        assert!(load_environment_exr(&path, -1.0, 0.0).is_err());
        std::fs::remove_dir_all(&dir).ok();
    }
}
