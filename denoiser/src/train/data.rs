//! Loading the shots of a `pixguide dataset` folder into memory, prepared once per shot and
//! sample count, and cutting batches from them.

use std::path::{Path, PathBuf};

use burn::tensor::Device;
use film::descriptors::{field, FIELDS};
use film::{exr_io, DescriptorFile, Descriptors};

use super::augment::{self, DescriptorSource, Dihedral};
use super::patches::{self, PatchSampler, Sampling};
use super::stored::StoredImage;
use super::TrainError;
use crate::preprocess::{
    finite, normalise_descriptor, prepare_target, prepare_without_descriptors, InputTensors, PreparedImage, PreparedTarget, TargetTensors,
    DESCRIPTOR_CHANNELS,
};

/// One shot: its inputs at every sample count, its target and its patch sampler.
pub struct Shot {
    /// `<split>/<scene>_<shot>` as in shots.jsonl.
    pub name: String,
    /// Inputs per entry of [`Dataset::spps`], without descriptors (those are shared below), in
    /// bf16 while in memory ([`StoredImage`]).
    pub images: Vec<StoredImage>,
    /// The per-sample descriptors of the largest sample count, read from disk patch by patch
    /// (a 64-spp training set's descriptors outgrow memory); a render at fewer samples uses
    /// the first S of each pixel's (the dataset's lower counts are prefixes).
    pub descriptors: Option<DescriptorFile>,
    pub target: PreparedTarget,
    pub sampler: PatchSampler,
}

pub struct Dataset {
    pub root: PathBuf,
    pub spps: Vec<usize>,
    pub train: Vec<Shot>,
    pub val: Vec<Shot>,
    pub width: usize,
    pub height: usize,
}

/// What to load.
#[derive(Clone, Debug)]
pub struct LoadOptions {
    /// Sample counts to use (each needs a noisy_<S>spp.exr); empty = all found in the first shot.
    pub spps: Vec<usize>,
    pub descriptors: bool,
    pub patch: usize,
    pub sampling: Sampling,
    /// At most this many training shots (None = all), for quick runs; `Some(0)` loads only the
    /// validation shots (calibration needs no training data).
    pub max_train: Option<usize>,
}

fn err(path: &Path, msg: impl std::fmt::Display) -> TrainError {
    TrainError::Data(format!("{}: {msg}", path.display()))
}

/// Sample counts of a shot folder's `noisy_<S>spp.exr` files, increasing (none if unreadable).
pub fn spps_in(dir: &Path) -> Vec<usize> {
    let mut v: Vec<usize> = std::fs::read_dir(dir)
        .into_iter()
        .flatten()
        .flatten()
        .filter_map(|e| {
            let n = e.file_name().to_string_lossy().into_owned();
            n.strip_prefix("noisy_")?.strip_suffix("spp.exr")?.parse().ok()
        })
        .collect();
    v.sort_unstable();
    v
}

/// Reads shots.jsonl: (split, dir) per line.
pub fn read_index(root: &Path) -> Result<Vec<(String, String)>, TrainError> {
    let path = root.join("shots.jsonl");
    let text = std::fs::read_to_string(&path).map_err(|e| err(&path, format!("{e} (is this a `pixguide dataset` folder?)")))?;
    let mut out = Vec::new();
    for (k, line) in text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty()) {
        let v: serde_json::Value = serde_json::from_str(line).map_err(|e| err(&path, format!("line {}: {e}", k + 1)))?;
        let s = |f: &str| {
            v.get(f).and_then(|x| x.as_str()).map(str::to_owned).ok_or_else(|| err(&path, format!("line {}: field `{f}` missing", k + 1)))
        };
        out.push((s("split")?, s("dir")?));
    }
    Ok(out)
}

/// Loads one shot folder.
pub fn load_shot(root: &Path, dir: &str, spps: &[usize], opts: &LoadOptions) -> Result<Shot, TrainError> {
    let d = root.join(dir);
    let max = *spps.iter().max().unwrap();
    let ref_path = d.join("reference.exr");
    let reference = exr_io::read_frame(&ref_path).map_err(|e| err(&ref_path, e))?;
    let target = prepare_target(&reference).map_err(|e| err(&ref_path, e))?;
    let desc_path = d.join(format!("descriptors_{max}spp.safetensors"));
    // The descriptors feed the P-buffer models, the G+P path-weight channel and the importance
    // map's bounce-type term, so they are read whenever present.
    let mut desc = if desc_path.exists() {
        Some(Descriptors::read_safetensors(&desc_path).map_err(|e| err(&desc_path, e))?)
    } else if opts.descriptors {
        return Err(err(&desc_path, "missing; P-buffer models need the per-sample descriptors"));
    } else {
        None
    };
    let descriptors = match (&desc, opts.descriptors) {
        (Some(d), true) => {
            let f = DescriptorFile::open(&desc_path).map_err(|e| err(&desc_path, e))?;
            if (f.width, f.height, f.spp) != (d.width, d.height, d.spp) {
                return Err(err(&desc_path, "changed while it was read"));
            }
            Some(f)
        }
        _ => None,
    };
    let mut images = Vec::with_capacity(spps.len());
    for &s in spps {
        let p = d.join(format!("noisy_{s}spp.exr"));
        let mut frame = exr_io::read_frame(&p).map_err(|e| err(&p, e))?;
        if frame.width as usize != target.width || frame.height as usize != target.height {
            return Err(err(&p, format!("{}×{} but the reference is {}×{}", frame.width, frame.height, target.width, target.height)));
        }
        // The descriptors are lent to each spp's frame (for the path weight and the
        // pass-through mask) and taken back; patches read them from the file.
        frame.descriptors = desc.take();
        let img = prepare_without_descriptors(&frame).map_err(|e| err(&p, e))?;
        desc = frame.descriptors.take();
        images.push(StoredImage::new(&img));
    }
    let (w, h) = (target.width, target.height);
    if w < opts.patch || h < opts.patch {
        return Err(err(&d, format!("{w}×{h} is smaller than the {}² patch", opts.patch)));
    }
    let sampler = match opts.sampling {
        Sampling::Uniform => PatchSampler::uniform(w, h, opts.patch),
        Sampling::Importance => {
            let n = w * h;
            let normal = reference.normal.as_ref().map(|b| b.mean.clone()).unwrap_or_else(|| vec![0.0; 3 * n]);
            let bounce0: Vec<[f32; 3]> = match &desc {
                Some(ds) => (0..n)
                    .map(|i| {
                        let mut f = [0.0f32; 3];
                        let k = ds.spp as usize;
                        for s in 0..k {
                            let b = ds.data[(i * k + s) * FIELDS + field::BOUNCE_TYPE].max(0.0) as u32;
                            for (j, flag) in [patches::DIFFUSE, patches::GLOSSY, patches::SPECULAR].into_iter().enumerate() {
                                if b & flag != 0 {
                                    f[j] += 1.0 / k as f32;
                                }
                            }
                        }
                        f
                    })
                    .collect(),
                None => vec![[0.0; 3]; n],
            };
            let m = patches::importance_map(&reference.radiance.mean, &normal, &bounce0, w, h, patches::sigma_for(w, h));
            PatchSampler::from_map(&m, w, h, opts.patch)
        }
    };
    Ok(Shot { name: dir.to_string(), images, descriptors, target, sampler })
}

impl Dataset {
    pub fn load(root: &Path, opts: &LoadOptions, progress: &mut dyn FnMut(usize, usize)) -> Result<Dataset, TrainError> {
        let index = read_index(root)?;
        let first = index.first().ok_or_else(|| err(&root.join("shots.jsonl"), "no shots"))?;
        let found = spps_in(&root.join(&first.1));
        let spps = if opts.spps.is_empty() { found.clone() } else { opts.spps.clone() };
        if spps.is_empty() {
            return Err(err(&root.join(&first.1), "no noisy_<S>spp.exr files"));
        }
        if let Some(s) = spps.iter().find(|s| !found.contains(s)) {
            return Err(err(&root.join(&first.1), format!("no noisy_{s}spp.exr (found {found:?})")));
        }
        let mut train = Vec::new();
        let mut val = Vec::new();
        let ntrain = index.iter().filter(|(s, _)| s == "train").count().min(opts.max_train.unwrap_or(usize::MAX));
        let wanted: Vec<&(String, String)> = {
            let mut k = 0;
            index
                .iter()
                .filter(|(s, _)| {
                    if s == "train" {
                        k += 1;
                        k <= ntrain
                    } else {
                        s == "val"
                    }
                })
                .collect()
        };
        for (i, (split, dir)) in wanted.iter().enumerate() {
            progress(i, wanted.len());
            let shot = load_shot(root, dir, &spps, opts)?;
            if split == "val" {
                val.push(shot)
            } else {
                train.push(shot)
            }
        }
        progress(wanted.len(), wanted.len());
        let all: Vec<&Shot> = train.iter().chain(&val).collect();
        let (width, height) = (all.first().map_or(0, |s| s.target.width), all.first().map_or(0, |s| s.target.height));
        if train.is_empty() && opts.max_train != Some(0) {
            return Err(err(root, "no training shots"));
        }
        if all.is_empty() {
            return Err(err(root, "no validation shots"));
        }
        if let Some(s) = all.iter().find(|s| s.target.width != width || s.target.height != height) {
            return Err(err(&root.join(&s.name), format!("size differs from the first shot's {width}×{height}")));
        }
        Ok(Dataset { root: root.to_path_buf(), spps, train, val, width, height })
    }

    /// Bytes held by the prepared arrays (for the memory report); the descriptors stay on disk.
    pub fn bytes(&self) -> usize {
        self.train
            .iter()
            .chain(&self.val)
            .map(|s| s.images.iter().map(StoredImage::bytes).sum::<usize>() + 4 * 9 * s.target.width * s.target.height)
            .sum()
    }
}

/// One patch of a batch: shot index (into the split), spp index, corner, and the symmetry it
/// is moved by (augmentation; the identity for validation).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PatchRef {
    pub shot: usize,
    pub spp: usize,
    pub x: usize,
    pub y: usize,
    pub t: Dihedral,
}

/// The normalised descriptors (the first `spp` samples) of the `p × p` region at (x, y) of a
/// `width`-wide image, read from its file: the values [`crate::preprocess::prepare`] puts in
/// its planes, bit for bit, for the pixels a patch cut there reads.
pub struct Region {
    /// `[spp, 36, p·p]`.
    data: Vec<f32>,
    x: usize,
    y: usize,
    p: usize,
    width: usize,
    spp: usize,
}

impl Region {
    pub fn read(file: &DescriptorFile, spp: usize, x: usize, y: usize, p: usize, width: usize) -> Result<Region, film::Error> {
        let n = p * p;
        let mut data = vec![0.0f32; spp * DESCRIPTOR_CHANNELS * n];
        let mut rec = vec![0.0f32; spp * FIELDS];
        for row in 0..p {
            for col in 0..p {
                file.read_prefix((y + row) * width + x + col, spp, &mut rec)?;
                let j = row * p + col;
                for (k, r) in rec.chunks_exact(FIELDS).enumerate() {
                    for (c, &v) in r[..DESCRIPTOR_CHANNELS].iter().enumerate() {
                        data[(k * DESCRIPTOR_CHANNELS + c) * n + j] = finite(normalise_descriptor(c, v));
                    }
                }
            }
        }
        Ok(Region { data, x, y, p, width, spp })
    }
}

impl DescriptorSource for Region {
    fn columns(&self, pixels: &[usize]) -> Vec<f32> {
        let local: Vec<usize> = pixels
            .iter()
            .map(|&i| {
                let (ix, iy) = (i % self.width, i / self.width);
                assert!((self.x..self.x + self.p).contains(&ix) && (self.y..self.y + self.p).contains(&iy), "pixel {i} outside the region");
                (iy - self.y) * self.p + ix - self.x
            })
            .collect();
        let n = self.p * self.p;
        (0..self.spp * DESCRIPTOR_CHANNELS).flat_map(|plane| local.iter().map(move |&j| self.data[plane * n + j])).collect()
    }
}

/// Cuts a patch: inputs (with the first S descriptor samples if the model needs them) and the
/// target cropped to the output (`margin` less on each side), both moved by `r.t`.
/// Fails only if the shot's descriptor file cannot be read any more.
pub fn cut(
    shot: &Shot,
    r: &PatchRef,
    spp: usize,
    patch: usize,
    margin: usize,
    with_descriptors: bool,
) -> Result<(PreparedImage, PreparedTarget), TrainError> {
    let img = shot.images[r.spp].prepared();
    let region = match shot.descriptors.as_ref().filter(|_| with_descriptors) {
        Some(file) => Some(
            Region::read(file, spp, r.x, r.y, patch, img.width)
                .map_err(|e| TrainError::Data(format!("{} (shot {}): {e}", "descriptors", shot.name)))?,
        ),
        None => None,
    };
    let crop = augment::cut_image(&img, region.as_ref().map(|s| s as &dyn DescriptorSource), r.x, r.y, patch, r.t);
    let o = patch - 2 * margin;
    let t = augment::cut_target(&shot.target, r.x + margin, r.y + margin, o, r.t);
    Ok((crop, t))
}

/// Tensors of a batch.
pub fn batch_tensors(
    shots: &[Shot],
    refs: &[PatchRef],
    spps: &[usize],
    patch: usize,
    margin: usize,
    with_descriptors: bool,
    device: &Device,
) -> Result<(InputTensors, TargetTensors), TrainError> {
    // In parallel: a P-buffer patch reads and normalises its descriptors (up to 64 × 36 values
    // a pixel). The order of the batch is the order of `refs` whatever the thread count.
    use rayon::prelude::*;
    let cuts: Vec<(PreparedImage, PreparedTarget)> =
        refs.par_iter().map(|r| cut(&shots[r.shot], r, spps[r.spp], patch, margin, with_descriptors)).collect::<Result<_, _>>()?;
    let imgs: Vec<&PreparedImage> = cuts.iter().map(|c| &c.0).collect();
    let tgts: Vec<&PreparedTarget> = cuts.iter().map(|c| &c.1).collect();
    Ok((PreparedImage::to_tensors(&imgs, device), PreparedTarget::to_tensors(&tgts, device)))
}
