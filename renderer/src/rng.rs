//! Random numbers for rendering: one independent PCG32 stream per (seed, pixel, sample), so an
//! image depends only on the seed, never on how pixels are split over threads.

use glam::Vec2;

/// PCG32 (O'Neill 2014), XSH-RR output.
#[derive(Clone, Debug)]
pub struct Pcg32 {
    state: u64,
    inc: u64,
}

const MULT: u64 = 6364136223846793005;

/// SplitMix64 finaliser: decorrelates nearby integers before they seed a stream.
pub fn mix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

impl Pcg32 {
    pub fn new(seed: u64, stream: u64) -> Self {
        let mut r = Pcg32 { state: 0, inc: (stream << 1) | 1 };
        r.next_u32();
        r.state = r.state.wrapping_add(seed);
        r.next_u32();
        r
    }

    /// The stream of sample `sample` of pixel `pixel` in a render seeded with `seed`.
    pub fn for_sample(seed: u64, pixel: u64, sample: u64) -> Self {
        let a = mix64(seed ^ mix64(pixel.wrapping_mul(0x9E37_79B9) ^ (sample << 40)));
        let b = mix64(a ^ sample.wrapping_add(pixel << 20));
        Pcg32::new(a, b)
    }

    /// The state and increment, for code that keeps many streams in arrays (`integrator::wave`).
    pub(crate) fn parts(&self) -> (u64, u64) {
        (self.state, self.inc)
    }

    pub(crate) fn from_parts(state: u64, inc: u64) -> Self {
        Pcg32 { state, inc }
    }

    pub fn next_u32(&mut self) -> u32 {
        let old = self.state;
        self.state = old.wrapping_mul(MULT).wrapping_add(self.inc);
        let xorshifted = (((old >> 18) ^ old) >> 27) as u32;
        let rot = (old >> 59) as u32;
        xorshifted.rotate_right(rot)
    }

    /// Uniform in [0, 1): 24 random mantissa bits, so 1.0 is never returned.
    pub fn next_f32(&mut self) -> f32 {
        (self.next_u32() >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
    }

    pub fn next_2d(&mut self) -> Vec2 {
        Vec2::new(self.next_f32(), self.next_f32())
    }

    /// Uniform integer in [0, n) (Lemire's multiply-shift; bias < 2^-32·n, negligible here).
    pub fn below(&mut self, n: u32) -> u32 {
        ((self.next_u32() as u64 * n as u64) >> 32) as u32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uniform_floats_are_in_range_and_mean_half() {
        let mut r = Pcg32::for_sample(7, 3, 1);
        let n = 100_000;
        let mut s = 0.0f64;
        for _ in 0..n {
            let x = r.next_f32();
            assert!((0.0..1.0).contains(&x));
            s += x as f64;
        }
        // Std. error of the mean of U(0,1) is 1/sqrt(12 n) ≈ 9.1e-4; 5 of them is a 5-sigma bound.
        assert!((s / n as f64 - 0.5).abs() < 5.0 * 9.1e-4);
    }

    #[test]
    fn neighbouring_streams_differ() {
        let a: Vec<u32> = (0..8)
            .map({
                let mut r = Pcg32::for_sample(1, 0, 0);
                move |_| r.next_u32()
            })
            .collect();
        let b: Vec<u32> = (0..8)
            .map({
                let mut r = Pcg32::for_sample(1, 0, 1);
                move |_| r.next_u32()
            })
            .collect();
        let c: Vec<u32> = (0..8)
            .map({
                let mut r = Pcg32::for_sample(1, 1, 0);
                move |_| r.next_u32()
            })
            .collect();
        assert_ne!(a, b);
        assert_ne!(a, c);
        assert_ne!(b, c);
    }
}
