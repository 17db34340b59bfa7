//! Network inputs from a rendered frame (method.md §2 and §4.1), and training targets from a
//! reference frame. The same code serves the in-process render-and-denoise path and the dataset
//! files (which `film::exr_io::read_frame` turns back into the same [`Frame`]).
//!
//! Everything is kept on the CPU as planar `[C, H, W]` arrays so that training can cut patches
//! and inference can cut tiles before anything becomes a tensor: a 1024² frame at 8 spp has
//! 1.2 GB of descriptors, which must never be one tensor.

use burn::tensor::{Device, Tensor, TensorData};
use film::descriptors::{field, Descriptors, FIELDS};
use film::{Frame, PixelBuffer};

use crate::kpcn::channels::{COLOUR_BLOCK, G_BLOCK};
use crate::model::BranchInput;
use crate::ALBEDO_EPS;

/// Path-descriptor channels the path-manifold module sees (fields 0–35; method.md §4.1).
pub const DESCRIPTOR_CHANNELS: usize = 36;

#[derive(Debug, thiserror::Error)]
pub enum PrepareError {
    #[error("the frame has no {0} buffer: render it with the split and G-buffers (--aovs)")]
    MissingBuffer(&'static str),
    #[error("the frame has no per-sample path descriptors, which P-buffer models need")]
    MissingDescriptors,
    #[error("descriptors are {dw}×{dh} at {ds} spp but the frame is {fw}×{fh} at {fs} spp")]
    DescriptorShape { dw: u32, dh: u32, ds: u32, fw: u32, fh: u32, fs: u32 },
    #[error("crop {x},{y} {w}×{h} is outside the {width}×{height} image")]
    Crop { x: usize, y: usize, w: usize, h: usize, width: usize, height: usize },
    #[error("reference is {rw}×{rh} but the input is {w}×{h}")]
    Size { rw: usize, rh: usize, w: usize, h: usize },
}

/// The preprocessed inputs of one image (or one crop of it). All planar `[C, H, W]`, row-major.
#[derive(Clone, Debug, PartialEq)]
pub struct PreparedImage {
    pub width: usize,
    pub height: usize,
    /// Samples per pixel of the noisy render (also the sample count of `descriptors`).
    pub spp: usize,
    /// Diffuse colour block: D, σ²_D, ∂D (10 channels).
    pub diffuse: Vec<f32>,
    /// Specular colour block: P, σ²_P, ∂P (10 channels).
    pub specular: Vec<f32>,
    /// G-buffer block: N, σ²_N, ∂N, Z, σ²_Z, ∂Z, A, σ²_A, ∂A (24 channels).
    pub g_block: Vec<f32>,
    /// Per-pixel mean of the normalised path weight (1 channel; the G+P baseline's extra input).
    pub path_weight: Vec<f32>,
    /// Normalised per-sample descriptors `[S, 36, H, W]`, if the frame had them ([`prepare`]).
    pub descriptors: Option<Vec<f32>>,
    /// Instead of `descriptors` ([`prepare_for_inference`]): the renderer's own per-sample
    /// records, normalised in place, so inference never holds a second, planar copy of the
    /// largest buffer (1.2 GB per copy at 1024², 8 spp) and only gathers from them.
    pub records: Option<NormalisedRecords>,
    /// Pixels whose camera ray hit nothing or an emitter in every sample (method.md §7.3: the
    /// evaluation keeps the noisy value there). Empty if the frame had no descriptors.
    pub passthrough: Vec<bool>,
}

/// Training targets in the branch domains (method.md §2), planar `[3, H, W]`.
#[derive(Clone, Debug, PartialEq)]
pub struct PreparedTarget {
    pub width: usize,
    pub height: usize,
    /// ref_diffuse / (ref_albedo + ε_a).
    pub diffuse: Vec<f32>,
    /// ln(1 + max(ref_total − ref_diffuse, 0)).
    pub specular: Vec<f32>,
    /// Linear total radiance.
    pub total: Vec<f32>,
}

/// Tensors of a batch of crops, ready for [`crate::method::MethodModel::forward`].
#[derive(Clone, Debug)]
pub struct InputTensors {
    pub diffuse: BranchInput,
    pub specular: BranchInput,
    /// `[B, 1, H, W]`.
    pub path_weight: Tensor<4>,
}

/// Targets of a batch of crops, each `[B, 3, H, W]`.
#[derive(Clone, Debug)]
pub struct TargetTensors {
    pub diffuse: Tensor<4>,
    pub specular: Tensor<4>,
    pub total: Tensor<4>,
}

pub(crate) fn finite(x: f32) -> f32 {
    if x.is_finite() {
        x
    } else {
        0.0
    }
}

fn need<'a>(b: &'a Option<PixelBuffer>, name: &'static str) -> Result<&'a PixelBuffer, PrepareError> {
    b.as_ref().ok_or(PrepareError::MissingBuffer(name))
}

/// Appends `channels` planes of a per-pixel quantity.
fn push_planes(out: &mut Vec<f32>, n: usize, channels: usize, f: impl Fn(usize, usize) -> f32) {
    for c in 0..channels {
        out.extend((0..n).map(|i| finite(f(i, c))));
    }
}

/// Appends the forward-difference gradients of `planes` planes starting at `start` in `buf`:
/// all x planes, then all y planes; zero in the first column / row (method.md §2 step 7).
fn push_gradients(buf: &mut Vec<f32>, start: usize, planes: usize, w: usize, h: usize) {
    let n = w * h;
    for axis in 0..2 {
        for p in 0..planes {
            let base = start + p * n;
            for y in 0..h {
                for x in 0..w {
                    let i = y * w + x;
                    let g = match axis {
                        0 if x > 0 => buf[base + i] - buf[base + i - 1],
                        1 if y > 0 => buf[base + i] - buf[base + i - w],
                        _ => 0.0,
                    };
                    buf.push(g);
                }
            }
        }
    }
}

/// Preprocesses a noisy frame. Needs the split and the G-buffers; the descriptors are taken if
/// present (the first `frame.spp` samples of them, since lower spp renders are prefixes) and
/// normalised into planes `[S, 36, H, W]` that crops and batches can cut (training).
pub fn prepare(frame: &Frame) -> Result<PreparedImage, PrepareError> {
    let mut img = prepare_without_descriptors(frame)?;
    if let Some(d) = &frame.descriptors {
        let all: Vec<usize> = (0..img.width * img.height).collect();
        img.descriptors = Some(normalised_columns(d, img.spp, &all));
    }
    Ok(img)
}

/// [`prepare`] for inference: moves the frame's descriptors into `records` and normalises
/// them there, in place, instead of copying them into planes; inference then only gathers the
/// columns of the pixels it reads ([`PreparedImage::descriptor_columns`]).
pub fn prepare_for_inference(frame: &mut Frame) -> Result<PreparedImage, PrepareError> {
    let mut img = prepare_without_descriptors(frame)?;
    img.records = frame.descriptors.take().map(NormalisedRecords::new);
    Ok(img)
}

/// The renderer's per-sample records with their 36 descriptor channels normalised in place
/// ([`normalise_descriptor`], non-finite values zeroed); the 37th field (the path weight)
/// is left as it was. Same layout as [`Descriptors`]: pixel-major, then sample, then field.
#[derive(Clone, Debug, PartialEq)]
pub struct NormalisedRecords(Descriptors);

impl NormalisedRecords {
    pub fn new(mut d: Descriptors) -> Self {
        for rec in d.data.chunks_exact_mut(FIELDS) {
            for (c, v) in rec[..DESCRIPTOR_CHANNELS].iter_mut().enumerate() {
                *v = finite(normalise_descriptor(c, *v));
            }
        }
        NormalisedRecords(d)
    }

    /// The normalised descriptors of `pixels` as `[S, 36, len]`: the first `s` samples of each.
    pub fn columns(&self, s: usize, pixels: &[usize]) -> Vec<f32> {
        gather_columns(&self.0, s, pixels, |_, v| v)
    }
}

/// Normalised descriptors of `pixels` (indices into the record image) as `[S, 36, len]`: the
/// first `s` samples of each pixel, method.md §4.1 transform, non-finite values zeroed.
pub fn normalised_columns(d: &Descriptors, s: usize, pixels: &[usize]) -> Vec<f32> {
    gather_columns(d, s, pixels, |c, v| finite(normalise_descriptor(c, v)))
}

/// `[S, 36, len]` columns of the first `s` samples of `pixels`, each value through `f(channel, v)`.
fn gather_columns(d: &Descriptors, s: usize, pixels: &[usize], f: impl Fn(usize, f32) -> f32) -> Vec<f32> {
    let (ds, len) = (d.spp as usize, pixels.len());
    let mut out = vec![0.0f32; s * DESCRIPTOR_CHANNELS * len];
    for (j, &i) in pixels.iter().enumerate() {
        for k in 0..s {
            let rec = &d.data[(i * ds + k) * FIELDS..(i * ds + k) * FIELDS + DESCRIPTOR_CHANNELS];
            for (c, &v) in rec.iter().enumerate() {
                out[(k * DESCRIPTOR_CHANNELS + c) * len + j] = f(c, v);
            }
        }
    }
    out
}

/// Everything of [`prepare`] but the descriptor planes: colour and G-buffer blocks, and from the
/// descriptors (checked against the frame, and left in it) the path weight and the pass-through
/// mask.
pub fn prepare_without_descriptors(frame: &Frame) -> Result<PreparedImage, PrepareError> {
    let (w, h) = (frame.width as usize, frame.height as usize);
    let n = w * h;
    let s = frame.spp.max(1);
    let diff = need(&frame.diffuse, "diffuse")?;
    let spec = need(&frame.specular, "specular")?;
    let alb = need(&frame.albedo, "albedo")?;
    let nrm = need(&frame.normal, "normal")?;
    let dep = need(&frame.depth, "depth")?;
    let pv = |b: &PixelBuffer| b.population_variance_of_mean(s);
    let (dv, sv, av, nv, zv) = (pv(diff), pv(spec), pv(alb), pv(nrm), pv(dep));
    let mean3 = |v: &[f32], i: usize| (v[3 * i] + v[3 * i + 1] + v[3 * i + 2]) / 3.0;

    // Diffuse block: demodulated colour and its variance, as method.md §2 step 2.
    let mut dblock = Vec::with_capacity(COLOUR_BLOCK * n);
    push_planes(&mut dblock, n, 3, |i, c| diff.mean[3 * i + c].max(0.0) / (alb.mean[3 * i + c] + ALBEDO_EPS));
    push_planes(&mut dblock, n, 1, |i, _| {
        let a2 = (0..3).map(|c| (alb.mean[3 * i + c] + ALBEDO_EPS).powi(2)).sum::<f32>() / 3.0;
        mean3(&dv, i) / a2
    });
    push_gradients(&mut dblock, 0, 3, w, h);

    // Specular block: log colour; variance through the derivative of the log (step 3).
    let mut sblock = Vec::with_capacity(COLOUR_BLOCK * n);
    push_planes(&mut sblock, n, 3, |i, c| spec.mean[3 * i + c].max(0.0).ln_1p());
    push_planes(&mut sblock, n, 1, |i, _| {
        let d2 = (0..3).map(|c| (1.0 + spec.mean[3 * i + c].max(0.0)).powi(2)).sum::<f32>() / 3.0;
        mean3(&sv, i) / d2
    });
    push_gradients(&mut sblock, 0, 3, w, h);

    // G block. Depth is normalised by the image maximum (step 5), so a crop must be cut from
    // the prepared full image, never prepared on its own.
    let zmax = dep.mean.iter().copied().filter(|z| z.is_finite()).fold(0.0f32, f32::max);
    let zs = if zmax > 0.0 { 1.0 / zmax } else { 0.0 };
    let mut g = Vec::with_capacity(G_BLOCK * n);
    push_planes(&mut g, n, 3, |i, c| nrm.mean[3 * i + c]);
    push_planes(&mut g, n, 1, |i, _| mean3(&nv, i));
    push_gradients(&mut g, 0, 3, w, h);
    let z0 = g.len();
    push_planes(&mut g, n, 1, |i, _| (dep.mean[i] * zs).clamp(0.0, 1.0));
    push_planes(&mut g, n, 1, |i, _| zv[i] * zs * zs);
    push_gradients(&mut g, z0, 1, w, h);
    let a0 = g.len();
    push_planes(&mut g, n, 3, |i, c| alb.mean[3 * i + c]);
    push_planes(&mut g, n, 1, |i, _| mean3(&av, i));
    push_gradients(&mut g, a0, 3, w, h);
    debug_assert_eq!(g.len(), G_BLOCK * n);

    let (path_weight, passthrough) = match &frame.descriptors {
        None => (vec![0.0; n], Vec::new()),
        Some(d) => {
            if d.width != frame.width || d.height != frame.height || d.spp < s {
                return Err(PrepareError::DescriptorShape {
                    dw: d.width,
                    dh: d.height,
                    ds: d.spp,
                    fw: frame.width,
                    fh: frame.height,
                    fs: frame.spp,
                });
            }
            let (s, ds) = (s as usize, d.spp as usize);
            let mut pw = vec![0.0f32; n];
            let mut pass = vec![true; n];
            for i in 0..n {
                for k in 0..s {
                    let rec = &d.data[(i * ds + k) * FIELDS..(i * ds + k + 1) * FIELDS];
                    pw[i] += finite((rec[field::PATH_WEIGHT].max(0.0) + 1e-6).ln() / 90.0) / s as f32;
                    // A camera ray that continued off a non-emitting surface has a bounce type.
                    if rec[field::BOUNCE_TYPE] != 0.0 {
                        pass[i] = false;
                    }
                }
            }
            (pw, pass)
        }
    };
    Ok(PreparedImage {
        width: w,
        height: h,
        spp: s as usize,
        diffuse: dblock,
        specular: sblock,
        g_block: g,
        path_weight,
        descriptors: None,
        records: None,
        passthrough,
    })
}

/// Method.md §4.1 transform of descriptor field `c` (0–35).
pub fn normalise_descriptor(c: usize, v: f32) -> f32 {
    let v = v.max(0.0);
    match c {
        c if c < field::LIGHT_INTENSITY => (v + 1e-6).ln() / 30.0,
        c if c < field::THROUGHPUT => (v + 1e-8).ln() / 10.0,
        c if c < field::BOUNCE_TYPE => (v + 1e-6).ln() / 30.0,
        c if c < field::ROUGHNESS => v / 19.0,
        _ => v.sqrt(),
    }
}

/// Targets from a reference frame rendered with the split and G-buffers.
pub fn prepare_target(reference: &Frame) -> Result<PreparedTarget, PrepareError> {
    let n = reference.pixels();
    let diff = need(&reference.diffuse, "diffuse")?;
    let alb = need(&reference.albedo, "albedo")?;
    let t = &reference.radiance.mean;
    let mut diffuse = Vec::with_capacity(3 * n);
    let mut specular = Vec::with_capacity(3 * n);
    let mut total = Vec::with_capacity(3 * n);
    push_planes(&mut diffuse, n, 3, |i, c| diff.mean[3 * i + c].max(0.0) / (alb.mean[3 * i + c] + ALBEDO_EPS));
    push_planes(&mut specular, n, 3, |i, c| (t[3 * i + c] - diff.mean[3 * i + c]).max(0.0).ln_1p());
    push_planes(&mut total, n, 3, |i, c| t[3 * i + c].max(0.0));
    Ok(PreparedTarget { width: reference.width as usize, height: reference.height as usize, diffuse, specular, total })
}

/// Copies the `w × h` window at (x, y) of every plane of a planar buffer with `planes` planes.
fn crop_planes(src: &[f32], planes: usize, width: usize, height: usize, x: usize, y: usize, w: usize, h: usize) -> Vec<f32> {
    let n = width * height;
    let mut out = Vec::with_capacity(planes * w * h);
    for p in 0..planes {
        for row in y..y + h {
            let o = p * n + row * width + x;
            out.extend_from_slice(&src[o..o + w]);
        }
    }
    out
}

fn check_crop(x: usize, y: usize, w: usize, h: usize, width: usize, height: usize) -> Result<(), PrepareError> {
    if w == 0 || h == 0 || x + w > width || y + h > height {
        return Err(PrepareError::Crop { x, y, w, h, width, height });
    }
    Ok(())
}

/// One `dims` tensor from the same planar field of every crop of a batch.
fn stack_planes<T>(crops: &[&T], field: &dyn Fn(&T) -> &[f32], dims: [usize; 4], device: &Device) -> Tensor<4> {
    let data: Vec<f32> = crops.iter().flat_map(|c| field(c).iter().copied()).collect();
    Tensor::from_data(TensorData::new(data, dims), device)
}

impl PreparedImage {
    pub fn crop(&self, x: usize, y: usize, w: usize, h: usize) -> Result<PreparedImage, PrepareError> {
        check_crop(x, y, w, h, self.width, self.height)?;
        let c = |src: &[f32], planes| crop_planes(src, planes, self.width, self.height, x, y, w, h);
        let passthrough = if self.passthrough.is_empty() {
            Vec::new()
        } else {
            (y..y + h).flat_map(|r| self.passthrough[r * self.width + x..r * self.width + x + w].iter().copied()).collect()
        };
        Ok(PreparedImage {
            width: w,
            height: h,
            spp: self.spp,
            diffuse: c(&self.diffuse, COLOUR_BLOCK),
            specular: c(&self.specular, COLOUR_BLOCK),
            g_block: c(&self.g_block, G_BLOCK),
            path_weight: c(&self.path_weight, 1),
            descriptors: match &self.descriptors {
                Some(d) => Some(c(d, self.spp * DESCRIPTOR_CHANNELS)),
                None => {
                    let pixels: Vec<usize> = (y..y + h).flat_map(|r| (x..x + w).map(move |q| r * self.width + q)).collect();
                    self.descriptor_columns(&pixels)
                }
            },
            records: None,
            passthrough,
        })
    }

    /// Whether the image has per-sample descriptors, as planes or as records.
    pub fn has_descriptors(&self) -> bool {
        self.descriptors.is_some() || self.records.is_some()
    }

    /// Normalised descriptors of `pixels` (indices into this image) as `[S, 36, len]`, gathered
    /// from the planes or the records, whichever the image holds (both are normalised already).
    pub fn descriptor_columns(&self, pixels: &[usize]) -> Option<Vec<f32>> {
        if let Some(d) = &self.descriptors {
            let n = self.width * self.height;
            let mut out = Vec::with_capacity(self.spp * DESCRIPTOR_CHANNELS * pixels.len());
            for plane in 0..self.spp * DESCRIPTOR_CHANNELS {
                let p = &d[plane * n..(plane + 1) * n];
                out.extend(pixels.iter().map(|&i| p[i]));
            }
            return Some(out);
        }
        self.records.as_ref().map(|r| r.columns(self.spp, pixels))
    }

    /// Stacks crops of equal size and spp into one batch. Without descriptors, the descriptor
    /// tensors hold one all-zero sample (so shapes stay valid for models that ignore them).
    pub fn to_tensors(crops: &[&PreparedImage], device: &Device) -> InputTensors {
        assert!(!crops.is_empty(), "empty batch");
        let (w, h, s) = (crops[0].width, crops[0].height, crops[0].spp);
        assert!(crops.iter().all(|c| c.width == w && c.height == h && c.spp == s), "crops of a batch must agree in size and spp");
        let b = crops.len();
        let stack = |f: &dyn Fn(&PreparedImage) -> &[f32], ch: usize| stack_planes(crops, f, [b, ch, h, w], device);
        let g_block = stack(&|c| &c.g_block, G_BLOCK);
        let descriptors: Tensor<5> = if crops.iter().all(|c| c.descriptors.is_some()) {
            let data: Vec<f32> = crops.iter().flat_map(|c| c.descriptors.as_ref().unwrap().iter().copied()).collect();
            Tensor::from_data(TensorData::new(data, [b, s, DESCRIPTOR_CHANNELS, h, w]), device)
        } else {
            Tensor::zeros([b, 1, DESCRIPTOR_CHANNELS, h, w], device)
        };
        InputTensors {
            diffuse: BranchInput {
                colour: stack(&|c| &c.diffuse, COLOUR_BLOCK),
                g_block: g_block.clone(),
                descriptors: descriptors.clone(),
                spp: s,
            },
            specular: BranchInput { colour: stack(&|c| &c.specular, COLOUR_BLOCK), g_block, descriptors, spp: s },
            path_weight: stack(&|c| &c.path_weight, 1),
        }
    }
}

impl PreparedTarget {
    pub fn crop(&self, x: usize, y: usize, w: usize, h: usize) -> Result<PreparedTarget, PrepareError> {
        check_crop(x, y, w, h, self.width, self.height)?;
        let c = |src: &[f32]| crop_planes(src, 3, self.width, self.height, x, y, w, h);
        Ok(PreparedTarget { width: w, height: h, diffuse: c(&self.diffuse), specular: c(&self.specular), total: c(&self.total) })
    }

    pub fn to_tensors(crops: &[&PreparedTarget], device: &Device) -> TargetTensors {
        assert!(!crops.is_empty(), "empty batch");
        let (w, h) = (crops[0].width, crops[0].height);
        assert!(crops.iter().all(|c| c.width == w && c.height == h), "crops of a batch must agree in size");
        let b = crops.len();
        let stack = |f: &dyn Fn(&PreparedTarget) -> &[f32]| stack_planes(crops, f, [b, 3, h, w], device);
        TargetTensors { diffuse: stack(&|c| &c.diffuse), specular: stack(&|c| &c.specular), total: stack(&|c| &c.total) }
    }
}

#[cfg(test)]
mod tests;
