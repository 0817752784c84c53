//! Per-pixel Owen-scrambled Sobol samples (`sobol_burley`), deterministic from (pixel, sample
//! index, seed), so images do not depend on the thread count or tile order.
//!
//! Dimensions are consumed in order by the camera (film 2, lens 2, wavelength 1) and then by the
//! integrator. Past the 256 dimensions the Sobol tables hold, a hashed (PCG) stream continues.
//! Sobol dimensions are drawn four at a time (`sobol_burley::sample_4d`, the same values as four
//! calls of `sample`, computed in one SIMD pass) and handed out one by one.

/// Sample stream for one pixel sample.
#[derive(Debug, Clone)]
pub struct PixelSampler {
    seed: u32,
    sample_index: u32,
    dimension: u32,
    /// Dimensions 4⌊(dimension − 1)/4⌋ to +3, valid once `dimension` has passed their first.
    block: [f32; 4],
}

/// Mixes bits (a 32-bit finaliser from the hash-prospector).
#[inline]
pub fn hash_u32(mut x: u32) -> u32 {
    x ^= x >> 16;
    x = x.wrapping_mul(0x7feb_352d);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846c_a68b);
    x ^= x >> 16;
    x
}

impl PixelSampler {
    /// The stream for sample `sample_index` of pixel (x, y) under render seed `seed`.
    pub fn new(x: u32, y: u32, sample_index: u32, seed: u32) -> Self {
        let pixel_seed = hash_u32(x.wrapping_mul(0x9E37_79B9) ^ hash_u32(y ^ hash_u32(seed.wrapping_add(0x6a09_e667))));
        PixelSampler { seed: pixel_seed, sample_index, dimension: 0, block: [0.0; 4] }
    }

    /// Next value in [0, 1).
    #[inline]
    pub fn next_1d(&mut self) -> f32 {
        let d = self.dimension;
        self.dimension += 1;
        if d < sobol_burley::NUM_DIMENSIONS {
            // 1. A new block of four: compute it whole (identical to `sobol_burley::sample`).
            if d.is_multiple_of(4) {
                self.block = sobol_burley::sample_4d(self.sample_index, d / 4, self.seed);
            }
            self.block[(d % 4) as usize]
        } else {
            let h = hash_u32(self.seed ^ hash_u32(self.sample_index ^ hash_u32(d)));
            (h >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
        }
    }

    /// Next pair in [0, 1)².
    #[inline]
    pub fn next_2d(&mut self) -> glam::Vec2 {
        glam::Vec2::new(self.next_1d(), self.next_1d())
    }

    /// Dimensions used so far.
    pub fn dimension(&self) -> u32 {
        self.dimension
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The four-at-a-time stream gives exactly `sobol_burley::sample`'s values, dimension by
    /// dimension, and the hashed stream past the tables.
    #[test]
    fn blocks_of_four_match_single_dimensions() {
        for (x, y, s, seed) in [(0, 0, 0, 0), (17, 3, 5, 1), (639, 426, 255, 99), (5, 9, 4095, 7)] {
            let mut sp = PixelSampler::new(x, y, s, seed);
            for d in 0..sobol_burley::NUM_DIMENSIONS + 9 {
                let want = if d < sobol_burley::NUM_DIMENSIONS {
                    sobol_burley::sample(s, d, sp.seed)
                } else {
                    let h = hash_u32(sp.seed ^ hash_u32(s ^ hash_u32(d)));
                    (h >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
                };
                assert_eq!(sp.next_1d().to_bits(), want.to_bits(), "pixel ({x}, {y}) sample {s} dimension {d}");
            }
        }
    }
}
