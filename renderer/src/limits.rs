//! Every resource and value limit of the renderer in one place (issue 12), checked before the
//! work that would exceed it, and stated in the error. docs/reliability.md has the same table
//! with the front end that checks each.
//!
//! | limit | value | checked by |
//! |---|---|---|
//! | [`MAX_SIDE_PX`] | 16 384 px per side | [`crate::render::RenderSettings::validate`] |
//! | [`MAX_PIXELS`] | 100 MP | the same |
//! | [`FILM_BYTES_PER_PIXEL`] × pixels | at most [`MEMORY_SHARE`] of the available memory | the same, with [`available_memory_bytes`] |
//! | [`MAX_SPP`] | 2²⁰ samples per pixel | the same |
//! | [`MAX_DEPTH`] | 1 024 bounces | the same |
//! | [`MAX_COORD`] | 10¹² scene units | triangles beyond it are skipped with a warning ([`crate::RenderScene::new`]) |
//! | [`MAX_RADIANCE`] | 10¹⁵ (W/sr/m², W/sr, W/m²) | emission, lights and environment texels ([`crate::scene::Scene::check_values`]) |
//! | [`MAX_STORED_TRIANGLES`] | 2³¹ − 1 stored triangles | [`crate::RenderScene::new`] |
//! | [`BVH_BYTES_PER_TRIANGLE`] × stored triangles | at most [`MEMORY_SHARE`] of the available memory | the same, before the BVH build |
//! | [`MAX_NODE_INSTANCES`] | 10⁷ instances from a glTF node graph | the glTF loader |
//! | [`MAX_FILE_BYTES`] | 1 GiB per glTF buffer or image file | the glTF loader |
//! | lens lengths | 10⁷ mm ([`crate::optics::prescription::MAX_LENGTH_MM`]) | every lens format |
//! | glass Abbe number | 0 or 5…1000 ([`crate::optics::prescription::MIN_ABBE`], [`crate::optics::prescription::MAX_ABBE`]) | every lens format |
//! | [`LAYER_BYTES_PER_TEXEL`] × layers × texels | at most [`MEMORY_SHARE`] of the available memory | `dof::make_layers`, before the layers are traced |
//! | LRTF tables | 2…4096 cells per axis, 1…64 wavelengths, size equal to the data present | `LrtfTable::load` |

/// Largest image side.
pub const MAX_SIDE_PX: u32 = 16_384;

/// Largest image, in pixels.
pub const MAX_PIXELS: u64 = 100_000_000;

/// Largest samples per pixel.
pub const MAX_SPP: u32 = 1 << 20;

/// Largest path depth.
pub const MAX_DEPTH: u32 = 1024;

/// Largest coordinate of a triangle vertex (beyond it the BVH's f32 box arithmetic overflows).
pub const MAX_COORD: f32 = 1e12;

/// Largest emitted radiance, radiant intensity or irradiance of any light, emissive material or
/// environment texel (after its strength). The film sums f32 values: 10¹⁵ keeps 10²³ of headroom
/// for light-sampling weights and sample counts, and no physical source comes near it (the sun's
/// disc is about 2·10⁷ W/sr/m²).
pub const MAX_RADIANCE: f32 = 1e15;

/// Largest number of stored (not instanced) triangles: the BVH indexes them with 32 bits.
pub const MAX_STORED_TRIANGLES: usize = i32::MAX as usize;

/// Largest number of instances a glTF node graph or a USD stage's instancing may expand to.
pub const MAX_NODE_INSTANCES: usize = 10_000_000;

/// Largest glTF buffer or image file read.
pub const MAX_FILE_BYTES: u64 = 1 << 30;

/// Peak memory per image pixel during a render: the film's sums, the image of the last pass
/// kept for interrupts, the finished image, the output's channel copies, and adaptive
/// sampling's flags (the converged pixels and each step's tests, one byte each).
pub const FILM_BYTES_PER_PIXEL: u64 = PIXEL_SUMS_BYTES + 3 * IMAGE_BYTES_PER_PIXEL + 16 + 3;

/// Peak memory per texel of one depth-peeled layer of the preview methods: depth, radiance,
/// coverage, tangent plane and shaded flag (37 B), the surfaces and radiance rows while they are
/// traced (44 B), and IBRT's spans and pyramid (about 11 B).
pub const LAYER_BYTES_PER_TEXEL: u64 = 96;

/// Bytes of one pixel's sums on the film (`film::PixelSums`; the film asserts it at compile time).
pub const PIXEL_SUMS_BYTES: u64 = 18 * 4;

/// Bytes of one pixel of a finished [`crate::film::Image`] (RGBA, depth, normal, albedo).
const IMAGE_BYTES_PER_PIXEL: u64 = (4 + 1 + 3 + 3) * 4;

/// Peak memory per stored triangle while building the BVHs: the builder's working set, the
/// finished nodes and the mesh. Measured: a 1 002 528-triangle glTF peaks at 502 MB resident
/// (`/usr/bin/time -v petzval render big.gltf --resolution 16x16 --spp 1`), 493 B per triangle;
/// rounded up.
pub const BVH_BYTES_PER_TRIANGLE: u64 = 512;

/// Share of the available memory a render may plan to use.
pub const MEMORY_SHARE: f64 = 0.9;

/// Memory available to this process: `PETZVAL_MEMORY_BYTES` when set (a budget of the user's),
/// else the smaller of `MemAvailable` (/proc/meminfo) and the cgroup's `memory.max` less its
/// `memory.current` (containers); None when none can be read (then no memory check is made).
pub fn available_memory_bytes() -> Option<u64> {
    if let Some(v) = std::env::var("PETZVAL_MEMORY_BYTES").ok().and_then(|v| v.trim().parse::<u64>().ok()) {
        return Some(v);
    }
    let read = |p: &str| std::fs::read_to_string(p).ok();
    let meminfo = read("/proc/meminfo").and_then(|text| {
        let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?.to_string();
        line.split_whitespace().nth(1)?.parse::<u64>().ok()?.checked_mul(1024)
    });
    let cgroup = (|| {
        let max: u64 = read("/sys/fs/cgroup/memory.max")?.trim().parse().ok()?;
        let current: u64 = read("/sys/fs/cgroup/memory.current")?.trim().parse().ok()?;
        Some(max.saturating_sub(current))
    })();
    match (meminfo, cgroup) {
        (Some(a), Some(b)) => Some(a.min(b)),
        (a, b) => a.or(b),
    }
}

/// Whether `bytes` fits the memory budget; Err carries the budget in bytes.
pub fn check_memory(bytes: u64) -> Result<(), u64> {
    match available_memory_bytes() {
        Some(avail) if bytes as f64 > MEMORY_SHARE * avail as f64 => Err((MEMORY_SHARE * avail as f64) as u64),
        _ => Ok(()),
    }
}

/// The end of a memory error: "more than the 9.1 GiB a render may use (90 % of …)".
pub fn over_budget(budget: u64) -> String {
    format!(
        "more than the {} a render may use ({:.0} % of the memory available; PETZVAL_MEMORY_BYTES sets it)",
        format_bytes(budget),
        MEMORY_SHARE * 100.0
    )
}

/// `bytes` as "12.3 GiB" (or MiB below a GiB).
pub fn format_bytes(bytes: u64) -> String {
    let gib = bytes as f64 / (1u64 << 30) as f64;
    if gib >= 1.0 {
        format!("{gib:.1} GiB")
    } else {
        format!("{:.0} MiB", bytes as f64 / (1u64 << 20) as f64)
    }
}
