//! Small deterministic RNG for weight init and loss permutations.
//!
//! burn's own RNG is seeded per backend and may be global, so parallel tests or a second model
//! built on the same device would perturb each other's draws. Generating on the host with our
//! own stream makes "same seed → same weights" hold regardless of threading or backend.

/// SplitMix64 (Steele, Lea, Flood 2014): tiny, full-period, good enough for init and shuffles.
#[derive(Clone, Debug)]
pub struct SplitMix64 {
    state: u64,
}

impl SplitMix64 {
    pub fn new(seed: u64) -> Self {
        Self { state: seed }
    }

    /// A child stream whose draws do not overlap the parent's in practice; used to give every
    /// layer its own stream so that changing one layer's size leaves the others' weights alone.
    pub fn derive(seed: u64, tag: u64) -> Self {
        let mut s = Self::new(seed ^ tag.wrapping_mul(0xD1B5_4A32_D192_ED03));
        s.next_u64();
        s
    }

    pub fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1) with 53 random bits.
    pub fn next_f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform in [-bound, bound).
    pub fn symmetric(&mut self, bound: f64) -> f32 {
        ((2.0 * self.next_f64() - 1.0) * bound) as f32
    }

    /// Uniform integer in [0, n); n must be > 0. Lemire's multiply-shift, bias < 2^-32 for the
    /// sizes used here (n < 2^32).
    pub fn below(&mut self, n: usize) -> usize {
        (((self.next_u64() >> 32) * n as u64) >> 32) as usize
    }

    /// A uniformly random permutation of 0..n (Fisher–Yates).
    pub fn permutation(&mut self, n: usize) -> Vec<usize> {
        let mut p: Vec<usize> = (0..n).collect();
        for i in (1..n).rev() {
            let j = self.below(i + 1);
            p.swap(i, j);
        }
        p
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn permutation_is_a_permutation_and_seeded() {
        let p = SplitMix64::new(7).permutation(1000);
        let mut seen = vec![false; 1000];
        for &i in &p {
            assert!(!seen[i]);
            seen[i] = true;
        }
        assert_eq!(p, SplitMix64::new(7).permutation(1000));
        assert_ne!(p, SplitMix64::new(8).permutation(1000));
    }
}
