//! E as a small U-Net: two 3×3 convolutions per level, 2×2 max-pooling down, bilinear upsampling
//! and skip concatenation up, and a 1×1 head giving one logit per expert. The coarse levels let it
//! compare an expert with the noisy input over a neighbourhood (one pixel's noise says little at
//! 2 spp) for a few tens of thousands of multiply-accumulates per pixel.

use burn::config::Config;
use burn::module::{Module, Param};
use burn::tensor::activation::{relu, softmax};
use burn::tensor::module::{interpolate, max_pool2d};
use burn::tensor::ops::{InterpolateMode, InterpolateOptions, MaxPoolOptions};
use burn::tensor::{Device, Tensor};

use crate::layers::{conv_macs, Conv, ConvSpec, Init, Padding};

#[derive(Config, Debug)]
pub struct GateConfig {
    /// Input feature channels ([`super::feature_channels`]).
    pub in_channels: usize,
    /// Experts, i.e. output logits.
    pub experts: usize,
    /// Widths per level, full resolution first (one pooling between levels).
    #[config(default = "vec![16, 32, 32]")]
    pub widths: Vec<usize>,
}

/// Two 3×3 convolutions with ReLU.
#[derive(Module, Debug)]
pub struct Block {
    pub a: Conv,
    pub b: Conv,
}

impl Block {
    fn new(cin: usize, cout: usize, seed: u64, tag: u64, device: &Device) -> Block {
        let spec = |i, o| ConvSpec {
            in_channels: i,
            out_channels: o,
            kernel: 3,
            padding: Padding::Same,
            init: Init::XavierUniform { gain: std::f64::consts::SQRT_2 },
            weight_norm: false,
        };
        Block { a: Conv::new(spec(cin, cout), seed, tag, device), b: Conv::new(spec(cout, cout), seed, tag + 1, device) }
    }

    fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        relu(self.b.forward(relu(self.a.forward(x))))
    }
}

#[derive(Module, Debug)]
pub struct GateNet {
    /// Encoder blocks, full resolution first.
    pub down: Vec<Block>,
    /// Decoder convolutions, coarsest first: level l+1 upsampled and concatenated with level l.
    pub up: Vec<Conv>,
    /// 1×1 convolution to one logit per expert; starts at zero (uniform weights).
    pub head: Conv,
}

impl GateConfig {
    /// Image sides must be multiples of this (inference pads to it).
    pub fn alignment(&self) -> usize {
        1 << (self.widths.len() - 1)
    }

    pub fn init(&self, seed: u64, device: &Device) -> GateNet {
        assert!(!self.widths.is_empty() && self.experts >= 1);
        let w = &self.widths;
        let mut down = Vec::new();
        let mut cin = self.in_channels;
        for (l, &wl) in w.iter().enumerate() {
            down.push(Block::new(cin, wl, seed, 10 + 2 * l as u64, device));
            cin = wl;
        }
        let mut up = Vec::new();
        for l in (0..w.len() - 1).rev() {
            let from = w[l + 1];
            let spec = ConvSpec {
                in_channels: from + w[l],
                out_channels: w[l],
                kernel: 3,
                padding: Padding::Same,
                init: Init::XavierUniform { gain: std::f64::consts::SQRT_2 },
                weight_norm: false,
            };
            up.push(Conv::new(spec, seed, 100 + l as u64, device));
        }
        let mut head = Conv::new(
            ConvSpec {
                in_channels: w[0],
                out_channels: self.experts,
                kernel: 1,
                padding: Padding::Same,
                init: Init::XavierUniform { gain: 1.0 },
                weight_norm: false,
            },
            seed,
            200,
            device,
        );
        head.weight = Param::from_tensor(head.weight.val().zeros_like());
        GateNet { down, up, head }
    }

    /// Multiply-accumulates per pixel (coarse levels counted at their share of the pixels).
    pub fn macs_per_pixel(&self) -> f64 {
        let w = &self.widths;
        let mut total = 0.0;
        let mut cin = self.in_channels;
        for (l, &wl) in w.iter().enumerate() {
            let share = 1.0 / (1u64 << (2 * l)) as f64;
            total += share * (conv_macs(cin, wl, 3) + conv_macs(wl, wl, 3)) as f64;
            cin = wl;
        }
        for l in 0..w.len() - 1 {
            let share = 1.0 / (1u64 << (2 * l)) as f64;
            total += share * conv_macs(w[l + 1] + w[l], w[l], 3) as f64;
        }
        total + conv_macs(w[0], self.experts, 1) as f64
    }
}

impl GateNet {
    /// Logits `[B, K, H, W]` from features `[B, C, H, W]`; H and W multiples of the alignment.
    pub fn logits(&self, x: Tensor<4>) -> Tensor<4> {
        let mut skips = Vec::new();
        let mut x = x;
        for (l, block) in self.down.iter().enumerate() {
            if l > 0 {
                x = max_pool2d(x, MaxPoolOptions::new([2, 2]).with_stride([2, 2]));
            }
            x = block.forward(x);
            skips.push(x.clone());
        }
        skips.pop();
        for conv in &self.up {
            let skip = skips.pop().expect("one skip per decoder level");
            let [_, _, h, w] = skip.dims();
            let up = interpolate(x, InterpolateOptions::new(InterpolateMode::Bilinear).with_align_corners(false).with_output_size([h, w]));
            x = relu(conv.forward(Tensor::cat(vec![up, skip], 1)));
        }
        self.head.forward(x)
    }

    /// Softmax weights `[B, K, H, W]`.
    pub fn weights(&self, x: Tensor<4>) -> Tensor<4> {
        softmax(self.logits(x), 1)
    }
}
