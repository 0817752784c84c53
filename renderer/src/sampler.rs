//! Per-pixel Owen-scrambled Sobol samples (`sobol_burley`), deterministic from (pixel, sample
//! index, seed), so images do not depend on the thread count or tile order.
//!
//! Dimensions are consumed in order by the camera (film 2, lens 2, wavelength 1) and then by the
//! integrator. Past the 256 dimensions the Sobol tables hold, a hashed (PCG) stream continues.
//! Sobol dimensions are drawn eight at a time and handed out one by one: on CPUs with AVX2
//! (detected at run time; `PETZVAL_SIMD=baseline` forces the baseline) by one 8-lane pass of
//! `sobol_burley::sample_4d`'s own operations (the index shuffle done once per sample, native
//! 32-bit multiplies, the bit reversal by byte shuffles), else by two calls of `sample_4d`.
//! Both give `sobol_burley::sample`'s values, bit for bit.

/// Sample stream for one pixel sample.
#[derive(Debug, Clone)]
pub struct PixelSampler {
    seed: u32,
    sample_index: u32,
    dimension: u32,
    /// The sample index as Sobol-Burley shuffles it for this pixel (bit-reversed, top 16 bits:
    /// the digits the Sobol matrices see), the same for every dimension of the sample.
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
    index_rev: u32,
    /// Dimensions 8⌊(dimension − 1)/8⌋ to +7, valid once `dimension` has passed their first.
    block: [f32; 8],
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

/// Whether this process computes Sobol blocks with AVX2 (detected at first use;
/// `PETZVAL_SIMD=baseline` forces the baseline). Both give the same values.
#[cfg(target_arch = "x86_64")]
static USE_AVX2: std::sync::LazyLock<bool> = std::sync::LazyLock::new(|| {
    !std::env::var("PETZVAL_SIMD").is_ok_and(|v| v == "baseline") && std::arch::is_x86_feature_detected!("avx2")
});

/// Sobol-Burley's direction vectors (bit-reversed) of two consecutive dimension sets, as the
/// eight lanes of one vector per index digit: `SOBOL_PAIRS[k][p]` holds digit `p` of dimensions
/// 8k … 8k + 7. Read out of `sobol_burley` itself (the Sobol value of an index with only digit
/// `p` set is that digit's vector), so the values are the crate's.
#[cfg(target_arch = "x86_64")]
static SOBOL_PAIRS: std::sync::LazyLock<Vec<[[u32; 8]; 16]>> = std::sync::LazyLock::new(|| {
    use sobol_burley::parts::sobol_int4_rev;
    (0..sobol_burley::NUM_DIMENSION_SETS_4D / 2)
        .map(|k| {
            std::array::from_fn(|p| {
                let lo: [u32; 4] = sobol_int4_rev(0x8000_0000 >> p, 2 * k).into();
                let hi: [u32; 4] = sobol_int4_rev(0x8000_0000 >> p, 2 * k + 1).into();
                [lo[0], lo[1], lo[2], lo[3], hi[0], hi[1], hi[2], hi[3]]
            })
        })
        .collect()
});

/// Per-lane constants of Sobol-Burley's Owen scramble (`sobol_burley::sample_4d`).
#[cfg(target_arch = "x86_64")]
const SCRAMBLE_LANES: [u32; 4] = [0x912f_69ba, 0x174f_18ab, 0x691e_72ca, 0xb40c_c1b8];

/// Dimensions 8k … 8k + 7 of a sample whose shuffled index is `index_rev`, with AVX2: the
/// operations of `sobol_burley::sample_4d` (Sobol digits, hash, Owen scramble, bit reversal,
/// float) on eight lanes, so the same values.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn sobol_pair_avx2(index_rev: u32, k: u32, seed: u32) -> [f32; 8] {
    use std::arch::x86_64::*;
    let vecs = &SOBOL_PAIRS[k as usize];
    let load = |a: &[u32; 8]| {
        // SAFETY: 8 u32s, unaligned load.
        unsafe { _mm256_loadu_si256(a.as_ptr() as *const __m256i) }
    };
    // 1. Sobol digits: the direction vectors of the index's set digits, XORed.
    let mut sobol = _mm256_setzero_si256();
    let mut digits = index_rev & 0xffff_0000;
    while digits != 0 {
        let b = digits.trailing_zeros();
        digits &= digits - 1;
        sobol = _mm256_xor_si256(sobol, load(&vecs[(31 - b) as usize]));
    }
    // 2. Scramble per lane: hash of (seed, dimension set, lane).
    let (ds0, ds1) = (2 * k, 2 * k + 1);
    let sm = seed.wrapping_mul(0x9c8f_2d3b);
    let c = SCRAMBLE_LANES;
    let mut h = load(&[
        sm ^ ds0 ^ c[0],
        sm ^ ds0 ^ c[1],
        sm ^ ds0 ^ c[2],
        sm ^ ds0 ^ c[3],
        sm ^ ds1 ^ c[0],
        sm ^ ds1 ^ c[1],
        sm ^ ds1 ^ c[2],
        sm ^ ds1 ^ c[3],
    ]);
    let k32 = |v: u32| _mm256_set1_epi32(v as i32);
    h = _mm256_xor_si256(h, k32(0xe6fe_3beb));
    h = _mm256_xor_si256(h, _mm256_srli_epi32::<16>(h));
    h = _mm256_mullo_epi32(h, k32(0x7feb_352d));
    h = _mm256_xor_si256(h, _mm256_srli_epi32::<15>(h));
    h = _mm256_mullo_epi32(h, k32(0x846c_a68b));
    h = _mm256_xor_si256(h, _mm256_srli_epi32::<16>(h));
    // 3. Owen scramble (Burley's hash of the reversed bits).
    let mut n = sobol;
    n = _mm256_xor_si256(n, _mm256_mullo_epi32(n, k32(0x3d20_adea)));
    n = _mm256_add_epi32(n, h);
    n = _mm256_mullo_epi32(n, _mm256_or_si256(_mm256_srli_epi32::<16>(h), k32(1)));
    n = _mm256_xor_si256(n, _mm256_mullo_epi32(n, k32(0x0552_6c56)));
    n = _mm256_xor_si256(n, _mm256_mullo_epi32(n, k32(0x53a2_2864)));
    // 4. Un-reverse the bits: bytes reversed in each lane, then each byte's bits by nibbles.
    let bytes = _mm256_setr_epi8(
        3, 2, 1, 0, 7, 6, 5, 4, 11, 10, 9, 8, 15, 14, 13, 12, 3, 2, 1, 0, 7, 6, 5, 4, 11, 10, 9, 8, 15, 14, 13, 12,
    );
    n = _mm256_shuffle_epi8(n, bytes);
    let nibble_rev = _mm256_setr_epi8(
        0, 8, 4, 12, 2, 10, 6, 14, 1, 9, 5, 13, 3, 11, 7, 15, 0, 8, 4, 12, 2, 10, 6, 14, 1, 9, 5, 13, 3, 11, 7, 15,
    );
    let low = _mm256_set1_epi8(0x0f);
    let lo = _mm256_shuffle_epi8(nibble_rev, _mm256_and_si256(n, low));
    let hi = _mm256_shuffle_epi8(nibble_rev, _mm256_and_si256(_mm256_srli_epi32::<4>(n), low));
    n = _mm256_or_si256(_mm256_slli_epi32::<4>(lo), hi);
    // 5. To [0, 1): the top 23 bits as a mantissa.
    let f = _mm256_sub_ps(
        _mm256_castsi256_ps(_mm256_or_si256(_mm256_srli_epi32::<9>(n), k32(0x3f80_0000))),
        _mm256_set1_ps(1.0),
    );
    let mut out = [0f32; 8];
    // SAFETY: `out` holds 8 f32s.
    unsafe { _mm256_storeu_ps(out.as_mut_ptr(), f) };
    out
}

impl PixelSampler {
    /// The stream for sample `sample_index` of pixel (x, y) under render seed `seed`.
    pub fn new(x: u32, y: u32, sample_index: u32, seed: u32) -> Self {
        use sobol_burley::parts::{hash, owen_scramble_rev};
        let pixel_seed = hash_u32(x.wrapping_mul(0x9E37_79B9) ^ hash_u32(y ^ hash_u32(seed.wrapping_add(0x6a09_e667))));
        // the index shuffle of `sobol_burley::sample_4d`, done once for the whole sample
        let index_rev = owen_scramble_rev(sample_index.reverse_bits(), hash(pixel_seed ^ 0x79c6_8e4a));
        PixelSampler { seed: pixel_seed, sample_index, dimension: 0, index_rev, block: [0.0; 8] }
    }

    /// Dimensions 8k … 8k + 7 (the values of `sobol_burley::sample_4d` for sets 2k and 2k + 1).
    #[inline]
    fn sobol_pair(&self, k: u32) -> [f32; 8] {
        #[cfg(target_arch = "x86_64")]
        if *USE_AVX2 {
            // SAFETY: the CPU was checked for AVX2 (`USE_AVX2`).
            return unsafe { sobol_pair_avx2(self.index_rev, k, self.seed) };
        }
        let a = sobol_burley::sample_4d(self.sample_index, 2 * k, self.seed);
        let b = sobol_burley::sample_4d(self.sample_index, 2 * k + 1, self.seed);
        [a[0], a[1], a[2], a[3], b[0], b[1], b[2], b[3]]
    }

    /// Next value in [0, 1).
    #[inline(always)]
    pub fn next_1d(&mut self) -> f32 {
        let d = self.dimension;
        self.dimension += 1;
        if d < sobol_burley::NUM_DIMENSIONS {
            // 1. A new block of eight: compute it whole (identical to `sobol_burley::sample`).
            if d.is_multiple_of(8) {
                self.block = self.sobol_pair(d / 8);
            }
            self.block[(d % 8) as usize]
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

    /// The eight-at-a-time stream gives exactly `sobol_burley::sample`'s values, dimension by
    /// dimension, and the hashed stream past the tables; whichever build this CPU runs.
    #[test]
    fn blocks_of_eight_match_single_dimensions() {
        let mut cases = vec![(0, 0, 0, 0), (17, 3, 5, 1), (639, 426, 255, 99), (5, 9, 4095, 7), (1, 2, 65535, 3)];
        cases.extend((0..200u32).map(|i| (hash_u32(i) % 4096, hash_u32(i + 7) % 4096, hash_u32(i + 13) % 65536, i)));
        for (x, y, s, seed) in cases {
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

    /// The AVX2 block (where this CPU has AVX2) against two calls of `sobol_burley::sample_4d`,
    /// over every dimension pair and 20 000 (sample, seed) pairs.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn the_avx2_block_is_sample_4d() {
        if !std::arch::is_x86_feature_detected!("avx2") {
            return;
        }
        for i in 0..20_000u32 {
            let sp = PixelSampler::new(i % 97, i / 97, hash_u32(i) % 65536, i / 3);
            for k in 0..sobol_burley::NUM_DIMENSION_SETS_4D / 2 {
                // SAFETY: AVX2 was detected above.
                let fast = unsafe { sobol_pair_avx2(sp.index_rev, k, sp.seed) };
                let a = sobol_burley::sample_4d(sp.sample_index, 2 * k, sp.seed);
                let b = sobol_burley::sample_4d(sp.sample_index, 2 * k + 1, sp.seed);
                let want = [a[0], a[1], a[2], a[3], b[0], b[1], b[2], b[3]];
                assert_eq!(
                    fast.map(f32::to_bits),
                    want.map(f32::to_bits),
                    "sample {} seed {} pair {k}",
                    sp.sample_index,
                    sp.seed
                );
            }
        }
    }
}
