//! The inference engine: the shipped networks' forward passes without burn, on the host, with
//! direct convolution kernels picked at run time for the CPU (AVX-512, AVX2 or portable code).
//! It reads the weights from the burn modules that `weights::load` built, so it serves exactly
//! the files burn trains and loads; burn stays the training path and the reference the engine is
//! tested against (docs/inference-engine.md).
//!
//! Today it runs the multi-scale U-Net columns' convolutions ([`UnetEngine`]: every 3×3 layer,
//! pooling, upsampling, skip concatenation and the 1×1 heads); the composite that applies the
//! predicted kernels still runs in burn. The building blocks (a layer list of 3×3 convolutions
//! with fused ReLU and concatenation, pooling, upsampling) are those of any small plain conv net,
//! so E can be served by the same pieces.

use std::sync::Arc;

use burn::tensor::{Device, Tensor, TensorData};

use crate::layers::Conv;
use crate::method::MethodModel;
use crate::mskp::MsKpNet;

mod conv;
mod planes;
pub mod profile;

pub use conv::{conv, ConvWeights};
pub use planes::Planes;

/// An instruction set the kernels are compiled for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Isa {
    /// Portable Rust (any CPU).
    Scalar,
    /// AVX2 with FMA: 8 lanes.
    Avx2,
    /// AVX-512F: 16 lanes, two vectors per run of pixels.
    Avx512,
}

impl Isa {
    /// The widest set this CPU has.
    pub fn detect() -> Isa {
        *Isa::available().last().unwrap_or(&Isa::Scalar)
    }

    /// Every set this CPU can run, narrowest first (the tests run each).
    pub fn available() -> Vec<Isa> {
        let mut v = vec![Isa::Scalar];
        #[cfg(target_arch = "x86_64")]
        {
            if is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma") {
                v.push(Isa::Avx2);
                if is_x86_feature_detected!("avx512f") {
                    v.push(Isa::Avx512);
                }
            }
        }
        v
    }

    /// Output pixels per kernel call.
    fn run(self) -> usize {
        match self {
            Isa::Scalar => 8,
            Isa::Avx2 => 8,
            Isa::Avx512 => 32,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Isa::Scalar => "scalar",
            Isa::Avx2 => "avx2",
            Isa::Avx512 => "avx512",
        }
    }
}

fn conv_weights(c: &Conv) -> ConvWeights {
    let w = c.effective_weight();
    let [cout, cin, k, _] = w.dims();
    let w: Vec<f32> = w.into_data().convert::<f32>().try_to_vec::<f32>().expect("f32 weights");
    let b: Vec<f32> = c.bias.val().into_data().convert::<f32>().try_to_vec::<f32>().expect("f32 biases");
    assert_eq!(c.padding, k / 2, "the engine runs same-padded convolutions");
    ConvWeights::new(&w, &b, cout, cin, k)
}

/// The U-Net of a multi-scale column ([`MsKpNet`]) up to its heads: each level's two 3×3
/// convolutions with ReLU, 2×2 max-pooling down, bilinear upsampling up with the skip
/// concatenated (fused into the first convolution of the level), and the 1×1 head per kernel
/// scale.
#[derive(Clone, Debug)]
pub struct UnetEngine {
    pub isa: Isa,
    down: Vec<Vec<ConvWeights>>,
    up: Vec<Vec<ConvWeights>>,
    heads: Vec<ConvWeights>,
}

impl UnetEngine {
    /// Packs the network's weights for `isa`.
    pub fn new(net: &MsKpNet, isa: Isa) -> Self {
        let stack = |s: &crate::layers::ConvStack| s.layers.iter().map(conv_weights).collect();
        UnetEngine {
            isa,
            down: net.down.iter().map(stack).collect(),
            up: net.up.iter().map(stack).collect(),
            heads: net.heads.iter().map(conv_weights).collect(),
        }
    }

    /// Channels of the input.
    pub fn in_channels(&self) -> usize {
        self.down[0][0].cin
    }

    fn chain(&self, first: &[&Planes], layers: &[ConvWeights]) -> Planes {
        let mut x = conv(self.isa, first, &layers[0], true);
        for l in &layers[1..] {
            x = conv(self.isa, &[&x], l, true);
        }
        x
    }

    /// The head outputs at every kernel scale, finest first, as [`MsKpNet::heads`] computes them
    /// before splitting (kernel logits, blend logit, guide strengths).
    pub fn heads(&self, input: &Planes) -> Vec<Planes> {
        let levels = self.down.len();
        let scales = self.heads.len();
        let mut skips: Vec<Planes> = Vec::with_capacity(levels);
        for (l, block) in self.down.iter().enumerate() {
            let x = if l == 0 { self.chain(&[input], block) } else { self.chain(&[&skips[l - 1].max_pool()], block) };
            skips.push(x);
        }
        let mut x = skips.pop().expect("one level at least");
        let mut feats: Vec<Option<Planes>> = vec![None; scales];
        if levels - 1 < scales {
            feats[levels - 1] = Some(x.clone());
        }
        for l in (0..self.up.len()).rev() {
            let skip = skips.pop().expect("one skip per level");
            let up = x.upsample_to(skip.h, skip.w);
            x = self.chain(&[&up, &skip], &self.up[l]);
            if l < scales {
                feats[l] = Some(x.clone());
            }
        }
        feats.into_iter().zip(&self.heads).map(|(f, h)| conv(self.isa, &[&f.expect("a decoder level per scale")], h, false)).collect()
    }

    /// Multiply-accumulates of [`Self::heads`] on an `h × w` input (pooling floors odd sizes).
    pub fn macs(&self, h: usize, w: usize) -> u64 {
        let px = |l: usize| ((h >> l) * (w >> l)) as u64;
        let mut total = 0;
        for (l, block) in self.down.iter().enumerate() {
            total += px(l) * block.iter().map(ConvWeights::macs_per_pixel).sum::<u64>();
        }
        for (l, block) in self.up.iter().enumerate() {
            total += px(l) * block.iter().map(ConvWeights::macs_per_pixel).sum::<u64>();
        }
        for (s, head) in self.heads.iter().enumerate() {
            total += px(s) * head.macs_per_pixel();
        }
        total
    }

    /// [`Self::heads`] on a `[B, C, H, W]` tensor, as `[B, C_s, H_s, W_s]` tensors.
    pub fn head_tensors(&self, x: Tensor<4>, device: &Device) -> Vec<Tensor<4>> {
        let [b, c, h, w] = x.dims();
        let v: Vec<f32> = x.into_data().convert::<f32>().try_to_vec::<f32>().expect("f32 input");
        let per_item: Vec<Vec<Planes>> =
            (0..b).map(|i| self.heads(&Planes::from_planar(&v[i * c * h * w..(i + 1) * c * h * w], c, h, w))).collect();
        (0..self.heads.len())
            .map(|s| {
                let (cs, hs, ws) = (per_item[0][s].c, per_item[0][s].h, per_item[0][s].w);
                let data: Vec<f32> = per_item.iter().flat_map(|p| p[s].to_planar(0, cs)).collect();
                Tensor::from_data(TensorData::new(data, [b, cs, hs, ws]), device)
            })
            .collect()
    }
}

/// Shared by the clones of a model (burn modules are cloned freely).
pub type SharedUnet = Arc<UnetEngine>;

/// Makes every U-Net column of `model` (D_G, D_P, the both-buffers column) run its
/// convolutions on the engine with `isa` (`Some`), or on burn again (`None`). The weights are
/// packed here, once; training never calls this, so burn's modules stay what it updates.
pub fn use_engine(model: &mut MethodModel, isa: Option<Isa>) {
    for b in [&mut model.diffuse, &mut model.specular] {
        for c in [&mut b.d_g, &mut b.d_p, &mut b.d_gp].into_iter().flatten() {
            if let Some(u) = &mut c.unet {
                u.engine = isa.map(|isa| Arc::new(UnetEngine::new(u, isa)));
            }
        }
    }
}

#[cfg(test)]
mod tests;
