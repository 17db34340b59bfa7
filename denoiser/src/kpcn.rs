//! KPCN (Bako et al. 2017 as used by the seed, method.md §3, §5): a column of valid 5×5
//! convolutions predicting a k×k softmax kernel per pixel, one column per branch; the channel
//! layout of the columns' inputs; the recombination of the two branches.

use burn::config::Config;
use burn::tensor::{Device, Tensor};

use crate::column::Column;
use crate::layers::{center_crop, conv_macs, sanitize, Activation, ConvStack, Init, Padding, INPUT_LIMIT};
use crate::ALBEDO_EPS;

/// Channel counts of the per-branch inputs (method.md §2, §4.2, §5).
pub mod channels {
    /// Colour (3), its variance (1) and x/y gradients (6) — the D or P block.
    pub const COLOUR_BLOCK: usize = 10;
    /// N, σ²_N, ∂N, Z, σ²_Z, ∂Z, A, σ²_A, ∂A.
    pub const G_BLOCK: usize = 24;
    /// Pixel mean of the per-sample P-buffers.
    pub const P_FEATURES: usize = 12;
    /// f_P plus its variance channel v_P.
    pub const P_BLOCK: usize = P_FEATURES + 1;
    /// Offset of the albedo A inside the G block (after N 3+1+6, Z 1+1+2).
    pub const G_ALBEDO: usize = 14;
}

/// Which guidance a KPCN sees (method.md §5).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Variant {
    /// D_G: colour block + G-buffer block.
    G,
    /// D_P: colour block + f_P + v_P.
    P,
    /// Baseline G+P: colour + G + path-weight mean + f_P + v_P.
    GP,
}

impl Variant {
    pub fn in_channels(self) -> usize {
        use channels::*;
        match self {
            Variant::G => COLOUR_BLOCK + G_BLOCK,
            Variant::P => COLOUR_BLOCK + P_BLOCK,
            Variant::GP => COLOUR_BLOCK + G_BLOCK + 1 + P_BLOCK,
        }
    }
}

/// One KPCN column. Paper size: 9 layers, width 100, 5×5, 21×21 filter (`paper-half`: width 50).
#[derive(Config, Debug)]
pub struct KpcnConfig {
    /// Input channels; the first 3 are the colour that gets filtered.
    pub in_channels: usize,
    /// Convolution layers including the kernel-predicting output layer.
    #[config(default = 9)]
    pub depth: usize,
    /// Hidden width.
    #[config(default = 100)]
    pub width: usize,
    /// Convolution kernel size (odd).
    #[config(default = 5)]
    pub conv_kernel: usize,
    /// Predicted filter size k (odd); the output layer has k² channels.
    #[config(default = 21)]
    pub filter_size: usize,
}

impl KpcnConfig {
    /// Pixels lost per side by the valid convolutions.
    pub fn margin(&self) -> usize {
        self.depth * (self.conv_kernel / 2)
    }

    fn widths(&self) -> Vec<usize> {
        let mut w = vec![self.in_channels];
        w.extend(std::iter::repeat_n(self.width, self.depth - 1));
        w.push(self.filter_size * self.filter_size);
        w
    }

    /// Multiply-accumulates per output pixel: convolutions plus the k²·3 filter taps.
    pub fn macs_per_pixel(&self) -> u64 {
        let w = self.widths();
        let convs: u64 = w.windows(2).map(|p| conv_macs(p[0], p[1], self.conv_kernel)).sum();
        convs + (self.filter_size * self.filter_size * 3) as u64
    }

    /// Convolution kernel weights (no biases): a lower bound on the parameter count, which a
    /// weight file must hold.
    pub fn kernel_weights(&self) -> u64 {
        self.widths().windows(2).map(|p| conv_macs(p[0], p[1], self.conv_kernel)).sum()
    }

    /// Xavier-uniform weights, gain √2 before a ReLU and 1 on the linear output; zero biases.
    pub fn init(&self, seed: u64, device: &Device) -> Column {
        assert!(self.depth >= 1 && self.in_channels >= 3, "KPCN needs ≥ 1 layer and a colour input");
        assert!(self.filter_size % 2 == 1, "filter size must be odd");
        Column::kpcn(
            ConvStack::new(
                &self.widths(),
                self.conv_kernel,
                Padding::Valid,
                Init::XavierUniform { gain: std::f64::consts::SQRT_2 },
                Init::XavierUniform { gain: 1.0 },
                false,
                Activation::Relu,
                seed,
                0x4b50_434e,
                device,
            ),
            self.margin(),
        )
    }
}

/// Largest log-specular value fed to exp: e^80 ≈ 5.5e34 stays inside f32 even after adding the
/// diffuse part, so recombination never produces Inf. Real values are < 20 (ln(1 + 5e8)).
pub const MAX_LOG_SPECULAR: f32 = 80.0;

/// Final radiance from the two branches (method.md §3): D̂ ⊙ (A + ε_a) + exp(P̂) − 1. `albedo`
/// may be larger than the branch outputs; it is centre-cropped to them.
pub fn recombine(diffuse: Tensor<4>, log_specular: Tensor<4>, albedo: Tensor<4>) -> Tensor<4> {
    let [_, _, h, w] = diffuse.dims();
    let a = center_crop(sanitize(albedo, INPUT_LIMIT), h, w);
    diffuse * a.add_scalar(ALBEDO_EPS) + log_specular.clamp_max(MAX_LOG_SPECULAR).exp().sub_scalar(1.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cpu_device;
    use crate::test_util::to_vec;

    #[test]
    fn channel_counts_match_the_method() {
        assert_eq!(Variant::G.in_channels(), 34);
        assert_eq!(Variant::P.in_channels(), 23);
        assert_eq!(Variant::GP.in_channels(), 48);
    }

    #[test]
    fn paper_cost_is_the_hand_count() {
        let c = KpcnConfig::new(34);
        let expect = 34 * 100 * 25 + 7 * 100 * 100 * 25 + 100 * 441 * 25 + 441 * 3;
        assert_eq!(c.macs_per_pixel(), expect as u64);
        assert_eq!(c.margin(), 18);
    }

    #[test]
    fn output_shape_and_recombination() {
        let d = cpu_device();
        let cfg = KpcnConfig::new(Variant::G.in_channels()).with_depth(3).with_width(8).with_conv_kernel(3).with_filter_size(5);
        let x = Tensor::<4>::ones([2, 34, 12, 10], &d);
        let albedo = Tensor::<4>::ones([2, 3, 12, 10], &d).mul_scalar(0.5);
        let dh = cfg.init(6, &d).forward(x.clone(), 4);
        let ph = cfg.init(7, &d).forward(x, 4);
        let out = recombine(dh.clone(), ph.clone(), albedo);
        assert_eq!(dh.dims(), [2, 3, 6, 4]);
        // The kernel is a convex combination and here every tap inside the buffer reads 1 and
        // the receptive field is fully inside, so D̂ = P̂ = 1 and out = 1·(0.5+ε) + e − 1.
        let expect = 0.5 + ALBEDO_EPS as f64 + std::f64::consts::E - 1.0;
        for v in to_vec(out) {
            assert!((v - expect).abs() < 1e-5, "{v} vs {expect}");
        }
        assert!(to_vec(ph).iter().all(|v| (v - 1.0).abs() < 1e-5));
    }
}
