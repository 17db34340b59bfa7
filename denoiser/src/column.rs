//! A denoising column (D_G, D_P or the both-buffers column of docs/method.md §5): the paper's KPCN
//! or the multi-scale kernel-predicting U-Net ([`crate::mskp`]). Both filter the colour (input
//! channels 0..3) with predicted softmax kernels and return it `margin` pixels smaller per side,
//! so the methods, training and inference treat them alike.
//!
//! The two backbones are optional fields of one struct rather than an enum so that a KPCN's
//! tensors keep the names of the weight files written before the U-Net existed
//! (`diffuse.d_g.net.layers.0.weight`); exactly one is present.

use burn::module::Module;
use burn::tensor::Tensor;

use crate::kernel::apply_kernel;
use crate::layers::{sanitize, ConvStack, INPUT_LIMIT};
use crate::mskp::MsKpNet;

#[derive(Module, Debug)]
pub struct Column {
    /// KPCN: valid convolutions ending in the k² kernel logits.
    pub net: Option<ConvStack>,
    /// Multi-scale kernel-predicting U-Net.
    pub unet: Option<MsKpNet>,
    /// Pixels lost per side between input and output.
    pub margin: usize,
}

impl Column {
    pub fn kpcn(net: ConvStack, margin: usize) -> Self {
        Column { net: Some(net), unet: None, margin }
    }

    pub fn mskp(unet: MsKpNet) -> Self {
        let margin = unet.margin;
        Column { net: None, unet: Some(unet), margin }
    }

    /// `[B, C_in, H, W]` → `[B, 3, H−2m, W−2m]`: the colour filtered by the predicted kernels.
    /// Inputs are sanitised first (NaN → 0, clamped to ±[`INPUT_LIMIT`]). `spp`: the input's
    /// samples per pixel (noise-normalised guides weigh their test by it).
    pub fn forward(&self, input: Tensor<4>, spp: usize) -> Tensor<4> {
        let [_, _, h, w] = input.dims();
        assert!(h > 2 * self.margin && w > 2 * self.margin, "column input {h}×{w} smaller than its {} px margin", self.margin);
        let input = sanitize(input, INPUT_LIMIT);
        match (&self.net, &self.unet) {
            (Some(net), None) => {
                let logits = net.forward(input.clone());
                apply_kernel(input.narrow(1, 0, 3), logits)
            }
            (None, Some(unet)) => unet.forward(input, spp),
            _ => panic!("a column holds exactly one backbone"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cpu_device;
    use crate::kpcn::{KpcnConfig, Variant};
    use crate::mskp::MsKpConfig;
    use crate::test_util::{tensor, to_vec};

    fn tiny_columns(in_channels: usize) -> Vec<(&'static str, Column)> {
        let d = cpu_device();
        vec![
            ("kpcn", KpcnConfig::new(in_channels).with_depth(3).with_width(8).with_conv_kernel(3).with_filter_size(5).init(9, &d)),
            (
                "mskp",
                Column::mskp(
                    MsKpConfig::new(in_channels)
                        .with_widths(vec![6, 8, 8])
                        .with_kernel_scales(2)
                        .with_filter_size(3)
                        .with_margin(2)
                        .init(9, &d),
                ),
            ),
        ]
    }

    /// NaN, ±Inf, 1e6 and all-zero inputs give finite outputs of the documented size, for both
    /// backbones.
    #[test]
    fn hostile_inputs_give_finite_outputs() {
        let d = cpu_device();
        let c = Variant::P.in_channels();
        let n = c * 16 * 16;
        let specials = [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, 1e6, -1e6, 0.0];
        for (name, col) in tiny_columns(c) {
            for fill in [None, Some(0.0), Some(1e6), Some(f64::NAN)] {
                let v: Vec<f64> = (0..n).map(|i| fill.unwrap_or(specials[i % specials.len()])).collect();
                let out = col.forward(tensor(&v, [1, c, 16, 16], &d), 4);
                let o = 16 - 2 * col.margin;
                assert_eq!(out.dims(), [1, 3, o, o], "{name}");
                assert!(to_vec(out).iter().all(|v| v.is_finite()), "{name}: non-finite output for fill {fill:?}");
            }
        }
    }

    /// A constant colour comes back unchanged whatever the kernels: every level is a convex
    /// combination of input colours, and no tap reads past the edge as zero.
    #[test]
    fn constant_colour_is_preserved() {
        let d = cpu_device();
        let c = Variant::G.in_channels();
        let mut v: Vec<f64> = (0..c * 20 * 20).map(|i| ((i * 7919) % 101) as f64 / 50.0 - 1.0).collect();
        v[..3 * 400].iter_mut().for_each(|x| *x = 0.625);
        for (name, col) in tiny_columns(c) {
            let out = to_vec(col.forward(tensor(&v, [1, c, 20, 20], &d), 4));
            for x in out {
                assert!((x - 0.625).abs() < 1e-5, "{name}: {x}");
            }
        }
    }
}
