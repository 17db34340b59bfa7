//! The per-sample stages of the path-manifold module (embedding, output head, pooling) as one
//! fused loop on the host, for inference.
//!
//! These stages are 1×1 convolutions of 24–40 channels applied to every sample of every pixel:
//! as tensor ops each layer writes its whole `[S·pixels, C]` activation to memory and reads it
//! back, which made the path-manifold module 75–85 % of D_P's time at 8–64 spp
//! (docs/results.md, runtime breakdown). Here each sample goes through all its layers in a few
//! hundred floats of stack, pixels run in parallel, and the head's U-Net context term, the same
//! for every sample of a pixel, is computed once per pixel instead of once per sample. Same
//! arithmetic as [`PathNet::embed`] and [`PathNet::head_pool`] up to f32 rounding (tested); each
//! pixel's result depends on nothing but its own samples, so the thread count does not change it.

use rayon::prelude::*;

use crate::layers::{sanitize_value, Conv, ConvStack, INPUT_LIMIT};
use crate::pathnet::PathNet;
use crate::preprocess::{PreparedImage, DESCRIPTOR_CHANNELS};

/// Pixels per parallel work item: enough to amortise the gather, small enough to balance.
const PIXELS_PER_TASK: usize = 1024;

/// A 1×1 convolution as a dense layer; the weights are stored input-major (`[in][out]`) so the
/// inner loop runs over contiguous outputs and vectorises without reassociating any sum.
struct Dense {
    weight_t: Vec<f32>,
    bias: Vec<f32>,
    outputs: usize,
}

impl Dense {
    fn from_conv(c: &Conv) -> Dense {
        let w = c.effective_weight();
        let [o, i, kh, kw] = w.dims();
        assert!(kh == 1 && kw == 1, "the per-sample stages are 1×1 convolutions");
        let v = host(w.into_data());
        let mut weight_t = vec![0.0; o * i];
        for (oo, row) in v.chunks_exact(i).enumerate() {
            for (ii, &x) in row.iter().enumerate() {
                weight_t[ii * o + oo] = x;
            }
        }
        Dense { weight_t, bias: host(c.bias.val().into_data()), outputs: o }
    }

    /// The first `rows` inputs' weights as a layer of their own, with the bias, and the rest as
    /// a bias-free layer: `W·[a, b] + β = (W_a·a + β) + W_b·b`.
    fn split_inputs(self, rows: usize) -> (Dense, Dense) {
        let o = self.outputs;
        let (a, b) = self.weight_t.split_at(rows * o);
        (Dense { weight_t: a.to_vec(), bias: self.bias, outputs: o }, Dense { weight_t: b.to_vec(), bias: vec![0.0; o], outputs: o })
    }

    /// `y = W·x + b + y0`, `y0` the start value (the bias alone when `None`).
    #[inline]
    fn apply(&self, x: &[f32], y0: Option<&[f32]>, y: &mut [f32]) {
        y.copy_from_slice(y0.unwrap_or(&self.bias));
        if y0.is_some() {
            y.iter_mut().zip(&self.bias).for_each(|(a, b)| *a += b);
        }
        for (xi, row) in x.iter().zip(self.weight_t.chunks_exact(self.outputs)) {
            for (yo, w) in y.iter_mut().zip(row) {
                *yo += w * xi;
            }
        }
    }
}

fn host(d: burn::tensor::TensorData) -> Vec<f32> {
    d.convert::<f32>().try_into_vec::<f32>().expect("f32 tensor data")
}

fn relu(v: &mut [f32]) {
    v.iter_mut().for_each(|x| *x = x.max(0.0));
}

/// A [`ConvStack`]'s 1×1 layers as dense layers (the callers apply its ReLUs between them).
fn stack(s: &ConvStack) -> Vec<Dense> {
    s.layers.iter().map(Dense::from_conv).collect()
}

/// Runs `layers` on the `width` values in `a` (the previous layer's output), each after a ReLU;
/// returns the last output, in `a` or `b`.
fn run_rest<'a>(layers: &[Dense], mut a: &'a mut [f32], mut b: &'a mut [f32], width: usize) -> &'a mut [f32] {
    let mut w = width;
    for l in layers {
        relu(&mut a[..w]);
        l.apply(&a[..w], None, &mut b[..l.outputs]);
        w = l.outputs;
        std::mem::swap(&mut a, &mut b);
    }
    &mut a[..w]
}

/// The host copy of one branch's per-sample stages.
pub struct PathMlp {
    embed: Vec<Dense>,
    /// The head's first layer on the embedding (with the bias) and on the U-Net context.
    head_e: Dense,
    head_g: Dense,
    head_rest: Vec<Dense>,
    width: usize,
}

impl PathMlp {
    pub fn new(net: &PathNet) -> PathMlp {
        let embed = stack(&net.embed);
        let e = embed.last().expect("an embedding layer").outputs;
        let mut head = stack(&net.head);
        let first = head.remove(0);
        let (head_e, head_g) = first.split_inputs(e);
        let width = embed.iter().chain(&head).chain([&head_e]).map(|d| d.outputs).max().unwrap();
        PathMlp { embed, head_e, head_g, head_rest: head, width }
    }

    /// Embedding width E.
    pub fn embed_width(&self) -> usize {
        self.embed.last().unwrap().outputs
    }

    /// P-buffer channels per sample.
    fn out_channels(&self) -> usize {
        self.head_rest.last().unwrap_or(&self.head_e).outputs
    }

    /// One sample's embedding into `out` (E floats) from its sanitised descriptor `x`.
    fn embed_one(&self, x: &[f32], a: &mut [f32], b: &mut [f32], out: &mut [f32]) {
        let first = &self.embed[0];
        first.apply(x, None, &mut a[..first.outputs]);
        let e = run_rest(&self.embed[1..], a, b, first.outputs);
        out.copy_from_slice(e);
    }

    /// Runs `f(k, descriptors [S][36] of pixels[k] sanitised, output)` for every position k of
    /// `pixels` in parallel, each writing `per_pixel` floats; returns them in the order of `pixels`.
    fn per_pixel(
        &self,
        image: &PreparedImage,
        pixels: &[usize],
        per_pixel: usize,
        f: impl Fn(usize, &[f32], &mut [f32]) + Sync,
    ) -> Vec<f32> {
        let s = image.spp.max(1);
        let parts: Vec<Vec<f32>> = pixels
            .par_chunks(PIXELS_PER_TASK)
            .enumerate()
            .map(|(t, idx)| {
                let len = idx.len();
                let cols = image.descriptor_columns(idx).unwrap_or_else(|| vec![0.0; s * DESCRIPTOR_CHANNELS * len]);
                let mut out = vec![0.0; per_pixel * len];
                let mut desc = vec![0.0; s * DESCRIPTOR_CHANNELS];
                for i in 0..len {
                    for (k, d) in desc.iter_mut().enumerate() {
                        *d = sanitize_value(cols[k * len + i], INPUT_LIMIT);
                    }
                    f(t * PIXELS_PER_TASK + i, &desc, &mut out[i * per_pixel..(i + 1) * per_pixel]);
                }
                out
            })
            .collect();
        parts.concat()
    }

    /// Mean embedding over each listed pixel's samples, pixel-major `[len][E]`.
    pub fn mean_embedding(&self, image: &PreparedImage, pixels: &[usize]) -> Vec<f32> {
        let e = self.embed_width();
        let s = image.spp.max(1);
        self.per_pixel(image, pixels, e, |_, desc, out| {
            let (mut a, mut b, mut one) = (vec![0.0; self.width], vec![0.0; self.width], vec![0.0; e]);
            for x in desc.chunks_exact(DESCRIPTOR_CHANNELS) {
                self.embed_one(x, &mut a, &mut b, &mut one);
                out.iter_mut().zip(&one).for_each(|(o, v)| *o += v);
            }
            out.iter_mut().for_each(|o| *o /= s as f32);
        })
    }

    /// [f_P, v_P] (`C + 1` floats, pixel-major) of each listed pixel given its U-Net context
    /// `context(k)` (G floats) for the k-th listed pixel: the head on every sample, ReLU, the
    /// mean over samples and the mean over channels of the unbiased variance divided by S.
    pub fn pixel_buffer(&self, image: &PreparedImage, pixels: &[usize], context: impl Fn(usize, &mut [f32]) + Sync) -> Vec<f32> {
        let (e, c, s) = (self.embed_width(), self.out_channels(), image.spp.max(1));
        let g_width = self.head_g.weight_t.len() / self.head_g.outputs;
        self.per_pixel(image, pixels, c + 1, |k, desc, out| {
            let (mut a, mut b, mut emb) = (vec![0.0; self.width], vec![0.0; self.width], vec![0.0; e]);
            let mut g = vec![0.0; g_width];
            context(k, &mut g);
            // The context's share of the head's first layer, once per pixel.
            let mut from_g = vec![0.0; self.head_g.outputs];
            self.head_g.apply(&g, None, &mut from_g);
            let mut samples = vec![0.0; s * c];
            for (x, p) in desc.chunks_exact(DESCRIPTOR_CHANNELS).zip(samples.chunks_exact_mut(c)) {
                self.embed_one(x, &mut a, &mut b, &mut emb);
                self.head_e.apply(&emb, Some(&from_g), &mut a[..self.head_e.outputs]);
                let y = run_rest(&self.head_rest, &mut a, &mut b, self.head_e.outputs);
                relu(y);
                p.copy_from_slice(y);
            }
            let (mean, var) = out.split_at_mut(c);
            for p in samples.chunks_exact(c) {
                mean.iter_mut().zip(p).for_each(|(m, v)| *m += v);
            }
            mean.iter_mut().for_each(|m| *m /= s as f32);
            var[0] = if s > 1 {
                let mut acc = 0.0;
                for (ch, m) in mean.iter().enumerate() {
                    acc += samples.chunks_exact(c).map(|p| (p[ch] - m) * (p[ch] - m)).sum::<f32>() / (s - 1) as f32;
                }
                acc / c as f32 / s as f32
            } else {
                0.0
            };
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pathnet::PathNetConfig;
    use crate::rng::SplitMix64;
    use crate::test_util::{tensor, to_vec};

    /// The fused host stages against the tensor stages of [`PathNet`], on descriptors that
    /// include NaN and huge values (sanitised alike). Tolerance 1e-4 relative + 1e-5: only the
    /// order of the f32 additions differs (~1e-6 per layer).
    #[test]
    fn fused_stages_equal_the_tensor_stages() {
        let d = crate::cpu_device();
        for (cfg, spp) in [
            (PathNetConfig::new().with_embed_width(8).with_unet_widths(vec![8, 12]).with_out_hidden(10), 5),
            (crate::model::DenoiserConfig::cpu_default().pathnet, 1),
        ] {
            let net = cfg.init(7, &d);
            let (w, h) = (11, 9);
            let n = w * h;
            let mut rng = SplitMix64::new(3);
            let mut desc: Vec<f32> = (0..spp * DESCRIPTOR_CHANNELS * n).map(|_| rng.symmetric(2.0)).collect();
            desc[5] = f32::NAN;
            desc[17] = 1e9;
            let image = PreparedImage {
                width: w,
                height: h,
                spp,
                diffuse: Vec::new(),
                specular: Vec::new(),
                g_block: Vec::new(),
                path_weight: Vec::new(),
                descriptors: Some(desc.clone()),
                records: None,
                passthrough: Vec::new(),
            };
            let mlp = PathMlp::new(&net);
            let pixels: Vec<usize> = (0..n).rev().collect();

            let e = net.embed(tensor(&desc.iter().map(|&v| v as f64).collect::<Vec<_>>(), [1, spp, DESCRIPTOR_CHANNELS, h, w], &d));
            let want_mean = to_vec(PathNet::pixel_mean(&e)); // [E, n]
            let got_mean = mlp.mean_embedding(&image, &pixels); // [n][E], pixels reversed
            let ew = mlp.embed_width();
            let close =
                |got: f32, want: f64, what: &str| assert!((got as f64 - want).abs() <= 1e-5 + 1e-4 * want.abs(), "{what}: {got} vs {want}");
            for (k, &p) in pixels.iter().enumerate() {
                for c in 0..ew {
                    close(got_mean[k * ew + c], want_mean[c * n + p], "mean embedding");
                }
            }

            let g = net.unet(PathNet::pixel_mean(&e));
            let g_host = to_vec(g.clone());
            let want = to_vec(net.head_pool(e, g).pixel_buffer()); // [C+1, n]
            let got = mlp.pixel_buffer(&image, &pixels, |k, out: &mut [f32]| {
                for (c, o) in out.iter_mut().enumerate() {
                    *o = g_host[c * n + pixels[k]] as f32;
                }
            });
            let oc = want.len() / n;
            assert_eq!(got.len(), oc * n);
            for (k, &p) in pixels.iter().enumerate() {
                for c in 0..oc {
                    close(got[k * oc + c], want[c * n + p], "P-buffer");
                }
            }
        }
    }
}
